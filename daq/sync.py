r"""Synchronisation of the device streams onto the host clock, and the synchronised view.

Responsibility (DESIGN.md, "Synchronisation"): pure numerical code used by the acquisition engine

- :class:`ClockMap` maps one device clock onto the host clock, ``t_host = a + b t_device``, fitted
  robustly from every block's (device time, host arrival time) pair and from anchor events seen
  by both clocks (trigger pulses, the release), and updated during the run in bounded memory;
- :class:`CounterUnwrapper` / :func:`unwrap_counter` unwrap wrapping sample counters of any
  modulus and list the gaps (:class:`Gap`) and the steps that are not forward
  (:class:`CounterStep`): nothing is dropped or invented silently;
- :class:`Resampler` / :func:`resample` put several host-mapped streams onto one uniform time base
  (the ``/entry/sync`` view), block by block, marking gaps as NaN;
- the physical conversions of the sync view: :func:`heave_pitch_from_lasers`,
  :func:`forces_from_pressures`, :func:`wind_speed`, :func:`air_density`.

Not responsible for: reading devices, threads, queues or files (the acquisition engine feeds
arrays in and takes arrays out), the drivers' own counter and timestamp unwrapping (each driver
knows its device's restart rules; the helpers here are for streams that do not), nor the choice of
which events are anchors (the engine pairs a PLC pulse with what each device saw of it).

Conventions: SI units; times in seconds as float64. Host times are best passed relative to the run
start (``(host_time_ns - run_start_ns) * 1e-9``): then the sync view's ``time`` is "s from run
start" (DESIGN.md, "HDF5 file") and :attr:`ClockMap.offset_s` is the device time at the run start.
The clock convention is that of :class:`simulators.clock.DeviceClock`:
``t_device = offset_s + (1 + drift_ppm 1e-6) t_host``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final, NamedTuple, overload

import numpy as np
import numpy.typing as npt

from daq.errors import DaqError
from daq.vaisala_ptb330 import PRESSURE_RANGE_PA, R_DRY_AIR, TEMPERATURE_RANGE_K
from ident.taps import TapLayout

__all__ = [
    "ClockMap",
    "CounterStep",
    "CounterUnwrapper",
    "Gap",
    "HeavePitch",
    "Resampler",
    "StreamSpec",
    "SyncBlock",
    "SyncError",
    "Unwrapped",
    "WindSpeed",
    "air_density",
    "find_gaps",
    "forces_from_pressures",
    "heave_pitch_from_lasers",
    "resample",
    "trigger_times_from_flags",
    "trigger_times_from_latch",
    "unwrap_counter",
    "wind_speed",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

#: Scale from the median absolute deviation to the standard deviation of a normal distribution.
_MAD_TO_SIGMA: Final = 1.4826


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


#: Points used by :func:`_theil_sen_slope` (more are thinned evenly): 7140 pairs.
_MAX_SLOPE_POINTS = 120


def _weighted_median(values: FloatArray, weights: FloatArray) -> float:
    """Lower weighted median: the smallest value whose cumulative weight reaches half the total."""
    order = np.argsort(values, kind="stable")
    cum = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cum, 0.5 * cum[-1])])


def _theil_sen_slope(x: FloatArray, y: FloatArray) -> float:
    """Slope of y on x: the median of pairwise slopes weighted by the pairs' x separation.

    Weighting by ``|x_j - x_i|`` (Sievers 1978; the slope minimising
    ``sum |(y_j - y_i) - b (x_j - x_i)|``) lets the long-baseline pairs, whose slopes the
    per-point noise hardly moves, dominate the short ones; like the plain Theil-Sen estimator
    it ignores a minority of wild points (breakdown point about 29 %). Needs >= 2 distinct x.
    """
    if x.size > _MAX_SLOPE_POINTS:
        # All pairs of 600 points (a 5 min clock span) cost ~19 ms per refit; an even thinning
        # keeps the span (what the drift needs) and the robustness, at ~0.5 ms.
        keep = np.linspace(0, x.size - 1, _MAX_SLOPE_POINTS).round().astype(np.intp)
        x, y = x[keep], y[keep]
    i, j = np.triu_indices(x.size, 1)
    dx = x[j] - x[i]
    keep = dx != 0.0
    dx, dy = dx[keep], (y[j] - y[i])[keep]
    return _weighted_median(dy / dx, np.abs(dx))


# ------------------------------------------------------------------------------------------------
# Clock mapping
# ------------------------------------------------------------------------------------------------
class ClockMap:
    r"""Robust, incrementally updated map of one device clock onto the host clock.

    Model: ``t_host = a + b t_device`` over the recent past (a clock's rate changes slowly with
    temperature, so the fit covers a bounded span and follows it).

    Two kinds of evidence:

    1. Block pairs (:meth:`update`): the device time of a block's last sample and the host time
       the block arrived. Arrival is late by the transport latency ``L = L_min + jitter``, with
       a long one-sided tail (scheduling, USB polling, a stalled reader that then catches up in a
       burst). A least-squares fit of these pairs is late by the *mean* latency and is pulled by
       every outlier; a plain Theil-Sen fit is late by the *median* latency. The lower envelope
       is what carries the clock: this class keeps, per window of ``window_s`` device seconds,
       the pair of least latency (the lowest ``t_host - b_ref t_device``, with ``b_ref`` the
       current slope estimate so that drift within a window does not bias the choice), holds the
       last ``n_windows`` of these minima in a ring buffer, and fits them with a weighted
       Theil-Sen slope (:func:`_theil_sen_slope`) and the median intercept. The minimum over a
       window of ``N`` pairs with exponential jitter of mean ``mu`` is late by ``mu / N`` on
       average (``mu ln2 / N`` for the median over windows), i.e. microseconds; a window whose
       minimum is an early outlier (a corrupted device timestamp) is outvoted by the others.
       The envelope is still late by the latency floor ``L_min``, which no arrival-time
       statistic can tell apart from a clock offset.
    2. Anchors (:meth:`add_anchor`): events whose host time is known independently of the
       transport: the PLC's trigger pulse (seen by the scanner as its external-trigger time and
       by the lasers as the "value triggered" sample, see :func:`trigger_times_from_latch` and
       :func:`trigger_times_from_flags`) or the release. Each anchor measures the floor,
       ``L_min = envelope(t_device) - t_host``; the map uses the median over anchors (robust to
       one mis-paired pulse). Because the floor is a property of the transport, it is stored
       per anchor and frozen once the anchor is older than the fitted span, so old anchors keep
       counting after the envelope has moved on. Without anchors the floor is the
       ``assumed_floor_s`` given (0 by default: the map is then late by the true floor).

    The slope comes from the envelope (hundreds of pairs over minutes, against a few anchors);
    the anchors alone give it only while no block pair has been seen.

    Memory is fixed at construction: ``n_windows`` window minima and ``max_anchors`` anchors,
    whatever the run length. Call :meth:`reset` when the device clock is discontinuous (a
    device restart, a PTP lock step reported by the driver).

    Parameters
    ----------
    window_s : float
        Length of one envelope window in device time, s (> 0). Longer windows give lower minima
        (more pairs each) but fewer envelope points; 2 s holds ~100 laser blocks or 1000
        scanner frames.
    n_windows : int
        Windows held (>= 3): the fitted span is about ``window_s * n_windows`` (5 min by
        default), long enough to measure drift to well below 1 ppm, short enough to follow a
        thermal drift change.
    max_anchors : int
        Anchors held (>= 1); the oldest is forgotten first.
    assumed_floor_s : float
        Latency floor used while there is no anchor, s (>= 0), e.g. a measured USB latency.

    Examples
    --------
    >>> cm = ClockMap(window_s=1.0)
    >>> t_dev = np.arange(0.0, 60.0, 0.01)
    >>> cm.update(t_dev, 5.0 + t_dev * (1 - 20e-6) + 1e-4)  # arrivals 0.1 ms late
    >>> cm.add_anchor(30.0, 5.0 + 30.0 * (1 - 20e-6))
    >>> round(cm.drift_ppm, 3), round(cm.latency_floor_s, 9)
    (20.0, 0.0001)
    >>> abs(cm.to_host(10.0) - (5.0 + 10.0 * (1 - 20e-6))) < 1e-9
    True
    """

    def __init__(self, *, window_s: float = 2.0, n_windows: int = 150, max_anchors: int = 32,
                 assumed_floor_s: float = 0.0) -> None:
        self.window_s = _positive("window_s", window_s)
        if isinstance(n_windows, bool) or not isinstance(n_windows, int) or n_windows < 3:
            raise ValueError(f"n_windows must be an integer >= 3, got {n_windows!r}")
        if isinstance(max_anchors, bool) or not isinstance(max_anchors, int) or max_anchors < 1:
            raise ValueError(f"max_anchors must be an integer >= 1, got {max_anchors!r}")
        floor = float(assumed_floor_s)
        if not (math.isfinite(floor) and floor >= 0.0):
            raise ValueError(f"assumed_floor_s must be finite and >= 0, got {assumed_floor_s!r}")
        self.n_windows = n_windows
        self.max_anchors = max_anchors
        self.assumed_floor_s = floor
        self.reset()

    def reset(self) -> None:
        """Forget every pair and anchor (the device clock was discontinuous)."""
        # Times are stored relative to an origin (the first device and host time seen): a PTP
        # device time is ~1.7e9 s, whose float64 resolution (0.2 us) would otherwise eat into
        # the fit; relative values of minutes keep it at the femtosecond level.
        self._origin: tuple[float, float] | None = None
        self._windows = np.full((self.n_windows, 2), np.nan)  # ring: (d_rel, h_rel) minima
        self._n_closed = 0  # windows closed so far (the ring holds min(n, n_windows))
        self._open: tuple[int, float, float, float] | None = None  # id, d_rel, h_rel, key
        self._ref_slope = 1.0
        self._anchors = np.full((self.max_anchors, 3), np.nan)  # ring: d_rel, h_rel, floor
        self._n_anchors_total = 0
        self._envelope: tuple[float, float, float] | None = None  # slope, intercept, scatter
        self._map: tuple[float, float] | None = None
        self._n_pairs = 0

    # -- feeding ----------------------------------------------------------------------------------
    def update(self, t_device: Any, t_host: Any) -> None:
        """Add block pairs: device time of each block's last sample and its host arrival time.

        Parameters
        ----------
        t_device : float or array_like, shape (n,)
            Device times, s, in acquisition order.
        t_host : float or array_like, shape (n,)
            Host arrival times, s (same clock as every other host time given to this map).

        Raises
        ------
        ValueError
            Shapes differ, or a time is not finite (a pair without a time is not evidence).
        """
        d = _float_1d("t_device", t_device)
        h = _float_1d("t_host", t_host)
        if d.shape != h.shape:
            raise ValueError(f"t_device and t_host must have equal shapes, got {d.shape} and "
                             f"{h.shape}")
        if not (np.all(np.isfinite(d)) and np.all(np.isfinite(h))):
            bad = int(np.count_nonzero(~(np.isfinite(d) & np.isfinite(h))))
            raise ValueError(f"{bad} of {d.size} clock pairs are not finite")
        if d.size == 0:
            return
        if self._origin is None:
            self._origin = (float(d[0]), float(h[0]))
        d0, h0 = self._origin
        if d.size == 1:  # the recorder's case (one pair per block): the same, without arrays
            self._add_pair(float(d[0]) - d0, float(h[0]) - h0)
            return
        dr, hr = d - d0, h - h0
        ids = np.floor(dr / self.window_s).astype(np.int64)
        if self._open is not None:
            ids = np.maximum(ids, self._open[0])
        # A pair older than the open window (out-of-order blocks) joins the open window: a window
        # is only a bucket for picking the least-latency pair, and that pair keeps its own time.
        ids = np.maximum.accumulate(ids)
        starts = np.concatenate(([0], np.flatnonzero(np.diff(ids)) + 1, [ids.size]))
        for lo, hi in zip(starts[:-1], starts[1:], strict=True):
            wid = int(ids[lo])
            if self._open is not None and wid != self._open[0]:
                self._close_window()
            key = hr[lo:hi] - self._ref_slope * dr[lo:hi]
            k = int(np.argmin(key))
            if self._open is None or float(key[k]) < self._open[3]:
                self._open = (wid, float(dr[lo + k]), float(hr[lo + k]), float(key[k]))
        self._n_pairs += int(d.size)
        if self._n_closed < 2:  # the open window is part of the fit until two windows closed
            self._refit()

    def _add_pair(self, dr: float, hr: float) -> None:
        """Add one pair (relative times, s): :meth:`update`'s loop for a single pair."""
        wid = math.floor(dr / self.window_s)
        if self._open is not None:
            wid = max(wid, self._open[0])
            if wid != self._open[0]:
                self._close_window()
        key = hr - self._ref_slope * dr
        if self._open is None or key < self._open[3]:
            self._open = (wid, dr, hr, key)
        self._n_pairs += 1
        if self._n_closed < 2:
            self._refit()

    def add_anchor(self, t_device: float, t_host: float) -> None:
        """Add an event seen by the device at ``t_device`` that happened at host time ``t_host``.

        ``t_host`` may come from the host (the time the PLC pulsed the trigger line) or from
        another device's map (``other.to_host(t)`` for the release seen in both streams): a
        cross-device anchor ties this device to the other one.

        Parameters
        ----------
        t_device, t_host : float
            The event's device time and host time, s.
        """
        d, h = float(t_device), float(t_host)
        if not (math.isfinite(d) and math.isfinite(h)):
            raise ValueError(f"anchor times must be finite, got ({t_device!r}, {t_host!r})")
        if self._origin is None:
            self._origin = (d, h)
        d0, h0 = self._origin
        slot = self._n_anchors_total % self.max_anchors
        self._anchors[slot] = (d - d0, h - h0, self._floor_of(d - d0, h - h0))
        self._n_anchors_total += 1
        self._map = None

    # -- fitting ----------------------------------------------------------------------------------
    def _close_window(self) -> None:
        assert self._open is not None
        self._windows[self._n_closed % self.n_windows] = self._open[1:3]
        self._n_closed += 1
        self._open = None
        self._refit()

    def _points(self) -> FloatArray:
        held = self._windows[: min(self._n_closed, self.n_windows)]
        if self._n_closed >= 2 or self._open is None:
            return held
        return np.vstack([held, [self._open[1:3]]])

    def _refit(self) -> None:
        pts = self._points()
        if pts.shape[0] == 0:
            return
        d, h = pts[:, 0], pts[:, 1]
        b = 1.0 if pts.shape[0] < 2 or np.ptp(d) == 0.0 else _theil_sen_slope(d, h)
        r = h - b * d
        c = float(np.median(r))
        scatter = _MAD_TO_SIGMA * float(np.median(np.abs(r - c))) if r.size >= 3 else math.nan
        self._envelope = (b, c, scatter)
        if self._n_closed >= 2:
            self._ref_slope = b
        # Re-measure the floor of the anchors within (or after) the fitted span; older anchors
        # keep the floor measured while they were inside it.
        n = min(self._n_anchors_total, self.max_anchors)
        anchors = self._anchors[:n]
        recent = (anchors[:, 0] >= d.min() - self.window_s) | np.isnan(anchors[:, 2])
        anchors[recent, 2] = (c + b * anchors[recent, 0]) - anchors[recent, 1]
        self._map = None

    def _floor_of(self, d_rel: float, h_rel: float) -> float:
        if self._envelope is None:
            return math.nan
        b, c = self._envelope[:2]
        return (c + b * d_rel) - h_rel

    def _solve(self) -> tuple[float, float]:
        if self._map is not None:
            return self._map
        anchors = self._anchors[: min(self._n_anchors_total, self.max_anchors)]
        if self._envelope is None:
            if anchors.shape[0] == 0:
                raise SyncError("the clock map has no block pair and no anchor yet")
            d, h = anchors[:, 0], anchors[:, 1]
            b = 1.0 if np.ptp(d) == 0.0 else _theil_sen_slope(d, h)
            self._map = (b, float(np.median(h - b * d)))
            return self._map
        b, c = self._envelope[:2]
        self._map = (b, c - self.latency_floor_s)
        return self._map

    # -- results ----------------------------------------------------------------------------------
    @overload
    def to_host(self, t_device: float) -> float: ...

    @overload
    def to_host(self, t_device: npt.NDArray[Any]) -> FloatArray: ...

    def to_host(self, t_device: float | npt.NDArray[Any]) -> float | FloatArray:
        """Map device times (s) to host times (s); arrays keep their shape.

        Raises
        ------
        SyncError
            The map has seen no pair and no anchor.
        """
        b, c = self._solve()
        assert self._origin is not None
        d0, h0 = self._origin
        out = h0 + (c + b * (np.asarray(t_device, dtype=np.float64) - d0))
        return float(out) if np.ndim(out) == 0 else np.asarray(out, dtype=np.float64)

    @overload
    def to_device(self, t_host: float) -> float: ...

    @overload
    def to_device(self, t_host: npt.NDArray[Any]) -> FloatArray: ...

    def to_device(self, t_host: float | npt.NDArray[Any]) -> float | FloatArray:
        """Map host times (s) to device times (s), the inverse of :meth:`to_host`."""
        b, c = self._solve()
        assert self._origin is not None
        d0, h0 = self._origin
        out = d0 + ((np.asarray(t_host, dtype=np.float64) - h0) - c) / b
        return float(out) if np.ndim(out) == 0 else np.asarray(out, dtype=np.float64)

    @property
    def ready(self) -> bool:
        """Whether the map can answer (it has seen a pair or an anchor)."""
        return self._envelope is not None or self._n_anchors_total > 0

    @property
    def offset_s(self) -> float:
        """Device time at host time 0, s (``t_device = offset_s + (1 + drift_ppm 1e-6) t_host``).

        An extrapolation of the current (local) fit to host time 0: meaningful when host times
        count from the run start; hours later it carries the slope error times the run length.
        :meth:`to_host` near the present is what the fit guarantees.
        """
        return self.to_device(0.0)

    @property
    def drift_ppm(self) -> float:
        """Rate of the device clock against the host's, ppm (positive: the device runs fast)."""
        b, _ = self._solve()
        return 1e6 * (1.0 / b - 1.0)

    @property
    def residual_s(self) -> float:
        """Robust scatter (1.4826 MAD) of the window minima about the fitted envelope, s.

        The envelope's own noise: microseconds when the transport behaves; NaN before three
        windows. It grows when the latency floor moves (a congested link) or the device clock
        is not linear (an unreported step).
        """
        return math.nan if self._envelope is None else self._envelope[2]

    @property
    def latency_floor_s(self) -> float:
        """Transport latency floor subtracted from the envelope, s.

        The median over anchors of ``envelope(t_device) - t_host``, or ``assumed_floor_s`` when
        no anchor has been measured against the envelope yet.
        """
        floors = self._anchors[: min(self._n_anchors_total, self.max_anchors), 2]
        floors = floors[np.isfinite(floors)]
        return float(np.median(floors)) if floors.size else self.assumed_floor_s

    @property
    def anchor_residual_s(self) -> float:
        """Robust scatter (1.4826 MAD) of the anchors' floors, s; NaN with fewer than 2."""
        floors = self._anchors[: min(self._n_anchors_total, self.max_anchors), 2]
        floors = floors[np.isfinite(floors)]
        if floors.size < 2:
            return math.nan
        return _MAD_TO_SIGMA * float(np.median(np.abs(floors - np.median(floors))))

    @property
    def n_pairs(self) -> int:
        """Block pairs given to :meth:`update` since the last reset (a count, not storage)."""
        return self._n_pairs

    @property
    def n_anchors(self) -> int:
        """Anchors held (at most ``max_anchors``)."""
        return min(self._n_anchors_total, self.max_anchors)

    @property
    def n_windows_held(self) -> int:
        """Closed envelope windows held (at most ``n_windows``)."""
        return min(self._n_closed, self.n_windows)


