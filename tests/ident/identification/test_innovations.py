"""The Kalman filter's likelihood of a release in turbulence, checked against independent routes.

The dense multivariate normal of a short record, the simulator's exact noise-free decay, the
closed form of a second-order low-pass, and the likelihood's own peak on records drawn from the
model. The section and wind speed are the simulated campaign's (0.8 of the flutter speed of the
Jones plate, 11.87 m/s); the buffeting is about half a percent of turbulence intensity
(lift std 0.13 N/m, moment std 0.008 N m/m) and the sensor noise that of the rig's lasers and
pressure scanner.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg
from scipy.optimize import minimize_scalar
from scipy.stats import multivariate_normal

from ident.identification.innovations import (
    ReleaseModel,
    ShapingFilter,
    block_means,
    kalman_filter,
    log_likelihood,
)
from ident.identification.steady_predictor import SteadyPredictor, decorrelated
from ident.model import flat_plate
from ident.model.quasi_steady import StaticCoefficients, quasi_steady_model
from simulators.campaigns import SECTION
from simulators.tunnel import simulate_release

MODEL = flat_plate.jones_model()
U = 9.5  # m/s, 0.8 of the flutter speed (11.87 m/s)
FS = 500.0  # Hz
HOLD = (0.004, 0.02)  # m, rad
#: Buffeting: corner 3 Hz, damping 0.7, lift-moment correlation 0.45 (N m/m s^0.5).
L_TRUE = np.array([[0.015, 0.0], [0.0015, 0.003]])
#: Sensor noise: h m, alpha rad, lift N/m, moment N m/m.
NOISE = np.array([1e-5, 1e-4, 0.05, 0.005])


def release_model(*, scale: float = 1.0, U: float = U, noise=NOISE,
                  L=L_TRUE) -> ReleaseModel:
    shaping = ShapingFilter([3.0, 3.0], [0.7, 0.7], scale * np.asarray(L))
    return ReleaseModel(SECTION, MODEL, U, FS, shaping, noise)


def test_kalman_likelihood_equals_the_dense_normal_with_missing_samples():
    """The innovations' likelihood is the joint normal density of the record, NaNs marginalised."""
    model = release_model()
    n, n_x = 30, model.n_states
    x0 = model.initial_state(*HOLD)
    # The release position known to the lasers' noise: a full, non-trivial initial covariance.
    extra = np.zeros((n_x, n_x))
    extra[0, 0], extra[1, 1] = (NOISE[0] / SECTION.B) ** 2, NOISE[1] ** 2
    P0 = model.initial_covariance(extra)
    y = model.sample(x0, P0, n, np.random.default_rng(7))
    y[3, 2] = y[11, :] = y[17, 0] = y[17, 3] = y[25, 1] = np.nan

    # Mean and covariance of the whole record, propagated independently of the filter:
    # E x_k = Phi^k x0, Cov(x_j, x_k) = Phi^(k-j) P_j (k >= j), P_(j+1) = Phi P_j Phi^T + Qd.
    Phi, Qd, C, R = model.Phi, model.Qd, model.C, model.R
    means, P_states, P = [], [], P0
    x = x0
    for _ in range(n):
        means.append(C @ x)
        P_states.append(P)
        x, P = Phi @ x, Phi @ P @ Phi.T + Qd
    cov = np.zeros((4 * n, 4 * n))
    for j in range(n):
        cross = P_states[j]
        for k in range(j, n):
            block = C @ cross @ C.T
            cov[4 * k : 4 * k + 4, 4 * j : 4 * j + 4] = block
            cov[4 * j : 4 * j + 4, 4 * k : 4 * k + 4] = block.T
            cross = Phi @ cross
        cov[4 * j : 4 * j + 4, 4 * j : 4 * j + 4] += R
    keep = ~np.isnan(y.ravel())
    dense = multivariate_normal.logpdf(y.ravel()[keep], np.concatenate(means)[keep],
                                       cov[np.ix_(keep, keep)])

    result = kalman_filter(model, y, x0, P0, steady_tol=0.0)
    # 1e-9 relative: both are exact; the dense route factors a 114 x 114 covariance whose
    # channels span nine decades (h in m, lift in N/m), which costs it round-off: measured
    # 4e-11 relative.
    assert result.log_likelihood == pytest.approx(dense, rel=1e-9)
    assert np.isnan(result.innovations[11]).all() and np.isnan(result.innovations[17, [0, 3]]).all()
    assert np.isfinite(result.innovations[17, [1, 2]]).all()


