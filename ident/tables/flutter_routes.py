"""Flutter by both routes, compared: the number a report can rest on, with its caveats.

windrig has two routes to a flutter speed: the state space of a rational-function model
(eigenvalues against U, :func:`ident.model.flutter.analyze`) and the frequency domain (Scanlan's
iteration on K with flutter derivatives, :func:`ident.model.flutter.frequency_domain`). For a
model they are two numerics of one function and must agree. For a table the state space works on
the table's Roger fit and the frequency domain on the table itself: they agree when the fit holds
where flutter lives, and the fit says nothing beyond the table's reduced frequencies.
:func:`compare_routes` decides which number is the result, and says why:

- both routes found flutter within :data:`ROUTE_TOLERANCE` (0.5 %) of each other: the state
  space (exact eigenvalues, no iteration on K). Further apart: a warning names both, and the
  result rests on the route that uses the input itself (the frequency domain for a table, the
  state space for a model);
- flutter outside the table's reduced frequencies: a warning (the state space extrapolates the
  fit there; the frequency domain cannot look there at all), and when nothing else is found no
  result (basis ``"none"``: the extrapolation is named, never the headline); a frequency domain
  already unstable
  at the table's lowest reduced velocity: the table itself puts flutter at or below that speed;
- divergence is the ``K = 0`` limit of the model's static stiffness, always an extrapolation from
  the table's lowest K: a warning says so, its basis is stated, and for a section it is checked
  against the table's own lowest row (:func:`table_divergence_speed`).

:func:`section_flutter` runs both routes for a section from a model or a table; with a table,
a fit whose state space flutters below the table's range while the table does not is replaced by
the next structure the evidence allows (the choice is a warning).

Not responsible for: the routes' numerics (:mod:`ident.model.flutter`), the fit
(:mod:`ident.tables.roger_table`), a full bridge (:mod:`ident.bridge.flutter` uses
:func:`compare_routes` the same way).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg

from ident.model import flutter
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.tables.fd_table import FlutterDerivativeTable
from ident.tables.roger_table import TableFit, fit_table

__all__ = ["ROUTE_TOLERANCE", "RouteComparison", "SectionFlutter", "UNITS", "below_table",
           "compare_routes", "frequency_domain_failure", "next_structure_if_below",
           "section_flutter", "table_U_max", "table_divergence_speed"]

#: Largest relative difference between the routes' flutter speeds taken as agreement.
ROUTE_TOLERANCE = 0.005

#: Divergence estimates (fit at K = 0, table at its lowest K) further apart than this are named.
#: From a table's usual lowest row (reduced velocity ~20) to K = 0 a deck's static stiffness
#: still changes: the flat plate's by ~12 %, its divergence speed by ~6 %.
_DIVERGENCE_TOLERANCE = 0.15

#: Units of the numbers of :meth:`RouteComparison.to_dict`.
UNITS: dict[str, str] = {
    "flutter_speed": "m/s", "flutter_frequency": "Hz",
    "reduced_frequency": "1 (K = B omega / U, B the deck width)",
    "flutter_speed_frequency_domain": "m/s", "flutter_frequency_frequency_domain": "Hz",
    "result.flutter_speed": "m/s", "result.flutter_frequency": "Hz",
    "result.reduced_frequency": "1",
    "route_difference": "1 (frequency domain / state space - 1)",
    "table_K_range": "1 (K = B omega / U)", "divergence_speed": "m/s",
    "divergence_speed_table_edge": "m/s",
    "fit_error_at_flutter": "1 (a derivative's error / its force's size at that K)",
}


@dataclass(frozen=True)
class RouteComparison:
    """The flutter result both routes support, and what a reader must know about it.

    Attributes
    ----------
    speed, frequency : float or None
        The result: flutter speed (m/s) and frequency (Hz) of the route named by ``basis``.
    reduced_frequency : float or None
        ``K_F = B omega_F / U_F`` of the result.
    critical_mode : str or None
        The branch (or bridge mode) that goes unstable.
    basis : str
        ``"state-space"``, ``"frequency-domain"`` or ``"none"`` (no flutter found).
    basis_reason : str
        Why the result rests on that route.
    state_space_speed, frequency_domain_speed : float or None
        Each route's flutter speed, m/s.
    state_space_frequency, frequency_domain_frequency : float or None
        Each route's flutter frequency, Hz.
    state_space_reduced_frequency : float or None
        The state space's ``K_F``.
    difference : float or None
        ``frequency_domain_speed / state_space_speed - 1`` when both found flutter.
    source : str
        ``"table"`` or ``"model"``: what the aerodynamics came as.
    K_range : (float, float) or None
        The table's reduced frequencies, lowest and highest (None for a model).
    divergence_speed : float or None
        Static divergence speed of the state space (the model at K = 0), m/s.
    divergence_basis : str
        Where the divergence speed comes from, and that it is an extrapolation.
    divergence_speed_table_edge : float or None
        A section's divergence with the table's own static stiffness at its lowest K, m/s.
    fit_error_at_flutter : dict or None
        Each derivative's fit error at the result's K (a table within its range).
    warnings : tuple of str
        Everything a reader must know, in words; empty when nothing.
    """

    speed: float | None
    frequency: float | None
    reduced_frequency: float | None
    critical_mode: str | None
    basis: str
    basis_reason: str
    state_space_speed: float | None
    frequency_domain_speed: float | None
    state_space_frequency: float | None
    frequency_domain_frequency: float | None
    state_space_reduced_frequency: float | None
    difference: float | None
    source: str
    K_range: tuple[float, float] | None
    divergence_speed: float | None
    divergence_basis: str
    divergence_speed_table_edge: float | None = None
    fit_error_at_flutter: dict[str, float] | None = None
    warnings: tuple[str, ...] = field(default=())

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: both routes, the result and its basis, the table's range, divergence.

        ``flutter_speed``, ``flutter_frequency`` and ``reduced_frequency`` are the state space's
        (the run file and command contract); ``flutter_speed_frequency_domain`` and
        ``flutter_frequency_frequency_domain`` the frequency domain's; ``result`` the one a
        report rests on, with its ``basis`` and why. ``units`` and ``warnings`` as always.
        """
        return {
            "flutter_speed": self.state_space_speed,
            "flutter_frequency": self.state_space_frequency,
            "reduced_frequency": self.state_space_reduced_frequency,
            "flutter_speed_frequency_domain": self.frequency_domain_speed,
            "flutter_frequency_frequency_domain": self.frequency_domain_frequency,
            "route_difference": self.difference, "route_tolerance": ROUTE_TOLERANCE,
            "result": {"flutter_speed": self.speed, "flutter_frequency": self.frequency,
                       "reduced_frequency": self.reduced_frequency,
                       "critical_mode": self.critical_mode, "basis": self.basis,
                       "basis_reason": self.basis_reason},
            "aerodynamics": self.source,
            "table_K_range": None if self.K_range is None else list(self.K_range),
            "divergence_speed": self.divergence_speed,
            "divergence_basis": self.divergence_basis,
            "divergence_speed_table_edge": self.divergence_speed_table_edge,
            "fit_error_at_flutter": self.fit_error_at_flutter,
            "units": dict(UNITS), "warnings": list(self.warnings),
        }

    def summary(self) -> str:
        """One line: the result and its basis."""
        if self.speed is None:
            return f"no flutter found ({self.basis_reason})"
        return (f"flutter speed {self.speed:.4g} m/s, {self.frequency:.4g} Hz, K = "
                f"{self.reduced_frequency:.3g}, {self.critical_mode} (from the {self.basis}: "
                f"{self.basis_reason})")


