"""The acquisition engine: a reader thread per instrument, a dispatcher, (name, doc) subscribers.

Responsibility: open and start the instruments of a rig, read every one of them in its own
blocking reader thread (:class:`DeviceReader`: the scanner and the lasers with ``read_block``,
the barometer, the fan drive and the PLC by polling ``read()``), turn what each driver returns
into one uniform record (:class:`StreamBlock`), pass the records through bounded per-device
queues to one dispatcher thread, and hand them to subscribers as bluesky-style ``(name, doc)``
calls: ``"start"`` (metadata), ``"block"`` (a :class:`StreamBlock`), ``"event"`` (an
:class:`Event`: operator markers, releases, faults, overflows) and ``"stop"`` (a summary).
Operator actions on the PLC (arm, release, trigger) pass through the engine so that each is
recorded as an event with its host time. Every subscriber call happens on the dispatcher
thread, so a subscriber needs no locking of its own.

Not responsible for: the device protocols (the drivers), the reading of one device itself
(reads, faults and recovery, the bounded queue: :mod:`daq.device_reader`), the records' types
(:mod:`daq.records`; re-exported here), mapping device clocks onto the host clock
(:mod:`daq.sync`), writing files (:mod:`daq.recorder`), or plotting (:mod:`daq.live`, which
polls a :class:`~daq.ring_buffer.RingBuffer` fed by a subscriber). The acquisition threads never
touch h5py or Qt (STYLE.md, "Threads and GUI").

Design choices:

- **Full queue: drop the oldest block, mark the gap** and **faults: report, back off, recover**
  are the readers' choices, described where they are made: :mod:`daq.device_reader`. The
  dispatcher here does its part of the first: it marks the gap on the next block delivered
  and posts the ``"overflow"`` event before it.
- **Stop is cooperative.** :meth:`Acquisition.stop` stops the scan, sets each reader's
  ``threading.Event`` (polled readers wait on it; streaming reads use a short timeout), joins the
  readers within ``join_timeout_s``, closes the drivers (which also unblocks a reader stuck in a
  read), then lets the dispatcher drain what is queued and deliver ``"stop"``.
"""

from __future__ import annotations

import dataclasses
import datetime
import logging
import math
import queue
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from types import TracebackType
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from daq.device_reader import DeviceReader, _DropRun
from daq.errors import DaqError
from daq.records import (
    KINDS,
    SYSTEM_EVENT_KINDS,
    DeviceFault,
    DeviceStats,
    Event,
    FloatArray,
    StreamBlock,
)

if TYPE_CHECKING:
    from daq.config import RigConfig

__all__ = [
    "KINDS",
    "ROLE_KINDS",
    "SYSTEM_EVENT_KINDS",
    "Acquisition",
    "CalzError",
    "CalzResult",
    "DeviceFault",
    "DeviceReader",
    "DeviceStats",
    "Event",
    "StreamBlock",
    "Subscriber",
    "drivers_from_config",
]

log = logging.getLogger(__name__)

#: Rig-config role -> engine kind.
ROLE_KINDS: Mapping[str, str] = {"scanner": "scanner", "lasers": "laser",
                                 "barometer": "barometer", "fan": "fan", "plc": "plc"}
#: After a CALZ that timed out the scanner may still be zeroing: how long a restart of the scan
#: keeps trying, s (the manual: a CALZ takes "under 10 seconds").
_RESTART_WAIT_S = 10.0


# ------------------------------------------------------------------------------------------------
# CALZ results; subscribers
# ------------------------------------------------------------------------------------------------
class CalzError(DaqError, RuntimeError):
    """A zero calibration during a run failed after the scan was interrupted.

    The message says at which step (``pause``, ``stop``, ``calz``, ``restart``) and whether the
    scan runs again; the device's own error is the ``__cause__``.
    """


@dataclass(frozen=True, eq=False)
class CalzResult:
    """What :meth:`Acquisition.calz` did: the pause of the scan and the zero it removed.

    Attributes
    ----------
    device : str
        The scanner.
    wind_speed_now : float
        The wind speed the caller vouched for, m/s (0: the driver refuses anything else).
    stop_ns, stopped_ns : int
        Host ``time.monotonic_ns()`` just before STOP was sent and once it was acknowledged:
        the scanner stopped in between.
    restart_ns, restarted_ns : int
        The same for the new scan: before the (successful) restart began and once SCAN was
        acknowledged.
    pause_s : float
        How long the scanner did not scan, s: from the middle of the STOP command to the
        middle of the restart, each known to within half its duration (a few ms; the bounds
        are ``(restart_ns - stopped_ns)`` and ``(restarted_ns - stop_ns)``).
    calz_s : float
        Time from CALZ to READY, s.
    offsets_before_pa : ndarray of float64, (channels,)
        Mean pressure per channel over the last frames before STOP (``frames_averaged`` of
        them), Pa. Wind-off (as a CALZ must be) this is the zero error the CALZ removed; NaN
        for a channel without a frame.
    frames_averaged : int
        Frames in that mean.
    event : Event
        The ``"calz"`` event posted.
    """

    device: str
    wind_speed_now: float
    stop_ns: int
    stopped_ns: int
    restart_ns: int
    restarted_ns: int
    pause_s: float
    calz_s: float
    offsets_before_pa: FloatArray
    frames_averaged: int
    event: Event

    def summary(self) -> dict[str, float | int]:
        """Zero-offset figures for an event or a status line (Pa): RMS, max and where."""
        return _offsets_summary(self.offsets_before_pa, self.frames_averaged)


