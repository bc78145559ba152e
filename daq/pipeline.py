"""The recording pipeline: acquisition engine -> clock maps -> sync view -> HDF5 run file.

Responsibility: :class:`RunWriter`, a ``(name, doc)`` subscriber of
:class:`~daq.acquisition.Acquisition` that writes one run file laid out as DESIGN.md, "HDF5 file":
the raw stream of every device, the synchronised view (every device clock mapped onto the host
clock by a :class:`~daq.sync.ClockMap`, the streams resampled onto one time base by a
:class:`~daq.sync.Resampler` and converted to h, alpha, lift, moment, U, rho), the events and one
row per release; and :func:`record_run`, which runs a (simulated or real) rig through the engine
into a file, pulsing the PLC's trigger line every 0.5 s as clock anchors and, for a simulated rig,
checking the result against the simulators' truth (:mod:`daq.sync_check`).

Device clock restarts: a restart gap (length -1, e.g. the scanner's scan restarted after a TCP
reset) after which the device time goes back (relative frame times without PTP restart at 0)
starts a fresh clock map and timeline for that device, from the first sample after the gap (a
block is split there); the rows already written keep their times, a NaN sample marks the break
in the sync view, and a ``clock_restart`` event records it. The new epoch's samples reach the
sync view only once ``RESTART_SETTLE_S`` of them have arrived: a fresh map rests on the least
arrival latency seen, and a first block delayed by the host (a busy machine, the reconnect
itself) would otherwise place the new epoch late by that delay. Device times that move forward
across the gap (PTP, or relative ones the engine continued, as after ``Acquisition.calz``) keep
their map. The final clock fit in ``/entry/sync`` attrs then describes the last clock epoch only.

Not responsible for: reading devices or threads (the engine), the numerics of clocks, resampling
and conversions (:mod:`daq.sync`), the file layout itself (:mod:`daq.recorder`).

Threads: the writer runs on the engine's dispatcher thread only (one thread touches h5py); the
readers never wait for it (the engine's per-device queues are between them). A failure inside
the writer is kept in :attr:`RunWriter.error` (the engine logs and counts it), the recorder is
closed, and later docs are ignored; :func:`record_run` raises it at the end.
"""

from __future__ import annotations

import errno
import json
import logging
import math
import re
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from daq.acquisition import Event, StreamBlock
from daq.config import RigConfig
from daq.continuous_time import ContinuousTimeline
from daq.recorder import Recorder, RunRecorder, StorageError
from daq.sync import (
    ClockMap,
    Resampler,
    StreamSpec,
    SyncBlock,
    forces_from_pressures,
    heave_pitch_from_lasers,
    trigger_times_from_flags,
    trigger_times_from_latch,
    wind_speed,
)
from daq.sync_check import ClockTruthTracker

__all__ = ["DEFAULT_RHO", "DEFAULT_SYNC_RATE_HZ", "RunWriter", "SyncPulses",
           "default_sync_rate_hz", "record_run", "start_sync_pulses"]

log = logging.getLogger(__name__)

#: Sync rate without a scanner, Hz (with one: the scanner's frame rate).
DEFAULT_SYNC_RATE_HZ = 500.0
#: What a CALZ made during the run keeps in its metadata entry (:meth:`RunWriter._calz_record`).
_CALZ_FIELDS = ("pause_s", "calz_s", "wind_speed_now", "frames_averaged", "offsets_before_pa")
#: Air density used before the barometer's first reading, kg/m^3 (recorded in the rho column).
DEFAULT_RHO = 1.2
#: Window of the held position before a release (h0, alpha0): [t - 0.3 s, t - 0.05 s].
HOLD_WINDOW_S = (0.3, 0.05)
#: Envelope window of the clock maps, s (see :class:`~daq.sync.ClockMap`).
CLOCK_WINDOW_S = 0.5
#: A trigger pulse whose command took longer than this (round trip, s) is no anchor: its host
#: time, the midpoint, is off by at most half of it, and typically far less (the two legs are
#: alike); the clock map takes the median over its anchors.
MAX_ANCHOR_ROUND_TRIP_S = 3e-3
#: Default interval of the trigger pulses record_run sends as clock anchors, s.
SYNC_PULSE_INTERVAL_S = 0.5
#: A device trigger time is paired with the PLC trigger event within this distance, s.
TRIGGER_PAIRING_S = 0.05
#: After a device clock restart, the new epoch's samples are held back from the sync view until
#: this much device time has arrived, s: the fresh clock map then rests on the least-latency
#: block among them (12 blocks of 20 ms), not on the first one alone. Measured with two CPU
#: hogs on the two cores: a first block 124 ms late, the blocks after it back to ~1 ms.
RESTART_SETTLE_S = 0.25

FloatArray = npt.NDArray[np.float64]

# Raw channels of the polled kinds when the driver does not describe itself.
_POLLED_DEFAULTS: Mapping[str, tuple[tuple[str, str], ...]] = {
    "barometer": (("pressure", "Pa"), ("temperature", "K"), ("density", "kg/m^3")),
    "fan": (("speed", "rpm"), ("status_word", "1")),
    "plc": (("armed", "1"), ("released", "1"), ("trigger_count", "1")),
}
_POLLED_RATE_HZ = {"barometer": 1.0, "fan": 10.0, "plc": 10.0}


@dataclass
class _Device:
    """What the writer knows of one device."""

    name: str
    kind: str
    channels: list[str]
    rate_hz: float
    clock: ClockMap | None = None
    timeline: ContinuousTimeline | None = None  # continuous host times across clock refits
    samples: int = 0
    gaps: int = 0
    overflow_samples: int = 0
    last_trigger: float = -math.inf  # scanner: last latched trigger time taken
    pending_triggers: list[float] = field(default_factory=list)  # device times not yet paired
    last_device_time: float = math.nan  # newest finite device time mapped, s
    last_host: float = -math.inf  # host time (run s) of the newest sample pushed to the view
    restart_pending: bool = False  # a restart gap was seen; its first timed sample decides
    break_pending: bool = False  # the clock restarted: mark the break in the view (_push)
    clock_restarts: int = 0  # clock maps started afresh after a device clock restart
    settle_until: float = math.nan  # device time up to which a new epoch's rows are held back
    held: list[tuple[StreamBlock, FloatArray, npt.NDArray[np.bool_]]] = field(
        default_factory=list)  # rows of the new epoch waiting for its map to settle


