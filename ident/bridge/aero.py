"""The deck section's aerodynamics for a bridge: an RFC model or a Roger-fitted derivative table.

A bridge analysis needs the section's self-excited forces twice: as a rational-function model
for the state space (:func:`ident.bridge.flutter.analyze`) and as flutter-derivative functions
for the frequency-domain check (:func:`ident.bridge.flutter.frequency_domain`). From an RFC model
(``windrig identify --json``) both are the model's; from a flutter-derivative table the state
space gets its Roger fit (:func:`ident.tables.roger_table.fit_table`, weighted so that each force's
relative error counts alike at every tabulated K, which it reports) and the frequency domain the
table itself (monotone interpolation, only within its K range).

**Sway.** When the bridge's modes move the deck sideways (``p``) and the aerodynamics are of
heave and pitch only (2 DOF), the drag and sway terms are taken quasi-steady from the bridge's
static coefficients (:func:`ident.model.quasi_steady.quasi_steady_model`) if it has them; otherwise
the deck's sway feels no air, and a note says so.

**Where a table holds.** :func:`extrapolated_modes` names the modes that resonate at a wind
speed outside the table's reduced frequencies (the buffeting response marks them).

Not responsible for: reading the model or table files (:mod:`ident.tables.fd_table`, the command
line), the fit itself (:mod:`ident.tables.roger_table`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ident.bridge.flutter import in_wind_modes
from ident.bridge.model import BridgeModel
from ident.model.conventions import FLUTTER_DERIVATIVE_NAMES
from ident.model.quasi_steady import quasi_steady_derivatives, quasi_steady_model
from ident.model.rfc import RationalFunctionModel
from ident.tables.fd_table import FlutterDerivativeTable
from ident.tables.roger_table import TableFit, fit_table

__all__ = ["BridgeAero", "aero_from_model", "aero_from_table", "extrapolated_modes", "with_model"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class BridgeAero:
    """Self-excited forces of the deck section, in the two forms a bridge analysis uses.

    Attributes
    ----------
    model : RationalFunctionModel
        For the state space (2 or 3 DOF).
    flutter_derivatives : callable
        ``f(K) -> dict`` of derivatives, for the frequency-domain check.
    K_range : (float, float) or None
        The reduced frequencies the derivatives are known at (a table's range), or None (all).
    source : str
        Where they came from, for messages.
    table_fit : TableFit or None
        The Roger fit of a table, with its relative error at every tabulated K.
    table : FlutterDerivativeTable or None
    notes : list of str
        What was assumed (sway terms, missing derivatives).
    """

    model: RationalFunctionModel
    flutter_derivatives: Callable[[Any], dict[str, FloatArray]]
    K_range: tuple[float, float] | None
    source: str
    table_fit: TableFit | None = None
    table: FlutterDerivativeTable | None = None
    notes: list[str] = field(default_factory=list)


def _sways(bridge: BridgeModel) -> bool:
    return any(np.any(mode.p) for mode in bridge.modes)


def _with_sway(bridge: BridgeModel, model: RationalFunctionModel,
               fd: Callable[[Any], dict[str, FloatArray]], source: str,
               notes: list[str]) -> tuple[RationalFunctionModel,
                                          Callable[[Any], dict[str, FloatArray]]]:
    """Complete 2-DOF aerodynamics with quasi-steady sway terms when the modes sway."""
    if model.n_dof == 3 or not _sways(bridge):
        return model, fd
    static = bridge.static
    if static is None:
        notes.append(f"{source} has heave and pitch only and the bridge gives no static "
                     "coefficients: the deck's sway (p) feels no air")
        return model, fd
    notes.append(f"{source} has heave and pitch only: drag and sway terms quasi-steady from the "
                 "bridge's static coefficients (ident.model.quasi_steady)")

    def derivatives(K: Any) -> dict[str, FloatArray]:
        planar = fd(K)
        full = quasi_steady_derivatives(static, K)
        full.update({name: planar[name] for name in FLUTTER_DERIVATIVE_NAMES})
        return full

    return model.with_sway(quasi_steady_model(static)), derivatives


def aero_from_model(bridge: BridgeModel, model: RationalFunctionModel,
                    source: str = "model") -> BridgeAero:
    """Aerodynamics from a rational-function model (its own derivatives for the check)."""
    notes: list[str] = []
    full, fd = _with_sway(bridge, model, model.flutter_derivatives, source, notes)
    return BridgeAero(model=full, flutter_derivatives=fd, K_range=None, source=source,
                      notes=notes)


def aero_from_table(bridge: BridgeModel, table: FlutterDerivativeTable,
                    source: str = "table", *, n_lags: int | None = None) -> BridgeAero:
    """Aerodynamics from a flutter-derivative table: its Roger fit and its interpolation.

    Parameters
    ----------
    bridge : BridgeModel
    table : FlutterDerivativeTable
        At least 4 rows (2 or 3 DOF).
    source : str
        Name for messages.
    n_lags : int, optional
        Lags of the fit; default chosen by held-out rows
        (:func:`ident.tables.roger_table.fit_table`).

    Raises
    ------
    ValueError
        A table of fewer than 4 rows.
    ident.errors.RankDeficiencyError
        When no Roger structure is determined by the table.
    """
    if table.K.size < 4:
        raise ValueError(f"{source}: {table.K.size} row(s); a flutter analysis from a table "
                         "needs at least 4 reduced frequencies")
    notes: list[str] = []
    if table.filled:
        notes.append(f"{source} gives no {', '.join(table.filled)}: taken as zero")
    fit = fit_table(table, n_lags=n_lags)
    full, fd = _with_sway(bridge, fit.model, table.interpolator(), source, notes)
    return BridgeAero(model=full, flutter_derivatives=fd,
                      K_range=(float(table.K[0]), float(table.K[-1])), source=source,
                      table_fit=fit, table=table, notes=notes)


def with_model(bridge: BridgeModel, aero: BridgeAero, model: RationalFunctionModel) -> BridgeAero:
    """Return ``aero`` with another state-space model of the same table (e.g. a next structure).

    The frequency-domain functions (the table itself) stay; the sway terms are completed as
    :func:`aero_from_table` does.
    """
    full, _ = _with_sway(bridge, model, aero.flutter_derivatives, aero.source, [])
    return dataclasses.replace(aero, model=full)


def extrapolated_modes(bridge: BridgeModel, model: RationalFunctionModel, U: float,
                       K_range: tuple[float, float]) -> list[dict[str, Any]]:
    """Return the modes whose resonance at ``U`` lies outside the reduced frequencies known.

    A flutter-derivative table holds the self-excited forces between its lowest and highest
    reduced frequency ``K = 2 pi f B / U`` only; the Roger fit the state space uses is an
    extrapolation outside. A mode's resonant buffeting response is set by its aerodynamic
    damping at its in-wind frequency, so a mode resonating outside the table gives a result the
    table does not support (as U grows every K falls: the lowest modes leave the table first).
    The in-wind frequencies are :func:`ident.bridge.flutter.in_wind_modes`'s branches.

    Parameters
    ----------
    bridge : BridgeModel
    model : RationalFunctionModel
        The section's self-excited forces (a table's Roger fit: ``BridgeAero.model``).
    U : float
        Mean wind speed, m/s, > 0.
    K_range : (float, float)
        The lowest and highest reduced frequency of the table (``BridgeAero.K_range``).

    Returns
    -------
    list of dict
        ``{"mode": label, "frequency": Hz (in wind), "K": reduced frequency}`` for each mode
        outside ``K_range``, in mode order; empty when every mode resonates inside it.
    """
    if not (np.isfinite(U) and U > 0.0):
        raise ValueError(f"U must be > 0 m/s, got {U!r}")
    frequencies, _ = in_wind_modes(bridge, model, [U])
    out = []
    for label, f in zip(bridge.mode_labels(), frequencies[0], strict=True):
        K = 2.0 * np.pi * float(f) * bridge.B / U
        if not K_range[0] <= K <= K_range[1]:
            out.append({"mode": label, "frequency": float(f), "K": K})
    return out