def test_held_gain_matches_the_full_recursion():
    """Holding the settled gain changes a 10 s record's likelihood by round-off only."""
    model = release_model()
    x0 = model.initial_state(*HOLD)
    y = model.sample(x0, model.initial_covariance(), 5000, np.random.default_rng(3))
    y[2500:2510, 2] = np.nan  # a burst of missing lift samples mid-record: the gain is let go
    held = kalman_filter(model, y, x0)
    full = kalman_filter(model, y, x0, steady_tol=0.0)
    # Measured: 2e-10 absolute here (5e-8 on a 20 s record with a burst); 1e-6
    # absolute is 1e-11 relative and far below the 0.5 that matters to a likelihood ratio.
    assert held.log_likelihood == pytest.approx(full.log_likelihood, abs=1e-6)
    np.testing.assert_allclose(held.standardized, full.standardized, rtol=0, atol=1e-6)
    # The model is right, so the standardised innovations have unit variance: each channel's
    # sample variance over 5000 samples within 4 standard errors (sqrt(2/5000) = 0.02).
    np.testing.assert_allclose(np.nanvar(held.standardized, axis=0), 1.0, atol=0.08)


def test_recorded_force_is_the_structure_s_inertia_damping_and_stiffness():
    """Self-excited plus buffeting force, as the output rows give it, balances the structure."""
    model = release_model()
    Ac, _, C = model.continuous_matrices()
    x = np.random.default_rng(5).standard_normal((model.n_states, 20))
    q, qd, qdd = x[0:2], x[2:4], (Ac @ x)[2:4]
    # Newton on the section: everything the air does (the recorded lift B and moment) equals
    # Ms q'' + Cs q' + Ks q, whatever the state. An independent route to the output rows,
    # including the buffeting force's added-mass share; only round-off differs (measured
    # 4e-16 of the largest force, asserted 1e-12).
    s = SECTION
    balance = s.mass_matrix() @ qdd + s.damping_matrix() @ qd + s.stiffness_matrix() @ q
    recorded = np.vstack([(C @ x)[2] * s.B, (C @ x)[3]])
    np.testing.assert_allclose(recorded, balance, rtol=1e-12, atol=1e-12 * np.abs(balance).max())


#: A section with sway: the campaign's plate on a lateral spring at 2.5 Hz, Jones's lags with
#: quasi-steady drag; three correlated buffeting forces and six channels (p in m, drag in N/m).
SWAY = SECTION.replace(fp=2.5, zeta_p=0.005)
L_SWAY = np.array([[0.015, 0.0, 0.0], [0.0015, 0.003, 0.0], [-0.002, 0.0004, 0.004]])
NOISE_SWAY = np.concatenate([NOISE, [1e-5, 0.02]])


def sway_model() -> ReleaseModel:
    truth = MODEL.with_sway(quasi_steady_model(StaticCoefficients.flat_plate()))
    shaping = ShapingFilter([3.0, 3.0, 2.0], [0.7, 0.7, 0.6], L_SWAY)
    return ReleaseModel(SWAY, truth, U, FS, shaping, NOISE_SWAY)