def _in_range(K: float, K_range: tuple[float, float]) -> bool:
    return K_range[0] * (1 - 1e-9) <= K <= K_range[1] * (1 + 1e-9)


def compare_routes(state_space: Any, frequency_domain: Any, *, source: str,
                   K_range: tuple[float, float] | None = None, fit: TableFit | None = None,
                   fit_model: RationalFunctionModel | None = None,
                   state_space_mode: str | None = None, frequency_domain_mode: str | None = None,
                   divergence_table_edge: float | None = None,
                   notes: tuple[str, ...] = ()) -> RouteComparison:
    """Compare the two routes' results and choose the one a report rests on (module docstring).

    Parameters
    ----------
    state_space, frequency_domain : flutter results
        Objects with ``speed``, ``frequency``, ``reduced_frequency``, ``critical_mode``,
        ``divergence_speed``, ``U_max`` and (frequency domain) ``unstable_at_start``: a
        section's :class:`~ident.model.flutter.FlutterResult` or a bridge's.
    source : {"table", "model"}
        What the aerodynamics came as.
    K_range : (float, float), optional
        The table's lowest and highest reduced frequency.
    fit : TableFit, optional
        The table's Roger fit.
    fit_model : RationalFunctionModel, optional
        The fit of the table the state space used, when not ``fit``'s chosen one (one of its
        alternatives): the error at the flutter point is this model's.
    state_space_mode, frequency_domain_mode : str, optional
        Names of the critical branches (default: the results' ``critical_mode``).
    divergence_table_edge : float, optional
        Divergence speed from the table's lowest row, m/s (a section's, when known).
    notes : tuple of str
        Warnings of the caller to carry (e.g. a fit replaced).
    """
    if source not in ("table", "model"):
        raise ValueError(f"source must be 'table' or 'model', got {source!r}")
    warnings = list(notes)
    ss, fd = state_space, frequency_domain
    ss_mode = state_space_mode if state_space_mode is not None else ss.critical_mode
    fd_mode = frequency_domain_mode if frequency_domain_mode is not None else fd.critical_mode
    if fit is not None and not fit.meets_accuracy:
        warnings.append(f"{fit.summary()}: the state space rests on a fit that does not follow "
                        "the table (scatter, a typo, or a shape Roger's form cannot follow)")
    K_text = ("" if K_range is None else
              f"the table's K {K_range[0]:.3g} to {K_range[1]:.3g}")
    if ss.speed is not None and K_range is not None and not _in_range(ss.reduced_frequency,
                                                                      K_range):
        where = ("below the table's wind speeds" if ss.reduced_frequency > K_range[1]
                 else "above the table's wind speeds")
        warnings.append(f"state space: flutter at {ss.speed:.4g} m/s with K = "
                        f"{ss.reduced_frequency:.3g}, outside {K_text} ({where}): the Roger fit "
                        "is extrapolated there")
    if getattr(fd, "unstable_at_start", False):
        edge, covered = (("highest", "table covers; the table itself says so")
                         if source == "table" else ("highest searched", "search covers"))
        warnings.append(f"frequency domain: the {fd_mode} branch is already unstable at the "
                        f"{edge} K (the lowest reduced velocity): flutter at or below "
                        f"{fd.speed:.4g} m/s, below the range the {covered}")

    difference = None
    route_of = {"state-space": (ss, ss_mode), "frequency-domain": (fd, fd_mode)}
    own = "frequency-domain" if source == "table" else "state-space"
    why_own = ("the route that uses the table itself, not its fit" if source == "table" else
               "the model's exact eigenvalues; the frequency domain samples the same model")
    if ss.speed is not None and fd.speed is not None:
        difference = fd.speed / ss.speed - 1.0
        if abs(difference) <= ROUTE_TOLERANCE:
            basis, reason = "state-space", (f"the routes agree within {100 * ROUTE_TOLERANCE:g} "
                                            f"% ({100 * difference:+.2f} %)")
        else:
            basis, reason = own, why_own
            warnings.append(f"the two routes disagree by {100 * difference:+.2f} %: state space "
                            f"{ss.speed:.4g} m/s, frequency domain {fd.speed:.4g} m/s; the result "
                            f"rests on the {basis.replace('-', ' ')} ({why_own})")
    elif ss.speed is not None:
        basis, reason = "state-space", "the only route that found flutter"
        if source == "table":
            warnings.append(f"the frequency domain finds no flutter within {K_text}; the state "
                            f"space's {ss.speed:.4g} m/s has no check from the table")
        else:
            warnings.append(f"the frequency domain finds no flutter; the state space's "
                            f"{ss.speed:.4g} m/s is unchecked")
    elif fd.speed is not None:
        basis, reason = "frequency-domain", "the only route that found flutter"
        warnings.append(f"the state space finds no flutter below {ss.U_max:.4g} m/s; the "
                        f"frequency domain finds {fd.speed:.4g} m/s")
    else:
        basis, reason = "none", (f"neither route below {ss.U_max:.4g} m/s"
                                 + (f" or within {K_text}" if K_text else ""))
    result, mode = route_of.get(basis, (None, None))
    if (result is not None and K_range is not None and result.reduced_frequency is not None
            and not _in_range(result.reduced_frequency, K_range)
            and not getattr(result, "unstable_at_start", False)):
        # Only the fit, extrapolated beyond the table, flutters: no result a table supports.
        basis, reason = "none", (f"the only flutter found ({result.speed:.4g} m/s, K = "
                                 f"{result.reduced_frequency:.3g}) lies outside {K_text}: an "
                                 "extrapolation of the fit, not a result")
        result, mode = None, None
    if result is not None and getattr(result, "unstable_at_start", False):
        reason += "; an upper bound: unstable from the first reduced frequency searched"
    speed = None if result is None else result.speed
    K_F = None if result is None else result.reduced_frequency

    error_at = None
    if fit is not None and K_F is not None and K_range is not None and _in_range(K_F, K_range):
        error_at = fit.error_at(K_F, fit_model)
        name = max(error_at, key=lambda n: error_at[n])
        if error_at[name] > fit.accuracy:
            warnings.append(f"the Roger fit's error at the flutter K = {K_F:.3g}: {name}* "
                            f"{100 * error_at[name]:.2g} % of its force (more than "
                            f"{100 * fit.accuracy:g} %)")

    divergence = ss.divergence_speed
    if K_range is not None:
        divergence_basis = (f"the Roger fit's static stiffness (K = 0), extrapolated beyond the "
                            f"table's lowest K = {K_range[0]:.3g} (reduced velocity "
                            f"{2 * math.pi / K_range[0]:.3g})")
    else:
        divergence_basis = ("the model's static stiffness (K = 0, its A1), extrapolated beyond "
                            "the reduced frequencies it was identified at")
    if divergence is not None:
        if K_range is not None:
            warnings.append(f"divergence at {divergence:.4g} m/s lies outside the table's K "
                            f"range: {divergence_basis}")
        if divergence_table_edge is not None and abs(
                divergence / divergence_table_edge - 1.0) > _DIVERGENCE_TOLERANCE:
            warnings.append(f"divergence: {divergence:.4g} m/s from the fit at K = 0, "
                            f"{divergence_table_edge:.4g} m/s with the table's own lowest row: "
                            "the extrapolation to K = 0 is uncertain")
        if speed is not None and divergence < speed:
            warnings.append(f"divergence at {divergence:.4g} m/s comes before flutter at "
                            f"{speed:.4g} m/s and governs ({divergence_basis})")
    return RouteComparison(
        speed=speed, frequency=None if result is None else result.frequency,
        reduced_frequency=K_F, critical_mode=mode, basis=basis, basis_reason=reason,
        state_space_speed=ss.speed, frequency_domain_speed=fd.speed,
        state_space_frequency=ss.frequency, frequency_domain_frequency=fd.frequency,
        state_space_reduced_frequency=ss.reduced_frequency, difference=difference,
        source=source, K_range=K_range, divergence_speed=divergence,
        divergence_basis=divergence_basis, divergence_speed_table_edge=divergence_table_edge,
        fit_error_at_flutter=error_at, warnings=tuple(warnings))


