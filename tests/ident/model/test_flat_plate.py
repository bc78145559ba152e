"""Flat-plate truth case: Theodorsen's function, closed-form flutter derivatives, Jones's RFCs.

The closed-form flutter derivatives are those of ``docs/reference/conventions.md``, "The analytic
truth"; R. T. Jones's rational approximation makes the plate an exact Roger model.

Every expectation here is computed in the test itself, from Bessel functions (scipy.special.jv, yv,
not the Hankel routine ident uses), from the eight formulas written out again below, or from
published tables of Theodorsen's function.
"""

import numpy as np
import pytest
from scipy.special import jv, yv

from ident import SectionModel
from ident.model import conventions, flat_plate, flutter

from support.sections import FLAT_PLATE

PI = np.pi


def theodorsen_from_bessel(k):
    """C(k) = H1(k) / (H1(k) + i H0(k)) with H_n^(2) = J_n - i Y_n (second kind)."""
    k = np.asarray(k, dtype=float)
    h1 = jv(1, k) - 1j * yv(1, k)
    h0 = jv(0, k) - 1j * yv(0, k)
    return h1 / (h1 + 1j * h0)


def jones_from_formula(p):
    """R. T. Jones: C(p) = 1 - 0.165 p/(p + 0.091) - 0.335 p/(p + 0.6) (the conventions)."""
    p = np.asarray(p, dtype=complex)
    return 1.0 - 0.165 * p / (p + 0.091) - 0.335 * p / (p + 0.6)


def design_flutter_derivatives(K, C):
    """Evaluate the eight flat-plate formulas of docs/reference/conventions.md, C = F + iG."""
    K = np.asarray(K, dtype=float)
    F, G = C.real, C.imag
    return {
        "H1": -2 * PI * F / K,
        "H2": -(PI / (2 * K)) * (1 + F + 4 * G / K),
        "H3": -(2 * PI / K**2) * (F - K * G / 4),
        "H4": (PI / 2) * (1 + 4 * G / K),
        "A1": PI * F / (2 * K),
        "A2": -(PI / (8 * K)) * (1 - F - 4 * G / K),
        "A3": (PI / (2 * K**2)) * (K**2 / 32 + F - K * G / 4),
        "A4": -PI * G / (2 * K),
    }


def Q_by_hand(K, fd):
    """Q(iK) = K^2 [[H4 + i H1, H3 + i H2], [A4 + i A1, A3 + i A2]] (the conventions)."""
    K = np.asarray(K, dtype=float)
    Q = np.empty(K.shape + (2, 2), dtype=complex)
    Q[:, 0, 0] = fd["H4"] + 1j * fd["H1"]
    Q[:, 0, 1] = fd["H3"] + 1j * fd["H2"]
    Q[:, 1, 0] = fd["A4"] + 1j * fd["A1"]
    Q[:, 1, 1] = fd["A3"] + 1j * fd["A2"]
    return Q * (K**2)[:, None, None]


# --------------------------------------------------------------------------------------------------
# Theodorsen's function


@pytest.mark.parametrize(
    ("k", "F", "G"),
    [
        # Published values (Theodorsen, NACA Report 496; Bisplinghoff, Ashley and Halfman,
        # "Aeroelasticity", table of Theodorsen's function).
        (0.1, 0.8319, -0.1723),
        (0.5, 0.5979, -0.1507),
        (1.0, 0.5394, -0.1003),
    ],
)
def test_theodorsen_matches_published_table(k, F, G):
    """Both ident's C(k) and an independent Bessel evaluation reproduce the 4-digit table."""
    # The table is rounded to 4 decimals: a correct value lies within half a unit of the last digit.
    half_ulp_of_table = 0.5e-4
    for C in (complex(flat_plate.theodorsen(k)), complex(theodorsen_from_bessel(k))):
        assert abs(C.real - F) <= half_ulp_of_table
        assert abs(C.imag - G) <= half_ulp_of_table


def test_theodorsen_equals_bessel_form_over_a_wide_range():
    """The Hankel-function C(k) of ident equals J_n - i Y_n evaluated independently."""
    k = np.geomspace(1e-3, 50.0, 200)
    got = flat_plate.theodorsen(k)
    want = theodorsen_from_bessel(k)
    # Both are short closed expressions of Bessel functions that scipy evaluates to ~1e-15
    # relative (AMOS / Cephes); |C| >= 0.5 everywhere, so 1e-12 leaves three orders of margin.
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)


