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
couples heave and pitch, and a missing mode shows as a rank-deficient design).

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

Guards (:mod:`ident.records.plausibility`): before the fit each release's amplitudes and
force magnitudes are checked against the section's size (a pitch in degrees, a heave in
millimetres are refused); after it the model is checked against the decays it came from (a lift
of the wrong sign is refused; forces off by a factor, a release instant off from where the decay
starts from rest are warnings in ``diagnostics.warnings``).

What it returns is :mod:`ident.identification.results` (:class:`IdentifiedModel` and its
diagnostics); the flutter speed's uncertainty and its parts are
:mod:`ident.identification.uncertainty`.

Longer than 600 lines: the turbulence branches assemble the same diagnostics as E2RFC's fit
and read its module settings (:data:`TURBULENT_ESTIMATOR`, :data:`TURBULENT_A3`) that the
benchmarks set; moving them out is the next split, with those settings passed in.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import partial

import numpy as np
import numpy.typing as npt

from ident.errors import RankDeficiencyError
from ident.identification import _closed_loop_starts, _turbulent_fit, closed_loop_ml
from ident.identification._e2rfc_problem import FinalFit, Problem, improves
from ident.identification._regressors import PreparedRelease, prepare
from ident.identification.modal import ModalFit
from ident.identification.results import (
    DISTINCT_U_RTOL,
    GROWTH_LIMIT,
    MODE_NAMES,
    RANDOM_RESPONSE_LIMIT,
    Deferred,
    E2RFCDiagnostics,
    IdentifiedModel,
    K_ranges,
    distinct_wind_speeds,
)
from ident.identification.uncertainty import REFIT_GRID, nearest_wind_speed
from ident.model import flutter as _flutter
from ident.model.conventions import name_modes
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.numerics.selection import Candidate, select_one_se, within_one_se
from ident.numerics.threads import single_threaded_blas
from ident.records import plausibility
from ident.records.release import Release

__all__ = ["ESTIMATOR_TURBULENT", "TURBULENT_A3", "identify", "reduced_frequency_span"]

FloatArray = npt.NDArray[np.float64]

