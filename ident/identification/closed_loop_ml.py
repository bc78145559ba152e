"""Closed-loop maximum likelihood of the self-excited forces from releases in turbulence.

In turbulent flow the buffeting force drives the motion that the self-excited force answers: a
closed loop. A direct prediction-error method uses all of the excitation's information there,
the release's decay and the random response alike. This module maximises the exact-form
Gaussian likelihood of every release at every wind speed together, over

- Roger's coefficients ``A_k`` and lag roots ``d_l``, shared across speeds through the reduced
  frequency (:class:`~ident.model.rfc.RationalFunctionModel`);
- per wind speed, the buffeting force as white noise through a second-order shaping filter per
  force (or several in cascade, ``shaping_sections``) with the lift-moment correlation
  (:class:`~ident.identification.innovations.ShapingFilter`); or one filter for every speed,
  scaled to each as buffeting scales with the speed (``shared_buffeting``);
- per release, the channels' sensor-noise standard deviations (four; six with sway);
- per record, concentrated out by generalised least squares: the channels' constant offsets
  (mean wind load, static deflection, zero drift) and the initial state, but for a release's
  lag states, which are zero at the release (it starts from rest).

A hold before a release (the model held in the wind) adds its record as extra data: the force
channels see the buffeting alone there, the displacement channels only noise. It is used when
present, never required.

The model per release is :class:`~ident.identification.innovations.ReleaseModel` on the record
averaged over blocks to about 25 times (``TARGET_FACTOR``) the highest still-air frequency; the
block means are taken as samples of the state, or (``exact_block_means``) modelled as the means
they are (:func:`~ident.identification.innovations.block_means`), whose output noise is then
correlated with the process noise (:func:`~ident.identification.steady_predictor.decorrelated`). The
likelihood is that of the steady-state Kalman predictor ``x_{k+1} = Phi x_k + K_p (y_k - C x_k)``,
``K_p = Phi P C^T S^-1`` with ``P`` from the discrete Riccati equation (:func:`riccati`): with
the innovations ``e_k`` and their covariance ``S``,

    -log L = sum_records [ n/2 (n_y log 2 pi + log det S) + 1/2 sum_k e_k^T S^-1 e_k ]

with ``n_y`` channels (four; six with sway).

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

At the maximum the innovations are checked for whiteness, each record's alone and all records
pooled (:mod:`ident.identification.innovation_checks`, with the power of every record
together): innovations that are not white mean a model that misses part of the data (a warning
says which channels).

The steady-state predictor itself, the Riccati solution and the likelihood of one record are
:mod:`ident.identification.steady_predictor`.

The records it fits, the parameter vector's layout and the search's start are
:mod:`ident.identification._closed_loop_parameters`.

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

from ident.identification import _closed_loop_parameters as setup
from ident.identification._closed_loop_parameters import Layout, Record
from ident.identification.channels import coordinate_scales, force_channels
from ident.identification.innovation_checks import pooled_portmanteau, portmanteau_warning
from ident.identification.innovations import ReleaseModel, ShapingFilter, block_means, discretise
from ident.identification.results import distinct_wind_speeds
from ident.identification.steady_predictor import (
    SteadyPredictor,
    decorrelated,
    neg_log_likelihood,
)
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.numerics.threads import single_threaded_blas
from ident.records.release import Release

__all__ = ["ClosedLoopFit", "MAX_ITERATIONS", "fit_closed_loop"]

FloatArray = npt.NDArray[np.float64]

#: Most Fisher-scoring iterations. With one buffeting filter shared by the speeds the search
#: took 12-24 on the bluff deck's and plate's rows, but 49 on the plate under a Davenport
#: admittance (seed 0; 25 with a filter per speed), where 40 had stopped it unconverged.
MAX_ITERATIONS = 60
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
    shaping_exponents : (float, float) or None
        With one buffeting filter shared by the speeds (``shared_buffeting``), the fitted
        exponents of the wind speed in its frequencies and its white-noise level
        (quasi-steady buffeting in gusts of fixed intensity and scale: 1 and 1.5); else None.
    wind_speeds : tuple of float
        The distinct wind speeds, m/s.
    noise_std : ndarray, shape (n_releases, n_y)
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
    whiteness : ndarray, shape (n_records, n_y)
        Largest autocorrelation of each record's standardised innovations over lags 1-20, per
        channel (about 2/sqrt(n) if the model is right).
    n_parameters : int
        Parameters estimated whose information grows with the records' length: those searched
        and each record's concentrated offsets.
    n_initial_states : int
        The concentrated initial states' entries, every record's together (a release's lag
        states, known to be zero, are not among them): their information is that of the
        first samples after the release, whatever the length.
    n_samples : int
        Scalar samples of every record together (block means times channels).
    portmanteau : ndarray, shape (n_y,)
        Per channel, ``N sum_l rho_l^2`` over lags ``l`` of 1-20, with ``rho_l`` the
        autocorrelation of the standardised innovations pooled over every record and ``N``
        their number of samples (``innovation_checks.pooled_portmanteau``): chi-square with
        20 degrees of freedom if the model is right (a little less, for the parameters
        fitted). Pooled, it has the power of all the records together, where each record's
        :attr:`whiteness` has the power of one.
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
    portmanteau: FloatArray
    n_parameters: int
    n_initial_states: int
    n_samples: int
    warnings: tuple[str, ...] = field(default=())
    shaping_exponents: tuple[float, float] | None = None

    @property
    def schwarz(self) -> float:
        """Schwarz's criterion in log-likelihood units (lower: the model the evidence favours).

        ``-log L + n_parameters ln(n_samples) / 2 + n_initial_states``. Schwarz's ``ln N / 2``
        per parameter is the Laplace approximation of the evidence for parameters whose
        information grows with the samples; an initial state's does not (the first samples
        after the release tell it), and its share of the approximation stays of order one:
        one per entry, Akaike's. Counted at ``ln N / 2`` too, the eight-release plate's 48
        records would charge the fourth-order model's four more states per record 1200 in
        log L and refuse the model its innovations ask for (measured: 693 higher in log L).
        """
        return (self.neg_log_likelihood + 0.5 * self.n_parameters * math.log(self.n_samples)
                + self.n_initial_states)

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
        forces = force_channels(self.whiteness.shape[1] // 2)
        worst = float(self.whiteness[:, forces].max()) if self.whiteness.size else 0.0
        if worst > GROSS_WHITENESS:
            failed.append(f"its force innovations are far from white (autocorrelation "
                          f"{worst:.2f} at a lag of 1-20 samples)")
        return tuple(failed)


@dataclass
class _Evaluation:
    """-log L and, per record, what the Fisher information needs."""

    nll: float
    e: list[FloatArray]             # concentrated innovations (n, 4)
    S: list[FloatArray]             # their covariance (4, 4)
    columns: list[FloatArray]       # whitened nuisance columns (4 n, 4 + n_x)
    nuisance: list[FloatArray]      # offsets (4) then initial state (n_x)
    predictors: list[SteadyPredictor]  # the base of the Fisher information's differences


@single_threaded_blas
def fit_closed_loop(releases: Sequence[Release], section: SectionModel,
                    start: RationalFunctionModel, *, with_A3: bool = True,
                    n_lags: int | None = None, use_holds: bool = True,
                    window: tuple[float, float] | None = None, shaping_sections: int = 1,
                    exact_block_means: bool = False, shared_buffeting: bool = False,
                    mixed_buffeting: bool = False,
                    nuisance_from: tuple[ClosedLoopFit, Sequence[int]] | None = None
                    ) -> ClosedLoopFit:
    """Maximise the likelihood of every release (and hold) together, from ``start``.

    Parameters
    ----------
    releases : sequence of Release
        Releases in turbulence at two or more wind speeds, of the section's degrees of
        freedom (with sway, the sway and drag channels join the four); a hold before a
        release is used as extra data when ``use_holds``.
    section : SectionModel
        The structure (two or three degrees of freedom).
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
    shared_buffeting : bool, optional
        One shaping filter for every wind speed, scaled to each as buffeting scales in gusts
        of a fixed intensity and integral scale: its frequencies as ``U^a`` and its
        white-noise level as ``rho U^b``, both exponents fitted (quasi-steady: 1 and 1.5).
        A filter per speed (default False) has three times the buffeting parameters with
        three speeds, each told by that speed's releases alone.
    mixed_buffeting : bool, optional
        Independent sources, each through its own sections, mixed into the forces
        (:class:`ShapingFilter`'s ``mixed_after``): gusts with spectra of their own, as
        along-wind and vertical ones are. Default False: each force filtered of mixed white
        noise.
    nuisance_from : (ClosedLoopFit, sequence of int), optional
        A fit of a superset of ``releases`` with the same buffeting model, and the index there
        of each release here: its shaping filters (by wind speed) and noise stds (by release)
        start this fit's, instead of the records' own statistics. For a refit of part of the
        data (the extrapolation part's, without the top speed): the same maximum in fewer
        steps.

    Returns
    -------
    ClosedLoopFit

    Raises
    ------
    ValueError
        On releases whose degrees of freedom are not the section's, fewer than two wind
        speeds, or a start at which the likelihood cannot be evaluated (no stabilising Riccati
        solution). (A :class:`Release` holds no NaN: it refuses them itself.) Releases may be
        sampled at different rates: each record is discretised at its own.
    """
    if any(r.n_dof != section.n_dof for r in releases):
        raise ValueError(f"the releases and the section differ in their degrees of freedom "
                         f"(the section has {section.n_dof}; a release with sway carries p and "
                         "drag)")
    speeds = distinct_wind_speeds([r.U for r in releases])
    if len(speeds) < 2:
        raise ValueError("the closed-loop estimator needs releases at two or more wind speeds")
    f_max = max(section.fh, section.fa, section.fp or 0.0)
    records = setup.records(releases, section, speeds, f_max, use_holds, window)
    start = setup.with_lags(start, start.n_lags if n_lags is None else n_lags)
    if not isinstance(shaping_sections, int) or shaping_sections < 1:
        raise ValueError(f"shaping_sections must be an integer >= 1, got {shaping_sections!r}")
    scaled = None
    if shared_buffeting:
        U_ref = math.exp(float(np.mean(np.log(speeds))))
        rho = [np.mean([rec.rho for rec in records if rec.group == g])
               for g in range(len(speeds))]
        scaled = np.column_stack([np.log(np.asarray(speeds) / U_ref),
                                  np.log(np.asarray(rho) / section.rho)])
    layout = Layout(section.n_dof, start.n_lags, with_A3, len(speeds), len(releases),
                    shaping_sections, scaled, mixed_buffeting)
    layout.noise_floor = setup.noise_floor(records, len(releases))
    layout.log_lag_range = setup.log_lag_range(section, speeds)
    objective = _Objective(records, section, layout, exact_block_means)
    theta = setup.initial(records, layout, start, section, f_max)
    if nuisance_from is not None:
        other, index = nuisance_from
        setup.warm_nuisance(theta, layout, speeds, list(zip(other.wind_speeds, other.shaping,
                                                            strict=True)),
                            [other.noise_std[i] for i in index], other.shaping_exponents)
    current = objective.evaluate(theta)
    if not math.isfinite(current.nll):
        raise ValueError("the likelihood cannot be evaluated at the start (no stabilising "
                         "Riccati solution at a release's wind speed): start from another "
                         "estimate")
    theta, current, F, iterations, converged = _maximise(objective, layout, theta, current)
    inverse = _inverse(F)
    covariance = inverse[:layout.n_aero, :layout.n_aero]
    warnings = []
    exponents = None
    if layout.exponents is not None:
        a, b = (float(v) for v in theta[layout.exponents])
        exponents = (a, b)
        std = np.sqrt(np.maximum(np.diag(inverse)[layout.exponents], 0.0))
        if shaping_sections >= 2:  # one section's exponents absorb its shape misfit
            warnings.extend(setup.exponent_warning(exponents, (float(std[0]), float(std[1]))))
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
            f"model ({shaping_sections} second-order section(s) per "
            f"{'source' if mixed_buffeting else 'force'}) or the aerodynamic "
            "one misses part of the data; the Fisher covariance may understate the error")
    portmanteau = pooled_portmanteau(current.e, current.S)
    warnings.extend(portmanteau_warning(portmanteau, len(records), shaping_sections,
                                        n_holds=sum(r.held for r in records)))
    return ClosedLoopFit(
        model=layout.model(theta), with_A3=with_A3, covariance=covariance,
        parameter_index=layout.index,
        shaping=tuple(layout.shaping(theta, g) for g in range(len(speeds))),
        wind_speeds=tuple(speeds),
        noise_std=np.array([layout.noise(theta, r) for r in range(len(releases))]),
        neg_log_likelihood=current.nll, iterations=iterations, converged=converged,
        fs=min(record.fs for record in records),
        whiteness=whiteness, portmanteau=portmanteau,
        n_parameters=layout.size + layout.n_y * len(records),
        n_initial_states=sum(c.shape[1] - layout.n_y for c in current.columns),
        n_samples=sum(record.y.size for record in records), warnings=tuple(warnings),
        shaping_exponents=exponents)


def _maximise(objective: _Objective, layout: Layout, theta: FloatArray, current: _Evaluation
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


class _Objective:
    """-log L of every record and its Fisher information (derivatives to first order)."""

    def __init__(self, records: list[Record], section: SectionModel, layout: Layout,
                 exact_block_means: bool = False) -> None:
        self.records, self.section, self.layout = records, section, layout
        self.exact_block_means = exact_block_means
        self._dynamics: dict[tuple[int, float, float, float, int, bool, bytes],
                             tuple[FloatArray, ...]] = {}

    def matrices(self, theta: FloatArray, record: Record
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

    def predictor(self, theta: FloatArray, record: Record) -> SteadyPredictor:
        """Return the steady-state predictor of one record's model at ``theta`` (or raise)."""
        Phi, Qd, C, R, gain = self.matrices(theta, record)
        return SteadyPredictor(Phi, Qd, C, R, feedthrough=gain)

    def at_zero(self, record: Record) -> range:
        """Entries of a record's initial state known to be zero: a release's lag states.

        The state is ``[q, q', lag states, buffeting]`` (:class:`ReleaseModel`); a release from
        rest has its lag states at zero (:class:`~ident.records.release.Release`), which
        concentrating them out would leave to the record to tell.
        """
        if record.held or not record.from_rest:
            return range(0)
        n_dof = self.layout.n_dof
        return range(2 * n_dof, 2 * n_dof + n_dof * self.layout.n_lags)

    def evaluate(self, theta: FloatArray) -> _Evaluation:
        """-log L with each record's offsets and initial state concentrated out."""
        self._dynamics.clear()
        out = _Evaluation(0.0, [], [], [], [], [])
        for record in self.records:
            # A trial step far out (a search from a wild start) can make the block transition
            # or the Riccati solution overflow: that is no maximum either, not a warning.
            try:
                with np.errstate(over="raise", invalid="raise"):
                    predictor = self.predictor(theta, record)
                    e, columns, nuisance = predictor.concentrated(record.y, self.at_zero(record))
            except (ValueError, FloatingPointError, np.linalg.LinAlgError):
                return _Evaluation(math.inf, [], [], [], [], [])  # no stable predictor
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
            nearby, steps = [], np.empty(len(params))
            for row, p in enumerate(params):
                h = STEP * max(1.0, abs(theta[p]))
                shifted = theta.copy()
                shifted[p] += h
                try:
                    perturbed = self.matrices(shifted, record)
                except ValueError:  # at the edge of the models: a backward difference
                    h, shifted[p] = -h, theta[p] - h
                    perturbed = self.matrices(shifted, record)
                nearby.append(perturbed)
                steps[row] = h
            # The predictor's change for every perturbed model at once, to first order.
            changes = base.changes(*(np.stack(part) for part in zip(*nearby, strict=True)))
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
    n_f = C_b.shape[0]
    C = np.zeros((2 * n_f, A_b.shape[0]))
    C[force_channels(n_f)] = C_b / coordinate_scales(n_f, B)[:, None]
    return Phi, Qd, C


def _inverse(F: FloatArray) -> FloatArray:
    """Inverse of the information, scaled; directions the data do not inform are dropped."""
    scale = np.sqrt(np.maximum(np.diag(F), 1e-300))
    inv = np.linalg.pinv(F / np.outer(scale, scale), rcond=1e-12, hermitian=True)
    return np.asarray(inv / np.outer(scale, scale), dtype=float)
