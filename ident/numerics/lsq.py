"""A small bounded Levenberg-Marquardt solver for E2RFC's few-parameter lag-root searches.

E2RFC's lag-root search (:mod:`ident.identification._e2rfc_problem`) is a variable-projection
problem with 1 to 4 nonlinear parameters and a few thousand residuals, solved dozens of times per
identification. scipy's ``least_squares`` (trust-region reflective) spends more time on its own
bookkeeping per call and per iteration (set-up, an SVD of the Jacobian, scaling vectors) than on
these residuals; this solver needs only the normal matrix ``J^T J`` of the few columns and one
small solve per step. (The modal fit keeps scipy's solver: on a random response its landscape
has many local optima, and a different search path ends in different ones.)

Method: Levenberg-Marquardt with Marquardt's scaling (the damping is proportional to the
diagonal of ``J^T J``, which makes the steps invariant to the parameters' units, as scipy's
``x_scale="jac"``) and Nielsen's damping update; a step is clipped to the box, so the iterate
stays strictly feasible, and a parameter on a bound that the gradient pushes outwards is held
there while the others move (a projected step; clipping alone would leave the damped model
disagreeing with every step, and the search crawling along the bound). It stops as
``least_squares`` does: after a step below ``xtol (xtol + |x|)`` (taken if it lowers the cost),
when an accepted step that the quadratic model predicted well (ratio of actual to predicted
reduction above 0.25) lowers the cost by less than ``ftol`` of it, or after ``max_nfev``
residual evaluations.

References
----------
K. Madsen, H. B. Nielsen and O. Tingleff, "Methods for non-linear least squares problems",
2nd ed., IMM, Technical University of Denmark (2004), section 3.2.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["LsqResult", "bounded_lm"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class LsqResult:
    """Solution of :func:`bounded_lm`.

    Attributes
    ----------
    x : ndarray
        Parameters at the lowest cost found.
    fun : ndarray
        Residuals there.
    cost : float
        ``0.5 |fun|^2``.
    nfev : int
        Residual evaluations.
    """

    x: FloatArray
    fun: FloatArray
    cost: float
    nfev: int


def bounded_lm(
    residual: Callable[[FloatArray], FloatArray],
    jacobian: Callable[[FloatArray], FloatArray],
    x0: FloatArray,
    bounds: tuple[FloatArray, FloatArray],
    *,
    xtol: float,
    ftol: float,
    max_nfev: int,
) -> LsqResult:
    """Minimise ``0.5 |residual(x)|^2`` for ``lo < x < hi`` from ``x0`` (module docstring).

    Parameters
    ----------
    residual, jacobian : callable
        ``x -> r`` (n,) and ``x -> dr/dx`` (n, k). The Jacobian is asked for only at accepted
        points, each right after the residual at the same point (callers may cache).
    x0 : ndarray, shape (k,)
        Start, strictly inside the bounds.
    bounds : (ndarray, ndarray)
        Lower and upper bounds, each shape (k,).
    xtol, ftol : float
        Relative step and cost-reduction tolerances (as scipy's ``least_squares``).
    max_nfev : int
        Largest number of residual evaluations.

    Returns
    -------
    LsqResult
    """
    lo, hi = (np.asarray(b, dtype=float) for b in bounds)
    # Steps stop this far inside the box (relative to its width): the iterate stays feasible.
    margin = 1e-10 * (hi - lo)
    inner_lo, inner_hi = lo + margin, hi - margin
    x = np.clip(np.asarray(x0, dtype=float), inner_lo, inner_hi)
    r = residual(x)
    cost = 0.5 * float(r @ r)
    nfev = 1
    if x.size == 0:
        return LsqResult(x, r, cost, nfev)
    J = jacobian(x)
    A, g = J.T @ J, J.T @ r
    scale = np.diag(A).copy()  # Marquardt's scaling, the largest diagonal seen (as MINPACK)
    diagonal = np.diag_indices(x.size)
    damping = 1e-3
    growth = 2.0
    while nfev < max_nfev:
        scale = np.maximum(scale, A[diagonal])
        M = A.copy()
        M[diagonal] += damping * np.where(scale > 0.0, scale, 1.0)
        # A parameter on its bound that the gradient pushes outwards stays there: the step is
        # solved for the others (else every clipped step would disagree with the model).
        held = ((x <= lo + 2.0 * margin) & (g > 0.0)) | ((x >= hi - 2.0 * margin) & (g < 0.0))
        step = np.zeros_like(x)
        if held.any():
            free = ~held
            if free.any():
                step[free] = _solve(M[np.ix_(free, free)], -g[free])
        else:
            step = _solve(M, -g)
        x_new = np.clip(x + step, inner_lo, inner_hi)
        step = x_new - x
        step_norm = math.sqrt(float(step @ step))
        if step_norm == 0.0:
            break
        # A step below xtol is still taken when it lowers the cost, and is the last.
        small = step_norm <= xtol * (xtol + math.sqrt(float(x @ x)))
        predicted = -float(g @ step + 0.5 * step @ A @ step)
        r_new = residual(x_new)
        nfev += 1
        cost_new = 0.5 * float(r_new @ r_new)
        if math.isfinite(cost_new) and cost_new < cost and predicted > 0.0:
            ratio = (cost - cost_new) / predicted
            reduction = cost - cost_new
            x, r, cost = x_new, r_new, cost_new
            if small or (reduction <= ftol * (cost + reduction) and ratio > 0.25):
                break
            J = jacobian(x)
            A, g = J.T @ J, J.T @ r
            damping *= max(1.0 / 3.0, 1.0 - (2.0 * ratio - 1.0) ** 3)
            growth = 2.0
        elif small:
            break
        else:
            damping *= growth
            growth *= 2.0
    return LsqResult(x, r, cost, nfev)


def _solve(M: FloatArray, b: FloatArray) -> FloatArray:
    """Solve the damped normal equations (least squares if they are singular)."""
    try:
        return np.asarray(np.linalg.solve(M, b), dtype=float)
    except np.linalg.LinAlgError:
        return np.asarray(np.linalg.lstsq(M, b, rcond=None)[0], dtype=float)
