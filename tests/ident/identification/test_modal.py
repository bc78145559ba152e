"""Modal fits recover the eigenvalues of simulated aeroelastic decays, including lag poles."""

from __future__ import annotations

import numpy as np
import pytest

from ident import AeroelasticSystem
from ident.identification.modal import fit_modes, noise_std
from ident.model import flat_plate, flutter
from ident.model.conventions import name_modes
from simulators import simulate_release

from support.sections import FLAT_PLATE

MODEL = flat_plate.jones_model()
U_F = flutter.analyze(FLAT_PLATE, MODEL).speed


def q_of(rel):
    return np.column_stack([rel.h / FLAT_PLATE.B, rel.alpha])


@pytest.mark.parametrize("fraction", [0.4, 0.8])
def test_noise_free_fit_is_exact(fraction):
    """Without noise the fit reproduces the decay to round-off and finds the true poles."""
    U = fraction * U_F
    rel = simulate_release(FLAT_PLATE, MODEL, U, 0.004, 0.02, duration=20.0, fs=500.0)
    fit = fit_modes(rel.t, q_of(rel))
    lam = AeroelasticSystem(FLAT_PLATE, MODEL, U).eigenvalues()
    true_modes = np.sort_complex(lam[lam.imag > 0])
    # The decay is exactly a sum of these exponentials: only round-off separates them.
    np.testing.assert_allclose(fit.modes, true_modes, rtol=1e-8)
    np.testing.assert_allclose(fit.evaluate(rel.t), q_of(rel), atol=1e-12)
    # The two aerodynamic lag poles excited in q are found too (the other two real eigenvalues
    # carry no displacement); a third fitted pole may be a spare that BIC cannot rule out on
    # noise-free data.
    true_real = lam.real[lam.imag == 0]
    matched = [p for p in fit.real_poles if np.min(np.abs(true_real - p)) < 1e-6 * abs(p)]
    assert len(matched) >= 2
    assert fit.frequencies == pytest.approx(true_modes.imag / (2 * np.pi), rel=1e-8)


def test_noisy_fit_denoises_and_keeps_frequency_and_damping():
    """At 5 % noise frequencies are within 0.05 %, damping within 2 %, the signal within 0.3 %."""
    U = 0.6 * U_F
    rel = simulate_release(FLAT_PLATE, MODEL, U, 0.004, 0.02, duration=20.0, fs=500.0,
                           noise=0.05, rng=11)
    fit = fit_modes(rel.t, q_of(rel))
    lam = AeroelasticSystem(FLAT_PLATE, MODEL, U).eigenvalues()
    true_modes = np.sort_complex(lam[lam.imag > 0])
    # 10 000 samples at 5 % noise: Cramer-Rao-like spreads are ~1e-4 in frequency and ~1 % in
    # damping; the bounds leave a factor of ~3.
    np.testing.assert_allclose(fit.frequencies, true_modes.imag / (2 * np.pi), rtol=5e-4)
    np.testing.assert_allclose(fit.damping, -true_modes.real / np.abs(true_modes), rtol=0.02)
    clean = np.column_stack([rel.clean["h"] / FLAT_PLATE.B, rel.clean["alpha"]])
    error = np.sqrt(np.mean((fit.evaluate(rel.t) - clean) ** 2, axis=0))
    assert np.all(error < 0.003 * np.sqrt(np.mean(clean**2, axis=0)))  # 20x below the noise
    noise = np.sqrt(np.mean((q_of(rel) - clean) ** 2, axis=0))
    np.testing.assert_allclose(fit.noise, noise, rtol=0.05)  # robust estimate, 10 000 samples


def test_lag_state_solves_its_differential_equation():
    """X' = q' - mu x with x(0) = 0, checked by finite differences of the closed form."""
    rel = simulate_release(FLAT_PLATE, MODEL, 0.6 * U_F, 0.004, 0.02, duration=5.0, fs=1000.0)
    fit = fit_modes(rel.t, q_of(rel))
    mu = 7.0
    x = fit.lag_state(rel.t, mu)
    assert np.all(x[0] == pytest.approx(0.0, abs=1e-15))
    dx = np.gradient(x, rel.t, axis=0)
    residual = dx - (fit.evaluate(rel.t, 1) - mu * x)
    # Central differences at 1 kHz of a ~4 Hz signal: O((w dt)^2) ~ 1e-3 of the derivative.
    assert np.abs(residual[2:-2]).max() < 2e-3 * np.abs(dx).max()


