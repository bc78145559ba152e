"""Roger's rational-function model (evaluation, conversion, JSON) and Roger's least-squares fit."""

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ident import (
    IdentError,
    InsufficientDataError,
    RankDeficiencyError,
    RationalFunctionModel,
    SectionModel,
    roger_fit,
)
from ident.model import conventions, flat_plate

from support.sections import FLAT_PLATE

EPS = np.finfo(float).eps


def random_model(seed, lags, with_A3=True):
    A = np.random.default_rng(seed).normal(size=(3 + len(lags), 2, 2))
    if not with_A3:
        A[2] = 0.0
    return RationalFunctionModel(A, lags)


# --------------------------------------------------------------------------------------------------
# Evaluating Q(p)


def test_Q_is_rogers_form_evaluated_by_hand():
    """Q(p) = A1 + A2 p + A3 p^2 + sum A_{l+3} p/(p + d_l), at complex p, any shape."""
    model = random_model(1, [0.2, 1.3, 4.0])
    p = np.array([[0.3j, 1.0 + 2.0j], [-0.05 + 0.7j, 5.0j]])
    A, d = model.A, model.d
    got = model.Q(p)
    assert got.shape == (2, 2, 2, 2)
    for idx in np.ndindex(p.shape):
        pk = p[idx]
        want = A[0] + A[1] * pk + A[2] * pk**2 + sum(A[3 + k] * pk / (pk + d[k]) for k in range(3))
        # ~15 complex operations on O(1..30) numbers: a few eps of the largest term.
        np.testing.assert_allclose(got[idx], want, rtol=0, atol=1e-13 * max(1.0, abs(pk) ** 2))


def test_flutter_derivatives_of_a_quasi_steady_model():
    """Q = A1 + A2 p + A3 p^2 at p = iK gives K^2 H4* = A1 - A3 K^2, K^2 H1* = A2 K, etc."""
    A = np.zeros((3, 2, 2))
    A[0] = [[1.0, 2.0], [3.0, 4.0]]
    A[1] = [[5.0, 6.0], [7.0, 8.0]]
    A[2] = [[9.0, 10.0], [11.0, 12.0]]
    K = np.array([0.5, 2.0])
    fd = RationalFunctionModel(A, []).flutter_derivatives(K)
    real = {"H4": (0, 0), "H3": (0, 1), "A4": (1, 0), "A3": (1, 1)}
    imag = {"H1": (0, 0), "H2": (0, 1), "A1": (1, 0), "A2": (1, 1)}
    # Small integers times K in {0.5, 2}: exactly representable except the final /K^2 (1 ulp).
    for name, (i, j) in real.items():
        np.testing.assert_allclose(fd[name], (A[0, i, j] - A[2, i, j] * K**2) / K**2, rtol=4 * EPS)
    for name, (i, j) in imag.items():
        np.testing.assert_allclose(fd[name], A[1, i, j] * K / K**2, rtol=4 * EPS)


def test_model_is_an_immutable_value():
    """The model copies its inputs and exposes read-only arrays."""
    A = np.array(flat_plate.jones_model().A)
    d = np.array([0.091, 0.6])
    model = RationalFunctionModel(A, d)
    A[0, 0, 0] = 99.0
    d[0] = 99.0
    assert model.A[0, 0, 0] == 0.0 and model.d[0] == 0.091
    with pytest.raises(ValueError):
        model.A[0, 0, 0] = 1.0
    with pytest.raises(ValueError):
        model.d[0] = 1.0
    assert model == flat_plate.jones_model()
    assert model != random_model(0, [0.091, 0.6])
    assert model.n_lags == 2


# --------------------------------------------------------------------------------------------------
# Round trips


@pytest.mark.parametrize(
    "model",
    [flat_plate.jones_model(), random_model(5, [0.05, 0.3, 2.5]), random_model(6, [])],
    ids=["jones", "random-3-lags", "no-lags"],
)
def test_rfc_model_json_round_trip(model):
    """to_dict -> json.dumps -> json.loads -> from_dict gives an equal model (bit for bit)."""
    text = json.dumps(model.to_dict())
    back = RationalFunctionModel.from_dict(json.loads(text))
    assert back == model
    assert back.A.shape == model.A.shape and back.d.shape == model.d.shape
    np.testing.assert_array_equal(back.Q(0.7j), model.Q(0.7j))


