"""The test procedure's timing, shared by the console and the scripted campaigns.

Responsibility: how long the model is held between arming and releasing (:data:`HOLD_S`) and
how long a free decay is recorded (:func:`default_decay_s`: :data:`MIN_DECAY_PERIODS` periods of
the slower structural mode). The console's releases table (:mod:`daq.console.live_ident`), its
hands-free releases (:mod:`daq.console.auto_release`) and the simulated campaign
(:mod:`daq.sim.campaign`) all follow them, so that a decay cut live and one recorded by a
campaign are alike.

Not responsible for: the releases themselves (the engine's commands) or fitting them
(:mod:`ident`).
"""

from __future__ import annotations

from ident.model.section import SectionModel

__all__ = ["HOLD_S", "MIN_DECAY_PERIODS", "default_decay_s"]

#: Held time between arming and releasing, s (the recorded h0, alpha0 are taken over it).
HOLD_S = 0.5
#: Periods of the slower structural mode a decay must hold.
MIN_DECAY_PERIODS = 15.0


def default_decay_s(section: SectionModel) -> float:
    """Decay length, s: ``MIN_DECAY_PERIODS`` periods of the slower structural mode.

    15 periods give the modal fits of E2RFC enough cycles for a frequency and a damping ratio to
    better than a percent; the amplitude is then still well above the noise (with 0.5 % damping
    the envelope loses ``exp(-2 pi 0.005 15)`` ~ 38 %; even at 5 % aerodynamic damping in heave
    it keeps ~1 %, the end of the decay then adds little but costs nothing in the fit). On the
    flat-plate rig (fh = 2 Hz) this is 7.5 s, so a default campaign (3 speeds x 2 releases) is
    ~6 x 8 s of decays plus the fan ramps, ~80 s of wall time, inside the ~150 s budget.
    """
    return MIN_DECAY_PERIODS / min(section.fh, section.fa)
