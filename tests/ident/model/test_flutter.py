"""State-space model and flutter analysis of section models in the wind.

Still-air eigenvalues, forces, time- vs frequency-domain flutter speeds, and the contents of a
FlutterResult.

Expectations come from closed forms (single-degree-of-freedom oscillators, flat-plate added mass,
torsional divergence of a plate), from the force formula of docs/reference/conventions.md ("In the
time domain") evaluated here, or from the independent frequency-domain solver (Scanlan's iteration
on K).
"""

import functools
import math

import numpy as np
import pytest

from ident import AeroelasticSystem, RationalFunctionModel, SectionModel
from ident.model import flat_plate, flutter

from support.sections import FLAT_PLATE

PI = math.pi

# Physically plausible bridge section models (B 0.2-0.6 m, m 2-20 kg/m, radius of gyration
# 0.2-0.35 B, fh 1-3 Hz, fa/fh 1.5-3), varied in mass ratio, frequency ratio, inertia, width,
# damping, air density and static unbalance.
SECTIONS = {
    # B = 0.3 m, r = 0.33 B, fa/fh = 2, light (m / (rho B^2) = 27).
    "light_B0.3": FLAT_PLATE,
    # Narrow, fa/fh = 2.4, r = 0.3 B, higher damping.
    "narrow_B0.2": SectionModel(
        B=0.2, m=2.5, I=2.5 * (0.3 * 0.2) ** 2, fh=2.5, fa=6.0, zeta_h=0.01, zeta_a=0.008
    ),
    # Wide and heavy, low frequency ratio 1.67, r = 0.25 B, light damping.
    "heavy_B0.6": SectionModel(
        B=0.6, m=20.0, I=20.0 * (0.25 * 0.6) ** 2, fh=1.2, fa=2.0, zeta_h=0.002, zeta_a=0.002
    ),
    # fa/fh = 3, compact inertia r = 0.2 B.
    "stiff_pitch_B0.4": SectionModel(
        B=0.4, m=6.0, I=6.0 * (0.2 * 0.4) ** 2, fh=3.0, fa=9.0, zeta_h=0.005, zeta_a=0.005
    ),
    # 2 % damping, warm air, fa/fh = 2.5.
    "damped_B0.5": SectionModel(
        B=0.5, m=8.0, I=8.0 * (0.3 * 0.5) ** 2, fh=1.0, fa=2.5, zeta_h=0.02, zeta_a=0.02, rho=1.18
    ),
    # Static unbalance: centre of mass 1.7 cm (0.055 B) downstream of the elastic axis.
    "unbalanced_B0.3": SectionModel(
        B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005, S=0.05
    ),
}

JONES = flat_plate.jones_model()


@functools.cache
def time_domain(name):
    return flutter.analyze(SECTIONS[name], JONES)


@functools.cache
def frequency_domain_exact(name):
    return flutter.frequency_domain(SECTIONS[name], flat_plate.flutter_derivatives)


@functools.cache
def frequency_domain_jones(name):
    return flutter.frequency_domain(SECTIONS[name], JONES.flutter_derivatives)


def without_added_mass(model):
    """Return the same Roger model with A3 = 0."""
    A = np.array(model.A)
    A[2] = 0.0
    return RationalFunctionModel(A, model.d)


def oscillatory_eigenvalues(system):
    """Return the eigenvalues with Im > 0 by frequency (lag states at U = 0 give lambda = 0)."""
    lam = system.eigenvalues()
    lam = lam[lam.imag > 0]
    return lam[np.argsort(lam.imag)]


def sdof_root(M, c, k):
    """Upper root of M s^2 + c s + k = 0 for an underdamped single-degree-of-freedom oscillator."""
    return complex(-c / (2 * M), math.sqrt(k / M - (c / (2 * M)) ** 2))


# --------------------------------------------------------------------------------------------------
# Still air (U = 0)