def trigger_times_from_flags(device_time: Any, flag: Any, period_s: float) -> FloatArray:
    """Device times of trigger pulses from a per-sample "triggered" flag (the lasers' bit 15).

    The flag marks the first sample at or after the pulse, so the pulse fell in the sample
    interval ``(t_k - period_s, t_k]``; its centre ``t_k - period_s / 2`` is the unbiased
    estimate (uniform error within +-period_s/2, 0.125 ms at 4 kHz). Without the correction
    every laser anchor would be half a sample late on average.

    Parameters
    ----------
    device_time : array_like, shape (n,)
        Device time of each sample, s.
    flag : array_like of bool, shape (n,)
        The triggered flag per sample.
    period_s : float
        Sample period, s.

    Returns
    -------
    ndarray, shape (n_pulses,)
        Estimated pulse times on the device clock, s.
    """
    t = _float_1d("device_time", device_time)
    f = np.atleast_1d(np.asarray(flag, dtype=bool))
    if f.shape != t.shape:
        raise ValueError(f"flag must have the shape of device_time {t.shape}, got {f.shape}")
    return t[f] - 0.5 * _positive("period_s", period_s)


def trigger_times_from_latch(latched_time: Any, after: float = -math.inf) -> FloatArray:
    """Return the new trigger times of a latched "last external trigger" column (the scanner's).

    The scanner repeats the time of its last external trigger in every frame (NaN before the
    first), so one pulse appears in many frames. Returns each distinct finite value later than
    ``after`` (the last pulse already taken), in order.

    Parameters
    ----------
    latched_time : array_like, shape (n,)
        Trigger time per frame on the device clock, s, NaN when none.
    after : float
        Device time of the last pulse already used, s.
    """
    t = _float_1d("latched_time", latched_time)
    t = t[np.isfinite(t) & (t > after)]
    if t.size == 0:
        return t
    # A value counts once, and only when it is later than every value before it.
    previous = np.maximum.accumulate(np.concatenate(([after], t[:-1])))
    return t[t > previous]