def table_divergence_speed(section: SectionModel, table: FlutterDerivativeTable) -> float | None:
    """Divergence speed with the table's static stiffness at its lowest K, m/s (None: none).

    The aerodynamic stiffness ``rho/2 U^2 B^2 Re Q(iK)`` at the table's lowest reduced
    frequency stands for its static value: the lowest U at which ``Ks - rho/2 U^2 B^2 Re Q``
    loses positive definiteness. A check on the fit's extrapolation to ``K = 0``.
    """
    n = section.n_dof
    Q = table.Q()[0, :n, :n].real
    aero = 0.5 * section.rho * section.B**2 * Q
    nu = scipy.linalg.eigvals(aero, section.stiffness_matrix()[:n, :n])  # nu = 1 / U^2
    nu = nu[np.isfinite(nu) & (np.abs(nu.imag) <= 1e-9 * np.abs(nu).max(initial=1.0))].real
    nu = nu[nu > 0.0]
    return None if nu.size == 0 else float(1.0 / math.sqrt(nu.max()))


@dataclass(frozen=True, eq=False)
class SectionFlutter:
    """Both routes for a section and their comparison.

    Attributes
    ----------
    comparison : RouteComparison
    state_space, frequency_domain : FlutterResult
    model : RationalFunctionModel
        The model the state space used (a table's fit, perhaps an alternative structure).
    fit : TableFit or None
        The table's fit (None for a model).
    """

    comparison: RouteComparison
    state_space: flutter.FlutterResult
    frequency_domain: flutter.FlutterResult
    model: RationalFunctionModel
    fit: TableFit | None = None


