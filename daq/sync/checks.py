"""Argument checks the synchronisation modules share.

Responsibility: the checks :mod:`daq.sync.clock_map`, :mod:`daq.sync.resample` and
:mod:`daq.sync.counters` run on their inputs (:func:`float_1d`, :func:`positive`), raising
``ValueError`` with the argument's name. Their error for a step that cannot give an answer,
:class:`~daq.errors.SyncError`, is in :mod:`daq.errors` with every other error of daq.

Not responsible for: any synchronisation step itself.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["float_1d", "positive"]

FloatArray = npt.NDArray[np.float64]


def float_1d(name: str, value: Any) -> FloatArray:
    """Return ``value`` as a 1-D float64 array (a scalar becomes one element)."""
    if type(value) is np.ndarray and value.dtype == np.float64 and value.ndim == 1:
        return value  # already one (the usual call, from the run writer): nothing to check
    arr = np.atleast_1d(np.asarray(value, dtype=np.float64))
    if arr.ndim != 1:
        raise ValueError(f"{name} must be a scalar or 1-D, got shape {arr.shape}")
    return arr


def positive(name: str, value: Any) -> float:
    """Return ``value`` as a float, checked finite and > 0."""
    x = float(value)
    if not (math.isfinite(x) and x > 0.0):
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return x