#: Least signal of each mode in its own coordinate over a release, in noise standard deviations
#: (the norm of the mode's part of the record over the noise std), that some release at every
#: wind speed must show for a 3-DOF identification.
MODE_SNR_MIN = 20.0
#: Variance inflation of the force residuals' autocorrelation above which they are reported as
#: not white (measured: 1.0 for exact Roger aerodynamics, 3 for the exact-Theodorsen plate, 5 to
#: 30 for friction, quadratic damping, a cubic spring or a 10 ms channel delay).
WHITENESS_WARN = 5.0
#: ``diagnostics.estimator`` of the turbulence branch (module docstring).
ESTIMATOR_TURBULENT = "refined IV with the holds' noise model (turbulence branch)"
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
#: Lags of the closed-loop branch. Measured (plate, 1 % turbulence, 6 seeds): from E2RFC's
#: own lag count (none in turbulence) every flutter speed came out low, -3 to -13 %; with two
#: (Jones's count) the errors fall on both sides, -7 to +1 %, within their standard deviations.
#: On the bluff deck (ten lags in truth) a third raised log L by 26-35 but left the errors as
#: they were, at twice the time (docs/development/e2rfc_turbulence.md).
CLOSED_LOOP_LAGS = 2
#: The closed-loop branch's buffeting model (``fit_closed_loop``'s options, by name): one
#: second-order section per force on block means taken as samples, or two sections on exact
#: block means. docs/development/e2rfc_turbulence.md measures the second's smaller bias and
#: its two to three times the time.
CLOSED_LOOP_BUFFETING = "second-order"
#: name -> (``shaping_sections``, ``exact_block_means``).
CLOSED_LOOP_BUFFETING_MODELS = {"second-order": (1, False), "fourth-order": (2, True)}
#: ``diagnostics.estimator`` of the closed-loop branch.
ESTIMATOR_CLOSED_LOOP = "closed-loop maximum likelihood (turbulence branch)"
#: How E2RFC's turbulence warning ends, and how the closed-loop branch's ends in its place.
_SCATTER_STD = "the flutter speed's deviation is the release-to-release scatter"
_FISHER_STD = ("the closed-loop likelihood models the random response, and the flutter speed's "
               "deviation is its Fisher information's")


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
        closed-loop maximum likelihood (two degrees of freedom; a 3-DOF section runs refined IV
        and says so), or refined IV with the holds' noise model. Smooth flow ignores it.
    closed_loop_buffeting : {"second-order", "fourth-order"}, optional
        The closed-loop estimator's buffeting model (default :data:`CLOSED_LOOP_BUFFETING`):
        one second-order shaping section per force on block means taken as samples, or two
        sections on exact block means (less biased with many releases per speed, about twice
        the time; :data:`CLOSED_LOOP_BUFFETING_MODELS`). Ignored by the other estimators.

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
    prepared = [prepare(r, section) for r in releases]
    if section.n_dof == 3:
        _check_modes_excited(prepared, section)
    estimator = TURBULENT_ESTIMATOR if turbulent_estimator is None else turbulent_estimator
    if estimator not in TURBULENT_ESTIMATORS:
        raise ValueError(f"turbulent_estimator must be one of {TURBULENT_ESTIMATORS}, got "
                         f"{turbulent_estimator!r}")
    buffeting = CLOSED_LOOP_BUFFETING if closed_loop_buffeting is None else closed_loop_buffeting
    if buffeting not in CLOSED_LOOP_BUFFETING_MODELS:
        raise ValueError(f"closed_loop_buffeting must be one of "
                         f"{tuple(CLOSED_LOOP_BUFFETING_MODELS)}, got {closed_loop_buffeting!r}")
    model = _identify_prepared(prepared, section, n_lags, with_A3)
    return _guarded(_turbulence_branch(model, releases, section, n_lags, with_A3, estimator,
                                       buffeting), prepared, section, guards)


def _turbulence_branch(model: IdentifiedModel, releases: list[Release], section: SectionModel,
                       n_lags: int | None, with_A3: bool | None,
                       estimator: str, buffeting: str) -> IdentifiedModel:
    """Return E2RFC's model, or in turbulence the branch's (or a note on holds)."""
    if not model.diagnostics.turbulent:
        return model
    if estimator == "ml" and section.n_dof == 2:
        return _closed_loop(model, releases, section, buffeting)
    if estimator == "ml":
        note = ("closed-loop maximum likelihood identifies 2-DOF sections only: the refined-IV "
                "estimator ran on these 3-DOF releases")
        model = IdentifiedModel(model.A, model.d, replace(
            model.diagnostics, warnings=(*model.diagnostics.warnings, note)))
    if not _turbulent_fit.holds_suffice(releases):
        held = [r.hold.duration for r in releases if r.hold is not None]
        have = (f"the shortest hold here is {min(held):.3g} s" if len(held) == len(releases)
                else f"{len(releases) - len(held)} of {len(releases)} releases have none")
        note = (f"turbulence needs a hold of >= {_turbulent_fit.MIN_HOLD_S:g} s before each "
                f"release (the model held in the wind; {have}): with it the refined-IV "
                "estimator runs, without it today's, biased low in turbulence")
        diagnostics = replace(model.diagnostics, warnings=(*model.diagnostics.warnings, note))
        return IdentifiedModel(model.A, model.d, diagnostics)
    return _turbulent_model(model, releases, section, n_lags, with_A3)


