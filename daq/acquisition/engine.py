"""The acquisition engine: a reader thread per instrument, a dispatcher, (name, doc) subscribers.

Responsibility: open and start the instruments of a rig, read every one of them in its own
blocking reader thread (:class:`~daq.acquisition.reader.DeviceReader`: the scanner and the
lasers streaming, the barometer, the fan drive and the PLC polled, every driver by ``read()``),
turn what each driver returns into one uniform record
(:class:`~daq.acquisition.records.StreamBlock`), pass the records through bounded per-device
queues to one dispatcher thread (:class:`~daq.acquisition.dispatch.Dispatcher`), and hand them
to subscribers as bluesky-style ``(name, doc)`` calls: ``"start"`` (metadata), ``"block"`` (a
:class:`~daq.acquisition.records.StreamBlock`), ``"event"`` (an
:class:`~daq.acquisition.records.Event`: operator markers and commands, releases, faults,
overflows) and ``"stop"`` (a summary). Every operator command (the PLC's arm, disarm, release
and trigger, the fan's speed reference, start and stop, the scanner's CALZ, markers) passes
through the engine, so that each is recorded as an event with its host time
(:mod:`daq.acquisition.commands`, :mod:`daq.acquisition.calz`). Every subscriber call happens
on the dispatcher thread, so a subscriber needs no locking of its own.

Not responsible for: the device protocols (the drivers), the reading of one device itself (reads,
faults and recovery, the bounded queue: :mod:`daq.acquisition.reader`), the records' types
(:mod:`daq.acquisition.records`), mapping device clocks onto the host clock
(:mod:`daq.sync`), writing files (:mod:`daq.recording`), or plotting (the console, which
polls a ring buffer fed by a subscriber). The acquisition threads never touch h5py or Qt.

Design choices:

- **Full queue: drop the oldest block, mark the gap** and **faults: report, back off, recover**
  are the readers' choices, described where they are made: :mod:`daq.acquisition.reader`. The
  dispatcher does its part of the first: it marks the gap on the next block delivered and
  posts the ``"overflow"`` event before it.
- **Stop is cooperative.** :meth:`Acquisition.stop` stops the scan, sets each reader's
  ``threading.Event`` (polled readers wait on it; streaming reads use a short timeout), joins the
  readers within ``join_timeout_s``, closes the drivers (which also unblocks a reader stuck in a
  read), then lets the dispatcher drain what is queued and deliver ``"stop"``.

Longer than 600 lines: the engine is one class whose operator commands (PLC, manual releases,
fan, CALZ, markers) are thin methods that must live on it, each with its contract documented;
their work is in :mod:`daq.acquisition.commands` and :mod:`daq.acquisition.calz`.
"""

from __future__ import annotations

import dataclasses
import datetime
import logging
import math
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Mapping
from types import TracebackType
from typing import Any

from daq.acquisition import commands
from daq.acquisition.calz import CalzResult, refuse_unsafe_calz, run_calz
from daq.acquisition.dispatch import Dispatcher, Subscriber
from daq.acquisition.fan_watch import FanWatch
from daq.acquisition.reader import DeviceReader
from daq.acquisition.records import DeviceStats, Event
from daq.errors import DaqError

__all__ = ["Acquisition"]

log = logging.getLogger(__name__)


