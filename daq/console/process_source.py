"""The live console's acquisition in a process of its own.

Responsibility: :class:`ProcessLiveSource` is the console's live data source (the same interface as
:class:`~daq.console.live_source.LiveSource`: rows, status, health, decays, events, operator
commands through ``acq``, recordings) whose :class:`~daq.console.live_source.LiveSource` (the rig,
the drivers, the acquisition engine, the sync view, the recordings) runs in a child process started
with ``spawn``. The child appends the synchronised rows to a
:class:`~daq.console.shared_ring.SharedRingBuffer` that this process created, and this process reads
them as any :class:`~daq.console.source.RingSource`: no row is pickled. Everything else crosses one
:func:`multiprocessing.Pipe` as small numbered requests:

- ``state``: running, error, status line, fan speed, PLC ARM state, recording, decays and the
  device health, in one answer. :meth:`ProcessLiveSource.poll` (the GUI timer) asks for the
  next one and returns at once; the properties read the last answer, so the GUI thread never
  waits on the child.
- The operator's commands and the recordings (the engine's ``arm``, ``disarm``, ``release``,
  ``calz``, ``mark``, ``set_fan_speed``, ``start_fan``, ``stop_fan``; a fan's
  ``set_speed``/``start``/``stop`` and a PLC's ``disarm``, run as those engine commands;
  ``start_recording``, ``stop_recording``): the caller waits for the answer; the child runs
  each on a thread of its own, so that stopping the fan is not queued behind a CALZ.
  :data:`ENGINE_COMMANDS` and :data:`DRIVER_COMMANDS` list the only commands that cross;
  nothing else can be called in the child, and every command is recorded by the engine.
- ``events``, and ``close``.

A command's exception is raised in the caller as it was raised in the child (the same type and
message; :class:`RemoteError` when it cannot be pickled).

Why a process: on two cores the acquisition threads (readers, dispatcher, sync view) held the
interpreter lock against the GUI thread in one process: measured, the GUI thread waited for the
lock 22 % of the time and drew 6.7 frames/s with 511 taps (``benchmarks/console_frame_rate.py``).

Longer than 600 lines: the parent's source and the child's server are the two ends of one
protocol (requests, answers, the shared ring, the child's end and a lock it may die holding);
split, each half would have to be read with the other open beside it.

Not responsible for: acquisition, recording and health themselves (:mod:`daq.console.live_source`,
run unchanged in the child), or drawing (:mod:`daq.console.window`).
"""

from __future__ import annotations

import concurrent.futures
import itertools
import logging
import multiprocessing
import multiprocessing.util
import pickle
import signal
import threading
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy.typing as npt

from daq.config import RigConfig, parse_rig_config
from daq.console.live_source import LiveSource, check_live_options, ring_rows
from daq.console.ring_buffer import RingBuffer
from daq.console.shared_ring import SharedRingBuffer, SharedRingHandle
from daq.console.source import DeviceHealth, RingSource, SourceInfo, sync_columns
from daq.errors import AcquisitionProcessError, RemoteError, RingStalledError
from daq.recording.file_switch import Recording

__all__ = ["DRIVER_COMMANDS", "ProcessLiveSource",]

log = logging.getLogger(__name__)

#: The driver methods a console may call on a device, by driver kind, and the engine command
#: each runs as in the child (the engine records every command as an event of the run).
DRIVER_COMMANDS: dict[str, dict[str, str]] = {
    "fan": {"set_speed": "set_fan_speed", "start": "start_fan", "stop": "stop_fan"},
    "plc": {"disarm": "disarm"},
}
#: The engine methods an operator command may call in the child.
ENGINE_COMMANDS = ("arm", "disarm", "release", "manual_release", "manual_hold", "calz", "mark",
                   "set_fan_speed", "start_fan", "stop_fan")
#: How long the child may take to start the rig, the drivers and the engine, s.
START_TIMEOUT_S = 60.0
#: How long a command waits for its answer, s, unless it says otherwise (a CALZ takes its own
#: ``timeout_s`` plus this).
COMMAND_TIMEOUT_S = 30.0
#: How long closing waits for the child to stop everything and exit, s.
CLOSE_TIMEOUT_S = 30.0


# -- the child ---------------------------------------------------------------------------------
def _portable(exc: BaseException) -> BaseException:
    """Return ``exc`` if it survives pickling, else a :class:`RemoteError` saying what it was."""
    try:
        pickle.loads(pickle.dumps(exc))
    except Exception:  # any exception type whose constructor pickling cannot replay
        return RemoteError(f"{type(exc).__name__}: {exc}")
    return exc


