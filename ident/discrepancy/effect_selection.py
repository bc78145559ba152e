"""Forward selection of the named effects that explain a gap (the discrepancy workflow's core).

:func:`select` adds the named effects (``docs/reference/conventions.md``, "Named effects") to the
model one at a time, in rounds:

1. **Score**: every candidate not yet chosen is fitted *jointly* with the effects already chosen
   (their equation-error regressor families are all linear in the parameters,
   :mod:`ident.discrepancy._equation_error`, so the joint fit is one least-squares problem) and
   scored by its held-out residual relative to that of the chosen effects alone (the same chunks,
   paired). Vortex shedding has a residual of its own (the forces above the motion's band), so its
   score does not change from round to round; the aerodynamic nonlinearity has the force equation
   (:mod:`ident.discrepancy._force_fit`), scored each round on the data with the measurement effects
   found so far taken out.
2. **Clear?** A candidate qualifies if it leaves at most ``NONE_RATIO`` of the held-out residual
   and its improvement is ``MIN_SIGMAS`` standard errors clear of nothing, or ``LOOK_SIGMAS``
   when what the model leaves is not white
   (:func:`ident.discrepancy.residual_check.systematic_left`) (a base vibration
   also needs a line that stands out, :data:`ident.discrepancy._base_fit.MIN_PROMINENCE`; a
   candidate that contains another, a tube containing a delay, must be clear of that one fitted
   exactly; friction and drag must be clear of a linear damping of the structure, which is not
   in the library; and the parameters must be in range, a tube needs a resonance).
3. **Gap**: the best qualifying candidate is added: all chosen effects take the joint fit's
   parameters, the measurement effects are taken out of the data, the aerodynamic model is
   identified again by E2RFC (when the data changed, and beside the effects that bend the
   decays, on the releases with their share taken out), every release is simulated again and the
   gap (:func:`gap`) measured. If the gap did not shrink by the margin of
   :mod:`ident.discrepancy.gap_rule` (``GAP_MARGIN`` of the gap white noise leaves), the step is
   undone (its verdict keeps both gaps) and the next qualifying one is tried; the undone one is
   tried again in a later round, once the model has changed. A candidate that contains one
   already named (a tube, a delay) is tried in its place.
4. **Two at once** when nothing was named in a round and what is left is not white: the two
   best candidates undone in the round are tried *together*: named together only if together
   they shrink the gap by the margin and each is needed (the gap with the other alone is
   larger than with both by the margin). Nothing left: stop.
5. **Second search**: a named effect that contains another (a tube) must still be clear of the
   simpler one beside the effects named after it; if not, the selection runs again without it.

So an effect whose addition does not clearly reduce the simulated gap is never named, and the
gap after each step is smaller than before it by the margin.

Longer than 600 lines: the selection loop, the joint fits of the candidates it scores and the
simulation of each trial model share one state (the fitted parameters of every named effect,
the shedding and floor lines); split apart, every part would pass all of it back and forth.
The per-release corrections are in :mod:`ident.discrepancy._corrections`.

Not responsible for: the report, the whiteness and location of what is left
(:mod:`ident.discrepancy.workflow`, :mod:`ident.discrepancy.residual_check`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from ident.discrepancy._base_fit import (
    MIN_PROMINENCE,
    BaseLine,
    accelerations,
    base_columns,
    find_line,
    modal_peaks,
)
from ident.discrepancy._corrections import (
    channels,
    refit_beside,
    release_vortex,
    remove_aero,
    simulate_channels,
    take_out,
)
from ident.discrepancy._equation_error import (
    LOWPASS_FACTOR,
    STRUCTURAL_CANDIDATES,
    StructuralProblem,
    VortexFit,
    beside_linear_damping,
    chunk_ids,
    compare_held_out,
    decay_signals,
    fit_linear,
    fit_vortex,
    held_out_sse,
    passband_gain,
    structural_problem,
)
from ident.discrepancy._force_fit import AerodynamicFit, fit_aerodynamic, force_problem
from ident.discrepancy.gap_rule import GapStep, judge, noise_gap
from ident.discrepancy.residual_check import systematic_left
from ident.identification import e2rfc
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.physics.effects import (
    AerodynamicNonlinearity,
    BaseVibration,
    ChannelDelay,
    CoulombFriction,
    CubicStiffness,
    Effect,
    QuadraticDamping,
    SensorCrosstalk,
    StaticUnbalance,
    TubingDistortion,
    VortexShedding,
)
from ident.records.release import Release
from ident.simulation.decay import CHANNELS

__all__ = ["CHANNELS", "MAX_EFFECTS", "MIN_SIGMAS", "NONE_RATIO", "CandidateEvidence",
           "NamedEffect", "Selection", "channels", "gap", "select", "simulate_channels"]

FloatArray = npt.NDArray[np.float64]

#: A candidate must leave at most this fraction of the held-out residual (explain >= 2 %).
NONE_RATIO = 0.98
#: ... and its improvement must exceed this many standard errors (over the chunks).
MIN_SIGMAS = 2.0
#: When what the model leaves is not white, a candidate is tried (the gap rule decides) if its
#: improvement is this many standard errors clear of nothing: an amplitude-dependent force has
#: its evidence in the first seconds of the fastest releases, a few chunks, so its standard
#: error over the chunks is large (an aerodynamic nonlinearity beside friction: 0.33 +- 0.36; a
#: cubic spring beside a delay that stands for a tube: 0.73 +- 0.17).
LOOK_SIGMAS = 1.0
#: At most this many effects are named (more than three at once is not a diagnosis).
MAX_EFFECTS = 4
_VORTEX = "vortex_shedding"
_BASE = "base_vibration"
_AERO = "aerodynamic_nonlinearity"
_TUBING = "tubing_distortion"
#: A candidate that contains another (a second-order tube far below its resonance is a delay)
#: must also be clear of it, in the same round, to be chosen.
_CONTAINS = {_TUBING: "channel_delay"}
#: Named by how their damping changes with the amplitude, so each must be clear of a linear
#: damping (:data:`ident.discrepancy._equation_error.LINEAR_DAMPING`, outside the library):
#: else an unknown viscous damping was named drag, and beside a friction "explained".
_AMPLITUDE_DAMPING = frozenset({"coulomb_friction", "quadratic_damping"})
_UNITS = {spec.name: dict(zip(spec.parameters, spec.units, strict=True))
          for spec in STRUCTURAL_CANDIDATES}
_UNITS[_VORTEX] = {"strouhal": "1", "cl": "1", "cm": "1", "phase": "rad"}
_UNITS[_BASE] = {"frequency_hz": "Hz", "accel": "m/s^2", "phase": "rad"}
_UNITS[_AERO] = {"e_h": "1", "e_a": "1"}
_UNITS[_TUBING] = {"frequency_hz": "Hz", "damping": "1"}


@dataclass(frozen=True)
class CandidateEvidence:
    """What the data say about one candidate effect in one round of the selection.

    Attributes
    ----------
    effect : str
        One of the named effects.
    parameters, std : dict of str to float
        Fitted parameters (jointly with the effects already chosen) and their standard
        deviations (SI units, see :attr:`units`).
    units : dict of str to str
    cv_ratio : float
        Held-out residual with the candidate over that without it, the effects already chosen
        fitted in both (< 1: it predicts residual it was not fitted to).
    cv_ratio_se : float
        Standard error of ``cv_ratio`` over the chunks.
    verdict : str
        Why it was chosen or rejected, one line.
    trial : GapStep or None
        The simulated gaps without and with it, when it was tried as the next named effect
        (:func:`ident.discrepancy.gap_rule.judge`: ``trial.accepted`` is whether it was named);
        None when it was not tried (not clear, or another was chosen first).
    """

    effect: str
    parameters: dict[str, float]
    std: dict[str, float]
    units: dict[str, str]
    cv_ratio: float
    cv_ratio_se: float
    verdict: str = ""
    trial: GapStep | None = None


@dataclass(frozen=True)
class NamedEffect:
    """One effect the selection added, with the gap after it was added.

    Attributes
    ----------
    name : str
        The effect's name.
    effect : Effect
        The effect with its final parameters (the joint fit of all named effects).
    parameters, uncertainty : dict of str to float
        Final parameters and their standard deviations (SI units, see :attr:`units`).
    units : dict of str to str
    cv_ratio, cv_ratio_se : float
        Its held-out score in the round it was added.
    gap_after : float
        :func:`gap` of the model with this effect and those before it.
    trial : GapStep or None
        The gap rule's step that named it (two effects named together share one).
    """

    name: str
    effect: Effect
    parameters: dict[str, float]
    uncertainty: dict[str, float]
    units: dict[str, str]
    cv_ratio: float
    cv_ratio_se: float
    gap_after: float
    trial: GapStep | None = None


@dataclass(frozen=True)
class Selection:
    """The outcome of :func:`select`.

    Attributes
    ----------
    steps : tuple of NamedEffect
        The effects in the order added (empty: the baseline explains the data).
    rounds : tuple of tuple of CandidateEvidence
        Every round's candidates, best first.
    model : RationalFunctionModel
        The aerodynamic model of the final step (the baseline's with no measurement effect).
    physics : tuple of Effect
        The effects the final model is simulated with (a vortex line is added per release).
    simulated : tuple of dict
        Per release, the four channels of the final model (as measured).
    gap : float
        Their :func:`gap`.
    """

    steps: tuple[NamedEffect, ...]
    rounds: tuple[tuple[CandidateEvidence, ...], ...]
    model: RationalFunctionModel
    physics: tuple[Effect, ...]
    simulated: tuple[dict[str, FloatArray], ...]
    gap: float


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


def select(releases: Sequence[Release], section: SectionModel, baseline: RationalFunctionModel,
           before: Sequence[dict[str, FloatArray]], depth: float) -> Selection:
    """Add named effects while the held-out evidence and the gap support them (module doc).

    Parameters
    ----------
    releases : sequence of Release
        The measured decays.
    section : SectionModel
        The structure as known.
    baseline : RationalFunctionModel
        The aerodynamic model without effects.
    before : sequence of dict
        The baseline's simulated channels per release (as :func:`simulate_channels`).
    depth : float
        Section depth, m (a shedding frequency is reported as ``St = k D``).
    """
    search = _Search(list(releases), section, baseline, tuple(before), depth)
    excluded: dict[str, str] = {}
    while True:
        selection, demoted = search.run(excluded)
        if demoted is None:
            return selection
        # A richer effect named before its look-alike's rival was found (a tube that took a
        # crosstalk's share while the delay it contains could not): search again without it.
        excluded[demoted[0]] = demoted[1]


_Accepted = tuple[tuple[str, ...], "State", "Params", StructuralProblem, GapStep]


class _Search:
    """One forward selection over fixed data (module doc); :meth:`run` does it."""

    def __init__(self, releases: list[Release], section: SectionModel,
                 baseline: RationalFunctionModel, before: tuple[dict[str, FloatArray], ...],
                 depth: float) -> None:
        self.releases, self.section, self.baseline = releases, section, baseline
        self.before, self.depth = before, depth
        self.measured = [channels(r) for r in releases]
        self.vortex = fit_vortex([decay_signals(r, section) for r in releases], section)
        self.line = _find_line(_problem(releases, section, {}, self.vortex, None), releases,
                               section)
        self.noise_before = noise_gap(releases, before)

    def run(self, excluded: dict[str, str]) -> tuple[Selection, tuple[str, str] | None]:
        """Select; return the selection, or the effect to exclude and why (module doc)."""
        releases, section, vortex, line = self.releases, self.section, self.vortex, self.line
        chosen: list[str] = []
        added: list[tuple[str, float, float, GapStep]] = []  # name, cv ratio, se, its step
        params: Params = {}
        problem = _problem(releases, section, params, vortex, line)
        remaining = [spec.name for spec in STRUCTURAL_CANDIDATES] + [_BASE, _VORTEX, _AERO]
        state: State = (self.baseline, (), self.before, gap(self.measured, self.before))
        rounds: list[tuple[CandidateEvidence, ...]] = []
        aero = _aerodynamic(releases, section, params, vortex, self.baseline)
        while remaining and len(chosen) < MAX_EFFECTS:
            aero = _aerodynamic(releases, section, params, vortex, self.baseline)
            scored = self._score(problem, chosen, remaining, aero)
            against = "the baseline" if not chosen else "the model with " + " + ".join(chosen)
            verdicts: dict[str, str] = {}
            trials: dict[str, GapStep] = {}
            accepted: _Accepted | None = None
            undone: list[str] = []  # tried alone, undone by the gap rule (best first)
            # What is left is not white: a candidate is tried at fewer standard errors (the
            # gap rule unchanged decides).
            white = not systematic_left(releases, state[2])
            sigmas = MIN_SIGMAS if white else LOOK_SIGMAS
            for name, ratio, se in scored:
                if accepted is not None:
                    verdicts[name] = f"rejected: {ratio / scored[0][1]:.3g} x the best's"
                    continue
                if name in excluded:
                    verdicts[name] = excluded[name]
                    continue
                reason = self._gate(name, ratio, se, chosen, remaining, aero, sigmas,
                                    problem)
                if reason is None:
                    accepted = self._try_alone(name, chosen, state, aero, verdicts, trials,
                                               undone, len(rounds) + 1,
                                               second=not _clear(ratio, se))
                elif reason == "":
                    verdicts[name] = ((f"best, but not clear of {against}" if not verdicts
                                       else f"not clear of {against}")
                                      + f" (needs <= {NONE_RATIO} and {sigmas:g} standard "
                                      "errors)")
                else:
                    verdicts[name] = reason
            if (accepted is None and not white and len(undone) >= 2
                    and len(chosen) + 2 <= MAX_EFFECTS):
                accepted = self._try_pair(undone[:2], chosen, state, aero, verdicts, trials,
                                          len(rounds) + 1)
            # Each candidate's parameters as scored: one pass on this round's data, jointly
            # with the effects chosen (a chosen measurement effect's columns fit what is left).
            seen = {name: _unpack(problem, vortex, line, [*chosen, name], self.depth, params,
                                  aero)[name] for name, *_ in scored}
            rounds.append(tuple(
                CandidateEvidence(effect=name, parameters=seen[name].values, std=seen[name].std,
                                  units=_UNITS[name], cv_ratio=ratio, cv_ratio_se=se,
                                  verdict=verdicts[name], trial=trials.get(name))
                for name, ratio, se in scored))
            if accepted is None:
                break
            names, state, params, problem, step = accepted
            for name in names:
                ratio, se = next((r, e) for n, r, e in scored if n == name)
                replaced = _CONTAINS.get(name)
                if replaced in chosen:  # the richer effect takes the simpler one's place
                    chosen.remove(replaced)
                    added = [entry for entry in added if entry[0] != replaced]
                chosen.append(name)
                remaining.remove(name)
                added.append((name, ratio, se, step))
        demoted = self._demote(chosen, excluded, aero)
        model, physics, simulated, gap_final = state
        effects = {e.name: e for e in _effects(params, vortex, self.depth)}
        steps = tuple(NamedEffect(name=name, effect=effects[name],
                                  parameters=params[name].values,
                                  uncertainty=params[name].std, units=_UNITS[name],
                                  cv_ratio=ratio, cv_ratio_se=se, gap_after=step.after,
                                  trial=step)
                      for name, ratio, se, step in added)
        return (Selection(steps=steps, rounds=tuple(rounds), model=model, physics=physics,
                          simulated=simulated, gap=gap_final), demoted)

    def _score(self, problem: StructuralProblem, chosen: list[str], remaining: list[str],
               aero: AerodynamicFit) -> list[tuple[str, float, float]]:
        """Return every remaining candidate's held-out ratio and its standard error, best first."""
        chunk_id, _ = chunk_ids(problem.y, problem.chunks)
        current = held_out_sse(problem.y, problem.design(_structural(chosen)), problem.chunks)
        scored = []
        for name in remaining:
            if name == _VORTEX:
                scored.append((name, self.vortex.fit.cv_ratio, self.vortex.fit.cv_ratio_se))
            elif name == _AERO:
                scored.append((name, aero.cv_ratio, aero.cv_ratio_se))
            else:
                sse = held_out_sse(problem.y, problem.design(_structural([*chosen, name])),
                                   problem.chunks)
                scored.append((name, *compare_held_out(current, sse, chunk_id)))
        return sorted(scored, key=lambda item: item[1])

    def _gate(self, name: str, ratio: float, se: float, chosen: list[str],
              remaining: list[str], aero: AerodynamicFit, sigmas: float,
              problem: StructuralProblem) -> str | None:
        """Return why a candidate is not tried: "" when not clear, None when it is tried."""
        if not _clear(ratio, se, sigmas):
            return ""
        if name in _AMPLITUDE_DAMPING:
            # Significance only (no NONE_RATIO): half a realistic drag explains 0.4-0.7 % beside it.
            beside, beside_se, zeta = beside_linear_damping(problem, _structural(chosen), name,
                                                            self.section)
            if not (1.0 - beside) > sigmas * beside_se:
                return (f"rejected: not clear of a linear damping of the structure, which is "
                        f"not in the library ({beside:.4f} +- {beside_se:.4f} of the held-out "
                        f"residual beside it; fitted, it adds {zeta[0]:+.2g} +- {zeta[2]:.1g} "
                        f"to zeta_h and {zeta[1]:+.2g} +- {zeta[3]:.1g} to zeta_a)")
        if name == _BASE and self.line.prominence < MIN_PROMINENCE:
            return (f"rejected: no line stands out in the heave residual (peak "
                    f"{self.line.prominence:.3g} x the median, needs {MIN_PROMINENCE:g})")
        simpler = _CONTAINS.get(name)
        if simpler is not None and simpler in remaining:
            beyond = _beyond(self.releases, self.section, self.vortex, self.line, chosen,
                             simpler, name, self.depth, aero)
            if not _clear(*beyond):
                return (f"rejected: not clear of {simpler}, which it contains "
                        f"({beyond[0]:.4f} +- {beyond[1]:.4f} of the held-out residual with "
                        f"{simpler} taken out)")
        return None

    def _trial(self, names: list[str], state: State,
               aero: AerodynamicFit) -> tuple[GapStep, State, Params, StructuralProblem] | str:
        """Fit ``names`` jointly, simulate, judge against ``state``; or say why it cannot be."""
        releases = self.releases
        params, problem = _joint(releases, self.section, self.vortex, self.line, names,
                                 self.depth, aero)
        outside = [other for other, fitted in params.items()
                   if not all(math.isfinite(x) for x in fitted.values.values())]
        if outside:
            # Fitted jointly, an effect chosen before can lose its physical range too (a
            # tube's resonance beside a new crosstalk): the step cannot be taken.
            return ("rejected: its fitted parameters are outside their range"
                    if outside[0] == names[-1] else
                    f"rejected: beside it, the parameters of {outside[0]} are outside their "
                    "range")
        trial = _apply(releases, self.section, self.baseline, params, self.vortex, self.depth)
        # The one rule (ident.discrepancy.gap_rule): named only if the simulated gap shrinks
        # by the margin; otherwise the step is undone (state stays).
        finite = math.isfinite(trial[3])
        noise = min(self.noise_before, noise_gap(releases, trial[2])) if finite \
            else self.noise_before
        per_release = ([(gap([m], [b]), gap([m], [a])) for m, b, a
                        in zip(self.measured, state[2], trial[2], strict=True)] if finite else [])
        return judge(state[3], trial[3], noise, per_release), trial, params, problem

    def _try_alone(self, name: str, chosen: list[str], state: State, aero: AerodynamicFit,
                   verdicts: dict[str, str], trials: dict[str, GapStep], undone: list[str],
                   round_no: int, second: bool = False) -> _Accepted | None:
        """Try one candidate as the next named effect; record its verdict.

        A candidate that contains an effect already named (a tube, a delay) is tried in its
        place: fitted beside each other the two are degenerate.
        """
        result = self._trial([*_without_contained(chosen, [name]), name], state, aero)
        if isinstance(result, str):
            verdicts[name] = result
            return None
        step, trial, params, problem = result
        trials[name] = step
        why = ("not clear of the model by the held-out residual (but at "
               f"{LOOK_SIGMAS:g} standard error) and what is left is not white"
               if second else "explains the most held-out residual")
        if step.accepted:
            instead = (f" in place of {_CONTAINS[name]}, which it contains"
                       if _CONTAINS.get(name) in chosen else "")
            verdicts[name] = f"chosen in round {round_no}{instead}: {why}; {step.text()}"
            return (name,), trial, params, problem, step
        verdicts[name] = ("tried as what is left is not white; " if second else "") + (
            f"dropped: the simulated gap did not shrink clearly ({step.text()})")
        undone.append(name)
        return None

    def _try_pair(self, pair: list[str], chosen: list[str], state: State,
                  aero: AerodynamicFit, verdicts: dict[str, str],
                  trials: dict[str, GapStep], round_no: int) -> _Accepted | None:
        """Try the two best undone candidates together (module doc, "Two at once")."""
        result = self._trial([*_without_contained(chosen, pair), *pair], state, aero)
        if isinstance(result, str):
            for name in pair:
                verdicts[name] += f"; tried with {_other(pair, name)}: {result}"
            return None
        step, trial, params, problem = result
        # Each of the two must be needed: without it (the other alone, tried above) the gap
        # is larger by the margin.
        alone = {name: judge(trials[_other(pair, name)].after, step.after, step.noise)
                 for name in pair}
        if step.accepted and all(s.accepted for s in alone.values()):
            for name in pair:
                verdicts[name] = (f"chosen in round {round_no} together with "
                                  f"{_other(pair, name)} (neither alone shrank the gap by the "
                                  f"margin; both together: {step.text()}; without it: "
                                  f"{alone[name].text()})")
                trials[name] = step
            return tuple(pair), trial, params, problem, step
        for name in pair:
            verdicts[name] += (f"; with {_other(pair, name)} together: {step.text()}, without "
                               f"it: {alone[name].text()}: not named")
        return None

    def _demote(self, chosen: list[str], excluded: dict[str, str],
                aero: AerodynamicFit) -> tuple[str, str] | None:
        """Return a named richer effect not clear of its simpler look-alike beside the others."""
        for richer, simpler in _CONTAINS.items():
            others = [c for c in chosen if c != richer]
            if richer not in chosen or simpler in chosen or richer in excluded or not others:
                continue
            ratio, se = _beyond(self.releases, self.section, self.vortex, self.line, others,
                                simpler, richer, self.depth, aero)
            if not _clear(ratio, se):
                return richer, (f"rejected: beside {' + '.join(others)} (named after it in a "
                                f"first pass) not clear of {simpler}, which it contains "
                                f"({ratio:.4f} +- {se:.4f} of the held-out residual with "
                                f"{simpler} taken out)")
        return None


def _values(params: Params) -> dict[str, dict[str, float]]:
    return {name: fitted.values for name, fitted in params.items()}


def _without_contained(chosen: list[str], new: list[str]) -> list[str]:
    """Return the effects chosen less those that one of ``new`` contains."""
    return [c for c in chosen if c not in {_CONTAINS.get(n) for n in new}]


def _other(pair: list[str], name: str) -> str:
    return pair[1] if pair[0] == name else pair[0]


def _structural(names: Sequence[str]) -> list[str]:
    return [n for n in names if n not in (_VORTEX, _AERO)]


def _beyond(releases: list[Release], section: SectionModel, vortex: VortexFit, line: BaseLine,
            chosen: Sequence[str], simpler: str, richer: str, depth: float,
            aero: AerodynamicFit) -> tuple[float, float]:
    """Held-out ratio (and its standard error) of ``richer`` beyond ``simpler``, which it contains.

    ``simpler`` is fitted with the effects chosen (a measurement effect exactly, taken out of
    the data: a delay's linear column alone misses its second-order term, which a tube's
    columns would take for a tube); then ``richer`` is scored against that.
    """
    _, problem = _joint(releases, section, vortex, line, [*chosen, simpler], depth, aero)
    ids, _ = chunk_ids(problem.y, problem.chunks)
    base = _structural([*chosen, simpler])
    return compare_held_out(held_out_sse(problem.y, problem.design(base), problem.chunks),
                            held_out_sse(problem.y, problem.design([*base, richer]),
                                         problem.chunks), ids)


def _aerodynamic(releases: list[Release], section: SectionModel, params: Params,
                 vortex: VortexFit, model: RationalFunctionModel) -> AerodynamicFit:
    """Fit the aerodynamic-nonlinearity candidate on the data, measurement effects taken out."""
    corrected = take_out(releases, section, _values(params), vortex, notch_line=True,
                         untube_forces=True)
    signals = [decay_signals(r, section) for r in corrected]
    return fit_aerodynamic(force_problem(signals, section, model))


def _clear(ratio: float, se: float, sigmas: float = MIN_SIGMAS) -> bool:
    return ratio <= NONE_RATIO and (1.0 - ratio) > sigmas * se


class Fitted(NamedTuple):
    """One effect's fitted parameters, their standard deviations, and per-release values.

    ``per_release`` is, for a base vibration, each release's acceleration amplitude (m/s^2) and
    phase (rad), shape (n_releases, 2); None for the others.
    """

    values: dict[str, float]
    std: dict[str, float]
    per_release: FloatArray | None = None


Params = dict[str, Fitted]
#: The named effects that act on the structure (its equation of motion), not on the air or the
#: measurement: E2RFC is identified again beside them
#: (:func:`ident.discrepancy._corrections.refit_beside`).
_STRUCTURE_NAMES = frozenset({"coulomb_friction", "quadratic_damping", "cubic_stiffness",
                              "static_unbalance"})
#: Gauss-Newton passes of a joint fit with a measurement effect (see :func:`_joint`).
_PASSES = 4


def _problem(releases: list[Release], section: SectionModel, params: Params,
             vortex: VortexFit, line: BaseLine | None) -> StructuralProblem:
    """Return the structural problem of the releases, the measurement effects taken out.

    With ``line``, the base-vibration candidate's columns are added
    (:mod:`ident.discrepancy._base_fit`).
    """
    corrected = take_out(releases, section, _values(params), vortex)
    signals = [decay_signals(r, section) for r in corrected]
    problem = structural_problem(signals, section)
    if line is not None:
        gain = passband_gain(signals[0], line.frequency_hz)
        problem.X[_BASE] = [base_columns(problem.t, line, section, problem.scale, i, gain)
                            for i in range(len(problem.t))]
    return problem


def _find_line(problem: StructuralProblem, releases: list[Release],
               section: SectionModel) -> BaseLine:
    """Find the base-vibration candidate's line in the baseline's heave residual."""
    heave = [(y.reshape(-1, 2)[:, 0] * problem.scale[0]) for y in problem.y]
    signals = [decay_signals(r, section) for r in releases]
    modes = [modal_peaks(sig.t, sig.q) for sig in signals]
    cutoff = min(LOWPASS_FACTOR * max(section.fh, section.fa), 0.4 * releases[0].fs)
    return find_line(problem.t, heave, modes, cutoff)


def _joint(releases: list[Release], section: SectionModel, vortex: VortexFit,
           line: BaseLine, names: Sequence[str], depth: float,
           aero: AerodynamicFit) -> tuple[Params, StructuralProblem]:
    """Fit the effects ``names`` jointly; return their parameters and the corrected problem.

    A delay and a crosstalk enter the equation error to first order only (``tau f'``); fitted
    once, a 10 ms delay came out 7 % short and took a friction moment 30 % low with it. So the
    measurement effects found are taken out of the data, the signals derived again and the
    joint fit repeated, their columns now fitting what is left of them (added to the total):
    Gauss-Newton on the exact correction, a few passes.
    """
    params: Params = {}
    measurement = {"channel_delay", "sensor_crosstalk"} & set(names)
    for _ in range(_PASSES if measurement else 1):
        problem = _problem(releases, section, params, vortex, line)
        new = _unpack(problem, vortex, line, names, depth, params, aero)
        step = max((abs(new[n].values[k] - params[n].values[k]) / max(new[n].std[k], 1e-300)
                    for n in measurement if n in params for k in new[n].values),
                   default=math.inf)
        params = new
        if step < 0.1:  # the last pass moved the totals by a tenth of their uncertainty
            break
    return params, (_problem(releases, section, params, vortex, line) if measurement
                    else problem)


def _unpack(problem: StructuralProblem, vortex: VortexFit, line: BaseLine,
            names: Sequence[str], depth: float, totals: Params,
            aero: AerodynamicFit) -> Params:
    """One joint least-squares pass on ``problem``; measurement effects add to ``totals``."""
    out: Params = {}
    structural = _structural(names)
    if structural:
        fit = fit_linear(problem.y, problem.design(structural), problem.chunks)
        i = 0
        specs = {spec.name: spec for spec in STRUCTURAL_CANDIDATES}
        for name in structural:
            if name == _BASE:
                n = problem.X[_BASE][0].shape[1]
                out[name] = _base_params(line, fit.theta[i:i + n], fit.std[i:i + n])
                i += n
                continue
            p = specs[name].parameters
            if name == _TUBING:
                out[name] = _tubing_params(fit.theta[i:i + 2], fit.std[i:i + 2])
                i += 2
                continue
            value = {k: float(x) for k, x in zip(p, fit.theta[i:i + len(p)], strict=True)}
            if name in totals and name in ("channel_delay", "sensor_crosstalk"):
                value = {k: x + totals[name].values[k] for k, x in value.items()}
            out[name] = Fitted(value, {k: float(x) for k, x in zip(p, fit.std[i:i + len(p)],
                                                                    strict=True)})
            i += len(p)
    if _AERO in names:
        out[_AERO] = Fitted({"e_h": float(aero.e[0]), "e_a": float(aero.e[1])},
                            {"e_h": float(aero.e_std[0]), "e_a": float(aero.e_std[1])})
    if _VORTEX in names:
        out[_VORTEX] = Fitted({"strouhal": vortex.k * depth, "cl": vortex.cl, "cm": vortex.cm,
                               "phase": vortex.phase},
                              {"strouhal": vortex.k_std * depth, "cl": vortex.cl_std,
                               "cm": vortex.cm_std, "phase": math.nan})
    return out


def _tubing_params(theta: FloatArray, std: FloatArray) -> Fitted:
    """Return the second-order tube of ``1 / H = 1 + a1 s + a2 s^2`` and its uncertainty.

    ``w = 1 / sqrt(a2)``, ``damping = a1 w / 2``; without a resonance (``a2 <= 0`` or
    ``a1 <= 0``) the values are NaN (the candidate is then rejected).
    """
    a1, a2 = float(theta[0]), float(theta[1])
    if a1 <= 0.0 or a2 <= 0.0:
        nan = {"frequency_hz": math.nan, "damping": math.nan}
        return Fitted(nan, dict(nan))
    wn = 1.0 / math.sqrt(a2)
    rel_a2 = 0.5 * float(std[1]) / a2  # w and a2^(-1/2): half the relative error
    return Fitted({"frequency_hz": wn / (2 * math.pi), "damping": 0.5 * a1 * wn},
                  {"frequency_hz": rel_a2 * wn / (2 * math.pi),
                   "damping": 0.5 * a1 * wn * math.hypot(float(std[0]) / a1, rel_a2)})


def _base_params(line: BaseLine, theta: FloatArray, std: FloatArray) -> Fitted:
    """Return the base vibration's median amplitude and phase over the releases, and spread."""
    accel, phase = accelerations(theta)
    # A component's standard deviation is about the amplitude's (the two are alike).
    accel_std = float(np.median(np.hypot(*np.asarray(std).reshape(-1, 2).T) / math.sqrt(2)))
    return Fitted({"frequency_hz": line.frequency_hz, "accel": float(np.median(accel)),
                   "phase": float(np.median(phase))},
                  {"frequency_hz": math.nan, "accel": accel_std, "phase": math.nan},
                  np.column_stack([accel, phase]))


def _effects(params: Params, vortex: VortexFit, depth: float) -> list[Effect]:
    """Build the effects from fitted parameters (clipped to their physical range)."""
    out: list[Effect] = []
    for name, (p, _, _) in params.items():
        if name == "coulomb_friction":
            out.append(CoulombFriction(force_h=max(p["force_h"], 0.0),
                                       moment_a=max(p["moment_a"], 0.0)))
        elif name == "quadratic_damping":
            out.append(QuadraticDamping(c2_h=max(p["c2_h"], 0.0), c2_a=max(p["c2_a"], 0.0)))
        elif name == "cubic_stiffness":
            out.append(CubicStiffness(k3_h=p["k3_h"], k3_a=p["k3_a"]))
        elif name == "channel_delay":
            out.append(ChannelDelay(delay_s=max(p["delay_s"], 0.0)))
        elif name == "static_unbalance":
            out.append(StaticUnbalance(S=p["S"]))
        elif name == "sensor_crosstalk":
            out.append(SensorCrosstalk(h_from_alpha=p["h_from_alpha"],
                                       alpha_from_h=p["alpha_from_h"]))
        elif name == _TUBING:
            out.append(TubingDistortion(frequency_hz=p["frequency_hz"], damping=p["damping"]))
        elif name == _AERO:
            out.append(AerodynamicNonlinearity(e_h=p["e_h"], e_a=p["e_a"]))
        elif name == _BASE:
            out.append(BaseVibration(frequency_hz=p["frequency_hz"], accel=abs(p["accel"]),
                                     phase=p["phase"]))
        elif name == _VORTEX:
            out.append(VortexShedding(strouhal=vortex.k * depth, depth=depth, cl=vortex.cl,
                                      cm=vortex.cm, phase=vortex.phase))
        else:  # pragma: no cover - every candidate is handled above
            raise ValueError(f"unknown effect {name!r}")
    return out


State = tuple[RationalFunctionModel, tuple[Effect, ...], tuple[dict[str, FloatArray], ...], float]


def _apply(releases: list[Release], section: SectionModel, baseline: RationalFunctionModel,
           params: Params, vortex: VortexFit, depth: float) -> State:
    """Add the effects to the model, identify again where the data change, simulate, gap."""
    effects = _effects(params, vortex, depth)
    changed = bool({_VORTEX, _BASE, "channel_delay", "sensor_crosstalk", _TUBING} & set(params))
    # E2RFC chooses the structure again: contaminated data can make it choose another one (a
    # shedding line cost a lag: the refit kept at the baseline's structure stayed 4x the noise
    # away from the measurements, re-chosen it is at the noise). The structural effects do not
    # change the measured forces, but they bend the decays (E2RFC is identified again beside
    # them below, refit_beside); a base vibration changes the forces: its forced
    # motion near a mode biased E2RFC (the gap stayed at 2.6 times the noise with the floor's
    # parameters right within 1 %), so its line is notched out of all four channels first.
    corrected = take_out(releases, section, _values(params), vortex, notch_line=True,
                         untube_forces=True)
    measured_forces = corrected
    if _AERO in params:
        p = params[_AERO].values
        aero_effect = AerodynamicNonlinearity(e_h=p["e_h"], e_a=p["e_a"])
        corrected = [remove_aero(r, section, aero_effect) for r in corrected]
    model: RationalFunctionModel = (e2rfc.identify(corrected, section, turbulent_estimator="iv")
                                    if changed or _AERO in params else baseline)
    physics = tuple(e for e in effects if not isinstance(e, VortexShedding | BaseVibration))
    # The aerodynamic nonlinearity bends the decays too: its force is left in the forces here,
    # since the correction takes out its whole share of the response, force included.
    bending = tuple(e for e in physics
                    if e.name in _STRUCTURE_NAMES or isinstance(e, AerodynamicNonlinearity))
    if bending:
        model = refit_beside(measured_forces, section, model, bending)
    simulated = []
    for i, r in enumerate(releases):
        here = physics
        if _BASE in params:
            # The floor does not wait for the release: each has its own amplitude and phase.
            per_release = params[_BASE].per_release
            assert per_release is not None
            here = (*here, BaseVibration(frequency_hz=params[_BASE].values["frequency_hz"],
                                         accel=float(per_release[i, 0]),
                                         phase=float(per_release[i, 1])))
        if _VORTEX in params:
            # Shedding has a phase of its own in every release: the line fitted to each
            # drives the simulation (its force in the forces, the structure's response to it
            # in the motion: at three times the realistic strength that response is four
            # times the noise in heave), rather than one phase for all.
            here = (*here, release_vortex(r, section, model, vortex, i, depth))
        # A trial model can be unstable (a softening spring fitted to physics outside the
        # library runs away): its simulation overflows to inf or NaN, its gap is not finite
        # and the gap rule rejects it (ident.discrepancy.gap_rule), saying so.
        with np.errstate(over="ignore", invalid="ignore"):
            sim = simulate_channels(r, section, model, here)
        simulated.append(sim)
    return model, physics, tuple(simulated), gap([channels(r) for r in releases], simulated)
