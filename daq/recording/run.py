"""``windrig acquire``'s recorder: a rig acquired through the engine into one run file.

Responsibility: :func:`record_run` runs the instruments of a rig config whose URLs are real
(real instruments, or simulators someone else started) through the acquisition engine into one
HDF5 run file, with a :class:`~daq.recording.writer.RunWriter` as the engine's subscriber: the
run file is created first (:func:`open_run_file`: a missing or read-only directory, an existing
file or a full disk fail before anything starts), the scanner is optionally zeroed (CALZ) before
the engine starts, the PLC's trigger line is pulsed every 0.5 s as clock anchors
(:mod:`daq.acquisition.sync_pulses`), and an ``actions`` callback may script fan and release
sequences (through the engine's commands, so each is an event of the run) in its own thread.

Not responsible for: starting simulators or checking a run against their truth (the caller does:
:mod:`daq.sim.recording` starts the simulated rig, passes its URLs in, and checks the result),
the writer's numerics (:mod:`daq.recording.writer`), or the file layout
(:mod:`daq.recording.layout`).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from tqdm import tqdm

from daq.acquisition.device_check import require_devices_ok
from daq.acquisition.dispatch import Subscriber
from daq.acquisition.drivers import drivers_from_config
from daq.acquisition.engine import Acquisition
from daq.acquisition.sync_pulses import SYNC_PULSE_INTERVAL_S, SyncPulses, start_sync_pulses
from daq.config import RigConfig
from daq.recording.experiment_log import (
    ExperimentLog,
    experiment_log_path,
    refuse_logging_to,
)
from daq.recording.layout import metadata_name_part
from daq.recording.recorder import RunRecorder
from daq.recording.swmr_file import refuse_existing_run_file
from daq.recording.writer import RunWriter

__all__ = ["open_run_file", "record_run", "recording_bar"]

log = logging.getLogger(__name__)


def open_run_file(config: RigConfig, out_path: str | Path, *, operator_notes: str = "",
                  writer_options: Mapping[str, Any] | None = None) -> RunRecorder:
    """Create a run's file now and return its recorder, opened (streams not declared yet).

    The checks a run needs before anything starts: an existing file (refused unless
    ``writer_options["recorder_options"]["overwrite"]``), a missing or read-only directory,
    too little free space (:class:`~daq.errors.StorageError`).

    Parameters
    ----------
    config : RigConfig
        Its text and name are stored with the run.
    out_path : str or Path
        The run file to create.
    operator_notes : str
        Stored with the run.
    writer_options : mapping, optional
        The ``RunWriter`` options of the run; their ``recorder_options`` apply here.
    """
    path = Path(out_path)
    recorder_options = dict(dict(writer_options or {}).get("recorder_options", {}))
    if not bool(recorder_options.get("overwrite", False)):
        refuse_existing_run_file(path)
    recorder = RunRecorder(path, config_text=config.text, rig_name=config.name,
                           operator_notes=operator_notes, sway=config.section.n_dof == 3,
                           **recorder_options)
    recorder.open()  # a missing or read-only directory, a full disk: fail before anything starts
    return recorder


def recording_bar(path: Path, duration_s: float) -> tqdm:
    """Return a progress bar over a recording of at most ``duration_s`` s (``update`` in s)."""
    # mininterval: redrawn at most twice a second (a log file gets a line per redraw).
    return tqdm(total=round(float(duration_s), 1), unit="s", mininterval=0.5,
                desc=f"recording {path.name}",
                bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} s [{elapsed}<{remaining}]")


def record_run(config: RigConfig, out_path: str | Path, *, duration_s: float,
               actions: Callable[[Acquisition], None] | None = None, progress: bool = True,
               operator_notes: str = "", calz: bool = False,
               writer_options: Mapping[str, Any] | None = None,
               sync_pulse_interval_s: float | None = SYNC_PULSE_INTERVAL_S,
               recorder: RunRecorder | None = None,
               subscribers: Sequence[Subscriber] = (),
               until: threading.Event | None = None, check: bool = False,
               experiment_log: bool = True) -> dict[str, Any]:
    """Acquire a rig for ``duration_s`` into one HDF5 run file and return the summary.

    Parameters
    ----------
    config : RigConfig
        The rig; its URLs must be real (an ``"auto"`` URL is a
        :class:`~daq.errors.ConfigError`): a simulated rig's are filled in by whoever started
        its simulators (:func:`daq.sim.recording.record_simulated_run`).
    out_path : str or Path
        The run file to create.
    duration_s : float
        Length of the run, s (> 0), from the engine's start.
    actions : callable, optional
        ``actions(acquisition)`` called in its own thread once the engine runs: scripted fan
        and release sequences. It should finish within ``duration_s``; it is joined before the
        engine stops, and an exception in it is raised after the file is closed.
    progress : bool
        Show a tqdm progress bar over the duration.
    operator_notes : str
        Stored with the run.
    calz : bool
        Zero the scanner (CALZ) before the engine starts. With a real rig, ``calz=True`` asserts
        that the wind is off (the driver refuses a CALZ with a nonzero wind speed; it is told
        0 m/s).
    writer_options : mapping, optional
        Further keyword arguments of :class:`~daq.recording.writer.RunWriter`.
    sync_pulse_interval_s : float or None
        Pulse the PLC's trigger line this often during the run, s (None: never): the anchors
        that tie every device clock to the host's (see
        :class:`~daq.sync.clock_map.ClockMap`). Needs a PLC; a failed pulse is logged and the
        run goes on.
    recorder : RunRecorder, optional
        The run file, already opened by :func:`open_run_file` (a caller that must start
        something between the checks and the run); default: opened here.
    subscribers : sequence of callable, optional
        Further ``(name, doc)`` subscribers of the engine, after the writer (a campaign's live
        decay monitor, :mod:`daq.campaign.monitor`).
    until : threading.Event, optional
        End the run early when it is set (a campaign sets it once its actions are done, so
        that a run lasts as long as its releases and not as long as a worst-case estimate).
    check : bool
        Check every device first (:func:`~daq.acquisition.device_check.require_devices_ok`):
        a failing device raises :class:`~daq.errors.DeviceCheckError` naming every failing
        one, and nothing is recorded (no file left). The check's notes become ``"warning"``
        events of the run.
    experiment_log : bool
        Keep the run's events as text next to the file too (``RUN.events.log``,
        :mod:`daq.recording.experiment_log`).

    Returns
    -------
    dict
        The writer's summary (``samples``, ``gaps``, ``overflow_samples`` per device,
        ``clock_fits``, ``sync_rows``, ``releases``, ...) plus the engine's ``errors``.
    """
    if not (isinstance(duration_s, (int, float)) and math.isfinite(duration_s)
            and duration_s > 0):
        raise ValueError(f"duration_s must be a number > 0 s, got {duration_s!r}")
    path = Path(out_path)
    if recorder is None:
        recorder = open_run_file(config, path, operator_notes=operator_notes,
                                 writer_options=writer_options)
    action_error: list[BaseException] = []
    try:
        writer = RunWriter(out_path, config, operator_notes=operator_notes,
                           **dict(writer_options or {}))
        writer.recorder = recorder  # opened above; declared and started at the "start" doc
        checked = require_devices_ok(config) if check else []
        if experiment_log:
            refuse_logging_to(experiment_log_path(path))
            recorder.event_sink = ExperimentLog(
                experiment_log_path(path), [i.name for i in config.instruments],
                lambda: writer.t0_ns, run_file=path.name)
        drivers = drivers_from_config(config)
        if calz:
            for name, (kind, driver) in drivers.items():
                if kind == "scanner":
                    driver.open()  # idempotent: the engine's open() keeps this connection
                    calz_s = driver.calz(wind_speed_now=0.0)
                    # The file says that its pressures start zeroed (the offsets themselves
                    # are the scanner's: it reports none).
                    recorder.add_metadata(f"calz_{metadata_name_part(name)}_start",
                                          {"calz_s": float(calz_s), "wind_speed_now": 0.0})
        acq = Acquisition(drivers, subscribers=[writer, *subscribers],
                          metadata={"rig": config.name})
        acq.start()
        acq.mark("recording_started", f"recording {path.name}: {duration_s:g} s")
        for result in checked:  # what the check noted, in the run's record
            for note in result.notes:
                acq.mark("warning", f"check: {note}", result.device)
        reason = "duration"
        runner: threading.Thread | None = None
        pulser: SyncPulses | None = None
        try:
            if actions is not None:
                def run_actions() -> None:
                    try:
                        actions(acq)
                    except BaseException as exc:  # re-raised in the caller's thread below
                        log.exception("the actions callback failed")
                        action_error.append(exc)

                runner = threading.Thread(target=run_actions, name="windrig-actions",
                                          daemon=True)
                runner.start()
            pulser = start_sync_pulses(acq, drivers, sync_pulse_interval_s)
            end = time.monotonic() + float(duration_s)
            bar = recording_bar(path, duration_s) if progress else None
            try:
                while ((left := end - time.monotonic()) > 0 and writer.error is None
                       and not (until is not None and until.is_set())):
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
            if acq.running:
                acq.mark("recording_stopped", f"recording {path.name} stopped ({reason})")
            engine = acq.stop(reason)
    finally:
        if recorder.state == "declaring":  # the engine never started: no run, no file
            recorder.close()
            path.unlink(missing_ok=True)
            if experiment_log:
                experiment_log_path(path).unlink(missing_ok=True)
    if writer.error is not None:
        raise writer.error
    if action_error:
        raise action_error[0]
    summary = dict(writer.summary or {})
    summary["sync_pulses_failed"] = 0 if pulser is None else pulser.failures
    summary["errors"] = list(engine.get("errors", []))
    summary["subscriber_errors"] = dict(engine.get("subscriber_errors", {}))
    return summary