@pytest.mark.parametrize(
    "model",
    [
        RationalFunctionModel(np.zeros((3, 2, 2)), []),
        without_added_mass(JONES),
        # A random 3-lag model with A3 = 0: at U = 0 only A3 could act on the structure.
        without_added_mass(
            RationalFunctionModel(np.random.default_rng(7).normal(size=(6, 2, 2)), [0.1, 0.5, 2.0])
        ),
    ],
    ids=["no-aero", "jones-A3=0", "random-3-lags-A3=0"],
)
@pytest.mark.parametrize("zeta", [(0.0, 0.0), (0.01, 0.03), (0.2, 0.05)])
def test_still_air_eigenvalues_are_structural(model, zeta):
    """At U = 0 with A3 = 0 the eigenvalues are those of the two structural oscillators."""
    zh, za = zeta
    s = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=zh, zeta_a=za)
    lam = oscillatory_eigenvalues(AeroelasticSystem(s, model, 0.0))
    assert lam.shape == (2,)
    wh, wa = 2 * PI * s.fh, 2 * PI * s.fa
    want = np.array(
        [complex(-zh * wh, wh * math.sqrt(1 - zh**2)), complex(-za * wa, wa * math.sqrt(1 - za**2))]
    )
    # Non-defective eigenvalues of an 8x8 (or smaller) real matrix with entries of size |lambda|^2
    # ~ 600: LAPACK gives them to a few eps * ||A|| / |lambda| ~ 1e-14 relative; 1e-9 as specified.
    np.testing.assert_allclose(lam, want, rtol=1e-9, atol=0)
    # Damped frequencies f sqrt(1 - zeta^2) and damping ratios, as the issue states them.
    np.testing.assert_allclose(
        lam.imag / (2 * PI), [2.0 * math.sqrt(1 - zh**2), 4.0 * math.sqrt(1 - za**2)], rtol=1e-9
    )
    np.testing.assert_allclose(-lam.real / np.abs(lam), [zh, za], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("zeta", [0.0, 0.01])
@pytest.mark.parametrize("name", ["light_B0.3", "heavy_B0.6", "damped_B0.5"])
def test_still_air_flat_plate_adds_the_theodorsen_added_mass(name, zeta):
    """At U = 0 the plate adds m_a = pi rho B^2/4 to heave and pi rho B^4/128 to pitch inertia."""
    s = SECTIONS[name].replace(zeta_h=zeta, zeta_a=zeta)
    m_a = PI * s.rho * s.B**2 / 4  # pi rho b^2, b = B/2 (Theodorsen's apparent mass)
    I_a = PI * s.rho * s.B**4 / 128  # pi rho b^4 / 8 about mid-chord
    lam = oscillatory_eigenvalues(AeroelasticSystem(s, JONES, 0.0))
    wh, wa = 2 * PI * s.fh, 2 * PI * s.fa
    want = np.array(
        [
            sdof_root(s.m + m_a, 2 * s.m * zeta * wh, s.m * wh**2),
            sdof_root(s.I + I_a, 2 * s.I * zeta * wa, s.I * wa**2),
        ]
    )
    # The Jones A3 is diagonal and the lag gains are proportional to U^2, so at U = 0 the system is
    # exactly two uncoupled oscillators plus zero eigenvalues: only eigensolver rounding (~1e-14).
    np.testing.assert_allclose(lam, want, rtol=1e-9, atol=0)
    if zeta == 0.0:
        # The issue's form: f_h' = fh sqrt(m / (m + m_a)).
        assert lam[0].imag / (2 * PI) == pytest.approx(
            s.fh * math.sqrt(s.m / (s.m + m_a)), rel=1e-9
        )
        assert lam[1].imag / (2 * PI) == pytest.approx(
            s.fa * math.sqrt(s.I / (s.I + I_a)), rel=1e-9
        )


# --------------------------------------------------------------------------------------------------
# Forces


@pytest.mark.parametrize(
    "model",
    [
        JONES,
        RationalFunctionModel(np.random.default_rng(3).normal(size=(6, 2, 2)), [0.05, 0.4, 3.0]),
        RationalFunctionModel(np.random.default_rng(4).normal(size=(3, 2, 2)), []),
    ],
    ids=["jones", "random-3-lags", "random-no-lags"],
)
@pytest.mark.parametrize("U", [0.0, 4.7, 13.0])
def test_force_matrix_is_designs_force_formula(model, U):
    """F z = rho/2 [U^2 B^2 A1 q + U B^3 A2 q' + B^4 A3 q'' + U^2 B^2 sum A_{l+3} x_l]."""
    s = SECTIONS["unbalanced_B0.3"]  # S != 0: a full mass matrix
    system = AeroelasticSystem(s, model, U)
    rng = np.random.default_rng(11)
    z = rng.normal(size=system.n_states)
    q, qd, x = z[0:2], z[2:4], z[4:].reshape(-1, 2)
    A, B, rho = model.A, s.B, s.rho
    lag_force = sum((A[3 + k] @ x[k] for k in range(model.n_lags)), np.zeros(2))

    # q'' from the equations of motion, solved here: (Ms - rho/2 B^4 A3) q'' =
    #   -Cs q' - Ks q + rho/2 [U^2 B^2 A1 q + U B^3 A2 q' + U^2 B^2 sum A x].
    Ms = np.array([[s.m * B**2, s.S * B], [s.S * B, s.I]])
    Cs = np.diag([2 * s.m * s.zeta_h * 2 * PI * s.fh * B**2, 2 * s.I * s.zeta_a * 2 * PI * s.fa])
    Ks = np.diag([s.m * (2 * PI * s.fh) ** 2 * B**2, s.I * (2 * PI * s.fa) ** 2])
    aero_terms = [U**2 * B**2 * A[0] @ q, U * B**3 * A[1] @ qd, U**2 * B**2 * lag_force]
    rhs = -Cs @ qd - Ks @ q + rho / 2 * sum(aero_terms)
    M_eff = Ms - rho / 2 * B**4 * A[2]
    qdd = np.linalg.solve(M_eff, rhs)
    Az = system.matrix() @ z
    # Both sides: a 2x2 inverse/solve and ~30 products. Rounding is a few eps of the largest term
    # of the right-hand side, amplified by ||M_eff^-1||; 1e-12 of that bound leaves a 1e3 margin.
    rhs_scale = max(np.abs(t).max() for t in [Cs @ qd, Ks @ q, *(rho / 2 * t for t in aero_terms)])
    acc_scale = np.linalg.norm(np.linalg.inv(M_eff), 2) * rhs_scale
    np.testing.assert_allclose(Az[2:4], qdd, rtol=0, atol=1e-12 * acc_scale)
    # q' rows are identity rows: exactly z[2:4] (sums of exact zeros).
    np.testing.assert_array_equal(Az[0:2], qd)
    # Lag-state rows x_l' = q' - (U/B) d_l x_l: one product and one sum per entry, a few ulps of
    # |q'| + |U d_l x_l / B| (at most a few hundred here, ~1e-13), so 1e-12 absolute is ample.
    for k in range(model.n_lags):
        want_lag = qd - U / B * model.d[k] * x[k]
        np.testing.assert_allclose(Az[4 + 2 * k : 6 + 2 * k], want_lag, rtol=0, atol=1e-12)

    terms = [
        U**2 * B**2 * A[0] @ q,
        U * B**3 * A[1] @ qd,
        B**4 * A[2] @ Az[2:4],  # q'' taken from (A z)[2:4], as the design states
        U**2 * B**2 * lag_force,
    ]
    want = rho / 2 * sum(terms)
    got = system.force_matrix() @ z
    # A sum of four 2-vectors, each from a handful of products: rounding is a few eps times the
    # largest term; 1e-12 relative to that scale (the bound) leaves a 1e3 margin.
    term_scale = rho / 2 * max(np.abs(t).max() for t in terms)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * term_scale)
    # forces() with the linear system's own accelerations is the same thing.
    np.testing.assert_allclose(system.forces(z, Az[2:4]), want, rtol=0, atol=1e-12 * term_scale)
    # Given the state matrix the caller built, the same matrix to the bit; a matrix of
    # another system's size is refused, not sliced.
    np.testing.assert_array_equal(system.force_matrix(system.matrix()), system.force_matrix())
    with pytest.raises(ValueError, match="state_matrix must be"):
        system.force_matrix(np.eye(system.n_states + 2))


