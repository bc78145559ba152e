"""The PLC's trigger pulses as clock anchors, and what a file says when its clocks have none.

A clock map built from arrival times alone places a device's samples late by its transport
latency (USB, Ethernet, driver), which nothing in the stream measures. The PLC's trigger pulses,
latched by the scanner and flagged by the lasers, measure it: each pulse paired with a device's
trigger time is an anchor (:meth:`~daq.sync.clock_map.ClockMap.add_anchor`). A file in which a
clocked device got no anchor is still aligned by the envelope, but its devices may sit that
latency apart (about a millisecond on the simulated rig, the size of the aerodynamic damping's
phase at 4 Hz): :meth:`TriggerPulses.anchor_warnings` says so, naming the likely cause.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping

from daq.recording.devices import TRIGGER_PAIRING_S, DeviceState

__all__ = ["MAX_ANCHOR_ROUND_TRIP_S", "TriggerPulses"]

#: A trigger pulse whose command took longer than this (round trip, s) is no anchor: its host
#: time, the midpoint, is off by at most half of it, and typically far less (the two legs are
#: alike); the clock map takes the median over its anchors. A slower pulse's midpoint can be
#: milliseconds off one way, worse for absolute time than no anchor at all (measured on a
#: loaded two-core host: taking pulses up to 20 ms moved the lasers' and scanner's absolute
#: times by 1-3 ms).
MAX_ANCHOR_ROUND_TRIP_S = 3e-3


def _no_anchor(names: list[str]) -> str:
    """Return the end of every anchor warning: whose map has no anchor, and what it means."""
    maps = (f"the clock map of {names[0]} has" if len(names) == 1 else
            f"the clock maps of {', '.join(names[:-1])} and {names[-1]} have")
    whose = "its" if len(names) == 1 else "their"
    return (f"{maps} no anchor, so {whose} samples are placed late by {whose} transport "
            f"latency, which no pulse measured (motion and forces may be misaligned by as "
            f"much)")


class TriggerPulses:
    """The PLC's trigger pulses of one file: the anchors among them and the counts.

    Attributes
    ----------
    events : deque of (float, float)
        The usable pulses (the latest 64): host time (s from the run start) and its
        uncertainty (s, half the pulse command's round trip).
    received, slow : int
        Pulses received in the file, and those too slow to be anchors.
    """

    def __init__(self) -> None:
        self.events: deque[tuple[float, float]] = deque(maxlen=64)
        self.received = 0
        self.slow = 0

    def take(self, t: float, round_trip_s: float) -> bool:
        """Take a pulse at host time ``t`` (s) whose command took ``round_trip_s`` (s).

        Returns
        -------
        bool
            Whether it is usable as an anchor (its round trip within the cut).
        """
        self.received += 1
        if not round_trip_s <= MAX_ANCHOR_ROUND_TRIP_S:  # NaN included: no known midpoint
            self.slow += 1
            return False
        self.events.append((t, 0.5 * round_trip_s))
        return True

    def anchor_warnings(self, devices: Mapping[str, DeviceState], *,
                        anchors_used: bool = True) -> list[str]:
        """Return a warning per cause for the clocked devices whose map got no anchor.

        Parameters
        ----------
        devices : mapping of str to DeviceState
            The file's devices; those without a clock map (polled ones) are not concerned.
        anchors_used : bool
            Whether the writer paired trigger times with pulses at all.

        Returns
        -------
        list of str
            One line per cause: anchors switched off, no pulse in the file, every pulse too
            slow, and per device a trigger input that reported nothing or paired nothing.
        """
        bare = [name for name, dev in devices.items()
                if dev.clock is not None and dev.clock.ready and dev.clock.n_anchors == 0]
        if not bare:
            return []
        if not anchors_used:
            return [f"trigger anchors are switched off: {_no_anchor(bare)}"]
        if self.received == 0:
            return [f"no PLC trigger pulse reached this file (no PLC, or its pulses off or "
                    f"failing): {_no_anchor(bare)}"]
        if self.slow == self.received:
            return [f"every one of the {self.received} PLC trigger pulses took over "
                    f"{MAX_ANCHOR_ROUND_TRIP_S * 1e3:g} ms to confirm (a loaded host or a slow "
                    f"PLC link), too long to time a pulse: {_no_anchor(bare)}"]
        usable = self.received - self.slow
        warnings = []
        for name in bare:
            dev = devices[name]
            if not dev.trigger_channel:
                cause = "reports no trigger times (its driver has no trigger input)"
            elif dev.trigger_times == 0:
                cause = ("reported no trigger time: is its trigger input wired to the PLC's "
                         "trigger line?")
            else:
                cause = (f"reported {dev.trigger_times} trigger time(s), none within "
                         f"{TRIGGER_PAIRING_S * 1e3:g} ms of one of the {usable} usable PLC "
                         f"pulses: is its trigger input on the PLC's trigger line?")
            assumed = dev.clock.latency_floor_s if dev.clock is not None else math.nan
            kept = (f" (the {assumed * 1e3:.3f} ms latency measured before its clock restarted "
                    f"is assumed)" if math.isfinite(assumed) and assumed > 0.0 else "")
            warnings.append(f"{name}: {cause}; {_no_anchor([name])}{kept}")
        return warnings
