"""A run recorded from the simulated rig: simulators up, recorded, checked against their truth.

Responsibility: :func:`record_simulated_run` is ``windrig acquire --simulate``: it creates the
run file (the checks that must fail before anything starts), starts every simulated instrument
of a rig config on loopback, in this process (:func:`daq.sim.rig.start_simulated_rig`: tests
reach into the simulators to inject faults) or in a process of its own
(:mod:`daq.sim.rig_process`, the command line's choice), records
them with the production recorder (:func:`daq.recording.run.record_run`, given the simulators'
URLs), zeroes the scanner first (the simulated tunnel starts wind-off), stops the simulators,
and measures the file's synchronised view against the simulators' truth
(:func:`daq.sim.sync_check.check_run`: the clock error of every block, the delay of every
channel), which it stores in the file and returns as the summary's ``alignment``.

Not responsible for: recording (:mod:`daq.recording`), the simulators (:mod:`simulators`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from daq.acquisition.engine import Acquisition
from daq.acquisition.sync_pulses import SYNC_PULSE_INTERVAL_S
from daq.config import RigConfig
from daq.recording.run import open_run_file, record_run
from daq.sim.rig import SimulatedRig, start_simulated_rig
from daq.sim.rig_process import start_rig_process
from daq.sim.sync_check import ClockTruthTracker, check_run

__all__ = ["check_alignment", "record_simulated_run"]


def record_simulated_run(config: RigConfig, out_path: str | Path, *, duration_s: float,
                         actions: Callable[[Acquisition, SimulatedRig], None] | None = None,
                         progress: bool = True, operator_notes: str = "", calz: bool = True,
                         writer_options: Mapping[str, Any] | None = None,
                         sync_pulse_interval_s: float | None = SYNC_PULSE_INTERVAL_S,
                         check: bool = False, own_process: bool = False,
                         until: threading.Event | None = None) -> dict[str, Any]:
    """Record a simulated rig for ``duration_s`` into one run file; return the summary.

    Parameters
    ----------
    config : RigConfig
        A simulated rig (its ``"auto"`` URLs are the simulators started here).
    out_path : str or Path
        The run file to create.
    duration_s : float
        Length of the run, s (> 0).
    actions : callable, optional
        ``actions(acquisition, rig)`` called in its own thread once the engine runs (``rig`` is
        the :class:`~daq.sim.rig.SimulatedRig`, with its tunnel and simulators): scripted fan
        and release sequences (see :func:`daq.recording.run.record_run`).
    progress, operator_notes, writer_options, sync_pulse_interval_s :
        As :func:`daq.recording.run.record_run`. Unless ``writer_options`` has one, the writer
        gets a :class:`~daq.sim.sync_check.ClockTruthTracker` (the alignment check's).
    calz : bool
        Zero the scanner before the engine starts (default: the simulated tunnel starts
        wind-off).
    check : bool
        Check every simulated device first, through its real transport, as
        :func:`~daq.recording.run.record_run` does.
    until : threading.Event, optional
        End the run early when it is set (as :func:`~daq.recording.run.record_run`).
    own_process : bool
        Serve the simulators from a process of their own (:mod:`daq.sim.rig_process`), as
        ``windrig acquire --simulate`` does: in this process they share the recorder's
        interpreter lock, which on a loaded host delays the scanner's frames by 5-30 ms and
        the writer by seconds. ``actions`` then gets the
        :class:`~daq.sim.rig_process.RigProcess` (its config and truth, not the simulators).

    Returns
    -------
    dict
        :func:`~daq.recording.run.record_run`'s summary plus ``alignment``
        (:func:`check_alignment`).
    """
    options = dict(writer_options or {})
    options.setdefault("clock_truth", ClockTruthTracker())
    # The checks of the file first: nothing starts when it cannot be created.
    recorder = open_run_file(config, out_path, operator_notes=operator_notes,
                             writer_options=options)
    try:
        rig: Any = start_rig_process(config) if own_process else start_simulated_rig(config)
        alignment: dict[str, Any] = {}
    except BaseException:
        recorder.close()
        Path(out_path).unlink(missing_ok=True)
        raise
    try:
        summary = record_run(
            rig.config, out_path, duration_s=duration_s,
            actions=None if actions is None else (lambda acq: actions(acq, rig)),
            progress=progress, operator_notes=operator_notes, calz=calz,
            writer_options=options, sync_pulse_interval_s=sync_pulse_interval_s,
            recorder=recorder, check=check, until=until)
        tracker = options["clock_truth"]
        if own_process and "file" in summary and tracker is not None:
            # Asked of the child while it still runs (the in-process truth outlives the rig).
            alignment = check_run(Path(out_path), tracker, true_time_of=rig.true_time_of,
                                  decay_truth=rig.decay_truth, origin_s=rig.origin_s)
    finally:
        rig.close()
    if "file" in summary:  # the writer finished the file (its summary is in)
        summary["alignment"] = alignment if own_process else \
            check_alignment(Path(out_path), rig, tracker)
    return summary


def check_alignment(path: Path, rig: SimulatedRig, tracker: Any) -> dict[str, Any]:
    """Check the sync view against the simulated rig's truth; store the result in the file.

    Two measures (:mod:`daq.sim.sync_check`): the clock error of every block the sync view used
    (per device, and the misalignment between devices), and the delay of the h, alpha, lift and
    moment channels against the tunnel's decays (needs a release). Only for a tunnel on the
    host's real time (its clock has ``origin_s``) and a writer fed ``tracker``.
    """
    origin = getattr(rig.tunnel.clock, "origin_s", None)
    if origin is None or tracker is None:
        return {}
    return check_run(path, tracker,
                     true_time_of=lambda name, t: origin + rig.simulators[name].true_time_of(t),
                     decay_truth=rig.tunnel.decay_truth, origin_s=origin)