class _Server:
    """The child's side: answers the parent's requests over ``conn`` from one LiveSource."""

    def __init__(self, conn: Any, live: LiveSource) -> None:
        self._conn = conn
        self._live = live
        self._send_lock = threading.Lock()
        self._threads: list[threading.Thread] = []

    def run(self) -> None:
        """Serve until the parent asks to close or goes away (its end of the pipe closed)."""
        while True:
            try:
                number, name, args, kwargs = self._conn.recv()
            except (EOFError, OSError):
                log.warning("the console went away: stopping the acquisition")
                return
            if name == "close":
                self._finish(number)
                return
            if name in ("state", "events"):
                self._answer(number, name, args, kwargs)
            else:  # a command: on its own thread (a CALZ must not hold up a fan stop)
                thread = threading.Thread(target=self._answer, args=(number, name, args, kwargs),
                                          name=f"windrig-command-{name}", daemon=True)
                self._threads = [t for t in self._threads if t.is_alive()] + [thread]
                thread.start()

    def _finish(self, number: int) -> None:
        for thread in self._threads:
            thread.join(COMMAND_TIMEOUT_S)
        try:
            self._live.close()
        except Exception as exc:  # the parent raises it
            self._send((number, "error", _portable(exc)))
        else:
            self._send((number, "ok", None))

    def _answer(self, number: int, name: str, args: tuple[Any, ...],
                kwargs: dict[str, Any]) -> None:
        try:
            result = self._handle(name, args, kwargs)
        except Exception as exc:  # raised again in the caller, in the parent
            self._send((number, "error", _portable(exc)))
        else:
            self._send((number, "ok", result))

    def _send(self, message: tuple[Any, ...]) -> None:
        with self._send_lock:
            try:
                self._conn.send(message)
            except Exception as exc:  # an unpicklable result: the caller gets the reason
                if isinstance(exc, (BrokenPipeError, EOFError)):
                    raise
                self._conn.send((message[0], "error",
                                 RemoteError(f"answer not sendable: {type(exc).__name__}: "
                                             f"{exc}")))

    def _handle(self, name: str, args: tuple[Any, ...], kwargs: dict[str, Any]) -> Any:
        live = self._live
        if name == "state":
            return _state(live)
        if name == "events":
            return live.events(*args, **kwargs)
        if name == "engine":
            method, *rest = args
            if method not in ENGINE_COMMANDS:
                raise PermissionError(f"engine command {method!r} is not allowed from the "
                                      f"console (allowed: {ENGINE_COMMANDS})")
            acq = live.acq
            if acq is None:
                raise AcquisitionProcessError(f"{method}: acquisition not running")
            return getattr(acq, method)(*rest, **kwargs)
        if name == "driver":
            device, method, *rest = args
            acq = live.acq
            if acq is None:
                raise AcquisitionProcessError(f"{device}.{method}: acquisition not running")
            kind, _ = _kind_and_driver(acq, device)
            allowed = DRIVER_COMMANDS.get(kind, {})
            if method not in allowed:
                raise PermissionError(f"{device}.{method} is not allowed from the console "
                                      f"(a {kind}: {tuple(allowed)})")
            # Through the engine, named by its kind ("fan" or "plc"): recorded as an event.
            return getattr(acq, allowed[method])(*rest, **{kind: device}, **kwargs)
        if name == "simulated_hand":  # a simulated rig's operator: releases by hand
            return live.simulated_hand(*args)
        if name == "start_recording":
            return live.start_recording(*args, **kwargs)
        if name == "stop_recording":
            return live.stop_recording(*args, **kwargs)
        raise ValueError(f"unknown request {name!r}")


def _kind_and_driver(acq: Any, device: str) -> tuple[str, Any]:
    """Return a device's engine kind and driver."""
    driver = acq.drivers.get(device)
    if driver is None:
        raise KeyError(f"no device {device!r} in this rig")
    return acq.stats()[device].kind, driver


def _state(live: LiveSource) -> dict[str, Any]:
    """Return what the GUI timer reads of a live source, in one answer."""
    return {"running": live.running, "error": live.error, "status": live.status(),
            "fan_rpm": live.fan_speed_rpm, "plc_armed": live.plc_armed,
            "recording": live.recording, "decays": live.decays(), "health": live.health()}


