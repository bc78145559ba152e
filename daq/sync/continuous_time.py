"""Continuous host times for one device stream while its clock map keeps improving.

Responsibility: :class:`ContinuousTimeline` turns the device times of successive blocks into host
times through a :class:`~daq.sync.clock_map.ClockMap` that is refitted as evidence arrives, without
the refits showing up as steps in the stream.

Why: a clock map is re-solved every time an envelope window closes or an anchor arrives (every
0.5 s in the recorder). Each re-solve moves the map by the change of its estimate: early in a run
by up to a few tenths of a millisecond, later by microseconds. Mapped naively, block by block,
a forward move opens a spacing between two consecutive samples that the resampler must treat as
a gap (a NaN row in ``/entry/sync`` although no sample was lost), and a backward move makes
samples overlap (dropped from the sync view). Clock servos solve this by slewing instead of
stepping: the time scale is made continuous at the join and the correction is paid off at a
bounded rate. Here the rate is ``max_slew`` (1 % by default: a 1 ms correction is absorbed in
0.1 s of device time, and sample spacings change by at most 1 %, far inside the resampler's gap
tolerance of half a sample period). While a correction is being paid off the stream is off the
newest map by at most that correction, i.e. by what the old map was wrong by; it never makes
the alignment worse than not refitting would have.

A real discontinuity is never slewed over: a device-time gap (a lost sample, a device restart),
device time going backwards, or a correction larger than ``max_step_s`` (a map re-initialised
after :meth:`~daq.sync.clock_map.ClockMap.reset`) restarts the timeline on the map (counted in
:attr:`ContinuousTimeline.steps`).

Not responsible for: fitting the clock (:class:`~daq.sync.clock_map.ClockMap`), marking gaps (the
raw-stream gaps come from the drivers' counters).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["ContinuousTimeline"]

FloatArray = npt.NDArray[np.float64]


class ContinuousTimeline:
    """Map device times to host times, continuous across clock-map refits.

    Parameters
    ----------
    period_s : float
        Nominal sample period of the stream in device time, s. Consecutive samples further apart
        than ``max_gap_periods`` periods are a discontinuity.
    max_slew : float
        Largest rate at which a correction is paid off, s per device s (dimensionless, > 0 and
        < 0.5).
    max_step_s : float
        Corrections larger than this, s, are taken as a step (the timeline restarts on the map).
    max_gap_periods : float
        Device-time spacing, in periods, beyond which two consecutive samples are not
        contiguous.

    Examples
    --------
    >>> tl = ContinuousTimeline(period_s=0.01)
    >>> first = tl.map(np.array([0.0, 0.01]), lambda t: t + 1.0)
    >>> second = tl.map(np.array([0.02, 0.03]), lambda t: t + 1.001)  # the map moved by 1 ms
    >>> round(float(second[0] - first[-1]), 9)  # still one period after the previous sample
    0.0101
    >>> round(tl.correction_s, 9)  # what is left to pay off after this block
    -0.0008
    """

    def __init__(self, period_s: float, *, max_slew: float = 0.01, max_step_s: float = 0.05,
                 max_gap_periods: float = 1.5) -> None:
        for name, value in (("period_s", period_s), ("max_step_s", max_step_s),
                            ("max_gap_periods", max_gap_periods)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
        if not (isinstance(max_slew, (int, float)) and 0.0 < max_slew < 0.5):
            raise ValueError(f"max_slew must be in (0, 0.5), got {max_slew!r}")
        self.period_s = float(period_s)
        self.max_slew = float(max_slew)
        self.max_step_s = float(max_step_s)
        self.max_gap_periods = float(max_gap_periods)
        self._last_device: float | None = None
        self._version: int | None = None  # the map version of the last block
        self._last_host = math.nan
        #: Correction still being paid off after the last block, s (host = map + correction).
        self.correction_s = 0.0
        #: Discontinuities at which the timeline restarted on the map (not slewed).
        self.steps = 0
        #: Largest correction slewed so far, s (absolute).
        self.largest_slewed_s = 0.0

    def restart(self) -> None:
        """Forget the previous block: the next one starts on the map (a known discontinuity)."""
        self._last_device = None
        self._version = None
        self.correction_s = 0.0

    def map(self, t_device: Any, to_host: Callable[[FloatArray], FloatArray], *,
            version: int | None = None) -> FloatArray:
        """Host times of one block's samples.

        Parameters
        ----------
        t_device : array_like, shape (n,)
            Device times of the block, s, finite and increasing.
        to_host : callable
            The current clock map (device s -> host s), e.g. ``ClockMap.to_host``.
        version : int, optional
            The map's version (``ClockMap.version``): under the version of the previous block,
            with nothing left to pay off, the previous sample is where the map put it, and is
            not mapped again.

        Returns
        -------
        ndarray, shape (n,)
            Host times, s: the map's, plus a correction that keeps the stream continuous with the
            previous block and shrinks at ``max_slew``.
        """
        t = np.asarray(t_device, dtype=np.float64).reshape(-1)
        mapped = np.asarray(to_host(t), dtype=np.float64)
        if t.size == 0:
            return mapped
        correction = 0.0
        last = self._last_device
        if last is not None:
            spacing = float(t[0]) - last
            if 0.0 < spacing <= self.max_gap_periods * self.period_s:
                # Where the previous sample is on the new map, and where it was put.
                if version is not None and version == self._version and self.correction_s == 0.0:
                    moved = 0.0  # the same map put it there: to_host(last) == _last_host
                else:
                    moved = self._last_host - float(to_host(np.array([last]))[0])
                if abs(moved) <= self.max_step_s:
                    correction = moved
                    self.largest_slewed_s = max(self.largest_slewed_s, abs(moved))
                else:
                    self.steps += 1
            else:
                self.steps += 1
        if correction == 0.0 and float(t[0]) <= float(t.min()):
            out = mapped  # nothing to pay off (the usual case between refits)
        else:
            # Paid off from the previous sample on (the first sample already pays for its
            # spacing).
            origin = last if last is not None else float(t[0])
            remaining = np.maximum(abs(correction) - self.max_slew * (t - origin), 0.0)
            out = mapped + math.copysign(1.0, correction) * remaining
        self._last_device = float(t[-1])
        self._version = version
        self._last_host = float(out[-1])
        self.correction_s = float(out[-1] - mapped[-1])
        return out
