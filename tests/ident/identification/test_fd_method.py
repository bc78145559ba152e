"""The flutter-derivative route (fd_method): its accuracy, its known biases and its refusals.

The truth is the flat plate with Jones's approximation (an exact Roger model), simulated noise-free
by the virtual tunnel at 10 wind speeds from 0.3 to 0.9 of the flutter speed. The classical method
is biased even on such data; the tests pin that bias down where it comes from (the classical
reading of two decaying, coupled modes) rather than hide it behind loose tolerances.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from ident import (
    AeroelasticSystem,
    NonUniformSamplingError,
    PlausibilityError,
    RankDeficiencyError,
    RationalFunctionModel,
    Release,
)
from ident.identification import fd_method
from ident.model import flat_plate, flutter
from ident.model.conventions import FLUTTER_DERIVATIVE_NAMES
from ident.model.roger import fit_entries
from ident.tables.roger_table import RogerProblem
from simulators import simulate_release

from support.sections import FLAT_PLATE

JONES = flat_plate.jones_model()
U_F = flutter.analyze(FLAT_PLATE, JONES).speed
FRACTIONS = np.linspace(0.3, 0.9, 10)


def simulate(U, h0=0.004, alpha0=0.02, **kwargs):
    """Simulate a 20 s release at 500 Hz of the flat-plate section at wind speed U (m/s)."""
    return simulate_release(FLAT_PLATE, JONES, U, h0, alpha0, duration=20.0, fs=500.0, **kwargs)


def release(U, **kwargs):
    return Release.from_simulation(simulate(U, **kwargs))


@pytest.fixture(scope="module")
def releases():
    return [release(f * U_F) for f in FRACTIONS]


@pytest.fixture(scope="module")
def table(releases):
    return fd_method.flutter_derivatives(releases, FLAT_PLATE)


def true_derivatives(table):
    """Jones's flutter derivatives at the identified K: heave column at K_h, pitch column at K_a."""
    at_h = JONES.flutter_derivatives(table.K_h)
    at_a = JONES.flutter_derivatives(table.K_a)
    return {n: (at_h if n in fd_method.HEAVE_COLUMN else at_a)[n] for n in FLUTTER_DERIVATIVE_NAMES}


def classical_reading_of_exact_modes(U):
    """Return what the classical method must give for the exact modes at U (derived independently).

    Each mode k (pole lambda_k, shape phi_k of q) of the true system satisfies
    (lambda^2 Ms + lambda Cs + Ks) phi = qd B^2 Q(p) phi with p = lambda B/U, and the identified
    (lambda^2 Ms + lambda C_eff + K_eff) phi = 0; so (dK + lambda dC) phi = qd B^2 Q(p) phi: eight
    real equations for the eight entries of dK and dC. Returns ``qd B^2 Q = dK + i omega dC``,
    column 0 at the heave mode's omega, column 1 at the pitch mode's, and (K_h, K_a).
    """
    lam, vectors = np.linalg.eig(AeroelasticSystem(FLAT_PLATE, JONES, U).matrix())
    osc = np.flatnonzero(lam.imag > 1e-9)
    lam, phi = lam[osc], vectors[:2, osc].T
    share = np.abs(phi.T) ** 2 * np.diag(FLAT_PLATE.mass_matrix())[:, None]
    rows, cols = linear_sum_assignment(-share / share.sum(axis=0))
    order = [int(c) for _, c in sorted(zip(rows, cols, strict=True))]
    lam, phi = lam[order], phi[order]
    B = FLAT_PLATE.B
    qd_B2 = 0.5 * FLAT_PLATE.rho * U**2 * B**2
    M, rhs = [], []
    for lam_k, phi_k in zip(lam, phi, strict=True):
        force = qd_B2 * JONES.Q(lam_k * B / U) @ phi_k
        for i in range(2):
            row = np.zeros(8, dtype=complex)
            row[2 * i : 2 * i + 2] = phi_k  # dK[i, :]
            row[4 + 2 * i : 6 + 2 * i] = lam_k * phi_k  # dC[i, :]
            M += [row.real, row.imag]
            rhs += [force[i].real, force[i].imag]
    x = np.linalg.solve(np.array(M), np.array(rhs))
    dK, dC = x[:4].reshape(2, 2), x[4:].reshape(2, 2)
    omega = lam.imag
    return (dK + 1j * omega[None, :] * dC) / qd_B2, B * omega / U


