"""Checks of a flutter-derivative table against its own trends and the usual physics.

A table from outside (published, digitised, measured) can be wrong in ways the flutter analysis
cannot see: a sign typed wrong at one row, a column shifted by a constant, a few rows far apart,
columns left out. :func:`check_table` reads a :class:`~ident.tables.fd_table.FlutterDerivativeTable`
and returns one warning string per finding, each naming the table's file (when known), the
column (``A2*``), the row (1-based, with its K and Ur) and the value. It changes nothing and
refuses nothing: the caller prints the warnings and records them in its JSON.

The checks, and why each can be trusted:

- **One row against its neighbours** (:func:`_outliers`). Every row of a column is predicted from
  up to four neighbouring rows (a quadratic in ``log K``, least squares, the row itself left out;
  a straight line from three rows at the table's ends).
  A value is flagged when its residual is both many robust standard deviations of the column's
  residuals out (the median absolute residual, each residual scaled by the noise gain of its own
  prediction) and a large part of the predicted value (half of it, or of a tenth of the column's
  largest magnitude where the column crosses zero): a one-row sign typo leaves a residual of twice
  the value. A real table's noise of a few per cent does neither. In a sparse table the rows are
  too far apart for a trend: there only a value whose sign differs from both neighbours, while
  they agree and are of its size, is flagged.
- **Damping that does not vanish in still air** (:func:`_shifted_damping`). The direct damping
  derivatives H1*, A2*, P1* are aerodynamic damping; as the reduced velocity goes to zero (K
  large) the air is still relative to the motion and gives none, and a rational (Roger) model
  has ``K X* -> constant``, i.e. ``X* ~ a / K``. The table's rows at its largest K (from a
  third of the largest, which must reach K = 2, Ur = 3.1) are fitted with
  ``X* = a / K + b / K^2 + s`` (the ``b`` term takes up the approach; on the flat plate and the
  shipped deck it leaves ``|s|`` below 0.15 of the decaying part); an ``s`` above a quarter of
  the decaying part, and four standard errors clear of zero, is a column shifted by a constant.
- **Signs against the inter-relations** of Scanlan, Jones and Singh (1997), checked on the exact
  flat plate (:func:`ident.model.flat_plate.flutter_derivatives`, K = B omega / U, B the full
  width) before use: ``H1* ~ K H3*`` (within 10 % over K 0.2 to 3.2) and ``A1* ~ K A3*`` (ratio
  0.6 to 1) hold in windrig's signs, also on the shipped bluff deck (ratios 0.9 to 1 and 0.25 to
  0.5); ``H4* ~ -K H2*`` and ``A4* ~ -K A2*`` do not hold on the bluff deck, not even in sign, and
  are not used. Only the signs are compared, on rows where both sides are clearly non-zero: a
  column whose sign is the opposite over most of them contradicts the other column (lift or
  heave positive upward, i.e. the ``z_up`` convention read as Scanlan's, flips exactly H3* and A1*).
- **The size of H1* against K H3*** (:func:`_relation_scale`): on the rows where both are
  clearly non-zero the median of ``|H1*| / |K H3*|`` is 0.90 to 1.0 on the exact flat plate
  (K 0.1 to 4) and on the shipped bluff deck (quasi-steady, ``H1* = -(dC_L + C_D) / K`` against
  ``H3* = -dC_L / K^2``, with a deck's drag a small part of its lift slope). A first column
  that is not ``B omega / U`` moves it by the column's factor, and pitch derivatives per degree
  by 180 / pi, so a median outside :data:`_SCALE_RANGE` is reported, with the slip its size
  matches: K on the half-width ``b = B / 2`` (2), ``f B / U`` with f in Hz (2 pi), ``H2* H3*
  A2* A3*`` per degree (57.3), K twice windrig's (1/2). A common factor on every derivative
  (2 pi) leaves it alone and is not seen.
- **A reduced velocity headed K** (:func:`_reduced_velocity_as_k`). Against K the derivatives
  that quasi-steady aerodynamics dominates fall as ``1 / K`` (H1*, A1*) and ``1 / K^2`` (H3*,
  A3*): fitted as powers of K over the table, -1.1 to -1.2 and -1.8 to -2.2 on the exact flat
  plate and the shipped bluff deck, over K 0.2-3 and over any third of it. A first column of
  ``Ur = 2 pi / K`` headed ``K`` turns each power's sign; a table whose given ones (two or more)
  all grow faster than ``K^0.5``, over a span of two or more in K, is reported.
- **Sparse tables**: fewer than :data:`SPARSE_ROWS` rows, so most of the curve the flutter
  analysis uses lies between rows.
- **Missing columns**, filled with zero by the reader, named with what they govern.
- **Scatter**: the median relative scatter about the local fits, reported when it exceeds
  :data:`NOISE_REPORTED` (a measured table's noise).

:func:`check_flutter_range` says when a flutter or divergence reduced frequency found by an
analysis lies outside the table (the table stops short of it).

Not responsible for: reading tables (:mod:`ident.tables.fd_table`), fitting them
(:mod:`ident.tables.roger_table`).

References
----------
R. H. Scanlan, N. P. Jones, L. Singh, "Inter-relations among flutter derivatives", J. Wind Eng.
Ind. Aerodyn. 69-71 (1997) 829-837.
"""