def test_with_sway_the_outputs_balance_the_structure_and_the_likelihood_is_the_dense_normal():
    """Three degrees of freedom: the same two independent routes as the planar model's.

    Newton on the section (lift B, moment and drag B as the output rows give them equal Ms q''
    + Cs q' + Ks q for any state, sway as B q_p), and the joint normal density of a short
    record (the same propagation as the planar test's), missing samples included.
    """
    model = sway_model()
    assert model.C.shape == (6, model.n_states) and model.shaping.n_forces == 3
    Ac, _, C = model.continuous_matrices()
    x = np.random.default_rng(5).standard_normal((model.n_states, 20))
    q, qd, qdd = x[0:3], x[3:6], (Ac @ x)[3:6]
    balance = (SWAY.mass_matrix() @ qdd + SWAY.damping_matrix() @ qd
               + SWAY.stiffness_matrix() @ q)
    out = C @ x
    recorded = np.vstack([out[2] * SWAY.B, out[3], out[5] * SWAY.B])
    # Round-off only (measured 4e-16 of the largest force on the planar model).
    np.testing.assert_allclose(recorded, balance, rtol=1e-12, atol=1e-12 * np.abs(balance).max())
    np.testing.assert_allclose(out[4], SWAY.B * q[2], rtol=1e-14)

    n, n_y = 20, 6
    x0 = model.initial_state(0.004, 0.02, -0.003)
    assert x0[2] == pytest.approx(-0.003 / SWAY.B)
    P0 = model.initial_covariance()
    y = model.sample(x0, P0, n, np.random.default_rng(8))
    y[4, 5] = y[9, :] = np.nan
    Phi, Qd, R = model.Phi, model.Qd, model.R
    means, P_states, P, xm = [], [], P0, x0
    for _ in range(n):
        means.append(C @ xm)
        P_states.append(P)
        xm, P = Phi @ xm, Phi @ P @ Phi.T + Qd
    cov = np.zeros((n_y * n, n_y * n))
    for j in range(n):
        cross = P_states[j]
        for k in range(j, n):
            block = C @ cross @ C.T
            cov[n_y * k:n_y * (k + 1), n_y * j:n_y * (j + 1)] = block
            cov[n_y * j:n_y * (j + 1), n_y * k:n_y * (k + 1)] = block.T
            cross = Phi @ cross
        cov[n_y * j:n_y * (j + 1), n_y * j:n_y * (j + 1)] += R
    keep = ~np.isnan(y.ravel())
    dense = multivariate_normal.logpdf(y.ravel()[keep], np.concatenate(means)[keep],
                                       cov[np.ix_(keep, keep)])
    # As the planar test: both exact, the dense route's round-off on channels nine decades
    # apart (measured 4e-11 relative there).
    assert kalman_filter(model, y, x0, P0, steady_tol=0.0).log_likelihood == pytest.approx(
        dense, rel=1e-9)


def test_three_forces_spectrum_integrates_to_their_stationary_covariance():
    """The three-force filter's cross-spectrum, integrated over frequency, is ``C P C^T``.

    Two routes to the forces' covariance: the Lyapunov solution and the quadrature of
    :meth:`ShapingFilter.spectrum` (two-sided, so over all f). Two sections per force with
    zeros, so that the cascade and its output row are exercised for the drag as well.
    """
    shaping = ShapingFilter([[3.0, 9.0], [3.0, 7.0], [2.0, 8.0]], np.full((3, 2), 0.6),
                            L_SWAY, [[0.0, 0.01], [0.0, 0.02], [0.0, 0.015]])
    A_b, _, C_b = shaping.matrices()
    assert A_b.shape == (12, 12) and C_b.shape == (3, 12)
    covariance = C_b @ shaping.stationary_covariance() @ C_b.T
    f = np.linspace(0.0, 400.0, 400001)
    integral = 2.0 * scipy.integrate.trapezoid(shaping.spectrum(f).real, f, axis=0)
    # Each force's spectrum falls at least as f^-6 beyond its sections (9 Hz at most): the
    # tail past 400 Hz and the trapezoid's error are far below 1e-6 of the variances
    # (measured 1e-11).
    np.testing.assert_allclose(integral, covariance, rtol=0,
                               atol=1e-6 * np.abs(np.diag(covariance)).max())