# --------------------------------------------------------------------------------------------------
# (a) noise-free flutter derivatives


def test_the_table_is_the_classical_reading_of_the_exact_modes(table):
    """On noise-free decays the method computes exactly the classical reading of the true modes.

    So every difference from the true derivatives in the next tests is the classical method's own,
    not an artefact of the modal fit or of this implementation.
    """
    K, Q = table.Q_entries()
    for n, f in enumerate(FRACTIONS):
        Q_exact, K_exact = classical_reading_of_exact_modes(f * U_F)
        # The noise-free modal fit is exact to round-off (~1e-13 here); 1e-7 allows for its
        # solver tolerance (1e-10 on the poles) amplified by the cancellation in K_0 - K_eff (dK is
        # only ~2 % of K_0 at the lowest speed).
        np.testing.assert_allclose([K[n, 0, 0], K[n, 0, 1]], K_exact, rtol=1e-7)
        np.testing.assert_allclose(Q[n], Q_exact, rtol=0, atol=1e-7 * np.abs(Q_exact).max())


def test_noise_free_flutter_derivatives_have_the_classical_bias(table):
    """The dominant derivatives are close; the error grows with the coupling of the modes.

    Why the classical method is only approximately right on exact data (measured on this plate,
    0.3 to 0.9 U_F): the identified dK and dC satisfy (dK + lambda_k dC) phi_k = qd B^2 Q(p_k) phi_k
    exactly for both modes (previous test), but the classical reading assumes each column of Q is
    seen by one pure, harmonic mode. (1) Coupling: the heave-dominated mode carries pitch (|alpha| /
    |h/B| = 0.05 at 0.3 U_F, 0.45 at 0.9 U_F) and the pitch mode heave (0.03 to 0.43), each at its
    own frequency, so each column mixes forces at K_h and K_a. Solved with harmonic forces
    (p = iK) this alone gives A2 -0.5 % at 0.3 U_F and -12 % at 0.9 U_F, H1 -0.4 % and -14 %.
    (2) Decay: the forces act at p = K(-zeta + i), not iK (zeta_h reaches 0.26 at 0.9 U_F), and a
    linear-in-lambda reading of a curved Q(p) mis-assigns stiffness and damping; e.g. the added
    mass A3 p^2 of the plate appears partly as damping (H1 += -2 zeta A3_11 ~ pi zeta). With
    uncoupled modes this alone gives A2 +1 % / -2 %, H1 +3 % / -2.5 %. Together (measured): H1
    +2.7 % -> -10.8 %, A2 +0.5 % -> -18.4 %, H3 +2.6 % -> +3.4 %, A3 +0.2 % -> -0.6 %. The small
    derivatives H2, H4, A1, A4 are differences of large terms and are far worse in relative terms
    (H4 crosses zero near K_h = 0.74): they are checked through the Q entries they belong to.
    """
    truth = true_derivatives(table)
    error = {n: table.derivatives[n] / truth[n] - 1.0 for n in FLUTTER_DERIVATIVE_NAMES}
    low = FRACTIONS < 0.55  # weakly coupled: the four speeds 0.3 to 0.5 U_F
    # H3 and A3 (pitch-column stiffness, the flutter-driving terms): 3.4 % and 0.6 % measured.
    assert np.abs(error["H3"]).max() < 0.04
    assert np.abs(error["A3"]).max() < 0.01
    # H1 and A2 (heave and pitch aerodynamic damping): 2.7 % and 2.4 % measured up to 0.5 U_F,
    # 10.8 % and 18.4 % at 0.9 U_F, growing with the coupling (monotonically for U > 0.5 U_F).
    assert np.abs(error["H1"][low]).max() < 0.03
    assert np.abs(error["A2"][low]).max() < 0.03
    assert np.abs(error["H1"]).max() < 0.12
    assert np.abs(error["A2"]).max() < 0.20
    assert np.all(np.diff(np.abs(error["A2"][~low])) > 0)
    # All eight through the complex Q entries (relative to |Q_ij|): measured at most 5.2 % up to
    # 0.5 U_F and 22.5 % at 0.9 U_F (Q11 and Q21, the heave column of the most coupled mode).
    K, Q = table.Q_entries()
    Q_true = np.stack([JONES.Q(1j * K[:, 0, j])[:, :, j] for j in range(2)], axis=-1)
    entry_error = np.abs(Q - Q_true) / np.abs(Q_true)
    assert entry_error[low].max() < 0.06
    assert entry_error.max() < 0.25


