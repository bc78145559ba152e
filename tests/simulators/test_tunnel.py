"""Physics of simulated free-vibration releases: decay, growth, forces, noise and bad input."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.signal import find_peaks

from ident import AeroelasticSystem, RationalFunctionModel, SectionModel
from ident.model import flat_plate, flutter
from simulators import simulate_release

SECTION = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.01, zeta_a=0.008)
STILL_AIR = RationalFunctionModel(np.zeros((3, 2, 2)), [])  # no aerodynamic force at all


def log_decrement(x: np.ndarray) -> tuple[float, float]:
    """Mean logarithmic decrement per cycle and mean period (in samples) from positive peaks."""
    peaks, _ = find_peaks(x)
    amplitudes = x[peaks]
    slope = np.polyfit(np.arange(peaks.size), np.log(amplitudes), 1)[0]
    return -slope, float(np.mean(np.diff(peaks)))


@pytest.mark.parametrize(("dof", "f", "zeta"), [("h", 2.0, 0.01), ("alpha", 4.0, 0.008)])
def test_still_air_release_decays_with_structural_damping_and_frequency(dof, f, zeta):
    """At U = 0 (no added mass) the decay has the structural log decrement and frequency."""
    h0, a0 = (0.005, 0.0) if dof == "h" else (0.0, 0.02)
    fs = 1000.0
    rel = simulate_release(SECTION, STILL_AIR, 0.0, h0, a0, duration=20.0, fs=fs)
    delta, period = log_decrement(getattr(rel, dof))
    expected = 2 * np.pi * zeta / np.sqrt(1 - zeta**2)
    # 2 % is the bound; peak picking on 1 kHz samples errs by < 0.1 % here.
    assert delta == pytest.approx(expected, rel=0.02)
    # Peak spacing is quantised to one sample in ~40 periods: 0.1 % resolution.
    assert fs / period == pytest.approx(f * np.sqrt(1 - zeta**2), rel=2e-3)
    other = rel.alpha if dof == "h" else rel.h
    assert np.all(other == 0.0)  # uncoupled section: the other degree of freedom never moves


def test_still_air_flat_plate_feels_its_added_mass():
    """At U = 0 the flat plate's heave frequency drops by the added mass pi rho B^2 / 4."""
    rel = simulate_release(SECTION, flat_plate.jones_model(), 0.0, 0.005, 0.0,
                           duration=20.0, fs=1000.0)
    _, period = log_decrement(rel.h)
    m_added = np.pi * SECTION.rho * SECTION.B**2 / 4
    f_expected = SECTION.fh * np.sqrt(SECTION.m / (SECTION.m + m_added))
    zeta_still_air = SECTION.zeta_h * np.sqrt(SECTION.m / (SECTION.m + m_added))
    f_damped = f_expected * np.sqrt(1 - zeta_still_air**2)
    assert 1000.0 / period == pytest.approx(f_damped, rel=2e-3)  # one-sample quantisation
    # The still-air force is the added-mass force only: L = -m_a h''.
    h_dd = np.gradient(np.gradient(rel.h, rel.t), rel.t)
    inner = slice(5, -5)
    np.testing.assert_allclose(rel.lift[inner], -m_added * h_dd[inner],
                               atol=1e-3 * np.abs(rel.lift).max())  # O(dt^2) differencing


def test_release_above_flutter_grows_and_below_decays():
    """Just above the flutter speed the release grows; at 90 % of it, it decays."""
    model = flat_plate.jones_model()
    U_f = flutter.analyze(SECTION, model).speed
    above = simulate_release(SECTION, model, 1.03 * U_f, 0.0, 0.01, duration=20.0, fs=500.0)
    below = simulate_release(SECTION, model, 0.9 * U_f, 0.0, 0.01, duration=20.0, fs=500.0)
    early, late = slice(0, 1000), slice(-1000, None)
    assert np.abs(above.alpha[late]).max() > 2 * np.abs(above.alpha[early]).max()
    assert np.abs(below.alpha[late]).max() < 0.5 * np.abs(below.alpha[early]).max()


def test_linear_release_matches_the_matrix_exponential():
    """The exact discretisation reproduces expm(A t) z0 at every sample to round-off."""
    model = flat_plate.jones_model()
    rel = simulate_release(SECTION, model, 8.0, 0.004, 0.015, duration=5.0, fs=200.0)
    system = AeroelasticSystem(SECTION, model, 8.0)
    z0 = system.initial_state(0.004, 0.015)
    for k in (0, 1, 17, 999):
        z = expm(system.matrix() * rel.t[k]) @ z0
        assert rel.h[k] == pytest.approx(z[0] * SECTION.B, abs=1e-12)
        assert rel.alpha[k] == pytest.approx(z[1], abs=1e-12)


