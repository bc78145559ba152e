"""Closed-loop maximum likelihood of the self-excited forces from releases in turbulence.

In turbulent flow the buffeting force drives the motion that the self-excited force answers: a
closed loop. A direct prediction-error method uses all of the excitation's information there,
the release's decay and the random response alike. This module maximises the exact-form
Gaussian likelihood of every release at every wind speed together, over

- Roger's coefficients ``A_k`` and lag roots ``d_l``, shared across speeds through the reduced
  frequency (:class:`~ident.model.rfc.RationalFunctionModel`);
- per wind speed, the buffeting force as white noise through a second-order shaping filter per
  force (or several in cascade, ``shaping_sections``) with the lift-moment correlation
  (:class:`~ident.identification.innovations.ShapingFilter`);
- per release, the four channels' sensor-noise standard deviations;
- per record, concentrated out by generalised least squares: the channels' constant offsets
  (mean wind load, static deflection, zero drift) and the initial state.

A hold before a release (the model held in the wind) adds its record as extra data: the force
channels see the buffeting alone there, the displacement channels only noise. It is used when
present, never required.

The model per release is :class:`~ident.identification.innovations.ReleaseModel` on the record
averaged over blocks to about :data:`TARGET_FACTOR` times the highest still-air frequency; the
block means are taken as samples of the state, or (``exact_block_means``) modelled as the means
they are (:func:`~ident.identification.innovations.block_means`), whose output noise is then
correlated with the process noise (:func:`~ident.identification.steady_predictor.decorrelated`). The
likelihood is that of the steady-state Kalman predictor ``x_{k+1} = Phi x_k + K_p (y_k - C x_k)``,
``K_p = Phi P C^T S^-1`` with ``P`` from the discrete Riccati equation (:func:`riccati`): with
the innovations ``e_k`` and their covariance ``S``,

    -log L = sum_records [ n/2 (4 log 2 pi + log det S) + 1/2 sum_k e_k^T S^-1 e_k ].

It maximises it by Fisher scoring with Levenberg-Marquardt damping. The derivatives of
``e_k`` and ``S`` come from forward differences of the model's matrices, carried through the
predictor to first order (the Riccati solution's change from a Stein equation, the
innovations' from one pass of the base predictor's filter for all parameters together:
:meth:`SteadyPredictor.change`, :meth:`SteadyPredictor.innovation_changes`), and the Fisher
information is

    F_ij = sum_k de_k/dth_i^T S^-1 de_k/dth_j + n/2 tr(S^-1 dS/dth_i S^-1 dS/dth_j),

so its inverse at the optimum is the parameters' covariance: the Cramer-Rao bound of the data
at hand. The steady gain costs a little of the exact filter's efficiency over the first second
of each record (where the exact filter's covariance has not yet settled), not its consistency.

The steady-state predictor itself, the Riccati solution and the likelihood of one record are
:mod:`ident.identification.steady_predictor`.

Longer than 600 lines: the record layout, the concentrated likelihood, the Fisher information
and the damped search all work on one parameter layout and are each short.

References
----------
L. Ljung, *System Identification: Theory for the User*, 2nd ed., Prentice Hall 1999, ch. 7 and 9
(prediction-error methods, closed loop: the direct approach).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from ident.identification.innovations import ReleaseModel, ShapingFilter, block_means, discretise
from ident.identification.results import distinct_wind_speeds
from ident.identification.steady_predictor import (
    PredictorChange,
    SteadyPredictor,
    decorrelated,
    neg_log_likelihood,
)
from ident.identification.uncertainty import nearest_wind_speed
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.numerics.sampling import RATE_RTOL, decimation_factor
from ident.numerics.threads import single_threaded_blas
from ident.records.release import Release

__all__ = ["ClosedLoopFit", "MAX_ITERATIONS", "TARGET_FACTOR", "fit_closed_loop"]

FloatArray = npt.NDArray[np.float64]

#: The records are decimated to at least this many times the highest still-air frequency: the
#: modes and the buffeting force's energy near them stay far inside the pass band, and the
#: likelihood costs a tenth of the full rate's at 500 Hz.
TARGET_FACTOR = 25.0
#: Least sensor-noise std of a channel, as a fraction of the channel's std over its release
#: (at the decimated rate). Lasers measure the motion to a few parts in 10^5 of its range, but
#: the sync view places them against the forces only to a few tenths of a millisecond (0.2 ms
#: is 0.5 % of the motion at 4 Hz): without a floor the likelihood trusted the displacements as
#: exact and fitted that misalignment (the simulated rig: -7.6 % with holds, -91 % without;
#: with the floor +0.6 and -2.7 %, docs/development/e2rfc_turbulence.md). Below the benchmark's own
#: noise.
NOISE_FLOOR = 5e-3
#: Most Fisher-scoring iterations.
MAX_ITERATIONS = 40
#: The search ends when a full Fisher-scoring step would gain less than this in log L (a third
#: of a standard deviation of the likelihood-ratio statistic along the step).
TOLERANCE = 5e-2
#: The search also ends when this many consecutive iterations together gain less than
#: :data:`STALL_TOLERANCE` in log L: along the few directions the data tell only to second
#: order the likelihood is near quartic and Fisher scoring crawls (0.03-1 per iteration).
#: Measured (plate, 1 % turbulence, seed 0): it stops at -6.46 % after 18 iterations, where
#: 40 reach -6.67 % (log L 1.1 higher; a twelfth of the std).
STALLED = 3
STALL_TOLERANCE = 1.0
#: Most increases (x4 each) of the damping in one iteration before the search gives up.
DAMPING_TRIES = 30
#: Relative forward-difference step of the derivatives.
STEP = 1e-6
#: Innovations whose autocorrelation at a lag of 1-20 exceeds this over sqrt(n) are not white
#: (a warning): chance alone stays below about 3.6 / sqrt(n) over 20 lags and 4 channels.
WHITE_LIMIT = 4.0
#: A force channel's innovations whose autocorrelation at a lag of 1-20 exceeds this fail the
#: fit's own check outright (:attr:`ClosedLoopFit.failed_checks`): far beyond chance (about
#: 0.1 for 20 s records). Measured at the maximum on the benchmark's rows (4 seeds each, with
#: holds and without): 0.06-0.18 on the plate and bluff deck in 1-3 % turbulence, with a
#: mismatched spectrum or non-Gaussian gusts; 0.52-0.71 with Coulomb friction (which the model
#: lacks; 6 of 8 searches did not converge either); 0.95 on a rig campaign whose records were
#: decimated by the wrong factor (a rate a rounding short of 500 Hz), fitted at -33 %.
GROSS_WHITENESS = 0.5
#: Start of each later section's zero, as ``tau w`` (:class:`ShapingFilter`): the likelihood
#: is even in it, so it cannot start at 0, where its derivative vanishes.
ZERO_START = 0.5


@dataclass(frozen=True)
class ClosedLoopFit:
    """The closed-loop maximum-likelihood estimate.

    Attributes
    ----------
    model : RationalFunctionModel
        Roger's coefficients and lag roots at the maximum.
    with_A3 : bool
        Whether the added-mass matrix A3 was estimated (else held at zero).
    covariance : ndarray
        Of the ``A`` entries (``parameter_index``) then ``log d``: the inverse Fisher information
        with every nuisance parameter estimated alongside (its Schur complement).
    parameter_index : tuple of (int, int, int)
        ``(k, i, j)`` of each ``A`` entry in ``covariance``.
    shaping : tuple of ShapingFilter
        The buffeting force per wind speed (``wind_speeds``).
    wind_speeds : tuple of float
        The distinct wind speeds, m/s.
    noise_std : ndarray, shape (n_releases, 4)
        Sensor-noise standard deviations at the decimated rate (m, rad, N/m, N m/m).
    neg_log_likelihood : float
        At the maximum.
    iterations : int
    converged : bool
        Whether the search stopped at the maximum (a full step would gain less than
        :data:`TOLERANCE` in log L, or the last :data:`STALLED` steps gained less than
        :data:`STALL_TOLERANCE`).
    fs : float
        The lowest decimated rate of the records, Hz (each record is discretised at its own;
        they differ only when the releases were recorded at different rates).
    whiteness : ndarray, shape (n_records, 4)
        Largest autocorrelation of each record's standardised innovations over lags 1-20, per
        channel (about 2/sqrt(n) if the model is right).
    warnings : tuple of str
    """

    model: RationalFunctionModel
    with_A3: bool
    covariance: FloatArray
    parameter_index: tuple[tuple[int, int, int], ...]
    shaping: tuple[ShapingFilter, ...]
    wind_speeds: tuple[float, ...]
    noise_std: FloatArray
    neg_log_likelihood: float
    iterations: int
    converged: bool
    fs: float
    whiteness: FloatArray
    warnings: tuple[str, ...] = field(default=())

    @property
    def failed_checks(self) -> tuple[str, ...]:
        """What makes this fit untrustworthy beyond its covariance (empty: nothing).

        The search did not converge, or a force channel's innovations are far from white
        (:data:`GROSS_WHITENESS`): the data hold something the model cannot describe, and
        the Fisher covariance, which assumes the model, says nothing of the resulting error.
        """
        failed = []
        if not self.converged:
            failed.append(f"its search did not converge in {self.iterations} iterations")
        worst = float(self.whiteness[:, 2:].max()) if self.whiteness.size else 0.0
        if worst > GROSS_WHITENESS:
            failed.append(f"its force innovations are far from white (autocorrelation "
                          f"{worst:.2f} at a lag of 1-20 samples)")
        return tuple(failed)


@dataclass
class _Record:
    """One record's decimated channels and what it depends on."""

    y: FloatArray          # (n, 4): h, alpha, lift, moment
    fs: float              # decimated rate, Hz
    factor: int            # samples per block mean
    U: float
    rho: float
    group: int             # wind-speed index
    release: int           # release index (its noise parameters)
    held: bool             # a hold: the model does not move


