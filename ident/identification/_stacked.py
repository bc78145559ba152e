"""E2RFC's lag-root search problem on a set of rows: residual and Jacobian (private to ident).

The lag-root search (``ident.identification._e2rfc_problem.Problem.search``) minimises the weighted
force residual over ``log d`` with the linear coefficients projected out (variable projection); this
module evaluates that residual and its exact Jacobian on one view of the releases' rows.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from ident.identification._regressors import PreparedRelease
from ident.numerics.normal_equations import ScaledSolver, SplitDesign

__all__ = ["Stacked"]

FloatArray = npt.NDArray[np.float64]


class Stacked:
    """The weighted, release-demeaned residual over log(d) and its Jacobian, for one structure.

    The fixed columns (``q``, ``q'``, ``q''``) do not depend on the lag roots: their stacked,
    demeaned form and their normal-equation blocks are computed once; each evaluation adds only
    the lag columns. The channel weights are constant over a release, so the products of the
    demeaned fixed columns and forces with the lag columns are taken unweighted-times-``w**2``
    for every force channel in one matrix product (a demeaned column is orthogonal to a constant
    per release, so the lag columns need no demeaning there). The Jacobian is Golub and
    Pereyra's exact variable-projection form ``-(I - P) (dX/dlog d_l) c - X G^-1
    (dX/dlog d_l)^T r`` (``P`` the projection on the columns, ``G`` the normal matrix), for
    every lag at once: a few matrix products instead of a residual evaluation per lag.
    """

    def __init__(self, prepared: Sequence[PreparedRelease], weights: FloatArray, with_A3: bool,
                 which: str) -> None:
        self.views = [p.view(which) for p in prepared]
        sizes = np.array([v.t.size for v in self.views])
        self.starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        self.sizes = sizes
        self.release = np.repeat(np.arange(sizes.size), sizes)
        self.n = n = weights.shape[1]
        # (n_releases, N): row r averages release r's rows (for _demeaned).
        self._averaging = np.zeros((sizes.size, int(sizes.sum())))
        for r, (start, size) in enumerate(zip(self.starts, sizes, strict=True)):
            self._averaging[r, start:start + size] = 1.0 / size
        self.w = weights[self.release]  # (N, n)
        self.w2 = self.w**2
        fixed = np.vstack([v.fixed if with_A3 else v.fixed[:, :2 * n] for v in self.views])
        y = np.vstack([v.force for v in self.views])
        self.Fc = self._demeaned(fixed)  # (N, k_f)
        self.yc = self._demeaned(y)  # (N, n)
        self.k_f = self.Fc.shape[1]
        # [F w0^2, F w1^2, ..., y w^2]: one product with the lag columns gives every cross block.
        self.W2FY = np.hstack([self.Fc * self.w2[:, i:i + 1] for i in range(n)]
                              + [self.yc * self.w2])
        self.Gff = [(self.Fc * self.w2[:, i:i + 1]).T @ self.Fc for i in range(n)]
        self.Fy = [self.W2FY[:, n * self.k_f + i] @ self.Fc for i in range(n)]
        self._cache: tuple[bytes, Any] | None = None

    def _demeaned(self, X: FloatArray, *, in_place: bool = False) -> FloatArray:
        """Return ``X`` with each release's mean removed (in place for a fresh array).

        The means are one matrix product with the averaging matrix (``_averaging``): a mean
        along the rows of a few columns is a slow reduction in numpy, a product is not.
        """
        out = X if in_place else np.array(X, dtype=float)
        means = self._averaging @ out
        for mean, start, size in zip(means, self.starts, self.sizes, strict=True):
            out[start:start + size] -= mean  # in place: no repeated copy of the means
        return out

    def _evaluate(self, theta: FloatArray) -> Any:
        key = theta.tobytes()
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        d = np.exp(theta)
        L = self._demeaned(np.vstack([v.lag_columns(d) for v in self.views]), in_place=True)
        k_f, n = self.k_f, self.n
        cross = self.W2FY.T @ L  # (n k_f + n, n m)
        X = SplitDesign(self.Fc, L)
        k = X.shape[1]
        G = np.empty((n, k, k))
        b = np.empty((n, k))
        for i in range(n):
            FL = cross[i * k_f:(i + 1) * k_f]
            G[i, :k_f, :k_f] = self.Gff[i]
            G[i, :k_f, k_f:] = FL
            G[i, k_f:, :k_f] = FL.T
            G[i, k_f:, k_f:] = (L * self.w2[:, i:i + 1]).T @ L
            b[i] = np.concatenate([self.Fy[i], cross[n * k_f + i]])
        solver = ScaledSolver(G)
        coef = solver.solve(b).T  # (k, n)
        residual = self.w * (self.yc - X @ coef)  # (N, n), weighted
        out = (d, X, coef, residual, solver)
        self._cache = (key, out)
        return out

    def residual(self, theta: FloatArray) -> FloatArray:
        """Weighted residuals of every force channel, stacked."""
        residual = self._evaluate(theta)[3]
        return np.asarray(residual.T.ravel(), dtype=float)

    def jacobian(self, theta: FloatArray) -> FloatArray:
        """Kaufman's variable-projection Jacobian over log(d), shape (n_dof N, m)."""
        d, X, coef, residual, solver = self._evaluate(theta)
        dL = self._demeaned(np.vstack([v.lag_derivatives(d) for v in self.views]), in_place=True)
        m, n = d.size, self.n
        N, k = X.shape
        lag0 = k - n * m
        rhs = np.empty((n, k, m))
        V = np.empty((n, N, m))
        for i in range(n):
            lag_coef = coef[lag0:, i].reshape(m, n)
            # Column l: the derivative of the fitted force in log d_l (unweighted).
            V[i] = np.einsum("nlc,lc->nl", dL.reshape(N, m, n), lag_coef)
            rhs[i] = X.transpose_times(V[i] * self.w2[:, i:i + 1])  # (k, m)
            # Golub and Pereyra's full Jacobian: -(I - P) dX c - X G^-1 dX^T r.
            dXr = (dL.T @ (residual[:, i] * self.w[:, i])).reshape(m, n)
            for l in range(m):
                rhs[i, lag0 + n * l:lag0 + n * l + n, l] -= dXr[l]
        solved = solver.solve(rhs)  # (n, k, m)
        J = np.empty((n * N, m))
        for i in range(n):
            J[i * N:(i + 1) * N] = -self.w[:, i:i + 1] * (V[i] - X @ solved[i])
        return J
