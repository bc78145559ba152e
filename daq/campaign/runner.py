"""The headless campaign loop: speed after speed, release after release, until a reason to stop.

Responsibility: :func:`run_plan` runs a :class:`~daq.campaign.plan.CampaignPlan` on a rig
through the same drivers, engine and run writer as the console (one engine for the whole
campaign, :class:`daq.recording.session.RecordingSession`, so that its clock maps settle once
and not at every speed; every fan and release step one of the engine's commands, so an event of
the run), one run file per wind speed (``speedNN_U<m/s>.h5``) or, with ``files =
"per_release"``, one per release (``speedNN_U<m/s>_rMM.h5``, :mod:`daq.campaign.files`), with a
line on the terminal for every step (speed, wind, release n of N, decay amplitude), each
release's modal fit as soon as its file is closed (after each release with one file per
release) and, from two speeds on, the
E2RFC flutter speed +- std after each speed. It stops for the first of these reasons, each
written to ``campaign.json`` as ``stopped_because``:

- the plan is done (fixed mode), the target std is met (from three speeds on: with two the
  std lacks its extrapolation part), no candidate speed gains or the listed speeds gave no
  estimate to choose from (adaptive mode, :mod:`daq.campaign.adaptive`), or ``max_speeds`` is
  reached;
- the next speed is above the safety bound ``fraction * (U_F - 3 std)`` of the current
  estimate (both modes; fixed plans use 0.9; without an estimate ``fraction`` times the
  still-air prediction, :func:`~daq.campaign.adaptive.still_air_flutter_speed`) or the rig's
  limits: it is never set. A speed not above one this session has already held with decaying
  releases is allowed whatever the estimate (a wide std can put the bound below speeds just
  shown to be stable: an FD-style plan going down from its highest speed would otherwise stop,
  and an adaptive one could not repeat its top speed to average the noise down);
- a decay grows (:class:`~daq.campaign.monitor.DecayMonitor`): the model is caught (re-armed)
  and the fan stopped at once;
- Ctrl-C: the run file in progress is finished and kept as ``*.interrupted.h5`` (with one
  file per release, the speed's earlier files too: the speed is repeated whole on resume).

Every speed gets the plan's ``releases_per_speed``, or, in adaptive mode with
``max_releases_per_speed``, the chosen speeds as many as the choice says (it is given the wind-on
cost of a speed: settle time, the wait for a steady wind and the last analysis, and of a
release: hold, the mean decay recorded so far and the pause).

Each release is recorded for the plan's ``decay_s`` or, with ``decay_end = "settled"``, until
the decay monitor finds it settled (:mod:`daq.campaign.monitor`), whichever comes first.

Whatever the reason, even an error, the fan is sent a stop and waited down before returning,
and the plan's closing CALZ is taken wind-off. The fan stays on between the speeds of a
campaign (the tunnel is not stopped for the analysis), so the wind-on time is the time from
the first start to the final stop.

Resumable: run files already in the output directory are read back and count as recorded
speeds (a fixed plan goes on with the next listed speed; an adaptive one decides from them).

Releases by hand (a rig without a PLC, or ``release = "manual"``): the same loop, with the
operator prompted before each hold and release (:mod:`daq.campaign.releasing`). With the
displacement-only route (``identification = "displacement"``) the files are read back for h and
alpha alone and nothing is identified between speeds: the route needs all of them.

Longer than 600 lines: the loop, its per-speed and per-file steps and the session's state are
one sequence whose safety order (catch, stop the fan, wait it down) is easier to check in one
place; the choices it delegates (speeds, files, releasing, monitoring) live in their modules.

Not responsible for: parsing the plan (:mod:`daq.campaign.plan`), choosing speeds
(:mod:`daq.campaign.adaptive`), the report (:mod:`daq.campaign.report`), or starting a
simulated rig's instruments (:mod:`daq.sim.rig_process`, started here only with
``simulate=True``).
"""

from __future__ import annotations