@dataclass
class _Release:
    time: float
    end_time: float | None = None  # the next arm event: the model is caught, the decay ends
    start_index: int | None = None
    stop_index: int | None = None
    h0: float = math.nan
    alpha0: float = math.nan
    U: list[FloatArray] = field(default_factory=list)


class RunWriter:
    """Subscriber writing one run to HDF5 (see the module docstring).

    Parameters
    ----------
    path : str or Path
        Run file to create.
    config : RigConfig
        The rig config: laser positions and standoffs, tap layout, scanner Pitot channel and
        rates; its text is stored verbatim.
    operator_notes : str
        Free text stored as an attribute of ``/entry``.
    sync_rate_hz : float, optional
        Rate of ``/entry/sync``; default: the scanner's rate, else 500 Hz.
    use_trigger_anchors : bool
        Pair the devices' trigger times (scanner latch, laser flags) with the PLC's trigger
        events and give them to the clock maps as anchors.
    max_hold_s : float
        How long a stalled stream may hold the sync view back, s.
    write_interval_s : float
        Raw and sync rows are appended to the file in batches this often, s (0: every block).
    recorder_options : mapping, optional
        Further keyword arguments of :class:`~daq.recorder.RunRecorder` (``overwrite``,
        ``min_free_bytes``, ``flush_interval_s``, ...).
    clock_truth : ClockTruthTracker, optional
        Simulated rigs: told the host times the sync view uses for every block, to measure them
        against the simulators' truth (:mod:`daq.sync_check`).
    release_hook : callable, optional
        Told of free decays as soon as they begin and end, before their row of the releases
        table is final: ``release_hook("release", t)`` with the release instant and
        ``release_hook("caught", t)`` when arming again ends the last decay (``t`` its last
        row's time), s from the run start. Called on the engine's dispatcher thread; it must
        be quick. The live console cuts its decays with it.
    """

    def __init__(self, path: str | Path, config: RigConfig, *, operator_notes: str = "",
                 sync_rate_hz: float | None = None, use_trigger_anchors: bool = True,
                 max_hold_s: float = 2.0, write_interval_s: float = 0.2,
                 recorder_options: Mapping[str, Any] | None = None,
                 clock_truth: ClockTruthTracker | None = None,
                 release_hook: Callable[[str, float], None] | None = None) -> None:
        self.path = Path(path)
        self.release_hook = release_hook
        self.clock_truth = clock_truth
        self.config = config
        self.operator_notes = operator_notes
        self.use_trigger_anchors = use_trigger_anchors
        self.max_hold_s = max_hold_s
        self.write_interval_s = float(write_interval_s)
        self._raw: dict[str, list[tuple[Any, Any, Any, Any, dict[str, Any]]]] = {}
        self._last_write = -math.inf
        self._recorder_options = dict(recorder_options or {})
        scanners = config.by_role("scanner")
        self._scanner_name = scanners[0].name if scanners else None
        self._pitot_channel = int(scanners[0].settings["pitot_channel"]) if scanners else -1
        self.sync_rate_hz = float(default_sync_rate_hz(config) if sync_rate_hz is None
                                  else sync_rate_hz)
        self._lasers = {inst.name: inst for inst in config.by_role("lasers")}
        self.recorder: Recorder | None = None
        self.error: BaseException | None = None
        self.summary: dict[str, Any] | None = None
        self._t0_ns = 0
        self._devices: dict[str, _Device] = {}
        self._resampler: Resampler | None = None
        self._laser_order: list[str] = []
        self._rho = DEFAULT_RHO
        self._rho_measured = False
        self._sync_rows = 0
        self._recent: deque[tuple[FloatArray, FloatArray, FloatArray]] = deque()
        self._releases: list[_Release] = []
        self._written_releases = 0
        self._calz_count: dict[str, int] = {}
        self._trigger_events: deque[float] = deque(maxlen=64)

    # -- dispatch ------------------------------------------------------------------------------
    def __call__(self, name: str, doc: Any) -> None:
        """Receive one engine doc (dispatcher thread)."""
        if self.error is not None:
            return
        try:
            if name == "start":
                self._start(doc)
            elif self.recorder is None:
                return
            elif name == "block":
                self._block(doc)
            elif name == "event":
                self._event(doc)
            elif name == "stop":
                self._stop(doc)
        except StorageError as exc:  # the file or its disk failed: one line, no traceback
            self.error = exc
            log.error("%s", exc)
            if self.recorder is not None:
                self.recorder.close()
            return  # not re-raised: the engine would log it again, with a traceback
        except Exception as exc:  # kept, reported by record_run; the recorder is closed
            self.error = exc
            log.exception("run writer failed on a %r doc; the run file is closed", name)
            if self.recorder is not None:
                try:
                    self.recorder.close()
                except Exception:  # already failing: the first error is the one reported
                    log.exception("closing the run file after the failure failed too")
            raise

    @staticmethod
    def _clock_map(assumed_floor_s: float = 0.0) -> ClockMap:
        # 0.5 s windows (20 laser blocks, 25 scanner blocks each): a usable slope after ~1.5 s
        # (2 s windows leave a short run with a two-point slope); 600 windows span 5 min.
        return ClockMap(window_s=CLOCK_WINDOW_S, n_windows=600, assumed_floor_s=assumed_floor_s)

    def _time(self, host_ns: Any) -> Any:
        return (np.asarray(host_ns, dtype=np.int64) - self._t0_ns) * 1e-9

    # -- start ---------------------------------------------------------------------------------
    def _start(self, doc: Mapping[str, Any]) -> None:
        self._t0_ns = int(doc["host_time_ns"])
        rec = self.recorder or RunRecorder(self.path, config_text=self.config.text,
                                           rig_name=self.config.name,
                                           operator_notes=self.operator_notes,
                                           **self._recorder_options)
        if rec.state == "new":
            rec.open()
        self.recorder = rec
        n_taps = self.config.taps.n_taps
        tap_names = [f"tap{i:03d}" for i in range(n_taps)]
        streams: list[StreamSpec] = []
        for name, info in doc["devices"].items():
            kind = str(info["kind"])
            describe = info.get("describe", {}) or {}
            if kind == "laser":
                rate = float(self._lasers[name].settings["rate_hz"]) if name in self._lasers \
                    else 4000.0
                rec.add_stream(name, ["distance"], "m", rate, "float64",
                               extra={"error_code": "int32", "triggered": "bool"})
                dev = _Device(name, kind, ["distance"], rate, self._clock_map(),
                              ContinuousTimeline(1.0 / rate))
                if name in self._lasers:
                    self._laser_order.append(name)
                    streams.append(StreamSpec(f"laser.{name}", 1.0 / rate, "boxcar"))
            elif kind == "scanner":
                inst = self.config.instrument(name)
                rate = float(inst.settings["rate_hz"])
                rec.add_stream(name, [*tap_names, "pitot"], "Pa", rate, "float32",
                               extra={"trigger_time": "float64"})
                dev = _Device(name, kind, [*tap_names, "pitot"], rate, self._clock_map(),
                              ContinuousTimeline(1.0 / rate))
                if name == self._scanner_name:
                    streams.append(StreamSpec("pressure", 1.0 / rate, "linear", n_taps))
                    streams.append(StreamSpec("pitot", 1.0 / rate, "linear"))
            else:
                pairs = [(k, str(v.get("units", "") or "1")) for k, v in describe.items()
                         if tuple(v.get("shape", ())) == () and k != "host_time_ns"]
                if not pairs:
                    pairs = list(_POLLED_DEFAULTS.get(kind, (("value", "1"),)))
                channels = [k for k, _ in pairs]
                rate = _POLLED_RATE_HZ.get(kind, 1.0)
                rec.add_stream(name, channels, [u for _, u in pairs], rate, "float64")
                dev = _Device(name, kind, channels, rate)
            self._devices[name] = dev
        if len(self._laser_order) < 2:
            self._laser_order = []  # h and alpha need two lasers: no laser stream in the view
            streams = [s for s in streams if not s.name.startswith("laser.")]
        rec.add_sync(tap_names)
        rec.start(self._t0_ns)
        if streams:
            self._resampler = Resampler(streams, rate_hz=self.sync_rate_hz, t_start=0.0,
                                        max_hold_s=self.max_hold_s)

    # -- blocks --------------------------------------------------------------------------------
    def _block(self, block: StreamBlock) -> None:
        dev = self._devices.get(block.device)
        if dev is None:
            return
        rec = self.recorder
        assert rec is not None
        n = len(block)
        dev.samples += n
        dev.overflow_samples += int(block.overflow_samples)
        restarts: list[int] = []  # counters after which the device restarted (length -1)
        for after, length in block.gaps:
            rec.add_gap(dev.name, int(after), int(length) if int(length) >= 1 else -1)
            dev.gaps += 1
            if int(length) < 0:
                restarts.append(int(after))
        if n == 0:
            dev.restart_pending = dev.restart_pending or bool(restarts)
            return
        counter = (block.counter if block.counter is not None
                   else np.arange(dev.samples - n, dev.samples, dtype=np.int64))
        values = block.values
        if dev.kind == "laser":
            distance = np.asarray(values["distance"], dtype=np.float64)
            self._buffer_raw(dev, block, counter, distance,
                             {"error_code": values.get("error_code", np.zeros(n, np.int32)),
                              "triggered": values.get("triggered", np.zeros(n, bool))})
        elif dev.kind == "scanner":
            n_taps = self.config.taps.n_taps
            pressure = np.asarray(values["pressure"], dtype=np.float64)
            pitot = np.asarray(values["pitot"], dtype=np.float64).reshape(n, 1)
            self._buffer_raw(dev, block, counter, np.hstack([pressure[:, :n_taps], pitot]),
                             {"trigger_time": values.get("trigger_time", np.full(n, np.nan))})
        else:
            table = np.column_stack([np.asarray(values.get(c, np.full(n, np.nan)),
                                                dtype=np.float64).reshape(n)
                                     for c in dev.channels])
            self._buffer_raw(dev, block, counter, table, {})
            if dev.kind == "barometer" and "density" in values:
                rho = float(np.asarray(values["density"], dtype=np.float64)[-1])
                if math.isfinite(rho) and rho > 0:
                    self._rho, self._rho_measured = rho, True
            self._write_if_due()
            return
        if block.device_time is None or dev.clock is None:
            self._write_if_due()
            return
        if not restarts:  # the usual case: one clock epoch, the whole block
            self._map_rows(dev, block)
            self._write_if_due()
            return
        # A restart gap splits the block: the rows before it belong to the old device clock
        # (and its map), the rows after it perhaps to a restarted one (see _map_rows).
        cuts = sorted({int(np.searchsorted(counter, after, side="right")) for after in restarts})
        bounds = [0, *(k for k in cuts if 0 < k < n), n]
        for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
            if lo in cuts:
                dev.restart_pending = True
            self._map_rows(dev, block if hi - lo == n else _take_rows(block, lo, hi))
        if n in cuts:  # the restart follows this block's rows: the next block decides
            dev.restart_pending = True
        self._write_if_due()

    def _map_rows(self, dev: _Device, block: StreamBlock) -> None:
        """Feed one clock epoch's rows of a block to the clock map and the sync view.

        Called with a whole block, or with the rows on one side of a restart gap. After a
        restart gap (``dev.restart_pending``) the first finite device time decides whether the
        device clock restarted (see :meth:`_restart_clock`). After a restart the rows are held
        back from the sync view until ``RESTART_SETTLE_S`` of device time has arrived; the
        clock map takes every block's pair at once.
        """
        assert dev.clock is not None
        t_dev = np.asarray(block.device_time, dtype=np.float64)
        t_host = self._time(block.host_time_ns)
        finite = np.isfinite(t_dev)
        if not np.any(finite):
            return
        rows = np.flatnonzero(finite)
        first, last = int(rows[0]), int(rows[-1])
        if dev.restart_pending:
            dev.restart_pending = False
            # Device time not after the last one mapped: the device clock restarted with the
            # scan (relative frame times start again at 0 without PTP, DEVICES.md A.1.1), and
            # the map from the previous scan no longer applies. Absolute (PTP) frame times,
            # and relative ones the engine continued across its own pause (Acquisition.calz),
            # move forward: their map stays valid and is kept. (NaN: nothing mapped yet.)
            if float(t_dev[first]) <= dev.last_device_time:
                self._restart_clock(dev, float(t_dev[first]), float(t_host[first]))
        dev.clock.update(t_dev[last], float(t_host[last]))
        if self.use_trigger_anchors:
            self._anchor_triggers(dev, block, t_dev)
            if dev.pending_triggers:
                self._pair_triggers(dev)  # pulses seen before the clock map was ready
        dev.last_device_time = float(t_dev[last])
        if math.isnan(dev.settle_until):
            self._push(dev, block, t_dev, finite)
            return
        dev.held.append((block, t_dev, finite))
        if dev.last_device_time >= dev.settle_until:
            self._release_held(dev)

    def _release_held(self, dev: _Device) -> None:
        """Push the rows held since a clock restart, on the map fitted from all of them."""
        held, dev.held, dev.settle_until = dev.held, [], math.nan
        for block, t_dev, finite in held:
            self._push(dev, block, t_dev, finite)

    def _restart_clock(self, dev: _Device, t_device: float, t_host: float) -> None:
        """Start a fresh clock map and timeline after the device clock went back to ``t_device``.

        Nothing already mapped changes: the raw rows and the sync rows written keep the old
        map's times, and the old map's samples stay in the resampler. What is discarded is what
        only the old clock could use: its fit, the timeline's continuity, the latched trigger
        time and the trigger times still waiting for their PLC event (device times on the old
        clock: paired with the new map they would be anchors of the wrong epoch).

        Parameters
        ----------
        dev : _Device
            The device (clocked: it has a map and a timeline).
        t_device : float
            Device time of the first sample of the new clock epoch, s.
        t_host : float
            Its host arrival time, s from the run start.
        """
        assert dev.clock is not None and dev.timeline is not None
        rec = self.recorder
        assert rec is not None
        self._release_held(dev)  # an epoch still settling goes out on its own map
        # The latency floor is a property of the transport (same link, same driver), not of
        # the device clock: the old anchors' value keeps the new map from being late by it
        # until the new epoch's first trigger pulse is paired (0.5 s pulses). Clamped at 0:
        # a floor cannot be negative (a negative median is the anchors' noise).
        floor = dev.clock.latency_floor_s
        floor = floor if math.isfinite(floor) and floor > 0.0 else 0.0
        previous = dev.last_device_time
        dev.clock = self._clock_map(assumed_floor_s=floor)
        dev.timeline.restart()
        dev.last_trigger = -math.inf
        dev.pending_triggers.clear()
        dev.clock_restarts += 1
        dev.break_pending = True
        dev.settle_until = t_device + RESTART_SETTLE_S
        text = (f"{dev.name}: device clock restarted (device time {t_device:.6f} s after "
                f"{previous:.6f} s); clock map started afresh, latency floor "
                f"{floor * 1e3:.3f} ms kept")
        log.warning("%s", text)
        rec.add_event(t_host, "clock_restart", text)

    def _buffer_raw(self, dev: _Device, block: StreamBlock, counter: Any, values: Any,
                    extra: Mapping[str, Any]) -> None:
        n = len(block)
        t_dev = (np.full(n, np.nan) if block.device_time is None
                 else np.asarray(block.device_time, dtype=np.float64))
        self._raw.setdefault(dev.name, []).append(
            (np.asarray(block.host_time_ns, dtype=np.int64), t_dev,
             np.asarray(counter, dtype=np.int64), np.asarray(values),
             {k: np.asarray(v) for k, v in extra.items()}))

    def _write_if_due(self, *, force: bool = False) -> None:
        """Append the buffered raw rows and the ready sync rows (every ``write_interval_s``).

        Appending per block costs ~0.1 ms per dataset in h5py: a few hundred blocks per
        second times ~8 datasets would take longer than the run. Batching bounds it.
        """
        now = time.monotonic()
        if not force and now - self._last_write < self.write_interval_s:
            return
        self._last_write = now
        rec = self.recorder
        assert rec is not None
        for name, parts in self._raw.items():
            if not parts:
                continue
            host = np.concatenate([p[0] for p in parts])
            t_dev = np.concatenate([p[1] for p in parts])
            counter = np.concatenate([p[2] for p in parts])
            values = np.concatenate([p[3] for p in parts])
            extra = {k: np.concatenate([p[4][k] for p in parts]) for k in parts[0][4]}
            rec.append_raw(name, host, t_dev, counter, values, extra=extra)
            parts.clear()
        if self._resampler is not None:
            self._write_sync(self._resampler.pull())

    def _anchor_triggers(self, dev: _Device, block: StreamBlock, t_dev: FloatArray) -> None:
        if dev.kind == "scanner" and "trigger_time" in block.values:
            found = trigger_times_from_latch(block.values["trigger_time"], dev.last_trigger)
            if found.size:
                dev.last_trigger = float(found[-1])
        elif dev.kind == "laser" and "triggered" in block.values:
            ok = np.isfinite(t_dev)
            found = trigger_times_from_flags(t_dev[ok],
                                             np.asarray(block.values["triggered"])[ok],
                                             1.0 / dev.rate_hz)
        else:
            return
        dev.pending_triggers.extend(float(t) for t in found)
        del dev.pending_triggers[:-32]
        self._pair_triggers(dev)

    def _pair_triggers(self, dev: _Device) -> None:
        if dev.clock is None or not dev.clock.ready or not self._trigger_events:
            return
        events = np.fromiter(self._trigger_events, dtype=np.float64)
        left: list[float] = []
        for td in dev.pending_triggers:
            predicted = dev.clock.to_host(td)
            k = int(np.argmin(np.abs(events - predicted)))
            if abs(events[k] - predicted) <= TRIGGER_PAIRING_S:
                dev.clock.add_anchor(td, float(events[k]))
            elif predicted > events[-1]:
                left.append(td)  # its PLC event may still come
        dev.pending_triggers = left

    def _push(self, dev: _Device, block: StreamBlock, t_dev: FloatArray,
              finite: npt.NDArray[np.bool_]) -> None:
        r = self._resampler
        if r is None or dev.clock is None or dev.timeline is None:
            return
        t = dev.timeline.map(t_dev[finite], dev.clock.to_host)
        # Only samples after every earlier one of the block: the resampler needs increasing
        # times, and a sample compared with its neighbour alone would let one that went back
        # (device time going back inside a block) through after the first.
        keep = (np.concatenate(([True], t[1:] > np.maximum.accumulate(t)[:-1])) if t.size
                else np.zeros(0, bool))
        t = t[keep]
        if dev.break_pending and t.size:
            dev.break_pending = False
            self._mark_break(dev, t[0])
        if t.size:
            dev.last_host = max(dev.last_host, float(t[-1]))
        if self.clock_truth is not None:
            self.clock_truth.observe(dev.name, t, t_dev[finite][keep], self._t0_ns * 1e-9)

        def rows(a: Any) -> FloatArray:
            return np.asarray(a, dtype=np.float64)[finite][keep]

        if dev.kind == "laser" and dev.name in self._laser_order:
            d = rows(block.values["distance"])
            if "error_code" in block.values:
                d = np.where(rows(block.values["error_code"]) != 0, np.nan, d)
            r.push(f"laser.{dev.name}", t, d)
        elif dev.kind == "scanner" and dev.name == self._scanner_name:
            n_taps = self.config.taps.n_taps
            r.push("pressure", t, rows(block.values["pressure"])[:, :n_taps])
            r.push("pitot", t, rows(block.values["pitot"]))

    def _mark_break(self, dev: _Device, t_next: float) -> None:
        """Put a NaN sample between a device's last sample and ``t_next`` (run s) in the view.

        After a clock restart the spacing between the two epochs' samples is the difference of
        two maps, the new one fitted from a single block: a sync row interpolated across it
        would blend samples whose relative timing is unknown to milliseconds. The NaN sample
        (sync view only, not the raw record) makes every row between them NaN, whatever the
        spacing, and no row outside them: the restart stays visible where it is.
        """
        r = self._resampler
        if r is None or dev.last_host == -math.inf:
            return
        # Midway; or just after the last sample if the new map put the first one on or before it
        # (those samples are dropped as overlapping by the resampler, the break still marked).
        t_nan = (0.5 * (dev.last_host + t_next) if t_next > dev.last_host
                 else float(np.nextafter(dev.last_host, math.inf)))
        at = np.array([t_nan])
        if dev.kind == "laser" and dev.name in self._laser_order:
            r.push(f"laser.{dev.name}", at, np.full(1, np.nan))
        elif dev.kind == "scanner" and dev.name == self._scanner_name:
            r.push("pressure", at, np.full((1, self.config.taps.n_taps), np.nan))
            r.push("pitot", at, np.full(1, np.nan))

    # -- sync view -----------------------------------------------------------------------------
    def _write_sync(self, sb: SyncBlock) -> None:
        n = len(sb)
        if n == 0:
            return
        rec = self.recorder
        assert rec is not None
        nan = np.full(n, np.nan)
        h, alpha = nan, nan
        if self._laser_order:
            d = np.column_stack([sb.values[f"laser.{name}"] for name in self._laser_order])
            x = [float(self._lasers[name].settings["x"]) for name in self._laser_order]
            s = [float(self._lasers[name].settings["standoff_mm"]) * 1e-3
                 for name in self._laser_order]
            if d.shape[1] > 3:  # the conversion takes 2 or 3 lasers: the first three
                d, x, s = d[:, :3], x[:3], s[:3]
            hp = heave_pitch_from_lasers(d, x, s)
            h, alpha = hp.h, hp.alpha
        n_taps = self.config.taps.n_taps
        if "pressure" in sb.values:
            pressure = sb.values["pressure"]
            lift, moment = forces_from_pressures(pressure, self.config.taps)
            rho = np.full(n, self._rho)
            U = wind_speed(sb.values["pitot"], rho).speed
        else:
            pressure = np.full((n, n_taps), np.nan)
            lift, moment, U, rho = nan, nan, nan, np.full(n, self._rho)
        rec.append_sync(sb.time, h=h, alpha=alpha, lift=lift, moment=moment, pressure=pressure,
                        U=U, rho=rho)
        base = self._sync_rows
        self._sync_rows += n
        self._track_releases(base, sb.time, h, alpha, U)

    def _track_releases(self, base: int, t: FloatArray, h: FloatArray, alpha: FloatArray,
                        U: FloatArray) -> None:
        self._recent.append((t, h, alpha))
        while len(self._recent) > 1 and self._recent[1][0][0] < t[-1] - 2 * HOLD_WINDOW_S[0]:
            self._recent.popleft()
        for rel in self._releases[self._written_releases:]:
            if rel.start_index is None and t[-1] >= rel.time:
                rel.start_index = base + int(np.searchsorted(t, rel.time, side="left"))
                rel.h0, rel.alpha0 = self._held(rel.time)
            if (rel.stop_index is None and rel.end_time is not None
                    and t[-1] >= rel.end_time):
                rel.stop_index = base + int(np.searchsorted(t, rel.end_time, side="left"))
            if rel.start_index is not None:
                lo = max(rel.start_index - base, 0)
                hi = t.size if rel.stop_index is None else max(rel.stop_index - base, lo)
                if lo < min(hi, t.size):
                    rel.U.append(U[lo:hi])
        self._write_finished_releases(final=False)

    def _held(self, t_release: float) -> tuple[float, float]:
        t = np.concatenate([b[0] for b in self._recent])
        sel = (t >= t_release - HOLD_WINDOW_S[0]) & (t < t_release - HOLD_WINDOW_S[1])
        out = []
        for col in (1, 2):
            v = np.concatenate([b[col] for b in self._recent])[sel]
            v = v[np.isfinite(v)]
            out.append(float(np.median(v)) if v.size else math.nan)
        return out[0], out[1]

    def _write_finished_releases(self, *, final: bool) -> None:
        rec = self.recorder
        assert rec is not None
        pending = self._releases[self._written_releases:]
        for i, rel in enumerate(pending):
            following = pending[i + 1] if i + 1 < len(pending) else None
            if rel.stop_index is not None:
                stop = rel.stop_index
            elif following is not None and following.start_index is not None:
                stop = following.start_index
            elif final:
                stop = self._sync_rows
            else:
                return
            start = rel.start_index if rel.start_index is not None else stop
            if rel.start_index is None:
                rel.h0, rel.alpha0 = self._held(rel.time)
            u = np.concatenate(rel.U) if rel.U else np.zeros(0)
            u = u[: max(stop - start, 0)]
            u = u[np.isfinite(u)]
            rec.add_release(release_time=rel.time, start_index=start, stop_index=max(stop, start),
                            U=float(np.median(u)) if u.size else math.nan, h0=rel.h0,
                            alpha0=rel.alpha0)
            self._written_releases += 1

    # -- events --------------------------------------------------------------------------------
    def _calz_record(self, event: Event, t: float) -> None:
        """Keep a CALZ made during the run: ``/entry/metadata/calz_<device>_<n>``.

        Its run time (s), pause, duration, the wind speed vouched for and the zero removed per
        scanner channel (``offsets_before_pa``: the mean over the last frames before the
        scan stopped, Pa; what the scanner's pressures shifted by at the CALZ).
        """
        rec = self.recorder
        assert rec is not None
        device = _name_part(event.device or "scanner")
        self._calz_count[device] = n = self._calz_count.get(device, 0) + 1
        record = {"time_s": t, **{k: v for k, v in event.data.items()
                                  if k in _CALZ_FIELDS and v is not None}}
        rec.add_metadata(f"calz_{device}_{n}", record)

    def _event(self, event: Event) -> None:
        rec = self.recorder
        assert rec is not None
        t = float(self._time(event.host_time_ns))
        text = event.text if event.device is None else f"{event.device}: {event.text}"
        # The event's numbers go into its text; arrays (a CALZ's offsets per channel) do not
        # fit there and go to /entry/metadata instead (below).
        scalars = {k: v for k, v in event.data.items() if not isinstance(v, np.ndarray)}
        if scalars:
            text = f"{text} {json.dumps(scalars, default=str)}"
        kind = event.kind.encode("utf-8")[:32].decode("utf-8", "ignore") or "event"
        rec.add_event(t, kind, text.encode("utf-8")[:1024].decode("utf-8", "ignore"))
        if event.kind == "calz":
            self._calz_record(event, t)
        if event.kind == "release":
            command = int(event.data.get("command_ns", event.host_time_ns))
            self._releases.append(_Release(time=float(self._time(command))))
            if self.release_hook is not None:
                self.release_hook("release", self._releases[-1].time)
        elif event.kind == "arm" and self._releases and self._releases[-1].end_time is None:
            # Arming again catches the model: the free decay of the last release ends before
            # the arm command (less one sync period: a sync row averages the lasers over
            # +- half a period, which must not reach into the caught model).
            self._releases[-1].end_time = t - 1.0 / self.sync_rate_hz
            if self.release_hook is not None:
                self.release_hook("caught", self._releases[-1].end_time)
        elif event.kind == "trigger":
            # Its host time is known to half the command's round trip: an anchor only if that
            # is well inside the alignment the sync view promises.
            round_trip = float(event.data.get("round_trip_s", 0.0))
            if round_trip > MAX_ANCHOR_ROUND_TRIP_S:
                return
            self._trigger_events.append(t)
            for dev in self._devices.values():
                if dev.pending_triggers:
                    self._pair_triggers(dev)

    # -- stop ----------------------------------------------------------------------------------
    def _stop(self, doc: Mapping[str, Any]) -> None:
        rec = self.recorder
        assert rec is not None
        for dev in self._devices.values():
            self._release_held(dev)  # a restart shortly before the stop: its rows still count
        self._write_if_due(force=True)
        # Not flush(): at the end the streams stop at slightly different times (the last laser
        # block in flight, the last scanner frame); the rows past the earliest end would be
        # partial (NaN). The view ends where every stream has data (or stalled for longer than
        # max_hold_s); the stragglers' samples stay in the raw streams.
        if self._resampler is not None:
            self._write_sync(self._resampler.pull())
        self._write_finished_releases(final=True)
        fits = self.clock_fits()
        offsets = {n: f["offset_s"] for n, f in fits.items() if math.isfinite(f["offset_s"])}
        drifts = {n: f["drift_ppm"] for n, f in fits.items() if math.isfinite(f["drift_ppm"])}
        residuals = [f["residual_s"] for f in fits.values() if math.isfinite(f["residual_s"])]
        rec.set_sync_attrs(clock_offset_s=offsets, clock_drift_ppm=drifts,
                           residual_misalignment_s=max(residuals) if residuals else None)
        summary = self._summary(doc)
        rec.add_metadata("acquisition_summary", _storable(summary))
        rec.close()
        self.summary = summary

    @property
    def t0_ns(self) -> int:
        """Host time of the run's time 0 (``time.monotonic_ns`` clock), ns."""
        return self._t0_ns

    def clock_fits(self) -> dict[str, dict[str, float]]:
        """Per clocked device: offset (s), drift (ppm), residual (s), anchors, pairs."""
        out: dict[str, dict[str, float]] = {}
        for name, dev in self._devices.items():
            cm = dev.clock
            if cm is None or not cm.ready:
                continue
            out[name] = {"offset_s": cm.offset_s, "drift_ppm": cm.drift_ppm,
                         "residual_s": cm.residual_s, "latency_floor_s": cm.latency_floor_s,
                         "anchors": float(cm.n_anchors), "pairs": float(cm.n_pairs)}
        return out

    def _summary(self, doc: Mapping[str, Any]) -> dict[str, Any]:
        return {
            "file": str(self.path),
            "reason": str(doc.get("reason", "")),
            "duration_s": float(doc.get("duration_s", 0.0)),
            "samples": {n: d.samples for n, d in self._devices.items()},
            "gaps": {n: d.gaps for n, d in self._devices.items()},
            "overflow_samples": {n: d.overflow_samples for n, d in self._devices.items()},
            "overflows": int(doc.get("overflows", 0)),
            "faults": int(doc.get("faults", 0)),
            "sync_rows": self._sync_rows,
            "sync_rate_hz": self.sync_rate_hz,
            "releases": self._written_releases,
            "rho_measured": self._rho_measured,
            "late_samples": dict(self._resampler.late_samples) if self._resampler else {},
            "overlapping_samples": (dict(self._resampler.overlapping_samples)
                                    if self._resampler else {}),
            "clock_restarts": {n: d.clock_restarts for n, d in self._devices.items()
                               if d.clock is not None},
            "timelines": {n: {"largest_slewed_s": d.timeline.largest_slewed_s,
                              "steps": d.timeline.steps}
                          for n, d in self._devices.items() if d.timeline is not None},
            "clock_fits": self.clock_fits(),
        }