def _turbulent_model(model: IdentifiedModel, releases: list[Release], section: SectionModel,
                     n_lags: int | None, with_A3: bool | None) -> IdentifiedModel:
    """Refit E2RFC's turbulent releases by refined IV with the holds' noise model.

    The result keeps E2RFC's data diagnostics (modal fits, random response, covered reduced
    frequencies); its coefficients, structure, covariance, alternatives and refits are the
    branch's, so that :meth:`IdentifiedModel.uncertainty` combines the same parts.
    """
    base = model.diagnostics
    a3_options: tuple[bool, ...] = (
        (with_A3,) if with_A3 is not None else (True, False) if TURBULENT_A3 == "choose"
        else (base.with_A3,) if TURBULENT_A3 == "e2rfc" else (True,))
    speeds = distinct_wind_speeds([r.U for r in releases])
    reduced_below = speeds[-1] / (1 + DISTINCT_U_RTOL) if len(speeds) >= 3 else None
    stable = base.decayed_at

    def admissible(fit: _turbulent_fit.TurbulentFit) -> bool:
        """Whether a fit's flutter speed (if any) lies above every decaying release's speed."""
        if stable is None:
            return True
        try:
            found = _flutter.analyze(section, RationalFunctionModel(fit.A, fit.d),
                                     n_points=REFIT_GRID).speed
        except ValueError:  # no still-air modes, a lost branch: nothing to trust
            return False
        return found is None or float(found) >= stable

    found = _turbulent_fit.fit_turbulent(
        releases, section, a3_options=a3_options, n_lags=n_lags, reduced_below=reduced_below,
        admissible=admissible)
    if found.contradicted and with_A3 is None and TURBULENT_A3 == "fitted-or-zero":
        fallback = _turbulent_fit.fit_turbulent(
            releases, section, a3_options=(False,), n_lags=n_lags,
            reduced_below=reduced_below, admissible=admissible)
        if not fallback.contradicted:
            found = _with_reason(fallback, "every structure with A3 fitted "
                                               "flutters below a decaying release's wind speed")
    note = (f"turbulence: coefficients by {ESTIMATOR_TURBULENT} from holds of "
            f"{min(r.hold.duration for r in releases if r.hold is not None):.3g} s or more; "
            f"{found.reason}")

    def assemble(fit: _turbulent_fit.TurbulentFit, reason: str,
                 alternatives: tuple[IdentifiedModel, ...], refits: dict[str, object]
                 ) -> IdentifiedModel:
        diagnostics = replace(
            base, n_lags=fit.d.size, with_A3=fit.with_A3, reason=reason,
            candidates=found.candidates, release_residuals=fit.release_residuals,
            condition_number=math.nan, covariance=fit.covariance,
            parameter_index=fit.parameter_index, alternatives=alternatives,
            warnings=(*base.warnings, note), estimator=ESTIMATOR_TURBULENT,
            _lag_roots=fit.d, _refits=refits)
        return IdentifiedModel(fit.A, fit.d, diagnostics)

    # The branch's refits replace E2RFC's (filled here: they came with the structure choice).
    none: dict[str, object] = {"jackknife": (), "release_jackknife": (), "reduced": None,
                               "finer": None}
    alternatives = tuple(
        assemble(f, "within one standard error of the best, not chosen", (), dict(none))
        for f in found.alternatives)
    jackknife = tuple(RationalFunctionModel(f.A, f.d) for f in found.leave_one_out)
    reduced = (None if found.reduced is None
               else RationalFunctionModel(found.reduced.A, found.reduced.d))
    return assemble(found.chosen, found.reason, alternatives,
                    {"jackknife": jackknife, "release_jackknife": jackknife,
                     "reduced": reduced, "finer": None})


