"""The flutter speed's uncertainty from an E2RFC identification, and its parts.

How uncertain the flutter speed is (:meth:`IdentifiedModel.uncertainty`), from these sources:

- *parametric*: measurement noise through the chosen model's parameter covariance;
- *structure*: the other structures within one standard error are fitted too
  (``diagnostics.alternatives``): the data do not tell them apart, and the spread of their
  flutter speeds is an uncertainty that one structure's covariance cannot show;
- *extrapolation*: the flutter speed lies beyond the wind speeds released at, at a lower reduced
  frequency than the releases cover, where a rational function fitted over the covered range
  can drift (real decks are not exactly of Roger's form). With releases at three or more wind
  speeds the model is fitted again without the highest one; how far its flutter speed moves,
  scaled by how much farther it extrapolates, measures that drift. Where the refit's estimator
  gives its own covariance (the closed-loop branch), the move's statistical scatter is taken
  off first: for two efficient fits of nested data the variance of their difference is the
  difference of their variances (Hausman's argument), and the parametric part already
  carries the full fit's own. What is left of the move's square beyond that is the drift;
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
  measured and dropped: docs/development/e2rfc_turbulence.md.)
- *cross-check*: when the closed-loop estimator of turbulence fails its own checks (its
  innovations far from white, or its search not converged: the data hold something its model
  cannot describe), the other estimator runs on the same releases
  (:attr:`E2RFCDiagnostics.cross_check`) and the distance between the two flutter speeds is
  added to the systematic part, with a warning: two routes to one number that disagree.

The interval (:meth:`FlutterUncertainty.interval`) is not the std either side of the estimate:
the flutter speed is extrapolated beyond the highest wind speed the releases show stable, and
its std grows with that distance, so an estimate that falls short carries a narrow std just
where the truth lies further out. It is drawn symmetric in the log of that distance.

The refits of the extrapolation and one-lag-more parts never count below that same bound (a
refit fluttering below a decaying release contradicts the data: it counts as fluttering
there), and a one-lag-more refit that flutters outside what the data allow (below the bound, or
not at all below the searched speed) counts only when the held-out error does not reject its
structure (:attr:`E2RFCDiagnostics.finer_rejected`): from one short release per wind speed such
refits had made the std as large as the flutter speed.

The functions here read what they need of an identification through
:class:`UncertaintySources` (the attributes of
:class:`~ident.identification.results.E2RFCDiagnostics`, which computes the refits on first
use); :class:`~ident.identification.results.IdentifiedModel` calls them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt
from scipy.stats import t as student_t

from ident.model import flutter as _flutter
from ident.model.conventions import derivative_layout, reduced_frequency
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.records.plausibility import UNUSUAL_REDUCED_VELOCITY, reduced_velocity_warnings

__all__ = ["CEILING_WARN", "DISTINCT_U_RTOL", "EXTRAPOLATION_WARN", "REFIT_GRID",
           "FlutterUncertainty", "UncertaintySources",
           "ceiling_warnings", "distinct_wind_speeds", "flutter_derivative_std",
           "flutter_uncertainty", "jackknife_std", "nearest_wind_speed", "no_flutter_warnings",
           "parametric"]

FloatArray = npt.NDArray[np.float64]

#: Wind speeds closer than this (relative) count as one wind speed.
DISTINCT_U_RTOL = 0.02

#: Grid of the flutter analyses of the refitted models (jackknife, extrapolation): they are
#: close to the chosen model, so a coarser grid than a first analysis needs is enough.
REFIT_GRID = 150
#: Largest extrapolation, as the ratio of the lowest covered reduced frequency to the flutter
#: one, accepted without a warning.
EXTRAPOLATION_WARN = 1.1
#: Without flutter below the search's ceiling ``U_max``, releases that reach this fraction of
#: it are warned of: their reduced velocities are beyond most decks' flutter point (the
#: default ceiling is a reduced velocity ``U / (f B)`` of about 31 for the faster mode), and
#: "no flutter" then rests on little room above the data. Campaigns reach 0.2-0.3 of it; wind
#: speeds in km/h (x 3.6) or mph (x 2.24) put them at 0.6-0.9.
CEILING_WARN = 0.5


class UncertaintySources(Protocol):
    """What the uncertainty reads of an identification (its diagnostics and refits)."""

    @property
    def warnings(self) -> tuple[str, ...]: ...  # noqa: D102
    @property
    def wind_speeds(self) -> FloatArray: ...  # noqa: D102
    @property
    def covariance(self) -> FloatArray: ...  # noqa: D102
    @property
    def parameter_index(self) -> tuple[tuple[int, int, int], ...]: ...  # noqa: D102
    @property
    def alternatives(self) -> tuple[RationalFunctionModel, ...]: ...  # noqa: D102
    @property
    def K_range(self) -> dict[str, tuple[float, float]]: ...  # noqa: D102
    @property
    def turbulent(self) -> bool: ...  # noqa: D102
    @property
    def decayed_at(self) -> float | None: ...  # noqa: D102
    @property
    def jackknife(self) -> tuple[RationalFunctionModel, ...]: ...  # noqa: D102
    @property
    def release_jackknife(self) -> tuple[RationalFunctionModel, ...]: ...  # noqa: D102
    @property
    def reduced(self) -> RationalFunctionModel | None: ...  # noqa: D102
    @property
    def reduced_K(self) -> dict[str, tuple[float, float]]: ...  # noqa: D102
    @property
    def reduced_covariance(self) -> FloatArray | None: ...  # noqa: D102
    @property
    def finer(self) -> RationalFunctionModel | None: ...  # noqa: D102
    @property
    def finer_rejected(self) -> bool: ...  # noqa: D102
    @property
    def cross_check(self) -> tuple[str, RationalFunctionModel] | None: ...  # noqa: D102


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
    cross_check : float
        How far the other turbulence estimator's flutter speed lies from this one when the
        closed-loop fit failed its own checks (:attr:`E2RFCDiagnostics.cross_check`); 0
        otherwise.
    floor : float or None
        The highest wind speed at which the releases show the section stable (one decayed on
        every mode, or closed-loop none grew), when the flutter speed lies above it; m/s.
        :meth:`interval` is drawn beyond it. None otherwise.
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
    cross_check: float = 0.0
    floor: float | None = None

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
                         + self.below_decay**2 + self.cross_check**2)

    def interval(self, k: float = 2.0) -> tuple[float, float]:
        """Return the flutter speed's ``k``-std interval, m/s (NaN, NaN without a flutter speed).

        The flutter speed is extrapolated beyond :attr:`floor`, the highest wind speed the
        releases show stable, from how the damping falls with the wind speed: its std grows
        with the distance ``d = speed - floor`` (an estimate that falls short of the truth
        carries a proportionally narrower std: on the benchmark's turbulence rows std / d
        stayed about 0.27 whether the estimate was 8 % low or on the truth). The interval is
        then ``k`` std of ``log d`` either side, ``total / d`` each: ``floor + d exp(+-k
        total / d)``, longer above than below, and never reaching below the floor the data
        set. Without a floor (no release seen stable, or the flutter speed below one) it is
        ``speed +- k total``.
        """
        if self.speed is None:
            return math.nan, math.nan
        total = self.total
        if self.floor is None or not math.isfinite(total):
            return self.speed - k * total, self.speed + k * total
        distance = self.speed - self.floor
        spread = min(k * total / distance, 700.0)  # e^700: no upper end, without an overflow
        return (self.floor + distance * math.exp(-spread),
                self.floor + distance * math.exp(spread))

    def parts(self) -> dict[str, float]:
        """Return the std's parts by their JSON names (``flutter_std_parts``), m/s."""
        return {"noise": self.parametric, "structure": self.structure,
                "extrapolation": self.extrapolation, "one_lag_more": self.refinement,
                "release_scatter": self.turbulence, "below_decaying_release": self.below_decay,
                "other_estimator": self.cross_check}

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
        if self.cross_check:
            parts.append(f"other estimator {self.cross_check:.3g}")
        parts += [f"structure {self.structure:.3g}", f"extrapolation {self.extrapolation:.3g}",
                  f"one lag more {self.refinement:.3g}"]
        low, high = self.interval()
        return (f"{self.speed:.3f} +- {self.total:.3f} m/s, 2-std interval {low:.3f} to "
                f"{high:.3f} ({', '.join(parts)})")


