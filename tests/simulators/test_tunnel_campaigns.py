"""Campaigns recorded from the virtual tunnel, with effects of random strength and shape.

The recorded campaign is checked against an independent computation of the same releases
(:func:`simulators.tunnel.simulate_release` called directly, in the tunnel's air, sampled on the
record's grid): what the tunnel adds (the spline between its internal samples, the taps'
integration) must not change the physics; the noise must be the stated fraction.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from ident.model import flat_plate, flutter
from simulators.campaigns import FRACTIONS, HOLDS, REALISTIC, SECTION, scaled
from simulators.tunnel import simulate_release
from simulators.tunnel_campaigns import AIR, STRENGTH_RANGE, random_effect, tunnel_campaign


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean((x - x.mean()) ** 2)))


def test_every_effect_has_a_range_about_its_realistic_strength():
    assert set(STRENGTH_RANGE) == set(REALISTIC)
    for low, high in STRENGTH_RANGE.values():
        assert 0 < low < 1.0 < high


def test_random_effects_stay_in_their_range_and_repeat_with_the_seed():
    for name in REALISTIC:
        draws = [random_effect(name, np.random.default_rng([5, k])) for k in range(40)]
        factors = np.array([f for _, f in draws])
        low, high = STRENGTH_RANGE[name]
        assert np.all((factors >= low) & (factors <= high))
        # Log-uniform: the median of 40 draws lies near the geometric middle (its standard
        # error in log factor is ~0.2 of the log range; 3 of them leave room).
        middle = math.log(math.sqrt(low * high))
        assert abs(float(np.median(np.log(factors))) - middle) < 0.6 * math.log(high / low)
        again = random_effect(name, np.random.default_rng([5, 0]))
        assert again == draws[0]
        effect, factor = draws[0]
        strength = scaled(name, factor)
        # The strength is the scaled realistic one; only shape parameters were redrawn.
        shape = {"strouhal", "phase", "frequency_hz", "damping"}
        for field in dataclasses.fields(effect):
            if field.name not in shape or name == "tubing_distortion" and field.name == \
                    "frequency_hz":
                assert getattr(effect, field.name) == getattr(strength, field.name), field.name


def test_the_recorded_campaign_is_the_simulated_physics_plus_the_stated_noise():
    effect = REALISTIC["coulomb_friction"]
    releases = tunnel_campaign(effect, 3, duration=3.0)
    assert len(releases) == len(FRACTIONS) * len(HOLDS)
    section = SECTION.replace(rho=AIR.density)
    speed = flutter.analyze(section, flat_plate.jones_model()).speed
    assert speed is not None
    quiet = tunnel_campaign(effect, 3, duration=3.0, noise=0.0)
    for r, q in zip(releases, quiet, strict=True):
        assert r.rho == pytest.approx(AIR.density, rel=1e-12)
        assert r.U == pytest.approx(r.meta["fraction"] * speed, rel=1e-9)
        direct = simulate_release(section, flat_plate.jones_model(), r.U, r.meta["h0"],
                                  r.meta["alpha0"], duration=3.0, fs=1000.0, effects=(effect,))
        for name in ("h", "alpha", "lift", "moment"):
            truth = np.asarray(getattr(direct, name))[::2][:r.t.size]
            # The tunnel's cubic spline of a 1 kHz record at 2-4 Hz: ~1e-6 of the RMS;
            # friction's kinks (its force steps at each velocity reversal) make it 1e-4.
            assert _rms(getattr(q, name) - truth) < 3e-4 * _rms(truth), name
            # Noise: 2 % of the RMS on the lasers and the lift (from 6000 samples, the
            # estimate's own scatter is ~1 %; 10 % of room); the moment's from the same taps.
            ratio = _rms(getattr(r, name) - getattr(q, name)) / _rms(truth)
            if name != "moment":
                assert ratio == pytest.approx(0.02, rel=0.1), name
            else:
                assert 0.001 < ratio < 0.1
