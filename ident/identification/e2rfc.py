"""E2RFC: Rational Function Coefficients directly from free-vibration releases.

Experimental Extraction of Rational Function Coefficients (Chowdhury and Sarkar, 2005): the
measured self-excited forces of releases at a few wind speeds are regressed on the measured motion
through Roger's time-domain form of the forces (see :mod:`ident.identification._regressors`). The
RFCs do not depend on U, so all releases are stacked into one least-squares problem; the wind speed
enters only through the regressors, and releases at two or more wind speeds are what make it
determined. One decay holds just two complex frequencies, so a single wind speed can never determine
the model: that case is refused, never answered with numbers.

How noise is handled: regressors come from a modal fit of the displacements (no differentiated
noise, no noise in the regressors to bias the fit); each release and force channel is weighted by
the inverse of its own noise level; per-release intercepts absorb static forces.

With three degrees of freedom (releases with sway p and drag) the coordinates are ``[h/B,
alpha, p/B]``, the forces ``[L B, M, D B]`` and the model's ``A_k`` 3x3; each force row is its own
weighted least-squares problem in the same regressors, the lag roots are shared. The rank
condition, in n = 2 or 3 degrees of freedom: a wind speed's decays tell, per force row, the
force on each of the n modes at its own frequency (2n numbers), and nothing about other
frequencies; so two or more wind speeds are needed, the design's condition number decides
which structures they determine, and every mode must be in the decays at every speed. The last
is checked for 3 DOF (:func:`_check_modes_excited`): sway is barely coupled to heave and pitch,
and a release without a lateral hold can leave the sway mode in the noise (in 2 DOF the wind
couples heave and pitch, and a missing mode shows as a rank-deficient design). In turbulence,
where the closed-loop likelihood reads the random response too, a mode below the check's level
is a warning rather than a refusal.

Lag roots are found by variable projection: for fixed lag roots the coefficients follow from a
linear least-squares solve, so the nonlinear search runs over log(d) alone (a bounded
Levenberg-Marquardt search, :mod:`ident.numerics.lsq`, from several starts spread over the reduced
frequencies the data cover). The number of lags (0 to 3) and whether the added-mass matrix A3
is fitted are chosen by five-fold held-out error (folds of interleaved one-period blocks of
every release), with the one-standard-error rule: the simplest model whose held-out error is
within one standard error of the best. The machinery of that problem is
:mod:`ident.identification._e2rfc_problem`.

The turbulence branch: when the releases hold a random response (turbulence), the model is
fitted again by the estimator :data:`TURBULENT_ESTIMATOR` names. By default (``"ml"``) that is
the closed-loop maximum likelihood of every release and hold together
(:mod:`ident.identification.closed_loop_ml`; two degrees of freedom, holds used when present,
never required), its covariance the inverse Fisher information. ``"iv"`` (and any 3-DOF
section) runs refined instrumental variables instead, which needs a hold of at least
:data:`ident.identification._turbulent_fit.MIN_HOLD_S` before every release (the model held in
the wind, :class:`~ident.records.release.ReleaseHold`) as its noise model
(:mod:`ident.identification._turbulent_fit`): its structure (one or two lags, A3 fitted) chosen
by leave-one-release-out prediction error among the structures that do not flutter below a
wind speed at which a release decayed (A3 zero only when every A3-fitted structure does,
:data:`TURBULENT_A3`); those refits are the jackknife of the turbulence part, the other
structures within one standard error the structure part. Without such holds the IV branch keeps
plain E2RFC's estimate, with a warning that says what turbulence needs.
``diagnostics.estimator`` says which estimator ran. In smooth flow nothing changes.

Guards (:mod:`ident.records.plausibility`, :mod:`ident.records.decay_checks`): before the fit
each release's amplitudes and force magnitudes are checked against the section's size (a pitch
in degrees, a heave in millimetres are refused), and the section's still-air frequencies
against the modes the smooth releases ring at (rad/s, or swapped, are refused); after it the
model is checked against the decays it came from (a lift of the wrong sign is refused; forces
off by a factor, a release instant off from where the decay starts from rest are warnings in
``diagnostics.warnings``).

What it returns is :mod:`ident.identification.results` (:class:`IdentifiedModel` and its
diagnostics); the flutter speed's uncertainty and its parts are
:mod:`ident.identification.uncertainty`.

The turbulence branch itself is :mod:`ident.identification._e2rfc_turbulence`; its settings
(:data:`TURBULENT_ESTIMATOR`, :data:`TURBULENT_A3`, :data:`CLOSED_LOOP_BUFFETING`) live here,
where the benchmarks set them, and go to it as arguments.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import partial

import numpy as np
import numpy.typing as npt

from ident.errors import RankDeficiencyError
from ident.identification._e2rfc_problem import FinalFit, Problem, improves
from ident.identification._e2rfc_turbulence import (
    BY_EVIDENCE,
    CLOSED_LOOP_BUFFETING_CHOICES,
    CLOSED_LOOP_BUFFETING_MODELS,
    CLOSED_LOOP_LAGS,
    ESTIMATOR_CLOSED_LOOP,
    ESTIMATOR_TURBULENT,
    SCATTER_STD,
    turbulence_branch,
)
from ident.identification._regressors import PreparedRelease, prepare
from ident.identification.results import (
    MODE_NAMES,
    RANDOM_RESPONSE_LIMIT,
    WEAK_RANDOM_RESPONSE,
    E2RFCDiagnostics,
    IdentifiedModel,
    K_ranges,
    distinct_wind_speeds,
    is_turbulent,
)
from ident.model.conventions import name_modes
from ident.model.section import SectionModel, proportion_warnings
from ident.numerics.selection import Candidate, select_one_se, within_one_se
from ident.numerics.threads import single_threaded_blas
from ident.records import decay_checks, plausibility
from ident.records.release import Release

__all__ = ["BY_EVIDENCE", "CLOSED_LOOP_BUFFETING", "CLOSED_LOOP_BUFFETING_CHOICES",
           "CLOSED_LOOP_BUFFETING_MODELS", "CLOSED_LOOP_LAGS",
           "ESTIMATOR_CLOSED_LOOP", "ESTIMATOR_TURBULENT", "TURBULENT_A3", "TURBULENT_ESTIMATOR",
           "identify", "reduced_frequency_span"]

FloatArray = npt.NDArray[np.float64]

#: Least signal of each mode in its own coordinate over a release, in noise standard deviations
#: (the norm of the mode's part of the record over the noise std), that some release at every
#: wind speed must show for a 3-DOF identification.
MODE_SNR_MIN = 20.0
#: Variance inflation of the force residuals' autocorrelation above which they are reported as
#: not white (measured: 1.0 for exact Roger aerodynamics, 3 for the exact-Theodorsen plate, 5 to
#: 30 for friction, quadratic damping, a cubic spring or a 10 ms channel delay).
WHITENESS_WARN = 5.0
#: A3 in the turbulence branch: "fitted-or-zero" (fitted; zero only when every structure with
#: A3 fitted flutters below a wind speed where a release decayed), "fitted" always, "choose"
#: (fitted or zero by held-out error with the lag count), or "e2rfc" as E2RFC's own choice on
#: the same releases has it. docs/development/e2rfc_turbulence.md measures them: A3 zero lands at
#: -99 % on some bluff-deck seeds whose held-out error prefers it, A3 fitted on some plate seeds
#: whose every A3-fitted structure contradicts the data.
TURBULENT_A3 = "fitted-or-zero"
#: The turbulence branch's estimator: ``"ml"`` (closed-loop maximum likelihood of every release
#: and hold together, :mod:`ident.identification.closed_loop_ml`; holds optional; two degrees of
#: freedom) or ``"iv"`` (refined IV with the holds' noise model; needs a hold before every
#: release), started from E2RFC's estimate. Measured in docs/development/e2rfc_turbulence.md on the
#: benchmark's turbulence rows: "ml" medians 1.5-4 times lower than refined IV's with holds and
#: 3.6-25 times lower than plain E2RFC's without them, 94 % of the 2-std intervals covering,
#: 7-12 s per identification with its uncertainty.
TURBULENT_ESTIMATOR = "ml"
#: The turbulence branch's estimators, by name.
TURBULENT_ESTIMATORS = ("iv", "ml")
#: The closed-loop branch's buffeting model (``fit_closed_loop``'s options, by name,
#: :data:`CLOSED_LOOP_BUFFETING_MODELS`): one second-order section per force on block means
#: taken as samples, or two sections on exact block means, one filter shared by the wind
#: speeds or (``-per-speed``) one per speed. docs/development/e2rfc_turbulence.md measures the
#: fourth-order model's smaller bias and its two to three times the time. ``"by-evidence"``
#: (:data:`BY_EVIDENCE`, the default) fits both shared models and keeps the fourth-order one
#: when the second-order one's innovations pooled over the records are not white, or when it
#: is higher in likelihood than chance allows its extra parameters (a buffeting model the
#: data reject biases the self-excited coefficients in closed loop).
CLOSED_LOOP_BUFFETING = "by-evidence"


@single_threaded_blas
def identify(
    releases: Sequence[Release],
    section: SectionModel,
    n_lags: int | None = None,
    with_A3: bool | None = None,
    turbulent_estimator: str | None = None,
    closed_loop_buffeting: str | None = None,
) -> IdentifiedModel:
    """Identify the rational-function model of the self-excited forces from releases (E2RFC).

    Parameters
    ----------
    releases : sequence of Release
        Free decays with measured forces, at two or more wind speeds.
    section : SectionModel
        The structure (its width B and, where a release has none, the air density).
    n_lags : int, optional
        Number of lag terms (0 to 3); None chooses by held-out error.
    with_A3 : bool, optional
        Fit the added-mass matrix A3; None chooses by held-out error.
    turbulent_estimator : {"iv", "ml"}, optional
        The estimator of releases in turbulence (default :data:`TURBULENT_ESTIMATOR`, "ml"):
        closed-loop maximum likelihood (two or three degrees of freedom), or refined IV with
        the holds' noise model. Smooth flow ignores it.
    closed_loop_buffeting : str, optional
        The closed-loop estimator's buffeting model (default :data:`CLOSED_LOOP_BUFFETING`),
        one of :data:`CLOSED_LOOP_BUFFETING_CHOICES`: ``"second-order"``, one second-order
        shaping section per force on block means taken as samples; ``"fourth-order"``, two
        sections on exact block means (less biased, about twice the time); each one filter
        for every wind speed, scaled as quasi-steady buffeting scales with the speed, or with
        ``"-per-speed"`` a filter per speed (turbulence that does not scale with the speed);
        ``"by-evidence"``, both shared models, keeping the fourth-order one where the
        second-order one's innovations pooled over the records are not white or a
        likelihood-ratio test at the 1 % level prefers it. Ignored by the other estimators.

    Returns
    -------
    IdentifiedModel
        A :class:`RationalFunctionModel` with ``.diagnostics`` (:class:`E2RFCDiagnostics`) and
        ``.flutter(section)`` giving the flutter speed with its standard deviation.

    Raises
    ------
    RankDeficiencyError
        Releases at fewer than two wind speeds, or data that cannot determine the requested model.
    TypeError
        If ``releases`` holds something other than :class:`Release` objects.

    References
    ----------
    M. Gan Chowdhury and P. P. Sarkar, "Experimental identification of rational function
    coefficients for time-domain flutter analysis", Engineering Structures 27 (2005) 1349-1364.
    G. H. Golub and V. Pereyra, "Separable nonlinear least squares: the variable projection
    method and its applications", Inverse Problems 19 (2003).

    Examples
    --------
    >>> from ident import SectionModel
    >>> from ident.model import flat_plate
    >>> from simulators import simulate_release
    >>> s = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)
    >>> truth = flat_plate.jones_model()
    >>> sims = [simulate_release(s, truth, U, 0.004, 0.02, duration=10.0, fs=200.0)
    ...         for U in (5.0, 8.0)]
    >>> model = identify([Release.from_simulation(r) for r in sims], s, n_lags=2, with_A3=True)
    >>> bool(np.allclose(model.d, truth.d, rtol=1e-3))
    True
    >>> identify([Release.from_simulation(sims[0])], s)
    Traceback (most recent call last):
    ...
    ident.errors.RankDeficiencyError: releases at one wind speed (5 m/s) cannot determine ...
    """
    releases = list(releases)
    for r in releases:
        if not isinstance(r, Release):
            raise TypeError(f"releases must be ident.Release objects, got {type(r).__name__}")
    _check_wind_speeds(releases)
    _check_degrees_of_freedom(releases, section)
    if n_lags is not None and (not isinstance(n_lags, int) or not 0 <= n_lags <= 3):
        raise ValueError(f"n_lags must be an integer in 0..3 or None, got {n_lags!r}")
    guards = [w for r in releases for w in plausibility.check_release(r, section)]
    guards += plausibility.check_air_density(releases, section)
    guards += proportion_warnings(section)
    prepared = [prepare(r, section) for r in releases]
    guards += _check_still_air(prepared, section)
    estimator = TURBULENT_ESTIMATOR if turbulent_estimator is None else turbulent_estimator
    if estimator not in TURBULENT_ESTIMATORS:
        raise ValueError(f"turbulent_estimator must be one of {TURBULENT_ESTIMATORS}, got "
                         f"{turbulent_estimator!r}")
    if section.n_dof == 3:
        turbulent = is_turbulent([p.fit.random_response for p in prepared],
                                 _held_load(prepared))
        guards += _check_modes_excited(prepared, section,
                                       refuse=not (turbulent and estimator == "ml"))
    buffeting = CLOSED_LOOP_BUFFETING if closed_loop_buffeting is None else closed_loop_buffeting
    if buffeting not in CLOSED_LOOP_BUFFETING_CHOICES:
        raise ValueError(f"closed_loop_buffeting must be one of "
                         f"{CLOSED_LOOP_BUFFETING_CHOICES}, got {closed_loop_buffeting!r}")
    model = _identify_prepared(prepared, section, n_lags, with_A3)
    return _guarded(turbulence_branch(model, releases, section, n_lags, with_A3,
                                      estimator=estimator, buffeting=buffeting,
                                      a3_rule=TURBULENT_A3), prepared, section, guards)


def _identify_prepared(
    prepared: list[PreparedRelease], section: SectionModel, n_lags: int | None,
    with_A3: bool | None, *, checks: bool = True,
) -> IdentifiedModel:
    """Choose the structure, search the lag roots and fit, on prepared releases.

    Separate from :func:`identify` so that other regressor constructions (the benchmark's
    ablation with differentiated raw displacements) run through the very same estimator.
    ``checks`` adds the data checks' warnings (module docstring).
    """
    problem = Problem(prepared)
    given = n_lags is not None and with_A3 is not None
    lags = range(4) if n_lags is None else [n_lags]
    a3_options = (True, False) if with_A3 is None else (with_A3,)
    candidates: list[Candidate] = []
    previous: FloatArray | None = None
    history: list[list[Candidate]] = []
    for m in lags:
        starts = problem.starts(m, previous)
        tried = []
        for a3 in a3_options:
            candidate, d_found = problem.candidate(m, a3, starts, score=not given)
            tried.append(candidate)
            if d_found is not None:
                starts = [d_found]  # the other A3 option starts from these roots
                previous = d_found if a3 == a3_options[0] else previous
        candidates.extend(tried)
        history.append(tried)
        # Two lag counts in a row that beat nothing simpler: more lags will not either.
        if n_lags is None and m >= 2 and not any(
            improves(history[j], [c for h in history[:j] for c in h]) for j in (m - 1, m)
        ):
            break
    # A structure whose held-out error is NaN (a fold's fit that failed numerically:
    # seen once in 64 turbulent benchmark cases) cannot be compared; the one-SE rule would
    # find nothing within NaN of the best.
    usable = [c for c in candidates if not c.note and (given or not math.isnan(c.cv_error))]
    if not usable:
        notes = "; ".join(f"n_lags={c.n_lags}, A3={c.with_A3}: "
                          f"{c.note or 'held-out error not a number'}" for c in candidates)
        raise RankDeficiencyError(f"no model structure is determined by these releases ({notes})")
    chosen, reason = select_one_se(usable, given=given)
    context = _Context(prepared, section, tuple(candidates))
    if given:
        return context.model(problem.final(chosen), reason, checks=checks)
    alternatives = tuple(
        context.model(problem.final(problem.polished(c)),
                      f"{c.label}: within one standard error of the best, not chosen",
                      checks=False)
        for c in within_one_se(usable) if c is not chosen)
    return context.model(problem.final(problem.polished(chosen)), reason, alternatives,
                         checks=checks)


@dataclass(frozen=True)
class _Context:
    """What every model of one identification shares: the releases and the candidates tried."""

    prepared: list[PreparedRelease]
    section: SectionModel
    candidates: tuple[Candidate, ...]

    def model(self, fit: FinalFit, reason: str, alternatives: tuple[IdentifiedModel, ...] = (),
              *, checks: bool) -> IdentifiedModel:
        """Assemble an :class:`IdentifiedModel`, with the data checks when asked."""
        prepared = self.prepared
        random_response = np.array([p.fit.random_response for p in prepared])
        held_load = _held_load(prepared)
        ratio = float(np.median(random_response))
        warnings: list[str] = []
        if checks:
            if is_turbulent(random_response, held_load):
                holds = ("" if ratio > RANDOM_RESPONSE_LIMIT else
                         f", and the holds' forces {float(np.median(held_load)):.3g} times "
                         "theirs")
                warnings.append(
                    f"the decays turn into a random response (turbulence: residual "
                    f"{ratio:.3g} times the noise{holds}): the modal fits "
                    f"and the least-squares covariance do not hold; {SCATTER_STD}")
            elif fit.residual_inflation > WHITENESS_WARN:
                # Weak turbulence (3-DOF releases at Iw 1 % with 2 % noise: 7-21 per release)
                # can fall under the limit; its buffeting is then one of the likely causes.
                weak = (f", or buffeting too weak to be taken as turbulence (the decays' "
                        f"residual is {ratio:.3g} times the noise, under "
                        f"{RANDOM_RESPONSE_LIMIT:g})" if ratio > WEAK_RANDOM_RESPONSE else "")
                warnings.append(
                    f"the force residuals are not white (their autocorrelation inflates the "
                    f"variance {fit.residual_inflation:.3g}-fold): the model misses a systematic "
                    "part of the forces, such as friction, a nonlinear spring or a delayed "
                    f"channel (windrig diagnose names it){weak}")
            worst = fit.release_residuals.max(axis=1)
            median = float(np.median(worst))
            for p, r in zip(prepared, worst, strict=True):
                if r > 3.0 * median and r > 0.05:
                    name = p.release.meta.get("name", f"release at {p.U:.3g} m/s")
                    warnings.append(f"{name}: force residual {100 * r:.1f} % of the signal, "
                                    f"over 3 times the median ({100 * median:.1f} %)")
        diagnostics = E2RFCDiagnostics(
            n_lags=fit.d.size, with_A3=fit.with_A3, reason=reason,
            candidates=self.candidates, release_residuals=fit.release_residuals,
            wind_speeds=np.array([p.U for p in prepared]),
            condition_number=fit.condition_number, covariance=fit.covariance,
            parameter_index=fit.parameter_index, modal_fits=tuple(p.fit for p in prepared),
            alternatives=alternatives, random_response=random_response, held_load=held_load,
            K_range=K_ranges(prepared, self.section), warnings=tuple(warnings),
            _prepared=tuple(prepared), _section=self.section, _lag_roots=fit.d)
        return IdentifiedModel(fit.A, fit.d, diagnostics)


def _held_load(prepared: list[PreparedRelease]) -> FloatArray:
    """Return each hold's force fluctuation over its noise (``ReleaseHold.random_load``)."""
    return np.array([p.release.hold.random_load for p in prepared
                     if p.release.hold is not None])


