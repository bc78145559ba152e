"""Bad input gets a clear error naming the offending field, never a silent wrong number."""

import math
import warnings

import numpy as np
import pytest

from ident import AeroelasticSystem, RationalFunctionModel, SectionModel
from ident.model import conventions, flat_plate, flutter

GOOD = {"B": 0.3, "m": 3.0, "I": 0.03, "fh": 2.0, "fa": 4.0, "zeta_h": 0.005, "zeta_a": 0.005}


def section(**changes):
    return SectionModel(**{**GOOD, **changes})


# --------------------------------------------------------------------------------------------------
# SectionModel


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"m": -3.0}, r"^m must be > 0, got -3\.0"),
        ({"m": 0.0}, r"^m must be > 0"),
        ({"B": 0.0}, r"^B must be > 0"),
        ({"I": -0.03}, r"^I must be > 0"),
        ({"fh": float("nan")}, r"^fh must be finite"),
        ({"fa": float("inf")}, r"^fa must be finite"),
        ({"rho": 0.0}, r"^rho must be > 0"),
        ({"zeta_h": 1.0}, r"^zeta_h must be in \[0\.0, 1\.0\)"),
        ({"zeta_a": -0.1}, r"^zeta_a must be in \[0\.0, 1\.0\)"),
        ({"S": float("nan")}, r"^S must be finite"),
        # m I = 4 * 0.25 = 1 exactly in binary, S^2 = 1: the boundary itself is rejected.
        ({"m": 4.0, "I": 0.25, "S": 1.0}, r"S must satisfy S\^2 < m I"),
        ({"S": -1.0}, r"S must satisfy S\^2 < m I"),
    ],
)
def test_section_rejects_bad_values(changes, match):
    """Non-positive sizes, out-of-range damping, NaN/inf and S^2 >= m I raise ValueError."""
    with pytest.raises(ValueError, match=match):
        section(**changes)


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"m": "3.0"}, r"^m must be a real number, got str"),
        ({"B": None}, r"^B must be a real number, got NoneType"),
        ({"zeta_h": True}, r"^zeta_h must be a real number, got bool"),
        ({"fh": 2.0 + 0j}, r"^fh must be a real number, got complex"),
    ],
)
def test_section_rejects_non_numbers(changes, match):
    """Strings, None, bools and complex numbers are TypeErrors, not coerced."""
    with pytest.raises(TypeError, match=match):
        section(**changes)


def test_section_accepts_numpy_scalars_and_ints():
    """Numpy floats and Python ints are real numbers; fields become floats."""
    s = section(m=np.float64(3.0), B=np.float32(0.25), fh=2)
    assert isinstance(s.m, float) and isinstance(s.fh, float) and s.fh == 2.0
    assert s.B == 0.25


def test_section_just_below_the_unbalance_limit_is_accepted():
    """S^2 slightly below m I is a (stiff but) valid positive-definite mass matrix."""
    s = section(m=4.0, I=0.25, S=0.999)
    # Symmetric positive definite: both eigenvalues > 0.
    assert np.all(np.linalg.eigvalsh(s.mass_matrix()) > 0)


def test_section_from_dict_and_replace_reject_unknown_keys():
    """Unknown fields are TypeErrors that name them (a typo must not fall back to a default)."""
    with pytest.raises(TypeError, match=r"unknown SectionModel field\(s\): \['mass'\]"):
        SectionModel.from_dict({**GOOD, "mass": 3.0})
    with pytest.raises(TypeError, match=r"unknown SectionModel field\(s\): \['Rho'\]"):
        SectionModel.from_dict({**GOOD, "Rho": 1.2})
    with pytest.raises(TypeError, match=r"unknown SectionModel field\(s\): \['zeta'\]"):
        section().replace(zeta=0.01)
    with pytest.raises(ValueError, match=r"^m must be > 0"):
        section().replace(m=-1.0)
    with pytest.raises(TypeError):  # a missing required field
        SectionModel.from_dict({k: v for k, v in GOOD.items() if k != "I"})


def test_section_is_frozen():
    """A validated section cannot be changed behind the validation's back."""
    s = section()
    with pytest.raises(AttributeError):
        s.m = -1.0


# --------------------------------------------------------------------------------------------------
# RationalFunctionModel


