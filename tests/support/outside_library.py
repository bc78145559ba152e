"""Physics outside the discrepancy workflow's library, simulated for its tests and benchmark.

None of these is one of the named effects (``ident.physics.effects.EFFECT_NAMES``) nor a sum
of them, so the honest answer of ``diagnose`` is ``explained = False`` and nothing named that
did not shrink the gap (issue 39):

- :class:`FreePlay`: the pitch spring has a small dead zone (a loose clamp), so the pitch
  stiffness falls to nothing for ``|alpha| < dead_zone``: a frequency that *falls* as the
  decay dies away, unlike a cubic spring, whose change grows with the amplitude;
- :class:`HeaveStop`: a stiff stop limits the heave amplitude (an impact with the rig's
  frame): a one-sided force only beyond ``gap``, active in the first cycles only;
- :func:`growing_mass_campaign`: the model's mass changes between releases (water collecting
  in the section during a campaign): each release has its own heave frequency, not a term
  any one model of all releases holds.

The two forces are :class:`ident.physics.effects.Effect` subclasses defined here, outside the
library: ``ident.simulation`` integrates any effect's ``structural_force``
(``ident.simulation.plant``). Strengths are chosen so that the decays change visibly (the
baseline's gap several times the 2 % noise).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from ident.model import flat_plate, flutter
from ident.physics.effects import Effect
from ident.records.release import Release
from simulators.campaigns import FRACTIONS, HOLDS, SECTION
from simulators.tunnel import simulate_release

FloatArray = npt.NDArray[np.float64]

#: The flat-plate rig's pitch stiffness, N m/m per rad (I w_a^2).
PITCH_STIFFNESS = SECTION.I * (2 * np.pi * SECTION.fa) ** 2
#: ... and heave stiffness, N/m per m (m w_h^2).
HEAVE_STIFFNESS = SECTION.m * (2 * np.pi * SECTION.fh) ** 2


@dataclass(frozen=True)
class FreePlay(Effect):
    """A pitch spring with a dead zone: no restoring moment for ``|alpha| < dead_zone``.

    The linear spring ``-k alpha`` of the model becomes ``-k (alpha - clip(alpha))``; the extra
    moment is ``+k clip(alpha, -dead_zone, dead_zone)``.

    Parameters
    ----------
    dead_zone : float
        Half-width of the dead zone, rad.
    stiffness : float
        The pitch spring it cuts into, N m/m per rad.
    """

    name: ClassVar[str] = "free_play"
    nonlinear: ClassVar[bool] = True
    dead_zone: float = 0.0005
    stiffness: float = float(PITCH_STIFFNESS)

    def structural_force(self, q: FloatArray, qd: FloatArray, B: float) -> FloatArray:
        """Return the extra generalised force ``[F_h B, M]``, N m/m."""
        return np.array([0.0, self.stiffness * float(np.clip(q[1], -self.dead_zone,
                                                                 self.dead_zone))])


@dataclass(frozen=True)
class HeaveStop(Effect):
    """A stiff stop beyond ``|h| = gap``: force ``-k_stop (|h| - gap) sgn(h)`` there, 0 inside.

    Parameters
    ----------
    gap : float
        Free travel either side of the rest position, m.
    k_stop : float
        Stiffness of the stop, N/m per m of penetration.
    """

    name: ClassVar[str] = "impact_stop"
    nonlinear: ClassVar[bool] = True
    gap: float = 0.0025
    k_stop: float = float(10 * HEAVE_STIFFNESS)

    def structural_force(self, q: FloatArray, qd: FloatArray, B: float) -> FloatArray:
        """Return the extra generalised force ``[F_h B, M]``, N m/m."""
        h = float(q[0]) * B
        penetration = max(abs(h) - self.gap, 0.0)
        return np.array([-self.k_stop * penetration * np.sign(h) * B, 0.0])


#: Mass added per release by :func:`growing_mass_campaign`, as a fraction of the model's mass.
MASS_STEP = 0.03


def growing_mass_campaign(seed: int, *, duration: float = 5.0, noise: float = 0.02,
                          step: float = MASS_STEP,
                          fractions: Sequence[float] = FRACTIONS) -> list[Release]:
    """Simulate the flat-plate campaign with the heave mass growing ``step`` per release.

    Release ``k`` (in the order of ``simulators.campaigns``: speeds, then holds) has the heave
    mass ``m (1 + step k)`` on the same spring, so its heave frequency is
    ``fh / sqrt(1 + step k)`` (-7 % at the sixth release with the default step); the pitch is
    unchanged (the water sits on the axis). Seeded like ``simulated_campaign``.
    """
    truth = flat_plate.jones_model()
    speed = flutter.analyze(SECTION, truth).speed
    assert speed is not None  # the flat plate flutters
    rng = np.random.default_rng(seed)
    releases = []
    k = 0
    for fraction in fractions:
        for h0, alpha0 in HOLDS:
            factor = 1.0 + step * k
            section = SECTION.replace(m=SECTION.m * factor, fh=SECTION.fh / np.sqrt(factor))
            sim = simulate_release(section, truth, fraction * speed, h0, alpha0,
                                   duration=duration, fs=500.0, noise=noise, rng=rng)
            releases.append(Release.from_simulation(
                sim, meta={"fraction": fraction, "h0": h0, "alpha0": alpha0,
                           "mass_factor": factor}))
            k += 1
    return releases
