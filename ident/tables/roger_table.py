"""Roger fit of a flutter-derivative table with its structure chosen by evidence.

A table of ``Q(iK)`` samples (from :class:`ident.tables.fd_table.FlutterDerivativeTable`, 2 or 3
degrees of freedom, or from the decay route of :mod:`ident.identification.fd_method`, whose columns
are known at different K) is fitted with Roger's rational function: for fixed lag roots each entry
is a linear least-squares problem (:func:`ident.model.roger.roger_fit`); the shared lag roots are
searched by variable projection over ``log d``, and the structure (0 to 3 lags, with or without the
added-mass matrix ``A3``) is chosen by held-out error, leaving out one table row at a time, with
the one-standard-error rule (:mod:`ident.numerics.selection`).

**Accuracy where flutter lives.** Held-out error alone may choose few lags for a noisy or
irregular table and leave one force tens of percent off at some K, enough to move a flutter
speed anywhere. :func:`fit_table` therefore also requires every force's flutter derivatives
within :data:`ACCURACY` (2 %) of that force's size at every tabulated K: when the held-out choice
misses it, the structures up to :data:`MAX_LAGS` lags are tried and the simplest that reaches it
is used; when none does, the held-out choice stays and :attr:`TableFit.meets_accuracy` is False
(the commands then warn, and rest on the frequency-domain route).

**Weighting.** An unweighted fit of ``Q`` is ruled by the high reduced frequencies, where
``Q ~ K^2`` is large, and may miss the low ones, where a deck flutters, by tens of percent; a
flutter speed can move by several percent. :func:`fit_table` therefore weighs, by default
(``weighting="relative"``), every row of ``Q`` at every tabulated K by the inverse of that force
row's largest entry there: each force's relative error counts alike at every reduced velocity.
``weighting="entry_rms"`` scales each entry by its RMS over the table (the decay route's choice,
where each column is known at its own K and noise, not the K^2 growth, dominates).

Not responsible for: reading tables (:mod:`ident.tables.fd_table`), flutter derivatives from decays
(:mod:`ident.identification.fd_method`).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from ident.errors import RankDeficiencyError
from ident.model.conventions import Q_from_flutter_derivatives, derivative_layout
from ident.model.rfc import RationalFunctionModel
from ident.model.roger import fit_entries, roger_basis
from ident.numerics.selection import Candidate, select_one_se
from ident.tables.fd_table import FlutterDerivativeTable

__all__ = ["ACCURACY", "MAX_LAGS", "RogerProblem", "TableFit", "WEIGHTINGS", "fit_table",
           "select_structure"]

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]

#: Weightings :func:`fit_table` offers (see the module docstring).
WEIGHTINGS: tuple[str, ...] = ("relative", "entry_rms")

#: Largest error of a flutter derivative, relative to its force's size at that K, a table fit
#: must reach to be used without a caveat. A flutter speed moves by about as much as the
#: damping derivatives near the flutter K do: 2 % keeps the routes within a percent or so.
ACCURACY = 0.02

#: Most lags :func:`fit_table` tries when the held-out choice misses :data:`ACCURACY`.
MAX_LAGS = 6


class RogerProblem:
    """Roger fit of ``Q`` samples, each column at its own K, for any structure.

    Parameters
    ----------
    K : ndarray, shape (n, k, k)
        Reduced frequency of each sample; the entries of one column share theirs (k = 2 or 3).
    Q : ndarray, shape (n, k, k), complex
        ``Q(iK)`` samples.
    weights : ndarray, shape (n, k, k), optional
        Weight of each sample's residual (its inverse scale). Default: each entry scaled by the
        inverse of its RMS over the table, so that the shared lag roots and the held-out score
        weigh the entries alike whatever their size; the scale does not change an entry's own
        linear solution, only how the entries share the lag roots.
    max_condition : float
        Largest condition number of an entry's column-scaled design accepted as determined.
    row_name : str
        What a row of the table is, for messages (e.g. ``"wind speeds"``).
    """

    def __init__(self, K: FloatArray, Q: ComplexArray, weights: FloatArray | None = None,
                 max_condition: float = 1e4, row_name: str = "rows") -> None:
        self.row_name = row_name
        self.K = K
        self.Q = Q
        if weights is None:
            scale = np.sqrt(np.mean(np.abs(Q) ** 2, axis=0))
            weights = np.broadcast_to(1.0 / np.where(scale > 0.0, scale, 1.0), Q.shape)
        self.weights = np.asarray(weights, dtype=float)
        self.n_rows = K.shape[0]
        self.n_dof = Q.shape[-1]
        self.max_condition = max_condition

    def fit(self, d: FloatArray, with_A3: bool, rows: Any = slice(None), *,
            check_rank: bool = True) -> RationalFunctionModel:
        """Return the coefficients for fixed lag roots, fitted on some rows of the table."""
        return fit_entries(self.K[rows], self.Q[rows], d, with_A3, self.weights[rows] ** 2,
                            check_rank=check_rank)

    def residual(self, model: RationalFunctionModel, rows: Any = slice(None)) -> ComplexArray:
        """Return the weighted residual ``w (Q_model - Q)``, shape (n_rows, k, k), complex."""
        K = self.K[rows]
        Q_model = np.empty(K.shape, dtype=complex)
        for j in range(self.n_dof):  # the entries of a column share their K
            Q_model[:, :, j] = model.Q(1j * K[:, 0, j])[:, :, j]
        return np.asarray((Q_model - self.Q[rows]) * self.weights[rows], dtype=complex)

    def relative_residual(self, model: RationalFunctionModel) -> FloatArray:
        """Return the RMS weighted residual per entry, shape (k, k)."""
        return np.asarray(np.sqrt(np.mean(np.abs(self.residual(model)) ** 2, axis=0)),
                          dtype=float)

    def condition(self, d: FloatArray, with_A3: bool) -> float:
        """Return the largest condition number of an entry's column-scaled real design."""
        keep = [0, 1] + ([2] if with_A3 else []) + list(range(3, 3 + d.size))
        worst = 0.0
        for j in range(self.n_dof):
            basis = roger_basis(self.K[:, 0, j], d, with_A3)[:, keep]
            design = np.vstack([basis.real, basis.imag])
            norms = np.linalg.norm(design, axis=0)
            if np.any(norms == 0.0):
                return math.inf
            worst = max(worst, float(np.linalg.cond(design / norms)))
        return worst

    def starts(self, n_lags: int, previous: FloatArray | None) -> list[FloatArray]:
        """Return start values of the lag-root search for ``n_lags`` lags.

        Three evenly spread sets over (and a little beyond) the reduced frequencies the table
        covers; with the roots found for one lag fewer, also those plus one new root at three
        places (nested starts, which usually converge fastest).
        """
        if n_lags == 0:
            return []
        K_lo, K_hi = float(self.K.min()), float(self.K.max())
        spread = np.geomspace(K_lo / 3.0, 3.0 * K_hi, n_lags + 2)[1:-1]
        out = [spread, spread * 0.3, spread * 3.0]
        if previous is not None and previous.size == n_lags - 1:
            new_roots = np.geomspace(K_lo / 3.0, 3.0 * K_hi, 3)
            out += [np.sort(np.append(previous, r)) for r in new_roots]
        return out

    def search(self, n_lags: int, with_A3: bool, starts: list[FloatArray]) -> FloatArray:
        """Return the lag roots by variable projection over ``log d`` (coefficients inside)."""
        if n_lags == 0:
            return np.zeros(0)
        K_lo, K_hi = float(self.K.min()), float(self.K.max())
        lo, hi = math.log(K_lo / 20.0), math.log(20.0 * K_hi)

        def residual(theta: FloatArray) -> FloatArray:
            model = self.fit(np.exp(theta), with_A3, check_rank=False)
            r = self.residual(model)
            return np.concatenate([r.real.ravel(), r.imag.ravel()])

        best = None
        for start in starts:
            theta0 = np.clip(np.log(start), lo + 1e-6, hi - 1e-6)
            sol = least_squares(residual, theta0, bounds=(lo, hi), xtol=1e-10, ftol=1e-12,
                                max_nfev=60 * (n_lags + 1))
            if best is None or sol.cost < best.cost:
                best = sol
        assert best is not None
        return np.sort(np.exp(best.x))

    def candidate(self, n_lags: int, with_A3: bool,
                  starts: list[FloatArray]) -> tuple[Candidate, FloatArray | None]:
        """Search the lag roots of one structure and score it by leave-one-row-out error."""
        per_entry = 2 + int(with_A3) + n_lags
        n_params = self.n_dof**2 * per_entry + n_lags

        def skipped(note: str, d: tuple[float, ...] = ()) -> tuple[Candidate, None]:
            return Candidate(n_lags, with_A3, d, math.inf, math.inf, n_params, note), None

        # Each row gives every entry one complex (two real) equations.
        if 2 * (self.n_rows - 1) < per_entry or 2 * self.n_dof**2 * self.n_rows < n_params:
            return skipped(f"too few {self.row_name} ({self.n_rows}) for {per_entry} "
                           "coefficients per entry with one held out")
        d = self.search(n_lags, with_A3, starts)
        roots = tuple(float(x) for x in d)
        if n_lags and np.min(np.diff(np.concatenate([[0.0], d]))) <= 1e-6 * d.max():
            return skipped("lag roots merged: fewer lags describe the table", roots)
        cond = self.condition(d, with_A3)
        if cond > self.max_condition:
            return skipped(f"ill-conditioned (condition number {cond:.2g})", roots)
        try:
            errors = self._cross_validate(d, with_A3)
        except RankDeficiencyError as err:
            return skipped(f"rank deficient: {err}", roots)
        return Candidate(n_lags, with_A3, roots, float(errors.mean()),
                         float(errors.std(ddof=1) / math.sqrt(errors.size)), n_params), d

    def _cross_validate(self, d: FloatArray, with_A3: bool) -> FloatArray:
        """Return the mean squared weighted error of each held-out row (lag roots fixed)."""
        errors = np.empty(self.n_rows)
        for k in range(self.n_rows):
            train = np.delete(np.arange(self.n_rows), k)
            model = self.fit(d, with_A3, train)
            errors[k] = float(np.mean(np.abs(self.residual(model, [k])) ** 2))
        return errors


