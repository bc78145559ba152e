"""Campaigns recorded from the virtual tunnel, with effects of random strength and shape.

Responsibility: the data of the discrepancy workflow's confusion benchmark. Unlike
:func:`simulators.campaigns.simulated_campaign`, which takes the simulator's output directly,
:func:`tunnel_campaign` records each release the way the rig's instruments see the
:class:`~simulators.virtual_tunnel.VirtualTunnel`: the tunnel is released on a manual clock at
each wind speed (its fan setting from the tunnel's calibration, its air density from the air
state, not 1.2 kg/m^3), the lasers sample its spline-interpolated motion at the sync view's
rate, with noise, and the forces are integrated from the pressures of 16 + 16 + 2 taps on the
plate's outline, each tap with its own noise (one noise level for every tap, as one scanner has;
the lift's noise is the given fraction of its RMS, the moment's whatever the taps give).

:func:`random_effect` draws an effect's strength log-uniformly over its realistic range
(:data:`STRENGTH_RANGE`, factors of :data:`simulators.campaigns.REALISTIC`, measured by
``benchmarks/discrepancy_detectability.py``) and its shape parameters (phases, the floor's
frequency, the shedding's Strouhal number, the tube's damping) uniformly over plausible values,
so that the benchmark does not test one strength and one shape per effect.

Not responsible for: the physics (:mod:`ident.simulation.decay` through the tunnel) or the
diagnosis (:mod:`ident.discrepancy.workflow`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any, cast

import numpy as np

from ident.model import flat_plate, flutter
from ident.physics.effects import Effect
from ident.physics.taps import TapLayout
from ident.records.release import Release
from simulators.campaigns import FRACTIONS, HOLDS, SECTION, scaled
from simulators.clock import ManualClock
from simulators.virtual_tunnel import AirState, VirtualTunnel

__all__ = ["STRENGTH_RANGE", "TAPS", "random_effect", "tunnel_campaign"]

#: Each effect's realistic range of strength, as factors of its strength in
#: :data:`simulators.campaigns.REALISTIC` (low, high). The low end is the weakest strength that
#: doubles the linear baseline's gap over a clean campaign's (the effect's residual about as
#: large as the noise's over the four channels: below it there is little to explain), measured
#: by ``benchmarks/discrepancy_detectability.py`` on tunnel campaigns at 2 % noise (one seed)
#: and rounded (quadratic damping's 0.54 down to 0.5, a little below the criterion: harder
#: for the workflow, not easier); the high end three times the realistic strength (a rig
#: with that much friction, drag or unbalance gets fixed before a campaign). In physical
#: terms: friction 5-90 mN/m in heave, drag coefficients 15-90 kg/m^2 (heave), a spring
#: 1.4-15 % stiffer at the release amplitude, delays of 0.9-30 ms, shedding lift coefficients
#: 0.0015-0.15, a centre of mass 0.9-15 mm off the axis, crosstalk of 0.9-9 mm of heave per
#: rad of pitch and 0.09-0.9 rad of pitch per m of heave, a floor shaking at 0.05-0.3 m/s^2,
#: aerodynamic damping that grows by 24-120 % in heave from small amplitudes to the release's,
#: tubes resonating at 6-340 Hz.
STRENGTH_RANGE: dict[str, tuple[float, float]] = {
    "coulomb_friction": (0.16, 3.0),
    "quadratic_damping": (0.5, 3.0),
    "cubic_stiffness": (0.27, 3.0),
    "channel_delay": (0.09, 3.0),
    "vortex_shedding": (0.03, 3.0),
    "static_unbalance": (0.17, 3.0),
    "sensor_crosstalk": (0.3, 3.0),
    "base_vibration": (0.5, 3.0),
    "aerodynamic_nonlinearity": (0.6, 3.0),
    "tubing_distortion": (0.05, 3.0),
}

#: Taps on the flat plate's outline (B 0.3 m, 10 mm deep): 16 on each face, one on each end.
TAPS = TapLayout.rectangle(SECTION.B, 0.01, 16)
#: Tunnel calibration, (m/s)/rpm (that of rig_configs/sim_flat_plate.toml).
WIND_PER_RPM = 0.01
#: Air of the tunnel hall: 98 kPa, 22 degC (a density of 1.156 kg/m^3, not the 1.2 of SECTION).
AIR = AirState(pressure_pa=98_000.0, temperature_k=295.15)


def random_effect(name: str, rng: np.random.Generator) -> tuple[Effect, float]:
    """Draw the effect ``name`` at a random strength and shape.

    Parameters
    ----------
    name : str
        An effect of :data:`STRENGTH_RANGE`.
    rng : numpy.random.Generator
        The draw's generator.

    Returns
    -------
    effect : Effect
        The effect, its strength :func:`simulators.campaigns.scaled` by a factor log-uniform
        over :data:`STRENGTH_RANGE` and its shape parameters uniform over plausible values.
    factor : float
        The strength factor drawn.
    """
    low, high = STRENGTH_RANGE[name]
    factor = float(math.exp(rng.uniform(math.log(low), math.log(high))))
    effect: Any = scaled(name, factor)
    shape: dict[str, float] = {}
    if name == "vortex_shedding":
        shape = {"strouhal": rng.uniform(0.10, 0.16), "phase": rng.uniform(0, 2 * math.pi)}
    elif name == "base_vibration":
        # A floor's machine line between the pitch mode (4 Hz) and the equation error's band edge.
        shape = {"frequency_hz": rng.uniform(5.0, 9.0), "phase": rng.uniform(0, 2 * math.pi)}
    elif name == "tubing_distortion":
        shape = {"damping": rng.uniform(0.6, 1.2)}
    return cast(Effect, dataclasses.replace(effect, **shape)), factor


def tunnel_campaign(effects: Effect | Sequence[Effect] | None, seed: int, *,
                    noise: float = 0.02, fractions: Sequence[float] = FRACTIONS,
                    duration: float = 7.5, fs: float = 500.0) -> list[Release]:
    """Record a campaign from the virtual tunnel with ``effects`` hidden (None: clean), seeded.

    Parameters
    ----------
    effects : Effect, sequence of Effect, or None
        The hidden effect or effects (at most one of each kind).
    seed : int
        Seed of the noise.
    noise : float
        Noise as a fraction of each laser channel's RMS, and of the lift's RMS for every tap.
    fractions : sequence of float
        Wind speeds as fractions of the flutter speed of :data:`simulators.campaigns.SECTION`
        with the Jones model, in the tunnel's air.
    duration, fs : float
        Record length after each release (s) and sampling rate (Hz).

    Returns
    -------
    list of Release
        ``len(fractions) * len(HOLDS)`` releases; ``meta`` holds the wind fraction and hold.
    """
    truth = flat_plate.jones_model()
    section = SECTION.replace(rho=AIR.density)
    speed = flutter.analyze(section, truth).speed
    assert speed is not None  # the flat plate flutters
    hidden = (() if effects is None else (effects,) if isinstance(effects, Effect)
              else tuple(effects))
    rng = np.random.default_rng(seed)
    G = TAPS.integration_matrix()
    n = int(round(duration * fs))
    releases = []
    for h0, alpha0 in HOLDS:
        clock = ManualClock()
        tunnel = VirtualTunnel(section, truth, TAPS, wind_per_rpm=WIND_PER_RPM,
                               hold=(h0, alpha0), effects=hidden, air=AIR, clock=clock,
                               decay_duration_s=duration + 1.0, fs_internal=2 * fs)
        for fraction in fractions:
            tunnel.arm()
            tunnel.set_fan_speed(fraction * speed / WIND_PER_RPM)
            clock.advance(30.0)  # the wind settles while the model is held
            t0 = tunnel.release()
            t = np.arange(n) / fs
            motion = tunnel.sample(t0 + t)
            p, _ = tunnel.pressures(t0 + t)
            U = float(motion["U"][0])
            clock.advance(duration + 1.0)
            h, alpha = motion["h"], motion["alpha"]
            h = h + rng.normal(0.0, noise * _rms(h), n)
            alpha = alpha + rng.normal(0.0, noise * _rms(alpha), n)
            # One noise level on every tap, such that the integrated lift's is `noise` of its RMS.
            sigma_p = noise * _rms(motion["lift"]) / float(np.linalg.norm(G[0]))
            lift, moment = ((p + rng.normal(0.0, sigma_p, p.shape)) @ G.T).T
            releases.append(Release(t=t, h=h, alpha=alpha, lift=lift, moment=moment, U=U,
                                    rho=AIR.density,
                                    meta={"fraction": fraction, "h0": h0, "alpha0": alpha0}))
    return releases


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean((x - x.mean()) ** 2)))