def _closed_loop(model: IdentifiedModel, releases: list[Release], section: SectionModel,
                 buffeting: str) -> IdentifiedModel:
    """Refit E2RFC's turbulent releases by closed-loop maximum likelihood from its estimate.

    The structure is :data:`CLOSED_LOOP_LAGS` lags with A3 estimated; the covariance is the
    inverse Fisher information (the turbulence is in the likelihood, so no jackknife part);
    with three or more wind speeds the fit without the highest one is the extrapolation
    part's refit. A first maximum that flutters below a speed at which no release grew is
    searched again from other starts (:mod:`ident.identification._closed_loop_starts`). A fit
    that fails its own checks (:attr:`ClosedLoopFit.failed_checks`) is cross-checked by refined
    IV when the holds allow it: the distance between the two flutter speeds joins the std
    (:attr:`E2RFCDiagnostics.cross_check`).
    """
    base = model.diagnostics
    sections, exact = CLOSED_LOOP_BUFFETING_MODELS[buffeting]
    search = partial(closed_loop_ml.fit_closed_loop, releases, section, with_A3=True,
                     n_lags=CLOSED_LOOP_LAGS, shaping_sections=sections, exact_block_means=exact)
    try:
        fit = search(model)
    except ValueError as exc:
        note = (f"turbulence: the closed-loop likelihood could not start from E2RFC's estimate "
                f"({exc}); E2RFC's own, biased low in turbulence, is kept")
        return IdentifiedModel(model.A, model.d,
                               replace(base, warnings=(*base.warnings, note)))
    bounded_at = _bounded_at(releases)
    fit, restarted = _closed_loop_starts.search_again(fit, section, bounded_at, search)
    speeds = distinct_wind_speeds([r.U for r in releases])
    below = [r for r in releases if r.U < speeds[-1] / (1 + DISTINCT_U_RTOL)]

    def reduced() -> RationalFunctionModel | None:
        """Return the fit without the highest wind speed, from the full fit."""
        try:
            return closed_loop_ml.fit_closed_loop(below, section, fit.model, with_A3=True,
                                                  shaping_sections=sections,
                                                  exact_block_means=exact).model
        except ValueError:  # likelihood not defined without the top speed: no extrapolation
            return None     # part, which the uncertainty's warnings then say

    holds = sum(r.hold is not None for r in releases)
    note = (f"turbulence: coefficients by {ESTIMATOR_CLOSED_LOOP} over {len(releases)} releases "
            f"and {holds} holds ({fit.iterations} iterations)")
    cross_check, checks = None, []
    if fit.failed_checks:
        failed = (f"the closed-loop fit failed its own checks ({'; '.join(fit.failed_checks)}): "
                  "the data hold something its model cannot describe (friction, a drift, a "
                  "channel that is not what it says), so its Fisher deviation understates the "
                  "error")
        if _turbulent_fit.holds_suffice(releases):
            other = _turbulent_model(model, releases, section, None, None)
            cross_check = ("refined IV", RationalFunctionModel(other.A, other.d))
            checks.append(f"{failed}; refined IV ran on the same releases as a cross-check")
        else:
            checks.append(f"{failed}; without a hold of >= {_turbulent_fit.MIN_HOLD_S:g} s "
                          "before every release no second estimator can check it")
    diagnostics = replace(
        base, n_lags=fit.model.n_lags, with_A3=True,
        reason=f"{CLOSED_LOOP_LAGS} lags, A3 fitted; {note}",
        condition_number=math.nan, covariance=fit.covariance,
        parameter_index=fit.parameter_index, alternatives=(),
        warnings=(*(w.replace(_SCATTER_STD, _FISHER_STD) for w in base.warnings), note,
                  *([restarted] if restarted else []), *fit.warnings, *checks),
        estimator=ESTIMATOR_CLOSED_LOOP,
        bounded_at=bounded_at,
        _lag_roots=fit.model.d,
        _refits={"jackknife": (), "release_jackknife": (), "finer": None,
                 "reduced": Deferred(reduced) if len(speeds) >= 3 else None,
                 "cross_check": cross_check})
    return IdentifiedModel(fit.model.A, fit.model.d, diagnostics)


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
        random_response = np.array([_random_response(p.fit) for p in prepared])
        warnings: list[str] = []
        if checks:
            if float(np.median(random_response)) > RANDOM_RESPONSE_LIMIT:
                warnings.append(
                    f"the decays turn into a random response (turbulence: residual "
                    f"{float(np.median(random_response)):.3g} times the noise): the modal fits "
                    f"and the least-squares covariance do not hold; {_SCATTER_STD}")
            elif fit.residual_inflation > WHITENESS_WARN:
                warnings.append(
                    f"the force residuals are not white (their autocorrelation inflates the "
                    f"variance {fit.residual_inflation:.3g}-fold): the model misses a systematic "
                    "part of the forces, such as friction, a nonlinear spring or a delayed "
                    "channel (windrig diagnose names it)")
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
            alternatives=alternatives, random_response=random_response,
            K_range=K_ranges(prepared, self.section), warnings=tuple(warnings),
            _prepared=tuple(prepared), _section=self.section, _lag_roots=fit.d)
        return IdentifiedModel(fit.A, fit.d, diagnostics)