def _offsets_summary(offsets: FloatArray, frames: int) -> dict[str, float | int]:
    finite = np.isfinite(offsets)
    if not finite.any():
        return {"frames_averaged": frames, "channels": 0}
    abs_off = np.where(finite, np.abs(offsets), -1.0)
    worst = int(np.argmax(abs_off))
    return {"frames_averaged": frames, "channels": int(finite.sum()),
            "offset_mean_pa": float(np.mean(offsets[finite])),
            "offset_rms_pa": float(np.sqrt(np.mean(offsets[finite] ** 2))),
            "offset_max_abs_pa": float(abs_off[worst]), "offset_max_channel": worst}


class Subscriber(Protocol):
    """A ``(name, doc)`` callback, as in bluesky: called on the dispatcher thread only."""

    def __call__(self, name: str, doc: Any, /) -> None:
        """Receive ``"start"`` (dict), ``"block"``, ``"event"`` or ``"stop"`` (dict)."""


# ------------------------------------------------------------------------------------------------
# Engine
# ------------------------------------------------------------------------------------------------
class Acquisition:
    """Run a rig's instruments: reader threads, a dispatcher, and ``(name, doc)`` subscribers.

    Parameters
    ----------
    drivers : mapping of str to (kind, driver)
        Instrument name -> (one of :data:`KINDS`, driver object). Drivers are opened by
        :meth:`start` and closed by :meth:`stop`. See :func:`drivers_from_config`.
    queue_size : int
        Blocks each device's queue holds, >= 1 (a laser gives ~50 blocks/s, the scanner up to
        one per frame): when full, the oldest block is dropped and the gap marked.
    subscribers : iterable of Subscriber
        ``callback(name, doc)``, called in order on the dispatcher thread. An exception in one
        is logged and counted (``"stop"`` summary) and does not stop the others.
    metadata : mapping, optional
        Added to the ``"start"`` doc under ``"metadata"`` (operator, section, config text ...).
    poll_interval_s : mapping of str to float, optional
        Poll period per device name for polled kinds, s (defaults in :class:`DeviceReader`).
    read_timeout_s : float
        Timeout of one streaming read, s (> 0); bounds the stop latency of a quiet stream.
    stall_s : float
        A stream silent this long (s) is reported as a fault (once per stall).
    join_timeout_s : float
        Time :meth:`stop` gives all readers together to finish, s, before closing the drivers
        under them. A driver that retries internally (e.g. a laser reopening its line) may need
        a few seconds.
    backoff_min_s, backoff_max_s : float
        Retry wait after a fault, s: the first, and the cap of its doubling.
    control_queue_size : int
        Capacity of the queue of events and start/stop docs; an event that finds it full is
        counted (``events_dropped``) and logged.

    Notes
    -----
    One run per object: :meth:`start` once, :meth:`stop` once (further calls return the same
    summary). Use it as a context manager, or :meth:`run_until`.
    """

    def __init__(self, drivers: Mapping[str, tuple[str, Any]], *, queue_size: int = 1024,
                 subscribers: Iterable[Subscriber] = (), metadata: Mapping[str, Any] | None = None,
                 poll_interval_s: Mapping[str, float] | None = None, read_timeout_s: float = 0.2,
                 stall_s: float = 2.0, join_timeout_s: float = 5.0, backoff_min_s: float = 0.1,
                 backoff_max_s: float = 5.0, control_queue_size: int = 4096) -> None:
        if isinstance(queue_size, bool) or not isinstance(queue_size, int) or queue_size < 1:
            raise ValueError(f"queue_size must be an integer >= 1, got {queue_size!r}")
        if isinstance(control_queue_size, bool) or not isinstance(control_queue_size, int) \
                or control_queue_size < 1:
            raise ValueError(f"control_queue_size must be an integer >= 1, got "
                             f"{control_queue_size!r}")
        for key, value in (("read_timeout_s", read_timeout_s), ("stall_s", stall_s),
                           ("join_timeout_s", join_timeout_s), ("backoff_min_s", backoff_min_s),
                           ("backoff_max_s", backoff_max_s)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"{key} must be a finite number > 0, got {value!r}")
        if backoff_max_s < backoff_min_s:
            raise ValueError(f"backoff_max_s = {backoff_max_s!r} is below backoff_min_s = "
                             f"{backoff_min_s!r}")
        polls = dict(poll_interval_s or {})
        unknown = sorted(set(polls) - set(drivers))
        if unknown:
            raise ValueError(f"poll_interval_s names unknown device(s) {unknown}; devices: "
                             f"{sorted(drivers)}")
        for key, value in polls.items():
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"poll_interval_s[{key!r}] must be > 0, got {value!r}")
        if not drivers:
            raise ValueError("drivers is empty: nothing to acquire")
        self._doorbell = threading.Event()
        self._control: queue.Queue[tuple[str, Any]] = queue.Queue(maxsize=control_queue_size)
        self._readers: dict[str, DeviceReader] = {}
        for name, pair in drivers.items():
            if not (isinstance(pair, (tuple, list)) and len(pair) == 2):
                raise TypeError(f"drivers[{name!r}] must be a (kind, driver) tuple, got {pair!r}")
            kind, driver = pair
            self._readers[name] = DeviceReader(
                name, kind, driver, queue_size=queue_size, on_event=self._post_event,
                doorbell=self._doorbell, poll_interval_s=polls.get(name),
                read_timeout_s=read_timeout_s, stall_s=stall_s, backoff_min_s=backoff_min_s,
                backoff_max_s=backoff_max_s)
        self._state = "idle"  # idle -> starting -> running -> stopping -> stopped (or failed)
        self._state_lock = threading.Lock()
        self._subscribers: list[Subscriber] = []
        self._subscriber_errors: list[int] = []
        for sub in subscribers:
            self.subscribe(sub)
        self._metadata = dict(metadata or {})
        self._queue_size = queue_size
        self._join_timeout_s = float(join_timeout_s)
        self._dispatcher: threading.Thread | None = None
        self._finish = threading.Event()
        self._events_dropped = 0
        self._counts_lock = threading.Lock()
        self._releases: list[Event] = []
        self._calz_lock = threading.Lock()  # one CALZ at a time; stop() waits for it
        self._errors: list[str] = []
        self._stop_done: set[str] = set()
        self._reason = ""
        self._t0_ns = 0
        self._summary: dict[str, Any] | None = None

    # -- configuration ---------------------------------------------------------------------------
    def subscribe(self, subscriber: Subscriber) -> None:
        """Add a ``(name, doc)`` subscriber (before :meth:`start` only)."""
        if not callable(subscriber):
            raise TypeError(f"a subscriber is a callable (name, doc), got {subscriber!r}")
        if self._state != "idle":
            raise RuntimeError("subscribe before start(): subscribers are fixed while running")
        self._subscribers.append(subscriber)
        self._subscriber_errors.append(0)

    @property
    def drivers(self) -> dict[str, Any]:
        """Measure the driver of each device (for operator commands such as the fan speed)."""
        return {name: r.driver for name, r in self._readers.items()}

    @property
    def running(self) -> bool:
        """Measure whether the engine is acquiring (started and not yet stopping)."""
        return self._state == "running"

    def stats(self) -> dict[str, DeviceStats]:
        """Return the counters of every device: blocks, samples, overflows, faults, ..."""
        return {name: r.stats() for name, r in self._readers.items()}

    # -- life cycle ------------------------------------------------------------------------------
    def start(self) -> None:
        """Open every driver, start the scan, then the dispatcher and the reader threads.

        A driver that fails to open (or a scan that fails to start) closes the ones already
        opened and re-raises: nothing runs.
        """
        with self._state_lock:
            if self._state != "idle":
                raise RuntimeError(f"start(): the acquisition is {self._state} (one run per "
                                   "object)")
            self._state = "starting"
        opened: list[DeviceReader] = []
        try:
            for reader in self._readers.values():
                reader.open_device()
                opened.append(reader)
            for reader in self._readers.values():
                reader.begin()
        except BaseException:
            for reader in reversed(opened):
                self._cleanup(reader.close_device, f"closing {reader.name}")
            self._state = "failed"
            raise
        self._t0_ns = time.monotonic_ns()
        self._post("start", {
            "uid": uuid.uuid4().hex,
            "time": datetime.datetime.now(datetime.UTC).isoformat(),
            "host_time_ns": self._t0_ns,
            "devices": {name: {"kind": r.kind, "describe": _describe(r.driver)}
                        for name, r in self._readers.items()},
            "queue_size": self._queue_size,
            "metadata": self._metadata,
        })
        self._dispatcher = threading.Thread(target=self._dispatch, name="windrig-dispatcher",
                                            daemon=True)
        self._dispatcher.start()
        for reader in self._readers.values():
            reader.start()
        self._state = "running"
        log.info("acquisition started: %s", ", ".join(
            f"{n} ({r.kind})" for n, r in self._readers.items()))

    def stop(self, reason: str = "stop") -> dict[str, Any]:
        """Stop the scan, the readers (joined within ``join_timeout_s``), the drivers, dispatch.

        Returns the ``"stop"`` summary (also sent to the subscribers). Idempotent; safe to call
        again after an interruption (steps already done are skipped). Must not be called from
        a subscriber (the dispatcher thread).

        Returns
        -------
        dict
            ``reason``, ``duration_s``, ``devices`` (per-device :class:`DeviceStats` as dicts),
            ``overflows`` and ``overflow_samples`` (totals), ``faults``, ``events_dropped``,
            ``subscriber_errors``, ``releases`` (their events), ``errors`` (failures while
            stopping), ``threads_alive`` (threads that did not finish: should be empty).
        """
        if threading.current_thread() is self._dispatcher:
            raise RuntimeError("stop() called from a subscriber: it would wait for itself")
        with self._state_lock:
            if self._state == "stopped" and self._summary is not None:
                return self._summary
            if self._state in ("idle", "failed", "starting"):
                return self._build_summary("never started")
            if self._state == "running":
                self._reason = reason
            self._state = "stopping"
        # A CALZ in progress first restarts the scan and resumes its reader (bounded by its own
        # timeouts): stopping under it would interleave STOP with its commands. calz() refuses
        # to begin once the state is "stopping".
        with self._calz_lock:
            pass
        readers = list(self._readers.values())
        if "halt" not in self._stop_done:
            for reader in readers:
                self._cleanup(reader.halt, f"stopping {reader.name}")
            self._stop_done.add("halt")
        for reader in readers:
            reader.request_stop()
        deadline = time.monotonic() + self._join_timeout_s
        for reader in readers:
            reader.join(deadline - time.monotonic())
        if "close" not in self._stop_done:
            for reader in readers:
                self._cleanup(reader.close_device, f"closing {reader.name}")
            self._stop_done.add("close")
        for reader in readers:  # closing a driver unblocks a reader stuck in a read
            if reader.alive and not reader.join(1.0):
                msg = f"reader {reader.name} did not finish within the join timeout"
                log.error(msg)
                self._errors.append(msg)
        self._finish.set()
        self._doorbell.set()
        if self._dispatcher is not None:
            self._dispatcher.join(self._join_timeout_s)
            if self._dispatcher.is_alive():
                msg = "dispatcher did not finish (a subscriber blocks?)"
                log.error(msg)
                self._errors.append(msg)
        summary = self._summary if self._summary is not None else self._build_summary(
            self._reason)
        self._summary = summary
        self._state = "stopped"
        log.info("acquisition stopped (%s): %d overflow(s), %d fault(s)", summary["reason"],
                 summary["overflows"], summary["faults"])
        return summary

    def __enter__(self) -> Acquisition:
        self.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if exc_type is None:
            self.stop()
        elif issubclass(exc_type, KeyboardInterrupt):
            self.stop("interrupted")
        else:
            self.stop(f"error: {exc_type.__name__}: {exc}")

    def run_until(self, until: float | threading.Event | None = None, *,
                  poll_s: float = 0.1) -> dict[str, Any]:
        """Start (unless running), acquire until ``until``, stop cleanly; return the summary.

        Parameters
        ----------
        until : float, threading.Event or None
            A duration in s (>= 0), an event to wait for, or None to run until Ctrl-C.
        poll_s : float
            Slice of the wait, s: how quickly Ctrl-C is acted on.

        Returns
        -------
        dict
            The ``"stop"`` summary; its ``reason`` is ``"duration"``, ``"event"`` or
            ``"interrupted"`` (Ctrl-C: KeyboardInterrupt is handled, the engine stopped, the
            summary returned; a second Ctrl-C while stopping does not abort the stop).
        """
        if isinstance(until, (int, float)) and not isinstance(until, bool):
            if not (math.isfinite(until) and until >= 0):
                raise ValueError(f"until must be a duration >= 0 s, got {until!r}")
        elif until is not None and not isinstance(until, threading.Event):
            raise TypeError(f"until must be a duration (s), a threading.Event or None, got "
                            f"{until!r}")
        reason = "stop"
        try:
            if self._state == "idle":
                self.start()
            if isinstance(until, threading.Event):
                while not until.wait(poll_s):
                    pass
                reason = "event"
            elif until is None:
                while True:
                    time.sleep(poll_s)
            else:
                end = time.monotonic() + float(until)
                while (left := end - time.monotonic()) > 0:
                    time.sleep(min(poll_s, left))
                reason = "duration"
        except KeyboardInterrupt:
            log.warning("interrupted: stopping the acquisition cleanly")
            reason = "interrupted"
        while True:
            try:
                return self.stop(reason)
            except KeyboardInterrupt:
                log.warning("interrupted again: still stopping (bounded by the join timeouts)")

    # -- operator actions --------------------------------------------------------------------------
    def mark(self, kind: str, text: str = "") -> Event:
        """Record an operator marker (``kind`` of the operator's choosing, e.g. ``"note"``).

        Raises
        ------
        ValueError
            ``kind`` is empty or one the engine reserves (:data:`SYSTEM_EVENT_KINDS`).
        RuntimeError
            The engine is not running (the marker would be recorded nowhere).
        """
        if not isinstance(kind, str) or not kind.strip():
            raise ValueError(f"a marker kind is a non-empty string, got {kind!r}")
        if kind in SYSTEM_EVENT_KINDS:
            raise ValueError(f"marker kind {kind!r} is reserved for the engine's own events "
                             f"{sorted(SYSTEM_EVENT_KINDS)}")
        self._require_running(f"mark({kind!r})")
        event = Event(kind=kind, host_time_ns=time.monotonic_ns(), text=str(text))
        self._post_event(event)
        return event

    def release(self, plc: str | None = None) -> Event:
        """Release the model through the PLC and record a ``"release"`` event; return it.

        The event's ``host_time_ns`` is when the PLC acknowledged the RELEASE coil
        (``ReleaseTiming.command_ns``); ``data`` holds ``requested_ns`` (before the command),
        ``command_ns``, ``confirmed_ns`` (RELEASED read set) and ``delay_s``.

        Parameters
        ----------
        plc : str, optional
            Name of the PLC device; default: the only device of kind ``"plc"``.

        Raises
        ------
        SafetyError, DeviceError, TransportError
            From ``plc.release()`` (not armed; RELEASED never came; link lost); a
            ``"release_failed"`` event is recorded first.
        RuntimeError
            The engine is not running (a release must be recorded).
        """
        name, driver = self._plc(plc, "release")
        requested = time.monotonic_ns()
        try:
            timing = driver.release()
        except DaqError as exc:
            self._post_event(Event(kind="release_failed", host_time_ns=requested, device=name,
                                   text=str(exc), data={"error": type(exc).__name__}))
            raise
        command = int(getattr(timing, "command_ns", requested))
        confirmed = int(getattr(timing, "confirmed_ns", command))
        event = Event(kind="release", host_time_ns=command, device=name, text="model released",
                      data={"requested_ns": requested, "command_ns": command,
                            "confirmed_ns": confirmed, "delay_s": (confirmed - command) * 1e-9})
        with self._counts_lock:
            self._releases.append(event)
        self._post_event(event)
        return event

    def arm(self, plc: str | None = None) -> Event:
        """Arm the PLC (magnet on, one release permitted) and record an ``"arm"`` event.

        The event's ``host_time_ns`` is when the command was requested: arming catches a
        decaying model, and the decay is certainly free before that instant (the magnet acts
        somewhere between the request and the acknowledgement, ``data["acknowledged_ns"]``).
        """
        name, driver = self._plc(plc, "arm")
        requested = time.monotonic_ns()
        driver.arm()
        event = Event(kind="arm", host_time_ns=requested, device=name, text="release armed",
                      data={"acknowledged_ns": time.monotonic_ns()})
        self._post_event(event)
        return event

    def trigger(self, plc: str | None = None) -> Event:
        """Pulse the trigger line and record a ``"trigger"`` event at the rising edge's time."""
        name, driver = self._plc(plc, "trigger_pulse")
        t_ns = int(driver.trigger_pulse())
        round_trip = int(getattr(driver, "last_trigger_round_trip_ns", 0))
        event = Event(kind="trigger", host_time_ns=t_ns, device=name, text="trigger pulse",
                      data={"round_trip_s": round_trip * 1e-9})
        self._post_event(event)
        return event

    def calz(self, device: str | None = None, *, wind_speed_now: float,
             timeout_s: float = 30.0) -> CalzResult:
        """Zero the pressure scanner (CALZ) during the run, wind-off; return what it did.

        The scanner refuses every command but STOP while it scans, so the scan is interrupted:
        the scanner's reader is parked between two reads, STOP is sent, the frames still in
        flight are read and delivered, the driver's CALZ runs (its wind-off rule stays in
        force: ``wind_speed_now`` is passed through), a new scan is started and the reader
        resumed. The interruption is marked, never silent: the scanner stream gets a gap over
        the pause (its length in frames where the frame times are absolute, else -1; see
        ``daq.device_reader._ScannerAdapter``), so the sync view has NaN pressures and forces
        there, and a ``"calz"`` event (at ``stop_ns``) carries the pause and the zero-offset
        summary.

        Parameters
        ----------
        device : str, optional
            The scanner's name; default: the only device of kind ``"scanner"``.
        wind_speed_now : float
            The wind speed now, m/s, as measured by the caller with the fan stopped. The
            driver refuses anything but 0 (:meth:`~daq.scanivalve_mps4264.ScanivalveMps4264.
            check_calz_allowed`), before anything is interrupted.
        timeout_s : float
            Longest wait for the scanner to finish zeroing, s (> 0; the manual: "under 10
            seconds"). Parking the reader is bounded separately by ``join_timeout_s``.

        Returns
        -------
        CalzResult
            Pause, CALZ duration, the zero it removed, the event posted.

        Raises
        ------
        RuntimeError
            The engine is not running, or a CALZ is already in progress (nothing is done).
        ValueError
            ``device`` is not a scanner of this engine, or ``timeout_s`` is not > 0.
        TypeError
            The scanner's driver has no ``calz()``.
        SafetyError
            The driver refuses: the wind is not off. Nothing was interrupted; a
            ``"calz_failed"`` event is posted.
        CalzError
            A step after the refusal check failed (the reader did not pause, STOP, CALZ or the
            restart of the scan failed); a ``"calz_failed"`` event is posted, the restart of
            the scan was tried in any case and the reader resumed. When the scan could not be
            restarted, a fault of the scanner is posted too and the reader's recovery (reopen,
            new scan) takes over.
        """
        if not (isinstance(timeout_s, (int, float)) and math.isfinite(timeout_s)
                and timeout_s > 0):
            raise ValueError(f"timeout_s must be a finite number > 0, got {timeout_s!r}")
        name, reader = self._scanner(device)
        if not self._calz_lock.acquire(blocking=False):
            raise RuntimeError(f"calz({name!r}): a CALZ is already in progress; wait for it")
        try:
            # Checked again under the lock: stop() waits for this lock once it is "stopping".
            self._require_running(f"calz({name!r})")
            if not reader.alive:
                raise RuntimeError(f"calz({name!r}): the scanner's reader has stopped "
                                   f"({reader.failed!r}); restart the acquisition")
            self._refuse_unsafe_calz(name, reader.driver, wind_speed_now)
            return self._calz_paused(name, reader, float(wind_speed_now), float(timeout_s))
        finally:
            self._calz_lock.release()

    def _scanner(self, name: str | None) -> tuple[str, DeviceReader]:
        self._require_running("calz()")
        scanners = [n for n, r in self._readers.items() if r.kind == "scanner"]
        if name is None:
            if len(scanners) != 1:
                raise ValueError(f"name the scanner: devices of kind 'scanner' are {scanners}")
            name = scanners[0]
        elif name not in scanners:
            raise ValueError(f"{name!r} is not a device of kind 'scanner'; those are "
                             f"{scanners}")
        driver = self._readers[name].driver
        if not callable(getattr(driver, "calz", None)):
            raise TypeError(f"scanner {name!r} driver {type(driver).__name__} has no calz()")
        return name, self._readers[name]

    def _refuse_unsafe_calz(self, name: str, driver: Any, wind_speed_now: float) -> None:
        """Apply the driver's wind-off rule before the scan is touched (a refusal costs no data)."""
        check = getattr(driver, "check_calz_allowed", None)
        if not callable(check):
            return  # the driver's calz() still applies its rule, after STOP
        try:
            check(wind_speed_now=wind_speed_now)
        except DaqError as exc:
            self._post_event(Event(
                kind="calz_failed", host_time_ns=time.monotonic_ns(), device=name,
                text=f"CALZ refused, the scan goes on: {exc}",
                data={"stage": "refused", "error": type(exc).__name__,
                      "wind_speed_now": wind_speed_now, "scan_interrupted": False}))
            raise

    def _calz_paused(self, name: str, reader: DeviceReader, wind_speed_now: float,
                     timeout_s: float) -> CalzResult:
        """Park the reader, STOP, drain, CALZ, restart the scan, resume: the steps of calz()."""
        driver = reader.driver
        if not reader.pause(self._join_timeout_s):
            reader.resume()
            why = (f"the reader of {name!r} did not pause within {self._join_timeout_s:g} s "
                   "(stuck in a read or a reconnect?)")
            self._calz_failed(name, "pause", why, time.monotonic_ns(), restarted=None)
            raise CalzError(f"CALZ of {name!r} not started: {why}; nothing was interrupted, "
                            "the scan goes on")
        stage = "stop"
        failure: DaqError | None = None
        calz_s = math.nan
        offsets, frames = np.zeros(0), 0
        stop_ns = stopped_ns = time.monotonic_ns()
        try:
            try:
                driver.stop()
                stopped_ns = time.monotonic_ns()
                # Frames sent before STOP are data like any other: deliver them, so that the
                # gap is only the time the scanner stood still.
                rate = float(getattr(driver, "rate_hz", 0.0) or 0.0)
                reader.drain(max(0.05, 5.0 / rate) if rate > 0 else 0.2)
                offsets, frames = reader.recent_pressure_mean()
                stage = "calz"
                took = driver.calz(wind_speed_now=wind_speed_now, timeout_s=timeout_s)
                calz_s = float(took) if isinstance(took, (int, float)) else math.nan
                stage = "restart"
            except DaqError as exc:
                failure = exc
            finally:  # also on a bug or Ctrl-C: the scan must run again if at all possible
                restart_error, restart_ns = self._restart_scan(name, reader)
                restarted_ns = time.monotonic_ns()
                # Each end of the standstill is known to within half its command's duration.
                pause_s = ((restart_ns + restarted_ns) - (stop_ns + stopped_ns)) * 0.5e-9
                reader.note_pause(pause_s)
        finally:
            reader.resume()
        if restart_error is not None:
            reader.report_fault(restart_error)
            if failure is None:
                stage, failure = "restart", restart_error
        if failure is not None:
            self._calz_failed(name, stage, failure, stop_ns, restarted=restart_error is None,
                              pause_s=pause_s)
            state = (f"the scan was restarted after {pause_s:.2f} s" if restart_error is None
                     else f"the scan could NOT be restarted ({restart_error}); the reader's "
                     "recovery retries")
            raise CalzError(f"CALZ of {name!r} failed at {stage}: {failure}; {state}") \
                from failure
        summary = _offsets_summary(offsets, frames)
        event = Event(kind="calz", host_time_ns=stop_ns, device=name,
                      text=f"scanner zeroed (CALZ, wind {wind_speed_now:g} m/s); scan paused "
                           f"{pause_s:.3f} s",
                      data={"pause_s": pause_s, "calz_s": calz_s, "stop_ns": stop_ns,
                            "stopped_ns": stopped_ns, "restart_ns": restart_ns,
                            "restarted_ns": restarted_ns, "wind_speed_now": wind_speed_now,
                            **summary, "offsets_before_pa": offsets.copy()})
        self._post_event(event)
        log.info("%s: CALZ done; scan paused %.3f s; zero removed: %s", name, pause_s, summary)
        return CalzResult(device=name, wind_speed_now=wind_speed_now, stop_ns=stop_ns,
                          stopped_ns=stopped_ns, restart_ns=restart_ns,
                          restarted_ns=restarted_ns, pause_s=pause_s, calz_s=calz_s,
                          offsets_before_pa=offsets, frames_averaged=frames, event=event)

    def _restart_scan(self, name: str, reader: DeviceReader) -> tuple[DaqError | None, int]:
        """Start the scan again after a pause; return the error when it could not be.

        A refused SCAN is retried while the scanner still zeroes (a CALZ that timed out),
        for at most ``_RESTART_WAIT_S``; a scanner found scanning already (STOP had failed)
        counts as restarted: it streams to the fresh data connections. Also returns the host
        time (ns) at which the last attempt began.
        """
        end = time.monotonic() + _RESTART_WAIT_S
        while True:
            began = time.monotonic_ns()
            try:
                reader.restart_after_pause()
                return None, began
            except DaqError as exc:
                error = exc
            try:
                state = reader.driver.status()
            except DaqError as exc:
                log.error("%s: scan not restarted (%s); status failed too: %s", name, error, exc)
                return error, began
            if state == "SCAN":
                return None, began
            if state != "CALZ" or time.monotonic() >= end:
                log.error("%s: scan not restarted (state %s): %s", name, state, error)
                return error, began
            time.sleep(0.1)

    def _calz_failed(self, name: str, stage: str, error: BaseException | str, at_ns: int, *,
                     restarted: bool | None, pause_s: float = 0.0) -> None:
        log.error("%s: CALZ failed at %s: %s", name, stage, error)
        self._post_event(Event(
            kind="calz_failed", host_time_ns=at_ns, device=name,
            text=f"CALZ failed at {stage}: {error}",
            data={"stage": stage,
                  "error": "timeout" if isinstance(error, str) else type(error).__name__,
                  "scan_interrupted": restarted is not None, "scan_restarted": restarted,
                  "pause_s": pause_s}))

    def _plc(self, name: str | None, method: str) -> tuple[str, Any]:
        self._require_running(f"{method}()")
        plcs = [n for n, r in self._readers.items() if r.kind == "plc"]
        if name is None:
            if len(plcs) != 1:
                raise ValueError(f"name the PLC: devices of kind 'plc' are {plcs}")
            name = plcs[0]
        elif name not in plcs:
            raise ValueError(f"{name!r} is not a device of kind 'plc'; those are {plcs}")
        driver = self._readers[name].driver
        if not callable(getattr(driver, method, None)):
            raise TypeError(f"PLC {name!r} driver {type(driver).__name__} has no {method}()")
        return name, driver

    def _require_running(self, what: str) -> None:
        if self._state != "running":
            raise RuntimeError(f"{what}: the acquisition is {self._state}, not running")

    # -- dispatch ----------------------------------------------------------------------------------
    def _post(self, name: str, doc: Any) -> None:
        try:
            self._control.put_nowait((name, doc))
        except queue.Full:
            with self._counts_lock:
                self._events_dropped += 1
            log.error("event queue full (%d): %s doc dropped: %r", self._control.maxsize, name,
                      doc)
            return
        self._doorbell.set()

    def _post_event(self, event: Event) -> None:
        self._post("event", event)

    def _dispatch(self) -> None:
        while True:
            self._doorbell.wait(0.1)
            self._doorbell.clear()
            finishing = self._finish.is_set()  # read before the sweep: nothing comes after it
            self._sweep()
            if finishing:
                break
        for reader in self._readers.values():  # drops never followed by a delivered block
            for run in reader.take_drops():
                self._emit("event", self._overflow_event(reader, run))
        self._summary = self._build_summary(self._reason)
        self._emit("stop", self._summary)

    def _sweep(self) -> None:
        """Deliver the control docs, then the queued blocks, round-robin over devices."""
        budget = {r: r.queue.qsize() for r in self._readers.values()}
        while True:
            while True:
                try:
                    name, doc = self._control.get_nowait()
                except queue.Empty:
                    break
                self._emit(name, doc)
            busy = False
            for reader, left in budget.items():
                if left <= 0:
                    continue
                try:
                    block = reader.queue.get_nowait()
                except queue.Empty:
                    budget[reader] = 0
                    continue
                budget[reader] = left - 1
                busy = True
                self._deliver(reader, block)
            if not busy:
                return

    def _deliver(self, reader: DeviceReader, block: StreamBlock) -> None:
        runs = reader.take_drops(block.seq)
        if runs:
            gaps: list[tuple[int, int]] = []
            for run in runs:
                self._emit("event", self._overflow_event(reader, run))
                # The run's own gap spans its counters; of the device gaps the dropped blocks
                # carried, pass on those before that span (and restart markers, length -1).
                first = run.first_counter
                gaps.extend(g for g in run.gaps
                            if first is None or g[1] < 0 or g[0] < first - 1)
                gap = run.gap()
                if gap is not None:
                    gaps.append(gap)
            block = dataclasses.replace(block, gaps=(*gaps, *block.gaps),
                                        overflow_samples=sum(r.samples for r in runs))
        self._emit("block", block)
        reader.delivered()

    @staticmethod
    def _overflow_event(reader: DeviceReader, run: _DropRun) -> Event:
        return Event(
            kind="overflow", host_time_ns=run.first_time_ns, device=reader.name,
            text=(f"{run.blocks} block(s), {run.samples} sample(s) of {reader.name} dropped: "
                  "queue full (subscribers too slow)"),
            data={"blocks": run.blocks, "samples": run.samples, "first_seq": run.first_seq,
                  "last_seq": run.last_seq, "gap": run.gap(),
                  "first_counter": run.first_counter, "last_counter": run.last_counter,
                  "last_time_ns": run.last_time_ns, "device_gaps": list(run.gaps),
                  "device_gaps_truncated": run.gaps_truncated})

    def _emit(self, name: str, doc: Any) -> None:
        for index, subscriber in enumerate(self._subscribers):
            try:
                subscriber(name, doc)
            except Exception:  # one subscriber's bug must not starve the others: counted, logged
                with self._counts_lock:
                    self._subscriber_errors[index] += 1
                    n = self._subscriber_errors[index]
                if n <= 3:
                    log.exception("subscriber %r failed on a %r doc%s", subscriber, name,
                                  " (further failures are counted, not logged)" if n == 3
                                  else "")

    # -- helpers -----------------------------------------------------------------------------------
    def _cleanup(self, step: Callable[[], None], what: str) -> None:
        """Run one clean-up step; a failure is logged and kept for the summary, never raised."""
        try:
            step()
        except Exception as exc:  # the remaining steps must still run; reported in "errors"
            log.error("%s failed: %s: %s", what, type(exc).__name__, exc)
            self._errors.append(f"{what}: {type(exc).__name__}: {exc}")

    def _build_summary(self, reason: str) -> dict[str, Any]:
        stats = self.stats()
        with self._counts_lock:
            sub_errors = list(self._subscriber_errors)
            dropped = self._events_dropped
            releases = list(self._releases)
        alive = [f"reader {s.device}" for s in stats.values() if s.running]
        if self._dispatcher is not None and self._dispatcher.is_alive() \
                and threading.current_thread() is not self._dispatcher:
            alive.append("dispatcher")
        now = time.monotonic_ns()
        return {
            "reason": reason,
            "host_time_ns": now,
            "duration_s": (now - self._t0_ns) * 1e-9 if self._t0_ns else 0.0,
            "devices": {name: dataclasses.asdict(s) for name, s in stats.items()},
            "overflows": sum(s.overflows for s in stats.values()),
            "overflow_samples": sum(s.overflow_samples for s in stats.values()),
            "faults": sum(s.faults for s in stats.values()),
            "events_dropped": dropped,
            "subscriber_errors": {repr(sub): n for sub, n in zip(self._subscribers, sub_errors,
                                                                 strict=True) if n},
            "releases": releases,
            "errors": list(self._errors),
            "threads_alive": alive,
        }


def _describe(driver: Any) -> dict[str, Any]:
    describe = getattr(driver, "describe", None)
    if not callable(describe):
        return {}
    return dict(describe())


def drivers_from_config(config: RigConfig) -> dict[str, tuple[str, Any]]:
    """Build (do not open) every instrument's driver of a rig config, with its engine kind.

    Parameters
    ----------
    config : daq.config.RigConfig
        A rig config whose URLs are real (a simulated rig's ``rig.config``).

    Returns
    -------
    dict
        Instrument name -> (kind, driver), ready for :class:`Acquisition`.
    """
    from daq.instruments import build_driver  # late: imports every driver module

    return {inst.name: (ROLE_KINDS[inst.role], build_driver(inst, config.limits))
            for inst in config.instruments}
