"""ident.simulation.decay: the exact linear decay, the ETD2RK order, the measurement effects."""

from __future__ import annotations

import numpy as np
import pytest

import ident.physics.effects
import simulators.effects
from ident import AeroelasticSystem, Release
from ident.model import flat_plate, flutter
from ident.physics.effects import ChannelDelay, CubicStiffness, SensorCrosstalk, VortexShedding
from ident.simulation.decay import CHANNELS, simulate_decay
from simulators import simulate_release

from support.sections import FLAT_PLATE

MODEL = flat_plate.jones_model()


def test_linear_decay_is_a_sum_of_the_system_eigenmodes():
    """A linear decay is exactly a combination of e^{lambda t} at AeroelasticSystem's eigenvalues.

    The displacements are projected on the real basis of all eigenvalues (two structural pairs,
    four real lag poles); the exact discretisation leaves a residual at round-off (~1e-14 of the
    signal; bound 1e-12). Moving the modal frequencies by 1e-6 (relative) or the damping ratios
    by 1e-5 (absolute) raises it to ~1e-5 and ~1e-4 over these 20 and 37 cycles (bound 1e-6): the
    simulated frequencies and damping agree with the eigenvalues to better than that.
    """
    U = 0.6 * flutter.analyze(FLAT_PLATE, MODEL).speed
    fs = 200.0
    decay = simulate_decay(FLAT_PLATE, MODEL, U, 0.004, 0.02, n=2000, fs=fs)
    lam = AeroelasticSystem(FLAT_PLATE, MODEL, U).eigenvalues()
    y = np.column_stack([decay.h / 0.004, decay.alpha / 0.02])

    def residual(poles: np.ndarray) -> float:
        columns = []
        for p in poles:
            if p.imag > 0:
                e = np.exp(p * decay.t)
                columns += [e.real, e.imag]
            elif p.imag == 0:
                columns.append(np.exp(p.real * decay.t))
        basis = np.column_stack(columns)
        coef, *_ = np.linalg.lstsq(basis, y, rcond=None)
        return float(np.abs(basis @ coef - y).max() / np.abs(y).max())

    assert lam.size == 8 and np.count_nonzero(lam.imag > 0) == 2
    assert residual(lam) < 1e-12
    oscillatory = lam.imag != 0
    wn, zeta = np.abs(lam), -lam.real / np.abs(lam)

    def poles(wn_: np.ndarray, zeta_: np.ndarray) -> np.ndarray:
        zeta_ = np.where(oscillatory, zeta_, 0.0)
        moved = wn_ * (-zeta_ + 1j * np.sign(lam.imag) * np.sqrt(1 - zeta_**2))
        return np.where(oscillatory, moved, lam)

    assert residual(poles(wn, zeta)) < 1e-12  # the same poles, rebuilt from wn and zeta
    assert residual(poles(wn * (1 + 1e-6), zeta)) > 1e-6
    assert residual(poles(wn, zeta + 1e-5)) > 1e-6


def test_etd2rk_is_second_order_in_the_substep():
    """Halving the integrator step divides the error of a cubic-spring decay by 4 (2nd order).

    A strongly nonlinear release (5 % frequency shift in heave, 2 % in pitch) in the wind; the
    reference takes 128 steps per sample. Measured ratios are 4.01 +- 0.01.
    """
    fs, n = 100.0, 300
    effects = [CubicStiffness(k3_h=2.5e6, k3_a=50.0)]
    args = (FLAT_PLATE, MODEL, 5.0, 0.005, 0.03)
    ref = simulate_decay(*args, n=n, fs=fs, effects=effects, oversample=128)
    errors = []
    for oversample in (2, 4, 8):
        d = simulate_decay(*args, n=n, fs=fs, effects=effects, oversample=oversample)
        errors.append(max(np.abs(d.h - ref.h).max() / 0.005,
                          np.abs(d.alpha - ref.alpha).max() / 0.03))
    assert errors[0] > 1e-5  # well above round-off: the ratio measures the truncation error
    for coarse, fine in zip(errors[:-1], errors[1:], strict=True):
        assert coarse / fine == pytest.approx(4.0, rel=0.05)


def test_channel_delay_shifts_the_forces_by_the_delay():
    """A delay of k samples moves lift and moment k samples later; before that, the held force."""
    fs, k = 500.0, 3
    U = 7.0
    plain = simulate_decay(FLAT_PLATE, MODEL, U, 0.004, 0.015, n=1000, fs=fs)
    delayed = simulate_decay(FLAT_PLATE, MODEL, U, 0.004, 0.015, n=1000, fs=fs,
                             effects=[ChannelDelay(k / fs)])
    for name in ("h", "alpha"):
        np.testing.assert_array_equal(delayed.measured[name], plain.measured[name])
    for name in ("lift", "moment"):
        np.testing.assert_array_equal(delayed.clean[name], plain.clean[name])
        x = getattr(delayed, name)
        # The spline passes through its knots: exact to round-off at whole-sample delays.
        np.testing.assert_allclose(x[k:], getattr(plain, name)[:-k], rtol=1e-12,
                                   atol=1e-12 * np.abs(x).max())
    system = AeroelasticSystem(FLAT_PLATE, MODEL, U)
    static = system.forces(system.initial_state(0.004, 0.015), np.zeros(2))
    np.testing.assert_allclose(delayed.lift[:k], static[0] / FLAT_PLATE.B, rtol=1e-12)
    np.testing.assert_allclose(delayed.moment[:k], static[1], rtol=1e-12)
    clean, measured = delayed.held(np.array([-0.2, -0.1]))
    assert np.all(clean["h"] == 0.004) and np.all(clean["alpha"] == 0.015)
    np.testing.assert_allclose(measured["lift"], static[0] / FLAT_PLATE.B, rtol=1e-12)