from __future__ import annotations

import math
import os

import numpy as np
import numpy.typing as npt

from ident.tables.fd_table import FlutterDerivativeTable, _read_rows

__all__ = ["NOISE_REPORTED", "SPARSE_ROWS", "GOVERNS", "check_flutter_range", "check_table"]

FloatArray = npt.NDArray[np.float64]

#: A table with fewer rows than this is sparse.
SPARSE_ROWS = 10
#: Relative scatter about the local fits above which it is reported (1-2 % is a good table).
NOISE_REPORTED = 0.03
#: What each derivative governs (the message of a column filled with zero).
GOVERNS: dict[str, str] = {
    "H1": "heave aerodynamic damping (vertical galloping)",
    "H2": "lift from pitch velocity (coupled flutter)",
    "H3": "lift from pitch (coupled flutter)",
    "H4": "heave aerodynamic stiffness (heave frequency in wind)",
    "H5": "lift from sway velocity",
    "H6": "lift from sway",
    "A1": "moment from heave velocity (coupled flutter)",
    "A2": "torsional aerodynamic damping (torsional flutter)",
    "A3": "torsional aerodynamic stiffness (torsional divergence, torsion frequency in wind)",
    "A4": "moment from heave (coupling)",
    "A5": "moment from sway velocity",
    "A6": "moment from sway",
    "P1": "sway aerodynamic damping",
    "P2": "drag from pitch velocity",
    "P3": "drag from pitch (the drag slope)",
    "P4": "sway aerodynamic stiffness",
    "P5": "drag from heave velocity",
    "P6": "drag from heave",
}

# One row against its neighbours: robust standard deviations out, and part of the value.
_Z_OUTLIER = 8.0
_REL_OUTLIER = 0.5
_REL_EDGE = 1.0
# Where a column crosses zero, a residual is compared with this part of its largest magnitude.
_FLOOR = 0.1
# Damping that does not vanish: rows used (K from K_max / _TOP_SPAN), the smallest K_max that
# reaches towards still air (Ur = 2 pi / K <= 3.1: a bluff deck's table that stops at K = 1.26,
# Ur = 5, is still in its transition there, A2* changing sign among the last rows), and the
# share of the column that is a shift.
_TOP_SPAN = 3.0
_TOP_K = 2.0
_SHIFT_SHARE = 0.25
_DAMPING = ("H1", "A2", "P1")
# Inter-relations used at the level of signs: (column, other column) with X ~ K Y.
_RELATIONS = (("H1", "H3"), ("A1", "A3"))
# Derivatives that fall as a power of K (quasi-steady), the power a reduced velocity headed K
# turns positive, and the span in K the fit needs.
_FALLING = ("H1", "H3", "A1", "A3")
_RISING_POWER = 0.5
_POWER_SPAN = 2.0
#: Median ``|H1*| / |K H3*|`` outside which the table's K or pitch unit is doubted (0.90 to 1.0 on
#: the flat plate and the shipped bluff deck; a slip moves it by 2 or more).
_SCALE_RANGE = (0.62, 1.6)
#: Slips the median ``|H1*| / |K H3*|`` names: its range, and what to change.
_SCALE_SLIPS: tuple[tuple[float, float, str], ...] = (
    (0.38, 0.62, "the first column looks like twice K = B omega / U: halve it"),
    (1.6, 2.6, "the first column looks like a reduced frequency on the half-width, b omega / U "
               "with b = B/2 (Theodorsen's k): double it (windrig's K = B omega / U has the "
               "full width B)"),
    (4.5, 9.0, "the first column looks like f B / U with f in Hz: multiply it by 2 pi"),
    (30.0, 110.0, "the pitch derivatives (H2*, H3*, A2*, A3*) look given per degree: multiply "
                  "them by 180/pi = 57.3"),
)