def test_forces_follow_the_roger_model_computed_independently():
    """Lift and moment equal the Roger forces rebuilt from the displacements alone.

    The lag states are rebuilt by integrating x' = q' - (U/B) d x from the sampled q, and q', q''
    come from finite differences, so the check shares no code with the simulator.
    """
    U, fs = 8.0, 4000.0
    model = flat_plate.jones_model()
    rel = simulate_release(SECTION, model, U, 0.004, 0.015, duration=3.0, fs=fs)
    B, dt = SECTION.B, 1.0 / fs
    q = np.column_stack([rel.h / B, rel.alpha])
    qd = np.gradient(q, dt, axis=0)
    qdd = np.gradient(qd, dt, axis=0)
    f = 0.5 * SECTION.rho * (U**2 * B**2 * q @ model.A[0].T + U * B**3 * qd @ model.A[1].T
                             + B**4 * qdd @ model.A[2].T)
    for lag, d in enumerate(model.d):
        # x_l(t) = int_0^t exp(-(U/B) d (t - s)) dq(s): a recursive exact update for piecewise
        # linear q, so the only error is that of the sampled q.
        a = np.exp(-(U / B) * d * dt)
        x = np.zeros_like(q)
        dq = np.diff(q, axis=0)
        gain = (1 - a) / ((U / B) * d * dt)
        for k in range(1, q.shape[0]):
            x[k] = a * x[k - 1] + gain * dq[k - 1]
        f += 0.5 * SECTION.rho * U**2 * B**2 * x @ model.A[3 + lag].T
    inner = slice(10, -10)
    # Second-order differences at 4 kHz on a 3 Hz signal: relative errors ~1e-4; allow 2e-3.
    np.testing.assert_allclose(rel.lift[inner], f[inner, 0] / B,
                               atol=2e-3 * np.abs(rel.lift).max())
    np.testing.assert_allclose(rel.moment[inner], f[inner, 1],
                               atol=2e-3 * np.abs(rel.moment).max())


def test_noise_is_seeded_and_scaled_to_each_channel_rms():
    """Noise of 5 % of each channel's RMS; the same seed gives the same record."""
    args = (SECTION, flat_plate.jones_model(), 6.0, 0.005, 0.02)
    a = simulate_release(*args, duration=20.0, fs=500.0, noise=0.05, rng=7)
    b = simulate_release(*args, duration=20.0, fs=500.0, noise=0.05, rng=7)
    c = simulate_release(*args, duration=20.0, fs=500.0, noise=0.05, rng=8)
    for name in ("h", "alpha", "lift", "moment"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        assert not np.array_equal(getattr(a, name), getattr(c, name))
        residual = getattr(a, name) - a.clean[name]
        rms = np.sqrt(np.mean(a.clean[name] ** 2))
        # 10 000 samples: the sample std of Gaussian noise is within ~1.5 % (2 sigma) of the true.
        assert residual.std() == pytest.approx(0.05 * rms, rel=0.03)


def test_noise_per_channel_and_none_without_noise():
    """A dict gives noise on the named channels only; no noise means measured == clean."""
    args = (SECTION, flat_plate.jones_model(), 6.0, 0.005, 0.02)
    rel = simulate_release(*args, duration=5.0, fs=500.0, noise={"lift": 0.02}, rng=1)
    assert np.array_equal(rel.h, rel.clean["h"]) and np.array_equal(rel.moment, rel.clean["moment"])
    assert not np.array_equal(rel.lift, rel.clean["lift"])


def test_hold_before_release_is_static():
    """pre_s adds a held, motionless stretch before t = 0 with the static aerodynamic force."""
    model = flat_plate.jones_model()
    rel = simulate_release(SECTION, model, 6.0, 0.0, 0.02, duration=2.0, fs=100.0, pre_s=0.5)
    held = rel.t < 0
    assert held.sum() == 50 and rel.t[0] == pytest.approx(-0.5)
    assert np.all(rel.alpha[held] == 0.02) and np.all(rel.h[held] == 0.0)
    qd_B = 0.5 * SECTION.rho * 6.0**2 * SECTION.B
    # Static lift on a held plate: qd B A1[0, 1] alpha0 (= -2 pi qd B alpha0, thin-aerofoil theory).
    np.testing.assert_allclose(rel.lift[held], qd_B * model.A[0, 0, 1] * 0.02, rtol=1e-12)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"U": -1.0}, "U must be >= 0"),
        ({"duration": 0.0}, "duration must be > 0"),
        ({"fs": -5.0}, "fs must be > 0"),
        ({"h0": float("nan")}, "h0 must be finite"),
        ({"noise": 0.02}, "noise needs rng"),
        ({"noise": {"pressure": 0.1}, "rng": 1}, "unknown channel"),
        ({"noise": -0.1, "rng": 1}, "noise for h must be a finite fraction"),
        ({"oversample": 0}, "oversample must be an integer"),
        ({"pre_s": -1.0}, "pre_s must be >= 0"),
        ({"duration": 0.001}, "at least 2 samples"),
    ],
)
def test_bad_input_is_refused_with_a_clear_message(kwargs, match):
    """Every bad argument raises ValueError naming the problem."""
    args = {"U": 5.0, "h0": 0.0, "alpha0": 0.01, "duration": 1.0, "fs": 100.0} | kwargs
    with pytest.raises(ValueError, match=match):
        simulate_release(SECTION, flat_plate.jones_model(), args.pop("U"), args.pop("h0"),
                         args.pop("alpha0"), **args)


def test_tap_pressures_of_a_release_integrate_to_its_forces():
    """The scanner-side view: pressures generated for a tap layout integrate to lift and moment."""
    from ident import TapLayout

    taps = TapLayout.rectangle(B=SECTION.B, D=0.02, taps_per_face=32)
    rel = simulate_release(SECTION, flat_plate.jones_model(), 8.0, 0.004, 0.015, duration=2.0,
                           fs=200.0, noise=0.02, rng=2)
    qd = 0.5 * SECTION.rho * 8.0**2
    p = rel.pressures(taps, mean=qd * np.where(taps.nz < 0, -0.6, -0.2))  # a plausible mean Cp
    lift, moment = taps.integrate(p)
    np.testing.assert_allclose(lift, rel.lift, atol=1e-9 * np.abs(rel.lift).max())
    np.testing.assert_allclose(moment, rel.moment, atol=1e-9 * np.abs(rel.moment).max())