def test_discretisation_keeps_the_stationary_covariance():
    """Van Loan's Phi and Qd carry the continuous stationary covariance onto itself."""
    model = release_model()
    Ac, G, _ = model.continuous_matrices()
    # Below flutter the augmented system is stable: its stationary covariance solves the
    # continuous Lyapunov equation, and the exact discrete model must leave it unchanged.
    P = scipy.linalg.solve_continuous_lyapunov(Ac, -G @ G.T)
    # Phi is the lower-right block of a larger exponential: measured 2e-16 from expm(Ac T).
    np.testing.assert_allclose(model.Phi, scipy.linalg.expm(Ac / FS), rtol=0, atol=1e-13)
    # Round-off of two solvers only: measured 1.3e-17 of the largest entry, asserted 1e-12 (a
    # slip such as Qd without its Phi factor leaves 5e-3).
    scale = np.abs(P).max()
    np.testing.assert_allclose(model.Phi @ P @ model.Phi.T + model.Qd, P, rtol=0,
                               atol=1e-12 * scale)


def test_noise_free_predictions_reproduce_the_simulated_decay():
    """Without buffeting the one-step predictions are the simulator's exact decay, all channels."""
    rel = simulate_release(SECTION, MODEL, U, *HOLD, duration=4.0, fs=FS)
    y = np.column_stack([rel.h, rel.alpha, rel.lift, rel.moment])
    rms = np.sqrt(np.mean(y**2, axis=0))
    # The filter needs S > 0: sensor noise 1e-12 of each channel's RMS. With no process noise
    # and an exact initial state the gain is zero, so the predictions are C Phi^k x0.
    model = release_model(noise=1e-12 * rms, L=np.zeros((2, 2)))
    result = kalman_filter(model, y, model.initial_state(*HOLD))
    error = np.abs(result.predictions - y).max(axis=0) / rms
    # Both discretise exactly (matrix exponentials, the simulator's on its own step): they
    # differ by the exponentials' round-off grown over 2000 steps of a lightly damped system,
    # measured at 1.3e-14 of the RMS; 1e-10 leaves room for other BLAS builds and expm
    # scalings while still catching any modelling slip (a wrong added-mass term is ~1e-2).
    assert error.max() < 1e-10, error


def test_shaping_filter_spectrum_is_a_second_order_low_pass():
    """The matrices give the closed-form spectrum, and the Lyapunov covariance its integral."""
    L = np.array([[0.02, 0.0], [0.004, 0.006]])
    freq, zeta = np.array([3.0, 5.0]), np.array([0.7, 0.3])
    shaping = ShapingFilter(freq, zeta, L)
    f = np.linspace(-40.0, 40.0, 801)
    w = 2 * np.pi * freq
    H = w**2 / (w**2 - (2 * np.pi * f[:, None]) ** 2 + 2j * zeta * w * (2 * np.pi * f[:, None]))
    closed = H[:, :, None] * (L @ L.T) * np.conj(H[:, None, :])
    # Same rational function evaluated two ways: only round-off differs.
    np.testing.assert_allclose(shaping.spectrum(f), closed, rtol=1e-12, atol=1e-18)

    P = shaping.stationary_covariance()
    A_b, B_b, C_b = shaping.matrices()
    # The Lyapunov residual, relative to the noise's input, is round-off.
    assert np.abs(A_b @ P + P @ A_b.T + B_b @ B_b.T).max() < 1e-12 * np.abs(B_b @ B_b.T).max()
    # A second-order low-pass with unit DC gain driven by intensity q has variance q w / (4 zeta).
    np.testing.assert_allclose(np.diag(C_b @ P @ C_b.T), np.diag(L @ L.T) * w / (4 * zeta),
                               rtol=1e-12)
    # And the cross-covariance is the integral of the cross-spectrum over all frequencies
    # (adaptive quadrature asked for 1e-10 relative).
    cross, _ = scipy.integrate.quad(lambda x: shaping.spectrum([x])[0, 0, 1].real,
                                    -np.inf, np.inf, epsabs=0.0, epsrel=1e-10, limit=200)
    assert cross == pytest.approx((C_b @ P @ C_b.T)[0, 1], rel=1e-8)