def _serve(conn: Any, handle: SharedRingHandle, config_text: str, source: str,
           options: dict[str, Any]) -> None:
    """Child process: open the live source over the shared ring and serve the parent."""
    # Ctrl-C in the operator's terminal reaches the whole process group: the console handles
    # it and closes this process in order (the recording finished, the fan stopped), which an
    # interrupt here would pre-empt. The simulated rig's process inherits the setting.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    ring = SharedRingBuffer.attach(handle)
    try:
        live = LiveSource(parse_rig_config(config_text, source), ring=ring, **options)
        try:
            live.open()
        except Exception as exc:  # the parent raises it
            conn.send((0, "error", _portable(exc)))
            return
        acq = live.acq
        kinds = {name: s.kind for name, s in acq.stats().items()}
        conn.send((0, "ok", (live.info, kinds)))
        try:
            _Server(conn, live).run()
        finally:
            live.close()
    finally:
        ring.close()
        conn.close()


# -- the parent --------------------------------------------------------------------------------
class _RemoteDriver:
    """A driver in the acquisition process: only :data:`DRIVER_COMMANDS` of its kind.

    Each command runs as the engine's command for it (e.g. a fan's ``set_speed`` as
    ``set_fan_speed``), so that it is recorded as an event.
    """

    def __init__(self, source: ProcessLiveSource, name: str, kind: str) -> None:
        self._source = source
        self.name = name
        self.kind = kind

    def __getattr__(self, method: str) -> Any:
        allowed = tuple(DRIVER_COMMANDS.get(self.kind, {}))
        if method.startswith("_") or method not in allowed:
            raise AttributeError(f"{self.name}: {method!r} cannot be called from the console "
                                 f"(a {self.kind}: {allowed})")

        def command(*args: Any, **kwargs: Any) -> Any:
            return self._source.call("driver", self.name, method, *args, **kwargs)

        return command


class _RemoteAcquisition:
    """The acquisition engine in the child, as the console's controls use it."""

    def __init__(self, source: ProcessLiveSource, kinds: Mapping[str, str]) -> None:
        self._source = source
        #: The rig's drivers by name (commands of :data:`DRIVER_COMMANDS` only).
        self.drivers = {name: _RemoteDriver(source, name, kind) for name, kind in kinds.items()}

    @property
    def running(self) -> bool:
        """Tell whether the engine runs (as of the last state)."""
        return self._source.running

    def arm(self, plc: str | None = None) -> Any:
        """Arm the PLC (:meth:`daq.acquisition.engine.Acquisition.arm`); return its event."""
        return self._source.call("engine", "arm", plc)

    def release(self, plc: str | None = None) -> Any:
        """Release the model (the engine's ``release``); return its event."""
        return self._source.call("engine", "release", plc)

    def manual_release(self, text: str = "") -> Any:
        """Say the model was let go by hand (the engine's ``manual_release``); its event."""
        return self._source.call("engine", "manual_release", text)

    def manual_hold(self, text: str = "") -> Any:
        """Say the model is held by hand again (the engine's ``manual_hold``); its event."""
        return self._source.call("engine", "manual_hold", text)

    def calz(self, device: str | None = None, *, wind_speed_now: float,
             timeout_s: float = 30.0) -> Any:
        """Zero the scanner (:meth:`daq.acquisition.engine.Acquisition.calz`); return its result."""
        return self._source.call("engine", "calz", device, wind_speed_now=wind_speed_now,
                                 timeout_s=timeout_s, answer_within_s=timeout_s
                                 + COMMAND_TIMEOUT_S)

    def mark(self, kind: str, text: str = "") -> Any:
        """Mark an event (:meth:`daq.acquisition.engine.Acquisition.mark`); return it."""
        return self._source.call("engine", "mark", kind, text)

    def disarm(self, plc: str | None = None) -> Any:
        """Disarm the PLC (:meth:`daq.acquisition.engine.Acquisition.disarm`); return its event."""
        return self._source.call("engine", "disarm", plc)

    def set_fan_speed(self, rpm: float, fan: str | None = None) -> Any:
        """Set the fan's speed reference (the engine's ``set_fan_speed``); return its event."""
        return self._source.call("engine", "set_fan_speed", rpm, fan)

    def start_fan(self, fan: str | None = None) -> Any:
        """Run the fan (:meth:`daq.acquisition.engine.Acquisition.start_fan`); return its event."""
        return self._source.call("engine", "start_fan", fan)

    def stop_fan(self, fan: str | None = None) -> Any:
        """Stop the fan (:meth:`daq.acquisition.engine.Acquisition.stop_fan`); return its event."""
        return self._source.call("engine", "stop_fan", fan)


