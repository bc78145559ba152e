"""The console's interlocks: which operator actions the rig's state allows now, and why not.

Responsibility: :class:`Interlocks` decides, from a :class:`ConsoleState` (what the console
knows of the rig: the engine running, the devices present, the measured fan speed and wind,
the PLC's ARM state, an action in progress, the recording), which of the control panel's
actions are allowed, and for each refused one the reason shown to the operator (``"release:
arm first"``). The rules:

- nothing while the acquisition does not run;
- one blocking action at a time (fan, arm, release, CALZ wait for the one in progress);
- the fan's actions need a fan, arm and release a PLC, CALZ a scanner;
- release only when armed (and the ARM state read), arm only when not armed;
- a release by hand (the operator's word: the instant is found in the lasers' signals) and a
  hold by hand need no PLC, but not while a PLC's magnet holds the model;
- CALZ only with the fan stopped (measured at or below :data:`FAN_STOPPED_RPM` and no start
  commanded) for :data:`CALZ_SETTLE_S`, and the measured wind (a median over
  :data:`CALZ_WIND_WINDOW_S`) below :data:`CALZ_MAX_WIND`;
- record only from a source that can record and while not recording; stop recording only
  while recording.

Pure: no Qt, no I/O, no clock of its own (the caller passes ``now_s``); the only state kept is
when the fan was first seen stopped, for the settling time. The Qt panel
(:class:`daq.console.controls.ControlPanel`) only asks it.

Not responsible for: the drivers' and the engine's own checks (the fan limit, ARM before
RELEASE, CALZ wind-off are enforced there as well), or carrying the actions out.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["ACTIONS", "CALZ_MAX_WIND", "CALZ_SETTLE_S", "CALZ_WIND_WINDOW_S", "FAN_STOPPED_RPM",
           "LABELS", "ConsoleState", "Interlocks"]

#: CALZ only below this wind speed, m/s: the median over the last CALZ_WIND_WINDOW_S, a dynamic
#: pressure of ~1.4 Pa. Above the wind-off reading (Pitot noise of ~1 Pa per sample gives single
#: samples of 1-1.5 m/s, but a median of ~0) and a small zero drift, far below any test wind.
CALZ_MAX_WIND = 1.5
#: The wind's median is taken over this long, s.
CALZ_WIND_WINDOW_S = 1.0
#: CALZ only once the fan has been seen stopped for this long, s (the air in the circuit slows
#: down after the fan).
CALZ_SETTLE_S = 3.0
#: The fan counts as stopped at or below this measured speed, rpm.
FAN_STOPPED_RPM = 1.0

#: The control panel's actions, as the reasons name them.
LABELS = {"fan_apply": "fan", "fan_stop": "fan", "arm": "arm", "release": "release",
          "hand_release": "released by hand", "hand_hold": "held by hand",
          "calz": "CALZ", "mark": "mark", "record": "record", "stop_record": "stop recording"}
#: Every action the interlocks rule on.
ACTIONS = tuple(LABELS)


@dataclass(frozen=True)
class ConsoleState:
    """What the console knows of the rig when it asks the interlocks.

    Attributes
    ----------
    running : bool
        The acquisition engine runs.
    busy : str or None
        The blocking action in progress (``"fan"``, ``"arm"``, ``"release"``, ``"calz"``).
    has_fan, has_plc, has_scanner : bool
        The running rig has that device.
    fan_rpm : float
        Measured fan speed, rpm (NaN: not read yet).
    fan_commanded : bool
        A fan start was commanded and not stopped since (the fan may still be spinning up).
    armed : bool or None
        The PLC's ARM state (the newer of its reading and the console's own command); None:
        not read yet.
    wind_m_s : float or callable
        Measured wind speed, median over :data:`CALZ_WIND_WINDOW_S`, m/s (NaN: none yet); or
        a function returning it, called only when the CALZ rules get that far (measuring reads
        the source's buffer: the panel asks at every frame).
    can_record : bool
        The data source can record to a run file.
    recording : bool
        A recording is in progress (one that failed does not count).
    """

    running: bool
    busy: str | None = None
    has_fan: bool = False
    has_plc: bool = False
    has_scanner: bool = False
    fan_rpm: float = math.nan
    fan_commanded: bool = False
    armed: bool | None = None
    wind_m_s: float | Callable[[], float] = math.nan
    can_record: bool = False
    recording: bool = False


class Interlocks:
    """The rules of the module docstring, with the memory of when the fan stopped.

    Parameters
    ----------
    calz_settle_s : float
        How long the fan must have been seen stopped before a CALZ, s.
    calz_max_wind : float
        Highest measured wind speed for a CALZ, m/s.
    fan_stopped_rpm : float
        The fan counts as stopped at or below this speed, rpm.
    """

    def __init__(self, *, calz_settle_s: float = CALZ_SETTLE_S,
                 calz_max_wind: float = CALZ_MAX_WIND,
                 fan_stopped_rpm: float = FAN_STOPPED_RPM) -> None:
        self.calz_settle_s = float(calz_settle_s)
        self.calz_max_wind = float(calz_max_wind)
        self.fan_stopped_rpm = float(fan_stopped_rpm)
        self._fan_stopped_at: float | None = None  # now_s when the fan was first seen stopped

    def refusals(self, state: ConsoleState, now_s: float) -> dict[str, str]:
        """Return the refused actions, each with its reason (``"release: arm first"``).

        Parameters
        ----------
        state : ConsoleState
            The rig as the console knows it now.
        now_s : float
            A monotonic clock, s (the fan's settling time is measured on it).

        Returns
        -------
        dict of str to str
            Action (one of :data:`ACTIONS`) -> reason; the allowed actions are absent. The
            first reason found for an action is kept (the order of the module docstring).
        """
        reasons: dict[str, str] = {}

        def refuse(keys: tuple[str, ...], why: str) -> None:
            for key in keys:
                reasons.setdefault(key, f"{LABELS[key]}: {why}")

        if not state.running:
            refuse(ACTIONS, "acquisition not running")
        if state.busy is not None:
            refuse(("fan_apply", "arm", "release", "calz"), f"busy ({state.busy})")
        if not state.has_fan:
            refuse(("fan_apply", "fan_stop"), "no fan in this rig")
        if not state.has_plc:
            refuse(("arm", "release"), "no PLC in this rig")
        elif state.armed is None:
            refuse(("release",), "PLC state not read yet")
        elif not state.armed:
            refuse(("release",), "arm first")
        else:
            refuse(("arm",), "already armed")
            # The magnet holds the model: no hand can let it go (release through the PLC).
            refuse(("hand_release",), "the PLC's magnet holds the model (disarm, or release)")
        self._check_fan_for_calz(state, now_s, refuse)
        if "calz" not in reasons:  # measured only now: measuring reads the buffer
            wind = state.wind_m_s() if callable(state.wind_m_s) else float(state.wind_m_s)
            if not math.isfinite(wind):
                refuse(("calz",), "wind speed not measured yet")
            elif wind >= self.calz_max_wind:
                refuse(("calz",), f"wind {wind:.2f} m/s, must be below "
                                  f"{self.calz_max_wind:g} m/s")
        if not state.can_record:
            refuse(("record", "stop_record"), "this source cannot record")
        elif state.recording:
            refuse(("record",), "already recording")
        else:
            refuse(("stop_record",), "not recording")
        return reasons

    def _check_fan_for_calz(self, state: ConsoleState, now_s: float,
                            refuse: Callable[[tuple[str, ...], str], None]) -> None:
        """Apply the CALZ rules before the wind: a scanner, and the fan stopped and settled."""
        if not state.has_scanner:
            refuse(("calz",), "no scanner in this rig")
            return
        if not state.has_fan:
            return
        if math.isnan(state.fan_rpm):
            refuse(("calz",), "fan speed not read yet")
        elif state.fan_rpm > self.fan_stopped_rpm or state.fan_commanded:
            self._fan_stopped_at = None
            refuse(("calz",), "stop the fan first")
        else:
            if self._fan_stopped_at is None:
                self._fan_stopped_at = now_s
            settled = now_s - self._fan_stopped_at
            if settled < self.calz_settle_s:
                refuse(("calz",), f"fan stopped {settled:.0f} s ago, wait "
                                  f"{self.calz_settle_s:g} s for the air to settle")