import contextlib
import logging
import math
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from daq.acquisition.device_check import require_devices_ok
from daq.acquisition.engine import Acquisition
from daq.campaign.adaptive import MIN_SPEEDS, choose_next, safety_bound, still_air_flutter_speed
from daq.campaign.files import interrupted_name, read_back, run_file_name
from daq.campaign.monitor import DecayMonitor
from daq.campaign.outcome import CampaignOutcome, SpeedStep
from daq.campaign.plan import CampaignPlan
from daq.campaign.releasing import ManualReleases, PlcReleases, releaser
from daq.campaign.wind import STEADY_TIMEOUT_S, ramp_rate, wait_steady
from daq.config import RigConfig
from daq.errors import DeviceCheckError, DeviceError
from daq.instruments.build import build_driver
from daq.procedure import default_decay_s
from daq.recording.devices import CLOCK_SETTLE_S
from daq.recording.session import RecordingSession
from ident.errors import IdentError
from ident.identification.campaign import CampaignAnalysis, analyze_campaign
from ident.identification.modal import fit_release_modes
from ident.identification.results import distinct_wind_speeds
from ident.records.release import Release
from ident.records.run_file import RunFile, read_run
from ident.records.run_set import campaign_section

__all__ = ["CHECK_FAILED", "CampaignOutcome", "SpeedStep", "run_plan"]

log = logging.getLogger(__name__)

#: Distinct wind speeds before an adaptive campaign may call its target met (see _loop).
MIN_SPEEDS_FOR_TARGET = MIN_SPEEDS
#: Wind-on seconds a new speed takes besides its settle time and analysis: the ramp and the
#: wait for a steady wind (the adaptive choice of the releases per speed counts them).
STEADY_OVERHEAD_S = 2.0
#: Fan speed counted as stopped, rpm.
STOPPED_RPM = 5.0
#: ``stopped_because`` of a session whose device check failed (nothing was moved or recorded).
CHECK_FAILED = "device check failed"


class _Session:
    """State of one session: the fan, the clock of the wind, the files, the output."""

    def __init__(self, plan: CampaignPlan, config: RigConfig, out: Path,
                 say: Callable[[str], None]) -> None:
        self.plan, self.config, self.out, self.say = plan, config, out, say
        fans = config.by_role("fan")
        if not fans:
            raise DeviceError(f"{config.source}: a campaign needs a fan drive ([fan])")
        self.fan_name = fans[0].name
        self.fan_on_at: float | None = None
        #: Set before the first fan command: from then on the campaign ends with a fan stop,
        #: even when the start itself failed halfway.
        self.fan_commanded = False
        self.fan_rpm = 0.0
        self.runs: list[RunFile] = []
        #: Wind-on seconds the last analysis between speeds took (the adaptive choice counts it
        #: in the cost of a speed).
        self.analysis_s = 0.0
        #: Set by Ctrl-C (the runner's SIGINT handler): the actions stop at their next step.
        self.abort = threading.Event()
        section = config.section
        #: Follows every decay of the session (its releases count across the files).
        self.monitor = DecayMonitor(1.0 / min(section.fh, section.fa))
        #: How the model is held and released (set by run_plan: the PLC or a hand).
        self.releases: PlcReleases | ManualReleases = PlcReleases()
        self._recording: RecordingSession | None = None
        self._stack = contextlib.ExitStack()

    # -- the acquisition: one engine for the whole campaign ---------------------------------
    def recording(self) -> RecordingSession:
        """Return the campaign's running acquisition, started at the first call.

        The scanner is zeroed wind-off before it starts if the plan says so and the fan has
        not been started yet.
        """
        if self._recording is None:
            calz = self.plan.calz_start and self.fan_on_at is None
            self._recording = self._stack.enter_context(
                RecordingSession(self.config, calz=calz, subscribers=[self.monitor]))
        return self._recording

    def close_recording(self) -> None:
        """Stop the acquisition (a file still recording is finished); idempotent."""
        self._recording = None
        self._stack.close()

    # -- the fan, outside a run: the final stop ---------------------------------------------
    def fan_down(self) -> None:
        """Stop the fan and wait until it has stopped (always; a stop is never refused)."""
        if not self.fan_commanded:
            return
        driver = build_driver(self.config.instrument(self.fan_name), self.config.limits)
        # Sent directly to the drive: the campaign's end is decided after the last run file
        # is closed, and a stop must not wait for an engine to start.
        try:
            driver.open()
            driver.stop()
            driver.wait_for_speed(0.0, tolerance_rpm=STOPPED_RPM)
        finally:
            driver.close()
        self.fan_rpm = 0.0

    def calz_wind_off(self) -> None:
        """Take the closing CALZ, wind-off (after :meth:`fan_down`)."""
        for inst in self.config.by_role("scanner"):
            driver = build_driver(inst, self.config.limits)
            try:
                driver.open()
                driver.calz(wind_speed_now=0.0)
            finally:
                driver.close()
            self.say(f"CALZ wind-off: {inst.name} zeroed")


