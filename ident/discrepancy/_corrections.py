"""The named effects taken out of measured releases, and releases simulated as measured.

Private to the discrepancy workflow (:mod:`ident.discrepancy.effect_selection` composes these
per release): undoing a recording delay, a sensor crosstalk, a tube's distortion or a floor's
line; taking a fitted shedding line or an aerodynamic nonlinearity's force out of the forces;
the shedding line of one release as the effect that drives its simulation; identifying E2RFC
again beside the effects that bend the decays; and simulating a release from its own initial
state with the measurement effects on (:func:`simulate_channels`, the gap's simulation).

Not responsible for: which effects are named and their fits
(:mod:`ident.discrepancy.effect_selection`).
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Mapping
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from ident.discrepancy._equation_error import VortexFit, decay_signals
from ident.identification import e2rfc
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.physics import tubing
from ident.physics.effects import (
    AerodynamicNonlinearity,
    Effect,
    SensorCrosstalk,
    TubingDistortion,
    VortexShedding,
)
from ident.records.release import Release
from ident.simulation.decay import CHANNELS, simulate_decay

__all__ = ["advance_forces", "channels", "notch", "refit_beside", "release_vortex", "remove_aero",
           "remove_vortex", "simulate_channels", "take_out", "unmix", "untube"]

FloatArray = npt.NDArray[np.float64]

#: Samples at the start of a decay fitted by ``c0 + c2 t^2 + c3 t^3`` for its initial state.
_START_SAMPLES = 20
#: Quality factor of the notch that takes a base vibration's line out before E2RFC (a
#: bandwidth of f / Q: 0.5 Hz at 5 Hz, narrow beside the modes' distance from it).
_NOTCH_Q = 10.0


def take_out(releases: list[Release], section: SectionModel,
             params: Mapping[str, Mapping[str, float]], vortex: VortexFit, *,
             notch_line: bool = False, untube_forces: bool = False) -> list[Release]:
    """Take the measurement effects (and the shedding lines) out of the releases.

    ``params`` maps each named effect to its fitted parameters (SI units). With
    ``notch_line``, a base vibration's line too (for E2RFC; the equation error keeps it, its
    columns fit it there); with ``untube_forces``, the tubing (for E2RFC and the force
    equation; the structural equation keeps it: its columns are exact for it).
    """
    corrected = list(releases)
    # In the reverse of the order they happened: the shedding line is in the recorded forces
    # as they are; the delay is undone next.
    if "vortex_shedding" in params:
        corrected = [remove_vortex(r, section, vortex, i) for i, r in enumerate(corrected)]
    if notch_line and "base_vibration" in params:
        corrected = [notch(r, params["base_vibration"]["frequency_hz"]) for r in corrected]
    if untube_forces and "tubing_distortion" in params:
        p = params["tubing_distortion"]
        corrected = [untube(r, TubingDistortion(frequency_hz=p["frequency_hz"],
                                                 damping=p["damping"])) for r in corrected]
    if "channel_delay" in params:
        delay = max(params["channel_delay"]["delay_s"], 0.0)
        corrected = [advance_forces(r, delay) for r in corrected]
    if "sensor_crosstalk" in params:
        p = params["sensor_crosstalk"]
        effect = SensorCrosstalk(h_from_alpha=p["h_from_alpha"], alpha_from_h=p["alpha_from_h"])
        corrected = [unmix(r, effect) for r in corrected]
    return corrected


def refit_beside(releases: list[Release], section: SectionModel, model: RationalFunctionModel,
                  effects: tuple[Effect, ...]) -> RationalFunctionModel:
    """Identify the aerodynamic model again with the named nonlinear effects' response out.

    E2RFC's regressors come from a modal fit of each decay, which assumes the decays of a
    linear system: friction, drag, a nonlinear spring, an unbalance or an aerodynamic
    nonlinearity bend them, and the model identified beside them is biased (friction at twice
    its realistic strength, its own parameters within 2 %: a systematic residual of 1.3-1.7
    times the noise in every channel, 0.07-0.17 of it with the true aerodynamic model).
    So each release's channels are corrected by the effects' share of the response, the
    difference between the current model's simulations with and without them, and E2RFC runs
    on what a linear section would have given (one pass: the residual fell to 0.16-0.28 of the
    noise; a second changed it by less than 0.1 of it). A trial whose simulation diverges
    keeps ``model`` (the gap rule rejects it).
    """
    linear = []
    for r in releases:
        with np.errstate(over="ignore", invalid="ignore"):
            bent = simulate_channels(r, section, model, effects)
            straight = simulate_channels(r, section, model, ())
        share = {c: bent[c] - straight[c] for c in CHANNELS}
        if not all(np.all(np.isfinite(x)) for x in share.values()):
            return model
        linear.append(replace(r, **{c: getattr(r, c) - share[c] for c in CHANNELS},
                              meta=dict(r.meta)))
    return e2rfc.identify(linear, section, turbulent_estimator="iv")  # as workflow's baseline


def notch(r: Release, frequency_hz: float) -> Release:
    """Notch a line out of all four channels (zero phase): the motion-force relation is kept."""
    from scipy.signal import filtfilt, iirnotch

    b, a = iirnotch(frequency_hz, _NOTCH_Q, fs=r.fs)
    return replace(r, **{c: filtfilt(b, a, getattr(r, c)) for c in CHANNELS}, meta=dict(r.meta))


def remove_aero(r: Release, section: SectionModel, effect: AerodynamicNonlinearity) -> Release:
    """Take a named aerodynamic nonlinearity's force (from the low-passed motion) out."""
    sig = decay_signals(r, section)
    assert sig.q_full is not None and sig.q1_full is not None
    rho = section.rho if r.rho is None else r.rho
    force = effect.aerodynamic_force(sig.q_full, sig.q1_full, section.B, r.U, rho)
    return replace(r, lift=r.lift - force[:, 0] / section.B, moment=r.moment - force[:, 1],
                   meta=dict(r.meta))