def table_U_max(section: SectionModel, K_low: float) -> float:
    """Highest wind speed at which a still-air mode of the section lies within a table, m/s.

    Beyond it every branch's reduced frequency lies below the table's lowest K.
    """
    frequencies = [section.fh, section.fa] + [f for f in (section.fp,) if f is not None]
    return 2.0 * math.pi * max(frequencies) * section.B / K_low


def section_flutter(section: SectionModel, *, model: RationalFunctionModel | None = None,
                    table: FlutterDerivativeTable | None = None, fit: TableFit | None = None,
                    U_max: float | None = None) -> SectionFlutter:
    """Flutter of a section by both routes, compared (module docstring).

    Parameters
    ----------
    section : SectionModel
    model : RationalFunctionModel, optional
        The aerodynamics as a model; or
    table : FlutterDerivativeTable, optional
        as a table (fitted here unless ``fit`` is given).
    fit : TableFit, optional
        The table's fit, when already made.
    U_max : float, optional
        Top of the state-space search, m/s (default: for a table, where its fastest still-air
        mode leaves the table's K range; else :func:`ident.model.flutter.default_U_max`).

    Raises
    ------
    ValueError
        Neither or both of ``model`` and ``table``.
    """
    if (model is None) == (table is None):
        raise ValueError("give exactly one of model and table")
    n = section.n_dof
    notes: list[str] = []
    if table is None:
        assert model is not None
        model = model if model.n_dof == n else model.planar()
        ss = flutter.analyze(section, model, U_max)
        fd = flutter.frequency_domain(section, model.flutter_derivatives)
        return SectionFlutter(compare_routes(ss, fd, source="model"), ss, fd, model)
    fit = fit_table(table) if fit is None else fit
    K_range = (float(table.K[0]), float(table.K[-1]))
    U_top = table_U_max(section, K_range[0]) if U_max is None else U_max
    try:
        fd = flutter.frequency_domain(section, table.interpolator(), K_range)
    except flutter.LostModeError as exc:
        raise ValueError(frequency_domain_failure(table.source, exc)) from exc
    model_used = fit.model if n == 3 else fit.model.planar()
    ss = flutter.analyze(section, model_used, U_top)
    fit_model = fit.model

    def with_alternative(alternative: RationalFunctionModel
                         ) -> tuple[flutter.FlutterResult, RationalFunctionModel]:
        used = alternative if n == 3 else alternative.planar()
        return flutter.analyze(section, used, U_top), used

    replaced = next_structure_if_below(ss, fd, fit, K_range[1], with_alternative)
    if replaced is not None:
        ss, model_used, note, fit_model = replaced
        notes.append(note)
    if ss.speed is None and fd.speed is None:
        beyond = flutter.analyze(section, model_used,
                                 max(flutter.default_U_max(section), 2.0 * U_top))
        if beyond.speed is not None:
            notes.append(f"no flutter within the table, which ends at K = {K_range[0]:.3g} "
                         f"(reduced velocity {2 * math.pi / K_range[0]:.3g}); the fit, "
                         f"extrapolated, flutters at {beyond.speed:.4g} m/s with K = "
                         f"{beyond.reduced_frequency:.3g}: not a result, a reason to measure "
                         "further")
        else:
            notes.append(f"no flutter within the table, which ends at K = {K_range[0]:.3g}: "
                         f"flutter above {U_top:.4g} m/s is not excluded")
    comparison = compare_routes(ss, fd, source="table", K_range=K_range, fit=fit,
                                fit_model=fit_model,
                                divergence_table_edge=table_divergence_speed(section, table),
                                notes=tuple(notes))
    return SectionFlutter(comparison, ss, fd, model_used, fit)