class ProcessLiveSource(RingSource):
    """A rig acquired live in a child process, as a console data source (module docstring).

    Parameters
    ----------
    config : RigConfig
        The rig (see :class:`~daq.console.live_source.LiveSource`).
    simulate : bool
        Start the simulated rig of the config (in a process of its own, started by the child).
    window_s : float
        Length of the history kept for the views, s, > 0.
    fan_rpm : float, optional
        Start the fan at this speed once the engine runs; stopped again on :meth:`close`.
    sync_pulse_interval_s : float or None
        Pulse the PLC's trigger line this often, s.
    record_dir : str or Path, optional
        Where the console suggests run files; default the current directory.
    start_timeout_s : float
        Longest wait for the child to start everything, s.

    Notes
    -----
    The constructor does no I/O; :meth:`open` starts the child and waits until its engine runs;
    :meth:`close` stops it (idempotent). Recording options are sent to the child, so they must
    pickle (no callables).
    """

    def __init__(self, config: RigConfig, *, simulate: bool = True, window_s: float = 20.0,
                 fan_rpm: float | None = None, sync_pulse_interval_s: float | None = 0.5,
                 record_dir: str | Path | None = None,
                 start_timeout_s: float = START_TIMEOUT_S, check: bool = False) -> None:
        check_live_options(window_s, fan_rpm)  # the child's checks, before it is started
        self.config = config
        self.window_s = float(window_s)
        self.record_dir = Path.cwd() if record_dir is None else Path(record_dir)
        self._options = {"simulate": bool(simulate), "window_s": float(window_s),
                         "fan_rpm": fan_rpm, "sync_pulse_interval_s": sync_pulse_interval_s,
                         "record_dir": self.record_dir, "check": bool(check)}
        self._start_timeout_s = float(start_timeout_s)
        self._ring: RingBuffer | None = None
        self._last_total = 0
        self._info: SourceInfo | None = None
        self._process: Any = None
        self._conn: Any = None
        self._reader: threading.Thread | None = None
        self._send_lock = threading.Lock()
        self._numbers = itertools.count(1)
        self._pending: dict[int, concurrent.futures.Future[Any]] = {}
        self._state: dict[str, Any] = {}
        self._state_asked: concurrent.futures.Future[Any] | None = None
        self._gone: str | None = None  # why the child cannot answer any more
        self._acq: _RemoteAcquisition | None = None
        self._seen_rows = 0
        self._closed = False

    # -- life cycle ------------------------------------------------------------------------------
    def open(self) -> None:
        """Start the child (rig, drivers, engine) and wait until it runs.

        Raises
        ------
        AcquisitionProcessError
            The child did not start within ``start_timeout_s`` or died.
        DaqError, RuntimeError, ...
            The child's own failure to start (raised there, the same type here).
        """
        if self._process is not None or self._closed:
            return
        ctx = multiprocessing.get_context("spawn")  # no fork of a threaded (Qt) parent
        ring = SharedRingBuffer(ring_rows(self.config, self.window_s),
                                *sync_columns(self.config.taps.n_taps,
                                              sway=self.config.section.n_dof == 3))
        self._ring = ring
        conn, child = ctx.Pipe()
        # Not a daemon: the child starts the simulated rig's process itself.
        process = ctx.Process(target=_serve, name="windrig-acquisition",
                              args=(child, ring.handle(), self.config.text, self.config.source,
                                    self._options))
        try:
            process.start()
            child.close()
            self._process, self._conn = process, conn
            # At interpreter exit, multiprocessing joins its non-daemon children: closing the
            # pipe first tells the child to stop (should the console not have closed us).
            multiprocessing.util.Finalize(self, conn.close, exitpriority=10)
            if not conn.poll(self._start_timeout_s):
                raise AcquisitionProcessError(
                    f"the acquisition process did not start within {self._start_timeout_s:g} s")
            try:
                _, kind, payload = conn.recv()
            except (EOFError, OSError) as exc:
                raise AcquisitionProcessError(f"the acquisition process died while starting "
                                              f"(exit code {process.exitcode})") from exc
            if kind == "error":
                raise payload
            info, kinds = payload
            self._info = info
            self._acq = _RemoteAcquisition(self, kinds)
            self._reader = threading.Thread(target=self._read_answers,
                                            name="windrig-acquisition-answers", daemon=True)
            self._reader.start()
            self._state = self.call("state")
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Stop the child's recording, fan (if it started it), engine and rig; end the child.

        Idempotent. The child finishes a recording in progress before it stops.
        """
        self._closed = True
        process, conn = self._process, self._conn
        if process is not None and self._gone is None and self._reader is not None:
            try:
                self.call("close", answer_within_s=CLOSE_TIMEOUT_S)
            except Exception as exc:  # logged: closing goes on (the child is ended below)
                log.error("closing the acquisition process: %s: %s", type(exc).__name__, exc)
        if process is not None:
            process.join(CLOSE_TIMEOUT_S)
            if process.is_alive():
                log.error("the acquisition process did not end; killing it")
                process.kill()
                process.join(5.0)
        # The child's end is closed now: the reader thread sees the end of the pipe and stops
        # (the pipe is closed after it, never under a blocked read).
        if self._reader is not None:
            self._reader.join(5.0)
        if conn is not None:
            conn.close()
        self._acq = None
        ring = self._ring
        if isinstance(ring, SharedRingBuffer):
            # The rows stay readable after close, as a LiveSource's do (a window may still
            # tick once): a copy in this process's memory, then the shared block is removed.
            kept = RingBuffer(ring.capacity_rows, *ring.columns)
            kept.append(ring.snapshot())
            self._ring = None if self._info is None else kept
            ring.close()
            ring.unlink()

    # -- requests --------------------------------------------------------------------------------
    def call(self, name: str, *args: Any, answer_within_s: float = COMMAND_TIMEOUT_S,
             **kwargs: Any) -> Any:
        """Send a request to the child and wait for its answer (see the module docstring).

        Raises
        ------
        AcquisitionProcessError
            The child is gone, or did not answer within ``answer_within_s``.
        Exception
            What the request raised in the child.
        """
        future = self._ask(name, args, kwargs)
        try:
            return future.result(answer_within_s)
        except concurrent.futures.TimeoutError as exc:
            raise AcquisitionProcessError(f"{name}: no answer from the acquisition process "
                                          f"within {answer_within_s:g} s") from exc

    def _ask(self, name: str, args: tuple[Any, ...],
             kwargs: dict[str, Any]) -> concurrent.futures.Future[Any]:
        future: concurrent.futures.Future[Any] = concurrent.futures.Future()
        with self._send_lock:
            if self._gone is not None or self._conn is None:
                raise AcquisitionProcessError(f"{name}: the acquisition process is not running"
                                              + (f" ({self._gone})" if self._gone else ""))
            number = next(self._numbers)
            self._pending[number] = future
            self._conn.send((number, name, args, kwargs))
        return future

    def _read_answers(self) -> None:
        """Hand each answer to the request waiting for it (the reader thread)."""
        conn = self._conn
        try:
            while True:
                number, kind, payload = conn.recv()
                with self._send_lock:
                    future = self._pending.pop(number, None)
                if future is None:
                    continue
                if kind == "error":
                    future.set_exception(payload)
                else:
                    future.set_result(payload)
        except (EOFError, OSError) as exc:
            code = None
            if self._process is not None:
                self._process.join(1.0)  # its pipe closed as it ended: reaped at once
                code = self._process.exitcode
            reason = ("closed" if self._closed
                      else f"acquisition process ended ({type(exc).__name__}, exit code {code})")
            if not self._closed:
                log.error("%s", reason)
            with self._send_lock:
                self._gone = reason
                pending, self._pending = self._pending, {}
            ring = self._ring
            if isinstance(ring, SharedRingBuffer):
                # The writer is gone, perhaps killed holding the ring's lock: its rows no longer
                # change, so they are read unlocked from now on (the GUI froze on that lock).
                ring.abandon_lock()
            for future in pending.values():
                future.set_exception(AcquisitionProcessError(reason))

    # -- the DataSource protocol -----------------------------------------------------------------
    def poll(self) -> int:
        """Ask for the next state (without waiting); return the rows appended since last time."""
        asked = self._state_asked
        if asked is not None and asked.done():
            self._state_asked = None
            if asked.exception() is None:
                self._state = asked.result()
        if self._state_asked is None and self._gone is None and not self._closed:
            try:
                self._state_asked = self._ask("state", (), {})
            except AcquisitionProcessError:
                pass  # ``_gone`` says why: the status line and ``error`` show it
        total = self.total_rows
        new, self._seen_rows = total - self._seen_rows, total
        return new

    @property
    def total_rows(self) -> int:
        """Count rows made available so far (the last count while the ring's lock stalls)."""
        try:
            self._last_total = super().total_rows
        except RingStalledError:
            # The child was killed holding the ring's lock; its reader thread sees the pipe
            # close and abandons the lock, so the next read goes through.
            log.warning("the shared ring's lock stalled; the acquisition process: %s",
                        self._gone or "running")
        return self._last_total

    def snapshot(self, last: int | None = None,
                 columns: Sequence[str] | None = None) -> dict[str, npt.NDArray[Any]]:
        """Return copies of the most recent rows, oldest first (``RingBuffer.snapshot``).

        Raises
        ------
        RingStalledError
            The ring's lock stalled twice (its writer stuck while its process still runs).
        """
        try:
            return super().snapshot(last, columns)
        except RingStalledError:
            return super().snapshot(last, columns)  # abandoned by now if the child died

    def refresh(self) -> None:
        """Read the child's state now (waiting for it), for a caller that cannot poll."""
        self._state = self.call("state")

    @property
    def error(self) -> str | None:
        """Describe the failure that stopped the live view, if any."""
        if self._gone is not None and not self._closed:
            return self._gone
        return self._state.get("error")

    @property
    def running(self) -> bool:
        """Tell whether the engine runs (as of the last state)."""
        return self._gone is None and bool(self._state.get("running"))

    @property
    def acq(self) -> _RemoteAcquisition | None:
        """The engine's commands (``drivers``, ``arm``, ``release``, ``calz``, ``mark``)."""
        return self._acq

    def status(self) -> str:
        """Return the status line (the child's, or why it is gone)."""
        if self._gone is not None and not self._closed:
            return f"error: {self._gone}"
        return str(self._state.get("status", "live: starting"))

    def health(self) -> list[DeviceHealth]:
        """Return every device's health (as of the last state)."""
        return list(self._state.get("health", []))

    @property
    def fan_speed_rpm(self) -> float:
        """Measure the fan speed last read, rpm (NaN before a reading)."""
        return float(self._state.get("fan_rpm", float("nan")))

    @property
    def plc_armed(self) -> tuple[int, bool] | None:
        """The PLC's ARM coil as last read: (host ``monotonic_ns``, armed); None before."""
        return self._state.get("plc_armed")

    def decays(self) -> list[tuple[float, float | None]]:
        """Return the free decays seen so far (as ``LiveSource.decays``)."""
        return list(self._state.get("decays", []))

    def events(self, kind: str | None = None) -> list[Any]:
        """Return the engine's latest events, oldest first (asks the child)."""
        return list(self.call("events", kind))

    def simulated_hand(self, what: str) -> None:
        """Let the simulated model go or hold it by hand (see ``LiveSource.simulated_hand``)."""
        self.call("simulated_hand", what)

    # -- recording -------------------------------------------------------------------------------
    @property
    def recording(self) -> Recording | None:
        """The recording in progress, the last one if it failed, or None (last state)."""
        return self._state.get("recording")

    def start_recording(self, path: str | Path, notes: str = "", *,
                        recorder_options: Mapping[str, Any] | None = None,
                        timeout_s: float = 10.0) -> Path:
        """Start recording to a new run file (:meth:`LiveSource.start_recording`)."""
        try:
            return Path(self.call("start_recording", str(path), notes,
                                  recorder_options=dict(recorder_options or {}),
                                  timeout_s=timeout_s, answer_within_s=timeout_s
                                  + COMMAND_TIMEOUT_S))
        finally:
            self.refresh_if_running()

    def stop_recording(self, *, reason: str = "stopped by the operator",
                       timeout_s: float = 10.0) -> dict[str, Any]:
        """Finish the recording (:meth:`LiveSource.stop_recording`); return its summary."""
        try:
            return dict(self.call("stop_recording", reason=reason, timeout_s=timeout_s,
                                  answer_within_s=timeout_s + COMMAND_TIMEOUT_S))
        finally:
            self.refresh_if_running()

    def refresh_if_running(self) -> None:
        """Read the state now, unless the child is gone (its reason is kept)."""
        if self._gone is None and not self._closed:
            self.refresh()