def test_theodorsen_limits():
    """C(k) -> 1 in steady flow (k -> 0) and -> 1/2 at high frequency (k -> inf)."""
    # C(k) - 1 = O(k ln k) as k -> 0: at k = 1e-6 that is ~1e-5; allow 1e-4.
    assert abs(complex(flat_plate.theodorsen(1e-6)) - 1.0) < 1e-4
    # C(k) - 1/2 = O(1/k) as k -> inf (G ~ -1/(8k)): at k = 1e4 that is ~1e-5; allow 1e-4.
    assert abs(complex(flat_plate.theodorsen(1e4)) - 0.5) < 1e-4


# --------------------------------------------------------------------------------------------------
# Exact flat-plate flutter derivatives


@pytest.mark.parametrize("K", [0.3, 0.6283, 1.0, 3.1416])
def test_flutter_derivatives_equal_closed_forms(K):
    """flat_plate.flutter_derivatives(K) equals the 8 documented formulas, Bessel-form C(K/2)."""
    want = design_flutter_derivatives(np.array([K]), theodorsen_from_bessel(K / 2.0))
    got = flat_plate.flutter_derivatives(K)
    assert set(got) == set(conventions.FLUTTER_DERIVATIVE_NAMES)
    for name in conventions.FLUTTER_DERIVATIVE_NAMES:
        assert got[name].shape == (1,)
        # C(k) is accurate to ~1e-15 on both paths; the formulas amplify that by the cancellation
        # in e.g. 1 + 4G/K (at most a factor ~20 at these K), so 1e-9 has ample margin while still
        # catching any sign, factor-of-2 or K-vs-k mistake (those are O(1) errors).
        np.testing.assert_allclose(got[name], want[name], rtol=1e-9, atol=0, err_msg=name)


def test_flat_plate_signs_are_scanlans():
    """Hand-checkable signs: heave aerodynamic damping H1* < 0, lift slope H3* < 0, A3* > 0."""
    fd = flat_plate.flutter_derivatives(np.linspace(0.2, 5.0, 50))
    # Scanlan: h and L positive downward; a nose-up alpha gives upward (negative) lift.
    assert np.all(fd["H1"] < 0)
    assert np.all(fd["H3"] < 0)
    assert np.all(fd["A1"] > 0)
    assert np.all(fd["A3"] > 0)


# --------------------------------------------------------------------------------------------------
# Jones's approximation: an exact Roger model


def test_jones_model_structure():
    """Jones's plate is a Roger model with lags (0.091, 0.6) and the flat-plate added mass in A3."""
    model = flat_plate.jones_model()
    np.testing.assert_array_equal(model.d, [0.091, 0.6])
    assert model.A.shape == (5, 2, 2)
    # A3 = diag(-pi/2, -pi/64): rho/2 B^4 A3 q'' gives L = -(pi rho B^2/4) h'' (added mass
    # pi rho b^2, b = B/2) and M = -(pi rho B^4/128) alpha'' (pi rho b^4/8). Built from a few exact
    # float operations, so a few ulps.
    np.testing.assert_allclose(model.A[2], [[-PI / 2, 0.0], [0.0, -PI / 64]], rtol=1e-15, atol=0)
    # Steady limit Q(0) = A1 = K^2 [[H4, H3], [A4, A3]] at K -> 0 with C(0) = 1:
    # K^2 H3 -> -2 pi (lift slope), K^2 A3 -> pi/2 (moment about mid-chord), others -> 0.
    np.testing.assert_allclose(model.A[0], [[0.0, -2 * PI], [0.0, PI / 2]], rtol=1e-15, atol=0)


def test_jones_C_is_jones_formula():
    """flat_plate.jones_C is 1 - 0.165 p/(p+0.091) - 0.335 p/(p+0.6)."""
    p = 1j * np.geomspace(0.01, 100.0, 300)
    # Same three rational terms in a possibly different summation order: a few ulps of |C| ~ 1.
    np.testing.assert_allclose(flat_plate.jones_C(p), jones_from_formula(p), rtol=1e-14, atol=0)


def test_jones_model_reproduces_exact_plate_within_2_5_percent():
    """Q of the Jones model is within 2.5 % of the exact Q_ij(iK) for K in [0.3, 3]."""
    K = np.linspace(0.3, 3.0, 500)
    exact = conventions.Q_from_flutter_derivatives(
        K, design_flutter_derivatives(K, theodorsen_from_bessel(K / 2.0))
    )
    approx = flat_plate.jones_model().Q(1j * K)
    rel = np.abs(approx - exact) / np.abs(exact)
    # Jones's two-lag fit of C(k) is a few-percent approximation: |C_Jones - C| / |C| peaks at
    # about 2.3 % near k ~ 0.5 (check: jones_from_formula vs theodorsen_from_bessel). Q21 =
    # (pi/2) p C carries exactly that relative error; the other entries add non-circulatory terms
    # that do not depend on C, which keeps them at the same level. 2.5 % is the bound the issue
    # states; a wrong lag root, amplitude, sign or entry breaks it by far more.
    assert rel.shape == (500, 2, 2)
    assert rel.max() < 0.025, (
        f"max relative error {rel.max():.4f} at entry {np.unravel_index(rel.argmax(), rel.shape)}"
    )


