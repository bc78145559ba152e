"""Small statistics shared by the identification modules."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

__all__ = ["autocorrelation_inflation", "white_noise_std"]

FloatArray = npt.NDArray[np.float64]


def white_noise_std(x: npt.ArrayLike) -> FloatArray:
    """Return the std of the white noise in ``x``, per column, from its third differences.

    Third differences of white noise of variance ``s^2`` have variance ``20 s^2``; a signal
    slow against the sampling rate reaches them only as ``(2 pi f dt)^3`` of its size, so the
    noise of a record sampled well above its content is read without a model of the rest.
    ``x`` has samples along its first axis (at least four).
    """
    return np.asarray(np.std(np.diff(x, 3, axis=0), axis=0) / math.sqrt(20.0), dtype=float)


def autocorrelation_inflation(residuals: list[FloatArray]) -> float:
    """Variance inflation ``1 + 2 sum (1 - k/(L+1)) rho_k`` (Bartlett window, L = 50 lags).

    Least-squares covariances assume white residuals; model error makes them coloured, and
    ignoring that would understate the uncertainty of the flutter speed.
    """
    factors = []
    L = 50
    for res in residuals:
        for e in res.T:
            e = e - e.mean()
            var = float(e @ e)
            if var == 0.0 or e.size <= 2 * L:
                continue
            rho = np.array([float(e[:-k] @ e[k:]) / var for k in range(1, L + 1)])
            factors.append(1.0 + 2.0 * float(np.sum((1 - np.arange(1, L + 1) / (L + 1)) * rho)))
    return max(1.0, float(np.median(factors))) if factors else 1.0
