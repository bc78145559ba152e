"""E2RFC: Rational Function Coefficients directly from free-vibration releases.

Experimental Extraction of Rational Function Coefficients (Chowdhury and Sarkar, 2005): the
measured self-excited forces of releases at a few wind speeds are regressed on the measured motion
through Roger's time-domain form of the forces (see :mod:`ident._regressors`). The RFCs do not
depend on U, so all releases are stacked into one least-squares problem; the wind speed enters only
through the regressors, and releases at two or more wind speeds are what make it determined. One
decay holds just two complex frequencies, so a single wind speed can never determine the model:
that case is refused, never answered with numbers.

How noise is handled: regressors come from a modal fit of the displacements (no differentiated
noise, no noise in the regressors to bias the fit); each release and force channel is weighted by
the inverse of its own noise level; per-release intercepts absorb static forces.

Lag roots are found by variable projection: for fixed lag roots the coefficients follow from a
linear least-squares solve, so the nonlinear search runs over log(d) alone (scipy's trust-region
least squares, several starts spread over the reduced frequencies the data cover). The number of
lags (0 to 3) and whether the added-mass matrix A3 is fitted are chosen by five-fold held-out
error (folds of interleaved one-period blocks of every release), with the one-standard-error rule:
the simplest model whose held-out error is within one standard error of the best. The other
structures within one standard error are fitted too (``diagnostics.alternatives``): the data do not
tell them apart, and the spread of their flutter speeds (:meth:`IdentifiedModel.structure_spread`)
is an uncertainty that the chosen structure's parameter covariance cannot show.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from ident import flutter as _flutter
from ident._regressors import PreparedRelease, prepare
from ident._selection import Candidate, select_one_se, structure_label, within_one_se
from ident._stats import autocorrelation_inflation
from ident._threads import single_threaded_blas
from ident.errors import RankDeficiencyError
from ident.modal import ModalFit
from ident.release import Release
from ident.rfc import RationalFunctionModel
from ident.section import SectionModel

__all__ = ["Candidate", "E2RFCDiagnostics", "IdentifiedModel", "StructureSpread",
           "distinct_wind_speeds", "identify", "reduced_frequency_span"]

FloatArray = npt.NDArray[np.float64]

#: Wind speeds closer than this (relative) count as one wind speed.
DISTINCT_U_RTOL = 0.02
#: Largest condition number of the column-scaled design accepted as determined.
MAX_CONDITION = 1e8
#: Folds of the held-out error.
N_FOLDS = 5


@dataclass(frozen=True, eq=False)
class E2RFCDiagnostics:
    """What an E2RFC identification found besides the coefficients.

    Attributes
    ----------
    n_lags, with_A3 :
        The chosen structure.
    reason : str
        Why it was chosen (or "given by the caller").
    candidates : tuple of Candidate
        Every structure tried, with its held-out error: the weighted mean squared force error
        over five folds (1 = the noise level).
    release_residuals : ndarray, shape (n_releases, 2)
        RMS force residual of each release and force channel relative to that channel's RMS.
    wind_speeds : ndarray, shape (n_releases,)
        m/s.
    condition_number : float
        Of the column-scaled design matrix of the final fit.
    covariance : ndarray, shape (p, p)
        Of the fitted parameters: ``A`` entries (see ``parameter_index``) then ``log d``.
    parameter_index : tuple of (int, int, int)
        ``(k, i, j)`` of ``A[k, i, j]`` for each of the first covariance rows.
    modal_fits : tuple of ModalFit
        Modal fit of each release's displacements ``[h/B, alpha]`` (frequencies, damping).
    alternatives : tuple of IdentifiedModel
        The other structures whose held-out error is within one standard error of the best,
        each fitted on every sample as the chosen one is (empty when the caller gave the
        structure).
    """

    n_lags: int
    with_A3: bool
    reason: str
    candidates: tuple[Candidate, ...]
    release_residuals: FloatArray
    wind_speeds: FloatArray
    condition_number: float
    covariance: FloatArray = field(repr=False)
    parameter_index: tuple[tuple[int, int, int], ...] = field(repr=False)
    modal_fits: tuple[ModalFit, ...] = field(repr=False)
    alternatives: tuple[IdentifiedModel, ...] = field(default=(), repr=False)


@dataclass(frozen=True)
class StructureSpread:
    """Flutter speeds of the structures the held-out error does not tell apart.

    Attributes
    ----------
    labels : tuple of str
        The structures, the chosen one first (e.g. ``n_lags=2, A3=zero``).
    speeds : tuple of float or None
        Flutter speed of each, m/s; None when it has no flutter below ``U_max``.
    stds : tuple of float or None
        Standard deviation of each from its own parameter covariance, m/s.
    U_max : float
        Upper end of the searched wind speeds, m/s.
    """

    labels: tuple[str, ...]
    speeds: tuple[float | None, ...]
    stds: tuple[float | None, ...]
    U_max: float

    @property
    def low(self) -> float | None:
        """Lowest flutter speed over the structures, m/s (None: none flutters)."""
        found = [u for u in self.speeds if u is not None]
        return min(found) if found else None

    @property
    def high(self) -> float | None:
        """Highest flutter speed, m/s; ``inf`` when a structure has none below ``U_max``."""
        if self.low is None:
            return None
        return math.inf if None in self.speeds else max(u for u in self.speeds if u is not None)

    def range_text(self) -> str:
        """Say the flutter speeds' range, e.g. ``11.91-12.11 m/s over 3 structures``."""
        n = len(self.labels)
        if n == 1:
            return "one structure"
        low, high = self.low, self.high
        if low is None or high is None:
            return f"no flutter below {self.U_max:.3g} m/s over {n} structures"
        if math.isinf(high):
            return f"{low:.2f} m/s to no flutter below {self.U_max:.3g} m/s over {n} structures"
        return f"{low:.2f}-{high:.2f} m/s over {n} structures"

    def summary(self) -> str:
        """One phrase, e.g. ``11.91-12.11 m/s over 3 structures within one SE``."""
        return f"{self.range_text()} within one SE"


