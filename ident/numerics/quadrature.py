"""Trapezoid-rule weights on a grid that need not be even.

The deck's nodes (:mod:`ident.bridge`: mode-shape integrals along the deck, the modes'
equivalent masses) and the buffeting response's frequency grid are integrated by the
trapezoid rule as a weighted sum, ``int g dx = w @ g``, with the weights of
:func:`trapezoid_weights`.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["trapezoid_weights"]

FloatArray = npt.NDArray[np.float64]


def trapezoid_weights(x: npt.ArrayLike) -> FloatArray:
    """Return ``w`` with ``w @ g == numpy.trapezoid(g, x)``, in the unit of ``x``.

    Parameters
    ----------
    x : array_like, shape (n,)
        The grid, increasing.

    Returns
    -------
    ndarray, shape (n,)
        Half the step to each neighbour.
    """
    grid = np.asarray(x, dtype=float)
    w = np.zeros(grid.size)
    half = np.diff(grid) / 2.0
    w[:-1] += half
    w[1:] += half
    return w
