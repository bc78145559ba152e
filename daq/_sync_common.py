"""What the synchronisation modules share: their error type and argument checks.

Responsibility: :class:`SyncError`, the error of a synchronisation step that cannot give an
answer (raised by :mod:`daq.clock_map` and :mod:`daq.resample`), and the argument checks those
modules and :mod:`daq.counters` run on their inputs (:func:`_float_1d`, :func:`_positive`).

Not responsible for: any synchronisation step itself. Private: import :class:`SyncError` from
:mod:`daq.sync`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from daq.errors import DaqError

__all__ = ["SyncError"]

FloatArray = npt.NDArray[np.float64]


class SyncError(DaqError, ValueError):
    """A synchronisation step cannot give an answer (e.g. a clock map with no data yet)."""


def _float_1d(name: str, value: Any) -> FloatArray:
    arr = np.atleast_1d(np.asarray(value, dtype=np.float64))
    if arr.ndim != 1:
        raise ValueError(f"{name} must be a scalar or 1-D, got shape {arr.shape}")
    return arr


def _positive(name: str, value: Any) -> float:
    x = float(value)
    if not (math.isfinite(x) and x > 0.0):
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return x
