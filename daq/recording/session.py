"""One engine across several run files: a campaign's speeds recorded without restarting it.

Responsibility: :class:`RecordingSession` opens a rig's instruments once (the scanner zeroed
wind-off first if asked), starts one :class:`~daq.acquisition.engine.Acquisition` and its
trigger pulses, and records run files on request under it (:meth:`RecordingSession.record`,
each file through :class:`~daq.recording.file_switch.FileRecording`: the same writer and layout
as :func:`~daq.recording.run.record_run`). Why: a new engine's clock maps take
:data:`~daq.recording.devices.CLOCK_SETTLE_S` to settle, and a campaign that started one per
wind speed kept the wind on for that long at every speed, waiting. Here each new file's writer
is fed the last ``CLOCK_SETTLE_S`` of blocks and trigger pulses (their raw samples precede the
file's time 0, so each file holds what its clock fit rests on), and the wait is paid once, at
the engine's start (:meth:`RecordingSession.clock_wait_s`).

Not responsible for: the fan and the release (the caller's actions, through the engine's
commands), starting simulators, or the file's content (:mod:`daq.recording.writer`).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

from daq.acquisition.dispatch import Subscriber
from daq.acquisition.drivers import drivers_from_config
from daq.acquisition.engine import Acquisition
from daq.acquisition.sync_pulses import SYNC_PULSE_INTERVAL_S, SyncPulses, start_sync_pulses
from daq.config import RigConfig
from daq.recording.devices import CLOCK_SETTLE_S
from daq.recording.experiment_log import ExperimentLog, experiment_log_path, refuse_logging_to
from daq.recording.file_switch import RECORDING_TIMEOUT_S, FileRecording
from daq.recording.layout import metadata_name_part
from daq.recording.run import open_run_file, recording_bar
from daq.recording.writer import RunWriter

__all__ = ["RecordingSession"]

log = logging.getLogger(__name__)


class RecordingSession:
    """A rig acquired by one engine, recorded into run files on request (module docstring).

    Use as a context manager: entering opens the instruments and starts the engine, leaving
    finishes a file still recording and stops the engine (the fan and the model are the
    caller's: it stops and catches them first).

    Parameters
    ----------
    config : RigConfig
        The rig; its URLs must be real (a simulated rig's are filled in by whoever started it).
    calz : bool
        Zero the scanner (CALZ) before the engine starts; this asserts that the wind is off
        (the driver is told 0 m/s). The first file records it in its metadata.
    subscribers : sequence of callable
        Further ``(name, doc)`` subscribers of the engine, for the whole session (a campaign's
        decay monitor).
    sync_pulse_interval_s : float or None
        Pulse the PLC's trigger line this often, s (None: never): the clock maps' anchors.
    """

    def __init__(self, config: RigConfig, *, calz: bool = False,
                 subscribers: Sequence[Subscriber] = (),
                 sync_pulse_interval_s: float | None = SYNC_PULSE_INTERVAL_S) -> None:
        self.config = config
        self.calz = calz
        self.subscribers = list(subscribers)
        self.sync_pulse_interval_s = sync_pulse_interval_s
        self.files = FileRecording(preroll_s=CLOCK_SETTLE_S)
        self.acq: Acquisition | None = None
        #: Host ``time.monotonic()`` of the engine's start, s.
        self.started_at = 0.0
        self._pulser: SyncPulses | None = None
        self._calz_metadata: dict[str, dict[str, float]] = {}

    def __enter__(self) -> RecordingSession:
        drivers = drivers_from_config(self.config)
        if self.calz:
            for name, (kind, driver) in drivers.items():
                if kind == "scanner":
                    driver.open()  # idempotent: the engine's open() keeps this connection
                    calz_s = driver.calz(wind_speed_now=0.0)
                    self._calz_metadata[f"calz_{metadata_name_part(name)}_start"] = {
                        "calz_s": float(calz_s), "wind_speed_now": 0.0}
        self.acq = Acquisition(drivers, subscribers=[self.files.feed, *self.subscribers],
                               metadata={"rig": self.config.name})
        self.acq.start()
        self.started_at = time.monotonic()
        self._pulser = start_sync_pulses(self.acq, drivers, self.sync_pulse_interval_s)
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        try:
            if self._pulser is not None:
                self._pulser.stop()
        finally:
            if self.acq is not None and self.acq.running:
                # A file still recording is finished by the engine's stop (FileRecording).
                self.acq.stop("session ended" if kind is None
                              else f"session ended: {kind.__name__}")

    def clock_wait_s(self) -> float:
        """Return how long the engine must still run before its clock maps have settled, s."""
        return max(0.0, CLOCK_SETTLE_S - (time.monotonic() - self.started_at))

    def record(self, path: str | Path, *, actions: Callable[[Acquisition], None],
               until: threading.Event, duration_s: float, operator_notes: str = "",
               writer_options: Mapping[str, Any] | None = None,
               progress: bool = False) -> tuple[str, dict[str, Any]]:
        """Record one run file while ``actions`` runs; return why it ended and the summary.

        Parameters
        ----------
        path : str or Path
            The run file to create (an existing one is refused before anything starts).
        actions : callable
            ``actions(acquisition)``, run in its own thread once the file records: the fan and
            release steps, through the engine's commands (events of this file).
        until : threading.Event
            Set by the actions when they are done: the file ends then.
        duration_s : float
            The file ends after this long at the latest, s (a bound on the actions).
        operator_notes : str
            Stored with the run.
        writer_options : mapping, optional
            Further keyword arguments of :class:`~daq.recording.writer.RunWriter` (a simulated
            rig's ``clock_truth``); their ``recorder_options`` apply to the file.
        progress : bool
            Show a progress bar over ``duration_s`` (tqdm, on stderr).

        Returns
        -------
        (str, dict)
            ``"done"`` (``until`` set), ``"duration"`` or ``"interrupted"`` (Ctrl-C in this
            thread: the file is finished all the same), and the writer's summary.

        Raises
        ------
        StorageError, RecordingError
            The file could not be created or started (nothing is left of it), or writing it
            failed.
        BaseException
            Whatever the actions raised, after the file is finished.
        """
        acq = self.acq
        if acq is None or not acq.running:
            raise RuntimeError("RecordingSession.record: the session is not running")
        path = Path(path)
        refuse_logging_to(experiment_log_path(path))
        recorder = open_run_file(self.config, path, operator_notes=operator_notes,
                                 writer_options=writer_options)
        try:
            writer = RunWriter(path, self.config, operator_notes=operator_notes,
                               **dict(writer_options or {}))
            writer.recorder = recorder  # opened above; declared and started by the dispatcher
            for name, entry in self._calz_metadata.items():  # the session's CALZ: first file
                recorder.add_metadata(name, entry)
            recorder.event_sink = ExperimentLog(
                experiment_log_path(path), [i.name for i in self.config.instruments],
                lambda: writer.t0_ns, run_file=path.name)
            self.files.start(writer, operator_notes, RECORDING_TIMEOUT_S)
        except BaseException:
            # Not started: the dispatcher holds no reference to the file, nothing is in it.
            recorder.close()
            path.unlink(missing_ok=True)
            experiment_log_path(path).unlink(missing_ok=True)
            raise
        self._calz_metadata = {}
        acq.mark("recording_started", f"recording {path.name}")
        errors: list[BaseException] = []

        def run_actions() -> None:
            try:
                actions(acq)
            except BaseException as exc:  # re-raised in the caller's thread below
                log.exception("the actions callback failed")
                errors.append(exc)

        runner = threading.Thread(target=run_actions, name="windrig-actions", daemon=True)
        runner.start()
        reason = "duration"
        bar = recording_bar(path, duration_s) if progress else None
        try:
            start = time.monotonic()
            end = start + float(duration_s)
            while time.monotonic() < end and not until.is_set() and runner.is_alive():
                rec = self.files.recording
                if rec is not None and rec.error is not None:
                    break  # the file failed (e.g. a full disk): raised by the stop below
                until.wait(0.05)
                if bar is not None:
                    bar.update(round(min(time.monotonic() - start, duration_s), 1) - bar.n)
            reason = "done" if until.is_set() else reason
        except KeyboardInterrupt:  # Ctrl-C: the actions catch the model; the file is finished
            log.warning("interrupted: stopping the recording of %s", path.name)
            reason = "interrupted"
        finally:
            if bar is not None:
                if until.is_set():  # done before the bound: the bar ends full
                    bar.total = bar.n
                bar.close()
            runner.join(max(1.0, 0.25 * float(duration_s)))
            if acq.running:
                acq.mark("recording_stopped", f"recording {path.name} stopped ({reason})")
            summary = self.files.stop(reason, RECORDING_TIMEOUT_S)
        if errors:
            raise errors[0]
        return reason, summary
