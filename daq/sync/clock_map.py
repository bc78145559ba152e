r"""Mapping of one device clock onto the host clock, and the trigger times that anchor it.

Responsibility (the synchronised view of docs/reference/file_format.md): pure numerical code used by
the run writer

- :class:`ClockMap` maps one device clock onto the host clock, ``t_host = a + b t_device``, fitted
  robustly from every block's (device time, host arrival time) pair and from anchor events seen
  by both clocks (trigger pulses, the release), and updated during the run in bounded memory;
- :func:`trigger_times_from_flags` and :func:`trigger_times_from_latch` give the device times of
  the trigger pulses from what a device records of them (a per-sample "triggered" flag, a
  latched "last external trigger" column).

Not responsible for: reading devices, threads, queues or files (the acquisition engine feeds
arrays in and takes arrays out), nor the choice of which events are anchors (the engine pairs a
PLC pulse with what each device saw of it).

Conventions: SI units; times in seconds as float64. Host times are best passed relative to the run
start (``(host_time_ns - run_start_ns) * 1e-9``): then the sync view's ``time`` is "s from run
start" (docs/reference/file_format.md; see :mod:`daq.sync.resample`) and :attr:`ClockMap.offset_s`
is the device time at the run start. The clock convention is that of
:class:`simulators.clock.DeviceClock`: ``t_device = offset_s + (1 + drift_ppm 1e-6) t_host``.
"""

from __future__ import annotations

import functools
import math
from typing import Any, Final, overload

import numpy as np
import numpy.typing as npt

from daq.errors import SyncError
from daq.sync.checks import float_1d, positive

__all__ = [
    "MIN_FLOOR_ANCHORS",
    "ClockMap",
    "trigger_times_from_flags",
    "trigger_times_from_latch",
]

FloatArray = npt.NDArray[np.float64]

#: Scale from the median absolute deviation to the standard deviation of a normal distribution.
_MAD_TO_SIGMA: Final = 1.4826

#: Fewest anchors whose median is the latency floor (robust to one mis-paired pulse).
MIN_FLOOR_ANCHORS: Final = 3

#: Points used by :func:`_theil_sen_slope` (more are thinned evenly): 7140 pairs.
_MAX_SLOPE_POINTS = 120


def _weighted_median(values: FloatArray, weights: FloatArray) -> float:
    """Lower weighted median: the smallest value whose cumulative weight reaches half the total."""
    # Any sort gives the same value: tied values are equal, and the cumulative weight at the
    # end of a run of ties does not depend on their order (the introsort is ~2x the stable one).
    order = np.argsort(values)
    cum = np.cumsum(weights[order])
    return float(values[order[np.searchsorted(cum, 0.5 * cum[-1])]])


@functools.lru_cache(maxsize=8)
def _pairs(n: int) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """Return the index pairs ``i < j`` of ``n`` points (cached: a full map refits on 120)."""
    i, j = np.triu_indices(n, 1)
    i.setflags(write=False)
    j.setflags(write=False)
    return i, j