def test_sensor_crosstalk_mixes_the_displacements_as_documented():
    """h_meas = h + h_from_alpha alpha, alpha_meas = alpha + alpha_from_h h; physics unchanged."""
    effect = SensorCrosstalk(h_from_alpha=0.01, alpha_from_h=0.2)
    plain = simulate_decay(FLAT_PLATE, MODEL, 6.0, 0.004, 0.02, n=600, fs=200.0)
    mixed = simulate_decay(FLAT_PLATE, MODEL, 6.0, 0.004, 0.02, n=600, fs=200.0, effects=[effect])
    for name in CHANNELS:
        np.testing.assert_array_equal(mixed.clean[name], plain.clean[name])
    np.testing.assert_array_equal(mixed.h, plain.h + 0.01 * plain.alpha)
    np.testing.assert_array_equal(mixed.alpha, plain.alpha + 0.2 * plain.h)
    np.testing.assert_array_equal(mixed.lift, plain.lift)
    np.testing.assert_array_equal(mixed.moment, plain.moment)
    clean, measured = mixed.held(np.array([-0.01]))
    assert measured["h"][0] == pytest.approx(0.004 + 0.01 * 0.02)
    assert measured["alpha"][0] == pytest.approx(0.02 + 0.2 * 0.004)


def test_release_simulation_is_the_decay_plus_hold_and_noise():
    """simulators.tunnel.simulate_release wraps simulate_decay: same numbers where they overlap."""
    effects = [VortexShedding(cl=0.05, cm=0.01), ChannelDelay(0.004), CubicStiffness(k3_a=50.0)]
    args = (FLAT_PLATE, MODEL, 6.0, 0.003, 0.02)
    decay = simulate_decay(*args, n=400, fs=200.0, effects=effects)
    rel = simulate_release(*args, duration=2.0, fs=200.0, effects=effects, pre_s=0.25)
    after = rel.t >= 0
    np.testing.assert_array_equal(rel.t[after], decay.t)
    for name in CHANNELS:
        np.testing.assert_array_equal(getattr(rel, name)[after], getattr(decay, name))
        np.testing.assert_array_equal(rel.clean[name][after], decay.clean[name])
    clean, measured = decay.held(rel.t[~after])
    for name in CHANNELS:
        np.testing.assert_array_equal(getattr(rel, name)[~after], measured[name])
        np.testing.assert_array_equal(rel.clean[name][~after], clean[name])


def test_a_decay_feeds_the_release_processing_directly():
    """Release.from_simulation takes a SimulatedDecay (t, channels, U, rho), as for the tunnel's."""
    decay = simulate_decay(FLAT_PLATE, MODEL, 6.0, 0.003, 0.02, n=400, fs=200.0)
    release = Release.from_simulation(decay)
    assert release.U == 6.0 and release.rho == FLAT_PLATE.rho
    np.testing.assert_array_equal(release.alpha, decay.alpha)


def test_the_effects_are_one_set_of_classes():
    """simulators.effects re-exports ident.physics.effects: one class per effect, one registry."""
    assert simulators.effects.EFFECT_NAMES is ident.physics.effects.EFFECT_NAMES
    for name in simulators.effects.__all__:
        assert getattr(simulators.effects, name) is getattr(ident.physics.effects, name)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"n": 1}, ValueError, "n must be an integer >= 2"),
        ({"n": 10.0}, ValueError, "n must be an integer >= 2"),
        ({"fs": 0.0}, ValueError, "fs must be > 0"),
        ({"oversample": 0}, ValueError, "oversample must be an integer"),
        ({"effects": ["cubic_stiffness"]}, TypeError, "Effect instances"),
    ],
)
def test_bad_input_is_refused(kwargs, error, match):
    """Bad sample counts, rates, step counts and effects raise, naming the problem."""
    args = {"n": 100, "fs": 100.0} | kwargs
    with pytest.raises(error, match=match):
        simulate_decay(FLAT_PLATE, MODEL, 5.0, 0.0, 0.01, **args)


def test_held_times_must_be_before_the_release():
    """held() is for t < 0 only: the model moves from t = 0 on."""
    decay = simulate_decay(FLAT_PLATE, MODEL, 5.0, 0.0, 0.01, n=100, fs=100.0)
    with pytest.raises(ValueError, match="t < 0"):
        decay.held(np.array([-0.1, 0.0]))
