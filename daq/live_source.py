"""The live console's data source: a rig acquired now, synchronised into a ring buffer.

Responsibility: :class:`LiveSource` (a :class:`~daq.source.DataSource`) starts a rig (the
simulated one in a child process, :func:`daq.rig_process.start_rig_process`, or the real
instruments of a config), runs the acquisition engine over its drivers and feeds the console's
:class:`~daq.ring_buffer.RingBuffer` with the rows of the synchronised view. The sync view is the
recording pipeline's own: a :class:`~daq.pipeline.RunWriter` runs as the engine's subscriber,
writing into a :class:`RingRecorder` instead of an HDF5 file (both are a
:class:`~daq.recorder.Recorder`), so the live view and a recorded file hold the same rows by
construction.
The GUI thread polls :meth:`LiveSource.snapshot` (the ring's copy) and :meth:`LiveSource.health`
(built from :meth:`Acquisition.stats` and what the subscriber kept under a lock); nothing is
pushed to the GUI from the acquisition threads (STYLE.md, "Threads and GUI").

Recording (:meth:`LiveSource.start_recording`, :meth:`LiveSource.stop_recording`): while the
operator records, the same subscriber also feeds a second, ordinary :class:`~daq.pipeline.RunWriter`
with its :class:`~daq.recorder.RunRecorder`, the pair ``windrig acquire`` uses, so the file has the
DESIGN.md layout by construction. That writer lives on the engine's dispatcher thread (the one
thread that touches its h5py file): the GUI thread creates the file (every check of
:meth:`RunRecorder.open <daq.recorder.RunRecorder.open>` runs before anything starts), then posts a
request and waits, with a timeout, for the dispatcher to start or finish the recording at its next
doc (:class:`_FileRecording`).

Not responsible for: drawing (:mod:`daq.live`), the sync numerics (:mod:`daq.sync` through
:class:`~daq.pipeline.RunWriter`), the file layout (:mod:`daq.recorder`), or the operator controls
(:mod:`daq.controls`, which use :attr:`LiveSource.acq` and the recording methods).
"""

from __future__ import annotations

import dataclasses
import datetime
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

from daq.config import RigConfig
from daq.errors import DaqError
from daq.pipeline import default_sync_rate_hz
from daq.recorder import RunRecorder
from daq.ring_buffer import RingBuffer
from daq.source import DeviceHealth, RingSource, SourceInfo, sync_columns