def select_structure(problem: RogerProblem, n_lags: int | None = None,
                     with_A3: bool | None = None, *, max_lags: int = 3
                     ) -> tuple[RationalFunctionModel, Candidate, str, tuple[Candidate, ...]]:
    """Fit every structure asked for and choose one by held-out error (one-standard-error rule).

    Parameters
    ----------
    problem : RogerProblem
    n_lags : int, optional
        0 to ``max_lags``; None tries all.
    with_A3 : bool, optional
        None tries both.
    max_lags : int
        Most lags tried when ``n_lags`` is None.

    Returns
    -------
    model, chosen, reason, candidates
        The chosen structure's fit on every row, its candidate, why it was chosen, and every
        candidate tried.

    Raises
    ------
    RankDeficiencyError
        When no structure is determined by the table (each one's reason is listed).
    """
    lags = range(max_lags + 1) if n_lags is None else [n_lags]
    a3_options = (True, False) if with_A3 is None else (with_A3,)
    candidates: list[Candidate] = []
    previous: FloatArray | None = None  # lag roots of the best structure with one lag fewer
    for m in lags:
        starts = problem.starts(m, previous)
        found: list[tuple[Candidate, FloatArray]] = []
        for a3 in a3_options:
            candidate, d_found = problem.candidate(m, a3, starts)
            candidates.append(candidate)
            if d_found is not None:
                found.append((candidate, d_found))
                starts = [d_found, *starts]  # the other A3 option also tries these roots
        previous = min(found, key=lambda f: f[0].cv_error)[1] if found else None
    usable = [c for c in candidates if not c.note]
    if not usable:
        notes = "; ".join(f"n_lags={c.n_lags}, A3={c.with_A3}: {c.note}" for c in candidates)
        raise RankDeficiencyError(
            f"no Roger structure is determined by this flutter-derivative table ({notes})")
    chosen, reason = select_one_se(usable, given=n_lags is not None and with_A3 is not None)
    model = problem.fit(np.array(chosen.d), chosen.with_A3)
    return model, chosen, reason, tuple(candidates)