def _analysis(runs: list[RunFile], plan: CampaignPlan) -> CampaignAnalysis | None:
    releases = [r for run in runs for r in run.releases]
    if len(distinct_wind_speeds([r.U for r in releases])) < 2:
        return None
    return analyze_campaign(releases, campaign_section(runs), table=False,
                            turbulent_estimator=plan.turbulent_estimator,
                            closed_loop_buffeting=plan.closed_loop_buffeting)


def _truth_speed(config: RigConfig) -> float | None:
    # The truth exists only for a simulated rig; imported here so that a real campaign never
    # loads the simulators.
    from daq.sim.campaign import simulated_truth
    from ident.model import flutter

    section, model = simulated_truth(config)
    speed = flutter.analyze(section, model).speed
    return None if speed is None else float(speed)


def run_plan(plan: CampaignPlan, config: RigConfig, out_dir: str | Path, *,
             simulate: bool = False, say: Callable[[str], None] = print,
             previous: dict[str, Any] | None = None,
             outcome: CampaignOutcome | None = None, check: bool = True,
             ask: Callable[[str], Any] | None = None) -> CampaignOutcome:
    """Run a campaign plan on a rig (see the module docstring).

    Parameters
    ----------
    plan : CampaignPlan
    config : RigConfig
        The rig; with ``simulate`` a simulated rig, whose instruments are started here in a
        process of their own (loopback only).
    out_dir : str or Path
        Run files (created; earlier ones are read back: resume).
    simulate : bool
        Start the simulated rig and report its truth.
    say : callable
        Receives each progress line.
    previous : dict, optional
        The earlier session's ``campaign.json`` (its wind-on time is carried on).
    outcome : CampaignOutcome, optional
        Filled in as the campaign goes (a caller that reports even after an error passes
        its own).
    check : bool
        Check every device first (:func:`~daq.acquisition.device_check.require_devices_ok`,
        as ``windrig check``), before the fan or the release moves.
    ask : callable, optional
        Releases by hand: ``ask(prompt)`` returns once the operator confirms (default: Enter
        on the terminal, :func:`daq.campaign.releasing.ask_on_terminal`).

    Raises
    ------
    DeviceCheckError
        A device failed the check (named, with every other failing one); nothing was moved
        or recorded, ``outcome.stopped_because`` starts with :data:`CHECK_FAILED`.

    Returns
    -------
    CampaignOutcome
    """
    started = time.monotonic()
    plan.check_against(config)
    plan.check_rig(config)  # it can release and identify: before anything moves
    out = Path(out_dir)
    outcome = CampaignOutcome() if outcome is None else outcome
    if previous:
        outcome.wind_on_s = float(previous.get("wind_on_s", 0.0))
    if simulate:
        outcome.truth_flutter_speed = _truth_speed(config)
    rig_cm: contextlib.AbstractContextManager[Any]
    if simulate:
        from daq.sim.rig_process import start_rig_process  # only a simulated rig needs it

        rig_cm = start_rig_process(config)
    else:
        rig_cm = contextlib.nullcontext()
    with rig_cm as rig:
        live = config if rig is None else rig.config
        if check:
            try:
                results = require_devices_ok(live)
            except DeviceCheckError as exc:
                outcome.stopped_because = f"{CHECK_FAILED}: {exc}"
                raise
            notes = [f"{r.device}: {note}" for r in results for note in r.notes]
            say(f"device check: {len(results)} device(s) OK"
                + "".join(f"\n  note: {note}" for note in notes))
        out.mkdir(parents=True, exist_ok=True)  # after the check: a failed one leaves nothing
        session = _Session(plan, live, out, say)
        defaults = plan.defaults_taken(live)
        if defaults:  # no default is taken silently
            say("plan defaults: " + "; ".join(defaults))
        session.releases = releaser(plan.release_method(live), rig=rig, ask=ask, say=say)
        if session.releases.manual:
            say("releases by hand: the operator is prompted before each hold and release")
        restore = _on_sigint(session.abort)
        try:
            try:
                _loop(session, outcome)
            finally:
                session.close_recording()
        except KeyboardInterrupt:
            outcome.stopped_because = "interrupted by the operator (Ctrl-C)"
            say("interrupted: stopping the fan")
        except BaseException as exc:
            outcome.stopped_because = f"error: {type(exc).__name__}: {exc}"
            raise
        finally:
            restore()
            fan_was_on = session.fan_on_at
            try:
                session.fan_down()
            finally:
                if fan_was_on is not None:
                    outcome.wind_on_s += time.monotonic() - fan_was_on
                    session.fan_on_at = None
            say(f"fan stopped; wind on {outcome.wind_on_s:.1f} s in all")
            if plan.calz_end and not outcome.stopped_because.startswith("error"):
                session.calz_wind_off()
    outcome.wall_s = time.monotonic() - started
    return outcome