def cascades(freq: np.ndarray, zeta: np.ndarray, tau: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Return each row's sections in cascade in closed form, ``prod_j w^2 (1 + tau s) / (...)``.

    Shape (len(f), rows): the transfer :class:`ShapingFilter` documents, written out apart
    from its state-space matrices.
    """
    s = 2j * np.pi * f[:, None, None]
    w = 2 * np.pi * freq
    return (w**2 * (1 + tau * s) / (s**2 + 2 * zeta * w * s + w**2)).prod(axis=2)


def variances(shaping: ShapingFilter, force: int) -> tuple[float, float]:
    """Return a force's variance two ways: its spectrum integrated, and the Lyapunov solution's.

    The quadrature is asked for a relative error of 1e-10.
    """
    integrated, _ = scipy.integrate.quad(lambda x: shaping.spectrum([x])[0, force, force].real,
                                         -np.inf, np.inf, epsabs=0.0, epsrel=1e-10, limit=400)
    _, _, C_b = shaping.matrices()
    return integrated, float((C_b @ shaping.stationary_covariance() @ C_b.T)[force, force])


def test_two_sections_give_the_product_of_their_transfers():
    """Each force's cascade is the product of its sections, the zeros' numerators included."""
    L = np.array([[0.02, 0.0], [0.004, 0.006]])
    freq = np.array([[3.0, 9.0], [4.0, 12.0]])
    zeta = np.array([[0.7, 0.5], [1.5, 0.8]])
    tau = np.array([[0.02, 0.01], [0.05, -0.004]])
    shaping = ShapingFilter(freq, zeta, L, tau)
    assert shaping.n_states == 8
    f = np.linspace(-40.0, 40.0, 401)
    H = cascades(freq, zeta, tau, f)
    closed = H[:, :, None] * (L @ L.T) * np.conj(H[:, None, :])
    # Same rational function evaluated two ways: only round-off differs.
    np.testing.assert_allclose(shaping.spectrum(f), closed, rtol=1e-11, atol=1e-18)
    # The force's variance is the integral of its spectrum (quadrature asked for 1e-10).
    integrated, lyapunov = variances(shaping, 1)
    assert integrated == pytest.approx(lyapunov, rel=1e-8)


def test_sources_mixed_after_their_sections_give_a_coherence_that_changes_with_frequency():
    """Mixed after the sections, the forces are ``L`` times independent filtered sources.

    The closed form ``S(f) = L diag(|H_i|^2) L^T`` with each source's cascade ``H_i`` (the
    same sections as above, zeros included) against the matrices' evaluation: round-off
    only. Quasi-steady buffeting's drag, mostly the along-wind gust's (source 2) and partly
    the vertical one's (source 0), is coherent with the lift in a measure that changes with
    frequency, which the forces filtered after the mix cannot give: there the coherence is
    ``(L L^T)_ij^2 / ((L L^T)_ii (L L^T)_jj)`` at every frequency (to round-off).
    """
    L = np.array([[0.02, 0.0, 0.0], [0.004, 0.006, 0.0], [0.003, 0.0, 0.01]])
    freq = np.array([[3.0, 9.0], [4.0, 12.0], [1.0, 3.0]])
    zeta = np.array([[0.7, 0.5], [1.5, 0.8], [0.9, 1.2]])
    tau = np.array([[0.02, 0.01], [0.05, -0.004], [0.03, 0.02]])
    mixed = ShapingFilter(freq, zeta, L, tau, mixed_after=True)
    f = np.linspace(-40.0, 40.0, 401)
    H = cascades(freq, zeta, tau, f)
    closed = np.einsum("ik,fk,jk->fij", L, np.abs(H) ** 2, L)
    np.testing.assert_allclose(mixed.spectrum(f), closed, rtol=1e-11, atol=1e-18)
    integrated, lyapunov = variances(mixed, 2)
    assert integrated == pytest.approx(lyapunov, rel=1e-8)

    def coherence(shaping: ShapingFilter) -> np.ndarray:
        S = shaping.spectrum([0.5, 3.0, 20.0])
        return np.abs(S[:, 0, 2]) ** 2 / (S[:, 0, 0].real * S[:, 2, 2].real)

    # Lift and drag share source 0 alone: their coherence is its share of the drag, 0.12 at
    # 0.5 Hz (the drag's own source, cornering at 1 Hz, dominates there) and 0.99 at 20 Hz.
    assert np.ptp(coherence(mixed)) > 0.5
    per_force = ShapingFilter(freq, zeta, L, tau)
    Q = L @ L.T
    np.testing.assert_allclose(coherence(per_force), Q[0, 2] ** 2 / (Q[0, 0] * Q[2, 2]),
                               rtol=1e-10)


def test_block_means_model_has_the_block_means_exact_covariances():
    """Against the stationary covariances of the fine-grid model, summed term by term."""
    model = release_model()
    Phi, Qd, n, m = model.Phi, model.Qd, model.n_states, 5
    P = scipy.linalg.solve_discrete_lyapunov(Phi, Qd)  # the fine grid's stationary covariance
    Phi_m, Qd_m, H, R_eta, M = block_means(Phi, Qd, np.eye(n), m)
    powers = [np.linalg.matrix_power(Phi, j) for j in range(m + 1)]
    # cov(x_i, x_j) = Phi^(i-j) P for i >= j: the block mean's covariance and its
    # covariance with the next block's first state, by brute force.
    cov = sum(powers[i - j] @ P if i >= j else P @ powers[j - i].T
              for i in range(m) for j in range(m)) / m**2
    with_next = sum(powers[m - j] @ P for j in range(m)) / m
    # The block model's own: s = H x + eta, x' = Phi_m x + w with E[w eta^T] = M.
    scale = np.abs(P).max()
    np.testing.assert_allclose(H @ P @ H.T + R_eta, cov, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(Phi_m @ P @ H.T + M, with_next, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(Phi_m @ P @ Phi_m.T + Qd_m, P, rtol=0, atol=1e-10 * scale)
    # One sample per block is the model itself.
    one = block_means(Phi, Qd, model.C, 1)
    np.testing.assert_array_equal(one[0], Phi)
    np.testing.assert_array_equal(one[2], model.C)
    assert not np.any(one[3]) and not np.any(one[4])


def test_the_predictor_of_block_means_leaves_white_innovations():
    """On block means of a broadband buffeting response; samples of the state do not.

    Simulated on the fine grid (500 Hz) and averaged over blocks of 5: 20 000 blocks. Exact,
    the standardised innovations have unit variance (sampling std 0.01; asserted 0.04) and
    no autocorrelation beyond chance at lags 1-20 (about 3.5 / sqrt(n) = 0.025 over 80
    checks; asserted 0.035). Taken as samples, the lift's variance was 0.77 and its largest
    autocorrelation 0.18 (asserted above 0.1).
    """
    shaping = ShapingFilter([3.7, 3.7], [2.4, 2.4], [[0.3, 0.0], [0.07, 0.003]])
    noise = np.array([2e-5, 2e-4, 0.02, 0.002])
    m = 5
    fine = ReleaseModel(SECTION, MODEL, U, FS, shaping, noise * np.sqrt(m))
    y = fine.sample(np.zeros(fine.n_states), fine.initial_covariance(), 100_000,
                    np.random.default_rng(1))
    blocks = y.reshape(-1, m, 4).mean(axis=1)
    Phi, Qd, H, R_eta, M = block_means(fine.Phi, fine.Qd, fine.C, m)
    R = R_eta + np.diag(noise**2)
    Phi_u, Qd_u, gain = decorrelated(Phi, Qd, H, R, M)
    exact = SteadyPredictor(Phi_u, Qd_u, H, R, feedthrough=gain)
    coarse = ReleaseModel(SECTION, MODEL, U, FS / m, shaping, noise)
    samples = SteadyPredictor(coarse.Phi, coarse.Qd, coarse.C, coarse.R)

    def whiteness(predictor):
        u = predictor.innovations(blocks)[500:] @ np.linalg.inv(
            np.linalg.cholesky(predictor.S)).T
        acf = max(np.abs(np.sum(u[lag:] * u[:-lag], axis=0) / np.sum(u * u, axis=0)).max()
                  for lag in range(1, 21))
        return np.var(u, axis=0), acf

    variance, acf = whiteness(exact)
    np.testing.assert_allclose(variance, 1.0, atol=0.04)
    assert acf < 0.035
    variance, acf = whiteness(samples)
    assert variance[2] < 0.9 and acf > 0.1


def test_likelihood_peaks_at_the_true_buffeting_level_and_wind_speed():
    """On a record drawn from the model, the profiles over L's scale and U peak at the truth."""
    model = release_model()
    x0 = model.initial_state(*HOLD)
    y = model.sample(x0, model.initial_covariance(), 5000, np.random.default_rng(11))

    def minus_ll(log_scale: float) -> float:
        return -log_likelihood(release_model(scale=float(np.exp(log_scale))), y, x0)

    best = minimize_scalar(minus_ll, bounds=(-0.3, 0.3), method="bounded",
                           options={"xatol": 1e-4})
    # The scale's std is 2.7 % over 12 seeds (3.4 % from the likelihood's curvature, the
    # Fisher information of this record): 10 % is three of those.
    assert abs(np.exp(best.x) - 1.0) < 0.10, np.exp(best.x)

    # U is known to about 0.8 % (a 5 % change costs 16-20 in log-likelihood on average over 12
    # seeds, at least 6): both neighbours are lower here.
    at_truth = log_likelihood(model, y, x0)
    for factor in (0.95, 1.05):
        assert log_likelihood(release_model(U=U * factor), y, x0) < at_truth - 1.0, factor


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda m, x0: kalman_filter(m, np.zeros((10, 3)), x0), "y must have shape"),
        (lambda m, x0: kalman_filter(m, np.zeros((10, 4)), np.full_like(x0, np.nan)),
         "x0 contains 12 non-finite"),
        (lambda m, x0: release_model(noise=[1e-5, -1e-4, 0.05, 0.005]), "noise_std must be"),
        (lambda m, x0: ShapingFilter([3.0, -1.0], [0.7, 0.7], L_TRUE), "frequencies must be > 0"),
        (lambda m, x0: ShapingFilter([3.0, np.inf], [0.7, 0.7], L_TRUE), "frequencies contains"),
        (lambda m, x0: ShapingFilter([3.0, 3.0], [0.7, 0.7], [[1.0, 0.1], [0.0, 1.0]]),
         "lower-triangular"),
        (lambda m, x0: ShapingFilter([[3.0, 9.0], [3.0, 9.0]], [0.7, 0.7], L_TRUE),
         "one row per force"),
        (lambda m, x0: ShapingFilter([3.0, 3.0], [0.7, 0.7], L_TRUE, [0.01, np.nan]),
         "zeros contains"),
        (lambda m, x0: ShapingFilter([3.0, 3.0], [0.7, 0.7], L_TRUE, mixed_after=1),
         "mixed_after must be True or False"),
        (lambda m, x0: kalman_filter(release_model(noise=np.zeros(4), L=np.zeros((2, 2))),
                                     np.zeros((3, 4)), x0), "not positive definite"),
    ],
)
def test_bad_input_raises_one_clear_error(make, match):
    model = release_model()
    with pytest.raises(ValueError, match=match):
        make(model, model.initial_state(*HOLD))