def parametric(section: SectionModel, model: RationalFunctionModel, sources: UncertaintySources,
               U_max: float | None) -> tuple[_flutter.FlutterResult, float | None]:
    """Flutter analysis, and the std from the parameter covariance (first-order)."""
    result = _flutter.analyze(section, model, U_max)
    if result.speed is None or result.frequency is None:
        return result, None
    return result, _first_order_std(section, model, result, sources.parameter_index,
                                    sources.covariance)


def _first_order_std(section: SectionModel, model: RationalFunctionModel,
                     result: _flutter.FlutterResult, index: Sequence[tuple[int, int, int]],
                     covariance: FloatArray) -> float:
    """Return the flutter speed's std from a parameter covariance, to first order (m/s).

    ``result`` is ``model``'s flutter analysis, with a flutter speed (NaN without one);
    ``covariance`` is over the coefficients at ``index`` and the log lag roots.
    """
    if result.speed is None or result.frequency is None:
        return math.nan
    dU_dA, dU_dd = _flutter.speed_sensitivity(section, model, result.speed, result.frequency)
    gradient = np.array(
        [dU_dA[k, i, j] for k, i, j in index]
        + list(dU_dd * model.d)  # the covariance is in log(d)
    )
    variance = float(gradient @ covariance @ gradient)
    return math.sqrt(max(variance, 0.0))