class SyncPulses:
    """A thread pulsing the PLC's trigger line every ``interval_s`` (clock-map anchors).

    Start it with :func:`start_sync_pulses`; :meth:`stop` ends it. ``failures`` counts the
    pulses that failed (each logged; the PLC's own fault reporting covers the link).
    """

    def __init__(self, acq: Any, interval_s: float) -> None:
        import threading

        self._acq = acq
        self._interval_s = interval_s
        self._stop = threading.Event()
        self.failures = 0
        self._thread = threading.Thread(target=self._run, name="windrig-sync-pulses",
                                        daemon=True)

    def start(self) -> None:
        """Start pulsing."""
        self._thread.start()

    def _run(self) -> None:
        from daq.errors import DaqError

        while not self._stop.wait(self._interval_s):
            try:
                self._acq.trigger()
            except DaqError as exc:  # the PLC's own fault reporting covers the link
                self.failures += 1
                log.warning("sync pulse failed (%d so far): %s", self.failures, exc)

    def stop(self) -> None:
        """Stop pulsing and join the thread."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0 + self._interval_s)


def _name_part(device: str) -> str:
    """Return a device name as part of a metadata name (letters, digits and ``_`` only)."""
    return re.sub(r"\W", "_", device)


def default_sync_rate_hz(config: RigConfig) -> float:
    """Return a rig's synchronised row rate, Hz: its scanner's frame rate, else the default."""
    scanners = config.by_role("scanner")
    return float(scanners[0].settings["rate_hz"]) if scanners else DEFAULT_SYNC_RATE_HZ


def start_sync_pulses(acq: Any, drivers: Mapping[str, tuple[str, Any]],
                      interval_s: float | None) -> SyncPulses | None:
    """Pulse the PLC's trigger line every ``interval_s`` while ``acq`` runs.

    Parameters
    ----------
    acq : Acquisition
        The running engine (its :meth:`~daq.acquisition.Acquisition.trigger` is called).
    drivers : mapping
        The engine's ``name -> (kind, driver)``: without a ``"plc"`` there is nothing to pulse.
    interval_s : float or None
        Interval, s (> 0); None: no pulses.

    Returns
    -------
    SyncPulses or None
        The running pulser (call ``stop()``), or None when there is none.
    """
    if interval_s is None or not any(kind == "plc" for kind, _ in drivers.values()):
        return None
    if not (math.isfinite(interval_s) and interval_s > 0):
        raise ValueError(f"sync_pulse_interval_s must be > 0 s or None, got {interval_s!r}")
    pulser = SyncPulses(acq, float(interval_s))
    pulser.start()
    return pulser


def _take_rows(block: StreamBlock, lo: int, hi: int) -> StreamBlock:
    """Rows ``lo:hi`` of a block (every value holds one row per sample), without its gaps."""
    return StreamBlock(
        device=block.device, kind=block.kind, seq=block.seq,
        host_time_ns=block.host_time_ns[lo:hi],
        device_time=None if block.device_time is None else block.device_time[lo:hi],
        counter=None if block.counter is None else block.counter[lo:hi],
        values={k: np.asarray(v)[lo:hi] for k, v in block.values.items()},
        gaps=(), raw=block.raw, overflow_samples=0)


def _check_alignment(path: Path, rig: Any, writer: RunWriter) -> dict[str, Any]:
    """Check the sync view against the simulated rig's truth; store the result in the file.

    Two measures (:mod:`daq.sync_check`): the clock error of every block the sync view used
    (per device, and the misalignment between devices), and the delay of the h, alpha, lift and
    moment channels against the tunnel's decays (needs a release). Only for a tunnel on the
    host's real time (its clock has ``origin_s``).
    """
    from daq.sync_check import check_run

    origin = getattr(rig.tunnel.clock, "origin_s", None)
    if origin is None or writer.clock_truth is None:
        return {}
    return check_run(path, writer.clock_truth,
                     true_time_of=lambda name, t: origin + rig.simulators[name].true_time_of(t),
                     decay_truth=rig.tunnel.decay_truth, origin_s=origin)


def _storable(value: Any) -> Any:
    """Make a summary storable as HDF5 metadata (names of letters, digits, _; no None)."""
    if isinstance(value, Mapping):
        return {"".join(c if c.isalnum() or c == "_" else "_" for c in str(k)): _storable(v)
                for k, v in value.items()}
    if value is None:
        return ""
    return value


def record_run(config: RigConfig, out_path: str | Path, *, duration_s: float,
               simulate: bool = True,
               actions: Callable[[Any, Any], None] | None = None, progress: bool = True,
               operator_notes: str = "", calz: bool | None = None,
               writer_options: Mapping[str, Any] | None = None,
               sync_pulse_interval_s: float | None = SYNC_PULSE_INTERVAL_S) -> dict[str, Any]:
    """Acquire a rig for ``duration_s`` into one HDF5 run file and return the summary.

    Parameters
    ----------
    config : RigConfig
        The rig. With ``simulate`` its simulated instruments are started (loopback); without,
        its URLs must be real (an ``"auto"`` URL is a :class:`~daq.errors.ConfigError`).
    out_path : str or Path
        The run file to create.
    duration_s : float
        Length of the run, s (> 0), from the engine's start.
    simulate : bool
        Start the simulated rig of the config.
    actions : callable, optional
        ``actions(acquisition, rig)`` called in its own thread once the engine runs (``rig`` is
        the :class:`~daq.simulated_rig.SimulatedRig` or None): scripted fan and release
        sequences. It should finish within ``duration_s``; it is joined before the engine
        stops, and an exception in it is raised after the file is closed.
    progress : bool
        Show a tqdm progress bar over the duration.
    operator_notes : str
        Stored with the run.
    calz : bool, optional
        Zero the scanner (CALZ) before the engine starts; default: with ``simulate`` (whose
        tunnel starts wind-off). With a real rig, ``calz=True`` asserts that the wind is off
        (the driver refuses a CALZ with a nonzero wind speed; it is told 0 m/s).
    writer_options : mapping, optional
        Further keyword arguments of :class:`RunWriter`.
    sync_pulse_interval_s : float or None
        Pulse the PLC's trigger line this often during the run, s (None: never): the anchors
        that tie every device clock to the host's (see :class:`~daq.sync.ClockMap`). Needs a
        PLC; a failed pulse is logged and the run goes on.

    Returns
    -------
    dict
        The writer's summary (``samples``, ``gaps``, ``overflow_samples`` per device,
        ``clock_fits``, ``sync_rows``, ``releases``, ...) plus the engine's ``errors``.
    """
    import threading

    from tqdm import tqdm

    from daq.acquisition import Acquisition, drivers_from_config

    if not (isinstance(duration_s, (int, float)) and math.isfinite(duration_s)
            and duration_s > 0):
        raise ValueError(f"duration_s must be a number > 0 s, got {duration_s!r}")
    path = Path(out_path)
    overwrite = bool(dict(dict(writer_options or {}).get("recorder_options", {}))
                     .get("overwrite", False))
    if path.exists() and not overwrite:
        raise StorageError(errno.EEXIST, f"run file {path} already exists; refusing to "
                           "overwrite a recorded run", str(path))
    if calz is None:
        calz = simulate
    recorder_options = dict(dict(writer_options or {}).get("recorder_options", {}))
    recorder = RunRecorder(path, config_text=config.text, rig_name=config.name,
                           operator_notes=operator_notes, **recorder_options)
    recorder.open()  # a missing or read-only directory, a full disk: fail before anything starts
    rig = None
    if simulate:
        from daq.simulated_rig import start_simulated_rig

        rig = start_simulated_rig(config)
        live = rig.config
    else:
        live = config
    action_error: list[BaseException] = []
    try:
        options = dict(writer_options or {})
        if rig is not None and "clock_truth" not in options:
            options["clock_truth"] = ClockTruthTracker()
        writer = RunWriter(out_path, live, operator_notes=operator_notes, **options)
        writer.recorder = recorder  # opened above; declared and started at the "start" doc
        drivers = drivers_from_config(live)
        if calz:
            for name, (kind, driver) in drivers.items():
                if kind == "scanner":
                    driver.open()  # idempotent: the engine's open() keeps this connection
                    calz_s = driver.calz(wind_speed_now=0.0)
                    # The file says that its pressures start zeroed (the offsets themselves
                    # are the scanner's: it reports none).
                    recorder.add_metadata(f"calz_{_name_part(name)}_start",
                                          {"calz_s": float(calz_s), "wind_speed_now": 0.0})
        acq = Acquisition(drivers, subscribers=[writer], metadata={"rig": live.name})
        acq.start()
        reason = "duration"
        runner: threading.Thread | None = None
        pulser: SyncPulses | None = None
        try:
            if actions is not None:
                def run_actions() -> None:
                    try:
                        actions(acq, rig)
                    except BaseException as exc:  # re-raised in the caller's thread below
                        log.exception("the actions callback failed")
                        action_error.append(exc)

                runner = threading.Thread(target=run_actions, name="windrig-actions",
                                          daemon=True)
                runner.start()
            pulser = start_sync_pulses(acq, drivers, sync_pulse_interval_s)
            end = time.monotonic() + float(duration_s)
            # mininterval: redrawn at most twice a second (a log file gets a line per redraw).
            bar = (tqdm(total=round(float(duration_s), 1), unit="s", mininterval=0.5,
                        desc=f"recording {path.name}", bar_format="{l_bar}{bar}| "
                        "{n:.1f}/{total:.1f} s [{elapsed}<{remaining}]") if progress else None)
            try:
                while (left := end - time.monotonic()) > 0 and writer.error is None:
                    time.sleep(min(0.1, left))
                    if bar is not None:
                        done = round(float(duration_s) - max(end - time.monotonic(), 0.0), 1)
                        bar.update(done - bar.n)
            except KeyboardInterrupt:  # Ctrl-C: stop cleanly, the file is closed and valid
                log.warning("interrupted: stopping the run")
                reason = "interrupted"
            finally:
                if bar is not None:
                    bar.close()
            if runner is not None:
                runner.join(max(1.0, 0.25 * float(duration_s)))
        finally:
            if pulser is not None:
                pulser.stop()
            engine = acq.stop(reason)
    finally:
        if rig is not None:
            rig.close()
        if recorder.state == "declaring":  # the engine never started: no run, no file
            recorder.close()
            path.unlink(missing_ok=True)
    if writer.error is not None:
        raise writer.error
    if action_error:
        raise action_error[0]
    summary = dict(writer.summary or {})
    summary["sync_pulses_failed"] = 0 if pulser is None else pulser.failures
    if rig is not None and writer.summary is not None:
        summary["alignment"] = _check_alignment(path, rig, writer)
    summary["errors"] = list(engine.get("errors", []))
    summary["subscriber_errors"] = dict(engine.get("subscriber_errors", {}))
    return summary