@functools.lru_cache(maxsize=8)
def _thinning(n: int) -> npt.NDArray[np.intp]:
    """Return the indices of ``_MAX_SLOPE_POINTS`` of ``n`` points, evenly spread (cached)."""
    keep = np.linspace(0, n - 1, _MAX_SLOPE_POINTS).round().astype(np.intp)
    keep.setflags(write=False)
    return keep


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
        keep = _thinning(x.size)
        x, y = x[keep], y[keep]
    i, j = _pairs(x.size)
    dx = x[j] - x[i]
    keep = dx != 0.0
    dx, dy = dx[keep], (y[j] - y[i])[keep]
    return _weighted_median(dy / dx, np.abs(dx))


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
       ``L_min = envelope(t_device) - t_host``; the map uses the median over the least
       uncertain anchors (:attr:`ClockMap.latency_floor_s`; robust to one mis-paired pulse).
       Because the floor is a property of the transport, it is stored per anchor and frozen
       once the anchor is older than the fitted span, so old anchors keep counting after the
       envelope has moved on. Without anchors the floor is the
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
        self.window_s = positive("window_s", window_s)
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
        #: Changes whenever the map may have changed (a refit, an anchor, a reset): a caller
        #: that mapped a time under one version gets the same host time under it again.
        self.version = 0
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
        # ring: d_rel, h_rel, floor, uncertainty of h (s; 0: exact)
        self._anchors = np.full((self.max_anchors, 4), np.nan)
        self._n_anchors_total = 0
        self._envelope: tuple[float, float, float] | None = None  # slope, intercept, scatter
        self._map: tuple[float, float] | None = None
        self.version += 1
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
        if isinstance(t_device, float) and isinstance(t_host, float):
            # The recorder's case (one pair per block, as floats): no arrays at all.
            if not (math.isfinite(t_device) and math.isfinite(t_host)):
                raise ValueError("1 of 1 clock pairs are not finite")
            if self._origin is None:
                self._origin = (t_device, t_host)
            self._add_pair(t_device - self._origin[0], t_host - self._origin[1])
            return
        d = float_1d("t_device", t_device)
        h = float_1d("t_host", t_host)
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

    def add_anchor(self, t_device: float, t_host: float, uncertainty_s: float = 0.0) -> None:
        """Add an event seen by the device at ``t_device`` that happened at host time ``t_host``.

        ``t_host`` may come from the host (the time the PLC pulsed the trigger line) or from
        another device's map (``other.to_host(t)`` for the release seen in both streams): a
        cross-device anchor ties this device to the other one.

        Parameters
        ----------
        t_device, t_host : float
            The event's device time and host time, s.
        uncertainty_s : float
            How far ``t_host`` may be off, s (>= 0): half the round trip of the command that
            pulsed the line. The floor comes from the least uncertain anchors held
            (:attr:`latency_floor_s`).
        """
        d, h, u = float(t_device), float(t_host), float(uncertainty_s)
        if not (math.isfinite(d) and math.isfinite(h)):
            raise ValueError(f"anchor times must be finite, got ({t_device!r}, {t_host!r})")
        if not (math.isfinite(u) and u >= 0.0):
            raise ValueError(f"an anchor's uncertainty must be finite and >= 0 s, got "
                             f"{uncertainty_s!r}")
        if self._origin is None:
            self._origin = (d, h)
        d0, h0 = self._origin
        slot = self._n_anchors_total % self.max_anchors
        self._anchors[slot] = (d - d0, h - h0, self._floor_of(d - d0, h - h0), u)
        self._n_anchors_total += 1
        self._map = None
        self.version += 1

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
        self.version += 1

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

        The median of ``envelope(t_device) - t_host`` over the least uncertain anchors (the
        third with the smallest ``uncertainty_s``, at least :data:`MIN_FLOOR_ANCHORS`), or
        ``assumed_floor_s`` when no anchor has been measured against the envelope yet. The
        choice is NTP's clock filter: a command's host time is the midpoint of its round trip,
        off by the asymmetry of its two legs, which can grow with the round trip (on a loaded
        host, a request or its reply waits for a busy process); the median keeps one mis-paired
        pulse from moving the floor.
        """
        best = self._best_anchors()
        return float(np.median(best[:, 2])) if best.shape[0] else self.assumed_floor_s

    @property
    def anchor_uncertainty_s(self) -> float:
        """How far the floor may be off by its anchors' host times, s; NaN without anchors.

        The largest ``uncertainty_s`` of the anchors :attr:`latency_floor_s` is the median
        of: the error of the map's absolute time that no envelope can tell.
        """
        best = self._best_anchors()
        return float(best[:, 3].max()) if best.shape[0] else math.nan

    def _measured_anchors(self) -> FloatArray:
        """Return the anchors held whose floor was measured against the envelope (rows)."""
        held = self._anchors[: min(self._n_anchors_total, self.max_anchors)]
        return held[np.isfinite(held[:, 2])]

    def _best_anchors(self) -> FloatArray:
        """Return the least uncertain third of the measured anchors (>= MIN_FLOOR_ANCHORS)."""
        held = self._measured_anchors()
        if held.shape[0] <= MIN_FLOOR_ANCHORS:
            return held
        n = max(MIN_FLOOR_ANCHORS, held.shape[0] // 3)
        return held[np.argsort(held[:, 3], kind="stable")[:n]]

    @property
    def anchor_residual_s(self) -> float:
        """Robust scatter (1.4826 MAD) of the anchors' floors, s; NaN with fewer than 2."""
        floors = self._measured_anchors()[:, 2]
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
    t = float_1d("device_time", device_time)
    f = np.atleast_1d(np.asarray(flag, dtype=bool))
    if f.shape != t.shape:
        raise ValueError(f"flag must have the shape of device_time {t.shape}, got {f.shape}")
    return t[f] - 0.5 * positive("period_s", period_s)


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
    t = float_1d("latched_time", latched_time)
    t = t[np.isfinite(t) & (t > after)]
    if t.size == 0:
        return t
    # A value counts once, and only when it is later than every value before it.
    previous = np.maximum.accumulate(np.concatenate(([after], t[:-1])))
    return t[t > previous]
