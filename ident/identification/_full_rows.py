"""E2RFC's work on every sample, from one Gram matrix per release (private to ident).

The lag-root search runs on subsampled rows; two steps use every sample (10^5 rows for five
30 s releases at 500 Hz): the Gauss-Newton step that moves the search rows' lag roots to the
full data's, and the final coefficients. Both need only sums over the rows of products of the
columns ``[fixed, lag columns, their derivatives in log d, forces]``. The channel weights are
constant over a release, so each release's unweighted Gram matrix of those columns (one matrix
product) gives every channel's weighted normal equations, the variable-projection Jacobian's
``J^T J`` and ``J^T r`` by small products: the Jacobian (10^5 rows per channel and lag) is
never formed. Every block is demeaned per release first (the intercepts are profiled out), so
no sum cancels more than the signal-to-noise ratio of the forces.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from ident.identification._regressors import PreparedRelease
from ident.numerics.normal_equations import ScaledSolver, SplitDesign

__all__ = ["FullRows"]

FloatArray = npt.NDArray[np.float64]


def _demeaned(X: FloatArray) -> FloatArray:
    """Return ``X`` minus its column means (a product: numpy's column mean is a slow reduction)."""
    return np.asarray(X - (np.ones(X.shape[0]) @ X) / X.shape[0], dtype=float)


class FullRows:
    """Every sample of every release, for one structure family (with or without A3).

    Parameters
    ----------
    prepared : sequence of PreparedRelease
        The releases (their ``"full"`` views).
    weights : ndarray, shape (n_releases, n)
        Each release's force-channel weights (one over the channel's noise level).
    with_A3 : bool
        Whether the added-mass columns ``(B/U)^2 q''`` are in the design.
    """

    def __init__(self, prepared: Sequence[PreparedRelease], weights: FloatArray,
                 with_A3: bool) -> None:
        self.n = n = weights.shape[1]
        self.views = [p.view("full") for p in prepared]
        self.w2 = weights**2  # (n_releases, n)
        self.weights = weights
        self.fixed = [_demeaned(v.fixed if with_A3 else v.fixed[:, :2 * n]) for v in self.views]
        self.force = [_demeaned(v.force) for v in self.views]
        self.k_f = self.fixed[0].shape[1]
        # [F, y] per release and its Gram matrix: they do not depend on the lag roots.
        self._fixed_force = [np.hstack([F, y]) for F, y in zip(self.fixed, self.force,
                                                                 strict=True)]
        self._fixed_force_gram = [Z.T @ Z for Z in self._fixed_force]

    def _weighted_grams(self, d: FloatArray, derivatives: bool
                        ) -> tuple[FloatArray, list[FloatArray]]:
        """Per channel, the weighted Gram matrix of ``[F, L(, dL), y]`` (n, c, c); the lags.

        ``L`` are the demeaned lag columns at roots ``d`` (per release, returned for reuse),
        ``dL`` their derivatives in ``log d``. Assembled from blocks: ``[F, y]``'s Gram is
        fixed, and joining every column of 10^5 rows again per call cost more than the products.
        """
        lags = [_demeaned(v.lag_columns(d)) for v in self.views]
        k_f, n = self.k_f, self.n
        grams = []
        for L, view, Z, ZZ in zip(lags, self.views, self._fixed_force, self._fixed_force_gram,
                                  strict=True):
            A = np.hstack([L, _demeaned(view.lag_derivatives(d))]) if derivatives else L
            a = A.shape[1]
            ZA, AA = Z.T @ A, A.T @ A
            Q = np.empty((k_f + a + n, k_f + a + n))
            # Order [F, A, y]: F and y from [F, y]'s rows and columns, A in between.
            fy = np.r_[0:k_f, k_f + a:k_f + a + n]
            Q[np.ix_(fy, fy)] = ZZ
            Q[fy, k_f:k_f + a] = ZA
            Q[k_f:k_f + a, fy] = ZA.T
            Q[k_f:k_f + a, k_f:k_f + a] = AA
            grams.append(Q)
        return np.tensordot(self.w2.T, np.array(grams), axes=1), lags

    def gauss_newton_step(self, theta: FloatArray) -> FloatArray:
        """Gauss-Newton step in ``log d`` of the variable-projection problem on every sample."""
        JtJ, Jtr = self._normal_form(theta)
        step, *_ = np.linalg.lstsq(JtJ, -Jtr, rcond=None)
        return np.asarray(step, dtype=float)

    def _normal_form(self, theta: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``J^T J`` and ``J^T r`` of the weighted residual on every sample.

        ``J`` is Golub and Pereyra's variable-projection Jacobian
        (``ident.identification._stacked.Stacked.jacobian``). Per channel, with ``V = dL C`` the
        fitted force's derivative (``C`` the lag coefficients, one column per lag), ``e = dL^T W r``
        and
        ``s = G^+ (X^T W V - E)`` (``E`` places each lag's ``e`` block in its own column):
        ``J^T J = C^T (dL^T W dL) C - 2 sym(C^T (X^T W dL)^T s) + s^T G s`` and
        ``J^T r = -(C^T e - s^T X^T W r)``, summed over the channels.

        Measured against the formed Jacobian: the same Gauss-Newton step to 1e-13 where the
        problem is nearly quadratic; only to 1e-6 relative for two nearly merged roots, whose
        step is too large to take (``MAX_ONE_STEP``). Those are converged with the formed
        residual and Jacobian: a Levenberg-Marquardt search on these sums stalled in their
        valley, at a cost 2e-5 above its floor, because the small eigenvalue of ``J^T J`` that
        separates the two roots is lost to cancellation here.
        """
        d = np.exp(theta)
        m, n, k_f = d.size, self.n, self.k_f
        k = k_f + n * m
        Q, _ = self._weighted_grams(d, derivatives=True)
        JtJ = np.zeros((m, m))
        Jtr = np.zeros(m)
        solver = ScaledSolver(Q[:, :k, :k])
        for i in range(n):
            G = Q[i, :k, :k]
            XD = Q[i, :k, k:k + n * m]
            DD = Q[i, k:k + n * m, k:k + n * m]
            y = k + n * m + i
            b, Dy = Q[i, :k, y], Q[i, k:k + n * m, y]
            coef = solver.solve_one(i, b)
            C = np.zeros((n * m, m))  # lag l's coefficients in column l
            for l in range(m):
                C[n * l:n * l + n, l] = coef[k_f + n * l:k_f + n * l + n]
            e = Dy - XD.T @ coef  # dL^T W r
            rhs = XD @ C
            for l in range(m):
                rhs[k_f + n * l:k_f + n * l + n, l] -= e[n * l:n * l + n]
            s = solver.solve_one(i, rhs)
            cross = C.T @ XD.T @ s
            JtJ += C.T @ DD @ C - cross - cross.T + s.T @ G @ s
            Jtr -= C.T @ e - s.T @ (b - G @ coef)
        return JtJ, Jtr

    def fit(self, d: FloatArray) -> tuple[FloatArray, list[FloatArray]]:
        """Coefficients (k, n) and weighted residuals per release at lag roots ``d``.

        The column-scaled normal equations, then one step of iterative refinement with the
        residual of every row: the normal equations' relative error, about ``eps cond^2``,
        shrinks by that factor again, to round-off.
        """
        Q, lags = self._weighted_grams(d, derivatives=False)
        k = Q.shape[1] - self.n
        solver = ScaledSolver(Q[:, :k, :k])
        b = np.stack([Q[i, :k, k + i] for i in range(self.n)])  # (n, k)
        coef = solver.solve(b).T  # (k, n)
        designs = [SplitDesign(F, L) for F, L in zip(self.fixed, lags, strict=True)]
        rhs = np.zeros((self.n, k))
        for X, y, w2 in zip(designs, self.force, self.w2, strict=True):
            rhs += w2[:, None] * X.transpose_times(y - X @ coef).T  # unweighted error
        coef = coef + solver.solve(rhs).T
        residuals = [w * (y - X @ coef)
                     for X, y, w in zip(designs, self.force, self.weights, strict=True)]
        return coef, residuals