@dataclass
class _Evaluation:
    """-log L and, per record, what the Fisher information needs."""

    nll: float
    e: list[FloatArray]             # concentrated innovations (n, 4)
    S: list[FloatArray]             # their covariance (4, 4)
    columns: list[FloatArray]       # whitened nuisance columns (4 n, 4 + n_x)
    nuisance: list[FloatArray]      # offsets (4) then initial state (n_x)
    predictors: list[SteadyPredictor]  # the base of the Fisher information's differences


class _Layout:
    """Where each parameter sits in the vector ``theta``."""

    def __init__(self, n_dof: int, n_lags: int, with_A3: bool, n_groups: int,
                 n_releases: int, sections: int = 1) -> None:
        terms = ([0, 1, 2] if with_A3 else [0, 1]) + [3 + m for m in range(n_lags)]
        self.index = tuple((k, i, j) for i in range(n_dof) for k in terms for j in range(n_dof))
        self.n_A, self.n_lags, self.n_dof = len(self.index), n_lags, n_dof
        self.n_aero = self.n_A + n_lags
        self.sections = sections
        #: Parameters of a wind speed's shaping filter (:meth:`shaping`).
        self.n_shaping = 3 + 4 * sections + (2 * sections if sections > 1 else 0)
        self.shaping0 = self.n_aero
        self.noise0 = self.shaping0 + self.n_shaping * n_groups
        self.size = self.noise0 + 4 * n_releases
        #: log of each channel's least noise std (:data:`NOISE_FLOOR`; :func:`_noise_floor`).
        self.noise_floor = np.full(4 * n_releases, -np.inf)
        #: log of the least and largest lag root (``d``, reduced; :func:`_log_lag_range`).
        self.log_lag_range = (-math.inf, math.inf)

    def model(self, theta: FloatArray) -> RationalFunctionModel:
        A = np.zeros((3 + self.n_lags, self.n_dof, self.n_dof))
        for value, (k, i, j) in zip(theta[:self.n_A], self.index, strict=True):
            A[k, i, j] = value
        return RationalFunctionModel(A, np.exp(theta[self.n_A:self.n_aero]))

    def shaping(self, theta: FloatArray, group: int) -> ShapingFilter:
        """``[log f (2 S), log zeta (2 S), log L00, L10 / L00, log(L11 / L00), tau w (2 S)]``.

        ``S`` sections per force, lift's first; the zeros (``tau w``, :class:`ShapingFilter`)
        only with more than one section: with one, the likelihood drove a zero to nothing
        (docs/development/e2rfc_turbulence.md). ``L11`` in log: the likelihood depends on its
        square, so it is flat in ``L11`` at 0 (a lift and moment that are one gust's) and
        Fisher scoring would stall there.
        """
        p = theta[self.shaping0 + self.n_shaping * group:
                  self.shaping0 + self.n_shaping * (group + 1)]
        k = 2 * self.sections
        f = np.exp(p[0:k]).reshape(2, self.sections)
        L00 = math.exp(p[2 * k])
        L = [[L00, 0.0], [p[2 * k + 1] * L00, math.exp(p[2 * k + 2]) * L00]]
        zeros = (p[2 * k + 3:3 * k + 3].reshape(2, self.sections) / (2.0 * math.pi * f)
                 if self.sections > 1 else None)
        return ShapingFilter(f, np.exp(p[k:2 * k]).reshape(2, self.sections), L, zeros)

    def step_limits(self, theta: FloatArray) -> FloatArray:
        """Return the largest move of each parameter in one step.

        A factor e in the logarithms and in the lift-moment ratio, half the coefficients' RMS
        (or the entry, if larger) in ``A``.
        """
        limit = np.ones(self.size)
        A = theta[:self.n_A]
        limit[:self.n_A] = np.maximum(0.5 * np.abs(A), 0.5 * math.sqrt(float(np.mean(A**2))))
        return limit

    def bounds(self, theta: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return the lower and upper bounds of the parameters.

        The lag roots within :attr:`log_lag_range` (E2RFC's own: a factor 20 beyond the reduced
        frequencies the releases cover), ``L11 / L00`` at least 1e-4 (its log), each noise at
        least a thousandth of its starting value and at least its :data:`NOISE_FLOOR`; the
        rest unbounded.
        """
        lower, upper = np.full(self.size, -np.inf), np.full(self.size, np.inf)
        lower[self.n_A:self.n_aero], upper[self.n_A:self.n_aero] = self.log_lag_range
        groups = (self.noise0 - self.shaping0) // self.n_shaping
        L11 = 4 * self.sections + 2
        lower[[self.shaping0 + self.n_shaping * g + L11 for g in range(groups)]] = math.log(1e-4)
        lower[self.noise0:] = np.maximum(theta[self.noise0:] - math.log(1e3), self.noise_floor)
        return lower, upper

    def noise(self, theta: FloatArray, release: int) -> FloatArray:
        return np.exp(theta[self.noise0 + 4 * release: self.noise0 + 4 * release + 4])

    def affecting(self, record: _Record) -> list[int]:
        """Return the parameters a record's likelihood depends on."""
        aero = [] if record.held else list(range(self.n_aero))
        shaping = list(range(self.shaping0 + self.n_shaping * record.group,
                             self.shaping0 + self.n_shaping * (record.group + 1)))
        noise = list(range(self.noise0 + 4 * record.release,
                           self.noise0 + 4 * record.release + 4))
        return aero + shaping + noise


@single_threaded_blas
def fit_closed_loop(releases: Sequence[Release], section: SectionModel,
                    start: RationalFunctionModel, *, with_A3: bool = True,
                    n_lags: int | None = None, use_holds: bool = True,
                    window: tuple[float, float] | None = None, shaping_sections: int = 1,
                    exact_block_means: bool = False) -> ClosedLoopFit:
    """Maximise the likelihood of every release (and hold) together, from ``start``.

    Parameters
    ----------
    releases : sequence of Release
        Two-degree-of-freedom releases in turbulence at two or more wind speeds; a hold before a
        release is used as extra data when ``use_holds``.
    section : SectionModel
        The structure (two degrees of freedom).
    start : RationalFunctionModel
        The starting estimate (E2RFC's or the refined-IV branch's); its structure (number of
        lags) is kept.
    with_A3 : bool, optional
        Estimate the added-mass matrix A3 (else it is held at zero).
    n_lags : int, optional
        Number of lags; default ``start``'s. Lags ``start`` lacks start with zero coefficients
        and roots spread over 0.1-1 (the reduced frequencies of section-model tests); lags it
        has beyond ``n_lags`` are dropped.
    use_holds : bool, optional
        Use the holds' records.
    window : (float, float), optional
        Use only the samples of each release with ``t0 <= t < t1`` (s from the release): the
        decay alone (``(0, 5)``) or the random response alone (``(10, inf)``), to measure what
        each part tells. Default: all of them.
    shaping_sections : int, optional
        Second-order sections per force of the buffeting's shaping filter
        (:class:`ShapingFilter`): 1 (default) or more.
    exact_block_means : bool, optional
        Model the decimated records as the block means they are (:func:`block_means`) rather
        than as samples of the state. Measured on a flat plate with the estimator's own model
        class at the benchmark's buffeting level (8 releases per speed): samples +2.6 to +10.6 %
        on six seeds, exact block means both sides of the truth. On von Karman buffeting
        with one section it found spurious maxima; with two it did not
        (docs/development/e2rfc_turbulence.md). Default False.

    Returns
    -------
    ClosedLoopFit

    Raises
    ------
    ValueError
        On a 3-DOF section or releases, fewer than two wind speeds, or a start at which the
        likelihood cannot be evaluated (no stabilising Riccati solution). (A :class:`Release`
        holds no NaN: it refuses them itself.) Releases may be sampled at different rates: each
        record is discretised at its own.
    """
    if section.n_dof != 2 or any(r.n_dof != 2 for r in releases):
        raise ValueError("the closed-loop estimator is for two degrees of freedom (heave, pitch)")
    speeds = distinct_wind_speeds([r.U for r in releases])
    if len(speeds) < 2:
        raise ValueError("the closed-loop estimator needs releases at two or more wind speeds")
    f_max = max(section.fh, section.fa)
    records = _records(releases, section, speeds, f_max, use_holds, window)
    start = _with_lags(start, start.n_lags if n_lags is None else n_lags)
    if not isinstance(shaping_sections, int) or shaping_sections < 1:
        raise ValueError(f"shaping_sections must be an integer >= 1, got {shaping_sections!r}")
    layout = _Layout(2, start.n_lags, with_A3, len(speeds), len(releases), shaping_sections)
    layout.noise_floor = _noise_floor(records, len(releases))
    layout.log_lag_range = _log_lag_range(section, speeds)
    objective = _Objective(records, section, layout, exact_block_means)
    theta = _initial(records, layout, start, section, f_max)
    current = objective.evaluate(theta)
    if not math.isfinite(current.nll):
        raise ValueError("the likelihood cannot be evaluated at the start (no stabilising "
                         "Riccati solution at a release's wind speed): start from another "
                         "estimate")
    theta, current, F, iterations, converged = _maximise(objective, layout, theta, current)
    covariance = _inverse(F)[:layout.n_aero, :layout.n_aero]
    warnings = []
    if not converged:
        warnings.append(f"the likelihood search stopped after {iterations} iterations without "
                        "converging: the estimate and its covariance are approximate")
    whiteness = objective.whiteness(current)
    bound = WHITE_LIMIT / math.sqrt(min(r.y.shape[0] for r in records))
    if np.any(whiteness > bound):
        warnings.append(
            f"the innovations of {int(np.sum(np.any(whiteness > bound, axis=1)))} of "
            f"{len(records)} records are not white (largest autocorrelation at lags 1-20 "
            f"{float(whiteness.max()):.2f}, chance stays below {bound:.2f}): the buffeting "
            f"model ({shaping_sections} second-order section(s) per force) or the aerodynamic "
            "one misses part of the data; the Fisher covariance may understate the error")
    return ClosedLoopFit(
        model=layout.model(theta), with_A3=with_A3, covariance=covariance,
        parameter_index=layout.index,
        shaping=tuple(layout.shaping(theta, g) for g in range(len(speeds))),
        wind_speeds=tuple(speeds),
        noise_std=np.array([layout.noise(theta, r) for r in range(len(releases))]),
        neg_log_likelihood=current.nll, iterations=iterations, converged=converged,
        fs=min(record.fs for record in records),
        whiteness=whiteness, warnings=tuple(warnings))


def _maximise(objective: _Objective, layout: _Layout, theta: FloatArray, current: _Evaluation
              ) -> tuple[FloatArray, _Evaluation, FloatArray, int, bool]:
    """Fisher scoring with Levenberg-Marquardt damping, bounds and per-parameter step limits.

    Returns the maximum, its evaluation, the Fisher information there, the iterations and
    whether the search converged.
    """
    limit = layout.step_limits(theta)
    lower, upper = layout.bounds(theta)
    lam, converged, iterations = 1e-3, False, 0
    gains: list[float] = []
    F_at: FloatArray | None = None  # theta at which F was computed
    for iterations in range(1, MAX_ITERATIONS + 1):  # noqa: B007 - returned
        F, g = objective.information(theta, current)
        F_at = theta
        # Parameters held at a bound by a gradient that pushes them beyond it are left out of
        # the step (an active set): a moment that is one gust's with the lift (L11 -> 0)
        # would otherwise stall every step.
        free = ~(((theta <= lower + 1e-9) & (g > 0.0)) | ((theta >= upper - 1e-9) & (g < 0.0)))
        Ff, gf = F[np.ix_(free, free)], g[free]
        scale = np.sqrt(np.maximum(np.diag(Ff), 1e-300))
        Fs, gs = Ff / np.outer(scale, scale), gf / scale
        # The Newton decrement g^T F^-1 g / 2 is what a full step could still gain in log L.
        if 0.5 * float(gs @ np.linalg.lstsq(Fs, gs, rcond=1e-12)[0]) < TOLERANCE:
            converged = True
            break
        for _ in range(DAMPING_TRIES):
            step = np.zeros(layout.size)
            step[free] = -np.linalg.solve(Fs + lam * np.eye(gs.size), gs) / scale
            # No parameter moves more than its limit in one step, nor beyond its bounds.
            trial_theta = np.clip(theta + np.clip(step, -limit, limit), lower, upper)
            trial = objective.evaluate(trial_theta)
            if trial.nll < current.nll:
                break
            lam *= 4.0
        else:
            break  # no step along the gradient decreases -log L: at the maximum, or lost
        gains.append(current.nll - trial.nll)
        theta, current = trial_theta, trial
        lam = max(lam / 3.0, 1e-6)
        if len(gains) >= STALLED and sum(gains[-STALLED:]) < STALL_TOLERANCE:
            # Where the likelihood is not quadratic the Fisher-predicted gain can stay above
            # what the steps realise: the maximum is reached when log L stops moving.
            converged = True
            break
    if F_at is not theta:
        F, _ = objective.information(theta, current)
    return theta, current, F, iterations, converged


def _with_lags(model: RationalFunctionModel, n_lags: int) -> RationalFunctionModel:
    """``model`` with ``n_lags`` lags: missing ones added with zero coefficients."""
    if n_lags == model.n_lags:
        return model
    A = np.zeros((3 + n_lags, 2, 2))
    keep = min(n_lags, model.n_lags)
    A[:3 + keep] = model.A[:3 + keep, :2, :2]
    spread = np.geomspace(0.1, 1.0, n_lags) if n_lags else np.zeros(0)
    d = np.concatenate([model.d[:keep], spread[keep:]])
    return RationalFunctionModel(A, d)


def _factor(fs: float, f_max: float) -> int:
    """Decimation factor: the rate stays at least TARGET_FACTOR times ``f_max``."""
    return decimation_factor(fs, TARGET_FACTOR * f_max)


def _decimate(y: FloatArray, factor: int) -> FloatArray:
    """Means of consecutive blocks of ``factor`` samples.

    Block means of white sensor noise stay white (a low-pass filter would colour it near the
    new Nyquist frequency, which the model's white sensor noise cannot follow); on the signals
    they act as a delay of half a block, the same on every channel, and a gain within 0.3 % of
    one at the still-air modes (a block is at most 1/:data:`TARGET_FACTOR` of their periods).
    """
    n = y.shape[0] // factor
    return np.asarray(y[: n * factor].reshape(n, factor, y.shape[1]).mean(axis=1), dtype=float)


def _records(releases: Sequence[Release], section: SectionModel, speeds: list[float],
             f_max: float, use_holds: bool, window: tuple[float, float] | None = None
             ) -> list[_Record]:
    """Decimated records of every release (within ``window``) and (when used) hold.

    Each record keeps its own decimated rate (releases may be recorded at different rates);
    rates within :data:`~ident.numerics.sampling.RATE_RTOL` of one already seen are taken as
    that one, so that records whose time stamps differ by rounding share one discretisation.
    """
    records: list[_Record] = []
    rates: list[float] = []
    for index, r in enumerate(releases):
        group = nearest_wind_speed(r.U, speeds)
        rho = section.rho if r.rho is None else r.rho
        factor = _factor(r.fs, f_max)
        fs = r.fs / factor
        fs = next((seen for seen in rates if abs(fs - seen) <= RATE_RTOL * seen), fs)
        rates.append(fs)
        y = np.column_stack([r.h, r.alpha, r.lift, r.moment])
        if window is not None:
            y = y[(r.t >= window[0]) & (r.t < window[1])]
            if y.shape[0] < 50 * factor:
                raise ValueError(f"the window {window} s leaves {y.shape[0]} samples of a "
                                 f"release; at least {50 * factor} are needed")
        records.append(_Record(_decimate(y, factor), fs, factor, r.U, rho, group, index,
                               False))
        if use_holds and r.hold is not None and r.hold.t.size > 50 * factor:
            hold = np.column_stack([r.hold.h, r.hold.alpha, r.hold.lift, r.hold.moment])
            records.append(_Record(_decimate(hold, factor), fs, factor, r.U, rho, group, index,
                                   True))
    return records


def _log_lag_range(section: SectionModel, speeds: list[float]) -> tuple[float, float]:
    """Return the log of E2RFC's range of lag roots: 20 times beyond the reduced frequencies.

    The still-air frequencies at the highest and lowest wind speed bound the reduced
    frequencies ``K = 2 pi f B / U``. Far outside them a lag is a constant or a derivative term
    that the other coefficients already hold; a fit sent there (a root of 175 where the data
    cover 0.3-1.6, friction in 1 % turbulence) had a stiff state that made its Fisher
    information meaningless (a flutter-speed std of 0.004 %).
    """
    f = [section.fh, section.fa]
    K_lo = 2.0 * math.pi * min(f) * section.B / max(speeds)
    K_hi = 2.0 * math.pi * max(f) * section.B / min(speeds)
    return math.log(K_lo / 20.0), math.log(20.0 * K_hi)


def _noise_floor(records: list[_Record], n_releases: int) -> FloatArray:
    """Return the log of each release's least channel noise std (:data:`NOISE_FLOOR`)."""
    floor = np.empty(4 * n_releases)
    for r in range(n_releases):
        released = np.vstack([rec.y for rec in records if rec.release == r and not rec.held])
        floor[4 * r: 4 * r + 4] = np.log(np.maximum(NOISE_FLOOR * np.std(released, axis=0),
                                                    1e-300))
    return floor


def _initial(records: list[_Record], layout: _Layout, start: RationalFunctionModel,
             section: SectionModel, f_max: float) -> FloatArray:
    """Return the start: ``start``'s coefficients, shaping and noise from the records."""
    theta = np.zeros(layout.size)
    A = start.A
    theta[:layout.n_A] = [A[k, i, j] if k < A.shape[0] else 0.0 for k, i, j in layout.index]
    theta[layout.n_A:layout.n_aero] = np.log(np.maximum(start.d, 1e-6))
    n_groups = 1 + max(rec.group for rec in records)
    for r in range(1 + max(rec.release for rec in records)):
        own = [rec for rec in records if rec.release == r]
        y = np.vstack([rec.y for rec in own])
        # Noise from third differences (the signals' part is small at 25 x f_max).
        d3 = np.diff(np.vstack([rec.y for rec in own if not rec.held]), n=3, axis=0)
        std = np.std(d3, axis=0) / math.sqrt(20.0)
        theta[layout.noise0 + 4 * r: layout.noise0 + 4 * r + 4] = np.maximum(np.log(
            np.maximum(std, 1e-12 * np.maximum(np.std(y, axis=0), 1e-300))),
            layout.noise_floor[4 * r: 4 * r + 4])
    for g in range(n_groups):
        own = [rec for rec in records if rec.group == g]
        # The buffeting force's level and bandwidth from a hold (force alone) or else the
        # second half of the releases (mostly random response).
        pieces = ([rec.y for rec in own if rec.held]
                  or [rec.y[rec.y.shape[0] // 2:] for rec in own])
        force = np.vstack([p - p.mean(axis=0) for p in pieces])[:, 2:] * [section.B, 1.0]
        fs = float(np.mean([rec.fs for rec in own]))  # a start: rates differ by little if at all
        rate = np.std(np.diff(force, axis=0), axis=0) * fs / np.maximum(
            np.std(force, axis=0), 1e-300)
        fc = np.clip(rate / (2.0 * math.pi), 0.5 * f_max, 5.0 * f_max)
        # Later sections an octave apart above the first, each with a zero an octave above
        # its own natural frequency.
        S = layout.sections
        f = fc[:, None] * 2.0 ** np.arange(S)[None, :]
        zeros = ZERO_START / (2.0 * math.pi * f) if S > 1 else None
        base = ShapingFilter(f, np.full((2, S), 0.7), np.eye(2), zeros)
        P = base.stationary_covariance()
        _, _, C_b = base.matrices()
        unit = np.sqrt(np.diag(C_b @ P @ C_b.T))
        cov = np.cov(force.T) / np.outer(unit, unit)
        L = np.linalg.cholesky(cov + 1e-9 * np.trace(cov) * np.eye(2))
        p0, k = layout.shaping0 + layout.n_shaping * g, 2 * S
        theta[p0:p0 + k] = np.log(f).ravel()
        theta[p0 + k:p0 + 2 * k] = math.log(0.7)
        theta[p0 + 2 * k] = math.log(L[0, 0])
        theta[p0 + 2 * k + 1] = L[1, 0] / L[0, 0]
        theta[p0 + 2 * k + 2] = math.log(max(L[1, 1] / L[0, 0], 1e-3))
        if S > 1:
            theta[p0 + 2 * k + 3:p0 + 3 * k + 3] = ZERO_START
    return theta


class _Objective:
    """-log L of every record and its Fisher information, by forward differences."""

    def __init__(self, records: list[_Record], section: SectionModel, layout: _Layout,
                 exact_block_means: bool = False) -> None:
        self.records, self.section, self.layout = records, section, layout
        self.exact_block_means = exact_block_means
        self._dynamics: dict[tuple[int, float, float, float, int, bool, bytes],
                             tuple[FloatArray, ...]] = {}

    def matrices(self, theta: FloatArray, record: _Record
                 ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """Return ``(Phi, Qd, C, R, feedthrough)`` of one record's block means at ``theta``.

        The model of the block means (:func:`block_means`), decorrelated
        (:func:`decorrelated`): what :class:`SteadyPredictor` takes.
        """
        layout = self.layout
        noise = layout.noise(theta, record.release)
        # The releases at one speed share the dynamics (their noise differs): build once.
        key = (record.group, record.U, record.rho, record.fs, record.factor, record.held,
               theta[:layout.noise0].tobytes())
        if key not in self._dynamics:
            shaping = layout.shaping(theta, record.group)
            # Block means as samples: the model at the decimated rate, one sample per block.
            factor = record.factor if self.exact_block_means else 1
            fine = record.fs * factor
            if record.held:
                Phi, Qd, C = _hold_matrices(shaping, self.section.B, fine)
            else:
                m = ReleaseModel(self.section, layout.model(theta), record.U, fine, shaping,
                                 noise, rho=record.rho)
                Phi, Qd, C = m.Phi, m.Qd, m.C
            self._dynamics[key] = block_means(Phi, Qd, C, factor)
        Phi, Qd, H, R_eta, M = self._dynamics[key]
        R = R_eta + np.diag(noise**2)
        Phi_u, Qd_u, gain = decorrelated(Phi, Qd, H, R, M)
        return Phi_u, Qd_u, H, R, gain

    def predictor(self, theta: FloatArray, record: _Record) -> SteadyPredictor:
        """Return the steady-state predictor of one record's model at ``theta`` (or raise)."""
        Phi, Qd, C, R, gain = self.matrices(theta, record)
        return SteadyPredictor(Phi, Qd, C, R, feedthrough=gain)

    def evaluate(self, theta: FloatArray) -> _Evaluation:
        """-log L with each record's offsets and initial state concentrated out."""
        self._dynamics.clear()
        out = _Evaluation(0.0, [], [], [], [], [])
        for record in self.records:
            try:
                predictor = self.predictor(theta, record)
                e, columns, nuisance = predictor.concentrated(record.y)
            except (ValueError, np.linalg.LinAlgError):  # no stable predictor: not a maximum
                return _Evaluation(math.inf, [], [], [], [], [])
            out.e.append(e)
            out.S.append(predictor.S)
            out.columns.append(columns)
            out.nuisance.append(nuisance)
            out.predictors.append(predictor)
            out.nll += neg_log_likelihood(e, predictor.S)
        return out

    def information(self, theta: FloatArray, at: _Evaluation
                    ) -> tuple[FloatArray, FloatArray]:
        """Fisher information of ``theta`` (the nuisance estimated alongside) and the gradient.

        The derivatives hold each record's offsets and initial state at their concentrated
        values; their own information is then taken out by projecting the innovations'
        derivatives off the nuisance columns (the Schur complement).
        """
        n = self.layout.size
        F, g = np.zeros((n, n)), np.zeros(n)
        self._dynamics.clear()
        for r, record in enumerate(self.records):
            e, S, nuisance = at.e[r], at.S[r], at.nuisance[r]
            base = at.predictors[r]
            W = np.linalg.inv(np.linalg.cholesky(S))
            Q, _ = np.linalg.qr(at.columns[r])
            params = self.layout.affecting(record)
            changes, steps = [], np.empty(len(params))
            for row, p in enumerate(params):
                h = STEP * max(1.0, abs(theta[p]))
                shifted = theta.copy()
                shifted[p] += h
                try:
                    change = self._change(base, shifted, record)
                except ValueError:  # at the edge of the models: a backward difference
                    h, shifted[p] = -h, theta[p] - h
                    change = self._change(base, shifted, record)
                changes.append(change)
                steps[row] = h
            de = base.innovation_changes(record.y, nuisance, changes) / steps[:, None, None]
            D = (de @ W.T).reshape(len(params), e.size)
            Sw = np.stack([W @ ((c.S - S) / h) @ W.T for c, h in zip(changes, steps,
                                                                      strict=True)])
            D_perp = D - (D @ Q) @ Q.T
            n_k = e.shape[0]
            idx = np.array(params)
            F[np.ix_(idx, idx)] += (D_perp @ D_perp.T
                                    + 0.5 * n_k * np.einsum("iab,jba->ij", Sw, Sw))
            ew = (e @ W.T).ravel()
            Ew = W @ (e.T @ e) @ W.T
            g[idx] += (D @ ew + 0.5 * n_k * np.einsum("iaa->i", Sw)
                       - 0.5 * np.einsum("iab,ba->i", Sw, Ew))
        return F, g

    def _change(self, base: SteadyPredictor, theta: FloatArray, record: _Record
                ) -> PredictorChange:
        """Return the predictor's change from ``base`` at ``theta`` (first order)."""
        Phi, Qd, C, R, gain = self.matrices(theta, record)
        return base.change(Phi, Qd, C, R, feedthrough=gain)

    def whiteness(self, at: _Evaluation) -> FloatArray:
        """Largest autocorrelation of each record's standardised innovations, lags 1-20."""
        out = []
        for e, S in zip(at.e, at.S, strict=True):
            u = e @ np.linalg.inv(np.linalg.cholesky(S)).T
            u = u - u.mean(axis=0)
            acf = [np.abs(np.sum(u[lag:] * u[:-lag], axis=0) / np.sum(u * u, axis=0))
                   for lag in range(1, 21)]
            out.append(np.max(acf, axis=0))
        return np.array(out)


def _hold_matrices(shaping: ShapingFilter, B: float, fs: float
                   ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Return ``(Phi, Qd, C)`` of a hold at ``fs``: the buffeting alone on the force channels."""
    A_b, B_b, C_b = shaping.matrices()
    Phi, Qd = discretise(A_b, B_b, 1.0 / fs)
    C = np.zeros((4, A_b.shape[0]))
    C[2], C[3] = C_b[0] / B, C_b[1]
    return Phi, Qd, C


def _inverse(F: FloatArray) -> FloatArray:
    """Inverse of the information, scaled; directions the data do not inform are dropped."""
    scale = np.sqrt(np.maximum(np.diag(F), 1e-300))
    inv = np.linalg.pinv(F / np.outer(scale, scale), rcond=1e-12, hermitian=True)
    return np.asarray(inv / np.outer(scale, scale), dtype=float)