# ------------------------------------------------------------------------------------------------
# Counters
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Gap:
    """Samples missing from a stream, found from its counter.

    Attributes
    ----------
    after_counter : int
        Unwrapped counter of the last sample before the gap.
    length : int
        Number of missing samples (>= 1).
    """

    after_counter: int
    length: int


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
        self.period_s = None if period_s is None else _positive("period_s", period_s)
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
            t = _float_1d("device_time", device_time)
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
    ([65534, 65535, 65536, 65539, 65540], (Gap(after_counter=65536, length=2),))
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


# ------------------------------------------------------------------------------------------------
# Resampling onto the sync time base
# ------------------------------------------------------------------------------------------------
_METHODS: Final = ("linear", "boxcar")


@dataclass(frozen=True)
class StreamSpec:
    """One stream of the sync view.

    Attributes
    ----------
    name : str
        Stream name (the key of its values in :class:`SyncBlock`).
    period_s : float
        Nominal sample period on the host time base, s.
    method : str
        ``"linear"``: linear interpolation, for a stream sampled at or below the sync rate (the
        scanner, the barometer). ``"boxcar"``: the mean of the linearly interpolated signal over
        one sync period centred on each sync time, for a stream sampled faster (the lasers at
        4 kHz onto 500 Hz): see :class:`Resampler`.
    channels : int or None
        Number of channels (values of shape (n, channels)), or None for a 1-D stream.
    max_gap_s : float or None
        Longest sample spacing interpolated across, s; a sync time whose support touches a
        longer spacing is NaN. Default ``1.5 period_s``: any missing sample is a gap, so
        nothing is made up; relax it explicitly to bridge single lost samples.
    """

    name: str
    period_s: float
    method: str = "linear"
    channels: int | None = None
    max_gap_s: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"stream name must be a non-empty string, got {self.name!r}")
        _positive(f"{self.name}: period_s", self.period_s)
        if self.method not in _METHODS:
            raise ValueError(f"{self.name}: method must be one of {list(_METHODS)}, got "
                             f"{self.method!r}")
        if self.channels is not None and (isinstance(self.channels, bool) or not isinstance(
                self.channels, int) or self.channels < 1):
            raise ValueError(f"{self.name}: channels must be None or an integer >= 1, got "
                             f"{self.channels!r}")
        if self.max_gap_s is None:
            object.__setattr__(self, "max_gap_s", 1.5 * self.period_s)
        elif _positive(f"{self.name}: max_gap_s", self.max_gap_s) < self.period_s:
            raise ValueError(f"{self.name}: max_gap_s = {self.max_gap_s!r} is below the sample "
                             f"period {self.period_s!r}: every sample would be a gap")