@dataclass(frozen=True, eq=False)
class TableFit:
    """A table's Roger fit and how well it holds at every tabulated reduced frequency.

    Attributes
    ----------
    model : RationalFunctionModel
        The fitted model (2 or 3 degrees of freedom, as the table).
    reason : str
        Why its structure was chosen.
    candidates : tuple of Candidate
        Every structure tried, with its held-out error.
    relative_error : ndarray, shape (n,)
        At each table row (increasing K), the largest error of a force row of ``Q`` relative to
        that row's largest entry there: what the weighting keeps small.
    derivative_error : mapping of str to ndarray, shape (n,)
        Each flutter derivative's error at each table row, relative to its force's size there
        (the largest modulus of that force's entries of ``Q/K^2``): a dimensionless fraction.
    table : FlutterDerivativeTable
        The table fitted.
    accuracy : float
        The error the fit had to reach (:data:`ACCURACY`).
    """

    model: RationalFunctionModel
    reason: str
    candidates: tuple[Candidate, ...]
    relative_error: FloatArray
    derivative_error: dict[str, FloatArray]
    table: FlutterDerivativeTable
    accuracy: float = ACCURACY
    weighting: str = "relative"

    def alternatives(self) -> Iterator[tuple[Candidate, RationalFunctionModel, float]]:
        """Yield the other scored structures, their fits and largest errors, most accurate first.

        For a caller whose check the chosen fit fails (a flutter below the table's range that
        the table does not show): the next structures the evidence allows, the one that
        follows the table best first. The error is a fraction of a force's size.
        """
        Q = self.table.Q()
        K = np.broadcast_to(self.table.K[:, None, None], Q.shape)
        problem = RogerProblem(K, Q, _row_weights(Q) if self.weighting == "relative" else None)
        found = []
        for candidate in (c for c in self.candidates if not c.note):
            if candidate.n_lags == self.model.n_lags and np.allclose(candidate.d, self.model.d):
                continue
            model = problem.fit(np.array(candidate.d), candidate.with_A3)
            found.append((candidate, model, _worst_error(Q, model.Q(1j * self.table.K))))
        yield from sorted(found, key=lambda item: (item[2], item[0].n_params))

    @property
    def worst(self) -> tuple[str, int, float]:
        """The derivative, row (0-based) and relative error of the largest error."""
        name = max(self.derivative_error, key=lambda n: float(self.derivative_error[n].max()))
        row = int(np.argmax(self.derivative_error[name]))
        return name, row, float(self.derivative_error[name][row])

    @property
    def meets_accuracy(self) -> bool:
        """Whether every derivative is within :attr:`accuracy` of its force at every row."""
        return self.worst[2] <= self.accuracy

    def error_at(self, K: float, model: RationalFunctionModel | None = None
                 ) -> dict[str, float]:
        """Each derivative's error at reduced frequency ``K`` (table interpolated), a fraction.

        ``model``: another fit of the same table (one of :meth:`alternatives`) instead of the
        chosen one.

        Raises
        ------
        ValueError
            When ``K`` lies outside the table's range (the table says nothing there).
        """
        table_values = self.table.interpolator()(np.array([K]))
        Q_table = Q_from_flutter_derivatives(np.array([K]), table_values)
        return {name: float(error[0]) for name, error in
                _derivative_errors(Q_table, (self.model if model is None else model).Q(
                    np.array([1j * K]))).items()}

    def summary(self) -> str:
        """One line: the structure, the largest error and whether it meets the accuracy."""
        name, row, error = self.worst
        verdict = ("within" if error <= self.accuracy else "MISSES")
        return (f"Roger fit with {self.model.n_lags} lag(s) ({self.reason}); largest error "
                f"{100 * error:.2g} % of its force ({name}* at K = {self.table.K[row]:.4g}): "
                f"{verdict} the {100 * self.accuracy:g} % a flutter analysis needs")


