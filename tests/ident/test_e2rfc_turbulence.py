"""E2RFC in turbulent flow: the decay window, and the interval when the model contradicts a decay.

The window (``ident._decay_window``) is checked against its closed form on a synthetic decay
with a stationary part of known level; the turbulent identifications on seeded simulated
campaigns (the benchmark's vertical gusts, ``benchmarks/ident_accuracy.py --part tunnel``).
"""

from __future__ import annotations

import math

import numpy as np

from ident import Release, SectionModel, e2rfc, flat_plate
from ident import flutter as fl
from ident._decay_window import decay_window
from ident.modal import fit_modes
from ident.turbulence import StaticCoefficients, TurbulenceSpec
from simulators import simulate_release

PLATE = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)
HOLDS = ((0.004, 0.02), (-0.003, 0.012))


def campaign(model, *, seed, Iw, duration=20.0):
    """The benchmark's plate campaign: 0.4/0.6/0.8 U_F x 2 holds, 2 % noise, vertical gusts."""
    U_F = fl.analyze(PLATE, model).speed
    wind = {}
    if Iw:
        wind = {"static": StaticCoefficients.flat_plate(), "span": 1.0,
                "turbulence": TurbulenceSpec(Iu=0.0, Iw=Iw, Lux=1.0, Lwx=0.3, Cuy=10.0, Cwy=8.0)}
    return [Release.from_simulation(simulate_release(
        PLATE, model, f * U_F, h0, a0, duration=duration, fs=500.0, noise=0.02,
        rng=(seed, i, j, int(1000 * Iw)), **wind))
        for i, f in enumerate((0.4, 0.6, 0.8)) for j, (h0, a0) in enumerate(HOLDS)]


def test_the_decay_window_ends_where_the_envelope_meets_the_random_level():
    """Closed form: ``A e^{-zeta omega t} = ratio sigma``, sigma the stationary part's RMS.

    Heave decays from A = 0.01 (h/B) with 2 % damping at 2 Hz; a sinusoid of amplitude A/20 at
    2.3 Hz stands for the stationary random response (RMS A / (20 sqrt 2)); pitch decays four
    times faster, so heave sets the window. Tolerance 0.3 s (under one period): the last
    quarter, whose RMS is taken as the random level, still holds a little of the decay.
    """
    fs, B = 200.0, 0.3
    t = np.arange(0.0, 20.0, 1.0 / fs)
    A, zeta_h, f_h, zeta_a, f_a = 0.01, 0.02, 2.0, 0.04, 4.0
    rng = np.random.default_rng(0)
    stationary = A / 20.0
    h = (A * np.exp(-zeta_h * 2 * math.pi * f_h * t) * np.cos(2 * math.pi * f_h * t)
         + stationary * np.sin(2 * math.pi * 2.3 * t) + 1e-5 * rng.standard_normal(t.size))
    alpha = (A * np.exp(-zeta_a * 2 * math.pi * f_a * t) * np.cos(2 * math.pi * f_a * t)
             + stationary * np.sin(2 * math.pi * 4.3 * t + 1.0)
             + 1e-5 * rng.standard_normal(t.size))
    release = Release(t=t, h=B * h, alpha=alpha, lift=rng.standard_normal(t.size),
                      moment=rng.standard_normal(t.size), U=5.0)
    fit = fit_modes(t, np.column_stack([h, alpha]))
    sigma = stationary / math.sqrt(2.0)
    for ratio in (1.0, 2.0, 4.0):
        expected = math.log(A / (ratio * sigma)) / (zeta_h * 2 * math.pi * f_h)
        assert abs(decay_window(release, fit, ratio) - expected) < 0.3


def test_smooth_flow_releases_are_fitted_whole():
    """Without a random response nothing is cut: the shipped smooth-flow estimator is unchanged."""
    releases = campaign(flat_plate.jones_model(), seed=0, Iw=0.0, duration=10.0)
    identified = e2rfc.identify(releases, PLATE)
    assert not identified.diagnostics.turbulent
    np.testing.assert_array_equal(identified.diagnostics.decay_windows,
                                  [r.t[-1] - r.t[0] for r in releases])