@dataclass(frozen=True, eq=False)
class SyncBlock:
    """Samples of the sync view.

    Attributes
    ----------
    index : ndarray of int64, shape (n,)
        Sync sample number ``k`` (time ``t_start + k / rate_hz``).
    time : ndarray of float64, shape (n,)
        Host time, s.
    values : dict of str to ndarray
        Per stream, shape (n,) or (n, channels); NaN where the stream has no data (a gap, before
        it started, after it stopped).
    """

    index: IntArray
    time: FloatArray
    values: Mapping[str, FloatArray]

    def __len__(self) -> int:
        return int(self.index.size)

    @staticmethod
    def concatenate(blocks: Sequence[SyncBlock]) -> SyncBlock:
        """Join consecutive blocks of one :class:`Resampler` (at least one block)."""
        if not blocks:
            raise ValueError("nothing to concatenate")
        return SyncBlock(
            index=np.concatenate([b.index for b in blocks]),
            time=np.concatenate([b.time for b in blocks]),
            values={k: np.concatenate([b.values[k] for b in blocks]) for k in blocks[0].values},
        )


class _Buffer:
    """Samples of one stream not yet consumed by the sync view (always 2-D values).

    Pushed pieces are kept in a list and joined once, when the sync view reads them: joining
    at every push would copy the whole buffer each time, quadratic in the pushes between two
    pulls (18 % of the recorder's time in benchmarks/daq_throughput.py).
    """

    def __init__(self, spec: StreamSpec) -> None:
        self.spec = spec
        self._t = np.zeros(0)
        self._v = np.zeros((0, spec.channels or 1))
        self._pieces: list[tuple[FloatArray, FloatArray]] = []
        self.last = -math.inf  # time of the newest sample held
        self.late = 0
        self.overlapping = 0

    def append(self, t: FloatArray, v: FloatArray) -> None:
        if t.size:
            self._pieces.append((t, v))
            self.last = float(t[-1])

    def _join(self) -> None:
        if self._pieces:
            self._t = np.concatenate([self._t, *(p[0] for p in self._pieces)])
            self._v = np.concatenate([self._v, *(p[1] for p in self._pieces)])
            self._pieces.clear()

    @property
    def t(self) -> FloatArray:
        self._join()
        return self._t

    @property
    def v(self) -> FloatArray:
        self._join()
        return self._v

    def keep_from(self, i0: int) -> None:
        """Drop the samples before index ``i0``."""
        self._join()
        self._t, self._v = self._t[i0:], self._v[i0:]