@pytest.mark.parametrize(
    "section",
    [
        FLAT_PLATE,
        SectionModel(
            B=0.45, m=7.3, I=0.3, fh=1.37, fa=3.1, zeta_h=0.0, zeta_a=0.01, rho=1.1, S=-0.2
        ),
    ],
)
def test_section_json_round_trip(section):
    """SectionModel.to_dict -> JSON -> from_dict gives an equal section."""
    back = SectionModel.from_dict(json.loads(json.dumps(section.to_dict())))
    assert back == section
    np.testing.assert_array_equal(back.mass_matrix(), section.mass_matrix())


# Physically meaningful flutter derivatives are O(1e-3..1e3); the range avoids overflow of
# value * K^2 and subnormal results of value * K^2 (which lose precision by construction).
fd_value = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False).filter(
    lambda x: x == 0.0 or abs(x) > 1e-200
)


@settings(max_examples=200, deadline=None, database=None)
@given(
    K=st.lists(st.floats(min_value=0.01, max_value=10.0), min_size=1, max_size=6),
    data=st.data(),
)
def test_flutter_derivatives_survive_Q_round_trip(K, data):
    """flutter_derivatives_from_Q(Q_from_flutter_derivatives(fd)) == fd for finite values."""
    K = np.array(K)
    fd = {
        name: np.array(data.draw(st.lists(fd_value, min_size=K.size, max_size=K.size)))
        for name in conventions.FLUTTER_DERIVATIVE_NAMES
    }
    Q = conventions.Q_from_flutter_derivatives(K, fd)
    assert Q.shape == (K.size, 2, 2)
    back = conventions.flutter_derivatives_from_Q(K, Q)
    assert set(back) == set(fd)
    for name in fd:
        # (x * K^2) / K^2: two correctly rounded operations, at most ~1 eps relative; 2 eps bound.
        np.testing.assert_allclose(back[name], fd[name], rtol=2 * EPS, atol=0, err_msg=name)


def test_Q_layout_is_designs():
    """Each flutter derivative lands in the entry and part docs/reference/conventions.md gives."""
    K = np.array([2.0])
    for name in conventions.FLUTTER_DERIVATIVE_NAMES:
        fd = {other: np.zeros(1) for other in conventions.FLUTTER_DERIVATIVE_NAMES}
        fd[name] = np.array([1.0])
        Q = conventions.Q_from_flutter_derivatives(K, fd)[0] / 4.0  # / K^2
        row = 0 if name.startswith("H") else 1
        col = 0 if name[1] in "14" else 1
        part = 1j if name[1] in "12" else 1.0
        want = np.zeros((2, 2), dtype=complex)
        want[row, col] = part
        np.testing.assert_array_equal(Q, want, err_msg=name)


# --------------------------------------------------------------------------------------------------
# Roger fit


def test_roger_fit_recovers_jones_model():
    """The Jones plate's own table, fitted with Jones's lags, returns its closed-form A."""
    K = np.linspace(0.1, 4.0, 60)
    fitted = roger_fit(K, flat_plate.flutter_derivatives(K, jones=True), flat_plate.JONES_LAGS)
    np.testing.assert_array_equal(fitted.d, flat_plate.JONES_LAGS)
    # Exact data, zero residual: the error is ~cond(design) * eps * |A|; the design matrix
    # [Re; Im] of 1, iK, -K^2, iK/(iK + d_l) has cond ~ 1e2 here (independent of ident's code:
    # it is the plain basis), so ~1e-13; 1e-8 (as specified) leaves a wide margin.
    np.testing.assert_allclose(fitted.A, flat_plate.jones_model().A, rtol=0, atol=1e-8)


@pytest.mark.parametrize("with_A3", [True, False])
@pytest.mark.parametrize(
    "lags", [[0.2, 1.3], [0.05, 0.5, 3.0], []], ids=["2-lags", "3-lags", "0-lags"]
)
def test_roger_fit_recovers_a_random_model(lags, with_A3):
    """A table generated by a known Roger model is fitted back exactly with the same lags."""
    model = random_model(42, lags, with_A3=with_A3)
    K = np.geomspace(0.05, 5.0, 40)
    weights = np.random.default_rng(0).uniform(0.5, 2.0, K.size)  # any positive weights: exact fit
    fitted = roger_fit(K, model.flutter_derivatives(K), lags, with_A3=with_A3, weights=weights)
    # As above: exact data; cond of the basis is ~1e2 for lags spanning 0.05..3 over K in
    # 0.05..5, weights in [0.5, 2] change it by at most 2x: error ~1e-13 against 1e-8.
    np.testing.assert_allclose(fitted.A, model.A, rtol=0, atol=1e-8)


