"""Driver of a Scanivalve DSA3217-class scanner: windrig's scanner role (docs/guides/drivers.md).

One TCP connection (the unit's Telnet port, 23) carries both the ASCII commands and, once
``SCAN`` is sent with ``FORMAT B``, the binary packets (:mod:`windrig_dsa3217.packets`).

Commands used (DSA3200 software manual, "Commands"): ``SET PERIOD`` (microseconds per channel
sample), ``SET AVG`` (samples averaged per frame), ``SET FPS 0`` (scan until ``STOP``),
``SET FORMAT B`` (binary packets), ``SET TIME 1`` (a time stamp in every packet), ``SET EU 1``
(engineering units), ``SCAN``, ``STOP``, ``CALZ`` (zero through the unit's calibration valve)
and ``STATUS``. [unverified] The frame period is ``PERIOD x AVG x 16`` microseconds (16
channels sampled in turn); the ``STATUS`` reply is one line ``STATUS: READY`` (or ``SCAN``,
``CALZ``); commands end in CR LF and ``SET`` commands are not answered.

The driver keeps its stream continuous across scans (after a CALZ or a lost connection): the
counter and device time of a new scan go on from the last frame read, and the rows between are
one gap of kind ``"restart"``, its length estimated from the host's clock. The DSA3217 has no
trigger time stamp: ``trigger_time`` is NaN throughout (``trigger_input = False``).
"""

from __future__ import annotations

import collections
import math
import re
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from daq.errors import DeviceError, ProtocolError, SafetyError, TransportError, TransportTimeout
from daq.instruments.entry import DriverEntry
from daq.instruments.reading import Gap, Reading
from windrig_dsa3217.packets import PACKET_SIZE, TIME_UNIT_S, decode
from windrig_dsa3217.settings import CHANNELS, Dsa3217Settings

__all__ = ["DRIVER", "Dsa3217"]

_STATUS = re.compile(rb"STATUS:\s*(\w+)")