class Acquisition:
    """Run a rig's instruments: reader threads, a dispatcher, and ``(name, doc)`` subscribers.

    Parameters
    ----------
    drivers : mapping of str to (kind, driver)
        Instrument name -> (one of :data:`~daq.acquisition.records.KINDS`, driver object).
        Drivers are opened by :meth:`start` and closed by :meth:`stop`. See
        :func:`daq.acquisition.drivers.drivers_from_config`.
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
        self._dispatch = Dispatcher(control_queue_size)
        self._readers: dict[str, DeviceReader] = {}
        for name, pair in drivers.items():
            if not (isinstance(pair, (tuple, list)) and len(pair) == 2):
                raise TypeError(f"drivers[{name!r}] must be a (kind, driver) tuple, got {pair!r}")
            kind, driver = pair
            self._readers[name] = DeviceReader(
                name, kind, driver, queue_size=queue_size, on_event=self._post_event,
                doorbell=self._dispatch.doorbell, poll_interval_s=polls.get(name),
                read_timeout_s=read_timeout_s, stall_s=stall_s, backoff_min_s=backoff_min_s,
                backoff_max_s=backoff_max_s)
        self._state = "idle"  # idle -> starting -> running -> stopping -> stopped (or failed)
        self._state_lock = threading.Lock()
        for fan, r in self._readers.items():  # first of all: fan_reached
            if r.kind == "fan":
                ramp = getattr(getattr(r.driver, "settings", None), "ramp_rpm_per_s", None)
                self._dispatch.subscribe(FanWatch(fan, self._post_event, ramp))
        for sub in subscribers:
            self.subscribe(sub)
        self._metadata = dict(metadata or {})
        self._queue_size = queue_size
        self._join_timeout_s = float(join_timeout_s)
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
        self._dispatch.subscribe(subscriber)

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
        self._dispatch.post("start", {
            "uid": uuid.uuid4().hex,
            "time": datetime.datetime.now(datetime.UTC).isoformat(),
            "host_time_ns": self._t0_ns,
            "devices": {name: {"kind": r.kind, "describe": _describe(r.driver)}
                        for name, r in self._readers.items()},
            "queue_size": self._queue_size,
            "metadata": self._metadata,
        })
        self._dispatch.start(self._readers.values(), self._final_summary)
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
            stopping, and every device whose reader a driver's bug stopped), ``threads_alive``
            (threads that did not finish: should be empty).
        """
        if self._dispatch.on_own_thread():
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
        if "failed" not in self._stop_done:
            # A reader stopped by a driver's bug read nothing more for the rest of the run: a
            # fault event says when, and the summary's errors say it at the end too (``windrig
            # acquire`` prints them and exits 1), rather than a run that ends as if complete.
            for reader in readers:
                if reader.failed is not None:
                    self._errors.append(f"{reader.name}: read no more after its driver failed: "
                                        f"{_one_line(reader.failed)}")
            self._stop_done.add("failed")
        if not self._dispatch.finish(self._join_timeout_s):
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

    # -- operator commands (each recorded as an event: daq.acquisition.commands) ----------------
    def mark(self, kind: str, text: str = "", device: str | None = None) -> Event:
        """Record a marker (``"note"``, ``"warning"``, ``"recording_started"``, ...) of a device.

        Raises
        ------
        ValueError
            ``kind`` is empty or one the engine reserves (:data:`SYSTEM_EVENT_KINDS`).
        RuntimeError
            The engine is not running (the marker would be recorded nowhere).
        """
        event = commands.marker(kind, text, device)
        self._require_running(f"mark({kind!r})")
        self._post_event(event)
        return event

    def release(self, plc: str | None = None) -> Event:
        """Release the model through the PLC and record a ``"release"`` event; return it.

        The event's ``host_time_ns`` is when the PLC acknowledged the RELEASE coil write
        (``ReleaseTiming.command_ns``); ``data`` holds ``requested_ns`` (before the command),
        ``command_ns``, ``confirmed_ns`` (RELEASED read set), ``delay_s`` and ``round_trip_s``
        (the write's: the release came within it).

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
        name, driver = self._device(plc, "plc", "release")
        event = commands.release(name, driver, self._post_event)
        with self._counts_lock:
            self._releases.append(event)
        return event

    def manual_release(self, text: str = "") -> Event:
        """Record that the operator let the model go by hand: a ``"manual_release"`` event.

        The run writer finds the release instant before it in the lasers' signals. Raises
        RuntimeError when the engine is not running (the release must be recorded).
        """
        self._require_running("manual_release()")
        event = commands.manual_release(self._post_event, text)
        with self._counts_lock:
            self._releases.append(event)
        return event

    def manual_hold(self, text: str = "") -> Event:
        """Record that the operator caught and holds the model: a ``"manual_hold"`` event."""
        self._require_running("manual_hold()")
        return commands.manual_hold(self._post_event, text)

    def arm(self, plc: str | None = None) -> Event:
        """Arm the PLC (magnet on, one release permitted) and record an ``"arm"`` event.

        The event's ``host_time_ns`` is when the command was requested: arming catches a
        decaying model, and the decay is certainly free before that instant (the magnet acts
        somewhere between the request and the acknowledgement, ``data["acknowledged_ns"]``).
        A failure is recorded as an ``"arm_failed"`` event, then raised.
        """
        name, driver = self._device(plc, "plc", "arm")
        return commands.arm(name, driver, self._post_event)

    def disarm(self, plc: str | None = None) -> Event:
        """Disarm the PLC (magnet off, no release permitted) and record a ``"disarm"`` event."""
        name, driver = self._device(plc, "plc", "disarm")
        return commands.disarm(name, driver, self._post_event)

    def trigger(self, plc: str | None = None) -> Event:
        """Pulse the trigger line and record a ``"trigger"`` event at the rising edge's time."""
        name, driver = self._device(plc, "plc", "trigger_pulse")
        return commands.trigger(name, driver, self._post_event)

    def set_fan_speed(self, rpm: float, fan: str | None = None) -> Event:
        """Send the fan drive its speed reference and record a ``"fan_speed"`` event.

        Parameters
        ----------
        rpm : float
            The speed reference, rpm; the driver refuses one outside [0, ``max_fan_rpm``].
        fan : str, optional
            Name of the fan drive; default: the only device of kind ``"fan"``.

        Raises
        ------
        SafetyError, DeviceError, TransportError
            From the driver (a speed beyond the rig's limit, a refused write, the link); a
            ``"fan_failed"`` event is recorded first.
        RuntimeError
            The engine is not running.
        """
        name, driver = self._device(fan, "fan", "set_speed")
        return commands.set_fan_speed(name, driver, float(rpm), self._post_event)

    def start_fan(self, fan: str | None = None) -> Event:
        """Run the fan at its speed reference and record a ``"fan_start"`` event.

        Raises as :meth:`set_fan_speed` (``"fan_failed"`` recorded first).
        """
        name, driver = self._device(fan, "fan", "start")
        return commands.start_fan(name, driver, self._post_event)

    def stop_fan(self, fan: str | None = None) -> Event:
        """Stop the fan (ramp stop) and record a ``"fan_stop"`` event.

        Unlike the other commands this one is sent whatever the engine's state (a stop must
        never be refused); it is recorded only while the engine runs.
        """
        name, driver = self._device(fan, "fan", "stop", running=False)
        return commands.stop_fan(name, driver, self._post_event if self.running else None)

    def calz(self, device: str | None = None, *, wind_speed_now: float,
             timeout_s: float = 30.0) -> CalzResult:
        """Zero the pressure scanner (CALZ) during the run, wind-off; return what it did.

        The scanner refuses every command but STOP while it scans, so the scan is interrupted:
        the scanner's reader is parked between two reads, STOP is sent, the frames still in
        flight are read and delivered, the driver's CALZ runs (its wind-off rule stays in
        force: ``wind_speed_now`` is passed through), a new scan is started and the reader
        resumed. The interruption is marked, never silent: the scanner stream gets a gap over
        the pause (its length in frames where the frame times are absolute, else -1; see
        ``daq.instruments.scanivalve_mps4264.continuity``), so the sync view has NaN pressures
        and forces there, and a ``"calz"`` event (at ``stop_ns``) carries the pause and the
        zero-offset summary.

        Parameters
        ----------
        device : str, optional
            The scanner's name; default: the only device of kind ``"scanner"``.
        wind_speed_now : float
            The wind speed now, m/s, as measured by the caller with the fan stopped. The driver
            refuses anything but 0
            (:meth:`~daq.instruments.scanivalve_mps4264.driver.ScanivalveMps4264.
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
        name, _ = self._device(device, "scanner", "calz")
        reader = self._readers[name]
        if not self._calz_lock.acquire(blocking=False):
            raise RuntimeError(f"calz({name!r}): a CALZ is already in progress; wait for it")
        try:
            # Checked again under the lock: stop() waits for this lock once it is "stopping".
            self._require_running(f"calz({name!r})")
            if not reader.alive:
                raise RuntimeError(f"calz({name!r}): the scanner's reader has stopped "
                                   f"({reader.failed!r}); restart the acquisition")
            refuse_unsafe_calz(name, reader.driver, wind_speed_now, self._post_event)
            return run_calz(name, reader, float(wind_speed_now), float(timeout_s),
                            join_timeout_s=self._join_timeout_s, post_event=self._post_event)
        finally:
            self._calz_lock.release()

    def _device(self, name: str | None, kind: str, method: str, *,
                running: bool = True) -> tuple[str, Any]:
        """Return the device of ``kind`` called ``name`` (or the only one) and its driver."""
        if running:
            self._require_running(f"{method}()")
        names = [n for n, r in self._readers.items() if r.kind == kind]
        label = "PLC" if kind == "plc" else kind
        if name is None:
            if len(names) != 1:
                raise ValueError(f"name the {label}: devices of kind {kind!r} are {names}")
            name = names[0]
        elif name not in names:
            raise ValueError(f"{name!r} is not a device of kind {kind!r}; those are {names}")
        driver = self._readers[name].driver
        if not callable(getattr(driver, method, None)):
            raise TypeError(f"{label} {name!r} driver {type(driver).__name__} has no {method}()")
        return name, driver

    def _require_running(self, what: str) -> None:
        if self._state != "running":
            raise RuntimeError(f"{what}: the acquisition is {self._state}, not running")

    # -- helpers -----------------------------------------------------------------------------------
    def _cleanup(self, step: Callable[[], None], what: str) -> None:
        """Run one clean-up step; a failure is logged and kept for the summary, never raised."""
        try:
            step()
        except Exception as exc:  # the remaining steps must still run; reported in "errors"
            log.error("%s failed: %s: %s", what, type(exc).__name__, exc)
            self._errors.append(f"{what}: {type(exc).__name__}: {exc}")

    def _post_event(self, event: Event) -> None:
        self._dispatch.post_event(event)

    def _final_summary(self) -> dict[str, Any]:
        """Build and keep the ``"stop"`` summary (called by the dispatcher as it ends)."""
        self._summary = self._build_summary(self._reason)
        return self._summary

    def _build_summary(self, reason: str) -> dict[str, Any]:
        stats = self.stats()
        with self._counts_lock:
            releases = list(self._releases)
        alive = [f"reader {s.device}" for s in stats.values() if s.running]
        if self._dispatch.alive_elsewhere():
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
            "events_dropped": self._dispatch.events_dropped,
            "subscriber_errors": self._dispatch.subscriber_errors(),
            "releases": releases,
            "errors": list(self._errors),
            "threads_alive": alive,
        }


def _one_line(exc: BaseException) -> str:
    """Say an exception in one line: a windrig error's message, else its type and message."""
    text = " ".join(str(exc).split())
    return text if isinstance(exc, DaqError) and text else f"{type(exc).__name__}: {text}"


def _describe(driver: Any) -> dict[str, Any]:
    describe = getattr(driver, "describe", None)
    if not callable(describe):
        return {}
    return dict(describe())


