"""How a campaign holds and releases the model: through the PLC, or by the operator's hand.

Responsibility: :func:`releaser` returns what the campaign's actions call to hold the model,
release it, catch it when a decay grows, and hold it when the campaign is interrupted:

- :class:`PlcReleases`: the engine's PLC commands (``arm``, ``release``), as always;
- :class:`ManualReleases`: a rig without a PLC (or a plan with ``release = "manual"``): the
  campaign prompts the operator on the terminal between releases and waits for Enter ("catch
  the model and hold it still", "let the model go by hand"), then records the operator's word
  (``manual_hold``, ``manual_release``); the run writer finds each release instant in the
  lasers' signals (:mod:`daq.recording.releases`). On a simulated rig the prompt is answered
  the same way and the simulated operator's hand acts through the virtual tunnel
  (:meth:`daq.sim.rig_process.RigProcess.hand_release`) before the key is recorded, a little
  after the release as a person's would be.

Not responsible for: deciding which (the plan's ``release`` key, checked against the rig before
the fan turns: :meth:`daq.campaign.plan.CampaignPlan.check_rig`), or waiting for the decays (the
runner).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any

from daq.errors import OperatorError

__all__ = ["KEY_LAG_S", "ManualReleases", "PlcReleases", "ask_on_terminal", "releaser"]

#: On a simulated rig, the simulated operator's key comes this long after the hand's release
#: (a person's key comes later; the writer looks back up to 4 s).
KEY_LAG_S = 0.3
#: On a simulated rig, the simulated operator holds the model still at least this long before
#: letting it go (the detector needs a still hold of 0.3 s; the plan's hold_s may be shorter).
SIMULATED_HOLD_S = 1.0


def ask_on_terminal(prompt: str) -> None:
    """Print ``prompt`` and wait for the operator's Enter on standard input.

    Raises
    ------
    OperatorError
        Standard input ended (no operator at the terminal): the campaign cannot go on.
    """
    print(prompt, flush=True)
    if not sys.stdin.readline():
        raise OperatorError(f"no operator: standard input ended at the prompt {prompt.strip()!r}"
                            " (a campaign with releases by hand needs a terminal)")


class PlcReleases:
    """Hold and release through the PLC (the engine's ``arm`` and ``release``)."""

    manual = False
    #: Seconds the model is held before the release (the plan's hold_s).
    min_hold_s = 0.0

    def hold(self, acq: Any) -> None:
        """Arm: the magnet catches and holds the model."""
        acq.arm()

    def release(self, acq: Any) -> None:
        """Release through the PLC."""
        acq.release()

    def catch(self, acq: Any) -> None:
        """Catch a growing decay at once (arm), before the fan is stopped."""
        acq.arm()

    def interrupted(self, acq: Any) -> None:
        """Hold the model before an interrupted run ends."""
        acq.arm()


class ManualReleases:
    """Hold and release by the operator's hand, prompted on the terminal.

    Parameters
    ----------
    ask : callable
        ``ask(prompt)`` shows the prompt and returns once the operator confirms
        (:func:`ask_on_terminal`).
    say : callable
        Receives progress lines (a warning when a run is interrupted).
    hand : callable, optional
        ``hand("release")`` / ``hand("hold")``: a simulated operator's hand (None on a real rig).
    """

    manual = True

    def __init__(self, ask: Callable[[str], Any], say: Callable[[str], None],
                 hand: Callable[[str], Any] | None = None) -> None:
        self.ask, self.say, self.hand = ask, say, hand
        #: Seconds the model is held before the release: a simulated hand holds it long
        #: enough for the detector; a person decides when to let go.
        self.min_hold_s = SIMULATED_HOLD_S if hand is not None else 0.0

    def hold(self, acq: Any) -> None:
        """Prompt: catch the model and hold it still; record ``manual_hold`` on Enter."""
        self.ask("  >>> catch the model and hold it still at its hold position, then press "
                 "Enter")
        if self.hand is not None:
            self.hand("hold")
        acq.manual_hold()

    def release(self, acq: Any) -> None:
        """Prompt: let the model go by hand; record ``manual_release`` on Enter."""
        self.ask("  >>> let the model go by hand (from rest, no push), then press Enter")
        if self.hand is not None:
            self.hand("release")
            time.sleep(KEY_LAG_S)  # the simulated operator's key, after the release
        acq.manual_release()

    def catch(self, acq: Any) -> None:
        """Tell the operator to catch a growing decay now (the fan is stopped next)."""
        if self.hand is not None:
            self.hand("hold")
        self.say("  >>> THE DECAY GROWS: catch the model NOW; the fan is stopping")
        acq.manual_hold("operator told to catch a growing decay")

    def interrupted(self, acq: Any) -> None:
        """Ctrl-C: tell the operator to catch the model (no prompt: the run is ending)."""
        if self.hand is not None:
            self.hand("hold")
        self.say("  >>> interrupted: catch the model and hold it; the fan is stopping")


def releaser(method: str, *, rig: Any = None, ask: Callable[[str], Any] | None = None,
             say: Callable[[str], None] = print) -> PlcReleases | ManualReleases:
    """Return the campaign's way of releasing: ``method`` ``"plc"`` or ``"manual"``.

    ``rig``: a simulated rig in its own process (its hand acts for a manual release); ``ask``:
    the prompt (default :func:`ask_on_terminal`).
    """
    if method == "plc":
        return PlcReleases()
    if method != "manual":
        raise ValueError(f"release method {method!r}: plc or manual")
    hand = None
    if rig is not None:
        def hand(what: str) -> Any:
            return rig.hand_release() if what == "release" else rig.hand_hold()
    return ManualReleases(ask or ask_on_terminal, say, hand)