class IdentifiedModel(RationalFunctionModel):
    """A :class:`RationalFunctionModel` identified from data, with its diagnostics."""

    __slots__ = ("diagnostics",)

    def __init__(self, A: FloatArray, d: FloatArray, diagnostics: E2RFCDiagnostics) -> None:
        super().__init__(A, d)
        self.diagnostics = diagnostics

    def flutter(
        self, section: SectionModel, U_max: float | None = None
    ) -> tuple[_flutter.FlutterResult, float | None]:
        """Flutter analysis with this model, and the standard deviation of the flutter speed.

        The standard deviation propagates the parameter covariance (coefficients and lag roots)
        through the first-order sensitivity of the flutter speed
        (:func:`ident.flutter.speed_sensitivity`).

        Returns
        -------
        result : FlutterResult
        speed_std : float or None
            m/s; None without flutter below ``U_max``.
        """
        result = _flutter.analyze(section, self, U_max)
        if result.speed is None or result.frequency is None:
            return result, None
        dU_dA, dU_dd = _flutter.speed_sensitivity(section, self, result.speed, result.frequency)
        gradient = np.array(
            [dU_dA[k, i, j] for k, i, j in self.diagnostics.parameter_index]
            + list(dU_dd * self.d)  # the covariance is in log(d)
        )
        variance = float(gradient @ self.diagnostics.covariance @ gradient)
        return result, math.sqrt(max(variance, 0.0))

    def structure_spread(self, section: SectionModel, U_max: float | None = None
                         ) -> StructureSpread:
        """Flutter speed of this model and of every alternative structure within one SE.

        With one short release per wind speed the held-out error often cannot tell one lag from
        two; the structures it cannot tell apart may predict flutter speeds further apart than
        the chosen one's standard deviation. Report this spread next to that deviation.

        Parameters
        ----------
        section : SectionModel
        U_max : float, optional
            Upper end of the searched wind speeds, m/s (default: :func:`ident.flutter.analyze`'s).

        Returns
        -------
        StructureSpread
        """
        models = (self, *self.diagnostics.alternatives)
        labels, speeds, stds = [], [], []
        searched = math.nan
        for model in models:
            result, std = model.flutter(section, U_max)
            searched = result.U_max
            labels.append(structure_label(model.diagnostics.n_lags, model.diagnostics.with_A3))
            speeds.append(result.speed)
            stds.append(std)
        return StructureSpread(tuple(labels), tuple(speeds), tuple(stds), float(searched))


