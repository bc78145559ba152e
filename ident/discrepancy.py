"""Where the identified model and the measurements disagree, which physical effect is missing.

:func:`diagnose` confronts a linear model (the section's structure plus the rational-function
aerodynamics, identified by E2RFC unless given) with the releases it came from:

1. **Gap before**: every release is simulated with the model from its own initial state
   (:func:`ident.simulate.simulate_decay`) and compared with what was measured:
   :func:`gap` is the RMS difference of h, alpha, lift and moment over all releases, each
   channel divided by its own RMS, averaged over the four channels.
2. **Candidates**: the seven named effects (``docs/conventions.md``, "Named effects") are each
   fitted to the data as a physical term with its own parameters (:mod:`ident._equation_error`: the
   residual of the structural equation for six of them, the forces' line above the motion's band for
   vortex shedding) and scored by the held-out fraction of that residual they explain.
3. **Naming**: the candidate with the smallest held-out residual wins if it explains at least
   ``1 - NONE_RATIO`` of it and its improvement is ``MIN_SIGMAS`` standard errors clear of
   nothing; otherwise the answer is None (the baseline explains the data: no false alarms).
   The runner-up is reported.
4. **Refit and gap after**: the effect is added to the model (a measurement effect is taken
   out of the data and the aerodynamic model identified again, its structure chosen again; a
   structural one joins the structure; vortex forcing is taken out of the forces before E2RFC
   and added to each release's simulated forces), every release is simulated again, and the
   gap measured the same way.

Not responsible for: reading files (:mod:`ident.io`), plots or the command line
(``windrig diagnose`` in :mod:`daq`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ident import e2rfc
from ident._equation_error import (
    STRUCTURAL_CANDIDATES,
    CandidateSpec,
    DecaySignals,
    LinearFit,
    VortexFit,
    decay_signals,
    fit_structural,
    fit_vortex,
)
from ident.coupling import ZeroWindCoupling, coupling_verdict, zero_wind_coupling
from ident.effects import (
    EFFECT_NAMES,
    ChannelDelay,
    CoulombFriction,
    CubicStiffness,
    Effect,
    QuadraticDamping,
    SensorCrosstalk,
    StaticUnbalance,
    VortexShedding,
)
from ident.release import Release
from ident.rfc import RationalFunctionModel
from ident.section import SectionModel
from ident.simulate import simulate_decay

__all__ = ["CHANNELS", "MIN_SIGMAS", "NONE_RATIO", "Backbone", "CandidateEvidence",
           "DiscrepancyReport", "backbone", "diagnose", "gap", "whiteness"]

FloatArray = npt.NDArray[np.float64]

#: Compared channels.
CHANNELS = ("h", "alpha", "lift", "moment")
#: A candidate must leave at most this fraction of the held-out residual (explain >= 2 %).
NONE_RATIO = 0.98
#: ... and its improvement must exceed this many standard errors (over the folds).
MIN_SIGMAS = 2.0
#: Samples at the start of a decay fitted by ``c0 + c2 t^2 + c3 t^3`` for its initial state.
_START_SAMPLES = 20
#: Depth used to express a fitted shedding frequency as a Strouhal number when none is given, m.
_UNIT_DEPTH = 1.0


@dataclass(frozen=True)
class CandidateEvidence:
    """What the data say about one candidate effect.

    Attributes
    ----------
    effect : str
        One of the seven names.
    parameters, std : dict of str to float
        Fitted parameters and their standard deviations (SI units, see :attr:`units`).
    units : dict of str to str
    cv_ratio : float
        Held-out residual with the candidate over that without it (< 1: it predicts residual
        it was not fitted to).
    cv_ratio_se : float
        Standard error of ``cv_ratio`` over the folds.
    verdict : str
        Why it was chosen or rejected, one line.
    """

    effect: str
    parameters: dict[str, float]
    std: dict[str, float]
    units: dict[str, str]
    cv_ratio: float
    cv_ratio_se: float
    verdict: str = ""


@dataclass(frozen=True)
class DiscrepancyReport:
    """The outcome of :func:`diagnose`.

    Attributes
    ----------
    effect : str or None
        The effect named, or None when the baseline explains the data.
    parameters, uncertainty : dict of str to float
        The named effect's fitted parameters and their standard deviations (empty for None).
    gap_before, gap_after : float
        :func:`gap` of the baseline and of the refitted model (equal for None).
    gap_per_release : ndarray, shape (n_releases, 2)
        Each release's gap before and after.
    evidence : tuple of CandidateEvidence
        Every candidate, best first.
    runner_up : str or None
        The second-best candidate.
    baseline : RationalFunctionModel
        The aerodynamic model of the baseline.
    refitted : RationalFunctionModel
        The aerodynamic model after the refit (the baseline's when nothing changed).
    section : SectionModel
        The structure the models are simulated with (as given: a static unbalance found is in
        :attr:`effects`, which the simulation adds to it).
    effects : tuple of Effect
        The effect added to the model (empty for None).
    simulated_before, simulated_after : tuple of dict
        Per release, the four simulated channels (as measured) of the baseline and of the
        refitted model (the same objects for None).
    whiteness_before, whiteness_after : dict of str to float
        Per channel, the lag-1 autocorrelation of measured minus simulated (:func:`whiteness`):
        near 1 when the model misses something smooth, near 0 when only the measurement
        noise is left.
    zero_wind_coupling : tuple of ZeroWindCoupling
        The heave and pitch modes' coupling that the baseline lacks, extrapolated to zero wind
        (:func:`ident.coupling.zero_wind_coupling`; empty when it cannot be estimated).
    """

    effect: str | None
    parameters: dict[str, float]
    uncertainty: dict[str, float]
    gap_before: float
    gap_after: float
    gap_per_release: FloatArray = field(repr=False)
    evidence: tuple[CandidateEvidence, ...] = field(repr=False)
    runner_up: str | None
    baseline: RationalFunctionModel = field(repr=False)
    refitted: RationalFunctionModel = field(repr=False)
    section: SectionModel = field(repr=False)
    effects: tuple[Effect, ...] = ()
    simulated_before: tuple[dict[str, FloatArray], ...] = field(default=(), repr=False)
    simulated_after: tuple[dict[str, FloatArray], ...] = field(default=(), repr=False)
    whiteness_before: dict[str, float] = field(default_factory=dict)
    whiteness_after: dict[str, float] = field(default_factory=dict)
    zero_wind_coupling: tuple[ZeroWindCoupling, ...] = ()

    def summary(self) -> str:
        """Return the report as text: the verdict, the gap, every candidate's evidence."""
        lines = []
        if self.effect is None:
            lines.append("effect: none (the baseline model explains the data)")
        else:
            params = ", ".join(f"{k} = {v:.4g} +- {self.uncertainty.get(k, math.nan):.2g}"
                               for k, v in self.parameters.items())
            lines.append(f"effect: {self.effect} ({params})")
        shrink = (1 - self.gap_after / self.gap_before) if self.gap_before > 0 else 0.0
        lines.append(f"gap: {self.gap_before:.4f} before, {self.gap_after:.4f} after "
                     f"({shrink:+.0%} shrink)" if self.effect is not None
                     else f"gap: {self.gap_before:.4f}")
        lines.append(f"runner-up: {self.runner_up}")
        lines.append("residual lag-1 autocorrelation (near 0: only white noise left): " + ", ".join(
            f"{c} {self.whiteness_before.get(c, math.nan):.2f}"
            + (f" -> {self.whiteness_after.get(c, math.nan):.2f}" if self.effect else "")
            for c in CHANNELS))
        lines.append("coupling at zero wind (measured minus baseline, extrapolated): "
                     + coupling_verdict(self.zero_wind_coupling))
        lines.extend(f"  {c.text()}" for c in self.zero_wind_coupling)
        lines.append(f"{'candidate':<20}{'held-out':>10}{'+-':>8}  verdict")
        for ev in self.evidence:
            lines.append(f"{ev.effect:<20}{ev.cv_ratio:>10.4f}{ev.cv_ratio_se:>8.4f}  "
                         f"{ev.verdict}")
        return "\n".join(lines)


def whiteness(measured: Sequence[dict[str, FloatArray]],
              simulated: Sequence[dict[str, FloatArray]]) -> dict[str, float]:
    """Return, per channel, the lag-1 autocorrelation of measured minus simulated.

    The mean over the releases of ``sum e[k] e[k+1] / sum e[k]^2`` (``e`` the residual less
    its mean): about 0 for white measurement noise, near 1 for a smooth model error.
    """
    out = {}
    for name in CHANNELS:
        values = []
        for m, s in zip(measured, simulated, strict=True):
            e = np.asarray(m[name] - s[name], dtype=float)
            e = e - e.mean()
            den = float(e @ e)
            if den > 0 and e.size > 2:
                values.append(float(e[:-1] @ e[1:]) / den)
        out[name] = float(np.mean(values)) if values else math.nan
    return out


def gap(measured: Sequence[dict[str, FloatArray]],
        simulated: Sequence[dict[str, FloatArray]]) -> float:
    """Return the normalised RMS difference of the four channels over all releases.

    For each channel, ``sqrt(sum (sim - meas)^2) / sqrt(sum meas^2)`` over every sample of
    every release (each channel is normalised by its own RMS), then the mean over the channels.
    """
    ratios = []
    for name in CHANNELS:
        num = sum(float(np.sum((s[name] - m[name]) ** 2))
                  for m, s in zip(measured, simulated, strict=True))
        den = sum(float(np.sum(m[name] ** 2)) for m in measured)
        ratios.append(math.sqrt(num / den) if den > 0 else 0.0)
    return float(np.mean(ratios))


def diagnose(releases: Sequence[Release], section: SectionModel,
             baseline: RationalFunctionModel | None = None, *,
             depth: float | None = None) -> DiscrepancyReport:
    """Find the physical effect the linear model misses, add it, refit, report the gap.

    Parameters
    ----------
    releases : sequence of Release
        Free decays with measured forces (at two or more wind speeds when ``baseline`` is None).
    section : SectionModel
        The structure as known (weighed masses, still-air frequencies and damping).
    baseline : RationalFunctionModel, optional
        The aerodynamic model to confront; None identifies it by E2RFC from the releases.
    depth : float, optional
        Section depth D, m: the shedding frequency ``k U`` of a vortex candidate is reported as
        a Strouhal number ``St = k D`` (default: per metre of depth, i.e. ``St = k``).

    Returns
    -------
    DiscrepancyReport

    Raises
    ------
    TypeError
        If ``releases`` holds something other than :class:`Release` objects.
    RankDeficiencyError
        With ``baseline=None``, releases at fewer than two wind speeds.
    """
    releases = list(releases)
    for r in releases:
        if not isinstance(r, Release):
            raise TypeError(f"releases must be ident.Release objects, got {type(r).__name__}")
    if baseline is None:
        baseline = e2rfc.identify(releases, section)
    depth = _UNIT_DEPTH if depth is None else float(depth)
    measured = [_channels(r) for r in releases]
    before = [_simulate(r, section, baseline, ()) for r in releases]
    gap_before = gap(measured, before)

    coupling = zero_wind_coupling(releases, section, baseline)
    signals = [decay_signals(r, section) for r in releases]
    evidence, fits = _candidates(signals, section, depth)
    ranked = sorted(evidence, key=lambda ev: ev.cv_ratio)
    best = ranked[0]
    chosen = _clear_winner(best)
    verdicts = {}
    for ev in ranked:
        if ev is best and chosen:
            verdicts[ev.effect] = "chosen: explains the most held-out residual"
        elif ev is best:
            verdicts[ev.effect] = (f"best, but not clear of the baseline (needs <= {NONE_RATIO} "
                                   f"and {MIN_SIGMAS:g} standard errors)")
        else:
            verdicts[ev.effect] = f"rejected: {ev.cv_ratio / best.cv_ratio:.3g} x the best's"
    ranked = [_with_verdict(ev, verdicts[ev.effect]) for ev in ranked]
    runner_up = ranked[1].effect if len(ranked) > 1 else None
    per_release = np.zeros((len(releases), 2))
    per_release[:, 0] = [gap([m], [s]) for m, s in zip(measured, before, strict=True)]
    if not chosen:
        per_release[:, 1] = per_release[:, 0]
        return DiscrepancyReport(
            effect=None, parameters={}, uncertainty={}, gap_before=gap_before,
            gap_after=gap_before, gap_per_release=per_release, evidence=tuple(ranked),
            runner_up=runner_up, baseline=baseline, refitted=baseline, section=section,
            simulated_before=tuple(before), simulated_after=tuple(before),
            whiteness_before=whiteness(measured, before),
            whiteness_after=whiteness(measured, before), zero_wind_coupling=coupling)

    effect = _effect(best.effect, best.parameters, fits, depth)
    refitted, new_section, effects = _refit(best.effect, effect, releases, section, baseline,
                                            fits)
    if isinstance(effect, VortexShedding):
        # Shedding has a phase of its own in every release: the line fitted to each is added
        # to its simulated forces (the structure's response at the shedding frequency, far
        # above its modes, is negligible), rather than one phase for all.
        after = []
        for i, r in enumerate(releases):
            sim = _simulate(r, new_section, refitted, ())
            lift, moment = _vortex_line(r, section, fits[best.effect], i)
            after.append({**sim, "lift": sim["lift"] + lift, "moment": sim["moment"] + moment})
    else:
        after = [_simulate(r, new_section, refitted, effects) for r in releases]
    per_release[:, 1] = [gap([m], [s]) for m, s in zip(measured, after, strict=True)]
    return DiscrepancyReport(
        effect=best.effect, parameters=dict(best.parameters), uncertainty=dict(best.std),
        gap_before=gap_before, gap_after=gap(measured, after), gap_per_release=per_release,
        evidence=tuple(ranked), runner_up=runner_up, baseline=baseline, refitted=refitted,
        section=new_section, effects=effects, simulated_before=tuple(before),
        simulated_after=tuple(after), whiteness_before=whiteness(measured, before),
        whiteness_after=whiteness(measured, after), zero_wind_coupling=coupling)


@dataclass(frozen=True)
class Backbone:
    """Instantaneous amplitude, frequency and damping of one mode of a decay (Hilbert).

    Attributes
    ----------
    t : ndarray
        Time, s.
    amplitude : ndarray
        Envelope, in the signal's unit.
    frequency : ndarray
        Instantaneous frequency, Hz.
    damping : ndarray
        Instantaneous damping ratio ``-d ln(amplitude)/dt / (2 pi frequency)``.
    """

    t: FloatArray
    amplitude: FloatArray
    frequency: FloatArray
    damping: FloatArray


def backbone(t: FloatArray, x: FloatArray, f0: float, *, bandwidth: float = 0.35,
             min_fraction: float = 0.1) -> Backbone:
    """Return the backbone (frequency against amplitude) and damping curve of one mode.

    The signal is band-passed around ``f0`` (zero phase, +-``bandwidth`` of it) and its
    analytic signal taken (Hilbert transform); frequency and damping are averaged over one
    period, and the first and last two periods (filter transients) are dropped. A cubic spring
    bends the backbone, friction makes the damping grow as the amplitude falls, quadratic drag
    makes it grow with the amplitude; the linear model has flat curves.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Uniform time, s.
    x : ndarray, shape (n,)
        One channel of a decay.
    f0 : float
        The mode's frequency, Hz.
    bandwidth : float
        Half-width of the pass band, as a fraction of ``f0``.
    min_fraction : float
        Samples whose envelope is below this fraction of its largest value are dropped (at
        the noise's amplitude, frequency and damping are meaningless).
    """
    from scipy.signal import butter, hilbert, sosfiltfilt

    fs = 1.0 / float(np.median(np.diff(t)))
    sos = butter(2, [f0 * (1 - bandwidth), min(f0 * (1 + bandwidth), 0.45 * fs)], btype="band",
                 fs=fs, output="sos")
    period = max(int(round(fs / f0)), 1)
    # Even padding of three periods: a release from rest starts like a cosine, which an even
    # extension continues smoothly (odd padding leaves a transient of ~50 % in damping).
    band = sosfiltfilt(sos, x - np.mean(x), padtype="even", padlen=min(x.size - 1, 3 * period))
    z = hilbert(band)
    amplitude = np.abs(z)
    phase = np.unwrap(np.angle(z))
    kernel = np.ones(period) / period
    frequency = np.convolve(np.gradient(phase, t) / (2 * math.pi), kernel, mode="same")
    log_amp = np.log(np.maximum(amplitude, np.finfo(float).tiny))
    damping = -np.convolve(np.gradient(log_amp, t), kernel, mode="same") / (2 * math.pi
                                                                            * frequency)
    keep = np.zeros(t.size, dtype=bool)
    keep[2 * period:max(t.size - 2 * period, 2 * period)] = True
    if keep.any():
        keep &= amplitude >= min_fraction * float(np.max(amplitude[keep]))
    return Backbone(t=t[keep], amplitude=amplitude[keep], frequency=frequency[keep],
                    damping=damping[keep])


# -- candidates ---------------------------------------------------------------------------------

def _candidates(signals: list[DecaySignals], section: SectionModel,
                depth: float) -> tuple[list[CandidateEvidence], dict[str, Any]]:
    evidence = []
    fits: dict[str, Any] = {}
    for spec in STRUCTURAL_CANDIDATES:
        fit = fit_structural(signals, section, spec)
        fits[spec.name] = fit
        evidence.append(_structural_evidence(spec, fit))
    vortex = fit_vortex(signals, section)
    fits["vortex_shedding"] = vortex
    evidence.append(CandidateEvidence(
        effect="vortex_shedding",
        parameters={"strouhal": vortex.k * depth, "cl": vortex.cl, "cm": vortex.cm,
                    "phase": vortex.phase},
        std={"strouhal": vortex.k_std * depth, "cl": vortex.cl_std, "cm": vortex.cm_std,
             "phase": math.nan},
        units={"strouhal": "1", "cl": "1", "cm": "1", "phase": "rad"},
        cv_ratio=vortex.fit.cv_ratio, cv_ratio_se=vortex.fit.cv_ratio_se))
    assert {ev.effect for ev in evidence} == set(EFFECT_NAMES)
    return evidence, fits


def _structural_evidence(spec: CandidateSpec, fit: LinearFit) -> CandidateEvidence:
    return CandidateEvidence(
        effect=spec.name,
        parameters={p: float(v) for p, v in zip(spec.parameters, fit.theta, strict=True)},
        std={p: float(s) for p, s in zip(spec.parameters, fit.std, strict=True)},
        units=dict(zip(spec.parameters, spec.units, strict=True)),
        cv_ratio=fit.cv_ratio, cv_ratio_se=fit.cv_ratio_se)


def _clear_winner(best: CandidateEvidence) -> bool:
    improvement = 1.0 - best.cv_ratio
    return best.cv_ratio <= NONE_RATIO and improvement > MIN_SIGMAS * best.cv_ratio_se


def _with_verdict(ev: CandidateEvidence, verdict: str) -> CandidateEvidence:
    return CandidateEvidence(effect=ev.effect, parameters=ev.parameters, std=ev.std,
                             units=ev.units, cv_ratio=ev.cv_ratio, cv_ratio_se=ev.cv_ratio_se,
                             verdict=verdict)


def _effect(name: str, params: dict[str, float], fits: dict[str, Any],
            depth: float) -> Effect:
    """Build the named effect from fitted parameters (clipped to its physical range)."""
    if name == "coulomb_friction":
        return CoulombFriction(force_h=max(params["force_h"], 0.0),
                               moment_a=max(params["moment_a"], 0.0))
    if name == "quadratic_damping":
        return QuadraticDamping(c2_h=max(params["c2_h"], 0.0), c2_a=max(params["c2_a"], 0.0))
    if name == "cubic_stiffness":
        return CubicStiffness(k3_h=params["k3_h"], k3_a=params["k3_a"])
    if name == "channel_delay":
        return ChannelDelay(delay_s=max(params["delay_s"], 0.0))
    if name == "static_unbalance":
        return StaticUnbalance(S=params["S"])
    if name == "sensor_crosstalk":
        return SensorCrosstalk(h_from_alpha=params["h_from_alpha"],
                               alpha_from_h=params["alpha_from_h"])
    if name == "vortex_shedding":
        vortex: VortexFit = fits[name]
        return VortexShedding(strouhal=vortex.k * depth, depth=depth, cl=vortex.cl,
                              cm=vortex.cm, phase=vortex.phase)
    raise ValueError(f"unknown effect {name!r}")


# -- refit ----------------------------------------------------------------------------------------

def _refit(name: str, effect: Effect, releases: list[Release], section: SectionModel,
           baseline: RationalFunctionModel,
           fits: dict[str, Any]) -> tuple[RationalFunctionModel, SectionModel, tuple[Effect, ...]]:
    """Add the effect to the model; identify the aerodynamics again where the data change."""
    if isinstance(effect, (StaticUnbalance, CoulombFriction, QuadraticDamping, CubicStiffness)):
        # Structural: the measured forces, hence E2RFC's model, do not depend on them.
        return baseline, section, (effect,)
    if isinstance(effect, ChannelDelay):
        corrected = [_advance_forces(r, effect.delay_s) for r in releases]
    elif isinstance(effect, SensorCrosstalk):
        corrected = [_unmix(r, effect) for r in releases]
    elif isinstance(effect, VortexShedding):
        corrected = [_remove_vortex(r, section, fits[name], i) for i, r in enumerate(releases)]
    else:  # pragma: no cover - every name is handled above
        raise ValueError(f"unknown effect {name!r}")
    # E2RFC chooses the structure again: contaminated data can make it choose another one (a
    # shedding line cost a lag: the refit kept at the baseline's structure stayed 4x the noise
    # away from the measurements, re-chosen it is at the noise).
    model = e2rfc.identify(corrected, section)
    return model, section, (effect,)


def _advance_forces(r: Release, delay_s: float) -> Release:
    """Undo a recording delay: ``f(t) = f_recorded(t + delay)`` (the last samples held)."""
    t = r.t
    lift = np.interp(t + delay_s, t, r.lift)
    moment = np.interp(t + delay_s, t, r.moment)
    return Release(t=t, h=r.h, alpha=r.alpha, lift=lift, moment=moment, U=r.U, rho=r.rho,
                   meta=dict(r.meta))


def _unmix(r: Release, effect: SensorCrosstalk) -> Release:
    """Undo crosstalk: solve ``[h_m, a_m] = [[1, a], [b, 1]] [h, alpha]``."""
    mix = np.array([[1.0, effect.h_from_alpha], [effect.alpha_from_h, 1.0]])
    h, alpha = np.linalg.solve(mix, np.vstack([r.h, r.alpha]))
    return Release(t=r.t, h=h, alpha=alpha, lift=r.lift, moment=r.moment, U=r.U, rho=r.rho,
                   meta=dict(r.meta))


def _vortex_line(r: Release, section: SectionModel, vortex: VortexFit,
                 index: int) -> tuple[FloatArray, FloatArray]:
    """Return one release's fitted shedding line (own phase): lift (N/m), moment (N m/m)."""
    w = 2 * math.pi * vortex.k * r.U
    a = vortex.amplitudes[index]
    sn, cs = np.sin(w * r.t), np.cos(w * r.t)
    return (a[0] * sn + a[1] * cs) / section.B, a[2] * sn + a[3] * cs


def _remove_vortex(r: Release, section: SectionModel, vortex: VortexFit, index: int) -> Release:
    """Subtract the fitted shedding line from the forces."""
    lift, moment = _vortex_line(r, section, vortex, index)
    return Release(t=r.t, h=r.h, alpha=r.alpha, lift=r.lift - lift, moment=r.moment - moment,
                   U=r.U, rho=r.rho, meta=dict(r.meta))


# -- simulation -----------------------------------------------------------------------------------

def _channels(r: Release) -> dict[str, FloatArray]:
    return {"h": r.h, "alpha": r.alpha, "lift": r.lift, "moment": r.moment}


def _initial_state(r: Release) -> tuple[float, float]:
    """Return the position at the release: ``c0`` of ``c0 + c2 t^2 + c3 t^3`` (from rest)."""
    n = min(_START_SAMPLES, r.t.size)
    t = r.t[:n] - r.t[0]
    basis = np.column_stack([np.ones(n), t**2, t**3])
    coef, *_ = np.linalg.lstsq(basis, np.column_stack([r.h[:n], r.alpha[:n]]), rcond=None)
    return float(coef[0, 0]), float(coef[0, 1])


def _simulate(r: Release, section: SectionModel, model: RationalFunctionModel,
              effects: tuple[Effect, ...]) -> dict[str, FloatArray]:
    """Simulate one release from its own initial state, as measured (measurement effects on)."""
    h0m, a0m = _initial_state(r)
    h0, a0 = h0m, a0m
    for effect in effects:
        if isinstance(effect, SensorCrosstalk):  # the measured start is mixed: unmix it
            mix = np.array([[1.0, effect.h_from_alpha], [effect.alpha_from_h, 1.0]])
            h0, a0 = (float(x) for x in np.linalg.solve(mix, [h0m, a0m]))
    rho = section.rho if r.rho is None else r.rho
    sim = simulate_decay(section.replace(rho=rho), model, r.U, h0, a0, n=r.t.size, fs=r.fs,
                         effects=effects)
    return sim.measured