def check_table(table: FlutterDerivativeTable, path: str | os.PathLike[str] | None = None
                ) -> list[str]:
    """Return warnings on a flutter-derivative table (see the module docstring); empty if none.

    Parameters
    ----------
    table : FlutterDerivativeTable
        The table, in windrig's signs.
    path : path-like, optional
        Its file (default: ``table.source``). With a readable CSV file, rows are numbered as in
        the file (1 = the first row below the header); otherwise by increasing K.

    Returns
    -------
    list of str
        One line per finding, e.g. ``"deck.csv: A2* at row 14 (K = 0.8976, Ur = 7): 0.3086 has
        the opposite sign of its neighbours' trend (about -0.31): a sign typo?"``.

    Examples
    --------
    >>> import numpy as np
    >>> from ident.model.flat_plate import flutter_derivatives
    >>> K = np.geomspace(0.3, 3.0, 30)
    >>> check_table(FlutterDerivativeTable(K, flutter_derivatives(K)))
    []
    """
    source = os.fspath(path) if path is not None else table.source
    where = f"{source}: " if source else ""
    rows = _row_numbers(table, source)
    out: list[str] = []
    if table.K.size < SPARSE_ROWS:
        out.append(f"{where}sparse: {table.K.size} rows (K {table.K[0]:.4g} to "
                   f"{table.K[-1]:.4g}): the fit between rows is an interpolation; "
                   f"{SPARSE_ROWS} or more rows over the flutter range are usual")
    if table.filled:
        named = "; ".join(f"{n}* governs {GOVERNS[n]}" for n in table.filled)
        out.append(f"{where}column(s) {', '.join(n + '*' for n in table.filled)} not in the "
                   f"table: taken as zero ({named})")
    given = [n for n in table.values if n not in table.filled and np.any(table.values[n])]
    scatter: list[float] = []
    noise: dict[str, float | None] = {}
    for name in given:
        found, level, noise[name] = _outliers(table, name, rows)
        out.extend(where + text for text in found)
        if level is not None:
            scatter.append(level)
    headed_k = _reduced_velocity_as_k(table, given)
    out.extend(where + text for text in headed_k)
    # Headed K, a table's damping does not vanish at large "K": the same cause, not a shift.
    shifts = [] if headed_k else [name for name in _DAMPING if name in given]
    for name in shifts:
        out.extend(where + text for text in _shifted_damping(table, name, noise[name]))
    for x_name, y_name in _RELATIONS:
        if x_name in given and y_name in given:
            out.extend(where + text for text in _relation_signs(table, x_name, y_name, rows))
    if not headed_k and "H1" in given and "H3" in given:
        out.extend(where + text for text in _relation_scale(table))
    if scatter and table.K.size >= SPARSE_ROWS:
        level = float(np.median(scatter))
        if level > NOISE_REPORTED:
            out.append(f"{where}the derivatives scatter about smooth curves by about "
                       f"{100 * level:.0f} % (median over the columns): a noisy table; the fit "
                       "smooths it, single rows are not to be trusted")
    return out


def check_flutter_range(table: FlutterDerivativeTable, K: float | None, what: str = "flutter",
                        path: str | os.PathLike[str] | None = None) -> list[str]:
    """Return a warning if the reduced frequency ``K`` of an analysis lies outside the table.

    Parameters
    ----------
    table : FlutterDerivativeTable
    K : float or None
        The reduced frequency (``B omega / U``) at flutter (or divergence: ``K -> 0``); None
        (nothing found) gives no warning.
    what : str
        What was found there (``"flutter"``, ``"divergence"``), for the message.
    path : path-like, optional
        The table's file (default: ``table.source``).

    Examples
    --------
    >>> zero = {n: [0.0] * 3 for n in ("H1", "H2", "H3", "H4", "A1", "A2", "A3", "A4")}
    >>> t = FlutterDerivativeTable([0.8, 1.6, 3.2], zero)
    >>> print(check_flutter_range(t, 0.45)[0])
    flutter at K = 0.45 (Ur = 13.96) lies outside the table (K 0.8 to 3.2, Ur 1.963 to 7.854):
    the table stops short of it, the result rests on an extrapolation
    """
    if K is None:
        return []
    low, high = float(table.K[0]), float(table.K[-1])
    if low <= K <= high:
        return []
    source = os.fspath(path) if path is not None else table.source
    where = f"{source}: " if source else ""
    ur = f"Ur = {2 * math.pi / K:.4g}" if K > 0 else "Ur infinite"
    return [f"{where}{what} at K = {K:.4g} ({ur}) lies outside the table (K {low:.4g} to "
            f"{high:.4g}, Ur {2 * math.pi / high:.4g} to {2 * math.pi / low:.4g}): the table "
            "stops short of it, the result rests on an extrapolation"]


