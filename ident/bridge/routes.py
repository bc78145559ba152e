"""A bridge's flutter by both routes, compared: the result a designer can sign, with its caveats.

The bridge's state space (:func:`ident.bridge.flutter.analyze`, the section's rational-function
model) and its frequency domain (:func:`ident.bridge.flutter.frequency_domain`, the section's
flutter derivatives: a table itself, or the model's) are compared as a section's are
(:func:`ident.tables.flutter_routes.compare_routes`): the 0.5 % agreement, the table's K range,
the basis of the divergence. With a table, a fit whose state space flutters below the table's
range while the table does not is replaced by the next structure the evidence allows (a warning
says so), as for a section.

Not responsible for: the numerics of either route (:mod:`ident.bridge.flutter`), the section's
aerodynamics (:mod:`ident.bridge.aero`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ident.bridge import fast_flutter, fast_flutter_fd
from ident.bridge import flutter as bridge_flutter
from ident.bridge.aero import BridgeAero, with_model
from ident.bridge.model import BridgeModel
from ident.model.flutter import LostModeError
from ident.model.rfc import RationalFunctionModel
from ident.tables.flutter_routes import (
    RouteComparison,
    compare_routes,
    frequency_domain_failure,
    next_structure_if_below,
)

__all__ = ["BridgeFlutter", "FAST_ABOVE_MODES", "METHODS", "bridge_flutter_routes"]

#: How each route is solved: ``"dense"`` (every branch on a U or K grid, a dense eigenproblem
#: each), ``"fast"`` (followed branches, :mod:`ident.bridge.fast_flutter`), ``"auto"``.
METHODS = ("auto", "dense", "fast")
#: ``"auto"`` takes the fast routes above this many modes (the dense sweep's cost grows as the
#: cube of the states; at 50 modes it is about a second, at 200 a minute).
FAST_ABOVE_MODES = 40


@dataclass(frozen=True, eq=False)
class BridgeFlutter:
    """Both routes for a bridge and their comparison.

    Attributes
    ----------
    comparison : RouteComparison
    state_space, frequency_domain : BridgeFlutterResult
    aero : BridgeAero
        The aerodynamics the state space used (a table's fit, perhaps the next structure).
    """

    comparison: RouteComparison
    state_space: bridge_flutter.BridgeFlutterResult
    frequency_domain: bridge_flutter.BridgeFlutterResult
    aero: BridgeAero


def _label(result: bridge_flutter.BridgeFlutterResult) -> str | None:
    return None if result.critical_mode is None else result.mode_labels[result.critical_mode]


def bridge_flutter_routes(bridge: BridgeModel, aero: BridgeAero,
                          U_max: float | None = None, method: str = "auto") -> BridgeFlutter:
    """Flutter of a bridge by both routes, compared (module docstring).

    Parameters
    ----------
    bridge : BridgeModel
    aero : BridgeAero
        The section's aerodynamics (:func:`ident.bridge.aero.aero_from_model` or
        :func:`~ident.bridge.aero.aero_from_table`).
    U_max : float, optional
        Top of the state-space search, m/s (default :func:`ident.bridge.flutter.default_U_max`).
    method : str
        One of :data:`METHODS`: how both routes are solved.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    fast = method == "fast" or (method == "auto" and bridge.n_modes > FAST_ABOVE_MODES)
    analyze = fast_flutter.analyze if fast else bridge_flutter.analyze
    ss = analyze(bridge, aero.model, U_max=U_max)
    check = fast_flutter_fd.frequency_domain if fast else bridge_flutter.frequency_domain
    try:
        fd = check(bridge, aero.flutter_derivatives, aero.K_range, U_max=ss.U_max)
    except LostModeError as exc:
        raise ValueError(frequency_domain_failure(aero.source, exc)) from exc
    notes: list[str] = []
    for route in (ss, fd):
        if route.certification is not None and "not certified" in route.certification:
            notes.append(f"{route.method}: {route.certification}")
    fit = aero.table_fit
    fit_model = None if fit is None else fit.model
    if fit is not None and aero.K_range is not None:
        def with_alternative(alternative: RationalFunctionModel) -> tuple[Any, BridgeAero]:
            trial_aero = with_model(bridge, aero, alternative)
            return analyze(bridge, trial_aero.model, U_max=U_max), trial_aero

        replaced = next_structure_if_below(ss, fd, fit, aero.K_range[1], with_alternative)
        if replaced is not None:
            ss, aero, note, fit_model = replaced
            notes.append(note)
    comparison = compare_routes(
        ss, fd, source="table" if fit is not None else "model", K_range=aero.K_range, fit=fit,
        fit_model=fit_model, state_space_mode=_label(ss), frequency_domain_mode=_label(fd),
        notes=tuple(notes))
    return BridgeFlutter(comparison, ss, fd, aero)
