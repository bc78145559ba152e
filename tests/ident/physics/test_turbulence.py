"""Turbulence: spectra, admittance, coherence, buffeting signs and the seeded generator."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, signal, stats

from ident.model.quasi_steady import StaticCoefficients
from ident.physics.turbulence import (
    GustField,
    TurbulenceSpec,
    buffeting_force_spectrum,
    buffeting_forces,
    buffeting_gain,
    davenport_function,
    joint_acceptance,
    von_karman_u,
    von_karman_w,
)

SPEC = TurbulenceSpec(Iu=0.1, Iw=0.08, Lux=0.6, Lwx=0.25, Cuy=10.0, Cwy=8.0,
                      admittance="davenport")
STATIC = StaticCoefficients(C_D=0.3, C_L=0.1, C_M=0.02, dC_D=0.4, dC_L=-5.0, dC_M=1.2)
B, SPAN, RHO, U = 0.3, 1.0, 1.2, 6.0


@pytest.mark.parametrize(("spectrum", "L"), [(von_karman_u, 0.6), (von_karman_w, 0.25)])
def test_von_karman_spectra_integrate_to_the_variance(spectrum, L):
    """Each spectrum integrates to sigma^2 (the 70.8 and 283.2 constants give 0.99986)."""
    sigma = 0.7
    total, err = integrate.quad(lambda f: spectrum(f, U, sigma, L), 0.0, np.inf, limit=500)
    assert err < 1e-6
    assert total == pytest.approx(sigma**2, rel=0.01)


@pytest.mark.parametrize("a", [1e-4, 5e-3, 0.3, 3.0, 40.0])
def test_joint_acceptance_is_the_double_integral_of_the_coherence(a):
    """J^2 = (1/s^2) int int exp(-C f |y1 - y2| / U) dy1 dy2, on both sides of the series switch.

    The square is integrated as twice its triangle y1 < y2 (smooth there: no kink on y1 = y2).
    """
    C, span = 8.0, 1.3
    f = a * U / (C * span)
    half, _ = integrate.dblquad(lambda y1, y2: math.exp(-C * f * (y2 - y1) / U),
                                0.0, span, 0.0, lambda y2: y2, epsabs=1e-13, epsrel=1e-11)
    assert float(joint_acceptance(f, U, C, span)) == pytest.approx(2 * half / span**2, rel=1e-8)


def test_davenport_function_is_continuous_at_the_series_switch():
    x = np.array([1e-2 * (1 - 1e-12), 1e-2])
    values = davenport_function(x)
    assert values[0] == pytest.approx(values[1], rel=1e-12)
    assert float(davenport_function(0.0)) == 1.0


def test_buffeting_gain_is_the_linearised_force_of_the_tilted_relative_wind():
    """Finite differences of the exact wind-axis forces (w up) give the quasi-steady gains.

    Relative wind (U + u, w up) at angle phi = atan(w / (U + u)) from below: the effective
    nose-up angle rises by phi; lift (down) and drag are perpendicular to and along it.
    Central differences with steps 1e-4 U have errors ~1e-8 relative.
    """
    qd = 0.5 * RHO * U**2

    def body_forces(u, w):
        V2 = (U + u) ** 2 + w**2
        phi = math.atan2(w, U + u)
        c_l = STATIC.C_L + STATIC.dC_L * phi
        c_d = STATIC.C_D + STATIC.dC_D * phi
        c_m = STATIC.C_M + STATIC.dC_M * phi
        q = 0.5 * RHO * V2
        L = q * B * (c_l * math.cos(phi) - c_d * math.sin(phi))
        D = q * B * (c_d * math.cos(phi) + c_l * math.sin(phi))
        return np.array([L * B, q * B**2 * c_m, D * B])

    step = 1e-4 * U
    numeric = np.column_stack([
        (body_forces(step, 0.0) - body_forces(-step, 0.0)) / (2 * step),
        (body_forces(0.0, step) - body_forces(0.0, -step)) / (2 * step),
    ])
    np.testing.assert_allclose(buffeting_gain(STATIC, U, B, RHO), numeric, rtol=1e-7)
    # Scanlan/Davenport's lift-up form: L_up = qd B [2 C_L^up u/U + (C_L'^up + C_D) w/U].
    up = StaticCoefficients.from_lift_up(C_D=0.3, C_L=-0.1, C_M=0.02, dC_D=0.4, dC_L=5.0,
                                         dC_M=1.2)
    assert up == STATIC
    lift_up = -buffeting_gain(up, U, B, RHO)[0] / B
    np.testing.assert_allclose(lift_up, qd * B / U * np.array([2 * -0.1, 5.0 + 0.3]))


def test_an_upward_gust_lifts_a_flat_plate_and_pitches_it_nose_up():
    gain = buffeting_gain(StaticCoefficients.flat_plate(), U, B, RHO)
    assert gain[0, 1] < 0 and gain[1, 1] > 0  # L positive down, M positive nose-up
    assert gain[0, 0] == 0.0 and gain[1, 0] == 0.0  # no mean lift or moment at zero incidence


def test_spec_and_static_validation_and_dicts():
    for bad, message in [({"Iu": -0.1}, "Iu must be >= 0"), ({"Lux": 0.0}, "Lux must be > 0"),
                         ({"admittance": "sears"}, "admittance must be one of"),
                         ({"decay": -1.0}, "decay must be > 0"),
                         ({"Cwy": float("nan")}, "Cwy must be finite")]:
        with pytest.raises(ValueError, match=message):
            TurbulenceSpec(**{**SPEC.to_dict(), **bad})
    assert TurbulenceSpec.from_dict(SPEC.to_dict()) == SPEC
    assert StaticCoefficients.from_dict(STATIC.to_dict()) == STATIC
    with pytest.raises(TypeError, match="unknown TurbulenceSpec key"):
        TurbulenceSpec.from_dict({**SPEC.to_dict(), "Iv": 0.1})
    with pytest.raises(ValueError, match="missing key"):
        StaticCoefficients.from_dict({"C_D": 1.0})
    with pytest.raises(ValueError, match="C_L must be finite"):
        StaticCoefficients(C_D=0.1, C_L=float("inf"), C_M=0, dC_D=0, dC_L=0, dC_M=0)


def _series(seed, n=2**20, fs=200.0):
    return buffeting_forces(SPEC, U, STATIC, B=B, span=SPAN, rho=RHO, n=n, fs=fs, rng=seed)


def test_generated_forces_have_the_target_spectrum_and_variance():
    """Welch PSD and variance of a generated series against the target force spectrum.

    Welch (Hann, 50 % overlap, K = 511 segments of 4096): each bin is a scaled chi-square
    estimate with relative standard deviation sqrt(1.06 / K) = 4.6 %; every bin above the
    fourth (leakage at the steep low end) must lie within 5 of those, and the mean ratio over
    the M bins within 4 sqrt(2 x 1.06 / (K M)) (adjacent Hann bins are correlated: M/2
    independent). The variance of one period of the generated series is a weighted sum of
    independent exponentials, sum_k S_k df |z_k|^2 / 2, whose relative standard deviation
    sqrt(sum S_k^2) / sum S_k is computed from the target; the tolerance is 4 of them plus the
    Riemann error of the sum against the integral to fs/2 (0.2 %).
    """
    fs, n, nperseg = 200.0, 2**20, 4096
    F = _series(3, n, fs)
    f, P = signal.welch(F, fs=fs, nperseg=nperseg, axis=0)
    target = buffeting_force_spectrum(SPEC, STATIC, f, U=U, B=B, span=SPAN, rho=RHO)
    K = 2 * n // nperseg - 1
    band = slice(4, -1)
    for i in range(3):
        ratio = P[band, i] / target[band, i, i]
        assert np.all(np.abs(ratio - 1) < 5 * math.sqrt(1.06 / K)), i
        assert abs(ratio.mean() - 1) < 4 * math.sqrt(2 * 1.06 / (K * ratio.size)), i
    _, P_lm = signal.csd(F[:, 0], F[:, 1], fs=fs, nperseg=nperseg)
    cross = P_lm.real[band] / target[band, 0, 1]
    assert abs(cross.mean() - 1) < 0.01
    df = fs / n
    fk = np.arange(1, n // 2) * df
    Sk = buffeting_force_spectrum(SPEC, STATIC, fk, U=U, B=B, span=SPAN, rho=RHO)
    for i in range(3):
        exact, _ = integrate.quad(
            lambda x, i=i: buffeting_force_spectrum(SPEC, STATIC, [x], U=U, B=B, span=SPAN,
                                                    rho=RHO)[0, i, i],
            0.0, fs / 2, limit=500, points=[0.01, 0.1, 1.0])
        rel_sd = math.sqrt(np.sum(Sk[:, i, i] ** 2)) / np.sum(Sk[:, i, i])
        assert F[:, i].var() / exact == pytest.approx(1.0, abs=4 * rel_sd + 0.002), i


def test_the_generator_is_reproducible_and_needs_a_seed():
    a, b, c = _series(11, 4096), _series(11, 4096), _series(12, 4096)
    assert np.array_equal(a, b) and not np.allclose(a, c)
    with pytest.raises(ValueError, match="needs rng"):
        _series(None, 4096)


def test_the_gust_field_is_one_field_of_distance_for_every_speed():
    """Sampled at t = k dx / U the field returns its own values times U, at any U."""
    field = GustField.generate(SPEC, B=B, span=SPAN, n=1000, dx=0.01, rng=2)
    for speed in (2.0, 9.0):
        t = np.arange(1000) * 0.01 / speed
        np.testing.assert_allclose(field.gusts(speed, t), speed * field.values, atol=1e-12)
    # Periodic, and shifted by whole samples it is the rolled field.
    np.testing.assert_allclose(field.shifted(0.05).gusts(1.0, np.arange(1000) * 0.01),
                               np.roll(field.values, -5, axis=0), atol=1e-12)
    assert field.length == pytest.approx(10.0)


def test_the_gust_field_is_linear_between_its_samples_and_wraps_around():
    """Between samples: numpy's linear interpolation of the periodic field (an independent one).

    Times before zero and beyond one period (the tunnel samples the field at x = x0 + U t for
    minutes) wrap around. Tolerance 1e-12 m/s: the two interpolations differ by rounding only.
    """
    field = GustField.generate(SPEC, B=B, span=SPAN, n=1000, dx=0.01, rng=3).shifted(2.345)
    rng = np.random.default_rng(0)
    t = np.sort(rng.uniform(-30.0, 30.0, 5000))
    speed = 7.3
    n = field.values.shape[0]
    grid = np.arange(n + 1) * field.dx
    periodic = np.vstack([field.values, field.values[:1]])
    x = np.mod(field.x0 + speed * t, field.length)
    expected = speed * np.column_stack([np.interp(x, grid, periodic[:, j]) for j in range(2)])
    np.testing.assert_allclose(field.gusts(speed, t), expected, atol=1e-12)
    assert np.all(field.gusts(0.0, t) == 0.0)


@pytest.mark.parametrize(("skewness", "kurtosis"), [(0.5, 4.5), (0.0, 6.0), (-0.8, 5.0)])
def test_non_gaussian_gusts_have_the_asked_moments_and_the_gaussian_variance(skewness,
                                                                              kurtosis):
    """Winterstein's transform: the field's skewness and kurtosis near the targets, same std.

    Tolerances: the cubic Hermite model's own moment error, measured on these fields (skewness
    off by -0.01, +0.01 and +0.04, kurtosis by +0.18, -0.04 and +0.55: with a large skewness
    the model overshoots the kurtosis), plus the sampling scatter of one field of 2^20 points
    (about 3 x 10^4 integral scales: std about 0.02 in skewness and 0.05 in kurtosis). The
    std is kept exactly in expectation; one field's within 2 %. The transformed field follows
    the Gaussian one (correlation above 0.95: the same draw).
    """
    base: dict[str, float] = {"Iu": 0.0, "Iw": 0.01, "Lux": 1.0, "Lwx": 0.3, "Cuy": 10.0,
                              "Cwy": 8.0}
    gaussian = GustField.generate(TurbulenceSpec(**base), B=B, span=SPAN, n=2**20, dx=0.01,
                                  rng=1).values[:, 1]
    spec = TurbulenceSpec(**base, skewness=skewness, kurtosis=kurtosis)
    w = GustField.generate(spec, B=B, span=SPAN, n=2**20, dx=0.01, rng=1).values[:, 1]
    assert stats.skew(w) == pytest.approx(skewness, abs=0.1)
    assert stats.kurtosis(w, fisher=False) == pytest.approx(kurtosis, abs=0.7)
    assert w.std() == pytest.approx(gaussian.std(), rel=0.02)
    assert np.corrcoef(w, gaussian)[0, 1] > 0.95
    assert TurbulenceSpec.from_dict(spec.to_dict()) == spec
    with pytest.raises(ValueError, match="kurtosis <= 8"):
        TurbulenceSpec(**base, kurtosis=2.0)
    with pytest.raises(ValueError, match=r"\|skewness\| <= 1"):
        TurbulenceSpec(**base, skewness=1.5)
