"""The wind of a campaign: the drive's ramp rate, and waiting for a steady wind at a set-point.

Responsibility: :func:`ramp_rate` (how long a change of set-point takes, from the fan's
settings) and :func:`wait_steady` (the set-point reached, then held within a tolerance for a
settle time, or a :class:`~daq.errors.DeviceError` after :data:`STEADY_TIMEOUT_S`).

Not responsible for: commanding the fan (the engine's commands, :mod:`daq.campaign.runner`).
"""

from __future__ import annotations

import threading
import time
from typing import Any

from daq.campaign.plan import DEFAULT_RAMP_RPM_PER_S
from daq.config import RigConfig
from daq.errors import DeviceError

__all__ = ["STEADY_TIMEOUT_S", "ramp_rate", "wait_steady"]

#: Longest wait for the wind to become steady at a set-point, s (beyond the ramp).
STEADY_TIMEOUT_S = 30.0


def ramp_rate(config: RigConfig, fan_name: str) -> float:
    """Return the drive's configured ramp rate, rpm/s (its settings' default otherwise)."""
    rate = config.instrument(fan_name).settings.get("ramp_rpm_per_s", DEFAULT_RAMP_RPM_PER_S)
    return float(rate)


def wait_steady(fan: Any, rpm: float, tolerance: float, settle_s: float,
                abort: threading.Event) -> None:
    """Wait for the set-point, then until the speed stays within tolerance for ``settle_s``.

    Parameters
    ----------
    fan : driver
        The fan drive (``wait_for_speed``, ``speed`` in rpm).
    rpm : float
        Set-point, rpm.
    tolerance : float
        Steady: within this fraction of the set-point (at least 2 rpm).
    settle_s : float
        How long the speed must stay within the tolerance, s.
    abort : threading.Event
        Set by Ctrl-C: stop waiting.

    Raises
    ------
    DeviceError
        The speed did not stay within the tolerance for ``settle_s`` within
        :data:`STEADY_TIMEOUT_S` plus ``settle_s``.
    """
    tol = max(2.0, tolerance * rpm)
    fan.wait_for_speed(rpm, tolerance_rpm=tol)
    deadline = time.monotonic() + STEADY_TIMEOUT_S + settle_s
    steady_since = time.monotonic()
    while time.monotonic() - steady_since < settle_s and not abort.is_set():
        if time.monotonic() > deadline:
            raise DeviceError(f"the wind did not stay within {100 * tolerance:g} % of "
                              f"{rpm:.0f} rpm for {settle_s:g} s within {STEADY_TIMEOUT_S:g} s")
        if abs(fan.speed() - rpm) > tol:
            steady_since = time.monotonic()
        time.sleep(0.05)