def _move_scatter(section: SectionModel, model: RationalFunctionModel,
                  found: _flutter.FlutterResult | None, covariance: FloatArray | None,
                  index: Sequence[tuple[int, int, int]], parametric: float) -> float:
    """Std of the extrapolation refit's move from statistics alone (m/s); 0 if unknown.

    ``found`` is the refit ``model``'s flutter analysis (None: a wild refit without two
    still-air modes). Hausman's argument: the refit on a subset of the data and the full fit
    are both efficient, so their difference has the variance ``var(refit) - var(full)``.
    Without a covariance, a flutter speed or two still-air modes, the move is kept whole.
    """
    if covariance is None or found is None:
        return 0.0
    refit = _first_order_std(section, model, found, index, covariance)
    if not math.isfinite(refit):  # no flutter below U_max
        return 0.0
    return math.sqrt(max(refit**2 - parametric**2, 0.0))


def flutter_uncertainty(section: SectionModel, result: _flutter.FlutterResult, parametric: float,
                        sources: UncertaintySources) -> FlutterUncertainty:
    """Return the flutter speed's uncertainty, every part (module docstring), with its warnings.

    ``result`` is the chosen model's flutter analysis (with a flutter speed) and ``parametric``
    the standard deviation from its parameter covariance (:func:`parametric`), m/s.
    """
    diag = sources
    speed = float(result.speed)  # type: ignore[arg-type]  # checked by the callers
    U_max = result.U_max
    warnings = list(diag.warnings)

    def refit_analysis(model: RationalFunctionModel) -> _flutter.FlutterResult | None:
        """Flutter analysis of a refitted model (None without two still-air modes)."""
        try:
            return _flutter.analyze(section, model, U_max, n_points=REFIT_GRID)
        except ValueError:  # StillAirModesError, or a branch the search lost
            return None

    def speed_of(found: _flutter.FlutterResult | None) -> float:
        """Flutter speed of a refit's analysis, m/s.

        A refit without flutter below ``U_max`` (or without two still-air modes, a wild
        refit) counts as ``U_max``: as far as the search can tell, so that the spread stays
        finite and large rather than infinite.
        """
        return U_max if found is None or found.speed is None else float(found.speed)

    def refit_speed(model: RationalFunctionModel) -> float:
        return speed_of(refit_analysis(model))

    structure = 0.0
    if diag.alternatives:
        speeds = [speed] + [refit_speed(m) for m in diag.alternatives]
        structure = float(np.std(speeds, ddof=1))
    turbulence = 0.0
    if diag.jackknife:
        pseudo = np.array([refit_speed(m) for m in diag.jackknife])
        n = pseudo.size
        jackknife = float(jackknife_std(pseudo))
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
        reduced = diag.reduced if reduced_K_min > K_F else None  # the refit only if it counts
        if reduced is not None:
            # How far the flutter speed moves when the coverage shrinks, scaled by the
            # ratio of the extrapolation distances (in log K).
            analysis = refit_analysis(reduced)
            moved = max(speed_of(analysis), lower)
            reach = max(math.log(K_min / K_F), 0.0) / math.log(reduced_K_min / K_F)
            scatter = _move_scatter(section, reduced, analysis, diag.reduced_covariance,
                                    diag.parameter_index, parametric)
            drift = math.sqrt(max((moved - speed)**2 - scatter**2, 0.0))
            extrapolation = drift * min(reach, 1.0)
        elif reduced_K_min > K_F and len(distinct_wind_speeds(list(diag.wind_speeds))) >= 3:
            warnings.append(
                "the refit without the highest wind speed failed, so the std has no "
                "extrapolation part although the flutter speed lies beyond what the lower "
                "speeds cover: the std is too small by that part")
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
            "decayed on every mode (or, closed-loop, no release grew): it contradicts the "
            "data (in turbulence, the random response biases the fit); the deviation "
            "includes the difference")
    cross_check = 0.0
    if diag.cross_check is not None:
        # The two routes' distance, the other's speed held to what the data allow as above.
        name, other = diag.cross_check
        moved = max(refit_speed(other), lower)
        cross_check = abs(moved - speed)
        found = (f"finds no flutter below {U_max:.3g} m/s" if moved >= U_max else
                 f"puts the flutter speed at {moved:.3g} m/s ({100 * (moved / speed - 1):+.0f} %)")
        warnings.append(f"{name} on the same releases {found}; the deviation includes the "
                        "difference")
    warnings.extend(reduced_velocity_warnings(section, speed))
    return FlutterUncertainty(speed=speed, parametric=parametric, structure=structure,
                              extrapolation=extrapolation, refinement=refinement,
                              turbulence=turbulence,
                              n_releases=diag.wind_speeds.size, warnings=tuple(warnings),
                              below_decay=below_decay, cross_check=cross_check,
                              floor=stable if stable is not None and speed > stable else None)


