"""The flutter derivatives of an identified model as a printed table, and its degrees of freedom.

Responsibility: :func:`derivative_rows` and :func:`format_derivative_table` give the flutter
derivatives of a rational-function model (``H1*..A4*``, or with sway all 18 ``H1*..H6*,
A1*..A6*, P1*..P6*`` in the order of :func:`ident.model.conventions.derivative_names`, Scanlan's
signs of ``docs/reference/conventions.md``) at a few reduced frequencies spanning what the releases
measured, one line per derivative; ``windrig identify`` prints it for a run of three degrees of
freedom. :func:`check_model_dof` refuses a model with fewer degrees of freedom than its
section, such as an identification that ignored the sway. :func:`write_derivative_table`
writes ``windrig identify --table OUT.csv``: the identified model's derivatives with their
standard deviations (``H1_std``, ...) at the reduced velocities the user chose
(:func:`parse_reduced_velocities`, ``--reduced-velocities 2:20:0.5``) or, by default,
:data:`FILE_ROWS` spanning the releases' own.

Not responsible for: identifying the model (:mod:`ident.identification.e2rfc`) or the command line
(:mod:`daq.offline.flutter_commands`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from daq.errors import UsageError
from ident.errors import IdentError
from ident.model.conventions import derivative_names
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel

__all__ = ["FILE_ROWS", "TABLE_POINTS", "check_model_dof", "derivative_rows",
           "format_derivative_table", "parse_reduced_velocities", "write_derivative_table"]

#: Reduced frequencies printed, evenly spread over the span the releases cover.
TABLE_POINTS = 5
#: Rows of ``--table`` by default: reduced velocities evenly spaced over the releases' span.
FILE_ROWS = 25
#: Most rows ``--reduced-velocities`` may ask for (a typo such as a step of 0.0005).
MAX_ROWS = 10_000


def derivative_rows(model: RationalFunctionModel,
                    K_span: npt.ArrayLike) -> tuple[npt.NDArray[np.float64], dict[str, Any]]:
    """Return the printed reduced frequencies and each derivative's values there.

    Parameters
    ----------
    model : RationalFunctionModel
        2 or 3 degrees of freedom.
    K_span : array_like
        Reduced frequencies ``B omega / U`` the releases cover (their minimum and maximum
        bound the table).

    Returns
    -------
    K : ndarray, shape (TABLE_POINTS,)
    values : dict of str to ndarray
        ``derivative_names(model.n_dof)`` in order, each of shape ``K.shape``.
    """
    span = np.asarray(K_span, dtype=float)
    K = np.linspace(float(np.min(span)), float(np.max(span)), TABLE_POINTS)
    derivatives = model.flutter_derivatives(K)
    return K, {name: np.asarray(derivatives[name], dtype=float)
               for name in derivative_names(model.n_dof)}


def format_derivative_table(model: RationalFunctionModel, K_span: npt.ArrayLike) -> list[str]:
    """Return the table's lines: a header of K and 1/K, then one line per derivative.

    Examples
    --------
    >>> from ident.model.flat_plate import jones_model
    >>> lines = format_derivative_table(jones_model(), [0.5, 1.0])
    >>> len(lines), lines[2].split()[0]
    (10, 'H1*')
    """
    K, values = derivative_rows(model, K_span)
    lines = ["flutter derivatives (Scanlan's signs, docs/reference/conventions.md):",
             f"{'K':>8}" + "".join(f"{k:>11.4f}" for k in K)]
    lines[1] += "   (1/K " + ", ".join(f"{1.0 / k:.3g}" for k in K) + ")"
    lines.extend(f"{name + '*':>8}" + "".join(f"{v:>11.4g}" for v in column)
                 for name, column in values.items())
    return lines


def check_model_dof(model: RationalFunctionModel, section: SectionModel) -> None:
    """Raise IdentError when the model has fewer degrees of freedom than the section.

    A 2-DOF model of a section with sway (``fp``) leaves out the drag and the sway forces: its
    flutter speed would be that of another structure.
    """
    if model.n_dof != section.n_dof:
        raise IdentError(
            f"the identified model has {model.n_dof} degrees of freedom, the section "
            f"{section.n_dof} (fp = {section.fp} Hz): E2RFC did not identify the sway and drag "
            "terms; a 3-DOF campaign needs E2RFC in 3x3")


def parse_reduced_velocities(text: str) -> npt.NDArray[np.float64]:
    """Return the reduced velocities ``U / (f B)`` of ``--reduced-velocities START:STOP:STEP``.

    ``STOP`` is included when the steps reach it (within a millionth of a step).

    Raises
    ------
    UsageError
        Not three numbers, a start that is not > 0, a stop not above the start, a step that is
        not > 0, or more than :data:`MAX_ROWS` rows.

    Examples
    --------
    >>> parse_reduced_velocities("2:4:0.5").tolist()
    [2.0, 2.5, 3.0, 3.5, 4.0]
    """
    parts = text.split(":")
    try:
        start, stop, step = (float(p) for p in parts)
    except ValueError:
        raise UsageError(f"--reduced-velocities {text!r}: expected START:STOP:STEP, three "
                         "numbers (U/(f B), e.g. 2:20:0.5)") from None
    if not (math.isfinite(start) and math.isfinite(stop) and math.isfinite(step)):
        raise UsageError(f"--reduced-velocities {text!r}: every number must be finite")
    if start <= 0.0 or stop <= start or step <= 0.0:
        raise UsageError(f"--reduced-velocities {text!r}: need 0 < START < STOP and STEP > 0")
    count = int(math.floor((stop - start) / step + 1e-6)) + 1
    if count > MAX_ROWS:
        raise UsageError(f"--reduced-velocities {text!r}: {count} rows, at most {MAX_ROWS}")
    return start + step * np.arange(count, dtype=float)


def write_derivative_table(model: Any, path: Path, K_span: npt.ArrayLike,
                           reduced_velocities: npt.ArrayLike | None = None) -> list[str]:
    """Write an identified model's flutter derivatives and their std as a CSV table.

    Parameters
    ----------
    model : IdentifiedModel
        An E2RFC model (its ``flutter_derivative_std``: parameter covariance, release
        jackknife, structures within one SE, one lag more).
    path : Path
        The CSV to write (:meth:`ident.tables.fd_table.FlutterDerivativeTable.to_csv`: ``K``,
        the derivatives, then ``H1_std``...).
    K_span : array_like
        Reduced frequencies ``B omega / U`` the releases cover.
    reduced_velocities : array_like, optional
        The rows' ``U / (f B) = 2 pi / K``; default :data:`FILE_ROWS` evenly spaced over
        ``K_span``.

    Returns
    -------
    list of str
        Warnings: rows outside the releases' span (the model extrapolated there, its std
        understated).

    Raises
    ------
    UsageError
        The file cannot be written.
    """
    from ident.tables.fd_table import FlutterDerivativeTable

    span = np.asarray(K_span, dtype=float)
    low, high = 2 * math.pi / float(np.max(span)), 2 * math.pi / float(np.min(span))
    Ur = (np.linspace(low, high, FILE_ROWS) if reduced_velocities is None
          else np.asarray(reduced_velocities, dtype=float))
    table = FlutterDerivativeTable.from_model(model, 2 * math.pi / Ur, source=str(path),
                                              with_std=True)
    try:
        table.to_csv(path)
    except OSError as exc:
        raise UsageError(f"{path}: cannot write the table: {exc.strerror or exc}") from exc
    outside = Ur[(Ur < low * (1 - 1e-9)) | (Ur > high * (1 + 1e-9))]
    if outside.size == 0:
        return []
    return [f"{path}: {outside.size} of {Ur.size} rows lie outside the reduced velocities the "
            f"releases cover ({low:.3g} to {high:.3g}, widened 20 %), e.g. U/(f B) = "
            f"{float(outside[0]):.3g}: there the model is extrapolated and its std understated"]


def table_std_report(table: Any) -> tuple[str | None, dict[str, Any]]:
    """Return a line on a read table's std columns and the JSON keys that carry them.

    ``windrig flutter --table`` and ``windrig bridge --aero`` analyse a table's values; its
    std (``H1_std``...) is carried into their JSON as ``table_std`` (name to one value per
    row of ``table_K``) and summed up in the line, with the largest std relative to the
    derivative's own largest magnitude.

    Returns
    -------
    line : str or None
        None for a table without std columns.
    keys : dict
        ``{"table_std": {...}}`` (empty without std columns).
    """
    std = dict(table.std)
    if not std:
        return None, {}
    relative = {name: float(np.max(column)) / max(float(np.max(np.abs(table.values[name]))),
                                                  1e-300)
                for name, column in std.items()}
    worst = max(relative, key=relative.__getitem__)
    line = (f"{table.source or 'the table'} gives the std of {len(std)} derivative(s) "
            f"({', '.join(std)}); the largest, {worst}*'s, is {100 * relative[worst]:.3g} % of "
            "its largest magnitude (the analysis uses the values)")
    return line, {"table_std": {name: column.tolist() for name, column in std.items()}}