def test_initial_state_is_a_release_from_rest():
    """A release from rest: q = [h0/B, alpha0], velocities and lag states zero."""
    system = AeroelasticSystem(SECTIONS["light_B0.3"], JONES, 5.0)
    z0 = system.initial_state(0.006, 0.02)
    assert z0.shape == (8,)
    np.testing.assert_array_equal(z0, [0.006 / 0.3, 0.02, 0, 0, 0, 0, 0, 0])


# --------------------------------------------------------------------------------------------------
# Flutter speed: time domain against frequency domain


@pytest.mark.parametrize("name", list(SECTIONS))
def test_time_domain_jones_agrees_with_frequency_domain_theodorsen(name):
    """State-space flutter of the Jones plate is within 1.5 % of Scanlan's with the exact plate."""
    td = time_domain(name)
    fd = frequency_domain_exact(name)
    assert td.found and fd.found
    # Jones's C(k) misstates the exact Q_ij by up to ~2.4 % near the flutter reduced frequencies
    # (test_flat_plate); since U_F^2 scales with stiffness over aerodynamic force, the speed moves
    # by about half of that: 1.5 % bounds the approximation, and a solver error (wrong branch,
    # wrong sign of a term, K vs k) shifts the speed by far more.
    assert td.speed == pytest.approx(fd.speed, rel=0.015)
    # The flutter frequency is mostly structural (coupled modes meeting), so the same bound holds.
    assert td.frequency == pytest.approx(fd.frequency, rel=0.015)