def frequency_domain_failure(source: str, exc: Exception) -> str:
    """Say why the frequency-domain route stopped on a table, naming the table and the causes.

    The route follows each still-air mode's root as K falls; it stops when a root is no longer
    oscillatory (``expected 2 oscillatory roots at K = 0.48, found 1``): at that reduced
    frequency the table's aerodynamic stiffness (``H4*``, ``A3*``, over ``K^2``) overcomes a
    mode's spring. Alone, that message names neither the file nor a cause; the flat plate's
    table with its H and A columns swapped stops so.

    Parameters
    ----------
    source : str
        The table's file (or the aerodynamics' source), for the message.
    exc : Exception
        What the route raised (a :class:`~ident.model.flutter.LostModeError`).

    Returns
    -------
    str
        One line for the error the caller raises from ``exc``.
    """
    where = f"{source}: " if source else ""
    return (f"{where}the frequency-domain route (the flutter derivatives themselves) cannot "
            f"follow the modes: {exc}: there the aerodynamic stiffness (H4*, A3*) overcomes "
            "a mode's spring; a static divergence inside the table's reduced frequencies, or "
            "derivatives in the wrong columns (H and A swapped?) or scaled (per degree, "
            "times 2 pi)? Check the table's columns and units")


def below_table(result: Any, K_high: float) -> bool:
    """Tell whether a state-space result flutters below the table's wind speeds (K > K_high)."""
    return (result.speed is not None and result.reduced_frequency is not None
            and result.reduced_frequency > K_high * (1 + 1e-9))