def _on_sigint(abort: threading.Event) -> Callable[[], None]:
    """Make Ctrl-C set ``abort`` as well as raise KeyboardInterrupt; return the undo.

    The interrupt reaches the main thread, which waits in :func:`record_run` and finishes the
    file; the actions thread learns of it from ``abort`` and commands nothing more than
    catching the model and stopping the fan. Outside the main thread (no signals there) the
    handler is left alone.
    """
    if threading.current_thread() is not threading.main_thread():
        return lambda: None

    def handler(signum: int, frame: Any) -> None:
        abort.set()
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGINT, handler)

    def undo() -> None:
        signal.signal(signal.SIGINT, previous)

    return undo


def _loop(session: _Session, outcome: CampaignOutcome) -> None:
    plan, config, say = session.plan, session.config, session.say
    listed = plan.listed_speeds(config.wind_per_rpm)
    fraction = plan.safety_fraction
    # The bound before E2RFC has an estimate (plan.check_against refused blind speeds above it).
    prior = still_air_flutter_speed(config.section)
    if prior is not None:
        say(f"safety: until E2RFC has an estimate, no speed above {fraction * prior:.2f} m/s "
            f"({fraction:g} x {prior:.2f} m/s, the still-air prediction: a flat plate of the "
            "section)")
    rig_limit = min(config.limits.max_wind_speed, config.limits.max_fan_rpm * config.wind_per_rpm)
    decay_s = plan.decay_s if plan.decay_s is not None else default_decay_s(config.section)

    for found in read_back(session.out, say,
                           displacements_only=plan.identification == "displacement"):
        why = "listed in the plan" if found.index <= len(listed) else "read back"
        outcome.steps.append(SpeedStep(found.index, found.U, found.paths[0], found.releases,
                                       f"{why} (resumed)", paths=found.paths, resumed=True))
        session.runs.extend(found.runs)
        outcome.recording_warnings.extend(found.recording_warnings)
        outcome.resumed += 1
    if outcome.resumed:
        say(f"resume: {outcome.resumed} speed(s) read back from {session.out}")
        if plan.identification == "e2rfc":
            outcome.analysis = _analysis(session.runs, plan)
            _say_estimate(say, outcome.analysis)

    while True:
        k = len(outcome.steps)  # speeds recorded so far
        analysis = outcome.analysis
        max_speeds = plan.adaptive.max_speeds if plan.adaptive else len(listed)
        if k >= max_speeds:
            outcome.stopped_because = (f"plan done: {k} speeds" if plan.mode == "fixed"
                                       else f"max_speeds ({max_speeds}) reached")
            return
        # Three speeds at least: from two, E2RFC cannot measure the extrapolation part of the
        # std (it refits without the top speed), so a two-speed std is only a lower bound.
        if plan.adaptive and analysis is not None and analysis.flutter_speed is not None \
                and k >= len(listed) and len(analysis.wind_speeds) >= MIN_SPEEDS_FOR_TARGET:
            rel = analysis.flutter_std / analysis.flutter_speed  # type: ignore[operator]
            if rel <= plan.adaptive.target_std:
                outcome.stopped_because = (f"target met: std {100 * rel:.2f} % <= "
                                           f"{100 * plan.adaptive.target_std:.2f} %")
                return
        # The wind may always go back to what this session has held (a grown decay ends the
        # campaign: every step of it decayed). The adaptive choice offers a held speed as a
        # candidate too: its prediction counts a repeat's gain on the statistical part only.
        held = max((s.U for s in outcome.steps if not s.resumed), default=0.0)
        bound = min(rig_limit, safety_bound(analysis, fraction, held, prior))
        n_releases = plan.releases_per_speed
        if k < len(listed):
            U, why = listed[k], "listed in the plan"
        elif analysis is None:  # the listed speeds gave no estimate (said above): nothing to aim at
            outcome.stopped_because = ("stopped: the listed speeds gave no E2RFC estimate (see "
                                       "the E2RFC line above); the next speed cannot be chosen")
            say(outcome.stopped_because)
            return
        else:
            assert plan.adaptive is not None
            releases = [r for run in session.runs for r in run.releases]
            choice = choose_next(analysis, releases, plan.adaptive.candidates(), bound=bound,
                                 releases_per_speed=plan.releases_per_speed, decay_s=decay_s,
                                 release_options=plan.adaptive.release_options(),
                                 overhead_s=_speed_overhead_s(plan) + session.analysis_s,
                                 per_release_s=_per_release_s(releases, plan),
                                 target=plan.adaptive.target_std * analysis.flutter_speed
                                 if analysis.flutter_speed else None)
            outcome.choices.append(choice)
            say(choice.summary())
            if choice.speed is None:
                outcome.stopped_because = choice.reason
                return
            U, why = choice.speed, choice.reason
            n_releases = choice.releases or plan.releases_per_speed
        if U > bound + 1e-9:
            estimated = analysis is not None and analysis.flutter_speed is not None
            basis = (f"{fraction:g} x (U_F - 3 std) of the current estimate" if estimated else
                     "no E2RFC estimate yet: " + (f"{fraction:g} x {prior:.2f} m/s, the still-air "
                                                  "prediction" if prior else "no prediction"))
            outcome.stopped_because = (
                f"safety stop: the next speed {U:.2f} m/s is above the bound {bound:.2f} m/s "
                f"({basis}, the highest speed held so far, or the rig's limit "
                f"{rig_limit:.3g} m/s); it was not set")
            say(outcome.stopped_because)
            return
        step = _record_speed(session, outcome, k + 1, U, why, decay_s, n_releases)
        if step is None:  # grown or interrupted: the reason is set
            return