@pytest.mark.parametrize("name", list(SECTIONS))
def test_time_and_frequency_domain_agree_tightly_on_the_same_model(name):
    """With the Jones model on both sides the two independent solvers agree tightly."""
    td = time_domain(name)
    fd = frequency_domain_jones(name)
    assert td.found and fd.found
    # Same aerodynamics, so the only differences are root-finding and eigenvalue rounding: both
    # refine with brentq to 1e-12 relative and the eigenvalues are good to ~1e-14, so the crossing
    # agrees to ~1e-12. 1e-9 is tighter than the 1e-6 yet keeps a 1000x margin.
    assert td.speed == pytest.approx(fd.speed, rel=1e-9)
    assert td.frequency == pytest.approx(fd.frequency, rel=1e-9)
    assert td.reduced_frequency == pytest.approx(fd.reduced_frequency, rel=1e-9)
    assert td.critical_mode == fd.critical_mode


def test_zero_aerodynamics_never_flutters():
    """Without aerodynamic forces a damped structure is stable at every wind speed."""
    s = SECTIONS["light_B0.3"]
    zero = RationalFunctionModel(np.zeros((3, 2, 2)), [])
    result = flutter.analyze(s, zero, U_max=50.0)
    assert result.speed is None
    assert result.found is False
    assert result.frequency is None and result.critical_mode is None
    assert result.reduced_frequency is None
    assert result.divergence_speed is None  # A1 = 0: the stiffness never changes
    assert "no flutter below" in result.summary()
    assert "50" in result.summary()
    # The curves are flat: the structural damping ratios at every wind speed. The matrix does not
    # depend on U at all, so only eigensolver rounding (~1e-15) separates the rows.
    np.testing.assert_allclose(
        result.damping, np.broadcast_to([0.005, 0.005], result.damping.shape), rtol=1e-9
    )
    freq = flutter.frequency_domain(s, zero.flutter_derivatives, n_points=50)
    assert freq.speed is None and not freq.found
    assert "no flutter below" in freq.summary()


def test_zero_aerodynamics_with_lags_never_flutters():
    """Lag states without gains (A all zero, two lags) add only stable real eigenvalues."""
    zero = RationalFunctionModel(np.zeros((5, 2, 2)), [0.091, 0.6])
    result = flutter.analyze(SECTIONS["narrow_B0.2"], zero, n_points=50)
    assert result.speed is None and not result.found
    assert "no flutter below" in result.summary()


@pytest.mark.parametrize("name", ["light_B0.3", "heavy_B0.6", "stiff_pitch_B0.4"])
def test_torsional_divergence_of_the_plate(name):
    """Divergence where the plate's moment slope (pi/2) qd B^2 cancels k_a = I w_a^2."""
    s = SECTIONS[name]
    U_div = math.sqrt(4 * s.I * (2 * PI * s.fa) ** 2 / (PI * s.rho * s.B**2))
    result = flutter.analyze(s, JONES, U_max=1.5 * U_div, n_points=40)
    # brentq on det(Ks - qd B^2 A1) with xtol 1e-12 U_max: 1e-9 relative is safe.
    assert result.divergence_speed == pytest.approx(U_div, rel=1e-9)
    assert f"{U_div:.4g}" in result.summary()


# --------------------------------------------------------------------------------------------------
# Contents of a FlutterResult


def test_result_shapes_and_reduced_frequency():
    """U, frequencies and damping have shapes (n,), (n, 2), (n, 2); K_F = 2 pi f_F B / U_F."""
    s = SECTIONS["light_B0.3"]
    for result, n in (
        (time_domain("light_B0.3"), 400),
        (frequency_domain_exact("light_B0.3"), 400),
    ):
        assert result.U.shape == (n,)
        assert result.frequencies.shape == (n, 2)
        assert result.damping.shape == (n, 2)
        assert result.mode_names == ("heave", "pitch")
        assert result.critical_mode in result.mode_names
        # One multiplication and one division: exact to a couple of ulps.
        assert result.reduced_frequency == pytest.approx(
            2 * PI * result.frequency * s.B / result.speed, rel=1e-14
        )
    td = time_domain("light_B0.3")
    assert td.method == "state-space"
    np.testing.assert_allclose(td.U, np.linspace(0.0, td.U_max, 400), rtol=0, atol=0)
    assert td.U_max == pytest.approx(flutter.default_U_max(s), rel=1e-15)
    # The default range reaches K = 0.2 on the faster mode: U = 2 pi max(fh, fa) B / 0.2.
    assert flutter.default_U_max(s) == pytest.approx(2 * PI * 4.0 * 0.3 / 0.2, rel=1e-15)
    assert 0.0 < td.speed < td.U_max


