"""Clocks for the virtual tunnel and the simulated instruments.

The tunnel runs on one true time base; each simulated instrument reads it through its own
:class:`DeviceClock`, with a configurable offset and drift, so that the acquisition's clock mapping
can be tested against a known truth. :class:`ManualClock` lets tests advance time explicitly
instead of sleeping.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Protocol

__all__ = ["Clock", "DeviceClock", "ManualClock", "MonotonicClock"]


class Clock(Protocol):
    """A source of true time, s."""

    def now(self) -> float:
        """Return the current true time, s."""
        ...


class MonotonicClock:
    """Real time: ``time.monotonic()`` relative to the clock's creation."""

    def __init__(self) -> None:
        self._start = time.monotonic()

    @property
    def origin_s(self) -> float:
        """``time.monotonic()`` at the clock's creation, s: true time 0 on the host's clock."""
        return self._start

    def now(self) -> float:
        """Return seconds since creation."""
        return time.monotonic() - self._start


class ManualClock:
    """A clock that only moves when told to (deterministic tests)."""

    def __init__(self, start: float = 0.0) -> None:
        self._t = start
        self._lock = threading.Lock()

    def now(self) -> float:
        """Return the current manual time, s."""
        with self._lock:
            return self._t

    def advance(self, dt: float) -> None:
        """Move time forward by ``dt`` seconds (>= 0)."""
        if dt < 0:
            raise ValueError(f"a clock cannot go back: dt = {dt!r}")
        with self._lock:
            self._t += dt


@dataclass(frozen=True)
class DeviceClock:
    """An instrument's own clock: ``t_device = offset_s + (1 + drift_ppm 1e-6) t_true``.

    Parameters
    ----------
    offset_s : float
        Device time at true time 0, s.
    drift_ppm : float
        Rate error, parts per million (positive: the device clock runs fast).
    """

    offset_s: float = 0.0
    drift_ppm: float = 0.0

    def device_time(self, t_true: float) -> float:
        """Return the device time at true time ``t_true``, s."""
        return self.offset_s + (1.0 + 1e-6 * self.drift_ppm) * t_true

    def true_time(self, t_device: float) -> float:
        """Return the true time at device time ``t_device``, s (the inverse map)."""
        return (t_device - self.offset_s) / (1.0 + 1e-6 * self.drift_ppm)