def _row_numbers(table: FlutterDerivativeTable, source: str) -> list[int]:
    """1-based row of each of the table's K (sorted increasing) in its file, else in K order."""
    order = list(range(1, table.K.size + 1))
    if not source or not os.path.isfile(source):
        return order
    try:
        header, rows = _read_rows(source)
    except ValueError:
        return order  # not the file this table came from: number rows by K
    first = np.array([r[0] for r in rows], dtype=float)
    if len(rows) != table.K.size or not header or np.any(first <= 0.0):
        return order
    K_file = 2 * math.pi / first if header[0].strip().upper() == "UR" else first
    numbers = []
    for K in table.K:
        match = np.flatnonzero(np.isclose(K_file, K, rtol=1e-12, atol=0.0))
        if match.size != 1:
            return order
        numbers.append(int(match[0]) + 1)
    return numbers


def _label(table: FlutterDerivativeTable, i: int, rows: list[int]) -> str:
    K = float(table.K[i])
    return f"row {rows[i]} (K = {K:.4g}, Ur = {2 * math.pi / K:.4g})"


def _neighbours(i: int, usable: list[int]) -> list[int]:
    """Up to two usable rows each side of row ``i``, topped up on the other side to four."""
    before = [j for j in usable if j < i]
    after = [j for j in usable if j > i]
    take_before = min(len(before), max(2, 4 - len(after)))
    take_after = min(len(after), 4 - take_before)
    return before[len(before) - take_before:] + after[:take_after]


def _loo_predictions(x: FloatArray, y: FloatArray,
                     excluded: set[int]) -> tuple[FloatArray, FloatArray]:
    """Leave-one-out predictions of ``y`` from its neighbours, and each one's noise gain.

    A quadratic in ``x`` between rows, a straight line beyond the first and the last usable row
    (a quadratic extrapolated a step amplifies the neighbours' noise several times). Rows in
    ``excluded`` (already found wrong) predict nothing. The gain is ``sqrt(1 + |w|^2)`` with
    ``w`` the prediction's weights on the neighbours: the standard deviation of the residual in
    units of one row's noise.
    """
    n = x.size
    usable = [j for j in range(n) if j not in excluded]
    pred = np.empty(n)
    gain = np.empty(n)
    for i in range(n):
        near = _neighbours(i, [j for j in usable if j != i])
        if near[0] > i or near[-1] < i:
            near = near[:3] if near[0] > i else near[-3:]
            degree = 1
        else:
            degree = 2
        # Centred on the row, so the prediction is the fit's constant term.
        V = np.vander(x[near] - x[i], degree + 1, increasing=True)
        weights = np.linalg.pinv(V)[0]
        pred[i] = weights @ y[near]
        gain[i] = math.sqrt(1.0 + float(weights @ weights))
    return pred, gain


