"""Flutter-derivative tables: the exchange format of measured and published derivatives.

A table holds Scanlan's flutter derivatives at a set of reduced frequencies: the eight of heave
and pitch, or the 18 of three degrees of freedom (``docs/reference/conventions.md``, "Three degrees
of freedom"). On disk it is a CSV file (``docs/reference/flutter_derivative_tables.md``): a
header, one row per reduced velocity, the first column ``K`` (``B omega / U``) or ``Ur``
(``U / (f B) = 2 pi / K``), then any of ``H1..H6, A1..A6, P1..P6`` in windrig's signs; a
derivative the file does not have is zero, and the table says which ones it filled
(:attr:`FlutterDerivativeTable.filled`). A derivative may carry its standard deviation
(:attr:`FlutterDerivativeTable.std`), in a column named after it with ``_std`` (``H1_std``):
``windrig identify --table`` writes them from the identified model's uncertainty, and reading a
table keeps them (its flutter analysis uses the values; the std is reported alongside).

Sources with other signs are converted on reading by a named ``convention``, never guessed:

- ``"scanlan"`` (the default): windrig's own, Scanlan's signs (h and L positive downward, alpha
  and M nose-up, p and D downwind);
- ``"z_up"``: the same definitions with h and L positive upward, as several structural codes
  use. Flipping both h and L leaves a derivative alone when it relates L to h (H1, H4) or
  neither to them; it changes the sign of those relating exactly one of them to something else:
  L to alpha or p (H2, H3, H5, H6), M or D to h (A1, A4, P5, P6).

Not responsible for: fitting a table with rational functions (:func:`ident.model.roger.roger_fit`),
flutter from a table (:func:`ident.model.flutter.frequency_domain` with :meth:`interpolator`).
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.interpolate import PchipInterpolator

from ident.model.conventions import (
    FLUTTER_DERIVATIVE_NAMES,
    FLUTTER_DERIVATIVE_NAMES_3DOF,
    Q_from_flutter_derivatives,
    derivative_names,
)

__all__ = ["CONVENTIONS", "STD_SUFFIX", "FlutterDerivativeTable"]

FloatArray = npt.NDArray[np.float64]

#: Sign conventions a table may be read in (see the module docstring).
CONVENTIONS: tuple[str, ...] = ("scanlan", "z_up")
#: Derivatives whose sign flips between windrig's signs and h, L positive upward.
_Z_UP_FLIPS = frozenset({"H2", "H3", "H5", "H6", "A1", "A4", "P5", "P6"})
#: Suffix of a derivative's standard-deviation column (``H1_std``); a std keeps its sign under
#: every convention.
STD_SUFFIX = "_std"


@dataclass(frozen=True, eq=False)
class FlutterDerivativeTable:
    """Flutter derivatives at reduced frequencies, in windrig's (Scanlan's) signs.

    Parameters
    ----------
    K : array_like, shape (n,)
        Reduced frequencies ``B omega / U``, > 0, distinct (stored increasing).
    values : mapping of str to array_like
        Every derivative of the table's degrees of freedom (``H1..H4, A1..A4``, or all 18
        ``H1..H6, A1..A6, P1..P6``), each of shape (n,), finite.
    filled : tuple of str, optional
        Derivatives that the source did not give and that were set to zero.
    source : str, optional
        Where the table came from (a file name), for messages.
    std : mapping of str to array_like, optional
        Standard deviation of some or all of the derivatives (same names, each of shape (n),
        finite and >= 0, non-dimensional); a derivative without one has no stated uncertainty.

    Raises
    ------
    ValueError
        On a K that is not > 0 or repeats, a missing or unknown derivative, a wrong length, or a
        value (or std) that is not finite (a std < 0); the message names the derivative or the K.
    """

    K: FloatArray
    values: Mapping[str, FloatArray]
    filled: tuple[str, ...] = ()
    source: str = ""
    std: Mapping[str, FloatArray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        where = f"{self.source}: " if self.source else ""
        K = np.asarray(self.K, dtype=float)
        if K.ndim != 1 or K.size < 1:
            raise ValueError(f"{where}K must be a 1-D array with at least one value")
        if not np.all(np.isfinite(K)) or np.any(K <= 0.0):
            raise ValueError(f"{where}every K must be finite and > 0")
        order = np.argsort(K)
        if np.any(np.diff(K[order]) == 0.0):
            repeated = K[order][1:][np.diff(K[order]) == 0.0]
            raise ValueError(f"{where}K = {float(repeated[0]):g} appears twice")
        n_dof = 3 if set(self.values) - set(FLUTTER_DERIVATIVE_NAMES) else 2
        names = derivative_names(n_dof)
        unknown = sorted(set(self.values) - set(names))
        if unknown:
            raise ValueError(f"{where}unknown flutter derivative(s) {unknown}; allowed: "
                             f"{', '.join(FLUTTER_DERIVATIVE_NAMES_3DOF)}")
        missing = [name for name in names if name not in self.values]
        if missing:
            raise ValueError(f"{where}flutter derivative(s) missing: {missing}")
        values: dict[str, FloatArray] = {}
        for name in names:
            column = np.asarray(self.values[name], dtype=float)
            if column.shape != K.shape:
                raise ValueError(f"{where}{name} has {column.size} values for {K.size} K")
            if not np.all(np.isfinite(column)):
                bad = float(K[~np.isfinite(column)][0])
                raise ValueError(f"{where}{name} is not finite at K = {bad:g}")
            values[name] = column[order]
            values[name].flags.writeable = False
        std = _checked_std(self.std, names, K, order, where)
        K = K[order]
        K.flags.writeable = False
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "std", std)
        object.__setattr__(self, "filled", tuple(self.filled))

    @property
    def n_dof(self) -> int:
        """Degrees of freedom of the table: 2 (eight derivatives) or 3 (18)."""
        return 3 if len(self.values) == len(FLUTTER_DERIVATIVE_NAMES_3DOF) else 2

    @property
    def reduced_velocity(self) -> FloatArray:
        """``U / (f B) = 2 pi / K`` of each row (decreasing)."""
        return np.asarray(2.0 * math.pi / self.K, dtype=float)

    def Q(self) -> npt.NDArray[np.complex128]:
        """``Q(iK)`` at the table's reduced frequencies, shape (n, n_dof, n_dof), complex."""
        return Q_from_flutter_derivatives(self.K, dict(self.values))

    @classmethod
    def from_model(cls, model: Any, K: Any, source: str = "", *,
                   with_std: bool = False) -> FlutterDerivativeTable:
        """Tabulate a model's derivatives (anything with ``flutter_derivatives(K)``) at ``K``.

        ``with_std`` also tabulates their standard deviations from the model's
        ``flutter_derivative_std(K)`` (an identified model's:
        :meth:`ident.identification.results.IdentifiedModel.flutter_derivative_std`).
        """
        K_arr = np.asarray(K, dtype=float)
        std = model.flutter_derivative_std(K_arr) if with_std else {}
        return cls(K_arr, model.flutter_derivatives(K_arr), source=source, std=std)

    def interpolator(self) -> Callable[[Any], dict[str, FloatArray]]:
        """Return ``f(K) -> derivatives`` between the table's rows (monotone cubic, PCHIP).

        PCHIP follows the table without overshoot between rows (a measured table is noisy, and a
        spline through noise swings). Outside the table's K range the function raises
        ``ValueError``: a table says nothing there, and a flutter search must not silently
        extrapolate it (:func:`ident.model.flutter.frequency_domain` takes the table's range).
        """
        if self.K.size < 2:
            raise ValueError(f"{self.source or 'table'}: one row cannot be interpolated")
        curves = {name: PchipInterpolator(self.K, column) for name, column in self.values.items()}
        low, high = float(self.K[0]), float(self.K[-1])

        def derivatives(K: Any) -> dict[str, FloatArray]:
            K_arr = np.asarray(K, dtype=float)
            tolerance = 1e-12 * high
            if np.any(K_arr < low - tolerance) or np.any(K_arr > high + tolerance):
                raise ValueError(f"K outside the table's range {low:g} to {high:g}")
            K_arr = np.clip(K_arr, low, high)
            return {name: np.asarray(curve(K_arr), dtype=float) for name, curve in curves.items()}

        return derivatives

    def to_csv(self, path: str | os.PathLike[str]) -> None:
        """Write the table as CSV: ``K``, every derivative, then each std there is (``H1_std``).

        Windrig's signs, 17 significant digits (a round trip is exact).
        """
        names = derivative_names(self.n_dof)
        with_std = [n for n in names if n in self.std]
        with open(path, "w", newline="", encoding="utf-8") as handle:
            writer = csv.writer(handle)
            writer.writerow(["K", *names, *(f"{n}{STD_SUFFIX}" for n in with_std)])
            for i, K in enumerate(self.K):
                writer.writerow([repr(float(K)), *(repr(float(self.values[n][i])) for n in names),
                                 *(repr(float(self.std[n][i])) for n in with_std)])

    @classmethod
    def from_csv(cls, path: str | os.PathLike[str], *, convention: str = "scanlan",
                 n_dof: int | None = None) -> FlutterDerivativeTable:
        """Read a table from CSV, converting from ``convention`` to windrig's signs.

        Parameters
        ----------
        path : path-like
            The CSV file: a header row, then one row per reduced frequency. Blank lines and
            lines starting with ``#`` are skipped. ``K``, ``Ur`` and ``_std`` may be in either
            case; the derivatives are Scanlan's capitals and may carry his star (``H1*``): lower
            case (``h1*``) is Politecnico di Milano's notation and is refused, not guessed. A
            column ``<name>_std`` (``H1_std``, ``H1*_std``) is the std of that derivative,
            which the file must also give.
        convention : str
            One of :data:`CONVENTIONS`: the signs the file's derivatives are written in.
        n_dof : int, optional
            2 or 3: the table's degrees of freedom. Default: 3 if the file has any derivative of
            sway or drag (``H5, H6, A5, A6, P1..P6``), else 2.

        Raises
        ------
        ValueError
            One line naming the file and what is wrong: no K or Ur column, an unknown column, a
            derivative headed in lower case (Milan's notation), a value that is not a number
            (with its line), an unknown convention.
        """
        source = os.fspath(path)
        if convention not in CONVENTIONS:
            raise ValueError(f"{source}: unknown convention {convention!r}; allowed: "
                             f"{', '.join(CONVENTIONS)}")
        header, rows = _read_rows(source)
        columns = [_column_name(name) for name in header]
        if not columns or columns[0] not in ("K", "UR"):
            raise ValueError(f"{source}: the first column must be K or Ur, got "
                             f"{header[0] if header else 'nothing'!r}")
        unknown = [h for h, c in zip(header[1:], columns[1:], strict=True)
                   if c.removesuffix(STD_SUFFIX.upper()) not in FLUTTER_DERIVATIVE_NAMES_3DOF]
        if unknown:
            raise ValueError(f"{source}: unknown column(s) {unknown}; allowed: K or Ur, then "
                             f"{', '.join(FLUTTER_DERIVATIVE_NAMES_3DOF)}")
        polimi = [h for h in header[1:] if h.strip()[:1] in ("h", "a", "p")]
        if polimi:
            # Lower case is Politecnico di Milano's notation (h1*..a4*, p1*..p6*), whose
            # normalisation and signs differ from Scanlan's: read as H1*.., every derivative
            # would be silently wrong, and no convention here converts it.
            raise ValueError(f"{source}: column(s) {polimi} are in lower case, the notation of "
                             "Politecnico di Milano's derivatives (h1*..a4*, p1*..p6*), which "
                             "differ from Scanlan's in normalisation and signs and are not "
                             "converted; head Scanlan's derivatives in capitals (H1..A6, "
                             "P1..P6), or convert a Milan table to them first")
        repeated = sorted({c for c in columns if columns.count(c) > 1})
        if repeated:
            raise ValueError(f"{source}: column(s) {repeated} appear twice")
        data = np.array(rows, dtype=float)
        if data.shape[0] == 0:
            raise ValueError(f"{source}: no rows below the header")
        first = data[:, 0]
        if columns[0] == "UR":
            if np.any(first <= 0.0):
                raise ValueError(f"{source}: every Ur must be > 0")
            first = 2.0 * math.pi / first
        read = dict(zip(columns[1:], data[:, 1:].T, strict=True))
        suffix = STD_SUFFIX.upper()
        given = {c: v for c, v in read.items() if not c.endswith(suffix)}
        std = {c.removesuffix(suffix): v for c, v in read.items() if c.endswith(suffix)}
        orphans = sorted(set(std) - set(given))
        if orphans:
            raise ValueError(f"{source}: std column(s) {[n + STD_SUFFIX for n in orphans]} "
                             "without their derivative's column")
        if n_dof is None:
            n_dof = 3 if set(given) - set(FLUTTER_DERIVATIVE_NAMES) else 2
        names = derivative_names(n_dof)
        extra = sorted(set(given) - set(names))
        if extra:
            raise ValueError(f"{source}: column(s) {extra} are not derivatives of {n_dof} "
                             "degrees of freedom")
        if convention == "z_up":
            given = {n: -v if n in _Z_UP_FLIPS else v for n, v in given.items()}
        filled = tuple(n for n in names if n not in given)
        values = {n: given.get(n, np.zeros_like(first)) for n in names}
        return cls(first, values, filled=filled, source=source, std=std)