class Resampler:
    r"""Put several host-mapped streams onto one uniform time base, block by block.

    The sync time base is ``t_k = t_start + k / rate_hz``. Each stream is pushed as it arrives
    (host-mapped times, values); :meth:`pull` returns the sync samples that every stream has
    covered (their values can no longer change) and keeps only the tail the next ones need, so
    memory is bounded and the concatenated output equals the one-shot :func:`resample` of the
    same data, sample for sample.

    Methods per stream (:class:`StreamSpec`):

    - ``"linear"``: linear interpolation between the two samples around ``t_k``. Its error on a
      sinusoid of amplitude ``A`` and angular frequency ``w`` sampled every ``T`` is at most
      ``A (w T)^2 / 8``: 3e-4 A for 4 Hz at 500 Hz.
    - ``"boxcar"``: the mean over ``[t_k - W/2, t_k + W/2]``, ``W = 1 / rate_hz``, of the linear
      interpolant (integrated exactly, so any rate ratio and any phase between the clocks give
      the same filter). Why for the lasers: decimating 4 kHz to 500 Hz by picking samples
      would fold their noise and any vibration above 250 Hz into the band; the boxcar is the
      anti-alias filter that needs no state across gaps, its zeros fall exactly on the
      multiples of the sync rate (the frequencies that alias to 0 Hz), it averages the laser
      noise down by about sqrt(8), and it is symmetric, hence zero phase: no delay between the
      lasers and the pressures, which the sync view exists to preserve. Its gain on the
      signal, ``sinc(f W)``, loses ``(pi f W)^2 / 6``: 1e-4 of the amplitude at 4 Hz.

    A sync time is NaN for a stream when its support (the two samples around it, or the boxcar
    interval) touches a sample spacing over the stream's ``max_gap_s``, a NaN sample (per
    channel), or lies outside the stream's data.

    A stream that stalls would hold the others back forever; once the newest sample of any
    stream is more than ``max_hold_s`` past a sync time, that time is output anyway, with NaN
    for the streams that have not covered it. Samples arriving later than the sync times they
    would have fed are counted (:attr:`late_samples`), as are samples not after the previous
    one of their stream (:attr:`overlapping_samples`, e.g. after a clock-map correction); both
    stay in the raw record, neither changes the sync view.

    Parameters
    ----------
    streams : sequence of StreamSpec
        The streams, with distinct names.
    rate_hz : float
        Sync rate, Hz.
    t_start : float
        Host time of sync sample 0, s.
    max_hold_s : float
        How long a stalled stream may hold the output back, s (``math.inf``: forever).
    """

    def __init__(self, streams: Sequence[StreamSpec], *, rate_hz: float, t_start: float,
                 max_hold_s: float = 2.0) -> None:
        if not streams:
            raise ValueError("a resampler needs at least one stream")
        names = [s.name for s in streams]
        if len(set(names)) != len(names):
            raise ValueError(f"stream names must be distinct, got {names}")
        self.rate_hz = _positive("rate_hz", rate_hz)
        start = float(t_start)
        if not math.isfinite(start):
            raise ValueError(f"t_start must be finite, got {t_start!r}")
        self.t_start = start
        hold = float(max_hold_s)
        if not hold > 0.0:
            raise ValueError(f"max_hold_s must be > 0, got {max_hold_s!r}")
        self.max_hold_s = hold
        self.width_s = 1.0 / self.rate_hz
        self._buffers = {s.name: _Buffer(s) for s in streams}
        self._next = 0  # next sync sample number to output

    # -- time base --------------------------------------------------------------------------------
    def _time(self, k: Any) -> FloatArray:
        # From the integer index every time, never by accumulation: no drift over hours.
        return self.t_start + np.asarray(k, dtype=np.float64) / self.rate_hz

    def _count_before(self, limit: float) -> int:
        """Count the sync samples with ``t_k < limit`` (exact against :meth:`_time`)."""
        if limit == -math.inf:
            return 0
        if limit == math.inf:
            raise SyncError("no finite limit")
        k = max(0, math.ceil((limit - self.t_start) * self.rate_hz))
        while k > 0 and float(self._time(k - 1)) >= limit:
            k -= 1
        while float(self._time(k)) < limit:
            k += 1
        return k

    def _support(self, spec: StreamSpec) -> float:
        return 0.5 * self.width_s if spec.method == "boxcar" else 0.0

    # -- feeding ----------------------------------------------------------------------------------
    def push(self, name: str, t: Any, values: Any) -> None:
        """Add samples of one stream.

        Parameters
        ----------
        name : str
            Stream name.
        t : array_like, shape (n,)
            Host-mapped sample times, s, increasing.
        values : array_like, shape (n,) or (n, channels)
            Sample values (NaN where invalid).
        """
        if name not in self._buffers:
            raise KeyError(f"unknown stream {name!r}; streams: {sorted(self._buffers)}")
        buf = self._buffers[name]
        spec = buf.spec
        tt = _float_1d("t", t)
        v = np.asarray(values, dtype=np.float64)
        want = (tt.size,) if spec.channels is None else (tt.size, spec.channels)
        if v.shape != want:
            raise ValueError(f"{name}: values must have shape {want}, got {v.shape}")
        if not np.all(np.isfinite(tt)):
            raise ValueError(f"{name}: sample times must be finite")
        if tt.size > 1 and np.any(np.diff(tt) <= 0.0):
            raise ValueError(f"{name}: sample times must increase within a push")
        v = v.reshape(tt.size, -1)
        if buf.last > -math.inf:
            keep = tt > buf.last
            buf.overlapping += int(tt.size - np.count_nonzero(keep))
            tt, v = tt[keep], v[keep]
        if self._next > 0:
            buf.late += int(np.count_nonzero(tt < float(self._time(self._next - 1))
                                             - self._support(spec)))
        buf.append(tt, v)

    # -- output -----------------------------------------------------------------------------------
    def pull(self) -> SyncBlock:
        """Return the sync samples every stream has covered (possibly none)."""
        ready = []
        newest = -math.inf
        for buf in self._buffers.values():
            last = buf.last
            newest = max(newest, last)
            ready.append(self._count_before(last - self._support(buf.spec)))
        stop = min(ready)
        if self.max_hold_s < math.inf and newest > -math.inf:
            stop = max(stop, self._count_before(newest - self.max_hold_s))
        return self._emit(stop)

    def flush(self) -> SyncBlock:
        """Return every sync sample any stream has covered (end of a run); NaN for the others."""
        stop = self._next
        for buf in self._buffers.values():
            if buf.t.size:
                stop = max(stop, self._count_before(float(buf.t[-1]) - self._support(buf.spec)))
        return self._emit(stop)

    def _emit(self, stop: int) -> SyncBlock:
        k = np.arange(self._next, max(stop, self._next), dtype=np.int64)
        times = self._time(k)
        values: dict[str, FloatArray] = {}
        for name, buf in self._buffers.items():
            spec = buf.spec
            if spec.method == "linear":
                out = _linear(buf.t, buf.v, times, float(spec.max_gap_s or 0.0))
            else:
                out = _boxcar(buf.t, buf.v, times, self.width_s, float(spec.max_gap_s or 0.0))
            values[name] = out[:, 0] if spec.channels is None else out
        self._next = int(k[-1]) + 1 if k.size else self._next
        self._trim()
        return SyncBlock(index=k, time=times, values=values)

    def _trim(self) -> None:
        t_next = float(self._time(self._next))
        for buf in self._buffers.values():
            # Keep the sample just before the next output's support: it brackets it.
            i0 = int(np.searchsorted(buf.t, t_next - self._support(buf.spec), side="right")) - 1
            if i0 > 0:
                buf.keep_from(i0)

    # -- diagnostics ------------------------------------------------------------------------------
    @property
    def late_samples(self) -> dict[str, int]:
        """Per stream, samples that arrived after the sync times they would have fed."""
        return {name: buf.late for name, buf in self._buffers.items()}

    @property
    def overlapping_samples(self) -> dict[str, int]:
        """Per stream, samples not later than the stream's previous sample (not used)."""
        return {name: buf.overlapping for name, buf in self._buffers.items()}

    @property
    def buffered(self) -> dict[str, int]:
        """Per stream, samples held for the next output (bounded by the hold time)."""
        return {name: int(buf.t.size) for name, buf in self._buffers.items()}


