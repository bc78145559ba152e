"""Small statistics shared by the identification modules."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["autocorrelation_inflation"]

FloatArray = npt.NDArray[np.float64]


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