def _speed_overhead_s(plan: CampaignPlan) -> float:
    """Wind-on seconds a new speed costs before its first release, s: the wind's ramp and settling.

    The clock maps' settling (:data:`CLOCK_SETTLE_S`) is paid once, at the campaign's start:
    every later file's writer starts from the session's last seconds of data.
    """
    return plan.settle_s + STEADY_OVERHEAD_S


def _per_release_s(releases: list[Release], plan: CampaignPlan) -> float:
    """Wind-on seconds one more release costs: hold, its decay as recorded so far, pause."""
    decays = [float(r.t[-1] - r.t[0]) for r in releases]
    return plan.hold_s + (sum(decays) / len(decays) if decays else 0.0) + plan.pause_s + 1.0


def _say_estimate(say: Callable[[str], None], analysis: CampaignAnalysis | None) -> None:
    if analysis is None:
        say("E2RFC: needs releases at two wind speeds")
    elif analysis.flutter_speed is None:
        say(f"E2RFC: {analysis.summary()}")
    else:
        std = analysis.flutter_std or math.nan
        say(f"E2RFC: flutter speed {analysis.flutter_speed:.3f} +- {std:.3f} m/s "
            f"({100 * std / analysis.flutter_speed:.2f} %), {analysis.structure}")
        # Which parts make the std (a jump at a new speed is one part's, and says which).
        parts = analysis.uncertainty.parts()
        say("  std parts (m/s): " + ", ".join(
            f"{name.replace('_', ' ')} {value:.3f}" for name, value in parts.items() if value))