def test_Q_entries_lay_out_the_columns_at_their_own_K(table):
    """Heave column at K_h, pitch column at K_a, Q = K^2 (real + i imag derivative)."""
    K, Q = table.Q_entries()
    np.testing.assert_array_equal(K[:, :, 0], np.column_stack([table.K_h, table.K_h]))
    np.testing.assert_array_equal(K[:, :, 1], np.column_stack([table.K_a, table.K_a]))
    fd = table.derivatives
    # One multiplication and one addition per value: a few ulps.
    np.testing.assert_allclose(Q[:, 0, 0], table.K_h**2 * (fd["H4"] + 1j * fd["H1"]), rtol=1e-14)
    np.testing.assert_allclose(Q[:, 1, 1], table.K_a**2 * (fd["A3"] + 1j * fd["A2"]), rtol=1e-14)
    # The heave-dominated mode is the slower one throughout, and U increases down the table.
    assert np.all(table.K_h < table.K_a) and np.all(np.diff(table.U) > 0)
    np.testing.assert_allclose(table.U, FRACTIONS * U_F, rtol=1e-12)


# --------------------------------------------------------------------------------------------------
# (b) the flutter speed of the fd route


def test_flutter_speed_of_the_fd_route_is_within_three_percent(releases, table):
    """The Roger fit of the biased table still predicts the flutter speed within 3 %.

    Measured: +2.2 % with the structure chosen by held-out error (2 lags and A3); +1.9 % to +2.3 %
    for the other structures with 1 to 3 lags that fit the table well (1 lag without A3: +10 %;
    no lag: -10 %). The biased H1 and A2 (more damping near flutter, previous test) push it up.
    E2RFC is exact on noise-free releases at two speeds (tests/ident/identification/test_e2rfc.py).
    """
    model = fd_method.identify(releases, FLAT_PLATE)
    assert isinstance(model, RationalFunctionModel)
    assert model.table.U.size == len(releases)
    np.testing.assert_array_equal(model.table.derivatives["A2"], table.derivatives["A2"])
    assert "simplest structure" in model.diagnostics.reason
    assert {(c.n_lags, c.with_A3) for c in model.diagnostics.candidates} == {
        (m, a3) for m in range(4) for a3 in (True, False)
    }
    assert model.n_lags >= 1  # quasi-steady forces cannot follow the lags: 10 % off, rejected
    result = flutter.analyze(FLAT_PLATE, model)
    assert result.speed == pytest.approx(U_F, rel=0.03)
    assert result.critical_mode == "pitch"


# --------------------------------------------------------------------------------------------------
# (c) still-air reference from measured decays


