"""Small input checks shared by the public constructors of :mod:`ident`.

Each check raises ``ValueError`` (or ``TypeError`` for wrong kinds) with a message that names the
offending field, so that a user reading the traceback knows what to fix without opening the code.
"""

from __future__ import annotations

import math
import operator
from dataclasses import MISSING, fields
from typing import Any

import numpy as np
import numpy.typing as npt


def positive(name: str, value: Any) -> float:
    """Return ``value`` as a float after checking that it is finite and > 0."""
    x = finite(name, value)
    if not x > 0.0:
        raise ValueError(f"{name} must be > 0, got {x!r}")
    return x


def finite(name: str, value: Any) -> float:
    """Return ``value`` as a float after checking that it is a finite real number."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"{name} must be finite, got {x!r}")
    return x


def in_range(name: str, value: Any, lo: float, hi: float, *, hi_open: bool = True) -> float:
    """Return ``value`` as a float after checking ``lo <= value < hi`` (``<= hi`` if closed)."""
    x = finite(name, value)
    ok = lo <= x < hi if hi_open else lo <= x <= hi
    if not ok:
        bracket = ")" if hi_open else "]"
        raise ValueError(f"{name} must be in [{lo}, {hi}{bracket}, got {x!r}")
    return x


def finite_array(name: str, value: Any, *, ndim: int | None = None) -> npt.NDArray[np.float64]:
    """Return ``value`` as a float64 array after checking it is finite (and of ``ndim`` dims)."""
    if np.iscomplexobj(value):
        # np.asarray(..., dtype=float) would drop the imaginary part with only a warning.
        raise TypeError(f"{name} must be real, got a complex array")
    arr = np.asarray(value, dtype=float)
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name} must be a {ndim}-D array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = int(np.size(arr) - np.count_nonzero(np.isfinite(arr)))
        raise ValueError(f"{name} contains {bad} non-finite value(s) (NaN or inf)")
    return arr


def positive_array(name: str, value: Any, *, ndim: int | None = None) -> npt.NDArray[np.float64]:
    """Return ``value`` as a finite float64 array whose entries are all > 0."""
    arr = finite_array(name, value, ndim=ndim)
    if np.any(arr <= 0.0):
        raise ValueError(f"{name} must be > 0 everywhere, got minimum {float(arr.min())!r}")
    return arr


def grid_size(n_points: Any) -> int:
    """Validate the size of a wind-speed grid: an integer (Python or numpy) >= 20."""
    try:
        n = operator.index(n_points)
    except TypeError:
        raise ValueError(f"n_points must be an integer >= 20, got {n_points!r}") from None
    if n < 20:
        raise ValueError(f"n_points must be an integer >= 20, got {n_points!r}")
    return n


def checked_keys(cls: Any, data: dict[str, Any]) -> dict[str, Any]:
    """Return ``data`` after checking its keys against the fields of dataclass ``cls``.

    An unknown key raises ``TypeError``, a missing required one ``ValueError``; both name them.
    """
    names = {f.name for f in fields(cls)}
    unknown = set(data) - names
    if unknown:
        raise TypeError(f"unknown {cls.__name__} key(s): {sorted(unknown)}")
    required = {f.name for f in fields(cls) if f.default is MISSING}
    missing = required - set(data)
    if missing:
        raise ValueError(f"{cls.__name__} dict is missing key(s): {sorted(missing)}")
    return dict(data)