def test_roger_fit_without_A3_has_exactly_zero_A3():
    """with_A3=False fixes A3 to zero, even for data that has added mass."""
    K = np.linspace(0.1, 4.0, 60)
    fitted = roger_fit(K, flat_plate.flutter_derivatives(K), flat_plate.JONES_LAGS, with_A3=False)
    assert np.all(fitted.A[2] == 0.0)
    assert fitted.A.shape == (5, 2, 2)


def test_roger_fit_of_the_exact_plate_is_close_to_jones():
    """A 2-lag fit of the exact Theodorsen plate reproduces the table better than Jones's model."""
    K = np.linspace(0.3, 3.0, 100)
    exact = conventions.Q_from_flutter_derivatives(K, flat_plate.flutter_derivatives(K))
    fitted = roger_fit(K, flat_plate.flutter_derivatives(K), flat_plate.JONES_LAGS)
    err_fit = np.linalg.norm(fitted.Q(1j * K) - exact)
    err_jones = np.linalg.norm(flat_plate.jones_model().Q(1j * K) - exact)
    # Least squares over this exact grid minimises this very norm among models with these lags,
    # and Jones's model is one of them.
    assert err_fit <= err_jones


@pytest.mark.parametrize(
    "K",
    [
        [0.5, 1.0],  # 2 distinct K: 4 real equations per entry for 5 unknowns
        [0.5] * 10 + [1.0] * 10,  # many rows, still only 2 distinct K
        [0.7] * 30,
    ],
    ids=["two-K", "two-distinct-K-repeated", "one-K-repeated"],
)
def test_roger_fit_too_few_reduced_frequencies_is_rank_deficient(K):
    """Too few distinct K for 3 + m unknowns per entry: RankDeficiencyError, no numbers."""
    K = np.array(K)
    table = flat_plate.flutter_derivatives(K, jones=True)
    with pytest.raises(RankDeficiencyError, match="cannot determine 5 coefficients") as info:
        roger_fit(K, table, flat_plate.JONES_LAGS)
    assert isinstance(info.value, ValueError)
    assert isinstance(info.value, InsufficientDataError)
    assert isinstance(info.value, IdentError)


def test_roger_fit_repeated_lags_is_rank_deficient():
    """Two equal lag roots make two identical columns: RankDeficiencyError."""
    K = np.linspace(0.1, 3.0, 40)
    with pytest.raises(RankDeficiencyError):
        roger_fit(K, flat_plate.flutter_derivatives(K), [0.3, 0.3])


def test_roger_fit_three_distinct_K_suffice_for_two_lags():
    """The rank boundary: 3 distinct K give 6 equations for 5 unknowns, and an exact fit."""
    K = np.array([0.3, 1.0, 2.5])
    model = flat_plate.jones_model()
    fitted = roger_fit(K, model.flutter_derivatives(K), flat_plate.JONES_LAGS)
    # A small, square-ish system with exact data (cond ~1e2): rounding ~1e-13, far below 1e-8.
    np.testing.assert_allclose(fitted.A, model.A, rtol=0, atol=1e-8)


@pytest.mark.parametrize(
    ("weights", "match"),
    [
        (np.ones(9), "weights must be non-negative with the shape of K"),
        (np.ones((10, 1)), "weights must be a 1-D array"),
        (np.r_[np.ones(9), -1.0], "weights must be non-negative"),
        (np.r_[np.ones(9), np.nan], "weights contains 1 non-finite"),
    ],
    ids=["short", "2-D", "negative", "nan"],
)
def test_roger_fit_rejects_bad_weights(weights, match):
    """Weights of the wrong shape, negative or NaN raise ValueError naming the weights."""
    K = np.linspace(0.2, 3.0, 10)
    with pytest.raises(ValueError, match=match):
        roger_fit(K, flat_plate.flutter_derivatives(K), flat_plate.JONES_LAGS, weights=weights)


def test_roger_fit_all_zero_weights_is_rank_deficient():
    """Zero weights carry no information: RankDeficiencyError rather than arbitrary numbers."""
    K = np.linspace(0.2, 3.0, 10)
    with pytest.raises(RankDeficiencyError):
        roger_fit(K, flat_plate.flutter_derivatives(K), flat_plate.JONES_LAGS, weights=np.zeros(10))


@pytest.mark.parametrize(
    ("d", "match"), [([0.3, -0.1], "d must be > 0"), ([0.3, np.nan], "d contains 1 non-finite")]
)
def test_roger_fit_rejects_bad_lags(d, match):
    """Lag roots must be finite and > 0."""
    K = np.linspace(0.2, 3.0, 10)
    with pytest.raises(ValueError, match=match):
        roger_fit(K, flat_plate.flutter_derivatives(K), d)