def _guarded(model: IdentifiedModel, prepared: list[PreparedRelease], section: SectionModel,
             guards: list[str]) -> IdentifiedModel:
    """Add the guards' warnings (plausibility and decay checks) to a model's.

    The releases' own (``guards``, from before the fit) come first, then the release instants
    and the model against the measured decays. In turbulence the decays are a random response
    whose modal fits neither start from rest nor give the modes' damping to the precision
    these checks need: only the releases' own checks run there.

    Raises
    ------
    PlausibilityError
        The model says the lift's sign is flipped.
    """
    warnings = list(guards)
    if not model.diagnostics.turbulent:
        speeds, measured, heave = [], [], []
        for p in prepared:
            fit, release = p.fit, p.release
            frequencies = [section.fh, section.fa, section.fp or 0.0][:section.n_dof]
            q = release.coordinates(section.B)
            scale = [max(math.sqrt(2) * float(np.std(q[:, j])), 1e-300) * 2 * math.pi * f
                     for j, f in enumerate(frequencies)]
            warnings += plausibility.check_start(release, section, partial(
                fit.evaluate, derivative=1), scale, fit.random_response)
            if fit.modes.size >= section.n_dof:
                speeds.append(p.U)
                measured.append(fit.modes)
                heave.append(name_modes(fit.mode_shapes(), section.mass_matrix())[0])
        if len(speeds) >= 2:
            warnings += decay_checks.check_model(section, model, speeds, measured, heave)
    if not warnings:
        return model
    diagnostics = replace(model.diagnostics, warnings=(*warnings, *model.diagnostics.warnings))
    return IdentifiedModel(model.A, model.d, diagnostics)