@pytest.mark.parametrize(
    ("A", "d", "match"),
    [
        (np.zeros((4, 2, 2)), [0.0], r"^d must be > 0"),
        (np.zeros((4, 2, 2)), [-0.1], r"^d must be > 0"),
        (np.zeros((5, 2, 2)), [0.1, np.nan], r"^d contains 1 non-finite"),
        (np.zeros((5, 2, 2)), [[0.1, 0.2]], r"^d must be a 1-D array"),
        (np.full((3, 2, 2), np.inf), [], r"^A contains 12 non-finite"),
        (
            np.r_[np.zeros((4, 2, 2)), np.full((1, 2, 2), np.nan)],
            [0.1, 0.2],
            r"^A contains 4 non-finite",
        ),
        (np.zeros((4, 2, 2)), [0.1, 0.2], r"^A must have shape \(3 \+ m, n, n\) = \(5, 2, 2\)"),
        (np.zeros((4, 3, 3)), [0.1, 0.2], r"^A must have shape \(3 \+ m, n, n\) = \(5, 3, 3\)"),
        (np.zeros((3, 4, 4)), [], r"^A must have shape .* = \(3, 2, 2\) .* n = 2 or 3"),
        (np.zeros((3, 2, 3)), [], r"^A must have shape"),
        (np.zeros((5, 2, 2)), [0.1], r"^A must have shape .* for m = 1 lag"),
        (np.zeros((2, 2)), [], r"^A must have shape"),
    ],
)
def test_rfc_model_rejects_bad_coefficients_and_lags(A, d, match):
    """Non-positive or non-finite lags, 2-D lags, non-finite or misshapen A raise ValueError."""
    with pytest.raises(ValueError, match=match):
        RationalFunctionModel(A, d)


def test_rfc_model_from_dict_rejects_unknown_and_missing_keys():
    """Unknown keys are TypeErrors naming them; a missing key is a ValueError naming it."""
    good = flat_plate.jones_model().to_dict()
    with pytest.raises(TypeError, match=r"unknown RationalFunctionModel key\(s\): \['lags'\]"):
        RationalFunctionModel.from_dict({**good, "lags": [0.1, 0.2]})
    with pytest.raises(ValueError, match=r"missing key\(s\): \['d'\]"):
        RationalFunctionModel.from_dict({"A": good["A"]})


@pytest.mark.parametrize("p", [np.nan, np.inf, complex(0.0, np.inf), [0.5j, complex(np.nan, 1.0)]])
def test_Q_rejects_non_finite_p(p):
    """Q(p) at NaN or infinite p raises instead of returning NaN matrices."""
    with pytest.raises(ValueError, match=r"^p contains non-finite"):
        flat_plate.jones_model().Q(p)


@pytest.mark.parametrize(
    ("K", "match"),
    [
        (0.0, r"^K must be > 0"),
        (-1.0, r"^K must be > 0"),
        ([0.5, -0.5], r"^K must be > 0"),
        (np.nan, r"^K contains 1 non-finite"),
        ([1.0, np.inf], r"^K contains 1 non-finite"),
    ],
)
def test_flutter_derivatives_reject_bad_K(K, match):
    """K <= 0 or non-finite K is rejected by every flutter-derivative function."""
    for function in (
        flat_plate.flutter_derivatives,
        lambda k: flat_plate.flutter_derivatives(k, jones=True),
        flat_plate.jones_model().flutter_derivatives,
    ):
        with pytest.raises(ValueError, match=match):
            function(K)


@pytest.mark.parametrize("k", [0.0, -0.2, np.nan])
def test_theodorsen_rejects_bad_k(k):
    """C(k) needs k > 0 (H0, H1 are singular at 0)."""
    with pytest.raises(ValueError, match=r"^k must be finite and > 0"):
        flat_plate.theodorsen(k)


# --------------------------------------------------------------------------------------------------
# conventions


def _fd(value=1.0):
    return {name: np.array([value]) for name in conventions.FLUTTER_DERIVATIVE_NAMES}