def _guarded(model: IdentifiedModel, prepared: list[PreparedRelease], section: SectionModel,
             guards: list[str]) -> IdentifiedModel:
    """Add the plausibility guards' warnings (:mod:`ident.records.plausibility`) to a model's.

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
                fit.evaluate, derivative=1), scale, _random_response(fit))
            if fit.modes.size >= section.n_dof:
                speeds.append(p.U)
                measured.append(fit.modes)
                heave.append(name_modes(fit.mode_shapes(), section.mass_matrix())[0])
        if len(speeds) >= 2:
            warnings += plausibility.check_model(section, model, speeds, measured, heave)
    if not warnings:
        return model
    diagnostics = replace(model.diagnostics, warnings=(*warnings, *model.diagnostics.warnings))
    return IdentifiedModel(model.A, model.d, diagnostics)


def _with_reason(found: _turbulent_fit.TurbulentResult, why: str
                               ) -> _turbulent_fit.TurbulentResult:
    """Return a turbulence-branch result whose reason starts with ``why``."""
    return replace(found, reason=f"{why}: {found.reason}")


def _random_response(fit: ModalFit) -> float:
    """Return a release's modal-fit residual over its white measurement noise (larger channel)."""
    scale = np.maximum(fit.noise, 1e-9 * np.maximum(fit.residual_rms, 1e-300))
    return float(np.max(fit.residual_rms / scale)) if np.any(fit.residual_rms > 0) else 0.0


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


def _bounded_at(releases: list[Release]) -> float | None:
    """Highest wind speed at which no release's motion grew over its record, m/s.

    A displacement grew when its RMS about the record's mean over the last quarter exceeds
    :data:`~ident.identification.results.GROWTH_LIMIT` times that over the first quarter.
    """
    speeds = distinct_wind_speeds([r.U for r in releases])
    grown = dict.fromkeys(speeds, False)
    for r in releases:
        quarter = r.t.size // 4
        U = speeds[nearest_wind_speed(r.U, speeds)]
        for x in (r.h - r.h.mean(), r.alpha - r.alpha.mean()):
            grown[U] |= bool(np.std(x[-quarter:]) > GROWTH_LIMIT * np.std(x[:quarter]))
    bounded = [U for U, g in grown.items() if not g]
    return max(bounded) if bounded else None


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


def _check_modes_excited(prepared: list[PreparedRelease], section: SectionModel) -> None:
    """Refuse a wind speed at which no release shows every mode above the noise (3 DOF).

    Each wind speed's decays tell the force on each mode at its own frequency; a mode that is
    not in them leaves its coordinate's columns of the model undetermined. The sway of a deck
    is barely coupled to heave and pitch, so it has to be released too.
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
    for U, ratios in best.items():
        for coordinate, value in enumerate(ratios):
            if value < MODE_SNR_MIN:
                raise RankDeficiencyError(
                    f"no release at {U:.3g} m/s shows the {MODE_NAMES[coordinate]} mode above "
                    f"the noise (its signal is {value:.3g} noise standard deviations, "
                    f"{MODE_SNR_MIN:g} needed): the model's {MODE_NAMES[coordinate]} columns "
                    "would be undetermined. Release from a hold that displaces every degree "
                    "of freedom (with sway: a lateral displacement too).")
