"""The parameter covariance as files carry it: its checks, its JSON form, the models drawn."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from ident.identification.covariance import ModelCovariance
from ident.model import flat_plate

MODEL = flat_plate.jones_model()
#: A1's two heave-row entries and the two lag roots: four parameters.
INDEX = ((0, 0, 0), (0, 0, 1))


def covariance() -> ModelCovariance:
    """Return a correlated 4 x 4 covariance (entries of A1 and log d)."""
    root = np.array([[0.02, 0.0, 0.0, 0.0], [0.01, 0.03, 0.0, 0.0],
                     [0.0, 0.005, 0.05, 0.0], [0.0, 0.0, 0.02, 0.04]])
    return ModelCovariance(INDEX, 2, root @ root.T)


def test_the_json_form_reads_back_to_the_same_matrix():
    original = covariance()
    back = ModelCovariance.from_dict(json.loads(json.dumps(original.to_dict())))
    assert back.parameter_index == INDEX and back.n_lags == 2
    # JSON keeps every digit of a float: equal, not close.
    np.testing.assert_array_equal(back.matrix, original.matrix)
    assert original.to_dict()["parameters"] == ["A1[0,0]", "A1[0,1]", "log d1", "log d2"]


@pytest.mark.parametrize(("matrix", "message"), [
    (np.eye(3), "must be 4 x 4"),
    (np.eye(4) + np.triu(np.full((4, 4), 0.1), 1), "not symmetric"),
    (np.diag([1.0, 1.0, -0.5, 1.0]), "not positive semi-definite"),
    (np.diag([1.0, np.nan, 1.0, 1.0]), "not finite"),
])
def test_a_matrix_that_is_no_covariance_is_refused(matrix, message):
    with pytest.raises(ValueError, match=message):
        ModelCovariance(INDEX, 2, matrix)


def test_an_index_the_model_does_not_have_is_refused():
    with pytest.raises(ValueError, match=r"A\[9, 0, 0\]"):
        ModelCovariance(((9, 0, 0),), 2, np.eye(3)).check_model(MODEL)
    with pytest.raises(ValueError, match="1 lag root"):
        ModelCovariance(INDEX, 1, np.eye(3)).check_model(MODEL)


def test_the_models_drawn_have_the_covariance_about_the_model():
    """4000 draws: mean and covariance of the parameters as stated, other entries untouched.

    Tolerance: the sample mean's std is sigma / sqrt(n) (0.016 sigma at n = 4000) and a sample
    covariance entry's std is at most sqrt(2 / n) sigma_i sigma_j (0.022): 4 of each.
    """
    cov = covariance()
    n = 4000
    models = cov.sample(MODEL, n, np.random.default_rng(3))
    theta = np.array([cov.parameters(m) for m in models])
    sigma = np.sqrt(np.diag(cov.matrix))
    np.testing.assert_array_less(np.abs(theta.mean(axis=0) - cov.parameters(MODEL)),
                                 4 * sigma / math.sqrt(n))
    assert np.all(np.abs(np.cov(theta.T) - cov.matrix)
                  <= 4 * math.sqrt(2 / n) * np.outer(sigma, sigma))
    # Entries outside the index are certain: every draw keeps them.
    assert all(np.array_equal(m.A[1:], MODEL.A[1:]) and np.array_equal(m.A[0, 1], MODEL.A[0, 1])
               for m in models[:50])
    assert all(np.all(m.d > 0) for m in models)  # log d normal: d stays positive


def test_an_estimates_round_off_is_cleaned_not_refused():
    """A pseudo-inverse's round-off (asymmetry, a tiny negative eigenvalue) passes.

    :meth:`ModelCovariance.from_estimate` (what ``windrig identify --json`` writes through
    ``of``) symmetrises and sets negative eigenvalues to zero; the checks of the constructor
    and of :meth:`from_dict` stay strict for a matrix a user gives. A singular covariance
    (rank 3) whose zero eigenvalue came out at -1e-6 of the largest, and 1e-7 asymmetric:
    refused as given, cleaned to within 2e-6 of the largest entry, and read back.
    """
    root = np.array([[0.02, 0.0, 0.0], [0.01, 0.03, 0.0], [0.0, 0.005, 0.05], [0.0, 0.0, 0.02]])
    good = root @ root.T  # 4 x 4 of rank 3
    values, vectors = np.linalg.eigh(good)
    scale = float(np.abs(good).max())
    values[0] = -1e-6 * scale
    noisy = (vectors * values) @ vectors.T
    noisy[0, 1] += 1e-7 * scale
    with pytest.raises(ValueError):
        ModelCovariance(INDEX, 2, noisy)
    cleaned = ModelCovariance.from_estimate(INDEX, 2, noisy)
    back = ModelCovariance.from_dict(json.loads(json.dumps(cleaned.to_dict())))
    assert np.linalg.eigvalsh(back.matrix).min() >= -1e-12 * scale
    np.testing.assert_allclose(back.matrix, good, atol=2e-6 * scale)
