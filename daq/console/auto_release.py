"""Hands-free releases for a simulated session in the console: fan, arm, release, decay, repeat.

Responsibility: :class:`AutoReleaser` drives the console's own
:class:`~daq.console.controls.ControlPanel` through a short test programme, one release per fan
speed given: set the fan and wait until it reads the speed, let the wind settle, arm (the model is
pulled back and held), hold, release, let the model decay for ``decay_s``, arm again (which ends the
decay), and go on with the next speed; at the end the fan is left running at the last speed. Every
step goes through the panel's actions, so the panel's and the drivers' safety rules apply exactly as
to an operator's clicks. It is polled by a ``QTimer`` on the GUI thread and never blocks. ``windrig
gui --simulate --auto-release RPM,RPM,...`` uses it to demonstrate a session (the README's
screenshot); a real rig is never driven by it (the command line refuses).

Not responsible for: the actions themselves (:mod:`daq.console.controls`) or fitting the releases
(:mod:`daq.console.live_ident`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

from PySide6 import QtCore

from daq.procedure import HOLD_S

__all__ = ["SETTLE_S", "AutoReleaser"]

#: Wind settling time once the fan reads its speed, s.
SETTLE_S = 0.5
#: The fan is at its speed within this fraction (or 2 rpm).
FAN_TOLERANCE = 0.005
#: Polling period, ms.
POLL_MS = 50


class AutoReleaser(QtCore.QObject):
    """One release per fan speed, through the console's control panel (module docstring).

    Parameters
    ----------
    panel : ControlPanel
        The live window's control panel.
    source : LiveSource
        Its source (``fan_speed_rpm``).
    speeds_rpm : sequence of float
        Fan speeds, rpm, one release each, in order (each within the rig's limits: the
        driver refuses others, and the programme stops with that error shown).
    decay_s : float
        Length of each free decay, s (> 0).
    clock : callable, optional
        Monotonic clock, s (a seam for tests).

    Attributes
    ----------
    step : str
        ``"fan"``, ``"settle"``, ``"arm"``, ``"hold"``, ``"release"``, ``"decay"``, ``"catch"``,
        ``"done"`` or ``"failed"``.
    releases : int
        Releases made so far.
    """

    def __init__(self, panel: Any, source: Any, speeds_rpm: Sequence[float], decay_s: float,
                 *, clock: Any = None, parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        speeds = [float(rpm) for rpm in speeds_rpm]
        if not speeds or not all(math.isfinite(rpm) and rpm > 0 for rpm in speeds):
            raise ValueError(f"speeds_rpm must be fan speeds > 0 rpm, got {list(speeds_rpm)!r}")
        if not (math.isfinite(decay_s) and decay_s > 0):
            raise ValueError(f"decay_s = {decay_s!r} must be a number of seconds > 0")
        self._panel = panel
        self._source = source
        self._speeds = speeds
        self._decay_s = float(decay_s)
        self._clock = clock if clock is not None else time.monotonic
        self._index = 0
        self._since = self._clock()
        self.step = "fan"
        self.releases = 0
        self._timer = QtCore.QTimer(self)
        self._timer.setInterval(POLL_MS)
        self._timer.timeout.connect(self.poll)

    def start(self) -> None:
        """Start the programme (the first step is setting the fan)."""
        self._enter("fan")
        self._panel.apply_fan(self._speeds[0])
        self._timer.start()

    def stop(self) -> None:
        """Stop polling (the rig stays as it is)."""
        self._timer.stop()

    @property
    def speed_rpm(self) -> float:
        """The fan speed of the current release, rpm."""
        return self._speeds[min(self._index, len(self._speeds) - 1)]

    def poll(self) -> None:
        """Advance the programme by at most one step (the timer's slot)."""
        panel = self._panel
        if self.step in ("done", "failed") or panel.busy is not None:
            return
        if " failed: " in panel.message:  # an action was refused: stop, leave it shown
            self._enter("failed")
            self._timer.stop()
            return
        waited = self._clock() - self._since
        rpm = self.speed_rpm
        if self.step == "fan":
            fan = float(self._source.fan_speed_rpm)
            if abs(fan - rpm) <= max(2.0, FAN_TOLERANCE * rpm):
                self._enter("settle")
        elif self.step == "settle" and waited >= SETTLE_S:
            if panel.armed():
                self._enter("hold")
            else:
                panel.arm()
                self._enter("arm")
        elif self.step == "arm" and panel.armed():
            self._enter("hold")
        elif self.step == "hold" and waited >= HOLD_S:
            panel.release(confirmed=True)
            self._enter("release")
        elif self.step == "release" and panel.armed() is False:
            self.releases += 1
            self._enter("decay")
        elif self.step == "decay" and waited >= self._decay_s:
            panel.arm()  # catches the model: the decay ends
            self._enter("catch")
        elif self.step == "catch" and panel.armed():
            self._index += 1
            if self._index >= len(self._speeds):
                self._enter("done")
                self._timer.stop()
                return
            panel.apply_fan(self._speeds[self._index])
            self._enter("fan")

    def _enter(self, step: str) -> None:
        self.step = step
        self._since = self._clock()
        n = len(self._speeds)
        where = f"release {min(self._index + 1, n)}/{n} at {self.speed_rpm:.0f} rpm"
        if step == "done":
            text = (f"auto: {self.releases} release(s) done; the fan stays at "
                    f"{self.speed_rpm:.0f} rpm")
        elif step == "failed":
            text = f"auto: stopped ({where}): {self._panel.message}"
        else:
            text = f"auto: {where}: {step}"
        self._panel.show_message(text)