def _linear(t: FloatArray, v: FloatArray, times: FloatArray, max_gap: float) -> FloatArray:
    """Linear interpolation of rows ``v`` at ``t`` onto ``times``; NaN across long gaps."""
    out = np.full((times.size, v.shape[1]), np.nan)
    if t.size < 2 or times.size == 0:
        return out
    i = np.searchsorted(t, times, side="right") - 1
    ok = (i >= 0) & (i + 1 < t.size)
    i = np.clip(i, 0, t.size - 2)
    dt = t[i + 1] - t[i]
    ok &= dt <= max_gap
    w = ((times - t[i]) / dt)[:, None]
    # v_i + w (v_j - v_i): a NaN at either end gives NaN (a missing sample is never bridged).
    out[ok] = (v[i] + w * (v[i + 1] - v[i]))[ok]
    return out


def _boxcar(t: FloatArray, v: FloatArray, times: FloatArray, width: float,
            max_gap: float) -> FloatArray:
    """Mean of the linear interpolant over ``[time - width/2, time + width/2]``; NaN on gaps."""
    n_ch = v.shape[1]
    out = np.full((times.size, n_ch), np.nan)
    if t.size < 2 or times.size == 0:
        return out
    a, b = times - 0.5 * width, times + 0.5 * width
    ka = np.searchsorted(t, a, side="right") - 1
    kb = np.searchsorted(t, b, side="right") - 1
    ok = (ka >= 0) & (kb + 1 < t.size)
    ka, kb = np.clip(ka, 0, t.size - 2), np.clip(kb, 0, t.size - 2)
    dt = np.diff(t)
    slope = np.diff(v, axis=0) / dt[:, None]
    seg = 0.5 * (v[:-1] + v[1:]) * dt[:, None]  # integral over each segment
    bad_seg = ~np.isfinite(seg) | (dt > max_gap)[:, None]
    # Segments ka..kb (inclusive) are used; any bad one makes the output NaN (per channel).
    bad_count = np.concatenate([np.zeros((1, n_ch), np.int64), np.cumsum(bad_seg, axis=0)])
    bad = (bad_count[kb + 1] - bad_count[ka]) > 0
    # Whole segments ka..kb-1 summed per output with reduceat over exactly those rows, so that
    # the result depends on those samples only (not on where the buffer starts): block-by-block
    # output then equals the one-shot output bit for bit.
    seg0 = np.where(bad_seg, 0.0, seg)
    padded = np.vstack([seg0, np.zeros((1, n_ch))])
    idx = np.empty(2 * times.size, dtype=np.int64)
    idx[0::2], idx[1::2] = ka, kb
    full = np.add.reduceat(padded, idx, axis=0)[0::2]
    full[ka == kb] = 0.0

    def partial(k: IntArray, x: FloatArray) -> FloatArray:
        tau = (x - t[k])[:, None]
        return np.asarray(v[k] * tau + 0.5 * slope[k] * tau * tau)

    with np.errstate(invalid="ignore"):
        integral = full - partial(ka, a) + partial(kb, b)
    good = ok[:, None] & ~bad
    out[good] = (integral / width)[good]
    return out