def no_flutter_warnings(section: SectionModel, sources: UncertaintySources, U_max: float
                        ) -> tuple[str, ...]:
    """Return a model's warnings without flutter; with a random response, the refits' too.

    From releases in turbulence "no flutter below U_max" may be the noise speaking: when
    some of the jackknife refits do flutter below U_max, say so (how many, and where).
    """
    diag = sources
    ceiling = ceiling_warnings(section, diag.wind_speeds, U_max)
    if not diag.turbulent:
        return (*diag.warnings, *ceiling)
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
        return (*diag.warnings, *ceiling)
    return (*diag.warnings, *ceiling,
            f"no flutter below {U_max:.3g} m/s, but {len(speeds)} of {len(diag.jackknife)} "
            f"refits with one release left out flutter at {min(speeds):.3g}-"
            f"{max(speeds):.3g} m/s: these releases do not determine the flutter speed")


def ceiling_warnings(section: SectionModel, speeds: npt.ArrayLike, U_max: float
                     ) -> tuple[str, ...]:
    """Warn of "no flutter below U_max" from releases close to ``U_max`` (:data:`CEILING_WARN`).

    Parameters
    ----------
    section : SectionModel
    speeds : array_like
        The releases' wind speeds, m/s.
    U_max : float
        The flutter search's ceiling, m/s.

    Returns
    -------
    tuple of str
        One warning when the releases reach :data:`CEILING_WARN` of ``U_max`` (naming km/h and
        mph beyond :data:`~ident.records.plausibility.UNUSUAL_REDUCED_VELOCITY`), else none.
    """
    top = float(np.max(speeds)) if np.size(speeds) else 0.0
    if top < CEILING_WARN * U_max:
        return ()
    f_fast = max(section.fh, section.fa)
    reduced_velocity = top / (f_fast * section.B)
    units = ("" if reduced_velocity <= UNUSUAL_REDUCED_VELOCITY else
             f"; their reduced velocity U / (f B) of {reduced_velocity:.3g} for the {f_fast:g} "
             "Hz mode is beyond most decks' flutter point: if the wind speeds are in km/h or "
             "mph, convert them to m/s (/3.6, /2.237)")
    return (f"no flutter below {U_max:.3g} m/s, but the releases reach {top:.3g} m/s, "
            f"{top / U_max:.2f} of that ceiling: search further (U_max) before calling the "
            f"section stable{units}",)


