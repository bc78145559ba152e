"""The equation error's least-squares fit (``ident.discrepancy._equation_error.fit_linear``).

Its candidates' columns differ by many orders of magnitude (a cubic spring's ``h^3`` of a few
mm, a friction's sign of order one, a delay's force derivative): the parameters' standard
deviations must still be those of ordinary least squares, checked here against the closed form
for orthogonal columns, ``sigma / ||x_j||``.
"""

from __future__ import annotations

import numpy as np
import pytest

from ident.discrepancy._equation_error import fit_linear


def test_standard_deviations_hold_for_columns_ten_orders_of_magnitude_apart():
    rng = np.random.default_rng(7)
    t = np.arange(4000) / 500.0  # 8 s at 500 Hz: whole periods of 3 Hz, so sin and cos
    w = 2 * np.pi * 3.0  # are orthogonal
    sigma = 0.5
    y, X = [], []
    for _ in range(2):  # two releases
        cols = np.column_stack([1e-6 * np.sin(w * t), 1e4 * np.cos(w * t)])
        X.append(cols)
        y.append(cols @ np.array([3e5, -2e-4]) + rng.normal(0.0, sigma, t.size))
    fit = fit_linear(y, X, [125, 125])
    Xall, Y = np.vstack(X), np.concatenate(y)
    norms = np.linalg.norm(Xall, axis=0)
    # Orthogonal columns: each coefficient is its own projection, its variance sigma^2/||x||^2.
    assert fit.theta == pytest.approx(Xall.T @ Y / norms**2, rel=1e-9)
    # Before the fix the first came out ~1e-6 of this (pinv of the unscaled normal matrix,
    # condition 1e20, dropped its direction): a confident number for an unknown one.
    assert fit.std == pytest.approx(sigma / norms, rel=0.1)