class Dsa3217:
    """A DSA3217 on a byte transport (``tcp://host:23``); the constructor does no I/O.

    Parameters
    ----------
    transport : Transport
        The unit's TCP connection, not yet open.
    settings : Dsa3217Settings or mapping
        Validated settings, or a rig-config table to validate.
    """

    #: No trigger input with a time stamp: ``trigger_time`` is NaN (docs/guides/drivers.md).
    trigger_input = False

    def __init__(self, transport: Any, settings: Dsa3217Settings | Mapping[str, Any]) -> None:
        if not isinstance(settings, Dsa3217Settings):
            settings = Dsa3217Settings.from_table(settings)
        self.transport = transport
        self.settings = settings
        self.stats = {"reconnects": 0, "packets": 0}
        self._buffer = bytearray()
        self._scanning = False
        self._last: tuple[int, float, int] | None = None  # counter, device time s, host ns
        self._scan_base: tuple[int, float] | None = None  # counter, time added in this scan
        self._wrap = 0  # 2**32 time units already passed in this scan
        self._raw_time: int | None = None
        self._pause_s = 0.0
        self._recent: collections.deque[np.ndarray] = collections.deque(
            maxlen=max(1, round(0.5 * settings.rate_hz)))

    # -- life cycle --------------------------------------------------------------------------
    def open(self) -> None:
        """Connect."""
        self.transport.open()

    def close(self) -> None:
        """Stop a scan (best effort) and disconnect; idempotent."""
        if self._scanning and self.transport.is_open:
            self.transport.write(b"STOP\r\n")
        self._scanning = False
        self.transport.close()

    def describe(self) -> dict[str, dict[str, Any]]:
        """Describe the channels of :meth:`read` (16 pressures, one module)."""
        return {
            "pressure": {"units": "Pa", "dtype": "float64", "shape": (CHANNELS,)},
            "pitot": {"units": "Pa", "dtype": "float64", "shape": ()},
            "trigger_time": {"units": "s", "dtype": "float64", "shape": ()},
            "module_status": {"units": "1", "dtype": "int8", "shape": (1,)},
        }

    @property
    def rate_hz(self) -> float:
        """Measure the configured frame rate, Hz."""
        return self.settings.rate_hz

    @property
    def serial_numbers(self) -> tuple[int | None, ...]:
        """Measure the module serial numbers (the packets carry none: unknown)."""
        return (None,)

    # -- commands ----------------------------------------------------------------------------
    def _send(self, text: str) -> None:
        self.transport.write(text.encode("ascii") + b"\r\n")

    def status(self) -> str:
        """Return the unit's state: ``READY``, ``SCAN`` or ``CALZ`` (``SCAN`` while scanning)."""
        if self._scanning:  # its replies would be mixed with the packets: the state is known
            return "SCAN"
        self._send("STATUS")
        line = self.transport.read_until(b"\n", self.settings.timeout_s)
        found = _STATUS.search(line)
        if found is None:
            raise ProtocolError(f"{self.transport.url}: STATUS answered {line!r}")
        return found.group(1).decode("ascii")

    def start(self) -> None:
        """Configure the scan and start it (the engine's begin)."""
        period_us = max(1, round(1e6 / (self.settings.rate_hz * CHANNELS)))
        for command in ("STOP", f"SET PERIOD {period_us}", "SET AVG 1", "SET FPS 0",
                        "SET FORMAT B", "SET TIME 1", "SET EU 1"):
            self._send(command)
        self.scan()

    def scan(self, *, after_pause: bool = False) -> None:
        """Send ``SCAN``; a later scan's rows continue the stream (see the module's notes)."""
        self._buffer.clear()
        self._scan_base = None
        self._wrap, self._raw_time = 0, None
        self._send("SCAN")
        self._scanning = True

    def stop(self) -> None:
        """Send ``STOP``; frames already sent are read by :meth:`drain`."""
        self._send("STOP")
        self._scanning = False

    def note_pause(self, pause_s: float) -> None:
        """Take the host-measured standstill of the last pause, s (for the restart's gap)."""
        self._pause_s = float(pause_s)

    def recover(self, error: BaseException) -> None:
        """Reconnect and scan again after a lost connection; anything else needs nothing."""
        if not isinstance(error, TransportError) or isinstance(error, TransportTimeout):
            return
        self.transport.close()
        self.transport.open()
        self.stats["reconnects"] += 1
        self.start()

    def check_calz_allowed(self, *, wind_speed_now: float) -> None:
        """Refuse a zero unless the wind is known to be off (windrig's rule, no I/O)."""
        if wind_speed_now != 0.0:
            raise SafetyError(f"CALZ refused: wind speed {wind_speed_now!r} m/s, not 0")

    def calz(self, *, wind_speed_now: float, timeout_s: float = 30.0) -> float:
        """Zero the sensors (``CALZ``) and wait for ``READY``; return how long it took, s."""
        self.check_calz_allowed(wind_speed_now=wind_speed_now)
        if self._scanning:
            raise DeviceError("CALZ refused while scanning: stop() first")
        sent = time.monotonic()
        self._send("CALZ")
        while (state := self.status()) != "READY":
            if time.monotonic() - sent > timeout_s:
                raise DeviceError(f"CALZ: still {state} after {timeout_s:g} s")
            time.sleep(0.05)
        return time.monotonic() - sent

    # -- data ----------------------------------------------------------------------------------
    def read(self, timeout_s: float | None = None) -> Reading:
        """Read at least one frame (``min_block_s`` of them when they are there already).

        Raises
        ------
        TransportTimeout
            No whole packet within ``timeout_s`` (default: the settings').
        """
        wait = self.settings.timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + wait
        want = max(1, round(self.settings.min_block_s * self.settings.rate_hz)) * PACKET_SIZE
        while len(self._buffer) < want:
            left = deadline - time.monotonic()
            if left <= 0 and len(self._buffer) >= PACKET_SIZE:
                break
            if left <= 0:
                raise TransportTimeout(f"{self.transport.url}: no frame within {wait:g} s")
            try:
                self._buffer += self.transport.read(65536, min(left, 0.05))
            except TransportTimeout:
                if len(self._buffer) >= PACKET_SIZE:
                    break
        host_ns = time.monotonic_ns()
        n = len(self._buffer) // PACKET_SIZE
        packets = decode(self._buffer[:n * PACKET_SIZE])
        del self._buffer[:n * PACKET_SIZE]
        return self._reading(packets, host_ns)

    def drain(self, timeout_s: float) -> list[Reading]:
        """Read the frames still in flight after ``STOP``, until ``timeout_s`` of silence."""
        out = []
        while True:
            try:
                out.append(self.read(timeout_s))
            except TransportTimeout:
                return out

    def recent_pressure_mean(self) -> tuple[np.ndarray, int]:
        """Mean pressure per channel over the last 0.5 s of frames read, Pa, and their number."""
        if not self._recent:
            return np.zeros(0), 0
        rows = np.concatenate(list(self._recent))[-max(1, round(0.5 * self.rate_hz)):]
        return rows.mean(axis=0), int(rows.shape[0])

    def _reading(self, packets: np.ndarray, host_ns: int) -> Reading:
        n = packets.shape[0]
        self.stats["packets"] += n
        raw = packets["time"].astype(np.int64)
        # Unwrap the 32-bit time within this scan.
        steps = np.diff(np.concatenate([[raw[0] if self._raw_time is None else self._raw_time],
                                        raw]))
        wraps = self._wrap + np.cumsum(steps < -(1 << 31))
        self._wrap, self._raw_time = int(wraps[-1]), int(raw[-1])
        unit = np.array([TIME_UNIT_S[int(u)] for u in packets["time_units"]])
        scan_time = (raw + wraps * (1 << 32)) * unit
        frame = packets["frame"].astype(np.int64)
        gaps: list[Gap] = []
        if self._scan_base is None:  # the first frame of a scan: continue the stream
            if self._last is None:
                self._scan_base = (0, 0.0)
            else:
                last_counter, last_time, last_host = self._last
                standstill = max(self._pause_s, (host_ns - last_host) * 1e-9
                                 - (n - 1) / self.rate_hz)
                missing = max(round(standstill * self.rate_hz) - 1, 0)
                self._scan_base = (last_counter + missing + 1 - int(frame[0]),
                                   last_time + (missing + 1) / self.rate_hz - scan_time[0])
                gaps.append(Gap(last_counter, missing, "restart"))
                self._pause_s = 0.0
        counter = frame + self._scan_base[0]
        device_time = scan_time + self._scan_base[1]
        # Frames the unit numbered but never sent: a gap of each jump of the frame number.
        previous = [] if self._last is None or gaps else [self._last[0]]
        seq = np.concatenate([previous, counter]).astype(np.int64)
        gaps += [Gap(int(seq[i]), int(seq[i + 1] - seq[i] - 1))
                 for i in np.flatnonzero(np.diff(seq) > 1)]
        pressure = packets["pressure"].astype(np.float64) * self.settings.units_pa
        self._recent.append(pressure)
        host = np.full(n, host_ns, np.int64)
        self._last = (int(counter[-1]), float(device_time[-1]), host_ns)
        return Reading(
            channels={"pressure": pressure,
                      "pitot": pressure[:, self.settings.pitot_channel].copy(),
                      "trigger_time": np.full(n, math.nan),
                      "module_status": np.zeros((n, 1), np.int8)},
            host_time_ns=host, counter=counter, device_time=device_time.astype(np.float64),
            gaps=tuple(gaps), info={"time_base": "relative"})


DRIVER = DriverEntry(name="scanivalve_dsa3217", role="scanner", factory=Dsa3217,
                     validate=Dsa3217Settings.from_table)