def _record_speed(session: _Session, outcome: CampaignOutcome, index: int, U: float, why: str,
                  decay_s: float, n: int) -> SpeedStep | None:
    """Record one speed's ``n`` releases (one file, or one per release); its step, or None."""
    plan, config, say = session.plan, session.config, session.say
    rpm = U / config.wind_per_rpm
    say(f"[speed {index}] U = {U:.2f} m/s ({rpm:.0f} rpm): {why}")
    if plan.files == "per_release":
        batches = [(session.out / run_file_name(index, U, i + 1), range(i, i + 1))
                   for i in range(n)]
    else:
        batches = [(session.out / run_file_name(index, U), range(n))]
    paths: list[Path] = []
    runs: list[RunFile] = []
    status = "done"
    for path, releases in batches:
        status = _record_file(session, outcome, path, rpm, releases, n, decay_s,
                              f"campaign speed {index}: {why}")
        displacement = plan.identification == "displacement"
        paths.append(path)
        if status == "interrupted":
            for kept in paths:
                kept.rename(interrupted_name(kept))
            outcome.stopped_because = "interrupted by the operator (Ctrl-C)"
            say(f"interrupted: {', '.join(interrupted_name(p).name for p in paths)} kept, the "
                "speed is repeated on resume")
            return None
        run = _read_recorded(path, say, displacement)
        if run is not None:
            runs.append(run)
            # The modal fit of each release as soon as its file is closed (per release: live).
            for j, mode in enumerate(_modes(run), start=releases.start + 1):
                say(f"  release {j}: {mode}")
        if status == "grown":
            break
    session.runs.extend(runs)
    step = SpeedStep(index, U, paths[0], sum(len(r.releases) for r in runs), why, paths=paths)
    outcome.steps.append(step)
    if status == "grown":
        outcome.stopped_because = (
            f"safety stop: a decay grew at {U:.2f} m/s (negative total damping: at or beyond "
            "flutter); the model was caught and the fan stopped")
        _update(session, outcome, step)
        return None
    _update(session, outcome, step)
    return step


def _read_recorded(path: Path, say: Callable[[str], None],
                   displacement: bool = False) -> RunFile | None:
    """Read a file just recorded back for identification (None, said, when it cannot be).

    ``displacement``: for the displacement-only route, h and alpha alone (a rig without taps
    records no forces, which are otherwise a gap from the release on).
    """
    try:
        # A gap (a device fault, frames lost on a busy host) ends a release early, or leaves
        # it out when too little remains: the campaign goes on with the rest, and says so.
        run = read_run(path, cut_at_gaps=True, displacements_only=displacement)
    except (IdentError, ValueError, OSError) as exc:
        say(f"  {path.name}: cannot be identified ({exc}); left out of the fit")
        return None
    say(f"  {path.name}: {len(run.releases)} release(s) recorded")
    for cut in run.cuts:
        say(f"  {path.name}: {cut}")
    return run