@single_threaded_blas
def identify(
    releases: Sequence[Release],
    section: SectionModel,
    n_lags: int | None = None,
    with_A3: bool | None = None,
) -> IdentifiedModel:
    """Identify the rational-function model of the self-excited forces from releases (E2RFC).

    Parameters
    ----------
    releases : sequence of Release
        Free decays with measured forces, at two or more wind speeds.
    section : SectionModel
        The structure (its width B and, where a release has none, the air density).
    n_lags : int, optional
        Number of lag terms (0 to 3); None chooses by held-out error.
    with_A3 : bool, optional
        Fit the added-mass matrix A3; None chooses by held-out error.

    Returns
    -------
    IdentifiedModel
        A :class:`RationalFunctionModel` with ``.diagnostics`` (:class:`E2RFCDiagnostics`) and
        ``.flutter(section)`` giving the flutter speed with its standard deviation.

    Raises
    ------
    RankDeficiencyError
        Releases at fewer than two wind speeds, or data that cannot determine the requested model.
    TypeError
        If ``releases`` holds something other than :class:`Release` objects.

    References
    ----------
    M. Gan Chowdhury and P. P. Sarkar, "Experimental identification of rational function
    coefficients for time-domain flutter analysis", Engineering Structures 27 (2005) 1349-1364.
    G. H. Golub and V. Pereyra, "Separable nonlinear least squares: the variable projection
    method and its applications", Inverse Problems 19 (2003).

    Examples
    --------
    >>> from ident import SectionModel, flat_plate
    >>> from simulators import simulate_release
    >>> s = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)
    >>> truth = flat_plate.jones_model()
    >>> sims = [simulate_release(s, truth, U, 0.004, 0.02, duration=10.0, fs=200.0)
    ...         for U in (5.0, 8.0)]
    >>> model = identify([Release.from_simulation(r) for r in sims], s, n_lags=2, with_A3=True)
    >>> bool(np.allclose(model.d, truth.d, rtol=1e-3))
    True
    >>> identify([Release.from_simulation(sims[0])], s)
    Traceback (most recent call last):
    ...
    ident.errors.RankDeficiencyError: releases at one wind speed (5 m/s) cannot determine ...
    """
    releases = list(releases)
    for r in releases:
        if not isinstance(r, Release):
            raise TypeError(f"releases must be ident.Release objects, got {type(r).__name__}")
    _check_wind_speeds(releases)
    if n_lags is not None and (not isinstance(n_lags, int) or not 0 <= n_lags <= 3):
        raise ValueError(f"n_lags must be an integer in 0..3 or None, got {n_lags!r}")
    return _identify_prepared([prepare(r, section) for r in releases], n_lags, with_A3)


def _identify_prepared(
    prepared: list[PreparedRelease], n_lags: int | None, with_A3: bool | None
) -> IdentifiedModel:
    """Choose the structure, search the lag roots and fit, on prepared releases.

    Separate from :func:`identify` so that other regressor constructions (the benchmark's
    ablation with differentiated raw displacements) run through the very same estimator.
    """
    problem = _Problem(prepared)
    given = n_lags is not None and with_A3 is not None
    lags = range(4) if n_lags is None else [n_lags]
    a3_options = (True, False) if with_A3 is None else (with_A3,)
    candidates: list[Candidate] = []
    previous: FloatArray | None = None
    history: list[list[Candidate]] = []
    for m in lags:
        starts = problem.starts(m, previous)
        tried = []
        for a3 in a3_options:
            candidate, d_found = problem.candidate(m, a3, starts, score=not given)
            tried.append(candidate)
            if d_found is not None:
                starts = [d_found]  # the other A3 option starts from these roots
                previous = d_found if a3 == a3_options[0] else previous
        candidates.extend(tried)
        history.append(tried)
        # Two lag counts in a row that beat nothing simpler: more lags will not either.
        if n_lags is None and m >= 2 and not any(
            _improves(history[j], [c for h in history[:j] for c in h]) for j in (m - 1, m)
        ):
            break
    usable = [c for c in candidates if not c.note]
    if not usable:
        notes = "; ".join(f"n_lags={c.n_lags}, A3={c.with_A3}: {c.note}" for c in candidates)
        raise RankDeficiencyError(f"no model structure is determined by these releases ({notes})")
    chosen, reason = select_one_se(usable, given=given)
    if given:
        return problem.final(chosen, tuple(candidates), reason)
    alternatives = tuple(
        problem.final(problem.polished(c), tuple(candidates),
                      f"{c.label}: within one standard error of the best, not chosen")
        for c in within_one_se(usable) if c is not chosen)
    return problem.final(problem.polished(chosen), tuple(candidates), reason, alternatives)