def _outliers(table: FlutterDerivativeTable, name: str,
              rows: list[int]) -> tuple[list[str], float | None, float | None]:
    """Rows of one column far off their neighbours' trend.

    Returns the findings, the column's relative scatter about its local fits and its absolute
    robust noise (one row's standard deviation), both None when the table is sparse. The worst
    row is found first and left out of its neighbours' predictions before the next is looked
    for, so that one typo does not make its neighbours look wrong too.
    """
    y = np.asarray(table.values[name], dtype=float)
    n = y.size
    if n < SPARSE_ROWS:
        return _sign_flips(table, name, rows), None, None
    x = np.log(table.K)
    floor = _FLOOR * float(np.max(np.abs(y)))
    # The first and the last row are extrapolated from one side, less surely: there a finding
    # must be as large as the value (a sign typo leaves twice the value).
    share = np.full(n, _REL_OUTLIER)
    share[[0, -1]] = _REL_EDGE
    found: list[tuple[int, float, float, float]] = []
    excluded: set[int] = set()
    while len(excluded) < n // 4:
        pred, gain = _loo_predictions(x, y, excluded)
        resid = y - pred
        scale = np.maximum(np.abs(pred), floor)
        # Two standardisations: absolute (a column's noise is often of one size) and relative
        # to the value (often a share of it); a finding must stand out in both, and be a large
        # part of the value, so that neither noise model raises a false alarm.
        z = resid / gain
        z_rel = z / scale
        keep = np.array([i not in excluded for i in range(n)])
        sigma = 1.4826 * float(np.median(np.abs(z[keep])))
        sigma_rel = 1.4826 * float(np.median(np.abs(z_rel[keep])))
        candidates = [i for i in range(n) if keep[i]
                      and abs(z[i]) > _Z_OUTLIER * sigma
                      and abs(z_rel[i]) > _Z_OUTLIER * sigma_rel
                      and abs(resid[i]) > share[i] * scale[i]]
        if not candidates:
            break
        # The worst is the largest residual against the larger of value and prediction: a
        # typo's own row scores 2 (a sign) or nearly 1 (a gross value), a neighbour whose
        # prediction the typo pulled scores less.
        worst = max(candidates, key=lambda i: abs(resid[i]) / max(scale[i], abs(y[i])))
        excluded.add(worst)
        found.append((worst, float(pred[worst]), abs(float(z[worst])) / max(sigma, 1e-300),
                      sigma))
    out = []
    for i, expected, n_sigma, _ in sorted(found):
        label = _label(table, i, rows)
        if np.sign(y[i]) == -np.sign(expected) and abs(y[i] + expected) < 0.5 * abs(expected):
            kind, hint = "has the opposite sign of its neighbours' trend", "a sign typo?"
        else:
            kind, hint = "lies far off its neighbours' trend", "a typo or an outlier?"
        out.append(f"{name}* at {label}: {y[i]:.4g} {kind} (about {expected:.4g}, "
                   f"{n_sigma:.0f} robust standard deviations out): {hint}")
    keep = np.array([i not in excluded for i in range(n)])
    return (out, 1.4826 * float(np.median(np.abs(z_rel[keep]))),
            1.4826 * float(np.median(np.abs(z[keep]))))


def _sign_flips(table: FlutterDerivativeTable, name: str, rows: list[int]) -> list[str]:
    """Find a sparse table's rows whose sign differs from both neighbours while they agree.

    Rows far apart give no local trend to trust beyond the signs; a value is flagged only when
    it is of the neighbours' size (a real zero crossing between two rows is small there) and
    not lost in the column's smallest values.
    """
    y = np.asarray(table.values[name], dtype=float)
    floor = _FLOOR * float(np.max(np.abs(y)))
    out = []
    for i in range(1, y.size - 1):
        left, right = y[i - 1], y[i + 1]
        if (np.sign(left) == np.sign(right) != np.sign(y[i]) and abs(y[i]) > floor
                and abs(y[i]) > 0.5 * min(abs(left), abs(right))):
            out.append(f"{name}* at {_label(table, i, rows)}: {y[i]:.4g} has the opposite sign "
                       f"of both neighbours ({left:.4g}, {right:.4g}): a sign typo?")
    return out


def _reduced_velocity_as_k(table: FlutterDerivativeTable, given: list[str]) -> list[str]:
    """Return a finding when the quasi-steady derivatives grow with K as they do with Ur."""
    K = table.K
    if K[-1] / K[0] < _POWER_SPAN:
        return []
    powers = {}
    for name in _FALLING:
        magnitude = np.abs(table.values[name]) if name in given else np.zeros(0)
        ok = magnitude > 0.0
        if ok.sum() >= 3:
            powers[name] = float(np.polyfit(np.log(K[ok]), np.log(magnitude[ok]), 1)[0])
    if len(powers) < 2 or min(powers.values()) <= _RISING_POWER:
        return []
    grows = ", ".join(f"{n}* as K^{p:.2g}" for n, p in powers.items())
    return [f"the first column looks like the reduced velocity Ur = U / (f B), not K = B omega "
            f"/ U: {grows}, where against K they fall as 1/K (H1*, A1*) and 1/K^2 (H3*, A3*); "
            f"head it Ur (its {K[0]:.4g} to {K[-1]:.4g} are K {2 * math.pi / K[-1]:.4g} to "
            f"{2 * math.pi / K[0]:.4g}), or every result from this table is wrong"]


