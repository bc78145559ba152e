"""Unwrapping of wrapping sample counters, and the gaps and backward steps they reveal.

Responsibility (the synchronised view of docs/reference/file_format.md): pure numerical code used by
the run writer

- :class:`CounterUnwrapper` / :func:`unwrap_counter` unwrap wrapping sample counters of any
  modulus and list the gaps (:class:`~daq.instruments.reading.Gap`, the one gap type of every
  stream) and the steps that are not forward
  (:class:`CounterStep`): nothing is dropped or invented silently;
- :func:`find_gaps` lists the gaps of a counter that is already unwrapped.

Not responsible for: reading devices, threads, queues or files (the acquisition engine feeds
arrays in and takes arrays out), nor the drivers' own counter and timestamp unwrapping (each
driver knows its device's restart rules; the helpers here are for streams that do not).

Conventions: times in seconds as float64 (device times, when given).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from daq.instruments.reading import Gap
from daq.sync.checks import float_1d, positive

__all__ = [
    "CounterStep",
    "CounterUnwrapper",
    "Unwrapped",
    "find_gaps",
    "unwrap_counter",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True)
class CounterStep:
    """A counter step that is not forward: a repeated sample, or the counter went back.

    Duplicates and reordering (UDP) or an unreported restart; the samples are kept and their
    unwrapped counter goes back by ``-step`` (0 for a repeat), for the caller to decide.

    Attributes
    ----------
    index : int
        Index, within the batch given to :meth:`CounterUnwrapper.process`, of the sample after
        the step.
    after_counter : int
        Unwrapped counter of the sample before the step.
    step : int
        Counter step, <= 0.
    """

    index: int
    after_counter: int
    step: int


@dataclass(frozen=True, eq=False)
class Unwrapped:
    """An unwrapped counter batch.

    Attributes
    ----------
    counter : ndarray of int64, shape (n,)
        Unwrapped counter, one per input sample (none dropped, none inserted).
    gaps : tuple of Gap
        Forward jumps larger than one.
    steps : tuple of CounterStep
        Repeats and backward steps.
    """

    counter: IntArray
    gaps: tuple[Gap, ...]
    steps: tuple[CounterStep, ...]


class CounterUnwrapper:
    """Unwrap a counter that counts modulo ``modulus``, batch by batch, and list its gaps.

    A step ``dc = (c_i - c_(i-1)) mod modulus`` is forward when ``1 <= dc < modulus -
    max_backstep``; ``dc - 1`` samples are then missing. A step of 0 is a repeat, and one of
    ``modulus - max_backstep`` or more is the counter going back (both reported as
    :class:`CounterStep`). A counter alone cannot see a gap of a whole number of periods; given
    the samples' device times and the nominal ``period_s``, the step is instead the one
    congruent to ``dc`` modulo ``modulus`` nearest to the elapsed time in periods: that adds
    the whole periods a long gap lost (as the ILD1420 sequencer does with its timestamp) and
    tells a backward step from a gap whatever their sizes.

    Parameters
    ----------
    modulus : int
        Counter period (e.g. ``2**18`` for the ILD1420, ``2**32`` for the MPS4264), >= 2.
    period_s : float, optional
        Nominal sample period, s, used with the device times given to :meth:`process`.
    max_backstep : int, optional
        Largest backward step told apart from a forward gap when there are no times; default
        ``modulus // 2``.
    """

    def __init__(self, modulus: int, *, period_s: float | None = None,
                 max_backstep: int | None = None) -> None:
        if isinstance(modulus, bool) or not isinstance(modulus, int) or modulus < 2:
            raise ValueError(f"modulus must be an integer >= 2, got {modulus!r}")
        back = modulus // 2 if max_backstep is None else max_backstep
        if isinstance(back, bool) or not isinstance(back, int) or not 0 <= back < modulus - 1:
            raise ValueError(f"max_backstep must be an integer in [0, {modulus - 1}), "
                             f"got {max_backstep!r}")
        self.modulus = modulus
        self.max_backstep = back
        self.period_s = None if period_s is None else positive("period_s", period_s)
        self._last: tuple[int, int, float] | None = None  # raw, unwrapped, device time

    def process(self, raw: Any, device_time: Any = None) -> Unwrapped:
        """Unwrap one batch (continuing from the previous one).

        Parameters
        ----------
        raw : array_like of int, shape (n,)
            Raw counter values, in ``[0, modulus)``.
        device_time : array_like, shape (n,), optional
            Device time of each sample, s; needs ``period_s``.
        """
        c = np.atleast_1d(np.asarray(raw))
        if c.ndim != 1 or (c.size and not np.issubdtype(c.dtype, np.integer)):
            raise ValueError(f"raw must be a 1-D integer array, got {c.dtype} {c.shape}")
        c = c.astype(np.int64)
        if c.size and (c.min() < 0 or c.max() >= self.modulus):
            raise ValueError(f"raw counter values must be in [0, {self.modulus}), got "
                             f"[{c.min()}, {c.max()}]")
        t: FloatArray | None = None
        if device_time is not None:
            if self.period_s is None:
                raise ValueError("device_time needs period_s (given at construction)")
            t = float_1d("device_time", device_time)
            if t.shape != c.shape:
                raise ValueError(f"device_time must have shape {c.shape}, got {t.shape}")
        if c.size == 0:
            return Unwrapped(np.zeros(0, np.int64), (), ())
        if self._last is None:
            prev_raw, prev_unwrapped, prev_t = int(c[0]), int(c[0]) - 1, math.nan
            first_is_start = True
        else:
            prev_raw, prev_unwrapped, prev_t = self._last
            first_is_start = False
        m = self.modulus
        dc = np.diff(np.concatenate(([prev_raw], c))) % m
        # Without times: a step below modulus - max_backstep is forward, the rest went back.
        step = np.where(dc < m - self.max_backstep, dc, dc - m)
        if t is not None:
            assert self.period_s is not None
            # With times: the step congruent to dc (mod modulus) nearest to the elapsed periods.
            # It resolves gaps of whole counter periods, backward steps and coarse timestamps.
            expected = np.diff(np.concatenate(([prev_t], t))) / self.period_s
            timed = np.isfinite(expected)
            wraps = np.round((expected[timed] - dc[timed]) / m).astype(np.int64)
            step[timed] = dc[timed] + m * wraps
        if first_is_start:
            step[0] = 1
        unwrapped = prev_unwrapped + np.cumsum(step)
        before = np.concatenate(([prev_unwrapped], unwrapped[:-1]))
        gaps = tuple(Gap(int(before[i]), int(step[i] - 1)) for i in np.flatnonzero(step > 1))
        steps = tuple(CounterStep(int(i), int(before[i]), int(step[i]))
                      for i in np.flatnonzero(step <= 0))
        last_t = math.nan if t is None else float(t[-1])
        self._last = (int(c[-1]), int(unwrapped[-1]), last_t)
        return Unwrapped(unwrapped.astype(np.int64), gaps, steps)


def unwrap_counter(raw: Any, modulus: int, *, device_time: Any = None,
                   period_s: float | None = None) -> Unwrapped:
    """Unwrap a whole counter record at once (see :class:`CounterUnwrapper`).

    Examples
    --------
    >>> u = unwrap_counter([65534, 65535, 0, 3, 4], 65536)
    >>> u.counter.tolist(), u.gaps
    ([65534, 65535, 65536, 65539, 65540], (Gap(after_counter=65536, length=2, kind='missing'),))
    """
    return CounterUnwrapper(modulus, period_s=period_s).process(raw, device_time)


def find_gaps(counter: Any) -> list[Gap]:
    """Gaps of an already unwrapped, increasing counter (forward steps larger than one)."""
    c = np.atleast_1d(np.asarray(counter, dtype=np.int64))
    if c.ndim != 1:
        raise ValueError(f"counter must be 1-D, got shape {c.shape}")
    step = np.diff(c)
    if np.any(step <= 0):
        i = int(np.flatnonzero(step <= 0)[0])
        raise ValueError(f"counter is not increasing: {int(c[i])} then {int(c[i + 1])} "
                         f"at index {i + 1}")
    return [Gap(int(c[i]), int(step[i] - 1)) for i in np.flatnonzero(step > 1)]