def distinct_wind_speeds(speeds: Sequence[float]) -> list[float]:
    """Return the wind speeds that count as distinct for E2RFC, increasing, m/s.

    A speed within ``DISTINCT_U_RTOL`` above the last distinct one is the same wind speed.
    """
    out: list[float] = []
    for u in sorted(speeds):
        if not out or u > out[-1] * (1 + DISTINCT_U_RTOL):
            out.append(float(u))
    return out


def reduced_frequency_span(releases: Sequence[Release], section: SectionModel,
                           n: int) -> FloatArray:
    """Return ``n`` reduced frequencies spanning what the releases measured, widened 20 %.

    ``K = B omega / U`` of both structural modes at every release's wind speed: where an
    identified model's flutter derivatives rest on data (for plots and tables).
    """
    K = [section.B * 2 * math.pi * f / r.U for r in releases for f in (section.fh, section.fa)]
    return np.linspace(0.8 * min(K), 1.2 * max(K), n)


def _check_wind_speeds(releases: list[Release]) -> None:
    if not releases:
        raise RankDeficiencyError(
            "no releases given: E2RFC needs releases at two or more wind speeds"
        )
    speeds = sorted(r.U for r in releases)
    if len(distinct_wind_speeds(speeds)) < 2:
        raise RankDeficiencyError(
            f"releases at one wind speed ({speeds[0]:.3g} m/s) cannot determine the rational "
            "function model: one decay holds only two complex frequencies. Record releases at "
            "two or more wind speeds (E2RFC is designed for 2 to 5)."
        )


def _improves(new: list[Candidate], old: list[Candidate]) -> bool:
    """Tell whether the best new candidate beats the best old one by more than its std error."""
    new_ok = [c for c in new if not c.note]
    old_ok = [c for c in old if not c.note]
    if not new_ok or not old_ok:
        return bool(new_ok)
    best_new = min(new_ok, key=lambda c: c.cv_error)
    best_old = min(old_ok, key=lambda c: c.cv_error)
    return best_new.cv_error < best_old.cv_error - best_old.cv_se