def test_result_at_zero_wind_gives_structural_damping():
    """With A3 = 0 the first row of the curves holds the structural frequencies and damping."""
    s = SECTIONS["narrow_B0.2"]
    result = flutter.analyze(s, without_added_mass(JONES), n_points=60)
    assert result.U[0] == 0.0
    # Exact still-air oscillators (see test_still_air_eigenvalues_are_structural): eigen rounding.
    np.testing.assert_allclose(result.damping[0], [s.zeta_h, s.zeta_a], rtol=1e-9)
    np.testing.assert_allclose(
        result.frequencies[0],
        [s.fh * math.sqrt(1 - s.zeta_h**2), s.fa * math.sqrt(1 - s.zeta_a**2)],
        rtol=1e-9,
    )


@pytest.mark.parametrize("name", ["light_B0.3", "heavy_B0.6", "damped_B0.5", "unbalanced_B0.3"])
def test_critical_branch_damping_crosses_zero_at_the_flutter_speed(name):
    """The critical branch's damping is > 0 just below the flutter speed and < 0 just above it."""
    result = time_domain(name)
    j = result.mode_names.index(result.critical_mode)
    i = int(np.searchsorted(result.U, result.speed))  # U[i-1] < speed <= U[i]
    assert 0 < i < result.U.size
    assert result.damping[i - 1, j] > 0 > result.damping[i, j]
    # Every branch is stable below the bracket: this is the lowest crossing.
    assert np.all(result.damping[:i] > 0)
    # Linear interpolation of the damping curve lands within one grid step of the refined speed.
    d0, d1 = result.damping[i - 1, j], result.damping[i, j]
    U0, U1 = result.U[i - 1], result.U[i]
    U_zero = U0 + d0 / (d0 - d1) * (U1 - U0)
    assert abs(U_zero - result.speed) <= U1 - U0
    # The frequency curve of the critical branch passes through the flutter frequency there.
    f_interp = np.interp(
        result.speed, result.U[i - 1 : i + 1], result.frequencies[i - 1 : i + 1, j]
    )
    # The frequency changes by far less than 1 % over one grid step (400 points).
    assert f_interp == pytest.approx(result.frequency, rel=0.01)
    # Frequency-domain curves: the same sign change on the critical branch, ordered by K.
    fd = frequency_domain_jones(name)
    jf = fd.mode_names.index(fd.critical_mode)
    assert np.any((fd.damping[:-1, jf] > 0) & (fd.damping[1:, jf] <= 0))


# --------------------------------------------------------------------------------------------------
# Regression: zero structural damping with a coupled mass matrix (round-off at U = 0 once counted
# as instability and crashed the refinement).


@pytest.mark.parametrize("S", [0.01, 0.05, 0.1])
def test_undamped_unbalanced_section_has_a_flutter_speed(S):
    """Zero structural damping is allowed (zeta in [0, 1)); flutter must still be found."""
    s = SECTIONS["unbalanced_B0.3"].replace(zeta_h=0.0, zeta_a=0.0, S=S)
    td = flutter.analyze(s, JONES)
    fd = flutter.frequency_domain(s, JONES.flutter_derivatives, n_points=100)
    assert td.found and fd.found
    # Same model on both sides: see test_time_and_frequency_domain_agree_tightly_on_the_same_model.
    assert td.speed == pytest.approx(fd.speed, rel=1e-9)


def test_grid_size_accepts_numpy_integers():
    """n_points may be a numpy integer (e.g. from a config array); the result is the same."""
    s = SECTIONS["unbalanced_B0.3"]
    assert flutter.analyze(s, JONES, n_points=np.int64(200)).speed == pytest.approx(
        flutter.analyze(s, JONES, n_points=200).speed, rel=1e-12)


def test_a_model_whose_added_mass_makes_a_mode_grow_in_still_air_is_refused_naming_it():
    """A wild fit's skew added mass couples the modes without wind: 2.2 Hz grows at 28 %.

    Before, the crossing's refinement met a mode already growing at zero wind and stopped on
    scipy's "f(a) and f(b) must have different signs".
    """
    A = np.zeros((3, 2, 2))
    A[2] = [[0.0, 20.0], [-20.0, 0.0]]
    with pytest.raises(flutter.StillAirModesError, match=r"a mode grows in still air \(2.23 Hz"):
        flutter.analyze(FLAT_PLATE, RationalFunctionModel(A, []))
    A[2] *= 0.25  # the same coupling, weaker than the structure: it analyses as before
    assert flutter.analyze(FLAT_PLATE, RationalFunctionModel(A, [])).speed is None