def _check_still_air(prepared: list[PreparedRelease], section: SectionModel) -> list[str]:
    """Check the section's still-air frequencies and damping against what the releases show.

    A decay's modes are its modal fit's, named by their shapes; their frequencies and, in
    smooth flow, damping ratios are checked. A release with a random response gives each
    coordinate's spectral peak instead, for the frequencies only
    (:func:`ident.records.decay_checks.ringing_frequencies`): in turbulence the modal fit's
    pitch-named mode rings at 0.2-0.5 of the pitch's frequency on many releases (gust-driven
    motion below the modes; the benchmark's plate and bluff deck at Iw 1-3 %).

    Raises
    ------
    PlausibilityError
        Frequencies in rad/s, or two of them swapped
        (:func:`ident.records.decay_checks.check_frequencies`); damping ratios in per cent
        (:func:`ident.records.decay_checks.check_damping`).
    """
    speeds, frequencies = [], []
    smooth_speeds, damping = [], []
    for p in prepared:
        fit = p.fit
        if fit.random_response > RANDOM_RESPONSE_LIMIT:
            rung = decay_checks.ringing_frequencies(p.release, section.n_dof)
        elif fit.modes.size < section.n_dof:
            continue
        else:
            named = name_modes(fit.mode_shapes(), section.mass_matrix())
            rung = [float(fit.frequencies[i]) for i in named]
            smooth_speeds.append(p.U)
            damping.append([float(fit.damping[i]) for i in named])
        speeds.append(p.U)
        frequencies.append(rung)
    warnings = decay_checks.check_frequencies(section, speeds, frequencies)
    return warnings + decay_checks.check_damping(section, smooth_speeds, damping)