def fit_table(table: FlutterDerivativeTable, *, n_lags: int | None = None,
              with_A3: bool | None = None, weighting: str = "relative",
              accuracy: float = ACCURACY) -> TableFit:
    """Fit Roger's rational function to a flutter-derivative table, structure by evidence.

    Parameters
    ----------
    table : FlutterDerivativeTable
        Two or three degrees of freedom.
    n_lags : int, optional
        0 to :data:`MAX_LAGS`; None chooses by leave-one-row-out error and accuracy (module
        docstring).
    with_A3 : bool, optional
        Fit the added-mass matrix; None chooses.
    weighting : str
        One of :data:`WEIGHTINGS` (module docstring).
    accuracy : float
        Largest error of a derivative relative to its force the fit must reach (> 0).

    Returns
    -------
    TableFit

    Raises
    ------
    ValueError
        On an unknown weighting, ``n_lags`` outside 0..MAX_LAGS or an accuracy <= 0.
    RankDeficiencyError
        When the table has too few rows for any structure.
    """
    if weighting not in WEIGHTINGS:
        raise ValueError(f"unknown weighting {weighting!r}; allowed: {', '.join(WEIGHTINGS)}")
    if n_lags is not None and (isinstance(n_lags, bool) or n_lags not in range(MAX_LAGS + 1)):
        raise ValueError(f"n_lags must be an integer in 0..{MAX_LAGS} or None, got {n_lags!r}")
    if not (math.isfinite(accuracy) and accuracy > 0.0):
        raise ValueError(f"accuracy must be > 0, got {accuracy!r}")
    Q = table.Q()
    K = np.broadcast_to(table.K[:, None, None], Q.shape)
    relative = _row_weights(Q)
    weights = relative if weighting == "relative" else None
    problem = RogerProblem(K, Q, weights)
    model, chosen, reason, candidates = select_structure(problem, n_lags, with_A3)
    if n_lags is None:
        model, reason, candidates = _reach_accuracy(problem, Q, model, chosen, reason,
                                                    candidates, with_A3, accuracy)
    Q_model = model.Q(1j * table.K)
    error = np.abs(Q_model - Q) * relative
    return TableFit(model, reason, candidates, error.max(axis=(1, 2)),
                    _derivative_errors(Q, Q_model), table, accuracy, weighting)