def _shifted_damping(table: FlutterDerivativeTable, name: str,
                     noise: float | None) -> list[str]:
    """Find a direct damping derivative that tends to a constant, not zero, as K grows.

    ``noise`` is one row's standard deviation (:func:`_outliers`): the shift must also stand
    four of its own standard errors clear of zero, so that a noisy table's last rows do not
    make one.
    """
    K = table.K
    if K[-1] < _TOP_K:
        return []  # the table does not reach towards still air: nothing to say
    top = K >= K[-1] / _TOP_SPAN
    if np.count_nonzero(top) < 5:
        return []  # three coefficients need a few rows more to be checked by the others
    y = np.asarray(table.values[name], dtype=float)[top]
    K_top = K[top]
    design = np.column_stack([1.0 / K_top, 1.0 / K_top**2, np.ones(K_top.size)])
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    s = float(coef[2])
    size = float(np.max(np.abs(y - s)))  # the part that decays towards still air
    error = (noise or 0.0) * math.sqrt(float(np.linalg.inv(design.T @ design)[2, 2]))
    if abs(s) <= _SHIFT_SHARE * size or abs(s) <= 4.0 * error:
        return []
    return [f"{name}* tends to {s:+.3g}, not to zero, towards still air (rows K {K_top[0]:.3g} "
            f"to {K_top[-1]:.3g}, where it is {y[0]:.4g} to {y[-1]:.4g}, fitted with a/K + b/K^2 "
            "+ s): a damping derivative vanishes as the reduced velocity goes to zero (still "
            f"air gives no aerodynamic damping); the column shifted by about {s:+.3g}?"]


def _related(x_name: str, y_name: str, table: FlutterDerivativeTable
             ) -> tuple[FloatArray, FloatArray, npt.NDArray[np.bool_]] | None:
    """Return ``X*``, ``K Y*`` and the rows where both are clearly non-zero (None: under 3).

    The inter-relations ``X* ~ K Y*`` (Scanlan, Jones and Singh 1997) are judged on those rows
    only: near a zero crossing either side's sign and size are noise.
    """
    x = np.asarray(table.values[x_name], dtype=float)
    y = np.asarray(table.K * table.values[y_name], dtype=float)
    clear = (np.abs(x) > _FLOOR * np.max(np.abs(x))) & (np.abs(y) > _FLOOR * np.max(np.abs(y)))
    return (x, y, clear) if np.count_nonzero(clear) >= 3 else None


def _relation_scale(table: FlutterDerivativeTable) -> list[str]:
    """``|H1*| ~ |K H3*|`` in size: a K column or a pitch unit off by a factor.

    Parameters
    ----------
    table : FlutterDerivativeTable
        The table, in windrig's signs (the sizes do not depend on them).

    Returns
    -------
    list of str
        Empty, or one line with the median ratio and the slip it matches, if one.
    """
    pair = _related("H1", "H3", table)
    if pair is None:
        return []
    x, y, clear = pair
    ratio = float(np.median(np.abs(x[clear] / y[clear])))
    if _SCALE_RANGE[0] <= ratio <= _SCALE_RANGE[1]:
        return []
    causes = [text for low, high, text in _SCALE_SLIPS if low <= ratio <= high]
    cause = (causes[0] if causes else "a first column other than K = B omega / U, or H1* or H3* "
             "scaled by a factor?")
    return [f"|H1*| is {ratio:.3g} times |K H3*| (median over {np.count_nonzero(clear)} rows), "
            "where they are about equal (0.9 to 1 on the flat plate and the shipped bluff deck; "
            f"Scanlan, Jones and Singh 1997): {cause}; unless this deck's lift slope is small "
            "against its drag, every result from this table is wrong"]


def _relation_signs(table: FlutterDerivativeTable, x_name: str, y_name: str,
                    rows: list[int]) -> list[str]:
    """``X* ~ K Y*`` in sign on most rows where both are clearly non-zero."""
    pair = _related(x_name, y_name, table)
    if pair is None:
        return []
    x, y, clear = pair
    against = clear & (np.sign(x) != np.sign(y))
    if np.count_nonzero(against) <= np.count_nonzero(clear) / 2:
        return []
    idx = np.flatnonzero(against)
    i = int(idx[0])
    n_clear = np.count_nonzero(clear)
    return [f"{x_name}* and {y_name}* have opposite signs on {idx.size} of {n_clear} rows"
            f" (e.g. {_label(table, i, rows)}: {x_name}* = {x[i]:.4g}, K {y_name}* = "
            f"{y[i]:.4g}), where {x_name}* ~ K {y_name}* (Scanlan, Jones and Singh 1997): one "
            "of the columns in the other sign (lift or heave positive upward: convention z_up)?"]