def test_still_air_decays_give_the_same_result_but_for_the_still_air_added_mass(releases, table):
    """With measured still-air decays only H1, H4, A2, A3 move, by exactly the still-air added mass.

    Still-air decays see the structure plus the air's added mass Ma (plate: rho/2 B^4 diag(pi/2,
    pi/64), 2.9 % of the heave mass and 0.8 % of the pitch inertia), so K_0 = Ms (Ms + Ma)^-1 Ks
    and C_0 = Ms (Ms + Ma)^-1 Cs instead of Ks and Cs. Read as flutter derivatives that is
    H4 -= (pi/2) (w0_h/w_h)^2, A3 -= (pi/64) (w0_a/w_a)^2 (w0: still-air frequency, w: wind-on),
    and a tiny change in H1 and A2 from the structural damping; the other four do not move. The
    flutter speed moves by 0.4 % (measured).
    """
    still = [simulate(0.0), simulate(0.0, h0=-0.003, alpha0=0.01)]
    with_still = fd_method.flutter_derivatives(
        releases, FLAT_PLATE, still_air=[(r.t, r.h, r.alpha) for r in still]
    )
    B, rho, U = FLAT_PLATE.B, FLAT_PLATE.rho, table.U
    Ma = 0.5 * rho * B**4 * np.array([math.pi / 2, math.pi / 64])
    Meff = np.diag(FLAT_PLATE.mass_matrix()) + Ma
    w0 = np.sqrt(np.diag(FLAT_PLATE.stiffness_matrix()) / Meff)
    w_h, w_a = table.K_h * U / B, table.K_a * U / B
    qd = 0.5 * rho * U**2
    Cs = np.diag(FLAT_PLATE.damping_matrix())
    shift = dict.fromkeys(FLUTTER_DERIVATIVE_NAMES, 0.0 * U)
    shift["H4"] = -math.pi / 2 * (w0[0] / w_h) ** 2
    shift["A3"] = -math.pi / 64 * (w0[1] / w_a) ** 2
    shift["H1"] = -(Ma[0] / Meff[0]) * Cs[0] * U / (qd * B**3 * table.K_h)
    shift["A2"] = -(Ma[1] / Meff[1]) * Cs[1] * U / (qd * B**3 * table.K_a)
    for name in FLUTTER_DERIVATIVE_NAMES:
        # Noise-free modal fits are exact to round-off (1e-13 measured); 1e-7 as in the tests above.
        np.testing.assert_allclose(
            with_still.derivatives[name] - table.derivatives[name], shift[name], rtol=0,
            atol=1e-7 * np.abs(table.derivatives[name]).max(), err_msg=name,
        )
    speeds = [
        flutter.analyze(FLAT_PLATE,
                        fd_method.identify(releases, FLAT_PLATE, 2, True, still_air=s)).speed
        for s in (None, [(r.t, r.h, r.alpha) for r in still])
    ]
    assert speeds[1] == pytest.approx(speeds[0], rel=0.01)  # 0.4 % measured


def test_bad_still_air_decays_are_refused(releases):
    with pytest.raises(TypeError, match=r"still_air\[0\] must be a \(t, h, alpha\) triple"):
        fd_method.flutter_derivatives(releases[:1], FLAT_PLATE, still_air=[np.zeros(10)])
    t = np.arange(100) / 100.0
    with pytest.raises(ValueError, match="equal lengths"):
        fd_method.flutter_derivatives(releases[:1], FLAT_PLATE, still_air=[(t, t, t[:-1])])
    with pytest.raises(ValueError, match="empty"):
        fd_method.flutter_derivatives(releases[:1], FLAT_PLATE, still_air=[])
    jittered = t + np.where(np.arange(100) == 50, 1e-4, 0.0)
    with pytest.raises(NonUniformSamplingError, match="not uniformly sampled"):
        fd_method.flutter_derivatives(releases[:1], FLAT_PLATE, still_air=[(jittered, t, t)])


# --------------------------------------------------------------------------------------------------
# (d) refusals


def test_fewer_than_three_wind_speeds_are_refused(releases):
    """Two speeds (one of them twice, within 2 %) cannot make a Roger table: an error."""
    twice = release(releases[0].U * 1.01, h0=-0.003)
    with pytest.raises(RankDeficiencyError, match="releases at 2 wind speed"):
        fd_method.identify([releases[0], twice, releases[5]], FLAT_PLATE)
    with pytest.raises(RankDeficiencyError, match="no releases given"):
        fd_method.identify([], FLAT_PLATE)


def test_a_dead_laser_is_refused_naming_it_but_not_a_dead_force(releases):
    """A heave of zeros is refused by name; zeros in the forces (no taps) change nothing.

    The route reads the motion alone.
    """
    dead = [releases[0], dataclasses.replace(releases[1], h=np.zeros_like(releases[1].h)),
            *releases[2:]]
    with pytest.raises(PlausibilityError, match="the h channel reads 0 m in every one"):
        fd_method.identify(dead, FLAT_PLATE)
    no_taps = [dataclasses.replace(r, lift=np.zeros_like(r.lift),
                                   moment=np.zeros_like(r.moment)) for r in releases]
    with_taps, without = (fd_method.identify(r, FLAT_PLATE) for r in (releases, no_taps))
    np.testing.assert_array_equal(without.A, with_taps.A)