def _column_name(header: str) -> str:
    """Return a header's canonical name: upper case, without Scanlan's star (``h1*_std``)."""
    name = header.strip().upper()
    suffix = STD_SUFFIX.upper()
    if name.endswith(suffix):
        return name.removesuffix(suffix).rstrip("*") + suffix
    return name.rstrip("*")


def _checked_std(std: Mapping[str, Any], names: tuple[str, ...] | list[str], K: FloatArray,
                 order: npt.NDArray[np.intp], where: str) -> dict[str, FloatArray]:
    """Return a table's std columns checked (known names, lengths, finite, >= 0) and sorted."""
    unknown = sorted(set(std) - set(names))
    if unknown:
        raise ValueError(f"{where}std of unknown flutter derivative(s) {unknown}")
    out: dict[str, FloatArray] = {}
    for name in names:
        if name not in std:
            continue
        column = np.asarray(std[name], dtype=float)
        if column.shape != K.shape:
            raise ValueError(f"{where}{name}{STD_SUFFIX} has {column.size} values for {K.size} K")
        bad = ~np.isfinite(column) | (column < 0.0)
        if np.any(bad):
            raise ValueError(f"{where}{name}{STD_SUFFIX} is not a finite value >= 0 at K = "
                             f"{float(K[bad][0]):g}")
        out[name] = column[order]
        out[name].flags.writeable = False
    return out


def _read_rows(source: str) -> tuple[list[str], list[list[float]]]:
    """Return the header and the numeric rows of a CSV file (one clear error per problem)."""
    try:
        with open(source, newline="", encoding="utf-8") as handle:
            lines = [(i, row) for i, row in enumerate(csv.reader(handle), start=1)
                     if row and any(cell.strip() for cell in row)
                     and not row[0].lstrip().startswith("#")]
    except FileNotFoundError:
        raise ValueError(f"{source}: no such file") from None
    except UnicodeDecodeError as exc:
        raise ValueError(f"{source}: not a text (UTF-8) CSV file: {exc.reason}") from None
    if not lines:
        raise ValueError(f"{source}: empty (no header)")
    (_, header), body = lines[0], lines[1:]
    rows: list[list[float]] = []
    for number, row in body:
        if len(row) != len(header):
            raise ValueError(f"{source}, line {number}: {len(row)} values for {len(header)} "
                             "columns")
        try:
            rows.append([float(cell) for cell in row])
        except ValueError:
            bad = next(c for c in row if not _is_number(c))
            raise ValueError(f"{source}, line {number}: {bad.strip()!r} is not a number") from None
    return [h.strip() for h in header], rows


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