def test_jones_model_is_exactly_the_design_formulas_with_jones_C():
    """The closed-form RFCs are exact: Q of jones_model() = the formulas with Jones's C(p)."""
    K = np.geomspace(0.05, 20.0, 400)
    model = flat_plate.jones_model()
    want_fd = design_flutter_derivatives(K, jones_from_formula(1j * K))
    # Compare Q_ij relative to |Q_ij| (|Q_ij| is bounded away from 0 for the plate, while single
    # flutter derivatives such as H4* cross zero). Both sides are ~10 float operations on O(1)
    # numbers, so agreement is at the 1e-15 level; 1e-12 is the bound the issue asks for.
    want_Q = Q_by_hand(K, want_fd)
    got_Q = model.Q(1j * K)
    assert np.all(np.abs(got_Q - want_Q) <= 1e-12 * np.abs(want_Q))
    # The same through ident's own Jones flutter derivatives and the model's conversion.
    got_fd = model.flutter_derivatives(K)
    ref_fd = flat_plate.flutter_derivatives(K, jones=True)
    ref_Q = Q_by_hand(K, ref_fd)
    assert np.all(np.abs(Q_by_hand(K, got_fd) - ref_Q) <= 1e-12 * np.abs(ref_Q))


def test_jones_and_exact_plate_agree_in_the_steady_limit():
    """Both C(0) = 1: at small K the Jones and exact A3* (moment slope) agree to O(K ln K)."""
    K = np.array([1e-4])
    exact = flat_plate.flutter_derivatives(K)
    jones = flat_plate.flutter_derivatives(K, jones=True)
    # K^2 A3* -> (pi/2) C(0) = pi/2 for both; the corrections are O(K) ~ 1e-4 at K = 1e-4
    # (1 - F ~ pi k / 2 for Theodorsen), so 1e-3 separates them from any O(1) error.
    assert abs(K[0] ** 2 * exact["A3"][0] - PI / 2) < 1e-3
    assert abs(K[0] ** 2 * jones["A3"][0] - PI / 2) < 1e-3


def test_the_eight_lag_fit_stands_for_the_exact_plate():
    """Theodorsen's function and the flutter speed of the exact plate, from the rational fit.

    The fit's C(p) is within 1e-4 of the exact function over the reduced frequencies of any
    section test (the fit reaches 4.6e-5; Jones's two lags are 100 times worse), and its
    state-space flutter speed matches the frequency-domain analysis with the exact derivatives
    to 0.01 % (measured 0.0012 % and 0.0005 %): the frequency-domain search itself resolves K
    only to about that. Jones's model, by contrast, is 0.8-1.1 % off on these sections.
    """
    model = flat_plate.theodorsen_model()
    K = np.geomspace(0.01, 10.0, 300)
    p = 1j * K
    C_fit = 1.0 - sum(
        a * p / (p + d)
        for a, d in zip(_plate_amplitudes(model), model.d, strict=True)
    )
    assert np.max(np.abs(C_fit - theodorsen_from_bessel(K / 2.0))) < 1e-4
    assert np.max(np.abs(jones_from_formula(p) - theodorsen_from_bessel(K / 2.0))) > 5e-3
    for section in (
        FLAT_PLATE,
        SectionModel(B=0.45, m=8.0, I=0.16, fh=1.2, fa=3.6, zeta_h=0.003, zeta_a=0.003),
    ):
        exact = flutter.frequency_domain(section, flat_plate.flutter_derivatives)
        fitted = flutter.analyze(section, model)
        jones = flutter.analyze(section, flat_plate.jones_model())
        assert fitted.speed == pytest.approx(exact.speed, rel=1e-4)
        assert fitted.frequency == pytest.approx(exact.frequency, rel=1e-4)
        assert abs(jones.speed / exact.speed - 1.0) > 5e-3


def _plate_amplitudes(model):
    """Return the a_l of a plate model from its lag terms (moment on heave: pi/2 a_l d_l)."""
    return model.A[3:, 1, 0] / ((np.pi / 2) * model.d)


def test_plate_model_refuses_mismatched_amplitudes_and_lags():
    with pytest.raises(ValueError, match="one length"):
        flat_plate.plate_model([0.1, 0.2], [0.5])
    with pytest.raises(ValueError, match="n_lags"):
        flat_plate.theodorsen_model(1)
