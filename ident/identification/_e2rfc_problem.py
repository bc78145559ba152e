"""The stacked least-squares problem of E2RFC for any model structure (private to E2RFC).

For fixed lag roots the normalised forces of every release are linear in Roger's coefficients;
this module holds that problem (:class:`Problem`): the weighted, intercept-profiled solve, the
lag-root search by variable projection, the held-out error of a structure, the final fit on
every sample and its covariance. Choosing among structures and reporting are
:mod:`ident.identification.e2rfc`'s.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ident.identification._full_rows import FullRows
from ident.identification._regressors import PreparedRelease
from ident.identification._stacked import Stacked
from ident.numerics.lsq import bounded_lm
from ident.numerics.selection import Candidate
from ident.numerics.stats import autocorrelation_inflation

__all__ = ["FinalFit", "MAX_CONDITION", "N_FOLDS", "Problem", "improves"]

FloatArray = npt.NDArray[np.float64]

#: Largest condition number of the column-scaled design accepted as determined.
MAX_CONDITION = 1e8
#: Folds of the held-out error.
N_FOLDS = 5
#: Most lags for which the lag-root search stops at two starts that agree (``Problem.search``).
#: Measured on the benchmark's releases: with one and two lags every start ends at the same
#: optimum; with three the landscape is flat, starts end at different optima of nearly equal
#: cost, and which one is kept moves the alternatives' flutter speeds (the structure spread),
#: so every start is run.
EARLY_STOP_LAGS = 2
#: Largest Gauss-Newton step (in log d) from the search rows' optimum to the full data's taken
#: as one step; a larger one means the problem is not nearly quadratic there (see search()).
#: Measured on the 30 smooth cases of benchmarks/ident_accuracy.py (plate and deck, 0-5 %
#: noise, 5 seeds): the chosen 2-lag structures' steps 0-0.064; the 3-lag alternatives' mostly
#: 0.21-1.02 (once 0.018).
MAX_ONE_STEP = 0.1
#: Most residual evaluations of the search on every sample, when one Gauss-Newton step is too
#: large (``Problem._precise``). The ill-determined 3-lag alternative of
#: ``test_the_lag_roots_of_an_ill_determined_alternative_are_converged_on_all_the_data`` takes
#: 33 (its valley of two nearly merged roots is long and flat); the earlier limit, 20, left it
#: short of the optimum.
FULL_NFEV = 60
#: Below this condition number the final fit solves the normal equations and refines once
#: (``Problem._full_fit``); above, an SVD of the rows.
NORMAL_EQUATIONS_CONDITION = 1e4


@dataclass(frozen=True, eq=False)
class FinalFit:
    """One structure fitted on every sample.

    Attributes
    ----------
    A : ndarray, shape (3 + n_lags, n_dof, n_dof)
    d : ndarray, shape (n_lags,)
    with_A3 : bool
    covariance : ndarray
        Of the fitted ``A`` entries (``parameter_index``) then ``log d``.
    parameter_index : tuple of (int, int, int)
    release_residuals : ndarray, shape (n_releases, n_dof)
        RMS force residual per release and channel relative to that channel's RMS.
    condition_number : float
    residual_inflation : float
        Variance inflation of the force residuals' autocorrelation (1: white).
    """

    A: FloatArray
    d: FloatArray
    with_A3: bool
    covariance: FloatArray
    parameter_index: tuple[tuple[int, int, int], ...]
    release_residuals: FloatArray
    condition_number: float
    residual_inflation: float


_Blocks = list[tuple[FloatArray, FloatArray]]


def improves(new: list[Candidate], old: list[Candidate]) -> bool:
    """Tell whether the best new candidate beats the best old one by more than its std error."""
    new_ok = [c for c in new if not c.note]
    old_ok = [c for c in old if not c.note]
    if not new_ok or not old_ok:
        return bool(new_ok)
    best_new = min(new_ok, key=lambda c: c.cv_error)
    best_old = min(old_ok, key=lambda c: c.cv_error)
    return best_new.cv_error < best_old.cv_error - best_old.cv_se


class Problem:
    """The stacked weighted least-squares problem over all releases, for any structure.

    Each of the ``n_dof`` force rows (lift, moment and, with sway, drag) is its own weighted
    least-squares problem in the same regressors; only the lag roots are shared.
    """

    def __init__(self, prepared: list[PreparedRelease]) -> None:
        self.prepared = prepared
        self.n = prepared[0].n_dof
        if any(p.n_dof != self.n for p in prepared):
            raise ValueError("releases mix two and three degrees of freedom")
        self.weights = np.array([1.0 / p.force_noise for p in prepared])  # (n_releases, n)
        # Reduced frequencies the data cover, from the modal frequencies: where lags can live.
        K = np.concatenate([2 * math.pi * p.fit.frequencies * p.B / p.U for p in prepared])
        self.K_range = (float(K.min()), float(K.max()))
        self._stacked_cache: dict[tuple[bool, str], Stacked] = {}
        self._full_rows_cache: dict[bool, FullRows] = {}
        self._last_blocks: tuple[tuple[bytes, bool, str], _Blocks] | None = None
        self._fold_rows = [self._folds(p) for p in prepared]
        # Each release's search rows in fold order, and where each fold starts and ends there:
        # one copy of the rows per candidate, every fold a slice of it.
        self._fold_order = [np.concatenate(folds) for folds in self._fold_rows]
        self._fold_bounds = [np.cumsum([0] + [f.size for f in folds]) for folds in self._fold_rows]

    # -- linear part -------------------------------------------------------------------------
    def _blocks(
        self, d: FloatArray, with_A3: bool, which: str
    ) -> list[tuple[FloatArray, FloatArray]]:
        """Per release: design (rows, k) and normalised forces (rows, n_dof) on a view.

        The last result is kept: a candidate's held-out error and its condition number (and the
        final fit's covariance and condition number) ask for the same blocks in turn.
        """
        key = (np.asarray(d, dtype=float).tobytes(), with_A3, which)
        if self._last_blocks is not None and self._last_blocks[0] == key:
            return self._last_blocks[1]
        out = []
        for p in self.prepared:
            view = p.view(which)
            fixed = view.fixed if with_A3 else view.fixed[:, :2 * self.n]
            out.append((np.hstack([fixed, view.lag_columns(d)]), view.force))
        self._last_blocks = (key, out)
        return out

    def _solve(
        self, blocks: list[tuple[FloatArray, FloatArray]], *, exact: bool = False
    ) -> tuple[FloatArray, list[FloatArray], list[FloatArray]]:
        """Coefficients (k, n_dof), per-release intercepts and weighted residuals.

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
        w = self.weights[release]  # (n_rows, n_dof)
        k = X.shape[1]
        coef = np.empty((k, self.n))
        for i in range(self.n):
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
        """Condition number of the column-scaled, demeaned, stacked design.

        From the eigenvalues of its Gram matrix (a few small products) when that is accurate:
        their square root carries a relative error of about ``eps cond^2``, 1e-8 below a
        condition number of 1e4; above, from the design's singular values (an SVD of every
        search row), so the ``MAX_CONDITION`` test is never decided by round-off.
        """
        blocks = self._blocks(d, with_A3, "search")
        M = np.vstack([X - X.mean(axis=0) for X, _ in blocks])
        norms = np.linalg.norm(M, axis=0)
        if np.any(norms == 0.0):
            return math.inf
        M = M / norms
        eigenvalues = np.linalg.eigvalsh(M.T @ M)
        if eigenvalues[0] > 0.0:
            estimate = math.sqrt(float(eigenvalues[-1] / eigenvalues[0]))
            if estimate < 1e4:
                return estimate
        return float(np.linalg.cond(M))

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

        ``loose`` stops at a relative change of 1e-3: enough to compare structures; the chosen
        one is then polished to full precision.
        """
        if n_lags == 0:
            return np.zeros(0)
        # Every start is run loosely on the coarse rows. Up to EARLY_STOP_LAGS lags, the starts
        # are tried in turn until two of them end at the same optimum (the same roots to 1 %, the
        # same cost to 1e-4): the landscape then leads the starts tried so far to one minimum,
        # and the remaining starts are not run.
        solutions: list[Any] = []
        for start in _distinct(starts):
            sol = self._lm(with_A3, np.log(start), "coarse", 1e-3, 20)
            agrees = any(_same_optimum(sol, other) for other in solutions)
            solutions.append(sol)
            if agrees and n_lags <= EARLY_STOP_LAGS:
                break
        theta = min(solutions, key=lambda sol: sol.cost).x
        return np.sort(np.exp(theta if loose else self._precise(with_A3, theta)))

    def _precise(self, with_A3: bool, theta: FloatArray) -> FloatArray:
        """Converge log lag roots from a loose optimum on the search rows, then on every sample.

        The search rows' optimum is moved by one Gauss-Newton step on every sample, so the lag
        roots use all the data: the subsample's optimum lies within the estimation noise of the
        full-data one, and from there one step of this nearly quadratic problem leaves d within
        0.15 of its own standard deviation of the converged value (measured at 5 % noise).
        """
        lo, hi = self._log_bounds()
        theta = self._lm(with_A3, theta, "search", 1e-8, 40).x
        step = self._full_rows(with_A3).gauss_newton_step(theta)
        if np.max(np.abs(step)) <= MAX_ONE_STEP:
            return np.asarray(np.clip(theta + step, lo + 1e-9, hi - 1e-9), dtype=np.float64)
        # The subsample's optimum is not within the estimation noise of the full-data one (an
        # ill-determined alternative structure): one undamped step from there lands wherever
        # round-off sends it (its flutter speed moved 2 % between two summation orders), so
        # converge on every sample instead.
        return np.asarray(self._lm(with_A3, theta, "full", 1e-8, FULL_NFEV).x, dtype=np.float64)

    def _log_bounds(self) -> tuple[float, float]:
        """Bounds of the log lag roots: a factor 20 beyond the covered reduced frequencies."""
        K_lo, K_hi = self.K_range
        return math.log(K_lo / 20.0), math.log(20.0 * K_hi)

    def _lm(self, with_A3: bool, theta0: FloatArray, which: str, tol: float, nfev: int) -> Any:
        """Run the bounded Levenberg-Marquardt search of the log lag roots on a view's rows."""
        lo, hi = self._log_bounds()
        problem = self._stacked(with_A3, which)
        return bounded_lm(
            problem.residual, problem.jacobian, np.clip(theta0, lo + 1e-6, hi - 1e-6),
            (np.full(theta0.size, lo), np.full(theta0.size, hi)), xtol=tol,
            ftol=1e-2 * tol, max_nfev=nfev)

    def _full_rows(self, with_A3: bool) -> FullRows:
        """Return every sample's Gram-matrix form for a structure family (built once)."""
        if with_A3 not in self._full_rows_cache:
            self._full_rows_cache[with_A3] = FullRows(self.prepared, self.weights, with_A3)
        return self._full_rows_cache[with_A3]

    def _stacked(self, with_A3: bool, which: str) -> Stacked:
        """Return the stacked problem of a structure family on a view (built once, reused)."""
        key = (with_A3, which)
        if key not in self._stacked_cache:
            self._stacked_cache[key] = Stacked(self.prepared, self.weights, with_A3, which)
        return self._stacked_cache[key]

    # -- structures ----------------------------------------------------------------------------
    def candidate(
        self, n_lags: int, with_A3: bool, starts: list[FloatArray], *, score: bool
    ) -> tuple[Candidate, FloatArray | None]:
        """Search the lag roots of one structure and (if ``score``) its held-out error.

        Without ``score`` (a structure given by the caller) the search runs at full precision
        at once and no held-out error is computed (it is reported as NaN).
        """
        n = self.n
        k = n * n * ((3 if with_A3 else 2) + n_lags) + n_lags
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

    def refit(self, n_lags: int, with_A3: bool, starts: list[FloatArray]) -> FinalFit | None:
        """Fit a structure from near-converged starts, loosely: for the uncertainty's refits.

        The lag roots are searched to a relative 1e-3 (their effect on a flutter speed that is
        compared with the chosen model's is far below the differences measured); None when the
        roots merge or the design is rank deficient.
        """
        d = self.search(n_lags, with_A3, starts, loose=True)
        if n_lags and np.min(np.diff(np.concatenate([[0.0], d]))) <= 1e-6 * d.max():
            return None
        if self.condition(d, with_A3) > MAX_CONDITION:
            return None
        return self.final(Candidate(n_lags, with_A3, tuple(d), math.nan, math.nan, 0))

    def held_out_error(self, d: FloatArray, with_A3: bool) -> float:
        """Held-out error of a structure with lag roots ``d`` (the candidates' score)."""
        return float(self._cross_validate(d, with_A3).mean())

    def _cross_validate(self, d: FloatArray, with_A3: bool) -> FloatArray:
        """Held-out weighted mean squared force error per fold.

        Each fold's training solve is the weighted, per-release-demeaned normal equations of
        :meth:`_solve` on the other folds' rows, assembled from per-release, per-fold moments
        of ``[X, y]`` (computed once; each release centred on its own mean first, so that
        removing the training mean cancels no digits) instead of stacking the rows again for
        every fold. The held-out residuals are computed from the fold's rows.
        """
        blocks = self._blocks(d, with_A3, "search")
        k = blocks[0][0].shape[1]
        n_rel = len(blocks)
        Z = [np.hstack([X, y])[order] for (X, y), order in zip(blocks, self._fold_order,
                                                               strict=True)]
        Z = [z - z.mean(axis=0) for z in Z]
        n = self.n
        moments = np.empty((n_rel, N_FOLDS, k + n, k + n))
        sums = np.empty((n_rel, N_FOLDS, k + n))
        counts = np.empty((n_rel, N_FOLDS))
        for r, (z, bounds) in enumerate(zip(Z, self._fold_bounds, strict=True)):
            for j in range(N_FOLDS):
                zj = z[bounds[j]:bounds[j + 1]]
                moments[r, j] = zj.T @ zj
                sums[r, j] = zj.sum(axis=0)
                counts[r, j] = zj.shape[0]
        w2 = self.weights**2  # (n_rel, n)
        errors = np.empty(N_FOLDS)
        for fold in range(N_FOLDS):
            n_train = counts.sum(axis=1) - counts[:, fold]
            # A release with no training rows in this fold (its one-period blocks all fell in
            # the fold) adds nothing to the solve, and its intercept is unknown (NaN), as
            # in the stacked solve.
            trained = n_train > 0
            mean = np.full((n_rel, k + n), np.nan)
            mean[trained] = ((sums.sum(axis=1) - sums[:, fold])[trained]
                             / n_train[trained, None])  # (n_rel, k + n)
            centred = np.zeros((n_rel, k + n, k + n))
            centred[trained] = (moments.sum(axis=1) - moments[:, fold])[trained] - (
                n_train[trained, None, None] * mean[trained, :, None] * mean[trained, None, :])
            coef = np.empty((k, n))
            for i in range(n):
                C = np.tensordot(w2[:, i], centred, axes=1)
                G, b = C[:k, :k], C[:k, k + i]
                scale = np.sqrt(np.diag(G))
                scale[scale == 0.0] = 1.0
                scaled, *_ = np.linalg.lstsq(G / np.outer(scale, scale), b / scale, rcond=None)
                coef[:, i] = scaled / scale
            intercepts = mean[:, k:] - mean[:, :k] @ coef  # (n_rel, n)
            sq, count = 0.0, 0
            for z, bounds, c, w in zip(Z, self._fold_bounds, intercepts, self.weights,
                                       strict=True):
                held = z[bounds[fold]:bounds[fold + 1]]
                e = w * (held[:, k:] - held[:, :k] @ coef - c)
                sq += float(np.sum(e**2))
                count += e.size
            errors[fold] = sq / count
        return errors

    @staticmethod
    def _folds(p: PreparedRelease) -> list[npt.NDArray[np.intp]]:
        """Split a release's search rows into folds of interleaved blocks, each one period long.

        Interleaving gives every fold the whole decay; one-period blocks keep neighbours together
        (shorter below N_FOLDS periods). Each release's first period is in fold 0: too few lags
        show at the largest amplitudes (dealt round-robin, one lag tied two on the demo's runs).
        """
        t = p.view("search").t
        period = min(1.0 / float(p.fit.frequencies.min()), float(t[-1] - t[0]) / N_FOLDS)
        labels = (np.floor((t - t[0]) / period).astype(int)) % N_FOLDS
        return [np.flatnonzero(labels == k) for k in range(N_FOLDS)]

    def polished(self, candidate: Candidate) -> Candidate:
        """Return the candidate with its lag roots searched again at full precision."""
        if candidate.n_lags == 0:
            return candidate
        # The candidate's roots are already the coarse rows' optimum: converge from there.
        theta = self._precise(candidate.with_A3, np.log(np.array(candidate.d)))
        return dataclasses.replace(candidate, d=tuple(float(x) for x in np.sort(np.exp(theta))))

    def final(self, chosen: Candidate) -> FinalFit:
        """Fit the chosen structure on every sample; return the model's arrays and statistics."""
        d = np.array(chosen.d)
        condition = self.condition(d, chosen.with_A3)
        coef, residuals = self._full_fit(d, chosen.with_A3, condition)
        terms = [0, 1, 2] if chosen.with_A3 else [0, 1]
        terms += [3 + l for l in range(d.size)]
        n = self.n
        A = np.zeros((3 + d.size, n, n))
        index: list[tuple[int, int, int]] = []
        for i in range(n):
            for col, (term, j) in enumerate((t, j) for t in terms for j in range(n)):
                A[term, i, j] = coef[col, i]
                index.append((term, i, j))
        release_residuals = np.array([
            np.sqrt(np.mean((r / w) ** 2, axis=0))
            / np.sqrt(np.mean(p.view("full").force ** 2, axis=0))
            for r, w, p in zip(residuals, self.weights, self.prepared, strict=True)
        ])
        inflation = autocorrelation_inflation(residuals)
        return FinalFit(
            A=A, d=d, with_A3=chosen.with_A3,
            covariance=self._covariance(d, chosen.with_A3, coef, residuals, inflation),
            parameter_index=tuple(index), release_residuals=release_residuals,
            condition_number=condition, residual_inflation=inflation)

    def _full_fit(self, d: FloatArray, with_A3: bool, condition: float
                  ) -> tuple[FloatArray, list[FloatArray]]:
        """Coefficients (k, n_dof) and weighted residuals per release of the fit on every sample.

        A design whose condition number (``condition``, of the search rows: an even subsample
        of the same decays) is below ``NORMAL_EQUATIONS_CONDITION`` is solved by the
        column-scaled normal equations from each release's Gram matrix
        (:mod:`ident.identification._full_rows`), then one step of iterative refinement with the
        residual of every row: the normal equations' relative error, about ``eps cond^2`` (1e-8 at
        most here), shrinks by that factor again, to round-off, at a few matrix products instead of
        an SVD of every row per force channel. Other designs take the SVD-based solve of the stacked
        rows.
        """
        if not condition < NORMAL_EQUATIONS_CONDITION:
            coef, _, residuals = self._solve(self._blocks(d, with_A3, "full"), exact=True)
            return coef, residuals
        return self._full_rows(with_A3).fit(d)

    def _covariance(
        self, d: FloatArray, with_A3: bool, coef: FloatArray, residuals: list[FloatArray],
        inflation: float,
    ) -> FloatArray:
        """Gauss-Newton covariance of [A entries (force row 0, row 1, ...), log d].

        The residual variance and its autocorrelation inflation (``inflation``) come from the
        full-rate residuals; the curvature ``J^T J`` from the search subsample, scaled by the
        ratio of sample counts (the rows are an even subsample of the same decays).
        """
        blocks = self._blocks(d, with_A3, "search")
        k = coef.shape[0]
        n = self.n
        n_search = sum(X.shape[0] for X, _ in blocks)
        n_full = sum(r.shape[0] for r in residuals)
        # Linear part: block diagonal over the force rows.
        J_lin = np.zeros((n * n_search, n * k))
        for i in range(n):
            J_lin[i * n_search : (i + 1) * n_search, i * k : (i + 1) * k] = np.vstack(
                [-w[i] * (X - X.mean(axis=0))
                 for (X, _), w in zip(blocks, self.weights, strict=True)]
            )
        columns = [J_lin]
        # Nonlinear part: the residual's derivative in log d_l at fixed coefficients (the
        # intercepts re-profiled, so demeaned per release), from the lag columns' derivatives.
        derivatives = [p.view("search").lag_derivatives(d) for p in self.prepared]
        k_f = k - n * d.size
        for l in range(d.size):
            column = []
            for i in range(n):
                c = coef[k_f + n * l:k_f + n * l + n, i]
                for dL, w in zip(derivatives, self.weights, strict=True):
                    e = -(dL[:, n * l:n * l + n] @ c)
                    column.append(w[i] * (e - e.mean()))
            columns.append(np.concatenate(column)[:, None])
        J = np.hstack(columns)
        r = np.concatenate([np.concatenate([res[:, i] for res in residuals]) for i in range(n)])
        dof = max(r.size - J.shape[1], 1)
        sigma2 = float(r @ r) / dof * inflation
        return np.asarray(sigma2 * np.linalg.pinv(J.T @ J) * n_search / n_full, dtype=float)


def _distinct(starts: list[FloatArray]) -> list[FloatArray]:
    """Return the starts without repeats (the search from a start is deterministic).

    With one lag, the evenly spread start is the middle one of the nested starts.
    """
    out: list[FloatArray] = []
    for start in starts:
        if not any(s.shape == start.shape and np.array_equal(s, start) for s in out):
            out.append(start)
    return out


def _same_optimum(a: Any, b: Any) -> bool:
    """Tell whether two loose lag-root searches ended at one optimum (roots 1 %, cost 1e-4)."""
    roots_a, roots_b = np.sort(a.x), np.sort(b.x)  # log d
    return bool(np.all(np.abs(roots_a - roots_b) <= 1e-2)
                and abs(a.cost - b.cost) <= 1e-4 * max(a.cost, b.cost))