def untube(r: Release, effect: TubingDistortion) -> Release:
    """Undo a tubing distortion of the forces (``tubing.correct``, band-limited)."""
    f = np.arange(0.25, r.fs / 2.0 + 1.0, 0.25)
    H = effect.response(f)
    table = tubing.TableResponse(frequency=f, gain=np.abs(H), phase=np.unwrap(np.angle(H)),
                                 source="tubing_distortion")
    tubes = tubing.tubing_set([tubing.TubingGroup(taps=None, model=table)], 2)
    forces = tubing.correct(np.column_stack([r.lift, r.moment]), r.fs, tubes)
    return replace(r, lift=forces[:, 0], moment=forces[:, 1], meta=dict(r.meta))


def advance_forces(r: Release, delay_s: float) -> Release:
    """Undo a recording delay: ``f(t) = f_recorded(t + delay)`` (the last samples held)."""
    t = r.t
    return replace(r, lift=np.interp(t + delay_s, t, r.lift),
                   moment=np.interp(t + delay_s, t, r.moment), meta=dict(r.meta))


def unmix(r: Release, effect: SensorCrosstalk) -> Release:
    """Undo crosstalk: solve ``[h_m, a_m] = [[1, a], [b, 1]] [h, alpha]``."""
    mix = np.array([[1.0, effect.h_from_alpha], [effect.alpha_from_h, 1.0]])
    h, alpha = np.linalg.solve(mix, np.vstack([r.h, r.alpha]))
    return replace(r, h=h, alpha=alpha, meta=dict(r.meta))


def release_vortex(r: Release, section: SectionModel, model: RationalFunctionModel,
                    vortex: VortexFit, index: int, depth: float) -> VortexShedding:
    """Return one release's fitted shedding line as the effect (its own amplitudes, phases).

    The line fitted to the measured forces holds, besides the shedding force, the self-excited
    force of the structure's response to the line (its added-mass part grows with the square
    of the frequency: a few per cent of the line, many times the noise at the realistic
    strength). The structure moves under both, ``q = H(w) F_measured`` with ``H`` the still-air
    structure's receptance, and the model's ``qd B^2 Q(iK) q`` is taken out to leave the
    shedding force that drives the simulation.
    """
    rho = section.rho if r.rho is None else r.rho
    qd_B2 = 0.5 * rho * r.U**2 * section.B**2
    w = 2 * math.pi * vortex.k * r.U
    lift_s, lift_c, moment_s, moment_c = vortex.amplitudes[index]
    # a_s sin(w t) + a_c cos(w t) = Re[(a_c - i a_s) exp(i w t)]
    measured = np.array([lift_c - 1j * lift_s, moment_c - 1j * moment_s])
    planar = section.planar() if section.n_dof == 3 else section
    receptance = np.linalg.inv(planar.stiffness_matrix() - w**2 * planar.mass_matrix()
                               + 1j * w * planar.damping_matrix())
    self_excited = qd_B2 * model.planar().Q(1j * w * section.B / r.U) @ (receptance @ measured)
    lift, moment = measured - self_excited
    # Re[c exp(i w t)] = |c| sin(w t + arg(c) + pi/2); the simulation's clock starts at the
    # release's first sample.
    start = w * float(r.t[0])
    lift_phase = cmath.phase(lift) + math.pi / 2 + start
    return VortexShedding(strouhal=vortex.k * depth, depth=depth, cl=abs(lift) / qd_B2,
                          cm=abs(moment) / qd_B2, phase=cmath.phase(moment) - cmath.phase(lift),
                          lift_phase=lift_phase)


def _vortex_line(r: Release, section: SectionModel, vortex: VortexFit,
                 index: int) -> tuple[FloatArray, FloatArray]:
    """Return one release's fitted shedding line (own phase): lift (N/m), moment (N m/m)."""
    w = 2 * math.pi * vortex.k * r.U
    a = vortex.amplitudes[index]
    sn, cs = np.sin(w * r.t), np.cos(w * r.t)
    return (a[0] * sn + a[1] * cs) / section.B, a[2] * sn + a[3] * cs


def remove_vortex(r: Release, section: SectionModel, vortex: VortexFit, index: int) -> Release:
    """Subtract the fitted shedding line from the forces."""
    lift, moment = _vortex_line(r, section, vortex, index)
    return replace(r, lift=r.lift - lift, moment=r.moment - moment, meta=dict(r.meta))


def channels(r: Release) -> dict[str, FloatArray]:
    """Return the four measured channels of a release."""
    return {"h": r.h, "alpha": r.alpha, "lift": r.lift, "moment": r.moment}


def _initial_state(r: Release) -> tuple[float, float]:
    """Return the position at the release: ``c0`` of ``c0 + c2 t^2 + c3 t^3`` (from rest)."""
    n = min(_START_SAMPLES, r.t.size)
    t = r.t[:n] - r.t[0]
    basis = np.column_stack([np.ones(n), t**2, t**3])
    coef, *_ = np.linalg.lstsq(basis, np.column_stack([r.h[:n], r.alpha[:n]]), rcond=None)
    return float(coef[0, 0]), float(coef[0, 1])


def simulate_channels(r: Release, section: SectionModel, model: RationalFunctionModel,
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