def _record_file(session: _Session, outcome: CampaignOutcome, path: Path, rpm: float,
                 releases: range, n: int, decay_s: float, notes: str) -> str:
    """Record the releases ``releases`` (0-based, of the speed's ``n``) into one run file.

    The fan is set (and started) at the start of every file, so that each file's events
    hold its wind setting; from the second file of a speed on the wind is already steady.

    Returns
    -------
    str
        ``"done"``, ``"grown"`` (a decay grew: model caught, fan stopped) or
        ``"interrupted"`` (Ctrl-C: model caught, fan stopped, the file not complete).
    """
    plan, config, say = session.plan, session.config, session.say
    monitor = session.monitor
    done, grown = threading.Event(), threading.Event()
    ramp = abs(rpm - session.fan_rpm) / ramp_rate(config, session.fan_name)
    duration = (1.5 * ramp + 2.0 + STEADY_TIMEOUT_S + plan.settle_s + CLOCK_SETTLE_S
                + len(releases) * (plan.hold_s + decay_s + plan.pause_s + 1.0) + 5.0)

    def wait(seconds: float, settled_after: int | None = None) -> bool:
        """Wait ``seconds``; True (stop) early if the decay grows or on Ctrl-C.

        With ``settled_after`` (the monitor's release count before this release), False (go
        on) early once this release's decay has settled.
        """
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            if monitor.growing.wait(min(left, 0.05)) or session.abort.is_set():
                return True
            if settled_after is not None and monitor.settled_since(settled_after):
                break
        return False

    def body(acq: Acquisition) -> None:
        fan = acq.drivers[session.fan_name]
        session.fan_commanded = True
        acq.set_fan_speed(rpm)  # operator commands through the engine: events of the run
        outcome.max_fan_rpm_commanded = max(outcome.max_fan_rpm_commanded, rpm)
        acq.start_fan()
        if session.fan_on_at is None:
            session.fan_on_at = time.monotonic()
        session.fan_rpm = rpm
        wait_steady(fan, rpm, plan.steady_tolerance, plan.settle_s, session.abort)
        # The engine's clock maps settle before the first release (its hold counts): only the
        # campaign's first file waits, later ones start from the session's last seconds.
        if wait(recording.clock_wait_s() - plan.hold_s) or session.abort.is_set():
            return
        say(f"  wind steady at {fan.speed() * config.wind_per_rpm:.2f} m/s")
        by = session.releases  # the PLC, or the operator's hand (daq.campaign.releasing)
        for i in releases:
            by.hold(acq)
            if wait(max(plan.hold_s, by.min_hold_s)):
                return
            seen = monitor.releases
            by.release(acq)
            if wait(decay_s, seen if plan.decay_end == "settled" else None):
                by.catch(acq)  # catch the model first, then take the wind away
                acq.stop_fan()
                if not monitor.growing.is_set():
                    return  # Ctrl-C: caught and stopped, the runner waits the fan down
                grown.set()
                amp = monitor.amplitude()
                say(f"  release {i + 1}/{n}: the decay GROWS"
                    + ("" if amp is None else f" ({1e3 * amp.first:.2f} -> "
                       f"{1e3 * amp.last:.2f} mm)") + ": model caught, fan stopped")
                break
            amp = monitor.amplitude()
            say(f"  release {i + 1}/{n}: decay amplitude "
                + ("?" if amp is None else f"{1e3 * amp.first:.2f} -> {1e3 * amp.last:.2f} mm "
                   f"over {amp.windows} periods"))
            if plan.pause_s and wait(plan.pause_s) and session.abort.is_set():
                return
        by.hold(acq)  # hold the model: the next decay is not recorded as part of this one
        done.set()

    def actions(acq: Acquisition) -> None:
        try:
            body(acq)
        finally:
            if session.abort.is_set() and acq.running:
                session.releases.interrupted(acq)  # Ctrl-C: the model held before the end
                acq.stop_fan()

    recording = session.recording()
    _, summary = recording.record(path, actions=actions, until=done, duration_s=duration,
                                  operator_notes=notes)
    for text in summary.get("warnings", []):
        say(f"  warning: {text}")
        outcome.recording_warnings.append(f"{path.name}: {text}")
    if not done.is_set():
        return "interrupted"
    return "grown" if grown.is_set() else "done"


def _update(session: _Session, outcome: CampaignOutcome, step: SpeedStep) -> None:
    if session.plan.identification == "displacement":  # from all speeds, after the campaign
        session.say(f"displacement-only route: identify after the campaign (`windrig identify "
                    f"{session.out}/*.h5 --route displacement`, which states its caveats)")
        return
    started = time.monotonic()
    try:
        try:
            outcome.analysis = _analysis(session.runs, session.plan)
        finally:  # the wind blows while the analysis runs: its time counts
            session.analysis_s = time.monotonic() - started
            if session.fan_on_at is not None:
                step.wind_on_s = outcome.wind_on_s + time.monotonic() - session.fan_on_at
    except IdentError as exc:
        session.say(f"E2RFC: {exc}")
        return
    _say_estimate(session.say, outcome.analysis)
    if outcome.analysis is not None:
        step.flutter_speed = outcome.analysis.flutter_speed
        step.flutter_std = outcome.analysis.flutter_std
        if outcome.analysis.flutter_speed is not None:
            step.flutter_std_parts = outcome.analysis.uncertainty.parts()


def _modes(run: RunFile) -> list[str]:
    """Each release's modal fit (the one E2RFC's regressors use), one phrase each."""
    out = []
    for r in run.releases:
        try:
            m = fit_release_modes(r.t, r.h, r.alpha, run.section)
        except (IdentError, ValueError) as exc:
            out.append(f"no modal fit ({exc})")
            continue
        out.append(f"f_h {m.f_h:.3f} Hz, zeta_h {100 * m.zeta_h:.2f} %, "
                   f"f_a {m.f_a:.3f} Hz, zeta_a {100 * m.zeta_a:.2f} %")
    return out
