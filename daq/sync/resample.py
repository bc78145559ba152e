r"""Resampling of host-mapped device streams onto the uniform time base of the sync view.

Responsibility (the synchronised view of docs/reference/file_format.md): pure numerical code used by
the run writer

- :class:`Resampler` / :func:`resample` put several host-mapped streams (:class:`StreamSpec`)
  onto one uniform time base (the ``/entry/sync`` view, :class:`SyncBlock`), block by block,
  marking gaps as NaN.

Not responsible for: reading devices, threads, queues or files (the acquisition engine feeds
arrays in and takes arrays out), nor mapping device times to host times (:mod:`daq.sync.clock_map`).

Conventions: SI units; times in seconds as float64. Host times are best passed relative to the run
start (``(host_time_ns - run_start_ns) * 1e-9``): then the sync view's ``time`` is "s from run
start" (docs/reference/file_format.md).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from daq.errors import SyncError
from daq.sync.checks import float_1d, positive

__all__ = [
    "Resampler",
    "StreamSpec",
    "SyncBlock",
    "resample",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

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
        positive(f"{self.name}: period_s", self.period_s)
        if self.method not in _METHODS:
            raise ValueError(f"{self.name}: method must be one of {list(_METHODS)}, got "
                             f"{self.method!r}")
        if self.channels is not None and (isinstance(self.channels, bool) or not isinstance(
                self.channels, int) or self.channels < 1):
            raise ValueError(f"{self.name}: channels must be None or an integer >= 1, got "
                             f"{self.channels!r}")
        if self.max_gap_s is None:
            object.__setattr__(self, "max_gap_s", 1.5 * self.period_s)
        elif positive(f"{self.name}: max_gap_s", self.max_gap_s) < self.period_s:
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
        self.rate_hz = positive("rate_hz", rate_hz)
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
        tt = float_1d("t", t)
        v = np.asarray(values, dtype=np.float64)
        want = (tt.size,) if spec.channels is None else (tt.size, spec.channels)
        if v.shape != want:
            raise ValueError(f"{name}: values must have shape {want}, got {v.shape}")
        if tt.size == 0:
            return
        if not np.isfinite(tt).all():
            raise ValueError(f"{name}: sample times must be finite")
        if tt.size > 1 and not (tt[1:] > tt[:-1]).all():
            raise ValueError(f"{name}: sample times must increase within a push")
        v = v.reshape(tt.size, -1)
        # The times increase: the first one tells whether any overlaps or comes late (the usual
        # push has neither, and is kept without a copy).
        if float(tt[0]) <= buf.last:
            keep = tt > buf.last
            buf.overlapping += int(tt.size - np.count_nonzero(keep))
            tt, v = tt[keep], v[keep]
        if self._next > 0 and tt.size:
            late_before = float(self._time(self._next - 1)) - self._support(spec)
            if float(tt[0]) < late_before:
                buf.late += int(np.count_nonzero(tt < late_before))
        buf.append(tt, v)

    def push_many(self, name: str, pieces: Sequence[tuple[FloatArray, FloatArray]]) -> None:
        """Add several pushes of one stream at once: the same as :meth:`push` of each in turn.

        Each piece's times increase; a sample not after every earlier one of the stream is
        dropped as overlapping, as :meth:`push` drops it (one concatenation instead of a push
        per block: the run writer collects its blocks between two pulls).

        Parameters
        ----------
        name : str
            Stream name.
        pieces : sequence of (t, values)
            Host-mapped times (s, finite, increasing within a piece) and their values, as
            :meth:`push` takes them, in order.
        """
        if len(pieces) == 1:
            self.push(name, *pieces[0])
            return
        if not pieces:
            return
        if name not in self._buffers:
            raise KeyError(f"unknown stream {name!r}; streams: {sorted(self._buffers)}")
        buf = self._buffers[name]
        spec = buf.spec
        width = 1 if spec.channels is None else spec.channels
        times = [float_1d("t", t) for t, _ in pieces]
        values = [np.asarray(x, dtype=np.float64).reshape(t.size, -1)
                  for t, (_, x) in zip(times, pieces, strict=True)]
        if any(v.shape[1] != width for v in values):
            raise ValueError(f"{name}: values must have {width} channel(s)")
        # The times are joined to decide what to keep; the values stay in their pieces (the
        # buffer joins them once, at the pull, as it joins a push per block).
        tt = np.concatenate(times)
        if not np.isfinite(tt).all():
            raise ValueError(f"{name}: sample times must be finite")
        if tt.size == 0:
            return
        # A sample is kept when it is after every earlier one (the newest kept is the running
        # maximum: a dropped sample is never above it), exactly as push() decides per piece.
        keep = tt > np.maximum.accumulate(np.concatenate(([buf.last], tt[:-1])))
        if not keep.all():
            buf.overlapping += int(tt.size - np.count_nonzero(keep))
            parts = np.split(keep, np.cumsum([t.size for t in times])[:-1])
            times = [t[k] for t, k in zip(times, parts, strict=True)]
            values = [v[k] for v, k in zip(values, parts, strict=True)]
            tt = tt[keep]
        if self._next > 0 and tt.size:
            late_before = float(self._time(self._next - 1)) - self._support(spec)
            if float(tt[0]) < late_before:
                buf.late += int(np.count_nonzero(tt < late_before))
        for t, v in zip(times, values, strict=True):
            buf.append(t, v)

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
    if ok.all():  # the usual pull: every time inside the data, no long gap (no masked copy)
        vi = v[i]
        interp = v[i + 1] - vi
        interp *= w
        interp += vi
        return np.asarray(interp)
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