__all__ = ["STALL_S", "LiveSource", "Recording", "RecordingError", "RingRecorder",
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
#: the releases table cuts it (:mod:`daq.live_ident`).
MIN_HISTORY_S = 30.0
#: A recording's file writer is first fed this much of the blocks already delivered, s: every
#: stream then covers time 0 (no NaN rows at the start of the file's sync view) and the clock
#: maps have closed their first two 0.5 s windows (a fitted slope, not a cold start; see
#: :meth:`daq.pipeline.RunWriter._clock_map`). Those raw samples precede time 0 in the file.
#: Cost: ~0.4 s of the dispatcher's time at the start (the maps refit at every block until
#: then); the engine's queues hold several seconds.
PREROLL_S = 1.0
#: How long the GUI thread waits for the dispatcher to start or finish a recording, s. The
#: dispatcher takes a request at its next doc (laser blocks come 50 times a second); finishing
#: writes the last rows and reopens the file for the clock fits (well under a second).
RECORDING_TIMEOUT_S = 10.0
#: A stop waits for the dispatcher to deliver the blocks that arrived before it was asked (it
#: lags by a few ms, by a few tenths of a second after a pre-roll or on a loaded host), at most
#: this long, s (a stalled device is not waited for longer).
STOP_CATCH_UP_S = 3.0
#: Devices whose blocks come further apart than this (polled ones: the 1 Hz barometer) are not
#: waited for by a stop, s.
SLOW_BLOCKS_S = 0.25


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


class RingRecorder:
    """What :class:`~daq.pipeline.RunWriter` writes into, for a live view: no file.

    A :class:`~daq.recorder.Recorder`, as :class:`~daq.recorder.RunRecorder` is. The sync rows go
    to ``ring`` (columns of :func:`daq.source.sync_columns`); of the raw streams only the last
    fan speed is kept (``fan_rpm``); everything else is dropped. Called on the engine's
    dispatcher thread; the ring is thread-safe, and ``fan_rpm`` is one float (atomic).

    Parameters
    ----------
    ring : RingBuffer
        The console's buffer.
    fan_devices : sequence of str
        Names of the fan drives whose ``speed`` channel is the fan state.
    plc_devices : sequence of str
        Names of the PLCs whose ``armed`` channel is the release state.
    """

    def __init__(self, ring: RingBuffer, fan_devices: Sequence[str] = (),
                 plc_devices: Sequence[str] = ()) -> None:
        self.ring = ring
        self._fans = set(fan_devices)
        self._plcs = set(plc_devices)
        self._channels: dict[str, list[str]] = {}
        self._state = "new"
        #: Last fan speed read, rpm (NaN before the first reading).
        self.fan_rpm = math.nan
        #: Last PLC ARM coil read: (host ``monotonic_ns`` of the reading, armed); None before.
        self.plc_armed: tuple[int, bool] | None = None

    @property
    def state(self) -> str:
        """Measure the phase, as ``RunRecorder.state``."""
        return self._state

    def open(self) -> None:
        """Start declaring streams (nothing to create)."""
        self._state = "declaring"

    def start(self, t0_host_ns: int | None = None) -> None:
        """Start taking rows."""
        self._state = "recording"

    def close(self) -> None:
        """Stop (the ring keeps its rows)."""
        self._state = "closed"

    def add_stream(self, device: str, channels: Sequence[str], units: Any, rate_hz: float,
                   value_dtype: Any = "float32", *,
                   extra: Mapping[str, Any] | None = None) -> None:
        """Remember a stream's channel names."""
        self._channels[device] = list(channels)

    def add_sync(self, tap_names: Sequence[str]) -> None:
        """Declare the sync view (the ring already has its columns)."""

    def append_raw(self, device: str, host_time_ns: Any, device_time: Any, counter: Any,
                   values: Any, *, extra: Mapping[str, Any] | None = None) -> None:
        """Keep the last fan speed and PLC ARM state; drop the other raw samples."""
        channels = self._channels.get(device, ())
        if device in self._fans and "speed" in channels:
            table = np.asarray(values, dtype=np.float64)
            if table.ndim == 2 and table.shape[0]:
                self.fan_rpm = float(table[-1, channels.index("speed")])
        elif device in self._plcs and "armed" in channels:
            table = np.asarray(values, dtype=np.float64)
            hosts = np.asarray(host_time_ns, dtype=np.int64)
            if table.ndim == 2 and table.shape[0] and hosts.size:
                # one tuple, swapped whole (atomic for the GUI thread that reads it)
                self.plc_armed = (int(hosts[-1]), bool(table[-1, channels.index("armed")]))

    def append_sync(self, time: Any, *, h: Any, alpha: Any, lift: Any, moment: Any,
                    pressure: Any, U: Any, rho: Any) -> None:
        """Append sync rows to the ring."""
        self.ring.append({"time": time, "h": h, "alpha": alpha, "lift": lift, "moment": moment,
                          "U": U, "rho": rho, "pressure": pressure})

    def add_gap(self, device: str, after_counter: int, length: int) -> None:
        """Ignore (gaps are counted by the engine's stats)."""

    def add_event(self, time: float, kind: str, text: str = "") -> None:
        """Ignore (faults reach the health panel through :class:`_HealthTap`)."""

    def add_release(self, *, release_time: float, start_index: int, stop_index: int, U: float,
                    h0: float, alpha0: float) -> None:
        """Ignore (the live releases come from the writer's ``release_hook``)."""

    def set_sync_attrs(self, *, clock_offset_s: Mapping[str, float] | None = None,
                       clock_drift_ppm: Mapping[str, float] | None = None,
                       residual_misalignment_s: float | None = None) -> None:
        """Ignore."""

    def add_metadata(self, name: str, value: Any) -> None:
        """Ignore."""


class RecordingError(DaqError, RuntimeError):
    """A recording request that cannot be carried out now.

    Already recording, not recording, the acquisition not running, or the dispatcher not
    answering in time. File problems (an existing file, a missing or read-only directory, a
    full disk) are :class:`~daq.recorder.StorageError` instead.
    """


@dataclass(frozen=True)
class Recording:
    """A recording to a run file, as the GUI sees it (:attr:`LiveSource.recording`).

    Attributes
    ----------
    path : Path
        The run file.
    notes : str
        The operator notes stored with it (attribute ``operator_notes`` of ``/entry``).
    started_ns : int
        Host ``time.monotonic_ns()`` of the file's time 0, ns (when the dispatcher started it).
    error : str or None
        Why the recording stopped by itself (e.g. the disk filled up): the file is closed and
        readable up to its last flush. None while it records.
    """

    path: Path
    notes: str
    started_ns: int
    error: str | None = None

    def elapsed_s(self, now_ns: int | None = None) -> float:
        """Return the time since the recording started, s.

        Parameters
        ----------
        now_ns : int, optional
            Host ``time.monotonic_ns()`` now (a seam for tests).
        """
        now_ns = time.monotonic_ns() if now_ns is None else now_ns
        return (now_ns - self.started_ns) * 1e-9


@dataclass
class _Request:
    """A start or stop asked by the GUI thread, answered by the dispatcher (``done``)."""

    kind: str  # "start" or "stop"
    requested_ns: int = dataclasses.field(default_factory=time.monotonic_ns)
    reason: str = ""
    writer: Any = None  # start: the RunWriter, its recorder opened
    notes: str = ""
    done: threading.Event = dataclasses.field(default_factory=threading.Event)
    result: dict[str, Any] | None = None
    error: BaseException | None = None


class _FileRecording:
    """Records the engine's docs to a run file while asked to (see the module docstring).

    Threads: :meth:`feed` runs on the engine's dispatcher thread and is the only code that
    calls the file's writer once a recording started; :meth:`start` and :meth:`stop` run on the
    GUI thread, which only opens the file (before the hand-over) and posts a request under
    ``_lock``. The dispatcher serves a request holding ``_lock``, so a request the GUI thread
    finds still posted after its timeout was never touched and can be withdrawn.
    :attr:`recording` is one immutable object, swapped whole (atomic for the GUI thread).
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._request: _Request | None = None
        self._writer: Any = None  # the active file writer (dispatcher thread only)
        self._start_doc: dict[str, Any] | None = None
        self._preroll: dict[str, deque[Any]] = {}
        self._recent_events: deque[Any] = deque(maxlen=256)  # delivered before a start
        self._events = {"overflow": 0, "fault": 0}  # during the active recording
        #: The active recording, the last one that failed, or None.
        self.recording: Recording | None = None

    # -- dispatcher thread -----------------------------------------------------------------------
    def feed(self, name: str, doc: Any) -> None:
        """Take one engine doc: serve a posted request, write the doc if recording."""
        if name == "start":
            self._start_doc = dict(doc)
            return
        request = self._request
        if request is not None and (request.kind == "start" or name == "stop"
                                    or self._caught_up(request, name, doc)):
            self._serve(request)
        if self._writer is not None:
            if name == "stop":  # the engine stops under an active recording: finish the file
                # a failure is kept in ``recording``
                self._finish("acquisition stopped", time.monotonic_ns())
            else:
                self._write(name, doc)
        if name == "block":
            self._keep(doc)
        elif name == "event":
            self._recent_events.append(doc)

    def _caught_up(self, request: _Request, name: str, doc: Any) -> bool:
        """Tell whether a stop is due: every streaming device's blocks reached its request.

        The dispatcher may lag behind the devices (its queues hold what it has not delivered
        yet): the file ends at the operator's request, not where the dispatcher happened to
        be. Devices with blocks further apart than :data:`SLOW_BLOCKS_S` are not waited for;
        a stalled device at most :data:`STOP_CATCH_UP_S`.
        """
        if time.monotonic_ns() - request.requested_ns > STOP_CATCH_UP_S * 1e9:
            return True
        for device, kept in self._preroll.items():
            last = int(kept[-1].host_time_ns[-1])
            if name == "block" and doc.device == device and len(doc):
                last = max(last, int(doc.host_time_ns[-1]))
            if last >= request.requested_ns:
                continue
            span = int(kept[-1].host_time_ns[-1]) - int(kept[0].host_time_ns[-1])
            if len(kept) < 2 or span > SLOW_BLOCKS_S * 1e9 * (len(kept) - 1):
                continue  # a polled device: its next block may be a second away
            return False
        return True

    def _keep(self, block: Any) -> None:
        """Keep the last :data:`PREROLL_S` of a device's blocks for the next recording."""
        if not len(block):
            return
        kept = self._preroll.setdefault(block.device, deque())
        kept.append(block)
        oldest = int(block.host_time_ns[-1]) - int(PREROLL_S * 1e9)
        while kept and int(kept[0].host_time_ns[-1]) < oldest:
            kept.popleft()

    def _serve(self, request: _Request) -> None:
        with self._lock:
            if self._request is not request:  # withdrawn by the GUI thread after its timeout
                return
            self._request = None
            try:
                if request.kind == "start":
                    self._begin(request)
                else:
                    request.result, request.error = self._finish(request.reason,
                                                                 request.requested_ns)
            except Exception as exc:  # handed to the waiting GUI thread, which raises it
                log.exception("recording %s failed", request.kind)
                request.error = exc
            finally:
                request.done.set()

    @staticmethod
    def _call(writer: Any, name: str, doc: Any) -> BaseException | None:
        """Feed the file's writer one doc; return its failure, if any.

        The writer logs a failure itself (a storage error in one line, anything else with its
        traceback), closes its file and keeps the error in ``writer.error``.
        """
        try:
            writer(name, doc)
        except Exception as exc:  # logged by the writer; returned, never dropped
            return exc
        return cast(BaseException | None, writer.error)

    def _begin(self, request: _Request) -> None:
        if self._start_doc is None:
            raise RecordingError("record: the acquisition has not started yet")
        writer = request.writer
        # Time 0 is the operator's request, not the moment the dispatcher (which may lag behind
        # the devices) serves it: the blocks that arrived after it are still to be delivered.
        t0 = request.requested_ns
        doc = dict(self._start_doc)
        doc["host_time_ns"] = t0  # the file's time 0 is the recording's start
        doc["time"] = datetime.datetime.now(datetime.UTC).isoformat()
        error = self._call(writer, "start", doc)
        if error is not None:
            raise error
        self._events = {"overflow": 0, "fault": 0}
        self._writer = writer
        self.recording = Recording(path=Path(writer.path), notes=request.notes, started_ns=t0)
        log.info("recording to %s", writer.path)
        # The GUI thread goes on now: the pre-roll takes a few tenths of a second (the clock
        # maps refit at every block until their first windows close), a failure in it ends the
        # recording like any later one (``recording.error``).
        request.done.set()
        # Oldest first across devices, as the engine delivered them; before the current doc.
        for block in sorted((b for kept in self._preroll.values() for b in kept),
                            key=lambda b: int(b.host_time_ns[-1])):
            if self._writer is None:
                return
            self._write("block", block)
        # Events already delivered that belong to the recording (trigger pulses, faults, made
        # between the request and now).
        for event in list(self._recent_events):
            if self._writer is None:
                return
            if int(getattr(event, "host_time_ns", -1)) >= t0:
                self._write("event", event)

    def _write(self, name: str, doc: Any) -> None:
        writer = self._writer
        if name == "event" and getattr(doc, "kind", "") in self._events:
            self._events[doc.kind] += 1
        error = self._call(writer, name, doc)
        if error is not None:  # e.g. the disk filled up: this recording ends, the live view not
            self._writer = None
            self._failed(error)

    def _finish(self, reason: str,
                end_ns: int) -> tuple[dict[str, Any] | None, BaseException | None]:
        """Write the stop doc (last rows, clock fits, summary) and close the file.

        Parameters
        ----------
        reason : str
            Why it stops (in the summary).
        end_ns : int
            Host ``time.monotonic_ns()`` of the stop (the request), ns.

        Returns
        -------
        (dict or None, exception or None)
            The writer's summary, or the failure (also in :attr:`recording`).
        """
        writer, self._writer = self._writer, None
        rec = self.recording
        if writer is None or rec is None:
            return None, RecordingError("stop recording: not recording")
        doc = {"reason": reason, "host_time_ns": end_ns,
               "duration_s": (end_ns - rec.started_ns) * 1e-9,
               "overflows": self._events["overflow"], "faults": self._events["fault"]}
        error = self._call(writer, "stop", doc)
        if error is not None:
            self._failed(error)
            return None, error
        self.recording = None
        log.info("recorded %s (%s)", writer.path, reason)
        return dict(writer.summary or {}), None

    def _failed(self, error: BaseException) -> None:
        """Keep a failure in :attr:`recording` (the writer closed the file)."""
        rec = self.recording
        text = f"{type(error).__name__}: {error}"
        log.error("recording to %s stopped: %s", None if rec is None else rec.path, text)
        if rec is not None:
            self.recording = dataclasses.replace(rec, error=text)

    # -- GUI thread ------------------------------------------------------------------------------
    def start(self, writer: Any, notes: str, timeout_s: float) -> None:
        """Hand an opened file's writer to the dispatcher and wait until it records.

        Raises
        ------
        RecordingError
            Already recording, or the dispatcher did not answer within ``timeout_s`` (the
            request is withdrawn).
        StorageError
            Writing the file's first rows failed.
        """
        request = _Request("start", writer=writer, notes=notes)
        with self._lock:
            self._check_idle()
            self._request = request
        if not request.done.wait(timeout_s):
            with self._lock:
                withdrawn = self._request is request
                if withdrawn:
                    self._request = None
            if withdrawn:
                raise RecordingError(f"record: the acquisition did not take the request within "
                                     f"{timeout_s:g} s (is it stalled?)")
            request.done.wait()  # served under the lock, so already done
        if request.error is not None:
            raise request.error

    def stop(self, reason: str, timeout_s: float) -> dict[str, Any]:
        """Ask the dispatcher to finish the file and wait; return the writer's summary.

        Raises
        ------
        RecordingError
            Not recording (or the recording had already failed), or the dispatcher did not
            finish within ``timeout_s`` (it still will: the request stays posted).
        StorageError
            Writing the file's last rows failed (also in :attr:`recording`).
        """
        with self._lock:
            request = self._request
            if request is None or request.kind != "stop":
                rec = self.recording
                if rec is None or rec.error is not None:
                    failed = "" if rec is None else f" (the last one failed: {rec.error})"
                    raise RecordingError(f"stop recording: not recording{failed}")
                request = _Request("stop", reason=reason)
                self._request = request
        if not request.done.wait(timeout_s):
            raise RecordingError(f"stop recording: the file is not finished after {timeout_s:g} "
                                 "s; the acquisition finishes it when it can")
        if request.error is not None:
            raise request.error
        return dict(request.result or {})

    def _check_idle(self) -> None:
        """Refuse a start while recording or while a request waits (hold ``_lock``)."""
        if self._request is not None:
            raise RecordingError(f"record: a {self._request.kind} request is pending")
        rec = self.recording
        if rec is not None and rec.error is None:
            raise RecordingError(f"record: already recording to {rec.path}")

    def check_idle(self) -> None:
        """Refuse a start while recording (before any file is created)."""
        with self._lock:
            self._check_idle()


class _HealthTap:
    """The engine subscriber: the run writer, the faults and clock fits for the GUI, the file.

    Parameters
    ----------
    writer : RunWriter
        The live view's writer (into a :class:`RingRecorder`).
    files : _FileRecording
        Fed every doc after the live writer: the operator's recordings.
    """

    def __init__(self, writer: Any, files: _FileRecording) -> None:
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
        Where the console suggests run files (:mod:`daq.controls`); default: the current
        directory. Only stored: :meth:`start_recording` takes any path.
    ring : RingBuffer, optional
        The buffer the synchronised rows go to, with the columns of :func:`sync_columns` and
        at least :func:`ring_rows` rows (a :class:`~daq.shared_ring.SharedRingBuffer` when
        another process draws them: :mod:`daq.acquisition_process`); default: one made by
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
                 record_dir: str | Path | None = None, ring: RingBuffer | None = None) -> None:
        check_live_options(window_s, fan_rpm)
        self.config = config
        self.simulate = bool(simulate)
        self.window_s = float(window_s)
        self.fan_rpm = fan_rpm
        self._pulse_s = sync_pulse_interval_s
        #: The directory the console suggests run files in.
        self.record_dir = Path.cwd() if record_dir is None else Path(record_dir)
        self._files = _FileRecording()
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
        from daq.acquisition import Acquisition, drivers_from_config
        from daq.pipeline import RunWriter, start_sync_pulses

        try:
            live = self.config
            if self.simulate:
                from daq.rig_process import start_rig_process

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
            if self.fan_rpm is not None and "fan" in self._acq.drivers:
                fan = self._acq.drivers["fan"]
                fan.set_speed(self.fan_rpm)
                fan.start()
                self._fan_started = True
            self._info = SourceInfo(label="live", config=live, rate_hz=rate, duration_s=None)
        except BaseException:
            self.close()
            raise

    def _make_ring(self, config: RigConfig) -> RingBuffer:
        """Return the given ring (checked against the config) or a new one."""
        columns = sync_columns(config.taps.n_taps)
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
                    acq.drivers["fan"].stop()
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
        """The acquisition engine (:class:`~daq.acquisition.Acquisition`); None when stopped.

        For operator commands (:mod:`daq.controls`): its ``drivers``, ``arm``, ``release``,
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
        """Start recording the live rig to a new run file (DESIGN.md layout); return its path.

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
            Further keyword arguments of :class:`~daq.recorder.RunRecorder`
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
        from daq.pipeline import RunWriter

        if not self.running or self._info is None:
            raise RecordingError("record: acquisition not running")
        self._files.check_idle()
        path = Path(path)
        recorder = RunRecorder(path, config_text=self.config.text, rig_name=self.config.name,
                               operator_notes=notes, **dict(recorder_options or {}))
        # The checks record_run relies on (a missing or read-only directory, an existing file,
        # too little free space), before anything starts: open() creates the file or raises.
        recorder.open()
        try:
            writer = RunWriter(path, self._info.config, operator_notes=notes)
            writer.recorder = recorder  # opened above; declared and started by the dispatcher
            self._files.start(writer, notes, timeout_s)
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
            ``samples``, ``gaps``, ``clock_fits``, ...), as :func:`~daq.pipeline.record_run`.

        Raises
        ------
        RecordingError
            Not recording (also when the last recording failed: see :attr:`recording`), or the
            file not finished within ``timeout_s`` (the dispatcher still finishes it).
        StorageError
            Writing the last rows failed; :attr:`recording` keeps the error.
        """
        return self._files.stop(reason, timeout_s)

    def events(self, kind: str | None = None) -> list[Any]:
        """Return the engine's latest events (:class:`~daq.acquisition.Event`), oldest first.

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
            table of a recorded run (:class:`~daq.pipeline.RunWriter`).
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