def reduced_frequency_span(releases: Sequence[Release], section: SectionModel,
                           n: int) -> FloatArray:
    """Return ``n`` reduced frequencies spanning what the releases measured, widened 20 %.

    ``K = B omega / U`` of every structural mode (heave, pitch and, with sway, the lateral one)
    at every release's wind speed: where an identified model's flutter derivatives rest on
    data (for plots and tables).
    """
    frequencies = [section.fh, section.fa] + ([] if section.fp is None else [section.fp])
    K = [section.B * 2 * math.pi * f / r.U for r in releases for f in frequencies]
    return np.linspace(0.8 * min(K), 1.2 * max(K), n)


def _check_wind_speeds(releases: list[Release]) -> None:
    if not releases:
        raise RankDeficiencyError(
            "no releases given: E2RFC needs releases at two or more wind speeds"
        )
    speeds = sorted(r.U for r in releases)
    if len(distinct_wind_speeds(speeds)) < 2:
        raise RankDeficiencyError(
            f"releases at one wind speed ({speeds[0]:.3g} m/s) cannot determine the rational "
            "function model: one decay holds only two complex frequencies. Record releases at "
            "two or more wind speeds (E2RFC is designed for 2 to 5)."
        )


def _check_degrees_of_freedom(releases: list[Release], section: SectionModel) -> None:
    """Refuse releases that mix 2 and 3 degrees of freedom, or that do not match the section."""
    counts = sorted({r.n_dof for r in releases})
    if len(counts) > 1:
        raise ValueError("the releases mix two and three degrees of freedom (some carry sway p "
                         "and drag, some do not): identify them separately")
    if counts[0] != section.n_dof:
        what = ("have sway (p and drag) but the section has no lateral spring: give the "
                "section's fp" if counts[0] == 3 else
                "have no sway but the section has a lateral spring (fp): give releases with p "
                "and drag, or the section's planar() part")
        raise ValueError(f"the releases {what}")


