"""What E2RFC returns: the identified model, its diagnostics and the spread over structures.

:class:`IdentifiedModel` is a :class:`~ident.model.rfc.RationalFunctionModel` with the
identification's :class:`E2RFCDiagnostics` (the structure chosen and why, the candidates, the
parameter covariance, the modal fits, the data checks' warnings). The refitted models its
uncertainty needs (leave one release out, without the highest wind speed, one lag more) are
computed on first use, here; how they become the flutter speed's standard deviation is
:mod:`ident.identification.uncertainty`. :class:`StructureSpread` is the flutter speed of every
structure the held-out error does not tell apart.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from ident.identification import uncertainty as unc
from ident.identification._e2rfc_problem import Problem
from ident.identification._regressors import PreparedRelease
from ident.identification.modal import ModalFit
from ident.identification.uncertainty import (
    DISTINCT_U_RTOL,
    FlutterUncertainty,
    distinct_wind_speeds,
)
from ident.model import flutter as _flutter
from ident.model.conventions import name_modes
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.numerics.selection import Candidate, structure_label

__all__ = ["DISTINCT_U_RTOL", "Deferred", "E2RFCDiagnostics", "ESTIMATOR_E2RFC", "GROWTH_LIMIT",
           "HELD_LOAD_LIMIT", "IdentifiedModel", "K_ranges", "MODE_NAMES",
           "RANDOM_RESPONSE_LIMIT", "StructureSpread", "WEAK_RANDOM_RESPONSE",
           "distinct_wind_speeds", "is_turbulent"]

FloatArray = npt.NDArray[np.float64]

#: Names of the still-air modes, in the order of the coordinates ``[h/B, alpha, p/B]``.
MODE_NAMES = ("heave", "pitch", "sway")
#: A release holds a random response (turbulence) when its modal fit's residual is more than
#: this many times its white measurement noise (:mod:`ident.identification.uncertainty`).
RANDOM_RESPONSE_LIMIT = 10.0
#: A median decay residual this many times the noise, under :data:`RANDOM_RESPONSE_LIMIT`, is
#: weak turbulence when the holds show the wind loading the held model (:func:`is_turbulent`),
#: and otherwise adds weak buffeting to the causes of residuals that are not white. Measured
#: with 2 % noise: the plate's smooth releases 1.0 clean, 3-4 with realistic friction, 6-10
#: with a vibrating floor; the 3-DOF bluff deck at Iw 1 %: 7-21 per release, medians 8-14.
WEAK_RANDOM_RESPONSE = 5.0
#: Median over the holds of their forces' fluctuation over white noise
#: (:attr:`~ident.records.release.ReleaseHold.random_load`) above which the holds show a
#: random wind load. Measured with 2 % noise: 1.00-1.02 in smooth flow (with friction, a
#: vibrating floor or a channel delay alike), 1.7-1.9 at 0.3 % turbulence, 4-5 at 1 % (the
#: 3-DOF bluff deck); vortex shedding 24, but its decays' residual stays at 1.
HELD_LOAD_LIMIT = 2.0
#: ``diagnostics.estimator`` of E2RFC's least squares (the turbulence branch names its own).
ESTIMATOR_E2RFC = "E2RFC (modal-fit regressors, least squares)"


class Deferred:
    """A refit another estimator supplies, computed when the uncertainty first asks for it.

    Parameters
    ----------
    compute : callable
        Returns the refitted model (or None).
    """

    def __init__(self, compute: Callable[[], object]) -> None:
        self.compute = compute


#: A release's motion "grew" when the RMS of a displacement over the last quarter of its record
#: exceeds this many times that over the first quarter. A release below flutter in turbulence
#: decays into a stationary random response (ratio about 1 or less; 5 s estimates of a lightly
#: damped response scatter by tens of per cent); one above flutter grows without bound (1.03
#: U_F: the pitch amplitude more than doubles within 20 s).
GROWTH_LIMIT = 2.0


def is_turbulent(random_response: npt.ArrayLike, held_load: npt.ArrayLike = ()) -> bool:
    """Tell whether releases hold a random response (turbulence).

    Their modal fits' residual over the noise (median over the releases) is above
    :data:`RANDOM_RESPONSE_LIMIT`; or above :data:`WEAK_RANDOM_RESPONSE` while the holds
    before them show the wind loading the held model at random (median over the holds above
    :data:`HELD_LOAD_LIMIT`). The second rule takes weak turbulence for what it is where the
    holds measure it: a decay residual of 5-10 alone is also what a vibrating floor gives, whose
    holds stay at their noise.
    """
    rr = np.asarray(random_response, dtype=float)
    held = np.asarray(held_load, dtype=float)
    if not rr.size:
        return False
    ratio = float(np.median(rr))
    return bool(ratio > RANDOM_RESPONSE_LIMIT
                or (ratio > WEAK_RANDOM_RESPONSE and held.size
                    and float(np.median(held)) > HELD_LOAD_LIMIT))


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
    held_load : ndarray, shape (n_holds,)
        Each hold's force fluctuation over its white noise
        (:attr:`~ident.records.release.ReleaseHold.random_load`); empty without holds.
    K_range : dict
        Reduced frequencies ``B omega / U`` each mode covers over the releases (modal fits,
        modes named by their kinetic energy), ``{"heave": (lo, hi), "pitch": (lo, hi)}`` (and
        ``"sway"`` with three degrees of freedom).
    bounded_at : float or None
        The closed-loop branch's: the highest wind speed at which no release's motion grew
        over its record (:data:`GROWTH_LIMIT`), m/s; a flutter speed lies above it, as above
        :attr:`decayed_at`. None elsewhere.
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
    held_load: FloatArray = field(default_factory=lambda: np.zeros(0), repr=False)
    K_range: dict[str, tuple[float, float]] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    estimator: str = ESTIMATOR_E2RFC
    bounded_at: float | None = None
    # What the refits need, and their results once computed (on first use: they cost about
    # as much as the identification, and not every caller asks for the uncertainty).
    _prepared: tuple[PreparedRelease, ...] = field(default=(), repr=False)
    _section: SectionModel | None = field(default=None, repr=False)
    _lag_roots: FloatArray = field(default_factory=lambda: np.zeros(0), repr=False)
    _refits: dict[str, object] = field(default_factory=dict, repr=False, compare=False)

    @property
    def turbulent(self) -> bool:
        """Whether the releases hold a random response (:func:`is_turbulent`)."""
        return is_turbulent(self.random_response, self.held_load)

    @property
    def decayed_at(self) -> float | None:
        """Highest wind speed at which a release's modal fit decays on every mode, m/s.

        The flutter speed lies above it: a model that flutters below contradicts the data.
        None when no release has all its modes (two, or three with sway) decaying. With the
        closed-loop branch, at least :attr:`bounded_at` (in turbulence the modal fits of a
        random response rarely decay on every mode, while the records stay bounded).
        """
        n_dof = self.release_residuals.shape[1]
        speeds = [float(U) for U, fit in zip(self.wind_speeds, self.modal_fits, strict=True)
                  if fit.modes.size >= n_dof and bool(np.all(fit.damping > 0.0))]
        if self.bounded_at is not None:
            speeds.append(self.bounded_at)
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
    def reduced_covariance(self) -> FloatArray | None:
        """Covariance of :attr:`reduced`'s parameters, in :attr:`parameter_index`'s layout.

        Given where the refit's estimator has one of its own (the closed-loop branch's inverse
        Fisher information); None otherwise. The extrapolation part takes the statistical
        scatter of the refit's move off with it (:func:`~ident.identification.uncertainty.
        flutter_uncertainty`).
        """
        return self._computed("reduced_covariance", lambda: None)  # type: ignore[return-value]

    @property
    def reduced_K(self) -> dict[str, tuple[float, float]]:
        """Reduced frequencies the releases of :attr:`reduced` cover, by mode."""
        return self._computed("reduced_K", lambda: K_ranges(  # type: ignore[return-value]
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

    @property
    def cross_check(self) -> tuple[str, RationalFunctionModel] | None:
        """The other turbulence estimator's model, named, when the chosen one failed its checks.

        Set by the closed-loop branch (:func:`ident.identification.e2rfc.identify`) when its
        fit fails its own checks; None otherwise.
        """
        return self._computed("cross_check", lambda: None)  # type: ignore[return-value]

    def _computed(self, name: str, compute: Callable[[], object]) -> object:
        value = self._refits[name] if name in self._refits else compute()
        if isinstance(value, Deferred):  # another estimator's refit, run on first use
            value = value.compute()
        self._refits[name] = value
        return value

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
            return result, FlutterUncertainty(
                None, math.nan, math.nan, math.nan, math.nan, math.nan,
                self.diagnostics.wind_speeds.size,
                unc.no_flutter_warnings(section, self.diagnostics, result.U_max))
        return result, unc.flutter_uncertainty(section, result, parametric,
                                               self.diagnostics)

    def _parametric(self, section: SectionModel, U_max: float | None
                    ) -> tuple[_flutter.FlutterResult, float | None]:
        """Flutter analysis, and the std from the parameter covariance (first-order)."""
        return unc.parametric(section, self, self.diagnostics, U_max)

    def flutter_derivative_std(self, K: npt.ArrayLike) -> dict[str, FloatArray]:
        """Return the standard deviation of each flutter derivative at reduced frequencies ``K``.

        See :func:`ident.identification.uncertainty.flutter_derivative_std`: the parameter
        covariance or the release jackknife, the structures within one SE, one lag more.

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
        return unc.flutter_derivative_std(self, self.diagnostics, K)

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


def K_ranges(prepared: list[PreparedRelease], section: SectionModel
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
