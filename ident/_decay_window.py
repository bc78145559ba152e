"""Where a release in turbulence is still a decay: the window E2RFC fits (private to ident.e2rfc).

In turbulent flow the measured displacement is ``x_det + x_rand``: the release's deterministic
decay, which dies out, plus the random (buffeting) response, which is stationary and
narrow-band at the modal frequencies. E2RFC's regressors come from a modal fit (damped
sinusoids) of the displacement, and its error term is ``F_se(x_rand) + F_b``. Late in a long
release the record is mostly random response: the modal fit then bends its damping and
amplitudes towards it, and the regressors become correlated with the error term. Those samples
carry almost no information about the decay but most of the bias.

So each release is cut where its decay's envelope (from the modal fit of the whole record,
``sum |C_k| e^{Re(p_k) t}`` per channel) has fallen to ``ENVELOPE_RATIO`` times the level of the
random response (the RMS of the modal fit's residual, which in turbulence is the random
response: :data:`ident.e2rfc.RANDOM_RESPONSE_LIMIT`), on both channels; the modal fit and the
regressors are then computed again on the kept part. A release keeps at least
``MIN_KEPT_PERIODS`` periods of its slowest mode and ``MIN_KEPT_FRACTION`` of its record (and
never more than it has).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from ident.errors import IdentError
from ident.modal import ModalFit, fit_modes
from ident.release import Release

__all__ = ["ENVELOPE_RATIO", "MIN_KEPT_FRACTION", "MIN_KEPT_PERIODS", "decay_window", "truncated"]

FloatArray = npt.NDArray[np.float64]

#: A release is cut where its decay's envelope falls below this many times the RMS of the
#: random response, on both channels (the choice is measured in docs/identification.md).
ENVELOPE_RATIO = 2.0
#: Fewest periods of the slowest mode a cut release keeps.
MIN_KEPT_PERIODS = 10.0
#: Smallest fraction of its record a cut release keeps (a spurious fast "slowest" mode of a
#: poor whole-record fit must not cut a release to a few periods of its real modes).
MIN_KEPT_FRACTION = 0.25


def decay_window(release: Release, fit: ModalFit, ratio: float | None = None) -> float:
    """Return the time (s) up to which the release's decay dominates its random response.

    The decay's envelope comes from a modal fit of the release's first ``MIN_KEPT_PERIODS``
    periods (of the slowest mode of ``fit``), where the decay dominates: the random response
    starts from rest at the release and builds up over many periods, while a fit of the whole
    record follows it (its damping can even come out negative). The random response's level is
    the RMS about the equilibrium over the record's last quarter (the decay is gone there, or
    what is left of it counts as random: a conservative, earlier cut).

    Parameters
    ----------
    release : Release
    fit : ModalFit
        Modal fit of the release's displacements ``[h/B, alpha]`` on its whole record.
    ratio : float, optional
        Envelope over the random response's RMS at the cut (default ``ENVELOPE_RATIO``).

    Returns
    -------
    float
        The end of the window, s (the release's last time when the decay never falls that low).
    """
    ratio = ENVELOPE_RATIO if ratio is None else ratio
    t = release.t
    if fit.modes.size == 0 or not float(fit.frequencies.min()) > 0.0:
        return float(t[-1])
    floor = float(t[0]) + max(MIN_KEPT_PERIODS / float(fit.frequencies.min()),
                              MIN_KEPT_FRACTION * float(t[-1] - t[0]))
    if floor >= t[-1]:
        return float(t[-1])
    q = np.column_stack([release.h, release.alpha])
    early = t <= floor
    try:
        start = fit_modes(t[early], q[early])
    except IdentError:
        return floor
    tail = q[t >= t[0] + 0.75 * (t[-1] - t[0])]
    level = np.maximum(np.sqrt(np.mean((tail - start.offset) ** 2, axis=0)), 1e-300)
    decay = np.minimum(start.poles.real, 0.0)  # a growing first fit is not trusted to grow
    envelope = np.exp(np.outer(t, decay)) @ np.abs(start.amplitudes)  # (n, 2)
    above = np.flatnonzero(np.any(envelope > ratio * level, axis=1))
    last = float(t[above[-1]]) if above.size else float(t[0])
    return float(min(max(last, floor), t[-1]))


def truncated(release: Release, end: float) -> Release:
    """Return the release cut at time ``end`` (s); the release itself when nothing is cut."""
    keep = release.t <= end
    if keep.all():
        return release
    n = max(int(np.count_nonzero(keep)), 64)
    meta = dict(release.meta)
    meta["decay_window_s"] = float(release.t[n - 1] - release.t[0])
    return Release(t=release.t[:n], h=release.h[:n], alpha=release.alpha[:n],
                   lift=release.lift[:n], moment=release.moment[:n], U=release.U,
                   rho=release.rho, meta=meta)


def kept_fraction(original: Release, cut: Release) -> float:
    """Fraction of the release's duration kept by the window."""
    return float(cut.t.size) / float(original.t.size) if original.t.size else math.nan
