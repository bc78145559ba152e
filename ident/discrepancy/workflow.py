"""Where the identified model and the measurements disagree, which physical effects are missing.

:func:`diagnose` confronts a linear model (the section's structure plus the rational-function
aerodynamics, identified by E2RFC unless given) with the releases it came from:

1. **Gap before**: every release is simulated with the model from its own initial state
   (:func:`ident.simulation.decay.simulate_decay`) and compared with what was measured:
   :func:`gap` is the RMS difference of h, alpha, lift and moment over all releases, each
   channel divided by its own RMS, averaged over the four channels.
2. **Forward selection** (:mod:`ident.discrepancy.effect_selection`): the named effects
   (``docs/reference/conventions.md``, "Named effects") are fitted to the data as physical terms
   with their own parameters (:mod:`ident.discrepancy._equation_error`: the residual of the
   structural equation for most, the forces' line above the motion's band for vortex shedding;
   :mod:`ident.discrepancy._force_fit`: the force equation for the aerodynamic nonlinearity, which
   the taps measure) and scored by the
   held-out fraction of that
   residual they explain. The best is added if it is clearly supported (``NONE_RATIO``,
   ``MIN_SIGMAS``) *and* the simulated gap shrinks by the margin of
   :mod:`ident.discrepancy.gap_rule` (the one rule every named effect passes, in every path;
   a step that fails it is undone and reported in :attr:`DiscrepancyReport.rejected`); then
   the next one is scored jointly with those chosen, and so on. Nothing clearly supported:
   the answer is None (no false alarms).
3. **Refit and gap after each step**: the effects are added to the model (a measurement effect
   (or a named aerodynamic nonlinearity's force) is taken out of the data and the aerodynamic
   model identified again, its structure chosen again; a structural one joins the structure;
   vortex forcing is taken out of the forces before E2RFC and added to each release's
   simulated forces), every release is simulated again, and the gap measured the same way.
4. **Honesty** (:mod:`ident.discrepancy.residual_check`): what is left of measured minus
   simulated is checked for a systematic part (beyond the white measurement noise); if there
   is one, the report is not ``explained`` and says where it is (channel, frequency,
   amplitudes, wind speeds).

Not responsible for: reading files (:mod:`ident.records.run_file`), plots or the command line
(``windrig diagnose`` in :mod:`daq`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from ident.discrepancy.coupling import ZeroWindCoupling, coupling_verdict, zero_wind_coupling
from ident.discrepancy.effect_selection import (
    CHANNELS,
    MAX_EFFECTS,
    MIN_SIGMAS,
    NONE_RATIO,
    CandidateEvidence,
    NamedEffect,
    channels,
    gap,
    select,
    simulate_channels,
)
from ident.discrepancy.gap_rule import GapStep
from ident.discrepancy.residual_check import ResidualFinding, locate_residual
from ident.identification import e2rfc
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.physics.effects import Effect
from ident.records.release import Release

__all__ = ["CHANNELS", "MAX_EFFECTS", "MIN_SIGMAS", "NONE_RATIO", "Backbone",
           "CandidateEvidence", "DiscrepancyReport", "NamedEffect", "ResidualFinding",
           "backbone", "diagnose", "gap", "whiteness"]

FloatArray = npt.NDArray[np.float64]

#: Depth used to express a fitted shedding frequency as a Strouhal number when none is given, m.
_UNIT_DEPTH = 1.0


@dataclass(frozen=True)
class DiscrepancyReport:
    """The outcome of :func:`diagnose`.

    Attributes
    ----------
    effect : str or None
        The first (most important) effect named, or None when the baseline explains the data.
    effects : tuple of NamedEffect
        Every effect named, in the order added, each with its parameters, uncertainty and the
        gap after it was added (empty for None).
    parameters, uncertainty : dict of str to float
        The named effects' fitted parameters (jointly) and their standard deviations, all
        effects' together (their parameter names are distinct; empty for None).
    gap_before, gap_after : float
        :func:`gap` of the baseline and of the final model (equal for None).
    gap_per_release : ndarray, shape (n_releases, 2)
        Each release's gap before and after.
    evidence : tuple of CandidateEvidence
        Every candidate of the first round (against the baseline), best first.
    rounds : tuple of tuple of CandidateEvidence
        Every round of the forward selection (:mod:`ident.discrepancy.effect_selection`), best
        first.
    runner_up : str or None
        The best candidate of the first round other than the effect named first (nothing
        named: the second best; a richer candidate rejected for containing the chosen one,
        a tube beside a delay, can be it).
    baseline : RationalFunctionModel
        The aerodynamic model of the baseline.
    refitted : RationalFunctionModel
        The aerodynamic model after the refit (the baseline's when nothing changed).
    section : SectionModel
        The structure the models are simulated with (as given: a static unbalance found is in
        :attr:`physics`, which the simulation adds to it).
    physics : tuple of Effect
        The effects the final model is simulated with (a shedding line is added per release).
    simulated_before, simulated_after : tuple of dict
        Per release, the four simulated channels (as measured) of the baseline and of the
        final model (the same objects for None).
    whiteness_before, whiteness_after : dict of str to float
        Per channel, the lag-1 autocorrelation of measured minus simulated (:func:`whiteness`):
        near 1 when the model misses something smooth, near 0 when only the measurement
        noise is left.
    explained : bool
        False when a systematic residual is left after the named effects
        (:func:`ident.discrepancy.residual_check.locate_residual`).
    unexplained : tuple of ResidualFinding
        Where that residual is, per channel (empty when explained).
    zero_wind_coupling : tuple of ZeroWindCoupling
        The heave and pitch modes' coupling that the baseline lacks, extrapolated to zero wind
        (:func:`ident.discrepancy.coupling.zero_wind_coupling`; empty when it cannot be estimated).
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
    effects: tuple[NamedEffect, ...] = ()
    rounds: tuple[tuple[CandidateEvidence, ...], ...] = field(default=(), repr=False)
    physics: tuple[Effect, ...] = ()
    simulated_before: tuple[dict[str, FloatArray], ...] = field(default=(), repr=False)
    simulated_after: tuple[dict[str, FloatArray], ...] = field(default=(), repr=False)
    whiteness_before: dict[str, float] = field(default_factory=dict)
    whiteness_after: dict[str, float] = field(default_factory=dict)
    explained: bool = True
    unexplained: tuple[ResidualFinding, ...] = ()
    zero_wind_coupling: tuple[ZeroWindCoupling, ...] = ()

    @property
    def rejected(self) -> tuple[tuple[str, GapStep], ...]:
        """Return every candidate tried and undone, with its gaps, in the order tried.

        A candidate clear on the held-out evidence is tried as the next named effect; if the
        simulated gap did not shrink by the margin (:mod:`ident.discrepancy.gap_rule`) the
        step is undone and it is listed here, with the gap before and the gap it left.
        """
        return tuple((ev.effect, ev.trial) for evidence in self.rounds for ev in evidence
                     if ev.trial is not None and not ev.trial.accepted)

    def summary(self) -> str:
        """Return the report as text: the sequence, the gap, what is left, the evidence."""
        lines = []
        if not self.effects:
            lines.append("effect: none (no named effect is clearly supported)")
        for i, step in enumerate(self.effects, 1):
            params = ", ".join(f"{k} = {v:.4g} +- {step.uncertainty.get(k, math.nan):.2g}"
                               for k, v in step.parameters.items())
            lines.append(f"effect {i}: {step.name} ({params}); gap after {step.gap_after:.4f}")
        shrink = (1 - self.gap_after / self.gap_before) if self.gap_before > 0 else 0.0
        lines.append(f"gap: {self.gap_before:.4f} before, {self.gap_after:.4f} after "
                     f"({shrink:+.0%} shrink)" if self.effects
                     else f"gap: {self.gap_before:.4f}")
        if self.explained:
            lines.append("explained: yes (no systematic residual is left)")
        else:
            lines.append("explained: NO, a systematic residual is left that no named effect "
                         "explains:")
            lines.extend(f"  {f.text()}" for f in self.unexplained)
        lines.extend(f"tried and undone: {name} ({step.text()})"
                     for name, step in self.rejected)
        lines.append(f"runner-up: {self.runner_up}")
        lines.append("residual lag-1 autocorrelation (near 0: only white noise left): " + ", ".join(
            f"{c} {self.whiteness_before.get(c, math.nan):.2f}"
            + (f" -> {self.whiteness_after.get(c, math.nan):.2f}" if self.effects else "")
            for c in CHANNELS))
        lines.append("coupling at zero wind (measured minus baseline, extrapolated): "
                     + coupling_verdict(self.zero_wind_coupling))
        lines.extend(f"  {c.text()}" for c in self.zero_wind_coupling)
        for k, evidence in enumerate(self.rounds or (self.evidence,), 1):
            lines.append(f"round {k}: {'candidate':<20}{'held-out':>10}{'+-':>8}  verdict")
            for ev in evidence:
                lines.append(f"         {ev.effect:<20}{ev.cv_ratio:>10.4f}"
                             f"{ev.cv_ratio_se:>8.4f}  {ev.verdict}")
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


def diagnose(releases: Sequence[Release], section: SectionModel,
             baseline: RationalFunctionModel | None = None, *,
             depth: float | None = None) -> DiscrepancyReport:
    """Find the physical effects the linear model misses, add them, refit, report the gap.

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
        # Refined IV in turbulence (plain E2RFC without holds): an unnamed effect's misfit can
        # look like a random response, which the closed-loop default would model as buffeting
        # and so hide from the search; the effects were validated on this estimator.
        baseline = e2rfc.identify(releases, section, turbulent_estimator="iv")
    depth = _UNIT_DEPTH if depth is None else float(depth)
    measured = [channels(r) for r in releases]
    before = [simulate_channels(r, section, baseline, ()) for r in releases]
    gap_before = gap(measured, before)
    coupling = zero_wind_coupling(releases, section, baseline)
    chosen = select(releases, section, baseline, before, depth)
    after = list(chosen.simulated)
    per_release = np.zeros((len(releases), 2))
    per_release[:, 0] = [gap([m], [s]) for m, s in zip(measured, before, strict=True)]
    per_release[:, 1] = [gap([m], [s]) for m, s in zip(measured, after, strict=True)]
    first = chosen.rounds[0]
    findings = locate_residual(releases, after, before)
    parameters: dict[str, float] = {}
    uncertainty: dict[str, float] = {}
    for step in chosen.steps:
        parameters.update(step.parameters)
        uncertainty.update(step.uncertainty)
    return DiscrepancyReport(
        effect=chosen.steps[0].name if chosen.steps else None, parameters=parameters,
        uncertainty=uncertainty, gap_before=gap_before, gap_after=chosen.gap,
        gap_per_release=per_release, evidence=first, rounds=chosen.rounds,
        runner_up=_runner_up(first, chosen.steps[0].name if chosen.steps else None),
        baseline=baseline,
        refitted=chosen.model, section=section, effects=chosen.steps, physics=chosen.physics,
        simulated_before=tuple(before), simulated_after=tuple(after),
        whiteness_before=whiteness(measured, before), whiteness_after=whiteness(measured, after),
        explained=not findings, unexplained=findings, zero_wind_coupling=coupling)


def _runner_up(first: Sequence[CandidateEvidence], named: str | None) -> str | None:
    """Return the best first-round candidate other than ``named`` (None named: the second)."""
    others = [ev.effect for ev in first if ev.effect != named]
    if named is None:
        return first[1].effect if len(first) > 1 else None
    return others[0] if others else None


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
