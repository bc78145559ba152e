"""Force-equation fits of the discrepancy workflow (private to it).

The pressures measure every force that acts through the air, so an aerodynamic effect leaves
the structural equation (:mod:`ident.discrepancy._equation_error`) satisfied: it shows instead in
the
*force equation*, the measured forces against the motion through Roger's form::

    [L B, M] = qd B^2 [A1 q + A2 (B/U) q' + A3 (B/U)^2 q'' + sum_l A_{l+3} x_l] + c_i

with the lag states ``x_l' = q' - (U/B) d_l x_l`` from rest at the release and an intercept
``c_i`` per release (a static force). With the lag roots ``d_l`` of a given model this is
linear in the ``A_k``, and the aerodynamic nonlinearity
(:class:`ident.physics.effects.AerodynamicNonlinearity`) adds two columns,
``qd B^2 (B/U) [(q_h/q_ref)^2 q_h', 0]`` and ``[0, (alpha/q_ref)^2 alpha']``, linear in
``e_h, e_a``. :func:`fit_aerodynamic` fits the candidate jointly with the ``A_k`` (a linear
model fitted to data with the nonlinearity absorbs its average, so the ``A_k`` must be free)
and scores it by the held-out residual with its columns over that without (the folds of
:mod:`ident.discrepancy._equation_error`). Quadratic damping, the structural look-alike (damping
that grows with the amplitude), leaves this equation alone: the taps do not see it.

Only for scoring and for ``e_h, e_a``: the ``A_k`` fitted here are not a model. Regressors
built from the measured motion carry its noise, differentiated twice for ``A3``, and a decay
that dies out early (friction) leaves that noise a large share of the rows: the coefficients
come out biased by a few per cent (a refit of this kind simulated worse than E2RFC's, whose
regressors come from a modal fit). The model is identified again by E2RFC with the named
force taken out (:mod:`ident.discrepancy.effect_selection`).

The signals are those of :func:`ident.discrepancy._equation_error.decay_signals` (low-passed,
trimmed of their edges); the lag states are run over the whole decay from the release, then trimmed.

Not responsible for: choosing effects (:mod:`ident.discrepancy.effect_selection`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.signal import lfilter

from ident.discrepancy._equation_error import (
    DecaySignals,
    chunk_ids,
    compare_held_out,
    fit_linear,
    held_out_sse,
)
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.physics.effects import AerodynamicNonlinearity

FloatArray = npt.NDArray[np.float64]

#: Reference displacement of the candidate's columns (the effect's default ``q_ref``).
Q_REF = AerodynamicNonlinearity().q_ref


@dataclass(frozen=True)
class ForceProblem:
    """The whitened force equation of all decays.

    Attributes
    ----------
    y : list of ndarray, shape (2 n_i,)
        Per release, ``[L B, M]`` (low-passed, trimmed), each equation divided by its RMS.
    linear : list of ndarray, shape (2 n_i, p)
        The ``A_k`` entries' columns (shared by all releases), then the intercepts (a block
        per release).
    nonlinear : list of ndarray, shape (2 n_i, 2)
        The aerodynamic nonlinearity's columns (``e_h``, ``e_a``).
    chunks : list of int
        Rows per held-out chunk, per release.
    n_shared : int
        Number of ``A_k`` columns (the first of :attr:`linear`).
    with_A3 : bool
        Whether ``A3`` is fitted (always, see :func:`force_problem`).
    """

    y: list[FloatArray]
    linear: list[FloatArray]
    nonlinear: list[FloatArray]
    chunks: list[int]
    n_shared: int
    with_A3: bool


@dataclass(frozen=True)
class AerodynamicFit:
    """The aerodynamic-nonlinearity candidate fitted on the force equation.

    Attributes
    ----------
    e, e_std : ndarray, shape (2,)
        ``e_h, e_a`` and their standard deviations.
    cv_ratio, cv_ratio_se : float
        Held-out residual with its columns over that without (the ``A_k`` free in both) and
        its standard error.
    """

    e: FloatArray
    e_std: FloatArray
    cv_ratio: float
    cv_ratio_se: float


def _lag_states(sig: DecaySignals, section: SectionModel, d: FloatArray) -> list[FloatArray]:
    """Lag states ``x_l`` (n_full, 2) from rest at the release (exact for a held ``q'``)."""
    assert sig.q1_full is not None
    dt = float(np.median(np.diff(sig.t)))
    out = []
    for root in d:
        c = sig.U * float(root) / section.B
        a = math.exp(-c * dt)
        out.append(np.asarray(lfilter([0.0, (1.0 - a) / c], [1.0, -a], sig.q1_full, axis=0),
                              dtype=float))
    return out


def force_problem(signals: Sequence[DecaySignals], section: SectionModel,
                  model: RationalFunctionModel) -> ForceProblem:
    """Build the whitened force equation with the lag roots of ``model`` (module docstring)."""
    A = np.asarray(model.A, dtype=float)
    if A.shape[-1] != 2:
        raise ValueError("the force equation is for two-degree-of-freedom models")
    # A3 always: E2RFC may leave it out of a model fitted to data with the nonlinearity in,
    # and without it the linear part cannot follow the forces (e came out 9 % low).
    with_A3 = True
    B = section.B
    f = [sig.f for sig in signals]
    scale = np.sqrt(np.mean(np.vstack(f) ** 2, axis=0))
    scale[scale == 0.0] = 1.0
    y, linear, nonlinear = [], [], []
    n = len(signals)
    for i, sig in enumerate(signals):
        assert sig.q_full is not None and sig.q1_full is not None and sig.q2_full is not None
        assert sig.keep is not None
        qdB2 = sig.qd * B**2
        tb = B / sig.U
        regressors = [sig.q_full, tb * sig.q1_full]
        if with_A3:
            regressors.append(tb**2 * sig.q2_full)
        regressors += _lag_states(sig, section, np.asarray(model.d, dtype=float))
        rows = int(np.count_nonzero(sig.keep))
        cols = []
        for r in regressors:
            r = r[sig.keep]
            for eq in range(2):
                for j in range(2):
                    c = np.zeros((rows, 2))
                    c[:, eq] = qdB2 * r[:, j]
                    cols.append((c / scale).ravel())
        shared = len(cols)
        intercepts = np.zeros((2 * rows, 2 * n))
        for eq in range(2):
            c = np.zeros((rows, 2))
            c[:, eq] = 1.0 / scale[eq]
            intercepts[:, 2 * i + eq] = c.ravel()
        linear.append(np.column_stack([np.column_stack(cols), intercepts]))
        q, q1 = sig.q_full, sig.q1_full
        amp = qdB2 * tb
        zero = np.zeros(q.shape[0])
        nl = [sig.band_limited(np.column_stack([amp * (q[:, 0] / Q_REF) ** 2 * q1[:, 0], zero])),
              sig.band_limited(np.column_stack([zero, amp * (q[:, 1] / Q_REF) ** 2 * q1[:, 1]]))]
        nonlinear.append(np.column_stack([(c / scale).ravel() for c in nl]))
        y.append((sig.f / scale).ravel())
    return ForceProblem(y=y, linear=linear, nonlinear=nonlinear,
                        chunks=[2 * sig.chunk for sig in signals], n_shared=shared,
                        with_A3=with_A3)


def fit_aerodynamic(problem: ForceProblem) -> AerodynamicFit:
    """Fit the aerodynamic nonlinearity jointly with the ``A_k``; score it held out."""
    joint = [np.column_stack([lin, nl]) for lin, nl in zip(problem.linear, problem.nonlinear,
                                                          strict=True)]
    fit = fit_linear(problem.y, joint, problem.chunks)
    chunk_id, _ = chunk_ids(problem.y, problem.chunks)
    ratio, se = compare_held_out(held_out_sse(problem.y, problem.linear, problem.chunks),
                                 held_out_sse(problem.y, joint, problem.chunks), chunk_id)
    return AerodynamicFit(e=fit.theta[-2:], e_std=fit.std[-2:], cv_ratio=ratio,
                          cv_ratio_se=se)