def flutter_derivative_std(model: RationalFunctionModel, sources: UncertaintySources,
                           K: npt.ArrayLike) -> dict[str, FloatArray]:
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
        Name (``H1``.. as :meth:`RationalFunctionModel.flutter_derivatives`) to an array of
        the shape of ``K`` (1-D), non-dimensional.
    """
    K_arr = reduced_frequency(np.atleast_1d(K))
    p = 1j * K_arr
    basis = [np.ones_like(p), p, p**2] + [p / (p + d_l) for d_l in model.d]
    # d/dlog d_l of p / (p + d_l), times A_{l+3}: the lag roots' part of the gradient.
    lag_slope = [-p * d_l / (p + d_l) ** 2 for d_l in model.d]
    covariance = sources.covariance
    index = sources.parameter_index
    n_entries = len(index)
    out = {}
    for name, (i, j, part) in derivative_layout(model.n_dof).items():
        gradient = np.zeros((K_arr.size, covariance.shape[0]), dtype=complex)
        for col, (k, row, column) in enumerate(index):
            if (row, column) == (i, j):
                gradient[:, col] = basis[k]
        for l, slope in enumerate(lag_slope):  # noqa: E741 - the lag index
            gradient[:, n_entries + l] = model.A[3 + l, i, j] * slope
        g = (gradient.imag if part == "imag" else gradient.real) / (K_arr**2)[:, None]
        out[name] = np.sqrt(np.maximum(np.einsum("kp,pq,kq->k", g, covariance, g), 0.0))
    own = model.flutter_derivatives(K_arr)
    refits = sources.release_jackknife
    if len(refits) >= 3:
        # Leave-one-release-out scatter: it also holds the modal fits' errors, which the
        # force regression's covariance (regressors taken as exact) cannot see.
        values = [m.flutter_derivatives(K_arr) for m in refits]
        for name in out:
            jack = jackknife_std(np.array([v[name] for v in values]))
            out[name] = np.maximum(out[name], jack)
    if sources.alternatives:
        values = [own] + [m.flutter_derivatives(K_arr) for m in sources.alternatives]
        for name in out:
            spread = np.std([v[name] for v in values], axis=0, ddof=1)
            out[name] = np.sqrt(out[name] ** 2 + spread**2)
    finer = sources.finer
    if finer is not None:
        moved = finer.flutter_derivatives(K_arr)
        for name in out:
            out[name] = np.sqrt(out[name] ** 2 + (moved[name] - own[name]) ** 2)
    return out


def jackknife_std(pseudo: FloatArray) -> FloatArray:
    """Jackknife standard deviation from leave-one-out estimates (first axis: the n refits)."""
    n = pseudo.shape[0]
    return np.asarray(np.sqrt((n - 1) / n * np.sum((pseudo - pseudo.mean(axis=0)) ** 2, axis=0)),
                      dtype=float)


def distinct_wind_speeds(speeds: Sequence[float]) -> list[float]:
    """Return the wind speeds that count as distinct for E2RFC, increasing, m/s.

    A speed within ``DISTINCT_U_RTOL`` above the last distinct one is the same wind speed.
    """
    out: list[float] = []
    for u in sorted(speeds):
        if not out or u > out[-1] * (1 + DISTINCT_U_RTOL):
            out.append(float(u))
    return out


def nearest_wind_speed(U: float, speeds: Sequence[float]) -> int:
    """Return the index of the speed in ``speeds`` (distinct ones, m/s) nearest to ``U``, m/s."""
    return int(np.argmin([abs(U - u) for u in speeds]))
