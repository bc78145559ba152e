"""The identification's small bounded Levenberg-Marquardt solver (ident.numerics.lsq)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from ident.numerics.lsq import bounded_lm


def rosenbrock(x: np.ndarray) -> np.ndarray:
    return np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]])


def rosenbrock_jacobian(x: np.ndarray) -> np.ndarray:
    return np.array([[-20.0 * x[0], 10.0], [-1.0, 0.0]])


def test_unbounded_minimum_of_rosenbrock():
    # Closed form: the residuals vanish at (1, 1). Tolerance: the solver stops at a step of
    # 1e-12 relative, far below the 1e-8 asked.
    sol = bounded_lm(rosenbrock, rosenbrock_jacobian, np.array([-1.2, 1.0]),
                     (np.full(2, -10.0), np.full(2, 10.0)), xtol=1e-12, ftol=1e-15,
                     max_nfev=200)
    assert np.allclose(sol.x, [1.0, 1.0], atol=1e-8)
    assert sol.cost < 1e-16


def test_active_bound_is_held_and_the_other_parameter_solved():
    # With x0 <= 0.5 the minimum is on that bound: x0 = 0.5 and the first residual vanishes
    # there (x1 = 0.25), cost 0.5 * 0.5^2. Tolerance 1e-6: the iterate stays 1e-10 of the box
    # width inside the bound.
    sol = bounded_lm(rosenbrock, rosenbrock_jacobian, np.array([-1.2, 1.0]),
                     (np.array([-10.0, -10.0]), np.array([0.5, 10.0])), xtol=1e-12,
                     ftol=1e-15, max_nfev=200)
    assert np.allclose(sol.x, [0.5, 0.25], atol=1e-6)
    assert sol.cost == pytest.approx(0.125, rel=1e-6)
    # scipy's trust-region reflective solver finds the same point (an independent check).
    reference = least_squares(rosenbrock, [-1.2, 1.0], jac=rosenbrock_jacobian,
                              bounds=([-10.0, -10.0], [0.5, 10.0]), xtol=1e-12, ftol=1e-15)
    assert np.allclose(sol.x, reference.x, atol=1e-6)


def test_exponential_decay_fit_matches_scipy():
    # A damped exponential in noise: the two solvers agree on the least-squares estimate to
    # well within its standard error (1e-3 relative here).
    rng = np.random.default_rng(7)
    t = np.linspace(0.0, 5.0, 400)
    y = 2.0 * np.exp(-0.8 * t) + 0.01 * rng.standard_normal(t.size)

    def residual(p):
        return p[0] * np.exp(-p[1] * t) - y

    def jacobian(p):
        e = np.exp(-p[1] * t)
        return np.column_stack([e, -p[0] * t * e])

    bounds = (np.array([0.0, 0.01]), np.array([10.0, 10.0]))
    sol = bounded_lm(residual, jacobian, np.array([1.0, 2.0]), bounds, xtol=1e-10,
                     ftol=1e-12, max_nfev=100)
    reference = least_squares(residual, [1.0, 2.0], jac=jacobian, bounds=bounds, xtol=1e-10,
                              ftol=1e-12)
    assert np.allclose(sol.x, reference.x, rtol=1e-6)
    assert sol.cost == pytest.approx(reference.cost, rel=1e-9)


def test_max_nfev_is_respected():
    calls = []

    def residual(x):
        calls.append(x.copy())
        return rosenbrock(x)

    sol = bounded_lm(residual, rosenbrock_jacobian, np.array([-1.2, 1.0]),
                     (np.full(2, -10.0), np.full(2, 10.0)), xtol=1e-15, ftol=1e-15, max_nfev=5)
    assert len(calls) == sol.nfev <= 5
    # The best point seen is returned: its cost is below the start's.
    assert sol.cost < 0.5 * float(rosenbrock(np.array([-1.2, 1.0])) @ rosenbrock(
        np.array([-1.2, 1.0])))
