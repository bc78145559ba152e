"""ident.simulation.decay in turbulent flow: random response, recorded forces, mean load, seeds."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm

from ident import AeroelasticSystem, RationalFunctionModel, SectionModel
from ident.model import flat_plate, flutter
from ident.model.quasi_steady import StaticCoefficients
from ident.physics.effects import ChannelDelay, CubicStiffness
from ident.physics.turbulence import GustField, TurbulenceSpec, buffeting_forces
from ident.simulation.decay import simulate_decay
from simulators import simulate_release

SECTION = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.01, zeta_a=0.01)
MODEL = flat_plate.jones_model()
SPEC = TurbulenceSpec(Iu=0.1, Iw=0.08, Lux=0.6, Lwx=0.25, Cuy=10.0, Cwy=8.0,
                      admittance="davenport")
PLATE = StaticCoefficients.flat_plate()
SPAN = 1.0


def turbulent(U, h0=0.0, alpha0=0.0, *, n, fs=200.0, seed=5, **kwargs):
    kwargs.setdefault("turbulence", SPEC)
    if isinstance(kwargs["turbulence"], TurbulenceSpec):
        kwargs.setdefault("span", SPAN)
        kwargs.setdefault("rng", seed)
    return simulate_decay(SECTION, kwargs.pop("model", MODEL), U, h0, alpha0, n=n, fs=fs,
                          static=kwargs.pop("static", PLATE), **kwargs)


def test_random_response_variance_matches_the_frequency_domain():
    """Long-run variances of h and alpha against sigma^2 = int |H|^2 S_F df.

    H(f) = (Ks - w^2 Ms + i w Cs - qd B^2 Q(i K))^-1 from the same Roger model, S_F the
    span-averaged buffeting spectrum, integrated to fs/2 (what is simulated). 1200 s at 200 Hz
    from rest, the first 30 s (over 10 time constants of the least-damped mode) dropped. The
    variance of a T-second record of a Gaussian process has relative standard deviation
    sqrt(int G^2 df / T) / sigma^2 (2.6 % and 2.8 % here); tolerance 4 of those plus 0.5 % for
    the linear interpolation of the force (sinc^4(f/fs): 0.3 % at 4 Hz). Measured ratios
    1.038 (h) and 0.988 (alpha).
    """
    U = 0.5 * flutter.analyze(SECTION, MODEL).speed
    fs, T, skip_s = 200.0, 1200.0, 30.0
    d = turbulent(U, n=int(T * fs), fs=fs)
    f = np.linspace(1e-4, fs / 2, 200001)
    df = f[1] - f[0]
    w = 2 * np.pi * f[:, None, None]
    s = SECTION
    qd = 0.5 * s.rho * U**2
    Z = (s.stiffness_matrix() - w**2 * s.mass_matrix() + 1j * w * s.damping_matrix()
         - qd * s.B**2 * MODEL.Q(1j * 2 * np.pi * f * s.B / U))
    H = np.linalg.inv(Z)
    from ident.physics.turbulence import buffeting_force_spectrum

    S_F = buffeting_force_spectrum(SPEC, PLATE, f, U=U, B=s.B, span=SPAN, rho=s.rho)[:, :2, :2]
    S_q = np.einsum("kij,kjl,kml->kim", H, S_F, H.conj()).real
    skip = int(skip_s * fs)
    record = (d.t.size - skip) / fs
    for G, x in ((S_q[:, 0, 0] * s.B**2, d.h), (S_q[:, 1, 1], d.alpha)):
        theory = G.sum() * df
        rel_sd = math.sqrt((G**2).sum() * df / record) / theory
        assert rel_sd < 0.035  # the record is long enough for a meaningful check
        assert x[skip:].var() / theory == pytest.approx(1.0, abs=4 * rel_sd + 0.005)


def test_recorded_forces_are_self_excited_plus_the_generated_buffeting():
    """Without self-excited forces, the recorded forces are exactly the generator's series.

    The same seed through ident.physics.turbulence.buffeting_forces on the same grid (dx = U / fs)
    gives the same gusts; the mean load of the static coefficients is added.
    """
    static = StaticCoefficients(C_D=0.3, C_L=0.1, C_M=0.02, dC_D=0.4, dC_L=-5.0, dC_M=1.2)
    U, n, fs = 6.0, 3000, 200.0
    still = RationalFunctionModel(np.zeros((3, 2, 2)), [])
    d = turbulent(U, n=n, fs=fs, model=still, static=static, seed=9)
    F = buffeting_forces(SPEC, U, static, B=SECTION.B, span=SPAN, rho=SECTION.rho, n=n, fs=fs,
                         rng=9)
    qd = 0.5 * SECTION.rho * U**2
    np.testing.assert_allclose(d.lift * SECTION.B, F[:, 0] + qd * SECTION.B**2 * 0.1,
                               rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(d.moment, F[:, 1] + qd * SECTION.B**2 * 0.02, rtol=1e-9,
                               atol=1e-12)
    np.testing.assert_allclose(d.wind_load[:, 0], d.lift * SECTION.B, rtol=1e-12)
    assert d.moment.std() > 0.1 * abs(d.moment.mean())


def test_a_release_in_turbulence_is_the_smooth_decay_plus_the_response_from_rest():
    """Linearity: (release in turbulence) = (release in smooth flow) + (turbulence from rest).

    This holds for every recorded channel, so the recorded forces in turbulence are the
    self-excited forces of the motion plus the buffeting. Round-off bound 1e-9 of the signal.
    """
    U, n = 6.0, 2000
    field = GustField.generate(SPEC, B=SECTION.B, span=SPAN, n=4096, dx=U / 200.0, rng=4)
    release = turbulent(U, 0.004, 0.02, n=n, turbulence=field)
    rest = turbulent(U, n=n, turbulence=field)
    smooth = simulate_decay(SECTION, MODEL, U, 0.004, 0.02, n=n, fs=200.0)
    for name in ("h", "alpha", "lift", "moment"):
        total = getattr(smooth, name) + getattr(rest, name)
        np.testing.assert_allclose(getattr(release, name), total,
                                   atol=1e-9 * np.abs(total).max())
    assert rest.alpha.std() > 0.05 * smooth.alpha.std()  # the turbulence is not negligible


def test_without_wind_load_the_decay_is_the_exact_exponential_stepping():
    """No static and no turbulence: z[k] = expm(A dt) z[k-1] and the self-excited forces.

    The integrator applies the powers of ``expm(A dt)`` a block at a time, so it equals the
    step-by-step recursion to round-off (1e-12 of the amplitude: the two orders of the same
    products differ in the last bits only). A zero static load takes the forced
    (first-order-hold) path: equal to round-off too.
    """
    U, n, fs = 6.0, 500, 200.0
    d = simulate_decay(SECTION, MODEL, U, 0.004, 0.02, n=n, fs=fs)
    system = AeroelasticSystem(SECTION, MODEL, U)
    A = system.matrix()
    phi = expm(A * (1.0 / fs))
    z = np.empty((n, system.n_states))
    z[0] = system.initial_state(0.004, 0.02)
    for k in range(1, n):
        z[k] = phi @ z[k - 1]
    forces = system.forces(z, z @ A[2:4, :].T)
    np.testing.assert_allclose(d.alpha, z[:, 1], rtol=0, atol=1e-12 * 0.02)
    np.testing.assert_allclose(d.h, z[:, 0] * SECTION.B, rtol=0, atol=1e-12 * 0.004)
    for name, column, scale in (("moment", forces[:, 1], 1.0), ("lift", forces[:, 0], SECTION.B)):
        np.testing.assert_allclose(getattr(d, name), column / scale, rtol=0,
                                   atol=1e-12 * np.abs(column / scale).max())
    assert d.wind_load is None and d.gusts is None
    zero = StaticCoefficients(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    d0 = simulate_decay(SECTION, MODEL, U, 0.004, 0.02, n=n, fs=fs, static=zero)
    np.testing.assert_allclose(d0.alpha, d.alpha, atol=1e-12 * 0.02)
    np.testing.assert_allclose(d0.moment, d.moment, atol=1e-10 * np.abs(d.moment).max())


def test_seeds_reproduce_and_differ():
    a, b, c = (turbulent(6.0, n=400, seed=s) for s in (1, 1, 2))
    assert np.array_equal(a.alpha, b.alpha) and np.array_equal(a.lift, b.lift)
    assert not np.allclose(a.alpha, c.alpha)


def test_the_mean_static_load_shifts_the_equilibrium():
    """A mean moment C_M: the decay settles at (Ks - qd B^2 A1)^-1 qd B^2 [C_L, C_M]."""
    static = StaticCoefficients(C_D=0.1, C_L=0.05, C_M=0.03, dC_D=0.0, dC_L=-2 * math.pi,
                                dC_M=math.pi / 2)
    U, fs = 6.0, 200.0
    d = simulate_decay(SECTION, MODEL, U, 0.0, 0.02, n=int(60 * fs), fs=fs, static=static)
    qd = 0.5 * SECTION.rho * U**2
    q_eq = np.linalg.solve(SECTION.stiffness_matrix() - qd * SECTION.B**2 * MODEL.A[0],
                           qd * SECTION.B**2 * np.array([0.05, 0.03]))
    assert d.alpha[-1] == pytest.approx(q_eq[1], rel=1e-3)
    assert d.h[-1] == pytest.approx(q_eq[0] * SECTION.B, rel=1e-3)
    assert abs(q_eq[1]) > 0.1 * 0.02  # a visible shift
    # Held at (0, 0.02) before the release the model feels the mean load plus A1 q0.
    clean, _ = d.held(np.array([-0.1]))
    held = qd * SECTION.B**2 * (MODEL.A[0] @ np.array([0.0, 0.02]) + np.array([0.05, 0.03]))
    assert clean["moment"][0] == pytest.approx(held[1], rel=1e-12)


def test_the_held_model_sees_the_buffeting_continuously_into_the_release():
    """simulate_release with pre_s: motionless, fluctuating forces, the field continuous at 0."""
    U, fs = 6.0, 200.0
    r = simulate_release(SECTION, MODEL, U, 0.004, 0.02, duration=5.0, fs=fs, pre_s=2.0,
                         static=PLATE, turbulence=SPEC, span=SPAN, rng=3)
    held = r.t < 0
    assert np.all(r.alpha[held] == 0.02) and r.moment[held].std() > 0
    d = turbulent(U, 0.004, 0.02, n=1000, fs=fs, seed=3, pre_s=2.0)
    # The held gusts are the generated field's tail, which wraps onto its start.
    w_held = d.gusts.gusts(U, np.array([-1.0 / fs, 0.0]))
    step = np.abs(np.diff(d.gusts.values[:, 1])).max() * U
    assert abs(w_held[1, 1] - w_held[0, 1]) <= step
    with pytest.raises(ValueError, match="pass pre_s"):
        d.held(np.array([-3.0]))


def test_the_nonlinear_path_takes_the_buffeting():
    """ETD2RK with a vanishing cubic spring and the exact linear path, driven by one field.

    The ETD2RK step treats the force as its explicit term with the same first-order hold, so
    with no nonlinearity it is the exact stepping on a finer grid: agreement to the
    interpolation of the field between grids (~1e-4 of the response here; bound 1e-3).
    """
    U = 6.0
    field = GustField.generate(SPEC, B=SECTION.B, span=SPAN, n=8192, dx=U / 800.0, rng=8)
    linear = turbulent(U, n=1500, turbulence=field)
    nonlinear = turbulent(U, n=1500, turbulence=field, effects=[CubicStiffness(k3_a=1e-12)],
                          oversample=4)
    scale = np.abs(linear.alpha).max()
    np.testing.assert_allclose(nonlinear.alpha, linear.alpha, atol=1e-3 * scale)
    with pytest.raises(ValueError, match="needs static"):
        simulate_decay(SECTION, MODEL, U, 0.0, 0.0, n=10, fs=100.0, turbulence=SPEC, span=1.0,
                       rng=1)
    with pytest.raises(ValueError, match="needs rng"):
        simulate_decay(SECTION, MODEL, U, 0.0, 0.0, n=10, fs=100.0, turbulence=SPEC, span=1.0,
                       static=PLATE)


def test_a_continued_record_is_the_longer_record():
    """continued(n) from the last state equals one record of the total length.

    The states to round-off; the delayed force channel to the fading of the spline's end
    condition over the 16 samples it runs through before the seam (0.27^16 ~ 1e-9).
    """
    U = 6.0
    field = GustField.generate(SPEC, B=SECTION.B, span=SPAN, n=4096, dx=U / 200.0, rng=6)
    effects = [ChannelDelay(delay_s=0.012)]
    whole = turbulent(U, 0.004, 0.02, n=1200, turbulence=field, effects=effects)
    first = turbulent(U, 0.004, 0.02, n=600, turbulence=field, effects=effects)
    more = first.continued(600)
    np.testing.assert_allclose(more.t, whole.t[600:], atol=1e-12)
    for name in ("h", "alpha", "lift", "moment"):
        scale = np.abs(getattr(whole, name)).max()
        np.testing.assert_allclose(getattr(more, name), getattr(whole, name)[600:],
                                   atol=1e-9 * scale)
