"""More starts for the closed-loop search when its first maximum contradicts the releases.

Responsibility: given a closed-loop fit whose model flutters below a wind speed at which no
release grew (a maximum of the likelihood the data themselves refute), search again from other
starts and keep the fit of highest likelihood, saying so.

The closed-loop likelihood has more than one maximum when the buffeting is strong and the start
is poor (releases without holds in 3 % turbulence, where plain E2RFC's start may itself flutter
at a fraction of the true speed). Measured on the bluff deck of ``benchmarks/ident_accuracy.py``
at Iw 3 % without holds, seed 0: the first maximum fluttered at 0.13 m/s, 1 % of the truth; a
second search from its coefficients, with the buffeting and noise started afresh from the
records, rose 21 in log L and fluttered within 0.6 % of the truth. The extra searches run only
on such a contradiction, so a sound fit costs nothing more.

Not responsible for: the search itself (:mod:`ident.identification.closed_loop_ml`), nor for
deciding at which speed releases grew (the caller passes it).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from ident.identification.closed_loop_ml import ClosedLoopFit
from ident.model import flat_plate
from ident.model import flutter as _flutter
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel

__all__ = ["search_again"]


def search_again(fit: ClosedLoopFit, section: SectionModel, bounded_at: float | None,
                 refit: Callable[[RationalFunctionModel], ClosedLoopFit]
                 ) -> tuple[ClosedLoopFit, str | None]:
    """Return the fit of highest likelihood over more starts, when ``fit`` contradicts the data.

    Parameters
    ----------
    fit : ClosedLoopFit
        The search's first result.
    section : SectionModel
    bounded_at : float or None
        Highest wind speed at which no release grew, m/s (None: none; nothing to contradict).
    refit : callable
        ``refit(start)`` runs the same closed-loop search (same releases, structure and
        buffeting model) from another starting model; it may raise ValueError (no likelihood
        at that start), which skips the start.

    Returns
    -------
    ClosedLoopFit, str or None
        The fit kept (``fit`` itself unless another start reached a higher likelihood), and a
        note saying what was searched and found (None when ``fit`` did not contradict the data).
    """
    first = _flutter.analyze(section, fit.model).speed
    if bounded_at is None or first is None or first >= bounded_at:
        return fit, None
    starts: Sequence[tuple[str, RationalFunctionModel]] = (
        ("its own maximum with the buffeting and noise started afresh", fit.model),
        ("the flat plate's aerodynamics (Jones)", flat_plate.jones_model()),
    )
    best, tried, failed = fit, [], []
    for name, start in starts:
        try:
            other = refit(start)
        except ValueError as exc:
            failed.append(f"{name} ({exc})")
            continue
        tried.append(name)
        if other.neg_log_likelihood < best.neg_log_likelihood:
            best = other
    speed = _flutter.analyze(section, best.model).speed
    found = ("none" if speed is None else f"{speed:.3g} m/s")
    note = (f"turbulence: the likelihood's first maximum fluttered at {first:.3g} m/s, below "
            f"{bounded_at:.3g} m/s where no release grew; searched again from "
            f"{'; '.join(tried) or 'no other start'}"
            + (f" (could not start from {'; '.join(failed)})" if failed else "")
            + (f": kept a maximum {fit.neg_log_likelihood - best.neg_log_likelihood:.1f} higher "
               f"in log L, fluttering at {found}" if best is not fit
               else ": none reached a higher likelihood, the first is kept"))
    return best, note
