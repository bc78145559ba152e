"""E2RFC's every-sample algebra from Gram matrices, against the formed residual and Jacobian.

``ident.identification._full_rows`` computes the Gauss-Newton step and the final coefficients from
one Gram matrix per release; ``ident.identification._stacked`` forms the 10^4-row residual and
Golub-Pereyra Jacobian of the same problem. Both must agree: that is the independent check. The lag
columns' real product (``RegressorView._real_design``) is checked against the complex product it
replaces.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ident import Release
from ident.identification._e2rfc_problem import Problem
from ident.identification._regressors import RegressorView, prepare
from ident.identification.modal import _exponentials
from ident.model import flat_plate, flutter
from simulators import simulate_release

from support.sections import FLAT_PLATE

JONES = flat_plate.jones_model()


@pytest.fixture(scope="module")
def problem() -> Problem:
    """Three releases of 10 s at 250 Hz with 2 % noise (seeded)."""
    U_F = flutter.analyze(FLAT_PLATE, JONES).speed
    data = [Release.from_simulation(simulate_release(
        FLAT_PLATE, JONES, f * U_F, 0.004, 0.02, duration=10.0, fs=250.0, noise=0.02,
        rng=(7, i))) for i, f in enumerate((0.4, 0.6, 0.8))]
    return Problem([prepare(r, FLAT_PLATE) for r in data])


# Well-posed lag roots (near the truth's 0.09 and 0.6, or one lag), and three spread roots.
THETAS = [np.log([0.2]), np.log([0.09, 0.6]), np.log([0.07, 0.5]),
          np.log([0.09, 0.66, 5.5])]


@pytest.mark.parametrize("with_A3", [True, False])
@pytest.mark.parametrize("theta", THETAS, ids=["1 lag", "2 lags", "2 lags off", "3 lags"])
def test_the_gauss_newton_step_from_gram_matrices_is_the_formed_jacobians(problem, theta,
                                                                          with_A3):
    """The same step as a least-squares solve with the formed Jacobian and residual.

    Tolerance 1e-8 of the step's size: the Gram form squares the Jacobian's condition number
    (at most ~1e3 for these well-separated roots), so it may lose 1e-10 relative; measured
    agreement is 1e-13 for two lags.
    """
    formed = problem._stacked(with_A3, "full")
    J, r = formed.jacobian(theta), formed.residual(theta)
    expected, *_ = np.linalg.lstsq(J, -r, rcond=None)
    step = problem._full_rows(with_A3).gauss_newton_step(theta)
    assert np.max(np.abs(step - expected)) <= 1e-8 * max(np.max(np.abs(expected)), 1e-3)


@pytest.mark.parametrize("with_A3", [True, False])
def test_the_final_coefficients_from_gram_matrices_are_the_row_solves(problem, with_A3):
    """Coefficients and residuals on every sample, against an SVD solve of the stacked rows.

    ``Problem._solve(exact=True)`` solves the weighted, demeaned rows by ``lstsq``; the Gram form
    with one refinement step must give the same coefficients to 1e-10 relative (measured
    1e-13) and the same weighted residuals to 1e-10 of their RMS.
    """
    d = np.array([0.09, 0.6])
    coef, residuals = problem._full_rows(with_A3).fit(d)
    expected, _, expected_residuals = problem._solve(problem._blocks(d, with_A3, "full"),
                                                     exact=True)
    assert np.max(np.abs(coef - expected)) <= 1e-10 * np.max(np.abs(expected))
    for got, want in zip(residuals, expected_residuals, strict=True):
        rms = np.sqrt(np.mean(want**2))
        assert np.max(np.abs(got - want)) <= 1e-10 * rms


def _complex_lag_columns(view: RegressorView, d: np.ndarray) -> np.ndarray:
    """Return the lag states by the complex formula over every pole (their definition)."""
    mu = view.rate * d
    poles = view.fit.poles[:, None]
    gained = ((poles / (poles + mu))[:, :, None] * view.fit.amplitudes[:, None, :]).reshape(
        poles.size, -1)
    decay = np.repeat(np.exp(-np.outer(view.t, mu)), view.n_dof, axis=1)
    return np.asarray((view.exponentials @ gained).real - decay * gained.sum(axis=0).real)


def test_the_real_lag_product_is_the_complex_one_with_and_without_conjugate_pairs(problem):
    """Paired poles count once (twice their real part); unpaired ones keep both columns.

    Tolerance 1e-12 of the columns' largest value: the real product sums in another order
    (measured 1e-16).
    """
    view = problem.prepared[1].view("search")
    d = np.array([0.09, 0.6])
    design, kept, _ = view._real_design
    assert kept.size < view.fit.poles.size  # the modal fit's conjugate pairs were found
    paired = view.lag_columns(d)
    assert np.max(np.abs(paired - _complex_lag_columns(view, d))) <= 1e-12 * np.max(
        np.abs(paired))
    # One pole of a pair taken away: no pair left to fold, every column kept.
    lone = np.array([0, *np.flatnonzero(view.fit.poles.imag == 0)])
    fit = dataclasses.replace(view.fit, poles=view.fit.poles[lone],
                              amplitudes=view.fit.amplitudes[lone])
    single = RegressorView(t=view.t, fixed=view.fixed, force=view.force,
                           exponentials=_exponentials(view.t, fit.poles), fit=fit,
                           rate=view.rate)
    assert single._real_design[1].size == lone.size
    columns = single.lag_columns(d)
    assert np.max(np.abs(columns - _complex_lag_columns(single, d))) <= 1e-12 * np.max(
        np.abs(columns))