def next_structure_if_below(first: Any, frequency_domain: Any, fit: TableFit, K_high: float,
                            analyze: Callable[[RationalFunctionModel], tuple[Any, Any]]
                            ) -> tuple[Any, Any, str, RationalFunctionModel] | None:
    """Replace a fit whose state space flutters below the table's range, when the table does not.

    Parameters
    ----------
    first : flutter result
        The state space of the fit chosen first (a section's or a bridge's).
    frequency_domain : flutter result
        The table's own route (its ``unstable_at_start`` says the table shows such flutter).
    fit : TableFit
    K_high : float
        The table's highest reduced frequency.
    analyze : callable
        ``analyze(model) -> (result, used)``: the state space of another structure's model and
        what the caller keeps with it (the model as used, or the bridge's aerodynamics).

    Returns
    -------
    (result, used, note, model) or None
        The first alternative (most accurate first) that does not flutter below the range,
        the warning that says so, and the alternative fit itself (for its error at the
        flutter point); None when nothing was replaced.
    """
    if not below_table(first, K_high) or frequency_domain.unstable_at_start:
        return None
    for candidate, alternative, error in fit.alternatives():
        result, used = analyze(alternative)
        if not below_table(result, K_high):
            return result, used, (
                f"the fit chosen first ({fit.model.n_lags} lag(s)) flutters at "
                f"{first.speed:.4g} m/s with K = {first.reduced_frequency:.3g}, below the "
                "table's range, which the table does not show: the state space uses the next "
                f"structure, {candidate.label} (largest error {100 * error:.2g} % of a force)"
            ), alternative
    return None