def _check_modes_excited(prepared: list[PreparedRelease], section: SectionModel, *,
                         refuse: bool = True) -> list[str]:
    """Refuse a wind speed at which no release shows every mode above the noise (3 DOF).

    Each wind speed's decays tell the force on each mode at its own frequency; a mode that is
    not in them leaves its coordinate's columns of the model undetermined. The sway of a deck
    is barely coupled to heave and pitch, so it has to be released too.

    In turbulence the modal fit's residual is the random response, and a mode's decay can lie
    under it while the random response itself carries the mode (the buffeting drives every
    mode). The closed-loop likelihood reads the coefficients from both, and its Fisher
    information says how well: with ``refuse=False`` (its case) the shortfall is returned as
    a warning instead. Measured on the 3-DOF bluff deck at Iw 3 % (10 and -12 mm of sway at
    the release): the sway's decay was 16 residual standard deviations at the lowest speed.
    """
    speeds = distinct_wind_speeds([p.U for p in prepared])
    best = {U: np.zeros(section.n_dof) for U in speeds}
    for p in prepared:
        U = max(u for u in speeds if u <= p.U * (1 + 1e-12))
        fit = p.fit
        if fit.modes.size < section.n_dof:
            continue
        shapes = fit.mode_shapes()
        named = name_modes(shapes, section.mass_matrix())
        dt = p.release.dt
        duration = p.release.duration
        for coordinate, mode in enumerate(named):
            sigma = max(-float(fit.modes[mode].real), 1e-9)
            # Norm of the mode's signal in its own coordinate over the record, in noise stds.
            energy = 2 * abs(shapes[mode, coordinate]) ** 2 * (
                1 - math.exp(-2 * sigma * duration)) / (2 * sigma * dt)
            snr = math.sqrt(energy) / max(float(fit.noise[coordinate]), 1e-300)
            best[U][coordinate] = max(best[U][coordinate], snr)
    notes = []
    for U, ratios in best.items():
        for coordinate, value in enumerate(ratios):
            if value >= MODE_SNR_MIN:
                continue
            name = MODE_NAMES[coordinate]
            if refuse:
                raise RankDeficiencyError(
                    f"no release at {U:.3g} m/s shows the {name} mode above the noise (its "
                    f"signal is {value:.3g} noise standard deviations, {MODE_SNR_MIN:g} "
                    f"needed): the model's {name} columns would be undetermined. Release from "
                    "a hold that displaces every degree of freedom (with sway: a lateral "
                    "displacement too).")
            notes.append(
                f"no release at {U:.3g} m/s shows the {name} mode's decay above its random "
                f"response (its signal is {value:.3g} of the residual's standard deviations, "
                f"{MODE_SNR_MIN:g} wanted): the closed-loop likelihood reads the {name} "
                "columns from the random response as well, and its deviation says how well; "
                "a larger displacement at the release would tell them from the decay too")
    return notes
