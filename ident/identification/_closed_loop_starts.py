"""More starts for the closed-loop search when its first maximum contradicts the releases.

Responsibility: given a closed-loop fit whose model flutters below a wind speed at which no
release grew (a maximum of the likelihood that the data themselves refute), search again from
other starts and keep the maximum of highest likelihood among those the data do not refute,
saying so.

The closed-loop likelihood has more than one maximum when the buffeting is strong or its
spectrum far from the shaping filter's, and the start is poor. Measured on
``benchmarks/ident_accuracy.py``'s rows:

- bluff deck at Iw 3 % without holds, seed 0: the first maximum fluttered at 0.13 m/s, 1 % of
  the truth; a second search from its coefficients, with the buffeting and noise started
  afresh from the records, rose 21 in log L and fluttered within 0.6 % of the truth;
- the same row, seed 1: the first maximum fluttered at 0.56 m/s; the search from its own
  coefficients rose 181 in log L and still fluttered at 0.6 m/s, the one from the flat plate's
  aerodynamics rose 179 and fluttered at 13.3 m/s (-2.0 %);
- plate at Iw 1 % under Davenport's admittance with a 1 m scale (a force spectrum that falls
  faster above the modes than one second-order section can), seed 1: a first maximum at
  1.27 m/s; another start's maximum, 3.2 lower in log L and not refuted, flutters at +3.5 %.

A maximum that flutters below such a speed is refuted by the records, whatever its likelihood:
keeping the best one they allow is maximum likelihood under that constraint. The extra searches
run only on a contradiction, so a sound fit costs nothing more.

Not responsible for: the search itself (:mod:`ident.identification.closed_loop_ml`), nor for
deciding at which speed releases grew (the caller passes it).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ident.identification.closed_loop_ml import ClosedLoopFit
from ident.model import flat_plate
from ident.model import flutter as _flutter
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel

__all__ = ["refuted", "search_again"]


def search_again(fit: ClosedLoopFit, section: SectionModel, bounded_at: float | None,
                 refit: Callable[[RationalFunctionModel], ClosedLoopFit]
                 ) -> tuple[ClosedLoopFit, str | None]:
    """Return the best maximum the releases do not refute, when ``fit`` is refuted.

    Parameters
    ----------
    fit : ClosedLoopFit
        The search's first result.
    section : SectionModel
    bounded_at : float or None
        Highest wind speed at which no release grew, m/s (None: none; nothing can refute).
    refit : callable
        ``refit(start)`` runs the same closed-loop search (same releases, structure and
        buffeting model) from another starting model; it may raise ValueError (no likelihood
        at that start), which skips the start.

    Returns
    -------
    ClosedLoopFit, str or None
        The fit kept, and a note saying what was searched and kept (None when ``fit`` was not
        refuted: then ``fit`` itself, and nothing more was searched). When every maximum is
        refuted, the one of highest likelihood is kept (the caller's check against the
        records then widens its interval).
    """
    if bounded_at is None:
        return fit, None
    first = _flutter_speed(section, fit.model)
    if first is None or not _refuted(first, bounded_at):
        return fit, None
    found: list[tuple[ClosedLoopFit, float | None]] = [(fit, first)]  # each with its flutter
    failed = []
    for name, start in (("its own maximum", fit.model),
                        ("the flat plate's aerodynamics", _plate_start(fit.model))):
        try:
            other = refit(start)
        except ValueError as exc:
            failed.append(f"{name} ({exc})")
            continue
        found.append((other, _flutter_speed(section, other.model)))
    allowed = [(f, speed) for f, speed in found if not _refuted(speed, bounded_at)]
    best, speed = min(allowed or found, key=lambda pair: pair[0].neg_log_likelihood)
    fluttering = ("without flutter in the searched range" if speed is None
                  else "unstable in still air" if speed == 0.0
                  else f"fluttering at {speed:.3g} m/s")
    if best is fit:
        kept = f"the first, {fluttering}"
    else:
        change = fit.neg_log_likelihood - best.neg_log_likelihood
        kept = (f"a maximum {abs(change):.1f} {'higher' if change > 0 else 'lower'} in log L "
                f"than the first, {fluttering}")
    was = "was unstable in still air" if first == 0.0 else f"fluttered at {first:.3g} m/s"
    return best, (
        f"turbulence: the likelihood's first maximum {was}, below "
        f"{bounded_at:.3g} m/s where no release grew; searched again from its own "
        "coefficients (buffeting and noise afresh) and from the flat plate's aerodynamics"
        + (f" (could not start from {'; '.join(failed)})" if failed else "")
        + (f": kept {kept}, the best the releases allow" if allowed
           else f": every maximum is refuted, kept {kept}"))


def _plate_start(found: RationalFunctionModel) -> RationalFunctionModel:
    """Return Jones's plate as a start, in ``found``'s degrees of freedom.

    With sway the plate has no drag of its own: the sway rows and columns of ``A1``-``A3`` are
    ``found``'s (its lag terms there zero), heave and pitch the plate's.
    """
    plate = flat_plate.jones_model()
    if found.n_dof == 2:
        return plate
    A = np.zeros((plate.A.shape[0], 3, 3))
    A[:, :2, :2] = plate.A
    A[:3, 2, :] = found.A[:3, 2, :]
    A[:3, :, 2] = found.A[:3, :, 2]
    return RationalFunctionModel(A, plate.d)


def refuted(fit: ClosedLoopFit, section: SectionModel, bounded_at: float | None) -> bool:
    """Tell whether the releases refute ``fit``'s maximum: it flutters below ``bounded_at``.

    ``bounded_at`` is the highest wind speed at which no release grew, m/s (None: nothing can
    refute). A maximum unstable in still air is refuted by any release that decayed.
    """
    return bounded_at is not None and _refuted(_flutter_speed(section, fit.model), bounded_at)


def _flutter_speed(section: SectionModel, model: RationalFunctionModel) -> float | None:
    """Return a maximum's flutter speed, m/s: None without flutter, 0 when unstable in still air.

    A maximum whose added mass overturns the structure's (:class:`StillAirModesError`) has a
    mode that grows without wind: any release that decayed refutes it, as a speed of zero.
    """
    try:
        return _flutter.analyze(section, model).speed
    except _flutter.StillAirModesError:
        return 0.0


def _refuted(speed: float | None, bounded_at: float) -> bool:
    """Tell whether the releases refute a flutter speed (None: none): below ``bounded_at``."""
    return speed is not None and speed < bounded_at
