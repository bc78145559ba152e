"""The fan's actual speed against its set-point: a ``"fan_reached"`` event once it settles.

Responsibility: :class:`FanWatch`, a ``(name, doc)`` subscriber the engine puts before every
other (:class:`~daq.acquisition.engine.Acquisition`), follows the fan commands of the run (the
``fan_speed``, ``fan_start`` and ``fan_stop`` events: the speed the drive is asked for is the
set-point while it runs, 0 once stopped) and the drive's polled actual speed (the fan's
``speed`` channel, rpm). When the target changed and the actual speed then stays within
tolerance of it for :data:`SETTLE_POLLS` polls in a row, it posts one ``"fan_reached"`` event
at the first of those polls, with the actual speed, the target and the time since the command:
the run's record of when the wind was there. A target not reached in the time the drive's ramp
allows (the driver's own ``wait_for_speed`` allowance: 1.5 times the ramp's time, plus 2 s) is
a ``"warning"`` event, once per command. Runs on the dispatcher thread (no lock needed).

Not responsible for: commanding the fan (:mod:`daq.acquisition.commands`) or refusing speeds
(the driver).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from daq.acquisition.records import Event

__all__ = ["SETTLE_POLLS", "FanWatch", "reached_tolerance_rpm"]

#: Polls in a row (10 Hz) the actual speed must stay within tolerance: 0.3 s, past the
#: overshoot of a ramp's end.
SETTLE_POLLS = 3


def reached_tolerance_rpm(target_rpm: float) -> float:
    """Return how close the actual speed must come to ``target_rpm``: 1 % of it, at least 5 rpm.

    A drive regulates its speed to a fraction of a percent; 5 rpm lies well above the
    resolution of a fieldbus speed reference (an ABB drive's 20000 counts, or PROFIdrive's
    0x4000, over a maximum of 1500 rpm: 0.075 or 0.09 rpm) with room for the actual value's
    noise. The speeds are the fan driver's, in rpm (docs/guides/drivers.md); its scaling is its own.
    """
    return max(0.01 * abs(target_rpm), 5.0)


class FanWatch:
    """Watch one fan drive's speed against its set-point (see the module docstring).

    Parameters
    ----------
    fan : str
        The fan drive's device name.
    post_event : callable
        Posts an :class:`~daq.acquisition.records.Event` (the engine's).
    ramp_rpm_per_s : float, optional
        The drive's ramp (its driver's ``settings.ramp_rpm_per_s``); None: no warning when a
        target takes long.
    """

    def __init__(self, fan: str, post_event: Callable[[Event], None],
                 ramp_rpm_per_s: float | None = None) -> None:
        self.fan = fan
        self._post = post_event
        self._ramp = ramp_rpm_per_s
        self._actual = 0.0  # the last actual speed read, rpm
        self._deadline_ns: int | None = None  # warn when the target is not reached by then
        self._setpoint = 0.0
        self._running = False
        self._target = 0.0  # what the drive was last asked for (0 before any command)
        self._pending: tuple[float, int] | None = None  # (target, command host ns)
        self._streak: list[tuple[int, float]] = []  # polls within tolerance: (host ns, rpm)

    def __call__(self, name: str, doc: Any) -> None:
        """Take one engine doc (dispatcher thread): a fan command, or the fan's readings."""
        if name == "event" and getattr(doc, "device", None) == self.fan:
            self._command(doc)
        elif name == "block" and getattr(doc, "device", None) == self.fan:
            self._speeds(doc.host_time_ns, doc.values.get("speed"))

    def _command(self, event: Event) -> None:
        if event.kind == "fan_speed":
            self._setpoint = float(event.data.get("rpm", self._setpoint))
        elif event.kind == "fan_start":
            self._running = True
        elif event.kind == "fan_stop":
            self._running = False
        else:
            return
        target = self._setpoint if self._running else 0.0
        if target != self._target:
            self._target = target
            self._pending = (target, int(event.host_time_ns))
            self._streak = []
            self._deadline_ns = None
            if self._ramp is not None and self._ramp > 0:
                allowed_s = 1.5 * abs(target - self._actual) / self._ramp + 2.0
                self._deadline_ns = int(event.host_time_ns) + round(allowed_s * 1e9)

    def _speeds(self, host_ns: Any, speed: Any) -> None:
        if self._pending is None or speed is None:
            return
        target, commanded = self._pending
        tolerance = reached_tolerance_rpm(target)
        for t_ns, rpm in zip(np.asarray(host_ns).tolist(), np.asarray(speed).tolist(),
                             strict=True):
            if math.isfinite(rpm):
                self._actual = float(rpm)
            if t_ns < commanded:
                continue
            if self._deadline_ns is not None and t_ns > self._deadline_ns:
                self._deadline_ns = None
                self._post(Event(kind="warning", host_time_ns=int(t_ns), device=self.fan,
                                 text=f"fan has not reached {target:g} rpm after "
                                      f"{(t_ns - commanded) * 1e-9:.1f} s (actual {rpm:.0f} "
                                      f"rpm, ramp {self._ramp:g} rpm/s)",
                                 data={"rpm": rpm, "setpoint_rpm": target}))
            if not (math.isfinite(rpm) and abs(rpm - target) <= tolerance):
                self._streak = []
                continue
            self._streak.append((int(t_ns), float(rpm)))
            if len(self._streak) >= SETTLE_POLLS:
                first_ns, first_rpm = self._streak[0]
                self._pending, self._streak = None, []
                text = (f"fan reached {first_rpm:.0f} rpm (set-point {target:g} rpm)"
                        if target else "fan stopped (0 rpm reached)")
                self._post(Event(kind="fan_reached", host_time_ns=first_ns, device=self.fan,
                                 text=text, data={"rpm": round(first_rpm, 1),
                                                  "setpoint_rpm": target,
                                                  "after_s": round((first_ns - commanded) * 1e-9,
                                                                   3)}))
                return