def resample(streams: Sequence[StreamSpec], data: Mapping[str, tuple[Any, Any]], *,
             rate_hz: float, t_start: float) -> SyncBlock:
    """One-shot sync view of whole records (the same numbers as :class:`Resampler` streaming).

    Parameters
    ----------
    streams : sequence of StreamSpec
        The streams.
    data : mapping of str to (times, values)
        Per stream name, host-mapped times (s, increasing) and values.
    rate_hz, t_start : float
        Sync rate (Hz) and host time of sync sample 0 (s).
    """
    missing = sorted({s.name for s in streams} - set(data))
    if missing:
        raise ValueError(f"no data for streams {missing}")
    r = Resampler(streams, rate_hz=rate_hz, t_start=t_start, max_hold_s=math.inf)
    for spec in streams:
        r.push(spec.name, *data[spec.name])
    return r.flush()


# ------------------------------------------------------------------------------------------------
# Physical conversions
# ------------------------------------------------------------------------------------------------
class HeavePitch(NamedTuple):
    """Heave and pitch from the lasers.

    Attributes
    ----------
    h : ndarray, shape (n,)
        Heave, m, positive downward.
    alpha : ndarray, shape (n,)
        Pitch, rad, positive nose-up.
    check : ndarray, shape (n,)
        With 3 lasers: the third laser's reading minus what the first two predict at its
        position, m (0 for a rigid, correctly positioned set-up, up to noise). NaN with 2
        lasers or when a laser has no value.
    """

    h: FloatArray
    alpha: FloatArray
    check: FloatArray


def heave_pitch_from_lasers(distances_m: Any, x_positions_m: Any, standoff_m: Any) -> HeavePitch:
    r"""Heave and pitch of the section from 2 or 3 laser distances.

    Geometry: the lasers look down on the model from above, at chord positions ``x_i``
    (downstream positive, origin at the elastic axis); with h positive downward and alpha
    positive nose-up (the leading edge, at x < 0, moves up for alpha > 0) a laser reads
    ``d_i = standoff_i + h + x_i alpha`` (small angles: ``tan(alpha) - alpha`` is 0.08 % of
    alpha at 3 degrees).

    With 3 lasers, h and alpha are the least-squares solution (the noise of all three
    averaged); the check is the third laser's disagreement with the line through the first
    two, which reveals a mis-positioned or mis-mastered laser, a dirty target, or a model that
    twists or bends. A sample where one of three lasers has no value (NaN: out of range, dark
    target) is solved exactly from the other two; with fewer than two values it is NaN.

    Parameters
    ----------
    distances_m : array_like, shape (n, n_lasers)
        Laser readings, m, NaN where invalid; n_lasers is 2 or 3.
    x_positions_m : array_like, shape (n_lasers,)
        Chord position of each laser spot, m; distinct.
    standoff_m : float or array_like, shape (n_lasers,)
        Reading of each laser with the model at rest (h = alpha = 0), m.

    Returns
    -------
    HeavePitch
        ``(h, alpha, check)``.

    Examples
    --------
    >>> r = heave_pitch_from_lasers([[0.026, 0.024]], [-0.1, 0.1], 0.025)
    >>> float(r.h[0]), float(r.alpha[0])
    (0.0, -0.01)
    """
    d = np.asarray(distances_m, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] not in (2, 3):
        raise ValueError(f"distances_m must have shape (n, 2) or (n, 3), got {d.shape}")
    k = d.shape[1]
    x = np.asarray(x_positions_m, dtype=np.float64)
    if x.shape != (k,) or not np.all(np.isfinite(x)):
        raise ValueError(f"x_positions_m must be {k} finite positions, got {x_positions_m!r}")
    if np.unique(x).size != k:
        raise ValueError(f"laser positions must be distinct (a pair at one x cannot see pitch), "
                         f"got {x.tolist()}")
    s = np.broadcast_to(np.asarray(standoff_m, dtype=np.float64), (k,))
    if not np.all(np.isfinite(s)):
        raise ValueError(f"standoff_m must be finite, got {standoff_m!r}")
    y = d - s
    valid = np.isfinite(y)
    h = np.full(d.shape[0], np.nan)
    alpha = np.full(d.shape[0], np.nan)
    # Solve once per pattern of valid lasers (at most 2**3 patterns), vectorised over samples.
    patterns, inverse = np.unique(valid, axis=0, return_inverse=True)
    for p, pattern in enumerate(patterns):
        cols = np.flatnonzero(pattern)
        if cols.size < 2:
            continue
        rows = np.flatnonzero(inverse.ravel() == p)
        A = np.column_stack([np.ones(cols.size), x[cols]])
        sol = np.linalg.pinv(A) @ y[np.ix_(rows, cols)].T  # exact for 2 lasers, LS for 3
        h[rows], alpha[rows] = sol[0], sol[1]
    check = np.full(d.shape[0], np.nan)
    if k == 3:
        a12 = (y[:, 1] - y[:, 0]) / (x[1] - x[0])
        check = y[:, 2] - (y[:, 0] + (x[2] - x[0]) * a12)
    return HeavePitch(h, alpha, check)