def _worst_error(Q: ComplexArray, Q_model: ComplexArray) -> float:
    return max(float(e.max()) for e in _derivative_errors(Q, Q_model).values())


def _reach_accuracy(problem: RogerProblem, Q: ComplexArray, model: RationalFunctionModel,
                    chosen: Candidate, reason: str, candidates: tuple[Candidate, ...],
                    with_A3: bool | None, accuracy: float
                    ) -> tuple[RationalFunctionModel, str, tuple[Candidate, ...]]:
    """Return the simplest structure that reaches ``accuracy``, or the held-out choice.

    The held-out choice is kept when it reaches the accuracy. Otherwise the scored candidates
    are taken in order of parameters, then structures of more lags (up to :data:`MAX_LAGS`)
    are searched from the best roots found with one lag fewer. When none reaches it, the
    held-out choice stays (the reason says so).
    """
    K = problem.K[:, 0, 0]

    def worst(m: RationalFunctionModel) -> float:
        return _worst_error(Q, m.Q(1j * K))

    chosen_error = worst(model)
    if chosen_error <= accuracy:
        return model, reason, candidates
    tried = list(candidates)
    scored = sorted((c for c in tried if not c.note), key=lambda c: c.n_params)
    best: tuple[float, RationalFunctionModel, Candidate] = (chosen_error, model, chosen)
    for candidate in scored:
        trial = problem.fit(np.array(candidate.d), candidate.with_A3)
        error = worst(trial)
        if error < best[0]:
            best = (error, trial, candidate)
        if error <= accuracy:
            break
    previous = np.array(best[2].d)
    n_lags = max(c.n_lags for c in tried)
    while best[0] > accuracy and n_lags < MAX_LAGS:
        n_lags += 1
        starts = problem.starts(n_lags, previous if previous.size == n_lags - 1 else None)
        for a3 in (True, False) if with_A3 is None else (with_A3,):
            candidate, d = problem.candidate(n_lags, a3, starts)
            tried.append(candidate)
            if d is None:
                continue
            trial = problem.fit(d, a3)
            error = worst(trial)
            if error < best[0]:
                best = (error, trial, candidate)
                previous = d
    error, model_best, candidate = best
    if error > accuracy:  # more lags would chase the table's scatter, not its shape
        return model, (f"{reason}; no structure up to {MAX_LAGS} lags reaches "
                       f"{100 * accuracy:g} % of each force (best {100 * error:.2g} %, "
                       f"{candidate.label})"), tuple(tried)
    return model_best, (f"{candidate.label}: the simplest that reaches {100 * accuracy:g} % of "
                        f"each force ({100 * error:.2g} %; the held-out choice, {chosen.label}, "
                        f"{100 * chosen_error:.2g} %)"), tuple(tried)


def _derivative_errors(Q: ComplexArray, Q_model: ComplexArray) -> dict[str, FloatArray]:
    """Each derivative's error relative to its force's size, at each row: name -> (n,)."""
    size = np.abs(Q).max(axis=2)  # (n, k): each force's largest entry at each K
    size = np.maximum(size, 1e-12 * float(size.max() or 1.0))
    delta = Q_model - Q
    out = {}
    for name, (i, j, part) in derivative_layout(Q.shape[-1]).items():
        diff = delta[:, i, j].real if part == "real" else delta[:, i, j].imag
        out[name] = np.asarray(np.abs(diff) / size[:, i], dtype=float)
    return out


def _row_weights(Q: ComplexArray) -> FloatArray:
    """Return the inverse of each force row's largest entry at each K, shape of ``Q``."""
    largest = np.abs(Q).max(axis=2, keepdims=True)
    floor = 1e-12 * float(np.abs(Q).max() or 1.0)
    return np.broadcast_to(1.0 / np.maximum(largest, floor), Q.shape).copy()
