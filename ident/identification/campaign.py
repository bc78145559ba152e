"""One campaign analysis: from a campaign's releases to everything its front ends show.

Responsibility: :func:`analyze_campaign` runs the identification chain on the releases of one
campaign (one section model, releases at two or more wind speeds) and returns one
:class:`CampaignAnalysis`: each release's modal fit (frequency and damping of the heave- and
pitch-dominated modes), the E2RFC model, its flutter analysis, the flutter speed with its
standard deviation and the parts of it
(:class:`ident.identification.uncertainty.FlutterUncertainty`), the flutter speeds of the structures
the data cannot tell apart, the model's flutter derivatives over the covered reduced frequencies
and, when the releases allow it, the indirect method's table from the same decays. The command line,
the operator console, the demo and the reprocessing job format this one object; none of them
rebuilds the chain.

Not responsible for: reading files (:mod:`ident.records.run_file`), plots, or choosing which
releases form a campaign.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ident.errors import IdentError
from ident.identification import e2rfc, fd_method, results, uncertainty
from ident.identification.modal import ReleaseModes, release_modes
from ident.model import flutter as _flutter
from ident.model.conventions import FLUTTER_DERIVATIVE_NAMES
from ident.model.section import SectionModel
from ident.numerics.selection import structure_label
from ident.records.release import Release

__all__ = ["CampaignAnalysis", "analyze_campaign"]

FloatArray = npt.NDArray[np.float64]

#: Reduced frequencies at which the derivatives are tabulated over the covered span.
K_POINTS = 120


@dataclass(frozen=True, eq=False)
class CampaignAnalysis:
    """Everything one campaign's releases say (see the module docstring).

    Attributes
    ----------
    section : SectionModel
    n_releases : int
    wind_speeds : tuple of float
        The distinct wind speeds, m/s.
    release_speeds : tuple of float
        Each release's wind speed, m/s, in the order given.
    modes : tuple of ReleaseModes
        Each release's heave and pitch modes (frequency, damping), in the order given.
    model : IdentifiedModel
    flutter : FlutterResult
        The model's flutter analysis (state space).
    uncertainty : FlutterUncertainty
        The flutter speed, its standard deviation and its parts, and the warnings.
    structures : StructureSpread
        Flutter speeds of the structures within one standard error, the chosen one first.
    K : ndarray
        Reduced frequencies spanning the releases (widened 20 %).
    derivatives : dict of str to ndarray
        The model's ``H1..H4, A1..A4`` at ``K``.
    table : DecayDerivativeTable or None
        The indirect method's derivatives from the same decays; None when not asked for or
        when it failed (``table_error`` says why).
    table_error : str or None
    """

    section: SectionModel
    n_releases: int
    wind_speeds: tuple[float, ...]
    release_speeds: tuple[float, ...]
    modes: tuple[ReleaseModes, ...]
    model: results.IdentifiedModel = field(repr=False)
    flutter: _flutter.FlutterResult = field(repr=False)
    uncertainty: uncertainty.FlutterUncertainty
    structures: results.StructureSpread
    K: FloatArray = field(repr=False)
    derivatives: dict[str, FloatArray] = field(repr=False)
    table: fd_method.DecayDerivativeTable | None = field(default=None, repr=False)
    table_error: str | None = None

    @property
    def flutter_speed(self) -> float | None:
        """Flutter speed, m/s (None: none below the searched speeds)."""
        return None if self.flutter.speed is None else float(self.flutter.speed)

    @property
    def flutter_std(self) -> float | None:
        """Its standard deviation (all parts), m/s."""
        return None if self.flutter.speed is None else float(self.uncertainty.total)

    @property
    def flutter_interval(self) -> tuple[float, float] | None:
        """Its 2-std interval, m/s: longer above (:meth:`FlutterUncertainty.interval`)."""
        return None if self.flutter.speed is None else self.uncertainty.interval()

    @property
    def flutter_frequency(self) -> float | None:
        """Flutter frequency, Hz."""
        return None if self.flutter.frequency is None else float(self.flutter.frequency)

    @property
    def structure(self) -> str:
        """The chosen structure, e.g. ``n_lags=2, A3=fitted``."""
        d = self.model.diagnostics
        return f"n_lags={d.n_lags}, A3={'fitted' if d.with_A3 else 'zero'}"

    @property
    def warnings(self) -> tuple[str, ...]:
        """What the checks found (random response, extrapolation, residuals, outliers)."""
        return self.uncertainty.warnings

    def summary(self) -> str:
        """One line: the flutter speed, the model and the data it rests on."""
        d = self.model.diagnostics
        model = f"E2RFC {d.n_lags} lag(s){' + A3' if d.with_A3 else ''}"
        speeds = ", ".join(f"{u:.2f}" for u in self.wind_speeds)
        data = f"{self.n_releases} releases at {speeds} m/s"
        if self.flutter_speed is None:
            return f"no flutter predicted ({model}; {data})"
        frequency = "" if self.flutter_frequency is None else f" at {self.flutter_frequency:.2f} Hz"
        spread = ("" if len(self.structures.labels) == 1
                  else f"; {self.structures.summary()}")
        low, high = self.uncertainty.interval()
        return (f"flutter speed {self.flutter_speed:.2f} +- {self.flutter_std:.2f} m/s "
                f"(2-std interval {low:.2f} to {high:.2f}){frequency} ({model}; {data}{spread})")

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-ready summary (numbers, lists and strings)."""
        u, interval = self.uncertainty, self.flutter_interval
        return {
            "n_releases": self.n_releases,
            "wind_speeds": list(self.wind_speeds),
            "section": self.section.to_dict(),
            "structure": self.structure,
            "reason": self.model.diagnostics.reason,
            "model": self.model.to_dict(),
            "flutter_speed": self.flutter_speed,
            "flutter_std": self.flutter_std,
            "flutter_interval": None if interval is None else list(interval),
            "flutter_frequency": self.flutter_frequency,
            "flutter_std_parts": None if self.flutter_speed is None else u.parts(),
            "flutter_structures": dict(zip(self.structures.labels, self.structures.speeds,
                                           strict=True)),
            "flutter_speed_low": self.structures.low,
            "flutter_speed_high": self.structures.high,
            "warnings": list(self.warnings),
            "modes": [{"U": u, **vars(m)} for u, m in zip(self.release_speeds, self.modes,
                                                           strict=True)],
        }


