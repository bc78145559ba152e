"""A whole simulated test campaign: releases at several wind speeds -> E2RFC -> flutter speed.

Responsibility: :func:`run_campaign` drives a *simulated* rig, started in a process of its own
(:mod:`daq.sim.rig_process`), through the real drivers, one acquisition engine for the whole
campaign and the production writer (:class:`daq.recording.session.RecordingSession`, every fan and
release step one of the engine's commands, so an event of the run): for each fraction ``f`` of
the true flutter speed it sets the fan so that the wind is ``f U_F``, waits for the ramp, then
arms, holds and releases the model ``releases_per_speed`` times, recording each free decay for
``decay_s`` seconds, one HDF5 run file per wind speed (``campaign_U<speed>.h5``), switched under the
running engine as ``windrig campaign`` does. It then reads the files back
(:func:`ident.records.run_file.read_run`: each release ends where the model is armed again),
identifies the rational-function model from all releases
(:func:`ident.identification.e2rfc.identify`), computes the identified flutter speed with its
standard deviation and compares it with the truth. Plots (matplotlib, Agg) are written next to the
files.

Three degrees of freedom (a rig config with ``[section] fp`` and a sway laser): the same
campaign, the releases carrying the sway and the drag; the decays plot shows p too. Until
:func:`ident.identification.e2rfc.identify` identifies 3x3 models, the campaign stops after reading
the files back: ``identification_error`` says why, and the plots show the decays and the truth.

Not responsible for: the drivers, the engine or the file (:mod:`daq.recording`), the numerics
(:mod:`ident`), or the decay length (:mod:`daq.procedure`). Real rigs are not driven here: the truth
(``U_F``) that sets the wind speeds exists only for a simulated rig.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from daq.acquisition.engine import Acquisition
from daq.config import RigConfig
from daq.offline.report_plots import (
    DerivativeCurves,
    ModeCurves,
    flutter_derivative_grid,
    flutter_diagram,
)
from daq.procedure import HOLD_S, default_decay_s
from daq.recording.session import RecordingSession
from daq.recording.swmr_file import refuse_existing_run_file
from daq.sim.rig_process import start_rig_process
from ident.errors import IdentError
from ident.identification import e2rfc, results
from ident.identification.campaign import CampaignAnalysis, analyze_campaign
from ident.model import flutter
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.records.release import Release
from ident.records.run_file import read_run
from ident.records.run_set import campaign_section, recording_notes
from simulators.virtual_tunnel import AirState

__all__ = ["CampaignResult", "run_campaign", "simulated_truth"]

#: Fan ramp rate assumed when the simulated drive's is not configured, rpm/s (the simulator's).
DEFAULT_RAMP_RPM_PER_S = 100.0


@dataclass
class CampaignResult:
    """Outcome of :func:`run_campaign`.

    Attributes
    ----------
    files : list of Path
        One run file per wind speed.
    wind_speeds : list of float
        Requested wind speeds, m/s.
    truth_speed : float
        Flutter speed of the simulated truth, m/s.
    identified_speed : float or None
        Flutter speed of the identified model, m/s (None: no flutter found).
    identified_std : float or None
        Its standard deviation, m/s.
    structures : StructureSpread or None
        The flutter speeds of the structures within one standard error of the best, the
        chosen one first.
    relative_error : float or None
        ``identified / truth - 1``.
    n_releases : int
    decay_s : float
    timings : dict
        Wall times, s: ``acquisition``, ``identification``, ``plots``, ``total``.
    plots : dict
        Plot name -> path.
    model : RationalFunctionModel or None
        The identified model.
    releases : list of Release
        The releases identified, in the order of the model's diagnostics.
    analysis : CampaignAnalysis or None
        The whole campaign analysis (:func:`ident.identification.campaign.analyze_campaign`).
    identification_error : str or None
        Why a 3-DOF campaign was not identified (None: it was, or the rig is 2-DOF).
    recording_warnings : list of str
        What the run files' writer warned of, each led by its file (a clock without a
        trigger anchor: :func:`ident.records.run_set.recording_notes`).
    """

    files: list[Path]
    wind_speeds: list[float]
    truth_speed: float
    identified_speed: float | None
    identified_std: float | None
    relative_error: float | None
    n_releases: int
    decay_s: float
    timings: dict[str, float] = field(default_factory=dict)
    plots: dict[str, Path] = field(default_factory=dict)
    model: RationalFunctionModel | None = field(default=None, repr=False)
    releases: list[Release] = field(default_factory=list, repr=False)
    structures: results.StructureSpread | None = None
    analysis: CampaignAnalysis | None = field(default=None, repr=False)
    identification_error: str | None = None
    recording_warnings: list[str] = field(default_factory=list)

    @property
    def warnings(self) -> list[str]:
        """The recordings' warnings, then the analysis's."""
        return [*self.recording_warnings,
                *(() if self.analysis is None else self.analysis.warnings)]

    def summary(self) -> str:
        """Plain-text summary for operators and logs."""
        lines = [
            f"campaign: {self.n_releases} releases at "
            + ", ".join(f"{u:.2f}" for u in self.wind_speeds) + " m/s "
            f"({self.decay_s:.1f} s decays), {len(self.files)} run files",
            f"truth flutter speed       {self.truth_speed:.3f} m/s",
        ]
        if self.identification_error is not None:
            lines.append(f"identified flutter speed  not identified: {self.identification_error}")
        elif self.identified_speed is None:
            lines.append("identified flutter speed  none found")
        else:
            std = "" if self.identified_std is None else f" +- {self.identified_std:.3f}"
            lines.append(f"identified flutter speed  {self.identified_speed:.3f}{std} m/s")
            if self.structures is not None:
                lines.append(f"structure                 {self.structures.summary()}")
            if self.relative_error is not None:
                lines.append(f"relative error            {100 * self.relative_error:+.2f} %")
        lines.extend(f"warning: {w}" for w in self.warnings)
        lines.append("wall time " + ", ".join(f"{k} {v:.1f} s" for k, v in self.timings.items()))
        lines.extend(f"plot {name}: {path}" for name, path in self.plots.items())
        return "\n".join(lines)


def simulated_truth(config: RigConfig) -> tuple[SectionModel, RationalFunctionModel]:
    """Section with the simulated air density, and the simulated aerodynamic model."""
    sim = config.simulation
    if sim is None:
        raise ValueError(f"{config.source}: run_campaign needs a simulated rig ([simulation])")
    air = AirState(pressure_pa=sim.pressure_pa, temperature_k=sim.temperature_c + 273.15)
    return config.section.replace(rho=air.density), config.aerodynamic_model()


def _ramp_rate(config: RigConfig) -> float:
    assert config.simulation is not None
    fan = config.by_role("fan")
    name = fan[0].name if fan else "fan"
    options = config.simulation.devices.get(name, {})
    return float(options.get("ramp_rpm_per_s", DEFAULT_RAMP_RPM_PER_S))


def run_campaign(config: RigConfig, out_dir: str | Path, *,
                 fractions: Sequence[float] = (0.5, 0.65, 0.8), releases_per_speed: int = 2,
                 decay_s: float | None = None, progress: bool = True,
                 n_lags: int | None = None, with_A3: bool | None = None) -> CampaignResult:
    """Run a simulated campaign and identify the flutter speed (see the module docstring).

    Parameters
    ----------
    config : RigConfig
        A simulated rig (its ``[simulation]`` table is the truth).
    out_dir : str or Path
        Directory for the run files and the plots (created; existing run files are refused).
    fractions : sequence of float
        Wind speeds as fractions of the true flutter speed (each in (0, 1), two or more distinct).
    releases_per_speed : int
        Releases recorded at each wind speed (>= 1).
    decay_s : float, optional
        Recorded length of each decay, s; default :func:`default_decay_s`.
    progress : bool
        Show progress bars while recording.
    n_lags, with_A3 : optional
        Model structure passed to :func:`ident.identification.e2rfc.identify` (None: chosen by
        held-out error; with two short releases the choice can fall on too few lags, see the HIL
        test).

    Returns
    -------
    CampaignResult
    """
    started = time.monotonic()
    fractions = [float(f) for f in fractions]
    if len(set(fractions)) < 2 or not all(0.0 < f < 1.0 for f in fractions):
        raise ValueError(f"fractions must hold two or more distinct values in (0, 1), "
                         f"got {fractions!r}")
    if not (isinstance(releases_per_speed, int) and releases_per_speed >= 1):
        raise ValueError(f"releases_per_speed must be an integer >= 1, got {releases_per_speed!r}")
    section, truth_model = simulated_truth(config)
    if decay_s is None:
        decay_s = default_decay_s(section)
    decay_s = float(decay_s)
    if not (math.isfinite(decay_s) and decay_s > 1.0):
        raise ValueError(f"decay_s must be a number > 1 s, got {decay_s!r}")
    truth = flutter.analyze(section, truth_model)
    if truth.speed is None:
        raise ValueError(f"the simulated truth has no flutter below {truth.U_max:.3g} m/s")
    U_F = float(truth.speed)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ramp_rate = _ramp_rate(config)

    plan: list[tuple[float, float, float, Path]] = []  # (fraction, U, rpm, path)
    for f in fractions:
        U = f * U_F
        rpm = U / config.wind_per_rpm
        if U > config.limits.max_wind_speed or rpm > config.limits.max_fan_rpm:
            raise ValueError(f"{f:g} U_F = {U:.3g} m/s ({rpm:.0f} rpm) exceeds the rig's limits "
                             f"({config.limits.max_wind_speed:g} m/s, "
                             f"{config.limits.max_fan_rpm:g} rpm)")
        plan.append((f, U, rpm, out / f"campaign_U{U:05.2f}.h5"))
    for *_, path in plan:  # refused before the fan turns, not after a speed's recording
        refuse_existing_run_file(path)

    # The simulated instruments run in their own process, as real ones run on their own
    # hardware: sharing the recorder's interpreter lock would add milliseconds of
    # simulated-device latency, which misaligns forces and motion (see daq.sim.rig_process).
    # One engine records all the speeds (daq.recording.session): its clock maps settle once,
    # and the fan goes from one speed to the next without stopping.
    files: list[Path] = []
    speeds: list[float] = []
    with start_rig_process(config) as rig, RecordingSession(rig.config, calz=True) as session:
        fan_rpm = 0.0
        for f, U, rpm, path in plan:
            ramp_s = abs(rpm - fan_rpm) / ramp_rate + 1.0
            duration = (max(ramp_s, session.clock_wait_s()) + releases_per_speed
                        * (HOLD_S + decay_s) + 5.0)
            done = threading.Event()

            def actions(acq: Acquisition, rpm: float = rpm, ramp_s: float = ramp_s,
                        done: threading.Event = done) -> None:
                acq.set_fan_speed(rpm)  # operator commands through the engine: events of the run
                acq.start_fan()
                acq.drivers["fan"].wait_for_speed(rpm, tolerance_rpm=max(2.0, 0.002 * rpm),
                                                  timeout_s=ramp_s + 5.0)
                # Let the wind settle at the set point (0.3 s), and on the first speed the
                # engine's clock maps (CLOCK_SETTLE_S from its start; the first hold counts):
                # releases ~1.5 s into a fresh engine left the demo 2.2-3.5 % off on a slow host.
                time.sleep(max(0.3, session.clock_wait_s() - HOLD_S))
                for _ in range(releases_per_speed):
                    acq.arm()
                    time.sleep(HOLD_S)
                    acq.release()
                    time.sleep(decay_s)
                acq.arm()  # catch the model: the next decay is not recorded as part of this one
                done.set()

            reason, summary = session.record(path, actions=actions, until=done,
                                             duration_s=duration, progress=progress,
                                             operator_notes=f"campaign, {f:g} U_F")
            if reason != "done" or summary.get("releases") != releases_per_speed:
                raise RuntimeError(f"{path}: recorded {summary.get('releases')} releases "
                                   f"({reason}), expected {releases_per_speed} (fan ramp "
                                   "slower than assumed?)")
            fan_rpm = rpm
            files.append(path)
            speeds.append(U)
        assert session.acq is not None
        session.acq.stop_fan()  # wind off before the engine stops: its last event
    t_acq = time.monotonic() - started

    t1 = time.monotonic()
    runs = [read_run(path) for path in files]
    releases = [r for run in runs for r in run.releases]
    file_section = campaign_section(runs)  # as `windrig identify` does
    analysis, why = _identify(releases, file_section, n_lags, with_A3)
    speed = None if analysis is None else analysis.flutter_speed
    error = None if speed is None else speed / U_F - 1.0
    t_ident = time.monotonic() - t1

    t2 = time.monotonic()
    plots = _plots(out, releases, file_section, None if analysis is None else analysis.model,
                   section, truth_model, None if analysis is None else analysis.flutter, truth)
    t_plots = time.monotonic() - t2
    return CampaignResult(
        files=files, wind_speeds=speeds, truth_speed=U_F, identified_speed=speed,
        identified_std=None if analysis is None else analysis.flutter_std, relative_error=error,
        n_releases=len(releases), decay_s=decay_s,
        timings={"acquisition": t_acq, "identification": t_ident, "plots": t_plots,
                 "total": time.monotonic() - started},
        plots=plots, model=None if analysis is None else analysis.model, releases=releases,
        structures=None if analysis is None else analysis.structures, analysis=analysis,
        identification_error=why, recording_warnings=recording_notes(runs))


def _identify(releases: list[Release], section: SectionModel, n_lags: int | None,
              with_A3: bool | None) -> tuple[CampaignAnalysis | None, str | None]:
    """Identify the campaign; a 3-DOF one E2RFC cannot identify yet gives ``(None, why)``.

    A 2-DOF campaign's errors propagate as ever. A 3-DOF one's identification error, or a
    model of fewer degrees of freedom than the section (an E2RFC that ignores the sway), is
    returned as the reason, so that the campaign's files and plots still come out.
    """
    if section.n_dof == 2:
        return analyze_campaign(releases, section, n_lags=n_lags, with_A3=with_A3,
                                table=False), None
    try:
        analysis = analyze_campaign(releases, section, n_lags=n_lags, with_A3=with_A3,
                                    table=False)
    except (IdentError, ValueError) as exc:  # reported as the campaign's outcome
        return None, f"E2RFC on 3-DOF releases: {type(exc).__name__}: {exc}"
    if analysis.model.n_dof != section.n_dof:
        return None, (f"E2RFC identified a {analysis.model.n_dof}-DOF model from 3-DOF "
                      "releases (it ignores the sway)")
    return analysis, None


def _plots(out: Path, releases: list[Release], section: SectionModel,
           model: RationalFunctionModel | None, truth_section: SectionModel,
           truth_model: RationalFunctionModel, identified: flutter.FlutterResult | None,
           truth: flutter.FlutterResult) -> dict[str, Path]:
    import matplotlib  # here: the backend is chosen before pyplot loads, only when plotting

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plots: dict[str, Path] = {}

    # Decays: h and alpha of each release (and p, with sway).
    sway = any(r.p is not None for r in releases)
    fig, axes = plt.subplots(3 if sway else 2, 1, figsize=(10, 8 if sway else 6), sharex=True)
    for i, r in enumerate(releases):
        label = f"#{i} U = {r.U:.2f} m/s"
        axes[0].plot(r.t, 1e3 * r.h, lw=0.7, label=label)
        axes[1].plot(r.t, 1e3 * r.alpha, lw=0.7, label=label)
        if sway and r.p is not None:
            axes[2].plot(r.t, 1e3 * r.p, lw=0.7, label=label)
    axes[0].set_ylabel("h (mm)")
    axes[1].set_ylabel("alpha (mrad)")
    if sway:
        axes[2].set_ylabel("p (mm)")
    axes[-1].set_xlabel("time from release (s)")
    axes[0].legend(fontsize=7, ncol=2)
    axes[0].set_title("recorded free decays")
    fig.tight_layout()
    plots["decays"] = out / "campaign_decays.png"
    fig.savefig(plots["decays"], dpi=110)
    plt.close(fig)

    # Flutter derivatives over the K range the releases cover (both modes, all wind speeds).
    K = e2rfc.reduced_frequency_span(releases, section, 200)
    derivatives = [DerivativeCurves("truth", "k-", truth_model.flutter_derivatives(K))]
    if model is not None:
        derivatives.append(DerivativeCurves("identified", "r--", model.flutter_derivatives(K)))
    plots["flutter_derivatives"] = flutter_derivative_grid(
        out / "campaign_flutter_derivatives.png", K, derivatives, dpi=110)

    # Damping and frequency against U, identified vs truth.
    U_max = truth.U_max if identified is None else max(truth.U_max, identified.U_max)
    truth_curves = flutter.analyze(truth_section, truth_model, U_max)
    modes = [ModeCurves(truth_curves, "-", "truth")]
    if model is not None:
        modes.append(ModeCurves(flutter.analyze(section, model, U_max), "--", "identified"))
    plots["flutter"] = flutter_diagram(
        out / "campaign_flutter.png", modes, [r.U for r in releases],
        title=("state-space flutter analysis: identified (--) vs truth (-)" if model is not None
               else "state-space flutter analysis of the truth (not identified)"),
        damping_top=max(0.2, float(np.nanmax(truth_curves.damping)) * 0.5), dpi=110)
    return plots
