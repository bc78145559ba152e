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

Longer than 600 lines: the identified model, its diagnostics and its uncertainty (the parts,
the refits they need, the warnings) are one result and stay together; the least-squares problem
itself is :mod:`ident.identification._e2rfc_problem`, the regressors
:mod:`ident.identification._regressors`.

How uncertain the flutter speed is (:meth:`IdentifiedModel.uncertainty`), from these sources:

- *parametric*: measurement noise through the chosen model's parameter covariance;
- *structure*: the other structures within one standard error are fitted too
  (``diagnostics.alternatives``): the data do not tell them apart, and the spread of their
  flutter speeds is an uncertainty that one structure's covariance cannot show;
- *extrapolation*: the flutter speed lies beyond the wind speeds released at, at a lower reduced
  frequency than the releases cover, where a rational function fitted over the covered range
  can drift (real decks are not exactly of Roger's form). With releases at three or more wind
  speeds the model is fitted again without the highest one; how far its flutter speed moves,
  scaled by how much farther it extrapolates, measures that drift;
- *turbulence*: in turbulent flow the decays turn into a random response (buffeting), which the
  modal fit cannot follow and which is correlated over whole periods, so the least-squares
  covariance says nothing. The releases' buffeting is independent from one release to the next,
  so the release-to-release scatter measures it honestly: each release is left out in turn and
  the model fitted again (jackknife). A release holds a random response when its modal fit's
  residual exceeds ``RANDOM_RESPONSE_LIMIT`` times its white measurement noise (smooth-flow
  decays, even with friction or other nonlinear physics, stay below 5; 0.3 % turbulence gives
  about 40). Its variance falls as one over the number of releases, which is how
  :meth:`FlutterUncertainty.releases_needed` tells how many would be needed;
- *below a decaying release*: a model that flutters below a wind speed at which a release was
  seen to decay on both modes (its modal fit's damping positive) contradicts the data. In
  turbulence the random response biases E2RFC that way: late in a release the modal fit follows
  the stationary random response, so its damping comes out low, and the force regression then
  gives the aeroelastic system that damping: a flutter speed far too low (-50 to -80 % at 3 %
  turbulence in the benchmark). Every release shares that bias, so the jackknife cannot see
  it. The distance to that wind speed is the least error of such an estimate; it is added to
  the systematic part, with a warning. (Fitting each release only while its decay dominates,
  and instrumental variables with instruments from the predicted deterministic decay, were
  measured and dropped: docs/e2rfc_turbulence.md.)

The refits of the extrapolation and one-lag-more parts never count below that same bound (a
refit fluttering below a decaying release contradicts the data: it counts as fluttering
there), and a one-lag-more refit that flutters outside what the data allow (below the bound, or
not at all below the searched speed) counts only when the held-out error does not reject its
structure (:attr:`E2RFCDiagnostics.finer_rejected`): from one short release per wind speed such
refits had made the std as large as the flutter speed.

The turbulence branch (issue 16): when the releases hold a random response and every release
carries a hold of at least :data:`ident.identification._turbulent_fit.MIN_HOLD_S` (the model held in
the wind before it, :class:`~ident.records.release.ReleaseHold`), the model is fitted again by
refined instrumental variables with each hold's force as the noise model
(:mod:`ident.identification._turbulent_fit`), its structure (one or two lags, A3 fitted) chosen by
leave-one-release-out prediction error among the structures that do not flutter below a wind speed
at which a release decayed (A3 zero only when every A3-fitted structure does, :data:`TURBULENT_A3`);
those refits are the jackknife of the turbulence part, the other structures within one standard
error the structure part.
``diagnostics.estimator`` says which estimator ran. Without such holds today's estimator runs,
with a warning that says what turbulence needs. In smooth flow nothing changes.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt
from scipy.stats import t as student_t

from ident.errors import RankDeficiencyError
from ident.identification import _turbulent_fit
from ident.identification._e2rfc_problem import FinalFit, Problem, improves
from ident.identification._regressors import PreparedRelease, prepare
from ident.identification.modal import ModalFit
from ident.model import flutter as _flutter
from ident.model.conventions import derivative_layout, name_modes, reduced_frequency
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.numerics.selection import Candidate, select_one_se, structure_label, within_one_se
from ident.numerics.threads import single_threaded_blas
from ident.records.release import Release

__all__ = ["Candidate", "E2RFCDiagnostics", "FlutterUncertainty", "IdentifiedModel",
           "StructureSpread", "distinct_wind_speeds", "identify", "reduced_frequency_span"]

FloatArray = npt.NDArray[np.float64]

#: Wind speeds closer than this (relative) count as one wind speed.
DISTINCT_U_RTOL = 0.02
#: Names of the still-air modes, in the order of the coordinates ``[h/B, alpha, p/B]``.
MODE_NAMES = ("heave", "pitch", "sway")
#: Least signal of each mode in its own coordinate over a release, in noise standard deviations
#: (the norm of the mode's part of the record over the noise std), that some release at every
#: wind speed must show for a 3-DOF identification.
MODE_SNR_MIN = 20.0
#: A release holds a random response (turbulence) when its modal fit's residual is more than
#: this many times its white measurement noise (module docstring).
RANDOM_RESPONSE_LIMIT = 10.0
#: Variance inflation of the force residuals' autocorrelation above which they are reported as
#: not white (measured: 1.0 for exact Roger aerodynamics, 3 for the exact-Theodorsen plate, 5 to
#: 30 for friction, quadratic damping, a cubic spring or a 10 ms channel delay).
WHITENESS_WARN = 5.0
#: Grid of the flutter analyses of the refitted models (jackknife, extrapolation): they are
#: close to the chosen model, so a coarser grid than a first analysis needs is enough.
REFIT_GRID = 150
#: Largest extrapolation, as the ratio of the lowest covered reduced frequency to the flutter
#: one, accepted without a warning.
EXTRAPOLATION_WARN = 1.1
#: ``diagnostics.estimator`` of today's E2RFC and of the turbulence branch (module docstring).
ESTIMATOR_E2RFC = "E2RFC (modal-fit regressors, least squares)"
ESTIMATOR_TURBULENT = "refined IV with the holds' noise model (turbulence branch)"
#: A3 in the turbulence branch: "fitted-or-zero" (fitted; zero only when every structure with
#: A3 fitted flutters below a wind speed where a release decayed), "fitted" always, "choose"
#: (fitted or zero by held-out error with the lag count), or "e2rfc" as E2RFC's own choice on
#: the same releases has it. docs/e2rfc_turbulence.md measures them: A3 zero lands at -99 %
#: on some bluff-deck seeds whose held-out error prefers it, A3 fitted on some plate seeds
#: whose every A3-fitted structure contradicts the data.
TURBULENT_A3 = "fitted-or-zero"


@dataclass(frozen=True, eq=False)
class E2RFCDiagnostics:
    """What an E2RFC identification found besides the coefficients.

    Attributes
    ----------
    n_lags, with_A3 :
        The chosen structure.
    reason : str
        Why it was chosen (or "given by the caller").
    candidates : tuple of Candidate
        Every structure tried, with its held-out error: the weighted mean squared force error
        over five folds (1 = the noise level).
    release_residuals : ndarray, shape (n_releases, n_dof)
        RMS force residual of each release and force channel relative to that channel's RMS.
    wind_speeds : ndarray, shape (n_releases,)
        m/s.
    condition_number : float
        Of the column-scaled design matrix of the final fit.
    covariance : ndarray, shape (p, p)
        Of the fitted parameters: ``A`` entries (see ``parameter_index``) then ``log d``.
    parameter_index : tuple of (int, int, int)
        ``(k, i, j)`` of ``A[k, i, j]`` for each of the first covariance rows.
    modal_fits : tuple of ModalFit
        Modal fit of each release's displacements ``[h/B, alpha(, p/B)]`` (frequencies,
        damping).
    alternatives : tuple of IdentifiedModel
        The other structures whose held-out error is within one standard error of the best,
        each fitted on every sample as the chosen one is (empty when the caller gave the
        structure).
    random_response : ndarray, shape (n_releases,)
        Each release's modal-fit residual over its white measurement noise (module docstring).
    K_range : dict
        Reduced frequencies ``B omega / U`` each mode covers over the releases (modal fits,
        modes named by their kinetic energy), ``{"heave": (lo, hi), "pitch": (lo, hi)}`` (and
        ``"sway"`` with three degrees of freedom).
    warnings : tuple of str
        What the checks of the data and the model found (random response, force residuals not
        white, a release far worse than the others); :meth:`IdentifiedModel.uncertainty` adds
        the flutter speed's own (extrapolation).

    The refitted models of the uncertainty are computed on first use: :attr:`jackknife` (with
    a random response, the chosen structure fitted with each release left out in turn, those
    whose removal leaves two wind speeds), :attr:`reduced` (fitted without the releases at the
    highest wind speed, with three or more speeds) and :attr:`reduced_K` (what those releases
    cover), :attr:`finer` (one lag more, on every release; None when the data do not
    determine it) and :attr:`finer_rejected`.
    """

    n_lags: int
    with_A3: bool
    reason: str
    candidates: tuple[Candidate, ...]
    release_residuals: FloatArray
    wind_speeds: FloatArray
    condition_number: float
    covariance: FloatArray = field(repr=False)
    parameter_index: tuple[tuple[int, int, int], ...] = field(repr=False)
    modal_fits: tuple[ModalFit, ...] = field(repr=False)
    alternatives: tuple[IdentifiedModel, ...] = field(default=(), repr=False)
    random_response: FloatArray = field(default_factory=lambda: np.zeros(0), repr=False)
    K_range: dict[str, tuple[float, float]] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    estimator: str = ESTIMATOR_E2RFC
    # What the refits need, and their results once computed (on first use: they cost about
    # as much as the identification, and not every caller asks for the uncertainty).
    _prepared: tuple[PreparedRelease, ...] = field(default=(), repr=False)
    _section: SectionModel | None = field(default=None, repr=False)
    _lag_roots: FloatArray = field(default_factory=lambda: np.zeros(0), repr=False)
    _refits: dict[str, object] = field(default_factory=dict, repr=False, compare=False)

    @property
    def turbulent(self) -> bool:
        """Whether the releases hold a random response (median over releases above the limit)."""
        return bool(self.random_response.size
                    and float(np.median(self.random_response)) > RANDOM_RESPONSE_LIMIT)

    @property
    def decayed_at(self) -> float | None:
        """Highest wind speed at which a release's modal fit decays on every mode, m/s.

        The flutter speed lies above it: a model that flutters below contradicts the data.
        None when no release has all its modes (two, or three with sway) decaying.
        """
        n_dof = self.release_residuals.shape[1]
        speeds = [float(U) for U, fit in zip(self.wind_speeds, self.modal_fits, strict=True)
                  if fit.modes.size >= n_dof and bool(np.all(fit.damping > 0.0))]
        return max(speeds) if speeds else None

    @property
    def jackknife(self) -> tuple[RationalFunctionModel, ...]:
        """With a random response: the chosen structure refitted with each release left out."""
        return self._computed("jackknife", self._jackknife)  # type: ignore[return-value]

    @property
    def reduced(self) -> RationalFunctionModel | None:
        """The chosen structure refitted without the highest wind speed (3 or more speeds)."""
        return self._computed("reduced", self._reduced)  # type: ignore[return-value]

    @property
    def reduced_K(self) -> dict[str, tuple[float, float]]:
        """Reduced frequencies the releases of :attr:`reduced` cover, by mode."""
        return self._computed("reduced_K", lambda: _K_ranges(  # type: ignore[return-value]
            self._below_top(), self._section) if self._section is not None else {})

    @property
    def finer(self) -> RationalFunctionModel | None:
        """The chosen structure with one lag more, fitted on every release (or None)."""
        return self._computed("finer", lambda: _refit_finer(  # type: ignore[return-value]
            list(self._prepared), self._lag_roots, self.with_A3) if self._prepared else None)

    @property
    def finer_rejected(self) -> bool:
        """Whether the held-out error rejects :attr:`finer` (see :func:`_rejected`)."""
        return self._computed("finer_rejected", lambda: (  # type: ignore[return-value]
            self.finer is not None and _rejected(list(self._prepared), self.finer,
                                                 self.with_A3, self.candidates)))

    def _computed(self, name: str, compute: Callable[[], object]) -> object:
        if name not in self._refits:
            self._refits[name] = compute()
        return self._refits[name]

    def _below_top(self) -> list[PreparedRelease]:
        speeds = distinct_wind_speeds([p.U for p in self._prepared])
        if len(speeds) < 3:
            return []
        return [p for p in self._prepared if p.U < speeds[-1] / (1 + DISTINCT_U_RTOL)]

    def _reduced(self) -> RationalFunctionModel | None:
        kept = self._below_top()
        return _refit(kept, self._lag_roots, self.with_A3) if kept else None

    @property
    def release_jackknife(self) -> tuple[RationalFunctionModel, ...]:
        """The chosen structure refitted with each release left out in turn (any flow)."""
        return self._computed("release_jackknife",  # type: ignore[return-value]
                              self._leave_one_out)

    def _jackknife(self) -> tuple[RationalFunctionModel, ...]:
        if not self.turbulent:
            return ()
        return self.release_jackknife

    def _leave_one_out(self) -> tuple[RationalFunctionModel, ...]:
        prepared = list(self._prepared)
        subsets = [prepared[:i] + prepared[i + 1:] for i in range(len(prepared))]
        refitted = [_refit(others, self._lag_roots, self.with_A3) for others in subsets
                    if len(distinct_wind_speeds([p.U for p in others])) >= 2]
        return tuple(m for m in refitted if m is not None)


@dataclass(frozen=True)
class FlutterUncertainty:
    """The flutter speed, its standard deviation and where that comes from (m/s).

    Attributes
    ----------
    speed : float or None
        Flutter speed of the chosen model, m/s (None: none below ``U_max``).
    parametric : float
        Measurement noise through the chosen model's parameter covariance.
    structure : float
        Standard deviation of the flutter speeds of the structures within one standard error
        (0 with one structure; one without flutter below ``U_max`` counts as ``U_max``).
    extrapolation : float
        Drift of the flutter speed with the covered reduced frequencies (module docstring).
    refinement : float
        How far the flutter speed moves with one lag more (module docstring).
    turbulence : float
        Release-to-release (jackknife) standard deviation, scaled by Student's 95 % quantile
        over the normal one for its few degrees of freedom; 0 without a random response.
    n_releases : int
    warnings : tuple of str
        The identification's warnings and the flutter speed's own.
    below_decay : float
        How far the flutter speed lies below the highest wind speed at which a release decayed
        on both modes (:attr:`E2RFCDiagnostics.decayed_at`); 0 when it does not.
    """

    speed: float | None
    parametric: float
    structure: float
    extrapolation: float
    refinement: float
    turbulence: float
    n_releases: int
    warnings: tuple[str, ...] = ()
    below_decay: float = 0.0

    @property
    def statistical(self) -> float:
        """The part that averages down with more releases, m/s.

        With a random response the release scatter (jackknife) measures all of the noise, and
        the least-squares covariance, which takes the buffeting for white noise, measures
        nothing: the scatter alone is taken then; otherwise the parametric part.
        """
        return self.turbulence if self.turbulence > 0.0 else self.parametric

    @property
    def total(self) -> float:
        """Standard deviation of the flutter speed, m/s: every part combined."""
        return math.sqrt(self.statistical**2 + self.systematic**2)

    @property
    def systematic(self) -> float:
        """The part more releases at these wind speeds do not reduce, m/s."""
        return math.sqrt(self.structure**2 + self.extrapolation**2 + self.refinement**2
                         + self.below_decay**2)

    def releases_needed(self, target: float) -> int | None:
        """Releases (in the same proportion over the wind speeds) for a total std of ``target``.

        Only the statistical part averages down (as one over the number of releases); None when
        the structure and extrapolation parts alone exceed the target (more releases at these
        wind speeds cannot reach it: releases closer to flutter can).
        """
        fixed = self.systematic**2
        if not math.isfinite(self.total) or target**2 <= fixed:
            return None
        if self.statistical == 0.0:
            return self.n_releases
        return max(self.n_releases,
                   math.ceil(self.n_releases * self.statistical**2 / (target**2 - fixed)))

    def summary(self) -> str:
        """One line, e.g. ``12.10 +- 0.35 m/s (noise 0.05, structure 0.10, ...)``."""
        if self.speed is None:
            return "no flutter below the searched wind speeds"
        parts = [f"noise {self.parametric:.3g}"]
        if self.turbulence:
            parts.append(f"release scatter {self.turbulence:.3g}")
        if self.below_decay:
            parts.append(f"below a decaying release {self.below_decay:.3g}")
        parts += [f"structure {self.structure:.3g}", f"extrapolation {self.extrapolation:.3g}",
                  f"one lag more {self.refinement:.3g}"]
        return f"{self.speed:.3f} +- {self.total:.3f} m/s ({', '.join(parts)})"


@dataclass(frozen=True)
class StructureSpread:
    """Flutter speeds of the structures the held-out error does not tell apart.

    Attributes
    ----------
    labels : tuple of str
        The structures, the chosen one first (e.g. ``n_lags=2, A3=zero``).
    speeds : tuple of float or None
        Flutter speed of each, m/s; None when it has no flutter below ``U_max`` (or, for an
        alternative, no oscillatory still-air modes to start the search from).
    stds : tuple of float or None
        Standard deviation of each from its own parameter covariance, m/s.
    U_max : float
        Upper end of the searched wind speeds, m/s.
    """

    labels: tuple[str, ...]
    speeds: tuple[float | None, ...]
    stds: tuple[float | None, ...]
    U_max: float

    @property
    def low(self) -> float | None:
        """Lowest flutter speed over the structures, m/s (None: none flutters)."""
        found = [u for u in self.speeds if u is not None]
        return min(found) if found else None

    @property
    def high(self) -> float | None:
        """Highest flutter speed, m/s; ``inf`` when a structure has none below ``U_max``."""
        if self.low is None:
            return None
        return math.inf if None in self.speeds else max(u for u in self.speeds if u is not None)

    def range_text(self) -> str:
        """Say the flutter speeds' range, e.g. ``11.91-12.11 m/s over 3 structures``."""
        n = len(self.labels)
        if n == 1:
            return "one structure"
        low, high = self.low, self.high
        if low is None or high is None:
            return f"no flutter below {self.U_max:.3g} m/s over {n} structures"
        if math.isinf(high):
            return f"{low:.2f} m/s to no flutter below {self.U_max:.3g} m/s over {n} structures"
        return f"{low:.2f}-{high:.2f} m/s over {n} structures"

    def summary(self) -> str:
        """One phrase, e.g. ``11.91-12.11 m/s over 3 structures within one SE``."""
        return f"{self.range_text()} within one SE"


class IdentifiedModel(RationalFunctionModel):
    """A :class:`RationalFunctionModel` identified from data, with its diagnostics."""

    __slots__ = ("diagnostics",)

    def __init__(self, A: FloatArray, d: FloatArray, diagnostics: E2RFCDiagnostics) -> None:
        super().__init__(A, d)
        self.diagnostics = diagnostics

    def flutter(
        self, section: SectionModel, U_max: float | None = None
    ) -> tuple[_flutter.FlutterResult, float | None]:
        """Flutter analysis with this model, and the flutter speed's standard deviation.

        The standard deviation is :attr:`FlutterUncertainty.total` (noise, structure,
        extrapolation and, in turbulence, release-to-release scatter); see
        :meth:`uncertainty` for its parts.

        Returns
        -------
        result : FlutterResult
        speed_std : float or None
            m/s; None without flutter below ``U_max``.
        """
        result, uncertainty = self.analysis(section, U_max)
        return result, None if uncertainty.speed is None else uncertainty.total

    def uncertainty(self, section: SectionModel, U_max: float | None = None
                    ) -> FlutterUncertainty:
        """Return the flutter speed and each part of its standard deviation (module docstring)."""
        return self.analysis(section, U_max)[1]

    def analysis(self, section: SectionModel, U_max: float | None = None
                 ) -> tuple[_flutter.FlutterResult, FlutterUncertainty]:
        """Return the flutter analysis and the flutter speed's uncertainty, from one analysis."""
        result, parametric = self._parametric(section, U_max)
        if result.speed is None or parametric is None:
            return result, FlutterUncertainty(None, math.nan, math.nan, math.nan, math.nan,
                                              math.nan, self.diagnostics.wind_speeds.size,
                                              self._no_flutter_warnings(section, result.U_max))
        return result, self._uncertainty(section, result, parametric)

    def _no_flutter_warnings(self, section: SectionModel, U_max: float) -> tuple[str, ...]:
        """Return a model's warnings without flutter; with a random response, the refits' too.

        From releases in turbulence "no flutter below U_max" may be the noise speaking: when
        some of the jackknife refits do flutter below U_max, say so (how many, and where).
        """
        diag = self.diagnostics
        if not diag.turbulent:
            return diag.warnings
        speeds = []
        for model in diag.jackknife:
            try:
                found = _flutter.analyze(section, model, U_max, n_points=REFIT_GRID).speed
            except ValueError:
                # A wild refit (StillAirModesError, a branch the search lost): it says nothing
                # about flutter below U_max.
                continue
            if found is not None:
                speeds.append(float(found))
        if not speeds:
            return diag.warnings
        return (*diag.warnings,
                f"no flutter below {U_max:.3g} m/s, but {len(speeds)} of {len(diag.jackknife)} "
                f"refits with one release left out flutter at {min(speeds):.3g}-"
                f"{max(speeds):.3g} m/s: these releases do not determine the flutter speed")

    def _parametric(self, section: SectionModel, U_max: float | None
                    ) -> tuple[_flutter.FlutterResult, float | None]:
        """Flutter analysis, and the std from the parameter covariance (first-order)."""
        result = _flutter.analyze(section, self, U_max)
        if result.speed is None or result.frequency is None:
            return result, None
        dU_dA, dU_dd = _flutter.speed_sensitivity(section, self, result.speed, result.frequency)
        gradient = np.array(
            [dU_dA[k, i, j] for k, i, j in self.diagnostics.parameter_index]
            + list(dU_dd * self.d)  # the covariance is in log(d)
        )
        variance = float(gradient @ self.diagnostics.covariance @ gradient)
        return result, math.sqrt(max(variance, 0.0))

    def _uncertainty(self, section: SectionModel, result: _flutter.FlutterResult,
                     parametric: float) -> FlutterUncertainty:
        diag = self.diagnostics
        speed = float(result.speed)  # type: ignore[arg-type]  # checked by the callers
        U_max = result.U_max
        warnings = list(diag.warnings)

        def refit_speed(model: RationalFunctionModel) -> float:
            """Flutter speed of a refitted model, m/s.

            A refit without flutter below ``U_max`` (or without two still-air modes, a wild
            refit) counts as ``U_max``: as far as the search can tell, so that the spread stays
            finite and large rather than infinite.
            """
            try:
                found = _flutter.analyze(section, model, U_max, n_points=REFIT_GRID).speed
            except ValueError:  # StillAirModesError, or a branch the search lost
                return U_max
            return U_max if found is None else float(found)

        structure = 0.0
        if diag.alternatives:
            speeds = [speed] + [refit_speed(m) for m in diag.alternatives]
            structure = float(np.std(speeds, ddof=1))
        turbulence = 0.0
        if diag.jackknife:
            pseudo = np.array([refit_speed(m) for m in diag.jackknife])
            n = pseudo.size
            jackknife = float(_jackknife_std(pseudo))
            # A deviation estimated from n releases has n - 1 degrees of freedom: scaled so
            # that 2 of it span Student's 95 % interval (x1.31 for 6 releases, 1.09 for 20).
            turbulence = jackknife * float(student_t.ppf(0.975, max(n - 1, 1))) / 1.96
        # The data bound the flutter speed from below: a release decayed on every mode at
        # `stable`. A refit of the extrapolation or refinement that flutters below it
        # contradicts the data (from a few short releases a four-lag refit was seen to flutter
        # at 0.1 m/s); it counts as fluttering there. Not when the chosen model itself lies
        # below (turbulence): the below-decay part says that.
        stable = diag.decayed_at
        lower = stable if stable is not None and speed >= stable else -math.inf
        extrapolation = 0.0
        K_F = result.reduced_frequency
        mode = result.critical_mode or ""
        K_min = diag.K_range.get(mode, (math.nan, math.nan))[0]
        reduced_K_min = diag.reduced_K.get(mode, (math.nan, math.nan))[0]
        if K_F is not None and math.isfinite(K_min):
            if K_min > EXTRAPOLATION_WARN * K_F:
                warnings.append(
                    f"the flutter speed is extrapolated: the {mode} branch flutters at K = "
                    f"{K_F:.3g}, below the lowest reduced frequency the releases cover on it "
                    f"({K_min:.3g}); releases closer to flutter would cover it")
            if diag.reduced is not None and reduced_K_min > K_F:
                # How far the flutter speed moves when the coverage shrinks, scaled by the
                # ratio of the extrapolation distances (in log K).
                moved = max(refit_speed(diag.reduced), lower)
                reach = max(math.log(K_min / K_F), 0.0) / math.log(reduced_K_min / K_F)
                extrapolation = abs(moved - speed) * min(reach, 1.0)
        refinement = 0.0
        if diag.finer is not None:
            moved = refit_speed(diag.finer)
            # A lag more that flutters outside what the data allow (below `stable`, or not at
            # all below U_max: a "move" set by the searched range) and that the held-out error
            # rejects is fitting the noise: from a few short releases such refits made the std
            # as large as the speed itself. Otherwise its move counts, whatever its held-out
            # error: it is how much the truncation of Roger's form matters (dropping every
            # rejected one cost the 3-DOF bluff deck's 2-std coverage 90 -> 30 %).
            outside = moved >= U_max or moved < lower
            if not (outside and diag.finer_rejected):
                refinement = abs(max(moved, lower) - speed)
        below_decay = 0.0
        if stable is not None and speed < stable:
            # The data say the flutter speed is above a speed where a release decayed: the
            # distance is the least error of this estimate (module docstring).
            below_decay = stable - speed
            warnings.append(
                f"the model flutters at {speed:.3g} m/s, below {stable:.3g} m/s where a release "
                "decayed on every mode: it contradicts the data (in turbulence, the random "
                "response biases the fit); the deviation includes the difference")
        return FlutterUncertainty(speed=speed, parametric=parametric, structure=structure,
                                  extrapolation=extrapolation, refinement=refinement,
                                  turbulence=turbulence,
                                  n_releases=diag.wind_speeds.size, warnings=tuple(warnings),
                                  below_decay=below_decay)

    def flutter_derivative_std(self, K: npt.ArrayLike) -> dict[str, FloatArray]:
        """Return the standard deviation of each flutter derivative at reduced frequencies ``K``.

        The noise part is the larger of the parameter covariance's (first order: a derivative
        is linear in ``A`` and smooth in the lag roots) and the leave-one-release-out
        jackknife's (with three or more refits): the covariance takes the regressors, built from
        the modal fits, as exact, and alone covered only 83-87 % of true errors within 2 std on
        an exact Roger model at 2 % noise; with the jackknife 94-98 %. Added in quadrature: the
        spread over the other structures within one standard error, and the move to the model
        with one lag more (as for the flutter speed).

        Parameters
        ----------
        K : array_like
            Reduced frequencies ``B omega / U``, > 0.

        Returns
        -------
        dict
            Name (``H1``.. as :meth:`flutter_derivatives`) to an array of the shape of ``K``
            (1-D), non-dimensional.
        """
        K_arr = reduced_frequency(np.atleast_1d(K))
        p = 1j * K_arr
        basis = [np.ones_like(p), p, p**2] + [p / (p + d_l) for d_l in self.d]
        # d/dlog d_l of p / (p + d_l), times A_{l+3}: the lag roots' part of the gradient.
        lag_slope = [-p * d_l / (p + d_l) ** 2 for d_l in self.d]
        covariance = self.diagnostics.covariance
        index = self.diagnostics.parameter_index
        n_entries = len(index)
        out = {}
        for name, (i, j, part) in derivative_layout(self.n_dof).items():
            gradient = np.zeros((K_arr.size, covariance.shape[0]), dtype=complex)
            for col, (k, row, column) in enumerate(index):
                if (row, column) == (i, j):
                    gradient[:, col] = basis[k]
            for l, slope in enumerate(lag_slope):  # noqa: E741 - the lag index
                gradient[:, n_entries + l] = self.A[3 + l, i, j] * slope
            g = (gradient.imag if part == "imag" else gradient.real) / (K_arr**2)[:, None]
            out[name] = np.sqrt(np.maximum(np.einsum("kp,pq,kq->k", g, covariance, g), 0.0))
        own = self.flutter_derivatives(K_arr)
        refits = self.diagnostics.release_jackknife
        if len(refits) >= 3:
            # Leave-one-release-out scatter: it also holds the modal fits' errors, which the
            # force regression's covariance (regressors taken as exact) cannot see.
            values = [m.flutter_derivatives(K_arr) for m in refits]
            for name in out:
                jack = _jackknife_std(np.array([v[name] for v in values]))
                out[name] = np.maximum(out[name], jack)
        if self.diagnostics.alternatives:
            values = [own] + [m.flutter_derivatives(K_arr) for m in self.diagnostics.alternatives]
            for name in out:
                spread = np.std([v[name] for v in values], axis=0, ddof=1)
                out[name] = np.sqrt(out[name] ** 2 + spread**2)
        finer = self.diagnostics.finer
        if finer is not None:
            moved = finer.flutter_derivatives(K_arr)
            for name in out:
                out[name] = np.sqrt(out[name] ** 2 + (moved[name] - own[name]) ** 2)
        return out

    def structure_spread(self, section: SectionModel, U_max: float | None = None
                         ) -> StructureSpread:
        """Flutter speed of this model and of every alternative structure within one SE.

        With one short release per wind speed the held-out error often cannot tell one lag from
        two; the structures it cannot tell apart may predict flutter speeds further apart than
        the chosen one's standard deviation. Report this spread next to that deviation.

        Parameters
        ----------
        section : SectionModel
        U_max : float, optional
            Upper end of the searched wind speeds, m/s (default:
            :func:`ident.model.flutter.analyze`'s).

        Returns
        -------
        StructureSpread
        """
        result, std = self._parametric(section, U_max)
        searched = result.U_max
        labels = [structure_label(self.diagnostics.n_lags, self.diagnostics.with_A3)]
        speeds, stds = [result.speed], [std]
        for model in self.diagnostics.alternatives:
            labels.append(structure_label(model.diagnostics.n_lags, model.diagnostics.with_A3))
            try:
                result, std = model._parametric(section, U_max)
            except ValueError:
                # As in the flutter speed's structure term: an alternative whose added mass
                # overturns the structure's (StillAirModesError: from releases at two low
                # speeds, it happens) or whose branch the search loses has no flutter the
                # search can find; it widens the spread to "no flutter".
                speeds.append(None)
                stds.append(None)
                continue
            speeds.append(result.speed)
            stds.append(std)
        return StructureSpread(tuple(labels), tuple(speeds), tuple(stds), float(searched))


@single_threaded_blas
def identify(
    releases: Sequence[Release],
    section: SectionModel,
    n_lags: int | None = None,
    with_A3: bool | None = None,
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
    prepared = [prepare(r, section) for r in releases]
    if section.n_dof == 3:
        _check_modes_excited(prepared, section)
    model = _identify_prepared(prepared, section, n_lags, with_A3)
    if not model.diagnostics.turbulent:
        return model
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
                    "and the least-squares covariance do not hold; the flutter speed's "
                    "deviation is the release-to-release scatter")
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
            K_range=_K_ranges(prepared, self.section), warnings=tuple(warnings),
            _prepared=tuple(prepared), _section=self.section, _lag_roots=fit.d)
        return IdentifiedModel(fit.A, fit.d, diagnostics)


def _with_reason(found: _turbulent_fit.TurbulentResult, why: str
                               ) -> _turbulent_fit.TurbulentResult:
    """Return a turbulence-branch result whose reason starts with ``why``."""
    return replace(found, reason=f"{why}: {found.reason}")


def _K_ranges(prepared: list[PreparedRelease], section: SectionModel
              ) -> dict[str, tuple[float, float]]:
    """Reduced frequencies ``B omega / U`` each mode covers over the releases, by mode name."""
    K: dict[str, list[float]] = {name: [] for name in MODE_NAMES}
    for p in prepared:
        fit = p.fit
        if fit.modes.size < p.n_dof:
            continue
        named = name_modes(fit.mode_shapes(), section.mass_matrix())
        for name, i in zip(MODE_NAMES, named, strict=False):
            K[name].append(2 * math.pi * float(fit.frequencies[i]) * p.B / p.U)
    return {name: (min(v), max(v)) for name, v in K.items() if v}


def _refit(prepared: list[PreparedRelease], d: FloatArray, with_A3: bool
           ) -> RationalFunctionModel | None:
    """Fit a structure (lag roots ``d`` as the start) again on some of the releases."""
    refit = Problem(prepared).refit(d.size, with_A3, [d])
    return None if refit is None else RationalFunctionModel(refit.A, refit.d)


def _refit_finer(prepared: list[PreparedRelease], d: FloatArray, with_A3: bool
                 ) -> RationalFunctionModel | None:
    """Fit a structure with one lag more (None when the data cannot determine it)."""
    problem = Problem(prepared)
    K_lo, K_hi = problem.K_range
    starts = [np.sort(np.append(d, root)) for root in (K_lo / 2.0, 2.0 * K_hi)]
    refit = problem.refit(d.size + 1, with_A3, starts)
    return None if refit is None else RationalFunctionModel(refit.A, refit.d)


def _rejected(prepared: list[PreparedRelease], model: RationalFunctionModel, with_A3: bool,
              candidates: Sequence[Candidate]) -> bool:
    """Whether the held-out error rejects a refitted structure.

    Rejected: its held-out error is more than one standard error above the best scored
    candidate's (an alternative structure must be within it). Never with no scored candidate
    (a structure given by the caller).
    """
    scored = [c for c in candidates if math.isfinite(c.cv_error)]
    if not scored:
        return False
    best = min(scored, key=lambda c: c.cv_error)
    return Problem(prepared).held_out_error(model.d, with_A3) > best.cv_error + best.cv_se


def _jackknife_std(pseudo: FloatArray) -> FloatArray:
    """Jackknife standard deviation from leave-one-out estimates (first axis: the n refits)."""
    n = pseudo.shape[0]
    return np.asarray(np.sqrt((n - 1) / n * np.sum((pseudo - pseudo.mean(axis=0)) ** 2, axis=0)),
                      dtype=float)


def _random_response(fit: ModalFit) -> float:
    """Return a release's modal-fit residual over its white measurement noise (larger channel)."""
    scale = np.maximum(fit.noise, 1e-9 * np.maximum(fit.residual_rms, 1e-300))
    return float(np.max(fit.residual_rms / scale)) if np.any(fit.residual_rms > 0) else 0.0


def distinct_wind_speeds(speeds: Sequence[float]) -> list[float]:
    """Return the wind speeds that count as distinct for E2RFC, increasing, m/s.

    A speed within ``DISTINCT_U_RTOL`` above the last distinct one is the same wind speed.
    """
    out: list[float] = []
    for u in sorted(speeds):
        if not out or u > out[-1] * (1 + DISTINCT_U_RTOL):
            out.append(float(u))
    return out


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