def test_noise_estimate_of_white_noise():
    """The robust noise estimate recovers the standard deviation of white noise within 3 %."""
    rng = np.random.default_rng(0)
    x = rng.normal(scale=0.7, size=(20000, 2))
    np.testing.assert_allclose(noise_std(x), 0.7, rtol=0.03)


def test_refinement_starts_inside_the_bounds_whatever_the_start_values():
    """A start value beyond a bound (e.g. a growing noise pole from the pencil) is moved inside.

    Regression: a default simulated campaign crashed with "Initial guess is outside of provided
    bounds" on one noisy release at 0.8 U_F.
    """
    from ident.identification import modal

    rel = simulate_release(FLAT_PLATE, MODEL, 0.6 * U_F, 0.004, 0.02, duration=10.0, fs=500.0,
                           noise=0.02, rng=4)
    t, q = rel.t, q_of(rel)
    block = 6
    tb, yb = modal._block_average(t - t[0], q / q.std(axis=0), block)
    dtb = block * (t[1] - t[0])
    bounds = modal._bounds(2, dtb, float(t[-1] - t[0]))
    good = np.array([-0.7, 12.5, -0.5, 24.3])
    outside = good.copy()
    outside[0] = 10.0 * bounds[1][0]  # grows far faster than allowed
    outside[3] = 2.0 * bounds[1][3]  # above the Nyquist bound
    theta, _ = modal._refine(tb, yb, block, t[1] - t[0], 2, 0, outside, bounds, loose=False)
    assert np.all(theta >= bounds[0][:4]) and np.all(theta <= bounds[1][:4])
    reference, _ = modal._refine(tb, yb, block, t[1] - t[0], 2, 0, good, bounds, loose=False)
    assert np.all(np.isfinite(theta)) and np.all(np.isfinite(reference))


def test_modes_are_named_by_their_kinetic_energy_share_not_their_amplitude():
    # h/B amplitude 1 against alpha 1.5: by amplitude the first mode would be pitch, but with
    # m B^2 = 0.27 and I = 0.03 its kinetic energy is 0.27 / (0.27 + 0.0675) = 80 % heave.
    mass = np.diag([0.27, 0.03])
    shapes = np.array([[0.2j, 1.0], [1.0, 1.5j]])
    assert name_modes(shapes, mass) == (1, 0)
    # A third (spurious) mode, 69 % heave: the pair most heave and most pitch jointly is named.
    three = np.vstack([shapes, [[0.5, 1.0]]])
    assert name_modes(three, mass) == (1, 0)
    assert name_modes(np.vstack([shapes, [[1.0, 0.1]]]), mass) == (2, 0)  # 99 % heave


def test_fast_pole_search_finds_scipys_poles_on_a_decay():
    """The fast search (ident.numerics.lsq) and scipy's reach the same poles on a decay in noise.

    fit_modes takes the fast search where it fits down to the noise; the two search paths
    differ, the optimum must not: 1e-7 relative is far below the poles' standard deviation at
    2 % noise (about 1e-4 of the frequency).
    """
    from ident.identification import modal

    rel = simulate_release(FLAT_PLATE, MODEL, 0.6 * U_F, 0.004, 0.02, duration=10.0, fs=500.0,
                           noise=0.02, rng=4)
    t, q = rel.t, q_of(rel)
    block = 6
    dt = float(t[1] - t[0])
    tb, yb = modal._block_average(t - t[0], q / modal.noise_std(q), block)
    duration = float(t[-1] - t[0])
    bounds = modal._bounds(2, block * dt, duration)
    pencil = modal._pencil(yb[:400], 2 * 2 + 3 + 3, block * dt)
    osc, reals = modal._strongest_poles(tb, yb, block, dt, pencil)
    search = (tb, yb, block, dt, 2, 3, osc, reals, bounds, duration)
    fast, rss_fast = modal._search_poles(*search, fast=True)
    slow, rss_slow = modal._search_poles(*search, fast=False)
    assert fast.size == slow.size
    assert np.allclose(fast, slow, rtol=1e-7, atol=1e-9)
    assert rss_fast == pytest.approx(rss_slow, rel=1e-9)
    # A decay fits down to the noise: the fast search's result is the one kept.
    assert np.sqrt(rss_fast * block / yb.size) < modal.FAST_SEARCH_LIMIT