def test_Q_from_flutter_derivatives_rejects_missing_and_unknown_names():
    """All eight (or all 18) derivatives are required and no others accepted.

    A typo is not ignored; one derivative of sway with the eight asks for the other nine of 3 DOF.
    """
    missing = _fd()
    del missing["A4"]
    with pytest.raises(ValueError, match=r"flutter derivatives missing: \['A4'\]"):
        conventions.Q_from_flutter_derivatives([1.0], missing)
    with pytest.raises(ValueError, match=r"flutter derivatives missing: \['H6', 'A5', 'A6', 'P1'"):
        conventions.Q_from_flutter_derivatives([1.0], {**_fd(), "H5": np.array([1.0])})
    with pytest.raises(ValueError, match=r"unknown flutter derivative name\(s\): \['h1'\]"):
        conventions.Q_from_flutter_derivatives([1.0], {**_fd(), "h1": np.array([1.0])})


def test_Q_from_flutter_derivatives_rejects_non_finite_values_and_bad_K():
    """A NaN derivative is named; K must be > 0."""
    fd = _fd()
    fd["H3"] = np.array([np.nan])
    with pytest.raises(ValueError, match=r"^H3 contains 1 non-finite"):
        conventions.Q_from_flutter_derivatives([1.0], fd)
    with pytest.raises(ValueError, match=r"^K must be > 0"):
        conventions.Q_from_flutter_derivatives([0.0], _fd())


def test_flutter_derivatives_from_Q_rejects_wrong_shape():
    """Q must be (n, 2, 2) or (n, 3, 3) for n reduced frequencies."""
    with pytest.raises(ValueError, match=r"^Q must have shape \(2, 2, 2\) or \(2, 3, 3\)"):
        conventions.flutter_derivatives_from_Q([0.5, 1.0], np.zeros((3, 2, 2), dtype=complex))


# --------------------------------------------------------------------------------------------------
# State space and flutter analysis


@pytest.mark.parametrize(
    ("U", "match", "error"),
    [
        (-1.0, r"^U must be >= 0", ValueError),
        (np.nan, r"^U must be finite", ValueError),
        ("5", r"^U must be a real number", TypeError),
    ],
)
def test_aeroelastic_system_rejects_bad_wind_speed(U, match, error):
    """U must be a finite number >= 0."""
    with pytest.raises(error, match=match):
        AeroelasticSystem(section(), flat_plate.jones_model(), U)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"U_max": 0.0}, r"^U_max must be > 0"),
        ({"U_max": -10.0}, r"^U_max must be > 0"),
        ({"U_max": math.nan}, r"^U_max must be finite"),
        ({"n_points": 19}, r"^n_points must be an integer >= 20"),
        ({"n_points": 0}, r"^n_points must be an integer >= 20"),
        ({"n_points": 100.0}, r"^n_points must be an integer >= 20"),
    ],
)
def test_analyze_rejects_bad_search_range(kwargs, match):
    """A non-positive U_max or fewer than 20 grid points is rejected before any work."""
    with pytest.raises(ValueError, match=match):
        flutter.analyze(section(), flat_plate.jones_model(), **kwargs)


@pytest.mark.parametrize(
    ("K_range", "match"),
    [
        ((0.0, 5.0), r"^K_range must be > 0"),
        ((5.0, 0.05), r"^K_range must be increasing"),
        ((1.0, 1.0), r"^K_range must be increasing"),
    ],
)
def test_frequency_domain_rejects_bad_K_range(K_range, match):
    """The frequency-domain K range must be positive and increasing."""
    with pytest.raises(ValueError, match=match):
        flutter.frequency_domain(section(), flat_plate.flutter_derivatives, K_range)


# --------------------------------------------------------------------------------------------------
# Complex arrays must be refused, never silently made real.


@pytest.mark.parametrize("where", ["A", "flutter-derivatives"])
def test_complex_arrays_are_rejected_not_truncated(where):
    """A complex coefficient array or flutter-derivative table raises instead of dropping Im."""
    with warnings.catch_warnings():
        # Production code runs without pytest's warnings-as-errors: observe what a user gets.
        warnings.simplefilter("ignore", np.exceptions.ComplexWarning)
        with pytest.raises(TypeError, match="must be real"):
            if where == "A":
                A = np.zeros((3, 2, 2), dtype=complex)
                A[0, 0, 1] = 1.0 + 2.0j
                RationalFunctionModel(A, [])
            else:
                conventions.Q_from_flutter_derivatives([1.0], _fd(1.0 + 0.5j))
