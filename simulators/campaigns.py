"""Seeded simulated campaigns with hidden effects, for the discrepancy workflow's tests.

Responsibility: :func:`simulated_campaign` returns the releases of a small test campaign on the
flat-plate rig (the section of ``rig_configs/sim_flat_plate.toml``, Jones aerodynamics): three
wind speeds (0.5, 0.65 and 0.8 of the flutter speed), two releases each from different held
positions, 7.5 s decays at 500 Hz (the sync view's rate), Gaussian noise of a given fraction
of each channel's RMS, and named effects hidden (none, one or several at once) in the physics
or the measurement. :data:`REALISTIC` holds one realistic strength of each effect for this rig, each
chosen to matter about as much as the things a tunnel engineer would notice: a friction force
of the order of the structural damping force at the release amplitude, a quadratic drag a few
times it (in heave the wind's own damping is 10 to 35 times the structural one, and a weaker
drag hides in it), a spring 5 % stiffer at the release amplitude, a centre of mass 5 mm off
the axis, 10 ms of pressure tubing, a shedding lift coefficient of 0.05, a few per cent of
laser crosstalk, a floor shaking at 6 Hz with 10 milli-g (a heave motion of about 4 % of the
decays' RMS), aerodynamic damping that grows by 40 % (heave) to 75 % (pitch) from small amplitudes
to the release amplitude, and the tubing of 2 m tubes of 0.8 mm bore into
50 mm^3 transducer volumes (Bergh-Tijdeman: as a second-order low-pass 16.9 Hz with damping
0.99, :meth:`ident.physics.effects.TubingDistortion.from_tube`; 5 % gain loss at 4 Hz, 18 ms lag).

Not responsible for: the physics (:mod:`ident.simulation.decay`, :mod:`simulators.tunnel`) or the
diagnosis (:mod:`ident.discrepancy.workflow`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any, cast

import numpy as np

from ident.model import flat_plate, flutter
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
from simulators.tunnel import simulate_release

__all__ = ["FRACTIONS", "HOLDS", "REALISTIC", "SECTION", "scaled", "simulated_campaign"]

#: The flat-plate rig's section model (rig_configs/sim_flat_plate.toml), in air of 1.2 kg/m^3.
SECTION = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005,
                       rho=1.2)
#: Wind speeds as fractions of the flutter speed.
FRACTIONS = (0.5, 0.65, 0.8)
#: Held positions (h0 m, alpha0 rad) of the releases at each wind speed.
HOLDS = ((0.004, 0.02), (-0.003, 0.012))

#: One realistic strength of each named effect on this rig (module docstring).
REALISTIC: dict[str, Effect] = {
    "coulomb_friction": CoulombFriction(force_h=0.03, moment_a=0.001),
    "quadratic_damping": QuadraticDamping(c2_h=30.0, c2_a=0.024),
    "cubic_stiffness": CubicStiffness(k3_h=1.5e6, k3_a=2400.0),
    "channel_delay": ChannelDelay(delay_s=0.01),
    "vortex_shedding": VortexShedding(strouhal=0.12, depth=0.03, cl=0.05, cm=0.01, phase=0.5),
    "static_unbalance": StaticUnbalance(S=0.015),
    "sensor_crosstalk": SensorCrosstalk(h_from_alpha=0.003, alpha_from_h=0.3),
    "base_vibration": BaseVibration(frequency_hz=6.0, accel=0.1, phase=0.3),
    "aerodynamic_nonlinearity": AerodynamicNonlinearity(e_h=-3.0, e_a=-0.15),
    "tubing_distortion": TubingDistortion(frequency_hz=17.0, damping=1.0),
}

#: The parameters of each effect that a diagnosis must recover (the others are fixed shapes).
_STRENGTHS: dict[str, tuple[str, ...]] = {
    "coulomb_friction": ("force_h", "moment_a"),
    "quadratic_damping": ("c2_h", "c2_a"),
    "cubic_stiffness": ("k3_h", "k3_a"),
    "channel_delay": ("delay_s",),
    "vortex_shedding": ("cl", "cm"),
    "static_unbalance": ("S",),
    "sensor_crosstalk": ("h_from_alpha", "alpha_from_h"),
    "base_vibration": ("accel",),
    "aerodynamic_nonlinearity": ("e_h", "e_a"),
    "tubing_distortion": ("frequency_hz", "damping"),
}

#: Strength parameters that weaken the effect as they grow: :func:`scaled` divides them (a
#: tube twice as strong resonates at half the frequency; its damping is a shape, kept).
_INVERSE: dict[str, tuple[str, ...]] = {"tubing_distortion": ("frequency_hz",)}


def scaled(name: str, factor: float) -> Effect:
    """Return the realistic effect ``name`` made ``factor`` times as strong.

    Its strength parameters are multiplied by ``factor`` (those in :data:`_INVERSE` divided;
    a tubing's damping ratio is its shape and stays).
    """
    effect: Any = REALISTIC[name]  # a frozen dataclass (every Effect is)
    if name in _INVERSE:
        changes = {p: getattr(effect, p) / factor for p in _INVERSE[name]}
    else:
        changes = {p: getattr(effect, p) * factor for p in _STRENGTHS[name]}
    return cast(Effect, dataclasses.replace(effect, **changes))


def simulated_campaign(effect: Effect | Sequence[Effect] | None, seed: int, *, noise: float = 0.02,
                       fractions: Sequence[float] = FRACTIONS, duration: float = 7.5,
                       fs: float = 500.0) -> list[Release]:
    """Simulate a campaign with ``effect`` hidden (None: clean), seeded.

    Parameters
    ----------
    effect : Effect, sequence of Effect, or None
        The hidden effect (or effects, at most one of each kind).
    seed : int
        Seed of the noise.
    noise : float
        Noise as a fraction of each channel's RMS.
    fractions : sequence of float
        Wind speeds as fractions of the flutter speed of :data:`SECTION` with the Jones model.
    duration, fs : float
        Decay length (s) and sampling rate (Hz).

    Returns
    -------
    list of Release
        ``len(fractions) * len(HOLDS)`` releases, ``meta`` holding the wind fraction and hold.
    """
    truth = flat_plate.jones_model()
    speed = flutter.analyze(SECTION, truth).speed
    assert speed is not None  # the flat plate flutters
    rng = np.random.default_rng(seed)
    effects = (() if effect is None else (effect,) if isinstance(effect, Effect)
               else tuple(effect))
    releases = []
    for fraction in fractions:
        for h0, alpha0 in HOLDS:
            sim = simulate_release(SECTION, truth, fraction * speed, h0, alpha0,
                                   duration=duration, fs=fs, noise=noise, rng=rng,
                                   effects=effects)
            releases.append(Release.from_simulation(
                sim, meta={"fraction": fraction, "h0": h0, "alpha0": alpha0}))
    return releases