class _Problem:
    """The stacked weighted least-squares problem over all releases, for any structure."""

    def __init__(self, prepared: list[PreparedRelease]) -> None:
        self.prepared = prepared
        self.weights = np.array([1.0 / p.force_noise for p in prepared])  # (n_releases, 2)
        # Reduced frequencies the data cover, from the modal frequencies: where lags can live.
        K = np.concatenate([2 * math.pi * p.fit.frequencies * p.B / p.U for p in prepared])
        self.K_range = (float(K.min()), float(K.max()))

    # -- linear part -------------------------------------------------------------------------
    def _blocks(
        self, d: FloatArray, with_A3: bool, which: str, rows: list[FloatArray] | None = None
    ) -> list[tuple[FloatArray, FloatArray]]:
        """Per release: design (n, k) and normalised forces (n, 2) on a view, or rows of it."""
        out = []
        for n, p in enumerate(self.prepared):
            view = p.view(which)
            fixed = view.fixed if with_A3 else view.fixed[:, :4]
            design = np.hstack([fixed, view.lag_columns(d)])
            force = view.force
            if rows is not None:
                design, force = design[rows[n]], force[rows[n]]
            out.append((design, force))
        return out

    def _solve(
        self, blocks: list[tuple[FloatArray, FloatArray]], *, exact: bool = False
    ) -> tuple[FloatArray, list[FloatArray], list[FloatArray]]:
        """Coefficients (k, 2), per-release intercepts and weighted residuals.

        Per-release intercepts are profiled out by demeaning each release (Frisch-Waugh). The
        many solves of the lag-root search and of cross-validation use column-scaled normal
        equations (fast; candidates are accepted only when well conditioned); the final fit uses
        an SVD-based solve of the stacked system (``exact=True``). The releases are stacked into
        one array so that each solve is a few matrix products, not a loop over releases.
        """
        sizes = np.array([X.shape[0] for X, _ in blocks])
        X = np.vstack([b[0] for b in blocks])
        y = np.vstack([b[1] for b in blocks])
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        X_mean = np.add.reduceat(X, starts, axis=0) / sizes[:, None]
        y_mean = np.add.reduceat(y, starts, axis=0) / sizes[:, None]
        release = np.repeat(np.arange(sizes.size), sizes)
        Xc = X - X_mean[release]
        yc = y - y_mean[release]
        w = self.weights[release]  # (n_rows, 2)
        k = X.shape[1]
        coef = np.empty((k, 2))
        for i in range(2):
            Xw = Xc * w[:, i : i + 1]
            yw = yc[:, i] * w[:, i]
            if exact:
                coef[:, i], *_ = np.linalg.lstsq(Xw, yw, rcond=None)
                continue
            G = Xw.T @ Xw
            b = Xw.T @ yw
            scale = np.sqrt(np.diag(G))
            scale[scale == 0.0] = 1.0
            scaled, *_ = np.linalg.lstsq(G / np.outer(scale, scale), b / scale, rcond=None)
            coef[:, i] = scaled / scale
        intercept_rows = y_mean - X_mean @ coef
        intercepts = list(intercept_rows)
        residual_rows = w * (yc - Xc @ coef)
        residuals = np.split(residual_rows, np.cumsum(sizes)[:-1])
        return coef, intercepts, residuals

    def condition(self, d: FloatArray, with_A3: bool) -> float:
        """Condition number of the column-scaled, demeaned, stacked design."""
        blocks = self._blocks(d, with_A3, "search")
        M = np.vstack([X - X.mean(axis=0) for X, _ in blocks])
        norms = np.linalg.norm(M, axis=0)
        if np.any(norms == 0.0):
            return math.inf
        return float(np.linalg.cond(M / norms))

    # -- lag-root search ---------------------------------------------------------------------
    def starts(self, n_lags: int, previous: FloatArray | None) -> list[FloatArray]:
        """Start values of the lag-root search for ``n_lags`` lags.

        Lags found with one lag fewer are kept and one new root is tried at three places across
        the covered reduced frequencies (nested starts converge fast); one evenly spread start
        guards against a poor previous solution.
        """
        K_lo, K_hi = self.K_range
        spread = np.geomspace(K_lo / 3.0, 3.0 * K_hi, n_lags + 2)[1:-1]
        if previous is None or previous.size != n_lags - 1:
            return [spread, spread * 0.3, spread * 3.0]
        new_roots = np.geomspace(K_lo / 3.0, 3.0 * K_hi, 3)
        return [np.sort(np.append(previous, r)) for r in new_roots] + [spread]

    def search(
        self, n_lags: int, with_A3: bool, starts: list[FloatArray], *, loose: bool
    ) -> FloatArray:
        """Lag roots minimising the weighted force residual, from the best of several starts.

        ``loose`` stops at a relative cost change of 1e-6: enough to compare structures; the
        chosen one is then polished to full precision.
        """
        if n_lags == 0:
            return np.zeros(0)
        K_lo, K_hi = self.K_range
        lo, hi = math.log(K_lo / 20.0), math.log(20.0 * K_hi)

        def residual(theta: FloatArray, which: str) -> FloatArray:
            blocks = self._blocks(np.exp(theta), with_A3, which)
            _, _, res = self._solve(blocks)
            return np.concatenate([r.ravel() for r in res])

        def solve(theta0: FloatArray, which: str, tol: float, nfev: int) -> Any:
            return least_squares(
                residual, np.clip(theta0, lo + 1e-6, hi - 1e-6), bounds=(lo, hi), args=(which,),
                xtol=tol, ftol=1e-2 * tol, max_nfev=nfev * (n_lags + 1),
            )

        # Every start is run loosely on the subsampled rows. When asked to be precise, the best
        # is converged there, then moved by one Gauss-Newton step on every sample, so that the
        # lag roots use all the data: the subsample's optimum lies within the estimation noise of
        # the full-data one, and from there one step of this nearly quadratic problem leaves d
        # within 0.15 of its own standard deviation of the converged value (measured at 5 %
        # noise; three more steps cost 0.2 s for that).
        best = min((solve(np.log(start), "search", 1e-3, 20) for start in starts),
                   key=lambda sol: sol.cost)
        theta = best.x
        if not loose:
            theta = solve(theta, "search", 1e-8, 40).x
            theta = self._gauss_newton_step(theta, lambda th: residual(th, "full"), lo, hi)
        return np.sort(np.exp(theta))

    @staticmethod
    def _gauss_newton_step(
        theta: FloatArray, residual: Any, lo: float, hi: float
    ) -> FloatArray:
        """One Gauss-Newton step (central-difference Jacobian), kept inside the bounds."""
        r0 = residual(theta)
        h = 1e-6
        J = np.column_stack([
            (residual(theta + h * e) - residual(theta - h * e)) / (2 * h)
            for e in np.eye(theta.size)
        ])
        step, *_ = np.linalg.lstsq(J, -r0, rcond=None)
        return np.asarray(np.clip(theta + step, lo + 1e-9, hi - 1e-9), dtype=float)

    # -- structures ----------------------------------------------------------------------------
    def candidate(
        self, n_lags: int, with_A3: bool, starts: list[FloatArray], *, score: bool
    ) -> tuple[Candidate, FloatArray | None]:
        """Search the lag roots of one structure and (if ``score``) its held-out error.

        Without ``score`` (a structure given by the caller) the search runs at full precision
        at once and no held-out error is computed (it is reported as NaN).
        """
        k = 2 * ((6 if with_A3 else 4) + 2 * n_lags) + n_lags
        d = self.search(n_lags, with_A3, starts, loose=score)
        if n_lags and np.min(np.diff(np.concatenate([[0.0], d]))) <= 1e-6 * d.max():
            return Candidate(n_lags, with_A3, tuple(d), math.inf, math.inf, k,
                             "lag roots merged: fewer lags describe the data"), None
        cond = self.condition(d, with_A3)
        if cond > MAX_CONDITION:
            return Candidate(n_lags, with_A3, tuple(d), math.inf, math.inf, k,
                             f"rank deficient (condition number {cond:.2g})"), None
        if not score:
            return Candidate(n_lags, with_A3, tuple(d), math.nan, math.nan, k), d
        errors = self._cross_validate(d, with_A3)
        return Candidate(n_lags, with_A3, tuple(d), float(errors.mean()),
                         float(errors.std(ddof=1) / math.sqrt(errors.size)), k), d

    def _cross_validate(self, d: FloatArray, with_A3: bool) -> FloatArray:
        """Held-out weighted mean squared force error per fold."""
        folds = [self._folds(p) for p in self.prepared]
        errors = np.empty(N_FOLDS)
        blocks = self._blocks(d, with_A3, "search")
        for k in range(N_FOLDS):
            train = [np.concatenate([f[j] for j in range(N_FOLDS) if j != k]) for f in folds]
            training = [(X[r], y[r]) for (X, y), r in zip(blocks, train, strict=True)]
            coef, intercepts, _ = self._solve(training)
            sq, n = 0.0, 0
            for (X, y), f, c, w in zip(blocks, folds, intercepts, self.weights, strict=True):
                e = w * (y[f[k]] - X[f[k]] @ coef - c)
                sq += float(np.sum(e**2))
                n += e.size
            errors[k] = sq / n
        return errors

    @staticmethod
    def _folds(p: PreparedRelease) -> list[npt.NDArray[np.intp]]:
        """Split a release's search rows into folds of interleaved blocks, each one period long.

        Contiguous folds would hold out the large-amplitude start of a decay in one fold and
        judge it by coefficients fitted to the small tail; interleaving gives every fold the
        whole decay, and one-period blocks keep neighbouring (correlated) samples together.
        """
        t = p.view("search").t
        period = 1.0 / float(p.fit.frequencies.min())
        labels = (np.floor((t - t[0]) / period).astype(int)) % N_FOLDS
        return [np.flatnonzero(labels == k) for k in range(N_FOLDS)]

    def polished(self, candidate: Candidate) -> Candidate:
        """Return the candidate with its lag roots searched again at full precision."""
        d = self.search(candidate.n_lags, candidate.with_A3, [np.array(candidate.d)], loose=False)
        return dataclasses.replace(candidate, d=tuple(float(x) for x in d))

    def final(
        self, chosen: Candidate, candidates: tuple[Candidate, ...], reason: str,
        alternatives: tuple[IdentifiedModel, ...] = (),
    ) -> IdentifiedModel:
        """Fit the chosen structure on every sample and assemble the model and diagnostics."""
        d = np.array(chosen.d)
        blocks = self._blocks(d, chosen.with_A3, "full")
        coef, _, residuals = self._solve(blocks, exact=True)
        terms = [0, 1, 2] if chosen.with_A3 else [0, 1]
        terms += [3 + l for l in range(d.size)]
        A = np.zeros((3 + d.size, 2, 2))
        index: list[tuple[int, int, int]] = []
        for i in range(2):
            for col, (term, j) in enumerate((t, j) for t in terms for j in range(2)):
                A[term, i, j] = coef[col, i]
                index.append((term, i, j))
        release_residuals = np.array([
            np.sqrt(np.mean((r / w) ** 2, axis=0)) / np.sqrt(np.mean(y**2, axis=0))
            for r, w, (_, y) in zip(residuals, self.weights, blocks, strict=True)
        ])
        covariance = self._covariance(d, chosen.with_A3, coef, residuals)
        diagnostics = E2RFCDiagnostics(
            n_lags=d.size,
            with_A3=chosen.with_A3,
            reason=reason,
            candidates=candidates,
            release_residuals=release_residuals,
            wind_speeds=np.array([p.U for p in self.prepared]),
            condition_number=self.condition(d, chosen.with_A3),
            covariance=covariance,
            parameter_index=tuple(index),
            modal_fits=tuple(p.fit for p in self.prepared),
            alternatives=alternatives,
        )
        return IdentifiedModel(A, d, diagnostics)

    def _covariance(
        self, d: FloatArray, with_A3: bool, coef: FloatArray, residuals: list[FloatArray]
    ) -> FloatArray:
        """Gauss-Newton covariance of [A entries (force row 0, row 1), log d].

        The residual variance and its autocorrelation inflation come from the full-rate
        residuals; the curvature ``J^T J`` from the search subsample, scaled by the ratio of
        sample counts (the rows are an even subsample of the same decays).
        """
        blocks = self._blocks(d, with_A3, "search")
        k = coef.shape[0]
        n_search = sum(X.shape[0] for X, _ in blocks)
        n_full = sum(r.shape[0] for r in residuals)
        # Linear part: block diagonal over the two force rows.
        J_lin = np.zeros((2 * n_search, 2 * k))
        for i in range(2):
            J_lin[i * n_search : (i + 1) * n_search, i * k : (i + 1) * k] = np.vstack(
                [-w[i] * (X - X.mean(axis=0))
                 for (X, _), w in zip(blocks, self.weights, strict=True)]
            )
        columns = [J_lin]
        for l in range(d.size):
            h = 1e-6
            d_plus, d_minus = d.copy(), d.copy()
            d_plus[l] *= math.exp(h)
            d_minus[l] *= math.exp(-h)
            r_plus = self._residual_vector(d_plus, with_A3, coef)
            r_minus = self._residual_vector(d_minus, with_A3, coef)
            columns.append(((r_plus - r_minus) / (2 * h))[:, None])
        J = np.hstack(columns)
        r = np.concatenate([np.concatenate([res[:, i] for res in residuals]) for i in range(2)])
        dof = max(r.size - J.shape[1], 1)
        sigma2 = float(r @ r) / dof * autocorrelation_inflation(residuals)
        return np.asarray(sigma2 * np.linalg.pinv(J.T @ J) * n_search / n_full, dtype=float)

    def _residual_vector(self, d: FloatArray, with_A3: bool, coef: FloatArray) -> FloatArray:
        """Weighted search-row residuals at fixed coefficients (intercepts re-profiled)."""
        blocks = self._blocks(d, with_A3, "search")
        out = []
        for i in range(2):
            for (X, y), w in zip(blocks, self.weights, strict=True):
                e = y[:, i] - X @ coef[:, i]
                out.append(w[i] * (e - e.mean()))
        return np.concatenate(out)