def test_bad_arguments_are_refused(releases):
    with pytest.raises(TypeError, match="ident.Release"):
        fd_method.identify([releases[0], "release.h5"], FLAT_PLATE)
    with pytest.raises(ValueError, match="n_lags must be an integer in 0..3"):
        fd_method.identify(releases, FLAT_PLATE, n_lags=5)


def test_structures_the_table_cannot_determine_are_skipped_with_a_note(releases):
    """Three speeds give each entry 6 real equations: 3 lags with A3 is skipped, not fitted."""
    model = fd_method.identify(releases[::4], FLAT_PLATE)  # 0.3, 0.57, 0.83 U_F
    notes = {(c.n_lags, c.with_A3): c.note for c in model.diagnostics.candidates}
    assert "too few wind speeds" in notes[(3, True)]
    assert notes[(0, True)] == ""
    assert "too few wind speeds" in notes[(2, True)]  # 5 per entry > 4 with one speed held out
    assert notes[(model.n_lags, model.diagnostics.with_A3)] == ""  # the chosen one was usable


# --------------------------------------------------------------------------------------------------
# (e) repeated releases at one wind speed


def test_repeated_releases_at_one_speed_are_averaged_and_their_spread_reported(releases):
    """Releases within 2 % in U form one row: mean and sample std of their derivatives."""
    U = releases[3].U
    pair = [release(U, noise=0.02, rng=1),
            release(U, h0=-0.003, alpha0=0.015, noise=0.02, rng=2)]
    near = release(1.01 * releases[6].U)  # 1 % faster: the same row as releases[6]
    data = [releases[6], releases[0], *pair, near]
    table = fd_method.flutter_derivatives(data, FLAT_PLATE)
    np.testing.assert_array_equal(table.n_releases, [1, 2, 2])
    assert table.U[2] == pytest.approx(1.005 * releases[6].U, rel=1e-12)
    assert [len(fits) for fits in table.modal_fits] == [1, 2, 2]
    alone = [fd_method.flutter_derivatives([r], FLAT_PLATE) for r in pair]
    for name in FLUTTER_DERIVATIVE_NAMES:
        values = np.array([a.derivatives[name][0] for a in alone])
        # Mean and std of two numbers: round-off only.
        assert table.derivatives[name][1] == pytest.approx(values.mean(), rel=1e-12, abs=1e-14)
        assert table.spread[name][1] == pytest.approx(values.std(ddof=1), rel=1e-9, abs=1e-14)
        assert math.isnan(table.spread[name][0])
    # The spread is real and small: 2 % noise on 20 s records moves the dominant derivatives by
    # 0.03 % to 0.16 % (measured). Within the 1 %-apart pair the speed difference itself shows
    # (H3 ~ 1/K^2 moves ~2 % per 1 % of U; measured std 1.7 % of H3).
    for name in ("H1", "H3", "A2", "A3"):
        assert 0.0 < table.spread[name][1] < 0.005 * abs(table.derivatives[name][1])
    assert 0.005 < table.spread["H3"][2] / abs(table.derivatives["H3"][2]) < 0.03


# --------------------------------------------------------------------------------------------------
# The Roger part on an exact table


def exact_table_entries(K_h, K_a, model):
    K = np.stack([np.column_stack([K_h, K_h]), np.column_stack([K_a, K_a])], axis=-1)
    Q = np.stack([model.Q(1j * K[:, 0, j])[:, :, j] for j in range(2)], axis=-1)
    return K, Q


def test_entrywise_fit_and_lag_search_recover_an_exact_roger_model():
    """Columns known at different K (as in a measured table): Jones's lags and RFCs come back."""
    K_h = np.linspace(0.35, 1.1, 10)
    K, Q = exact_table_entries(K_h, 1.9 * K_h, JONES)
    fitted = fit_entries(K, Q, np.array(flat_plate.JONES_LAGS), True)
    # Linear least squares on exact data with a well-conditioned design: round-off.
    np.testing.assert_allclose(fitted.A, JONES.A, atol=1e-9 * np.abs(JONES.A).max())
    problem = RogerProblem(K, Q)
    d = problem.search(2, True, problem.starts(2, None))
    # Exact data: the variable-projection optimum is the truth, to the solver's tolerance.
    np.testing.assert_allclose(d, flat_plate.JONES_LAGS, rtol=1e-5)