def forces_from_pressures(pressures: Any, taps: TapLayout) -> tuple[FloatArray, FloatArray]:
    """Lift and moment per unit span from tap pressures (:meth:`ident.taps.TapLayout.integrate`).

    Parameters
    ----------
    pressures : array_like, shape (n, n_taps)
        Tap pressures relative to the free-stream static pressure, Pa, in the layout's tap
        order (the scanner's first ``n_taps`` channels). A NaN tap makes that sample's forces
        NaN: a missing module is a marked gap, never a silently smaller force.
    taps : TapLayout
        Tap geometry of the section.

    Returns
    -------
    lift, moment : ndarray, shape (n,)
        N/m (positive downward) and N m/m (positive nose-up).
    """
    return taps.integrate(pressures)


class WindSpeed(NamedTuple):
    """Wind speed from the Pitot dynamic pressure.

    Attributes
    ----------
    speed : ndarray
        m/s; 0 where clipped, NaN where rejected or where the input was NaN.
    clipped : ndarray of bool
        Dynamic pressure in ``[-zero_tolerance_pa, 0)``: zero-offset noise, speed set to 0.
    rejected : ndarray of bool
        Dynamic pressure below ``-zero_tolerance_pa``: not noise (swapped Pitot lines, a zero
        taken with the wind on); speed NaN.
    """

    speed: FloatArray
    clipped: BoolArray
    rejected: BoolArray


def wind_speed(pitot_qd_pa: Any, rho: Any, *, zero_tolerance_pa: float = 5.0) -> WindSpeed:
    r"""Wind speed ``U = sqrt(2 qd / rho)`` from the Pitot dynamic pressure.

    At wind off the Pitot reads zero plus noise, half of it negative. Such a sample is clipped
    to 0 m/s and flagged rather than made NaN: NaN would mark every still-air record as lost
    data, while 0 is the true speed to within the noise (and a release's speed should come
    from its mean ``qd``, where the noise averages out, not from the mean of this channel). A
    value below ``-zero_tolerance_pa`` is not noise but a fault, so it is NaN and flagged: 0
    there would be a wrong number that looks right. The square root never sees a negative.

    Parameters
    ----------
    pitot_qd_pa : array_like
        Dynamic pressure, Pa.
    rho : float or array_like
        Air density, kg/m^3 (> 0; NaN gives NaN), broadcast against ``pitot_qd_pa``.
    zero_tolerance_pa : float
        Largest negative reading taken as zero-offset noise, Pa (>= 0). The default 5 Pa is
        5 standard deviations of the simulated scanner's noise and about the zero accuracy of
        a 1 psi MPS4264 module (0.06 % FS [unverified]).

    Examples
    --------
    >>> w = wind_speed([60.0, -1.0, -50.0], 1.2)
    >>> w.speed, w.clipped, w.rejected
    (array([10.,  0., nan]), array([False,  True, False]), array([False, False,  True]))
    """
    tol = float(zero_tolerance_pa)
    if not (math.isfinite(tol) and tol >= 0.0):
        raise ValueError(f"zero_tolerance_pa must be finite and >= 0, got {zero_tolerance_pa!r}")
    qd, r = np.broadcast_arrays(np.asarray(pitot_qd_pa, dtype=np.float64),
                                np.asarray(rho, dtype=np.float64))
    if np.any(r <= 0.0) or np.any(np.isinf(r)):
        raise ValueError(f"rho must be > 0 and finite (NaN allowed), got min {np.nanmin(r)!r}")
    with np.errstate(invalid="ignore"):
        clipped = (qd < 0.0) & (qd >= -tol)
        rejected = qd < -tol
    q = np.where(clipped, 0.0, np.where(rejected, np.nan, qd))
    speed = np.sqrt(2.0 * q / r)  # q >= 0 or NaN here
    return WindSpeed(speed, clipped, rejected)


def air_density(pressure_pa: Any, temperature_k: Any) -> FloatArray:
    r"""Dry-air density ``rho = p / (R_d T)``, R_d = 287.058 J/(kg K), as the barometer driver.

    Humidity is neglected (moist air is lighter: rho is overestimated by ~0.4 % at 20 degC and
    50 %RH; see :func:`daq.vaisala_ptb330.reading_from_line`).

    Parameters
    ----------
    pressure_pa : array_like
        Absolute pressure, Pa (NaN passes through).
    temperature_k : array_like
        Temperature, K (NaN passes through).

    Raises
    ------
    ValueError
        A value outside the barometer's plausible ranges (50-120 kPa, 233-353 K): most often
        hPa or degC passed by mistake.

    Examples
    --------
    >>> round(float(air_density(101325.0, 288.15)), 4)
    1.225
    """
    p = np.asarray(pressure_pa, dtype=np.float64)
    t = np.asarray(temperature_k, dtype=np.float64)
    for name, arr, (lo, hi), hint in (("pressure_pa", p, PRESSURE_RANGE_PA, "hPa?"),
                                      ("temperature_k", t, TEMPERATURE_RANGE_K, "degC?")):
        with np.errstate(invalid="ignore"):
            out = (arr < lo) | (arr > hi)
        if np.any(out):
            raise ValueError(f"{name} = {float(arr[out].ravel()[0])!r} is outside [{lo}, {hi}] "
                             f"({hint})")
    return np.asarray(p / (R_DRY_AIR * t), dtype=np.float64)
