"""The run writer: engine records -> clock maps -> sync view -> one run file.

Responsibility: :class:`RunWriter`, a ``(name, doc)`` subscriber of
:class:`~daq.acquisition.engine.Acquisition` that writes one run in the layout of
:mod:`daq.recording.layout`: the raw stream of every device, the synchronised view (every
device clock mapped onto the host clock by a :class:`~daq.sync.clock_map.ClockMap`, the streams
resampled onto one time base by a :class:`~daq.sync.resample.Resampler` and converted to h,
alpha, lift, moment, U, rho by :func:`~daq.recording.sync_view.physical_columns`), the events
and one row per release (:class:`~daq.recording.releases.ReleaseRows`). What it keeps per
device is a :class:`~daq.recording.devices.DeviceState`.

Device clock restarts: a restart gap (length -1, e.g. the scanner's scan restarted after a TCP
reset) after which the device time goes back (relative frame times without PTP restart at 0)
starts a fresh clock map and timeline for that device, from the first sample after the gap (a
block is split there); the rows already written keep their times, a NaN sample marks the break
in the sync view, and a ``clock_restart`` event records it. The new epoch's samples reach the
sync view only once ``RESTART_SETTLE_S`` of them have arrived, and as long again has passed on
the host since the first of them: a fresh map rests on the least arrival latency seen, and a
first block delayed by the host (a busy machine, the reconnect itself) would otherwise place
the new epoch late by that delay; a backlog that reaches the host at once is no measure of it.
Device times that move forward across the gap (PTP, or relative ones the engine continued, as
after ``Acquisition.calz``) keep their map. The final clock fit in ``/entry/sync`` attrs then
describes the last clock epoch only.

Not responsible for: reading devices or threads (the engine), the numerics of clocks, resampling
and conversions (:mod:`daq.sync`), the file (:mod:`daq.recording.recorder`), running a rig into
a file (:mod:`daq.recording.run`), or any simulator. A 3-DOF rig's p, drag, p0: see the layout.
An ``analog`` device is a clocked raw stream; without a scanner, its ``pitot`` (Pa) gives U.

Threads: the writer runs on the engine's dispatcher thread only (one thread touches h5py); the
readers never wait for it (the engine's per-device queues are between them). A failure inside
the writer is kept in :attr:`RunWriter.error` (the engine logs and counts it), the recorder is
closed, and later docs are ignored; :func:`daq.recording.run.record_run` raises it at the end.

Longer than 600 lines: :class:`RunWriter` is one subscriber whose start, blocks, clock restarts,
events and stop all work on the same per-run state (the devices' clock maps, the resampler, the
rows written); what needs none of it is in its helpers (:mod:`daq.recording.devices`,
:mod:`daq.recording.releases`, :mod:`daq.recording.raw_batches`, :mod:`daq.recording.sync_view`,
:mod:`daq.recording.trigger_anchors`).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from daq.acquisition.records import Event, StreamBlock
from daq.config import RigConfig, is_sway_laser
from daq.errors import StorageError
from daq.recording.devices import (
    ClockObserver,
    DeviceState,
    declare_device,
    new_clock_map,
    take_rows,
    view_streams,
)
from daq.recording.layout import event_row, metadata_name_part, storable_metadata
from daq.recording.raw_batches import RawBatches
from daq.recording.recorder import RunRecorder
from daq.recording.recorder_protocol import Recorder
from daq.recording.releases import ReleaseRows
from daq.recording.sync_view import physical_columns, polled_conditions, tap_columns
from daq.recording.trigger_anchors import TriggerPulses
from daq.sync.resample import Resampler, StreamSpec, SyncBlock
from daq.tubing_config import tubing_metadata

__all__ = ["DEFAULT_RHO", "DEFAULT_SYNC_RATE_HZ", "RunWriter", "default_sync_rate_hz"]

log = logging.getLogger(__name__)

#: Sync rate without a scanner, Hz (with one: the scanner's frame rate).
DEFAULT_SYNC_RATE_HZ = 500.0
#: What a CALZ made during the run keeps in its metadata entry (:meth:`RunWriter._calz_record`).
_CALZ_FIELDS = ("pause_s", "calz_s", "wind_speed_now", "frames_averaged", "offsets_before_pa")
#: Air density used before the barometer's first reading, kg/m^3 (recorded in the rho column).
DEFAULT_RHO = 1.2

#: After a device clock restart, the new epoch's samples are held back from the sync view until
#: this much device time has arrived and this much host time has passed since the first of
#: them arrived, s: the fresh clock map then rests on the least-latency block among them (12
#: blocks of 20 ms), not on the first one alone. Measured with two CPU hogs on the two cores: a
#: first block 124 ms late, the blocks after it back to ~1 ms. Host time too: a reconnect late
#: by more than this delivers the new scan's first RESTART_SETTLE_S as one backlog, every block
#: of it late (a CI run: the fresh map 78 ms late).
RESTART_SETTLE_S = 0.25

FloatArray = npt.NDArray[np.float64]

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
        Further keyword arguments of :class:`~daq.recording.recorder.RunRecorder` (``overwrite``,
        ``min_free_bytes``, ``flush_interval_s``, ...).
    clock_truth : ClockObserver, optional
        Told the host times the sync view uses for every block (e.g. to measure them against a
        simulated rig's truth).
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
                 clock_truth: ClockObserver | None = None,
                 release_hook: Callable[[str, float], None] | None = None) -> None:
        self.path = Path(path)
        self.release_hook = release_hook
        self.clock_truth = clock_truth
        self.config = config
        self.operator_notes = operator_notes
        self.use_trigger_anchors = use_trigger_anchors
        self.max_hold_s = max_hold_s
        self.write_interval_s = float(write_interval_s)
        self._raw = RawBatches()
        self._last_write = -math.inf
        self._recorder_options = dict(recorder_options or {})
        scanners = config.by_role("scanner")
        self._scanner_name = scanners[0].name if scanners else None
        self._pitot_channel = int(scanners[0].settings["pitot_channel"]) if scanners else -1
        self.sync_rate_hz = float(default_sync_rate_hz(config) if sync_rate_hz is None
                                  else sync_rate_hz)
        self._lasers = {inst.name: inst for inst in config.by_role("lasers")}
        self._sway = config.section.n_dof == 3  # 3-DOF: p and drag in the view, p0 per release
        self.recorder: Recorder | None = None
        self.error: BaseException | None = None
        self.summary: dict[str, Any] | None = None
        self._t0_ns = 0
        self._devices: dict[str, DeviceState] = {}
        self._resampler: Resampler | None = None
        self._laser_order: list[str] = []
        self._rho = DEFAULT_RHO
        self._rho_measured = False
        self._sync_rows = 0
        self._release_rows = ReleaseRows(f_max=max(config.section.fh, config.section.fa))
        self._calz_count: dict[str, int] = {}
        self._pulses = TriggerPulses()  # the PLC's trigger pulses: the clock maps' anchors
        self._view_pieces: dict[str, list[tuple[FloatArray, FloatArray]]] = {}
        self._n_taps = config.taps.n_taps
        self._tap_columns, self._fan_rpm = tap_columns(config.calibration, self._n_taps), math.nan

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

    def _time(self, host_ns: Any) -> Any:
        return (np.asarray(host_ns, dtype=np.int64) - self._t0_ns) * 1e-9

    # -- start ---------------------------------------------------------------------------------
    def _start(self, doc: Mapping[str, Any]) -> None:
        self._t0_ns = int(doc["host_time_ns"])
        rec = self.recorder or RunRecorder(self.path, config_text=self.config.text,
                                           rig_name=self.config.name, sway=self._sway,
                                           operator_notes=self.operator_notes,
                                           **self._recorder_options)
        if rec.state == "new":
            rec.open()
        self.recorder = rec
        n_taps = self.config.taps.n_taps
        if self.config.tubing:  # what an offline reader needs to undo it (the file format)
            rec.add_metadata("tubing", tubing_metadata(self.config.tubing, n_taps))
        tap_names = [f"tap{i:03d}" for i in range(n_taps)]
        streams: list[StreamSpec] = []
        for name, info in doc["devices"].items():
            kind = str(info["kind"])
            dev = declare_device(rec, self.config, name, kind, info.get("describe", {}) or {})
            # The sync view's streams: lasers (h, alpha; p), scanner (taps, Pitot), analog Pitot.
            streams += view_streams(dev, info.get("describe") or {}, self._scanner_name,
                                    n_taps, laser=name in self._lasers, taken=streams)
            if dev.view is not None and dev.view.startswith("laser."):
                self._laser_order.append(name)
            self._devices[name] = dev
        if sum(not is_sway_laser(self._lasers[n]) for n in self._laser_order) < 2:
            self._laser_order = []  # h and alpha need two lasers: no laser stream in the view
            streams = [s for s in streams if not s.name.startswith("laser.")]
            for dev in self._devices.values():
                if dev.view is not None and dev.view.startswith("laser."):
                    dev.view = None
        rec.add_sync(tap_names)
        rec.add_calibrations(self.config.calibration.records(n_taps))
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
        for gap in block.gaps:
            rec.add_gap(dev.name, gap.after_counter, gap.length if gap.length >= 1 else -1)
            dev.gaps += 1
            if gap.length < 0:
                restarts.append(gap.after_counter)
        if n == 0:
            dev.restart_pending = dev.restart_pending or bool(restarts)
            return
        values = block.values
        assert dev.raw_rows is not None
        table, extra = dev.raw_rows(values, n)
        self._raw.add(dev.name, block, table, extra)
        self._fan_rpm, rho = polled_conditions(dev.kind, values, self.config, self._fan_rpm)
        if math.isfinite(rho) and rho > 0:
            self._rho, self._rho_measured = rho, True
        if block.device_time is None or dev.clock is None:
            self._write_if_due()
            return
        if not restarts:  # the usual case: one clock epoch, the whole block
            self._map_rows(dev, block)
            self._write_if_due()
            return
        # A restart gap splits the block: the rows before it belong to the old device clock
        # (and its map), the rows after it perhaps to a restarted one (see _map_rows).
        counter = block.counter
        cuts = sorted({int(np.searchsorted(counter, after, side="right")) for after in restarts})
        bounds = [0, *(k for k in cuts if 0 < k < n), n]
        for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
            if lo in cuts:
                dev.restart_pending = True
            self._map_rows(dev, block if hi - lo == n else take_rows(block, lo, hi))
        if n in cuts:  # the restart follows this block's rows: the next block decides
            dev.restart_pending = True
        self._write_if_due()

    def _map_rows(self, dev: DeviceState, block: StreamBlock) -> None:
        """Feed one clock epoch's rows of a block to the clock map and the sync view.

        Called with a whole block, or with the rows on one side of a restart gap. After a
        restart gap (``dev.restart_pending``) the first finite device time decides whether the
        device clock restarted (see :meth:`_restart_clock`). After a restart the rows are held
        back from the sync view until ``RESTART_SETTLE_S`` of device time has arrived and as
        much host time has passed since the first of them; the clock map takes every block's
        pair at once.
        """
        assert dev.clock is not None
        t_dev = np.asarray(block.device_time, dtype=np.float64)
        mask = np.isfinite(t_dev)
        finite = None if mask.all() else mask  # None, the usual case: no mask downstream
        rows = np.arange(t_dev.shape[0]) if finite is None else np.flatnonzero(mask)
        if rows.size == 0:
            return
        first, last = int(rows[0]), int(rows[-1])
        t_host = self._time(block.host_time_ns)
        if dev.restart_pending:
            dev.restart_pending = False
            # Device time not after the last one mapped: the device clock restarted with the scan
            # (relative frame times start again at 0 without PTP, docs/reference/wire_formats.md,
            # "Pressure scanner"), and the map from the previous scan no longer applies. Absolute
            # (PTP) frame times, and relative ones the engine continued across its own pause
            # (Acquisition.calz), move forward: their map stays valid and is kept. (NaN: nothing
            # mapped yet.)
            if float(t_dev[first]) <= dev.last_device_time:
                self._restart_clock(dev, float(t_dev[first]), float(t_host[first]))
        # Each read in a block (lasers: 20 ms of reads) has its own arrival stamp: the last row
        # of every read is a tight pair for the clock map's lower envelope.
        timed = t_host if finite is None else t_host[rows]
        reads = np.flatnonzero(timed[1:] != timed[:-1])  # rows before a new arrival stamp
        if reads.size == 0:  # one read: one pair, given as floats (no arrays in the map)
            dev.clock.update(float(t_dev[last]), float(t_host[last]))
        else:
            ends = np.append(rows[reads], last)
            dev.clock.update(t_dev[ends], t_host[ends])
        if self.use_trigger_anchors:
            dev.anchor_triggers(block, t_dev, self._pulses.events)
            if dev.pending_triggers:
                # pulses seen before the clock map was ready
                dev.pair_triggers(self._pulses.events)
        dev.last_device_time = float(t_dev[last])
        if math.isnan(dev.settle_until):
            self._push(dev, block, t_dev, finite)
            return
        dev.held.append((block, t_dev, finite))
        if (dev.last_device_time >= dev.settle_until
                and float(t_host[last]) >= dev.settle_host_until):
            self._release_held(dev)

    def _release_held(self, dev: DeviceState) -> None:
        """Push the rows held since a clock restart, on the map fitted from all of them."""
        held, dev.held = dev.held, []
        dev.settle_until = dev.settle_host_until = math.nan
        for block, t_dev, finite in held:
            self._push(dev, block, t_dev, finite)

    def _restart_clock(self, dev: DeviceState, t_device: float, t_host: float) -> None:
        """Start a fresh clock map and timeline after the device clock went back to ``t_device``.

        Nothing already mapped changes: the raw rows and the sync rows written keep the old
        map's times, and the old map's samples stay in the resampler. What is discarded is what
        only the old clock could use: its fit, the timeline's continuity, the latched trigger
        time and the trigger times still waiting for their PLC event (device times on the old
        clock: paired with the new map they would be anchors of the wrong epoch).

        Parameters
        ----------
        dev : DeviceState
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
        dev.clock = new_clock_map(assumed_floor_s=floor)
        dev.timeline.restart()
        dev.last_trigger = -math.inf
        dev.pending_triggers.clear()
        dev.clock_restarts += 1
        dev.break_pending = True
        dev.settle_until = t_device + RESTART_SETTLE_S
        dev.settle_host_until = t_host + RESTART_SETTLE_S
        text = (f"{dev.name}: device clock restarted (device time {t_device:.6f} s after "
                f"{previous:.6f} s); clock map started afresh, latency floor "
                f"{floor * 1e3:.3f} ms kept")
        log.warning("%s", text)
        rec.add_event(t_host, "clock_restart", text)

    def _write_if_due(self, *, force: bool = False) -> None:
        """Append the buffered raw rows and the ready sync rows (every ``write_interval_s``)."""
        now = time.monotonic()
        if not force and now - self._last_write < self.write_interval_s:
            return
        self._last_write = now
        rec = self.recorder
        assert rec is not None
        with rec.batch():  # flushed after the sync rows, not between them and their raw rows
            self._raw.write(rec)
            if self._resampler is not None:
                self._write_sync(self._pull())

    def _push(self, dev: DeviceState, block: StreamBlock, t_dev: FloatArray,
              finite: npt.NDArray[np.bool_] | None) -> None:
        """Map a block's timed rows (``finite``; None: all, no copy) to the sync view's times."""
        r = self._resampler
        if r is None or dev.clock is None or dev.timeline is None:
            return
        t = dev.timeline.map(t_dev if finite is None else t_dev[finite], dev.clock.to_host,
                             version=dev.clock.version)
        # Only samples after every earlier one of the block: the resampler needs increasing
        # times, and a sample compared with its neighbour alone would let one that went back
        # (device time going back inside a block) through after the first.
        keep: npt.NDArray[np.bool_] | None = None
        if t.size > 1 and not (t[1:] > t[:-1]).all():
            keep = np.concatenate(([True], t[1:] > np.maximum.accumulate(t)[:-1]))
            t = t[keep]
        if dev.break_pending and t.size:
            dev.break_pending = False
            self._mark_break(dev, t[0])
        if t.size:
            dev.last_host = max(dev.last_host, float(t[-1]))
        if self.clock_truth is not None:
            t_seen = t_dev if finite is None else t_dev[finite]
            self.clock_truth.observe(dev.name, t, t_seen if keep is None else t_seen[keep],
                                     self._t0_ns * 1e-9)

        def rows(a: Any) -> FloatArray:
            out = np.asarray(a, dtype=np.float64)
            if finite is not None:
                out = out[finite]
            return out if keep is None else out[keep]

        if dev.view == "pressure":
            self._to_view("pressure", t, rows(block.values["pressure"])[:, self._tap_columns])
            self._to_view("pitot", t, rows(block.values["pitot"]))
        elif dev.view == "pitot":  # an analog Pitot transducer (NaN where its reading is invalid)
            self._to_view("pitot", t, rows(block.values["pitot"]))
        elif dev.view is not None:
            d = rows(block.values["distance"])
            if "error_code" in block.values:
                code = block.values["error_code"]
                if np.any(code):  # else every distance is valid as it stands
                    d = np.where(rows(code) != 0, np.nan, d)
            self._to_view(dev.view, t, d)

    def _to_view(self, stream: str, t: FloatArray, values: FloatArray) -> None:
        """Queue samples of a sync-view stream for the next pull (:meth:`_pull`)."""
        self._view_pieces.setdefault(stream, []).append((t, values))

    def _pull(self) -> SyncBlock:
        """Push the samples queued since the last pull, once per stream (as per block); pull."""
        r = self._resampler
        assert r is not None
        for stream, pieces in self._view_pieces.items():
            if pieces:
                r.push_many(stream, pieces)
                pieces.clear()
        return r.pull()

    def _mark_break(self, dev: DeviceState, t_next: float) -> None:
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
        if dev.view == "pressure":
            self._to_view("pressure", at, np.full((1, self._n_taps), np.nan))
            self._to_view("pitot", at, np.full(1, np.nan))
        elif dev.view is not None:  # a laser's stream, or an analog Pitot's
            self._to_view(dev.view, at, np.full(1, np.nan))

    # -- sync view -----------------------------------------------------------------------------
    def _write_sync(self, sb: SyncBlock) -> None:
        n = len(sb)
        if n == 0:
            return
        rec = self.recorder
        assert rec is not None
        cols = physical_columns(sb, [self._lasers[name] for name in self._laser_order],
                                self.config, self._rho, self._fan_rpm)
        rec.append_sync(sb.time, h=cols.h, alpha=cols.alpha, lift=cols.lift, moment=cols.moment,
                        pressure=cols.pressure, U=cols.U, rho=cols.rho, **cols.sway())
        base = self._sync_rows
        self._sync_rows += n
        self._release_rows.track(rec, base, sb.time, cols.h, cols.alpha, cols.U, p=cols.p)

    # -- events --------------------------------------------------------------------------------
    def _calz_record(self, event: Event, t: float) -> None:
        """Keep a CALZ made during the run: ``/entry/metadata/calz_<device>_<n>``.

        Its run time (s), pause, duration, the wind speed vouched for and the zero removed per
        scanner channel (``offsets_before_pa``: the mean over the last frames before the
        scan stopped, Pa; what the scanner's pressures shifted by at the CALZ).
        """
        rec = self.recorder
        assert rec is not None
        device = metadata_name_part(event.device or "scanner")
        self._calz_count[device] = n = self._calz_count.get(device, 0) + 1
        record = {"time_s": t, **{k: v for k, v in event.data.items()
                                  if k in _CALZ_FIELDS and v is not None}}
        rec.add_metadata(f"calz_{device}_{n}", record)

    def _event(self, event: Event) -> None:
        rec = self.recorder
        assert rec is not None
        t = float(self._time(event.host_time_ns))
        # The event's numbers go into its text; arrays (a CALZ's offsets) go to /entry/metadata.
        rec.add_event(t, *event_row(event.kind, event.text, event.device, event.data))
        if event.kind == "calz":
            self._calz_record(event, t)
        if event.kind == "release":
            command = int(event.data.get("command_ns", event.host_time_ns))
            t_release = self._release_rows.released(float(self._time(command)))
            if self.release_hook is not None:
                self.release_hook("release", t_release)
        elif event.kind == "arm":
            # Arming catches the model: the decay ends a sync period before the arm (a sync
            # row averages the lasers over +- half a period: not into the caught model).
            t_end = self._release_rows.caught(t - 1.0 / self.sync_rate_hz)
            if t_end is not None and self.release_hook is not None:
                self.release_hook("caught", t_end)
        elif event.kind in ("manual_release", "manual_hold"):  # found in the lasers' rows
            self._release_rows.operator(event.kind, t, self.release_hook)
        elif event.kind == "trigger":
            # Its host time is known to half the command's round trip: an anchor if that is short.
            if not self._pulses.take(t, float(event.data.get("round_trip_s", 0.0))):
                return
            for dev in self._devices.values():
                if dev.pending_triggers:
                    dev.pair_triggers(self._pulses.events)

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
            self._write_sync(self._pull())
        self._release_rows.finish(rec, self._sync_rows)
        fits = self.clock_fits()
        offsets = {n: f["offset_s"] for n, f in fits.items() if math.isfinite(f["offset_s"])}
        drifts = {n: f["drift_ppm"] for n, f in fits.items() if math.isfinite(f["drift_ppm"])}
        residuals = [f["residual_s"] for f in fits.values() if math.isfinite(f["residual_s"])]
        rec.set_sync_attrs(clock_offset_s=offsets, clock_drift_ppm=drifts,
                           residual_misalignment_s=max(residuals) if residuals else None)
        summary = self._summary(doc)
        # A clock map without an anchor is late by its device's transport latency: say so in
        # the file's events, the summary and the log (the file is still written).
        t_stop = (float(self._time(doc["host_time_ns"])) if "host_time_ns" in doc
                  else float(doc.get("duration_s", 0.0)))
        for text in summary["warnings"]:
            log.warning("%s", text)
            rec.add_event(t_stop, "warning", text)
        rec.add_metadata("acquisition_summary", storable_metadata(summary))
        rec.close()
        self.summary = summary

    @property
    def t0_ns(self) -> int:
        """Host time of the run's time 0 (``time.monotonic_ns`` clock), ns."""
        return self._t0_ns

    def clock_fits(self) -> dict[str, dict[str, float]]:
        """Per clocked device: offset (s), drift (ppm), residual (s), anchors, pairs."""
        fits = {name: dev.clock_fit() for name, dev in self._devices.items()}
        return {name: fit for name, fit in fits.items() if fit is not None}

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
            "releases": self._release_rows.written,
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
            "warnings": self._pulses.anchor_warnings(self._devices,
                                                     anchors_used=self.use_trigger_anchors),
        }


def default_sync_rate_hz(config: RigConfig) -> float:
    """Return a rig's synchronised row rate, Hz: its scanner's frame rate, else the default."""
    scanners = config.by_role("scanner")
    return float(scanners[0].settings["rate_hz"]) if scanners else DEFAULT_SYNC_RATE_HZ
