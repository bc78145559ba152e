"""The live console's data source: a rig acquired now, synchronised into a ring buffer.

Responsibility: :class:`LiveSource` (a :class:`~daq.console.source.DataSource`) starts a rig (the
simulated one in a child process, :func:`daq.sim.rig_process.start_rig_process`, or the real
instruments of a config), runs the acquisition engine over its drivers and feeds the console's
:class:`~daq.console.ring_buffer.RingBuffer` with the rows of the synchronised view. The sync view
is the recording's own: a :class:`~daq.recording.writer.RunWriter` runs as the engine's
subscriber, writing into a :class:`~daq.console.ring_recorder.RingRecorder` instead of an HDF5
file (both are a :class:`~daq.recording.recorder_protocol.Recorder`), so the live view and a
recorded file hold the same rows by construction. The GUI thread polls
:meth:`LiveSource.snapshot` (the ring's copy) and
:meth:`LiveSource.health` (built from :meth:`Acquisition.stats` and what the subscriber kept under a
lock); nothing is pushed to the GUI from the acquisition threads (docs/reference/architecture.md,
"Design rules").

Recording (:meth:`LiveSource.start_recording`, :meth:`LiveSource.stop_recording`): while the
operator records, the same subscriber also feeds a second, ordinary
:class:`~daq.recording.writer.RunWriter` with its :class:`~daq.recording.recorder.RunRecorder`, the
pair ``windrig acquire`` uses, so the file has the docs/reference/file_format.md layout by
construction. That writer lives on the engine's dispatcher thread (the one thread that touches its
h5py file): the GUI thread creates the file (every check of :meth:`RunRecorder.open
<daq.recording.recorder.RunRecorder.open>` runs before anything starts), then posts a request and
waits, with a timeout, for the dispatcher to start or finish the recording at its next doc
(:class:`~daq.recording.file_switch.FileRecording`).

Not responsible for: drawing (:mod:`daq.console.window`), the sync numerics (:mod:`daq.sync` through
:class:`~daq.recording.writer.RunWriter`), the file layout (:mod:`daq.recording.layout`), the
recordings' hand-over (:mod:`daq.recording.file_switch`), or the operator controls
(:mod:`daq.console.controls`, which use :attr:`LiveSource.acq` and the recording methods).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from daq.acquisition.device_check import require_devices_ok
from daq.acquisition.drivers import drivers_from_config
from daq.acquisition.engine import Acquisition
from daq.acquisition.sync_pulses import start_sync_pulses
from daq.config import RigConfig
from daq.console.ring_buffer import RingBuffer
from daq.console.ring_recorder import RingRecorder
from daq.console.source import DeviceHealth, RingSource, SourceInfo, sync_columns
from daq.errors import RecordingError
from daq.recording.experiment_log import ExperimentLog, experiment_log_path
from daq.recording.file_switch import RECORDING_TIMEOUT_S, FileRecording, Recording
from daq.recording.recorder import RunRecorder
from daq.recording.writer import RunWriter, default_sync_rate_hz
from daq.sim.rig_process import start_rig_process

__all__ = ["STALL_S", "LiveSource",
           "check_live_options", "ring_rows"]

log = logging.getLogger(__name__)

#: A device whose last block is older than this is stalled, s (the barometer polls at 1 Hz).
STALL_S = 3.0
#: A device fault keeps the alarm raised this long, s (the last fault stays in the table).
FAULT_ALARM_S = 10.0
#: Sample rates in the health panel are averaged over this long, s.
RATE_WINDOW_S = 2.0
#: How often the subscriber copies the writer's clock fits for the GUI, s.
CLOCK_FIT_INTERVAL_S = 0.5
#: The live source keeps this many of the engine's latest events (:meth:`LiveSource.events`).
EVENTS_KEPT = 1000
#: Sync rows are handed to the ring this often, s (the writer's batching interval): an append to
#: the ring is cheap, and the window redraws only when rows are new (20 frames/s need 20 appends/s).
WRITE_INTERVAL_S = 0.02
#: The ring holds at least this much history, s: a whole free decay must still be there when
#: the releases table cuts it (:mod:`daq.console.live_ident`).
MIN_HISTORY_S = 30.0


def check_live_options(window_s: float, fan_rpm: float | None) -> None:
    """Refuse a history length or a starting fan speed a live source cannot take.

    Raises
    ------
    ValueError
        ``window_s`` is not a number of seconds > 0, or ``fan_rpm`` not None or >= 0.
    """
    if not (isinstance(window_s, (int, float)) and 0 < window_s < math.inf):
        raise ValueError(f"window_s = {window_s!r} must be a number of seconds > 0")
    if fan_rpm is not None and not (math.isfinite(fan_rpm) and fan_rpm >= 0):
        raise ValueError(f"fan_rpm = {fan_rpm!r} must be a number of rpm >= 0")


def ring_rows(config: RigConfig, window_s: float) -> int:
    """Return the rows a live ring keeps: ``window_s`` or :data:`MIN_HISTORY_S`, the longer.

    Parameters
    ----------
    config : RigConfig
        The rig (its sync rate).
    window_s : float
        The console's time window, s.
    """
    history_s = max(float(window_s), MIN_HISTORY_S)
    return int(math.ceil(history_s * default_sync_rate_hz(config))) + 2


class _HealthTap:
    """The engine subscriber: the run writer, the faults and clock fits for the GUI, the file.

    Parameters
    ----------
    writer : RunWriter
        The live view's writer (into a :class:`RingRecorder`).
    files : FileRecording
        Fed every doc after the live writer: the operator's recordings.
    """

    def __init__(self, writer: Any, files: FileRecording) -> None:
        self.writer = writer
        self.files = files
        self._lock = threading.Lock()
        self._last_fault: dict[str, tuple[float, str]] = {}
        self._fits: dict[str, dict[str, float]] = {}
        self._next_fit = 0.0
        self._events: deque[Any] = deque(maxlen=EVENTS_KEPT)

    def __call__(self, name: str, doc: Any) -> None:
        try:
            self._live(name, doc)
        finally:  # the recording goes on whatever happened to the live view (raised on)
            self.files.feed(name, doc)

    def _live(self, name: str, doc: Any) -> None:
        if name == "event":
            with self._lock:
                self._events.append(doc)
        if name == "event" and getattr(doc, "kind", "") == "fault":
            device = str(getattr(doc, "device", None) or "?")
            text = f"{getattr(doc, 'error', 'fault')}: {getattr(doc, 'text', '')}"
            with self._lock:
                self._last_fault[device] = (time.monotonic(), text[:200])
        self.writer(name, doc)
        now = time.monotonic()
        if now >= self._next_fit:
            self._next_fit = now + CLOCK_FIT_INTERVAL_S
            fits = self.writer.clock_fits()
            with self._lock:
                self._fits = fits

    def events(self) -> list[Any]:
        with self._lock:
            return list(self._events)

    def read(self) -> tuple[dict[str, tuple[float, str]], dict[str, dict[str, float]]]:
        with self._lock:
            return dict(self._last_fault), dict(self._fits)


class LiveSource(RingSource):
    """A rig acquired live, as a console data source (see the module docstring).

    Parameters
    ----------
    config : RigConfig
        The rig. With ``simulate`` its simulated instruments are started in a child process;
        without, its URLs must be real.
    simulate : bool
        Start the simulated rig of the config.
    window_s : float
        Length of the history kept for the views, s, > 0.
    fan_rpm : float, optional
        Start the fan at this speed once the engine runs (within the config's limits; the
        driver refuses more); it is stopped again on :meth:`close`. None: leave the fan alone.
    sync_pulse_interval_s : float or None
        Pulse the PLC's trigger line this often, s (clock anchors, as ``record_run``).
    record_dir : str or Path, optional
        Where the console suggests run files (:mod:`daq.console.controls`); default: the current
        directory. Only stored: :meth:`start_recording` takes any path.
    check : bool
        Check every device before the engine starts, as ``windrig check``
        (:func:`~daq.acquisition.device_check.require_devices_ok`): a failing device stops
        :meth:`open` with a :class:`~daq.errors.DeviceCheckError` naming every failing one; the
        check's notes become ``"warning"`` events.
    ring : RingBuffer, optional
        The buffer the synchronised rows go to, with the columns of :func:`sync_columns` and
        at least :func:`ring_rows` rows (a :class:`~daq.console.shared_ring.SharedRingBuffer` when
        another process draws them: :mod:`daq.console.process_source`); default: one made by
        :meth:`open`.

    Notes
    -----
    The constructor does no I/O; :meth:`open` starts everything, :meth:`close` stops the
    engine, then the rig (idempotent). With ``simulate`` the scanner is zeroed (CALZ) before
    the engine starts: the simulated tunnel starts wind-off.
    """

    def __init__(self, config: RigConfig, *, simulate: bool = True, window_s: float = 20.0,
                 fan_rpm: float | None = None,
                 sync_pulse_interval_s: float | None = 0.5,
                 record_dir: str | Path | None = None, ring: RingBuffer | None = None,
                 check: bool = False) -> None:
        check_live_options(window_s, fan_rpm)
        self.config = config
        self.check = bool(check)
        self.simulate = bool(simulate)
        self.window_s = float(window_s)
        self.fan_rpm = fan_rpm
        self._pulse_s = sync_pulse_interval_s
        #: The directory the console suggests run files in.
        self.record_dir = Path.cwd() if record_dir is None else Path(record_dir)
        self._files = FileRecording()
        self._rig: Any = None
        self._acq: Any = None
        self._pulser: Any = None
        self._tap: _HealthTap | None = None
        self._writer: Any = None
        self._recorder: RingRecorder | None = None
        self._given_ring = ring
        self._ring: RingBuffer | None = None
        self._info: SourceInfo | None = None
        self._fan_started = False
        self._started_ns = 0
        self._closed = False
        self._error: str | None = None
        self._seen_rows = 0
        self._counts: deque[tuple[float, dict[str, int]]] = deque()  # (host s, samples)
        self._decay_lock = threading.Lock()
        self._decays: list[tuple[float, float | None]] = []  # (release s, caught s or None)

    # -- life cycle ------------------------------------------------------------------------------
    def open(self) -> None:
        """Start the rig (simulated: in its own process), the drivers and the engine.

        Raises
        ------
        DaqError, RuntimeError, TimeoutError
            A device did not open, or the simulated rig did not start; everything already
            started is stopped again.
        """
        if self._acq is not None or self._closed:
            return
        try:
            live = self.config
            if self.simulate:
                self._rig = start_rig_process(self.config)
                live = self._rig.config
            rate = default_sync_rate_hz(live)
            self._ring = self._make_ring(live)
            self._recorder = RingRecorder(self._ring, [i.name for i in live.by_role("fan")],
                                          [i.name for i in live.by_role("plc")])
            writer = RunWriter(Path("live"), live, write_interval_s=WRITE_INTERVAL_S,
                               release_hook=self._on_decay)
            writer.recorder = self._recorder  # a Recorder into the ring: no file
            self._writer = writer
            self._tap = _HealthTap(writer, self._files)
            checked = require_devices_ok(live) if self.check else []
            drivers = drivers_from_config(live)
            if self.simulate:
                for kind, driver in drivers.values():
                    if kind == "scanner":
                        driver.open()  # idempotent: the engine's open() keeps this connection
                        driver.calz(wind_speed_now=0.0)
            self._acq = Acquisition(drivers, subscribers=[self._tap],
                                    metadata={"rig": live.name, "mode": "live console"})
            self._acq.start()
            self._started_ns = time.monotonic_ns()
            self._pulser = start_sync_pulses(self._acq, drivers, self._pulse_s)
            for result in checked:  # what the check noted, in the run's record
                for note in result.notes:
                    self._acq.mark("warning", f"check: {note}", result.device)
            if self.fan_rpm is not None and "fan" in self._acq.drivers:
                # Through the engine, as an operator's commands: each is an event.
                self._acq.set_fan_speed(self.fan_rpm, "fan")
                self._acq.start_fan("fan")
                self._fan_started = True
            self._info = SourceInfo(label="live", config=live, rate_hz=rate, duration_s=None)
        except BaseException:
            self.close()
            raise

    def _make_ring(self, config: RigConfig) -> RingBuffer:
        """Return the given ring (checked against the config) or a new one."""
        columns = sync_columns(config.taps.n_taps, sway=config.section.n_dof == 3)
        rows = ring_rows(config, self.window_s)
        ring = self._given_ring
        if ring is None:
            return RingBuffer(rows, *columns)
        if ring.columns != columns or ring.capacity_rows < rows:
            raise ValueError(f"the ring given to LiveSource has columns {ring.columns} and "
                             f"{ring.capacity_rows} rows; this rig needs {columns} and at "
                             f"least {rows} rows")
        return ring

    def close(self) -> None:
        """Finish a recording, stop the fan (if this source started it), the engine, the rig.

        Idempotent. A recording is finished first, so that its file is complete; should that
        fail, the engine's own stop finishes it (its error is logged either way).
        """
        self._closed = True
        rec = self._files.recording
        if rec is not None and rec.error is None:
            try:
                self.stop_recording(reason="console closed")
            except (RecordingError, OSError) as exc:  # the engine's stop doc finishes it
                log.error("finishing the recording to %s on close failed: %s", rec.path, exc)
        pulser, self._pulser = self._pulser, None
        if pulser is not None:
            pulser.stop()
        acq, self._acq = self._acq, None
        if acq is not None:
            if self._fan_started:
                try:
                    acq.stop_fan("fan")
                except Exception:  # stopping anyway: the engine and rig close below
                    log.exception("stopping the fan failed")
            try:
                summary = acq.stop("console closed")
                if summary.get("threads_alive"):
                    log.error("threads still alive after stop: %s", summary["threads_alive"])
            except Exception:
                log.exception("stopping the acquisition failed")
        rig, self._rig = self._rig, None
        if rig is not None:
            rig.close()

    # -- the DataSource protocol -----------------------------------------------------------------
    @property
    def error(self) -> str | None:
        """Describe the failure that stopped the sync view, if any."""
        if self._error is None and self._writer is not None and self._writer.error is not None:
            self._error = f"sync view failed: {self._writer.error}"
        return self._error

    @property
    def running(self) -> bool:
        """Tell whether the engine runs."""
        return self._acq is not None and bool(self._acq.running)

    @property
    def acq(self) -> Any:
        """The acquisition engine (:class:`~daq.acquisition.engine.Acquisition`); None when stopped.

        For operator commands (:mod:`daq.console.controls`): its ``drivers``, ``arm``, ``release``,
        ``mark``.
        """
        return self._acq

    # -- recording -------------------------------------------------------------------------------
    @property
    def recording(self) -> Recording | None:
        """The recording in progress, the last one if it failed (``error`` set), or None."""
        return self._files.recording

    def start_recording(self, path: str | Path, notes: str = "", *,
                        recorder_options: Mapping[str, Any] | None = None,
                        timeout_s: float = RECORDING_TIMEOUT_S) -> Path:
        """Start recording the live rig to a new run file; return its path.

        The file's time 0 is the moment the engine's dispatcher starts the recording; the
        file's writer is first given the last :data:`PREROLL_S` of blocks (their raw samples
        precede time 0), so that its clock maps start warm. Releases, arms and markers made
        while recording are in its ``/entry/releases`` and ``/entry/events``.

        Parameters
        ----------
        path : str or Path
            The run file to create; its directory must exist and be writable.
        notes : str
            Operator notes, stored as ``/entry`` attribute ``operator_notes``.
        recorder_options : mapping, optional
            Further keyword arguments of :class:`~daq.recording.recorder.RunRecorder`
            (``min_free_bytes``, ``reserve_bytes``, ``flush_interval_s``, ``disk_free``, ...).
        timeout_s : float
            Longest wait for the dispatcher to start the recording, s.

        Returns
        -------
        Path
            The file being recorded.

        Raises
        ------
        RecordingError
            The acquisition is not running, a recording is already in progress, or the
            dispatcher did not answer within ``timeout_s`` (nothing is recorded, no file left).
        StorageError
            The directory is missing or not writable, the file exists, or the disk has too
            little free space: checked before anything starts (no file is left behind).
        """
        if not self.running or self._info is None:
            raise RecordingError("record: acquisition not running")
        self._files.check_idle()
        path = Path(path)
        recorder = RunRecorder(path, config_text=self.config.text, rig_name=self.config.name,
                               operator_notes=notes, sway=self.config.section.n_dof == 3,
                               **dict(recorder_options or {}))
        # The checks record_run relies on (a missing or read-only directory, an existing file,
        # too little free space), before anything starts: open() creates the file or raises.
        recorder.open()
        try:
            writer = RunWriter(path, self._info.config, operator_notes=notes)
            writer.recorder = recorder  # opened above; declared and started by the dispatcher
            recorder.event_sink = ExperimentLog(
                experiment_log_path(path), [i.name for i in self.config.instruments],
                lambda: writer.t0_ns, run_file=path.name)
            self._files.start(writer, notes, timeout_s)
            self._acq.mark("recording_started", f"recording {path.name}")
        except Exception:
            # Not started (refused, withdrawn after the timeout, or failed on its first rows):
            # the dispatcher holds no reference to the file, nothing is recorded in it.
            recorder.close()
            path.unlink(missing_ok=True)
            raise
        return path

    def stop_recording(self, *, reason: str = "stopped by the operator",
                       timeout_s: float = RECORDING_TIMEOUT_S) -> dict[str, Any]:
        """Finish the recording: its last rows, the clock fits and the summary; close the file.

        Parameters
        ----------
        reason : str
            Stored in the file's summary (``/entry/metadata/acquisition_summary/reason``).
        timeout_s : float
            Longest wait for the dispatcher to finish the file, s.

        Returns
        -------
        dict
            The file writer's summary (``file``, ``duration_s``, ``sync_rows``, ``releases``,
            ``samples``, ``gaps``, ``clock_fits``, ...), as :func:`~daq.recording.run.record_run`.

        Raises
        ------
        RecordingError
            Not recording (also when the last recording failed: see :attr:`recording`), or the
            file not finished within ``timeout_s`` (the dispatcher still finishes it).
        StorageError
            Writing the last rows failed; :attr:`recording` keeps the error.
        """
        rec = self._files.recording
        if rec is not None and rec.error is None and self.running:  # its last event
            self._acq.mark("recording_stopped", f"recording {rec.path.name} stopped ({reason})")
        return self._files.stop(reason, timeout_s)

    def events(self, kind: str | None = None) -> list[Any]:
        """Return the engine's latest events, oldest first.

        Parameters
        ----------
        kind : str, optional
            Only those of this kind (``"release"``, ``"arm"``, ``"note"``, ...).

        Returns
        -------
        list of Event
            At most :data:`EVENTS_KEPT`; empty before :meth:`open`.
        """
        events = [] if self._tap is None else self._tap.events()
        return [e for e in events if kind is None or getattr(e, "kind", None) == kind]

    def decays(self) -> list[tuple[float, float | None]]:
        """Return the free decays seen so far, oldest first.

        Returns
        -------
        list of (float, float or None)
            ``(release, caught)``: the release instant and, once the model was armed again, the
            time of the decay's last row, s from the run start (the sync view's ``time``);
            ``caught`` is None while the decay goes on. The same instants as the releases
            table of a recorded run (:class:`~daq.recording.writer.RunWriter`).
        """
        with self._decay_lock:
            return list(self._decays)

    def _on_decay(self, what: str, t: float) -> None:
        """Note a decay's start or end (the run writer's release hook, dispatcher thread)."""
        with self._decay_lock:
            if what == "release":
                self._decays.append((t, None))
            elif what == "caught" and self._decays and self._decays[-1][1] is None:
                self._decays[-1] = (self._decays[-1][0], t)

    @property
    def simulated_rig(self) -> Any:
        """The simulated rig's process (:class:`~daq.sim.rig_process.RigProcess`), or None.

        Its truth and, on a rig without a PLC, the hand that lets the model go
        (``hand_release``): what a test or a scripted operator needs of the simulation.
        """
        return self._rig

    def simulated_hand(self, what: str) -> None:
        """On a simulated rig, let the model go (``"release"``) or hold it (``"hold"``) by hand.

        What the console's "released" and "held" buttons do first on a simulated rig, where no
        person's hand reaches the virtual tunnel; nothing on a real rig.
        """
        if what not in ("release", "hold"):
            raise ValueError(f"simulated_hand({what!r}): release or hold")
        if self.simulate and self._rig is not None:
            if what == "release":
                self._rig.hand_release()
            else:
                self._rig.hand_hold()

    @property
    def plc_armed(self) -> tuple[int, bool] | None:
        """The PLC's ARM coil as last read: (host ``monotonic_ns``, armed); None before."""
        return None if self._recorder is None else self._recorder.plc_armed

    @property
    def fan_speed_rpm(self) -> float:
        """Measure the fan speed last read, rpm (NaN without a fan or before a reading)."""
        return math.nan if self._recorder is None else self._recorder.fan_rpm

    def poll(self) -> int:
        """Return the rows synchronised since the last poll (the engine runs by itself)."""
        total = self.total_rows
        new, self._seen_rows = total - self._seen_rows, total
        return new

    def status(self) -> str:
        """Return the status line: rig, rows, seconds shown, fan speed, errors."""
        if self.error is not None:
            return f"error: {self.error}"
        if self._info is None:
            return "live: not started"
        state = "running" if self.running else "stopped"
        fan = self.fan_speed_rpm
        fan_text = "" if math.isnan(fan) else f", fan {fan:.0f} rpm"
        rec, rec_text = self.recording, ""
        if rec is not None:
            rec_text = (f", recording {rec.path.name} ({rec.elapsed_s():.0f} s)"
                        if rec.error is None else f", recording {rec.path.name} failed")
        return (f"live {self._info.config.name}: {state}, {self.total_rows} sync rows at "
                f"{self._info.rate_hz:g} Hz{fan_text}{rec_text}")

    # -- health ----------------------------------------------------------------------------------
    def health(self, now_ns: int | None = None) -> list[DeviceHealth]:
        """Return every device's health: rate, gaps, overflows, faults, clock fit, alarm.

        Parameters
        ----------
        now_ns : int, optional
            Host ``time.monotonic_ns()`` now (a seam for tests).

        Returns
        -------
        list of DeviceHealth
            One per device, in the engine's order; empty before :meth:`open`. The rate is the
            samples read per second over the last :data:`RATE_WINDOW_S` of calls (since the
            start at first).
        """
        if self._acq is None or self._tap is None:
            return []
        now_ns = time.monotonic_ns() if now_ns is None else now_ns
        stats = self._acq.stats()
        faults, fits = self._tap.read()
        counts = {name: s.samples for name, s in stats.items()}
        # The rate over the last RATE_WINDOW_S (the 1 Hz barometer is lumpy over less).
        now_s = now_ns * 1e-9
        history = self._counts
        if not history:
            history.append((self._started_ns * 1e-9, dict.fromkeys(counts, 0)))
        while len(history) > 1 and history[1][0] <= now_s - RATE_WINDOW_S:
            history.popleft()
        t_old, old = history[0]
        dt = now_s - t_old
        rates = {n: (c - old.get(n, 0)) / dt if dt > 0 else 0.0 for n, c in counts.items()}
        if now_s > history[-1][0]:
            history.append((now_s, counts))
        out = []
        for name, s in stats.items():
            last_ns = self._started_ns if s.last_arrival_ns is None else s.last_arrival_ns
            age = (now_ns - last_ns) * 1e-9
            fault = faults.get(name)
            alarm = None
            if s.failed is not None or not s.running:
                alarm = f"reader stopped: {s.failed or 'not running'}"
            elif age > STALL_S:
                alarm = ("no data yet" if s.last_arrival_ns is None
                         else f"stalled: no data for {age:.1f} s")
            elif fault is not None and now_ns * 1e-9 - fault[0] < FAULT_ALARM_S:
                alarm = f"fault: {fault[1]}"
            out.append(DeviceHealth(
                device=name, kind=s.kind, rate_hz=rates[name], gaps=s.gaps,
                overflow_samples=s.overflow_samples, faults=s.faults,
                last_fault=None if fault is None else fault[1], clock_fit=fits.get(name),
                alarm=alarm))
        return out
