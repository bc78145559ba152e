"""The one rule every named effect passes: its addition shrinks the simulated gap by a margin.

The *gap* the rule uses is the simulated one (:func:`ident.discrepancy.effect_selection.gap`):
every release simulated from its own initial state with the model and its named effects, RMS
difference to the measurements per channel over the channel's RMS, mean of the four channels.
The held-out score of the selection (:mod:`ident.discrepancy.effect_selection`) only decides
which candidate is *tried*; this rule decides whether it is *named*. Every path that can name
an effect (forward selection; the joint refit of the effects chosen before; a measurement
effect taken out of the data and E2RFC run again; the shedding lines added to the simulated
forces; the aerodynamic nonlinearity's force taken out of the forces) ends in one trial model
whose gap is judged by :func:`judge`, and nothing else adds to the named effects.

The margin is relative to the gap white measurement noise alone would leave
(:func:`noise_gap`): ``gap_before - gap_after >= GAP_MARGIN * noise_gap``. Each release's own
gap change (mean and standard error over the releases) is reported beside it but is not part
of the decision: with two effects hidden, the first one named shrinks some releases' gaps a
lot and others' hardly or not at all while the other effect dominates them (a static
unbalance beside a cubic spring: +0.0305 +- 0.0290 per release for a total shrink of 0.029,
0.1426 -> 0.1136), so a test of consistency over the releases rejected true effects.

A step that does not pass is undone (the model stays as it was) and its verdict keeps both
gaps.

Not responsible for: the candidates' held-out scores, the trial models (
:mod:`ident.discrepancy.effect_selection`), the verdict on what is left
(:mod:`ident.discrepancy.residual_check`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ident.discrepancy.residual_check import systematic_levels
from ident.records.release import Release

__all__ = ["GAP_MARGIN", "GapStep", "judge", "noise_gap"]

FloatArray = npt.NDArray[np.float64]

#: The shrink of the gap an effect must bring, as a fraction of the gap white noise leaves.
#:
#: Why 0.1: :mod:`ident.discrepancy.residual_check` calls a channel's residual systematic when
#: its systematic RMS exceeds the noise's (``NOISE_RATIO = 1``). Taking out of one channel a
#: systematic residual exactly as large as the noise (RMS ``s = sigma``) lowers that channel's
#: gap from ``sqrt(sigma^2 + s^2) = 1.41 sigma`` to ``sigma``, and the four-channel mean by
#: ``(sqrt(2) - 1) / 4 = 0.10`` of the noise's gap. So an effect is named only if it removes at
#: least the smallest residual the honesty check would report (or the same spread over more
#: channels). The noise's own scatter of a paired gap change is far below this margin: with
#: the same noise in both simulations, only ``2 (s_before - s_after) . n`` varies, and a
#: channel's gap change then has a standard deviation of ``d / sqrt(N)`` (``d`` the change of
#: the simulated channel over its RMS): 0.0003 for a change of 5 % over a campaign of
#: N = 22 500 samples, about 0.02 of the noise's gap at 2 % noise. The margin is five times
#: that, a clear change and not a lucky one. It is not tuned to a case:
#: at 2 % noise it is 0.002 of gap, against 0.0035 for the smallest real step seen in the
#: confusion benchmark (a floor vibration beside a delay, 0.2862 -> 0.2827).
GAP_MARGIN = 0.1

@dataclass(frozen=True)
class GapStep:
    """The rule applied to one trial: the gaps before and after adding a candidate.

    Attributes
    ----------
    before, after : float
        The simulated gap (dimensionless, mean of the channels' normalised RMS differences)
        of the model before the candidate and of the trial model with it.
    noise : float
        The gap white measurement noise alone would leave (:func:`noise_gap`).
    required : float
        The shrink the rule requires, ``GAP_MARGIN * noise``.
    release_mean, release_se : float
        Mean over the releases of each release's gap change (before minus after) and its
        standard error (NaN with fewer than two releases); reported, not decided on (module
        docstring).
    """

    before: float
    after: float
    noise: float
    required: float
    release_mean: float = math.nan
    release_se: float = math.nan

    @property
    def shrink(self) -> float:
        """Return ``before - after`` (positive: the gap shrank)."""
        return self.before - self.after

    @property
    def accepted(self) -> bool:
        """True when the gap shrank by at least :attr:`required` (and is finite)."""
        return (math.isfinite(self.after) and self.after < self.before
                and self.shrink >= self.required)

    def text(self) -> str:
        """Return the gaps and the margin in one phrase."""
        after = (f"{self.after:.4f}" if math.isfinite(self.after)
                 else f"{self.after} (the trial model's simulation diverged)")
        text = (f"gap {self.before:.4f} -> {after}, needs <= "
                f"{self.before - self.required:.4f} (a shrink of {GAP_MARGIN:g} x the noise's "
                f"gap {self.noise:.4f})")
        if math.isfinite(self.release_mean):
            text += f"; per release {self.release_mean:+.4f} +- {self.release_se:.4f}"
        return text


def noise_gap(releases: Sequence[Release], *simulated: Sequence[dict[str, FloatArray]]) -> float:
    """Return the gap that white measurement noise alone would leave, dimensionless.

    Per channel the noise's RMS over the channel's RMS, from the first differences of measured
    minus simulated (:func:`ident.discrepancy.residual_check.systematic_levels`), averaged over
    the channels like the gap. A systematic residual can only inflate that estimate (a line
    well above the modes, shedding, survives differencing), so with several simulations the
    smallest estimate is taken.

    Parameters
    ----------
    releases : sequence of Release
        The measured decays.
    *simulated : sequence of dict
        One or more simulations of them (per release, the four channels as measured).
    """
    if not simulated:
        raise ValueError("noise_gap needs at least one simulation of the releases")
    estimates = []
    for sim in simulated:
        levels = systematic_levels(releases, sim)
        estimates.append(float(np.mean([noise for _, noise in levels.values()]))
                         if levels else 0.0)
    return min(estimates)


def judge(before: float, after: float, noise: float,
          per_release: Sequence[tuple[float, float]] = ()) -> GapStep:
    """Apply the rule: did the gap shrink by at least the margin.

    Parameters
    ----------
    before, after : float
        The simulated gaps without and with the candidate (dimensionless).
    noise : float
        The noise's gap (:func:`noise_gap`), >= 0.
    per_release : sequence of (float, float)
        Each release's gap before and after (the same measure on one release), reported in
        the step (fewer than two: not reported).

    Returns
    -------
    GapStep
        With ``accepted`` the verdict.

    Raises
    ------
    ValueError
        If ``noise`` is negative or not finite, or ``before`` is not finite.
    """
    if not (math.isfinite(noise) and noise >= 0.0):
        raise ValueError(f"noise gap must be finite and >= 0, got {noise!r}")
    if not math.isfinite(before):
        raise ValueError(f"gap before must be finite, got {before!r}")
    mean = se = math.nan
    if len(per_release) >= 2 and math.isfinite(after):
        change = np.array([b - a for b, a in per_release], dtype=float)
        mean = float(change.mean())
        se = float(change.std(ddof=1) / math.sqrt(change.size))
    return GapStep(before=float(before), after=float(after), noise=float(noise),
                   required=GAP_MARGIN * float(noise), release_mean=mean, release_se=se)