def analyze_campaign(
    releases: Sequence[Release], section: SectionModel, *, n_lags: int | None = None,
    with_A3: bool | None = None, table: bool = True, U_max: float | None = None,
    turbulent_estimator: str | None = None, closed_loop_buffeting: str | None = None,
) -> CampaignAnalysis:
    """Identify a campaign's releases and analyse the model (see the module docstring).

    Parameters
    ----------
    releases : sequence of Release
        Wind-on free decays with forces, at two or more wind speeds.
    section : SectionModel
        The structure, with the campaign's air density.
    n_lags, with_A3 : optional
        Model structure for :func:`ident.identification.e2rfc.identify` (None: chosen by held-out
        error).
    table : bool
        Also compute the indirect method's flutter-derivative table (it needs three or more
        wind speeds; a failure is recorded in ``table_error``, not raised).
    U_max : float, optional
        Upper end of the flutter search, m/s.
    turbulent_estimator : {"iv", "ml"}, optional
        The estimator of releases in turbulence (:func:`ident.identification.e2rfc.identify`;
        None: its default).
    closed_loop_buffeting : str, optional
        The closed-loop estimator's buffeting model (the same function's; None: its default).

    Returns
    -------
    CampaignAnalysis

    Raises
    ------
    IdentError
        E2RFC cannot identify a model from these releases (one wind speed, rank deficiency).
    """
    releases = list(releases)
    model = e2rfc.identify(releases, section, n_lags=n_lags, with_A3=with_A3,
                           turbulent_estimator=turbulent_estimator,
                           closed_loop_buffeting=closed_loop_buffeting)
    try:
        flutter, uncertainty = model.analysis(section, U_max)
    except _flutter.StillAirModesError as exc:
        structure = structure_label(model.diagnostics.n_lags, model.diagnostics.with_A3)
        raise IdentError(
            f"the identified model ({structure}) has no flutter analysis: {exc}; releases at "
            "more wind speeds, or the structure given, would determine it") from exc
    K = e2rfc.reduced_frequency_span(releases, section, K_POINTS)
    derivatives = model.flutter_derivatives(K)
    fd_table: fd_method.DecayDerivativeTable | None = None
    table_error = None
    if table and section.n_dof == 3:  # the indirect method fits heave and pitch modes only
        table_error = ("the indirect method's table is of 2-DOF sections (heave and pitch); "
                       "this section has sway")
    elif table:
        try:
            fd_table = fd_method.flutter_derivatives(releases, section)
        except IdentError as exc:  # shown next to the curves; the model itself stands
            table_error = f"{type(exc).__name__}: {exc}"
    return CampaignAnalysis(
        section=section, n_releases=len(releases),
        wind_speeds=tuple(results.distinct_wind_speeds([r.U for r in releases])),
        release_speeds=tuple(float(r.U) for r in releases),
        modes=tuple(release_modes(fit, section) for fit in model.diagnostics.modal_fits),
        model=model, flutter=flutter, uncertainty=uncertainty,
        structures=model.structure_spread(section, U_max), K=K,
        derivatives={name: np.asarray(derivatives[name], dtype=float)
                     for name in FLUTTER_DERIVATIVE_NAMES},
        table=fd_table, table_error=table_error)
