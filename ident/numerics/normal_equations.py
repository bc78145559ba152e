"""Column-scaled normal equations of stacked least-squares problems (E2RFC's structure search).

The lag-root search evaluates the variable-projection residual and Jacobian hundreds of times:
its design is a split matrix (:class:`SplitDesign`) and its column-scaled normal equations are
solved for every force channel at once (:class:`ScaledSolver` over :class:`PseudoInverse`).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["PseudoInverse", "ScaledSolver", "SplitDesign"]

FloatArray = npt.NDArray[np.float64]


class SplitDesign:
    """The design ``[F, L]`` (fixed and lag columns) as its two parts, never copied into one.

    Its products are the two parts' products: on every sample the design is 10^5 rows, and
    joining the parts cost more than the products themselves.
    """

    def __init__(self, F: FloatArray, L: FloatArray) -> None:
        self.F, self.L = F, L
        self.k_f = F.shape[1]
        self.shape = (F.shape[0], F.shape[1] + L.shape[1])

    def __matmul__(self, M: FloatArray) -> FloatArray:
        """``[F, L] @ M``."""
        return np.asarray(self.F @ M[:self.k_f] + self.L @ M[self.k_f:], dtype=float)

    def transpose_times(self, M: FloatArray) -> FloatArray:
        """``[F, L]^T @ M``."""
        return np.concatenate([self.F.T @ M, self.L.T @ M])


class PseudoInverse:
    """Minimum-norm solves with a batch of symmetric positive semi-definite matrices.

    The same solution as ``np.linalg.lstsq(G, b, rcond=None)`` (eigenvalues below ``eps k``
    times the largest are dropped, as ``lstsq`` drops singular values), from one symmetric
    eigendecomposition of every force channel's normal matrix: the residual and the Jacobian
    of the lag-root search then solve with the same factors instead of four ``lstsq`` calls.
    """

    def __init__(self, G: FloatArray) -> None:
        values, self.vectors = np.linalg.eigh(G)  # (c, k), (c, k, k)
        largest = np.abs(values).max(axis=1, keepdims=True)
        keep = np.abs(values) > np.finfo(float).eps * G.shape[-1] * largest
        self.inverse = np.where(keep, 1.0 / np.where(keep, values, 1.0), 0.0)

    def apply(self, b: FloatArray) -> FloatArray:
        """Solve for right-hand sides ``b`` of shape (c, k) or (c, k, m)."""
        vectors, inverse = self.vectors, self.inverse
        if b.ndim == 2:
            projected = np.einsum("cki,ck->ci", vectors, b)
            return np.asarray(np.einsum("cik,ck->ci", vectors, inverse * projected))
        projected = np.einsum("cki,ckm->cim", vectors, b)
        return np.asarray(np.einsum("cik,ckm->cim", vectors, inverse[:, :, None] * projected))

    def apply_one(self, channel: int, b: FloatArray) -> FloatArray:
        """Solve one channel's system for ``b`` of shape (k,) or (k, m)."""
        vectors = self.vectors[channel]
        inverse = self.inverse[channel] if b.ndim == 1 else self.inverse[channel][:, None]
        return np.asarray(vectors @ (inverse * (vectors.T @ b)), dtype=float)


class ScaledSolver:
    """Minimum-norm solves of every force channel's normal equations, columns scaled first.

    Each normal matrix is scaled to a unit diagonal (columns of a zero norm keep a scale of 1)
    before :class:`PseudoInverse`: the lag columns and the fixed ones differ by orders of
    magnitude, and the eigenvalue cut-off must not depend on their units.

    Parameters
    ----------
    G : ndarray, shape (c, k, k)
        The channels' normal matrices.
    """

    def __init__(self, G: FloatArray) -> None:
        scale = np.sqrt(np.diagonal(G, axis1=1, axis2=2)).copy()  # (c, k)
        scale[scale == 0.0] = 1.0
        self.scale = scale
        self.inverse = PseudoInverse(G / (scale[:, :, None] * scale[:, None, :]))

    def solve(self, b: FloatArray) -> FloatArray:
        """Solve every channel for ``b`` of shape (c, k) or (c, k, m)."""
        scale = self.scale if b.ndim == 2 else self.scale[:, :, None]
        return np.asarray(self.inverse.apply(b / scale) / scale, dtype=float)

    def solve_one(self, channel: int, b: FloatArray) -> FloatArray:
        """Solve one channel for ``b`` of shape (k,) or (k, m)."""
        scale = self.scale[channel] if b.ndim == 1 else self.scale[channel][:, None]
        return self.inverse.apply_one(channel, b / scale) / scale
