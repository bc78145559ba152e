"""Driver of the fan drive: an ABB ACS580-class VFD in the ABB Drives profile, over Modbus.

Responsibility: start, stop and coast the fan, send its speed reference, read its ramped actual
speed and decoded status, reset a trip, and wait for a speed, through a :class:`RegisterBus`
(:mod:`daq.transports.modbus`). Safety: the driver refuses (:class:`~daq.errors.SafetyError`) any
speed reference below 0 or above the rig's fan limit (``[limits] max_fan_rpm``, given to the
constructor as ``limit_rpm``) and never clips it; :meth:`AbbAcs580.start` refuses to run a drive
whose stored reference is above the limit. It writes only the Control Word and Reference 1 and reads
only the four registers of its ``registers`` table. Not responsible for Modbus transport, retries or
error normalisation (the bus), nor for turning wind speed into fan speed.

Facts implemented (docs/reference/wire_formats.md, "Fan drive", and the ABB Drives profile tables of
the ACS580 firmware manual "Contents of the fieldbus Control word / Status word", FDNA-01 manual
p.91, FPBA-01 manual p.113, ACS880 manual p.635):

- CW 0x0476 = prepare / ramp stop, 0x047F = run, 0x0000 = coast (a wind tunnel's published map);
- CW bit 7 RESET: a 0->1 edge resets an active fault and the drive proceeds to SWITCH-ON
  INHIBITED (ACS580 firmware manual);
- SW bits 0 RDY_ON, 1 RDY_RUN, 2 RDY_REF, 3 TRIPPED (a wind tunnel's published register map names
  them; the positions come from the ABB Drives profile Status word tables cited above), 4 OFF_2_STA,
  5 OFF_3_STA, 6 SWC_ON_INHIB, 7 ALARM, 8 AT_SETPOINT, 9 REMOTE, 10 ABOVE_LIMIT;
- Reference 1 is a signed word, 0..+/-20000 scaled to the maximum speed
  (docs/reference/wire_formats.md, "Fan drive");
- Actual 1 is the speed with the same 20000 = maximum-speed scaling. [unverified] The drive manuals
  call ACT1 "selectable, e.g. speed": its source and scaling are drive parameters, so the rig must
  map ACT1 to motor speed with the Reference 1 scaling for this driver to be right.
- [unverified] The reset sequence (CW 0x0476, then 0x04F6 = 0x0476 with bit 7, then 0x0476) is
  ours: the sources give bit 7's edge, not a sequence.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from typing import Any

from daq.errors import ConfigError, DeviceError, SafetyError
from daq.instruments.abb_acs580.profile import (
    CW_COAST,
    CW_PREPARE,
    CW_RESET_BIT,
    CW_RUN,
    FULL_SCALE,
    DriveStatus,
)
from daq.instruments.abb_acs580.settings import AbbAcs580Settings
from daq.instruments.entry import DriverEntry
from daq.instruments.reading import PollSequence, Reading
from daq.transports.modbus import RegisterBus, to_int16

__all__ = ["DRIVER", "AbbAcs580"]


#: dtypes of the channels of :meth:`AbbAcs580.read`.
_DTYPES = {"speed": "float64", "status_word": "uint16"}


class AbbAcs580:
    """An ABB-drives-profile fan drive (ACS580 / ACH580 / ACH550 class) on a Modbus bus.

    Parameters
    ----------
    bus : RegisterBus
        The drive's Modbus bus (:class:`daq.transports.modbus.ModbusBus`), not yet open.
    settings : AbbAcs580Settings or mapping
        Validated settings, or a rig-config table to validate.
    limit_rpm : float
        The rig's fan speed limit (``[limits] max_fan_rpm``), rpm: no reference above it (or
        below 0) is ever sent. Required, keyword-only.

    Notes
    -----
    The constructor does no I/O; :meth:`open` connects. Closing does not stop the fan.
    """

    def __init__(self, bus: RegisterBus, settings: AbbAcs580Settings | Mapping[str, Any], *,
                 limit_rpm: float) -> None:
        if not isinstance(settings, AbbAcs580Settings):
            settings = AbbAcs580Settings.from_table(settings)
        if isinstance(limit_rpm, bool) or not isinstance(limit_rpm, (int, float)) \
                or not (math.isfinite(limit_rpm) and limit_rpm > 0):
            raise ConfigError(f"limit_rpm must be a finite number > 0, got {limit_rpm!r}")
        self.bus = bus
        self._polls = PollSequence()
        self.settings = settings
        self.limit_rpm = float(limit_rpm)
        self._regs = settings.registers

    # -- lifecycle -----------------------------------------------------------------------------
    def open(self) -> None:
        """Connect the bus with this drive's reply timeout; idempotent."""
        self.bus.timeout_s = self.settings.poll_timeout_s
        self.bus.open()

    def close(self) -> None:
        """Disconnect; idempotent. The drive keeps doing what it was told (the fan may run)."""
        self.bus.close()

    def __enter__(self) -> AbbAcs580:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- scaling ---------------------------------------------------------------------------------
    @property
    def max_rpm(self) -> float:
        """Measure the speed at Reference 1 = 20000 (settings), rpm."""
        return self.settings.max_rpm

    def _counts_to_rpm(self, counts: int) -> float:
        return counts * self.settings.max_rpm / FULL_SCALE

    def reference_counts(self, rpm: float) -> int:
        """Return the Reference 1 counts for ``rpm``, refusing anything outside [0, limit].

        The counts are rounded to the nearest count, and one count lower if rounding would put
        the reference above the limit: the reference sent never exceeds ``limit_rpm``.

        Raises
        ------
        SafetyError
            ``rpm`` is not a finite number in [0, min(limit_rpm, max_rpm)].
        """
        if isinstance(rpm, bool) or not isinstance(rpm, (int, float)) or not math.isfinite(rpm):
            raise SafetyError(f"fan speed reference must be a finite number, got {rpm!r}")
        ceiling = min(self.limit_rpm, self.settings.max_rpm)
        if rpm < 0 or rpm > self.limit_rpm:
            raise SafetyError(f"fan speed reference {rpm!r} rpm refused: the rig limit is "
                              f"[0, {self.limit_rpm:g}] rpm ([limits] max_fan_rpm)")
        if rpm > self.settings.max_rpm:
            raise SafetyError(f"fan speed reference {rpm!r} rpm refused: above the drive's "
                              f"max_rpm {self.settings.max_rpm:g} (Reference 1 = 20000)")
        counts = round(rpm * FULL_SCALE / self.settings.max_rpm)
        while counts > 0 and self._counts_to_rpm(counts) > ceiling:
            counts -= 1
        return counts

    # -- commands --------------------------------------------------------------------------------
    def _write_cw(self, word: int) -> None:
        self.bus.write_register(self._regs.control_word, word)

    def set_speed(self, rpm: float) -> None:
        """Send the speed reference (Reference 1), rpm; the drive ramps to it when running.

        Raises
        ------
        SafetyError
            ``rpm`` below 0 or above the rig limit (nothing is sent).
        """
        counts = self.reference_counts(rpm)
        self.bus.write_register(self._regs.reference_1, counts)

    def start(self, timeout_s: float = 2.0) -> None:
        """Run the drive: CW 0x0476 (prepare), then 0x047F (run), checking each state.

        Raises
        ------
        SafetyError
            The reference stored in the drive is outside [0, limit_rpm] (nothing is written).
        DeviceError
            The drive is tripped, or does not reach READY TO SWITCH ON / OPERATION ENABLED
            within ``timeout_s``.
        """
        counts = to_int16(self.bus.read_holding_registers(self._regs.reference_1, 1)[0])
        stored = self._counts_to_rpm(counts)
        if counts < 0 or stored > self.limit_rpm:
            raise SafetyError(f"drive not started: its stored Reference 1 ({counts} counts = "
                              f"{stored:.1f} rpm) is outside [0, {self.limit_rpm:g}] rpm; "
                              "set_speed() first")
        status = self.status()
        if status.tripped:
            raise DeviceError(f"{self.bus.url}: drive tripped (SW {status.word:#06x}); "
                              "reset_trip() first")
        self._write_cw(CW_PREPARE)
        self._wait_status(lambda s: s.rdy_on, "READY TO SWITCH ON (SW RDY_ON)", timeout_s)
        self._write_cw(CW_RUN)
        self._wait_status(lambda s: s.rdy_ref, "OPERATION ENABLED (SW RDY_REF)", timeout_s)

    def stop(self) -> None:
        """Ramp the fan down to zero (CW 0x0476: OFF1, stop along the deceleration ramp)."""
        self._write_cw(CW_PREPARE)

    def coast(self) -> None:
        """Let the fan coast to a stop (CW 0x0000: OFF2, emergency off)."""
        self._write_cw(CW_COAST)

    def reset_trip(self, timeout_s: float = 2.0) -> DriveStatus:
        """Reset a trip with a rising edge of CW bit 7; return the status after the reset.

        Writes CW 0x0476, 0x04F6 (RESET set), 0x0476, then waits for TRIPPED to clear.

        Raises
        ------
        DeviceError
            TRIPPED is still set after ``timeout_s`` (the fault persists).
        """
        self._write_cw(CW_PREPARE)
        self._write_cw(CW_PREPARE | CW_RESET_BIT)
        self._write_cw(CW_PREPARE)
        return self._wait_status(lambda s: not s.tripped, "TRIPPED cleared after a reset",
                                 timeout_s)

    # -- readings ----------------------------------------------------------------------------------
    def status(self) -> DriveStatus:
        """Read and decode the Status Word."""
        return DriveStatus.decode(self.bus.read_holding_registers(self._regs.status_word, 1)[0])

    def speed(self) -> float:
        """Read the actual (ramped) speed from Actual 1, rpm."""
        return self._counts_to_rpm(
            to_int16(self.bus.read_holding_registers(self._regs.actual_1, 1)[0]))

    def read_status_and_speed(self) -> tuple[DriveStatus, float]:
        """Read the Status Word and Actual 1 (one request when they are adjacent)."""
        sw, act = self._regs.status_word, self._regs.actual_1
        if act == sw + 1:
            word, counts = self.bus.read_holding_registers(sw, 2)
            return DriveStatus.decode(word), self._counts_to_rpm(to_int16(counts))
        return self.status(), self.speed()

    def describe(self) -> dict[str, dict[str, Any]]:
        """Describe the channels of :meth:`read`: units, dtype, shape (one row per poll).

        ``speed`` (Actual 1, rpm) and ``status_word`` (the drive's status word, bits).
        """
        return {name: {"units": units, "dtype": _DTYPES[name], "shape": ()}
                for name, units in (("speed", "rpm"), ("status_word", "1"))}

    def read(self) -> Reading:
        """Read every channel of :meth:`describe` once: a one-row reading.

        Its host time is the host's ``time.monotonic_ns()`` when the reply arrived; its counter
        the poll number (a failed poll leaves a gap before the next reading).
        """
        number = self._polls.next()
        status, rpm = self.read_status_and_speed()
        return self._polls.reading(number, {"speed": rpm, "status_word": status.word}, _DTYPES)

    def wait_for_speed(self, rpm: float, tolerance_rpm: float,
                       timeout_s: float | None = None, poll_s: float = 0.02) -> float:
        """Poll Actual 1 until it is within ``tolerance_rpm`` of ``rpm``; return the speed.

        Parameters
        ----------
        rpm : float
            Expected speed, rpm.
        tolerance_rpm : float
            Accepted ``|actual - rpm|``, rpm (> 0).
        timeout_s : float, optional
            Time allowed, s; default: the ramp time at ``ramp_rpm_per_s`` from the current
            speed, times 1.5, plus 2 s.
        poll_s : float
            Interval between polls, s.

        Raises
        ------
        DeviceError
            The drive tripped, or the speed was not reached within ``timeout_s``.
        """
        if not (math.isfinite(tolerance_rpm) and tolerance_rpm > 0):
            raise ValueError(f"tolerance_rpm must be > 0, got {tolerance_rpm!r}")
        status, actual = self.read_status_and_speed()
        if timeout_s is None:
            timeout_s = 1.5 * abs(rpm - actual) / self.settings.ramp_rpm_per_s + 2.0
        if not (math.isfinite(timeout_s) and timeout_s > 0):
            raise ValueError(f"timeout_s must be > 0, got {timeout_s!r}")
        deadline = time.monotonic() + timeout_s
        while True:
            if abs(actual - rpm) <= tolerance_rpm:
                return actual
            if status.tripped and abs(rpm) > tolerance_rpm:  # a tripped drive only coasts
                raise DeviceError(f"{self.bus.url}: drive tripped while waiting for {rpm:g} rpm "
                                  f"(actual {actual:.1f} rpm, SW {status.word:#06x})")
            if time.monotonic() >= deadline:
                raise DeviceError(
                    f"{self.bus.url}: fan did not reach {rpm:g} +/- {tolerance_rpm:g} rpm within "
                    f"{timeout_s:g} s (actual {actual:.1f} rpm, SW {status.word:#06x}: "
                    f"{', '.join(status.active())})")
            time.sleep(poll_s)
            status, actual = self.read_status_and_speed()

    def _wait_status(self, ok: Any, what: str, timeout_s: float) -> DriveStatus:
        deadline = time.monotonic() + timeout_s
        while True:
            status = self.status()
            if ok(status):
                return status
            if time.monotonic() >= deadline:
                raise DeviceError(f"{self.bus.url}: drive did not reach {what} within "
                                  f"{timeout_s:g} s (SW {status.word:#06x}: "
                                  f"{', '.join(status.active()) or 'no bits'})")
            time.sleep(0.005)


#: This driver's registry entry (collected by :mod:`daq.instruments.registry`).
DRIVER = DriverEntry(name="abb_acs580", role="fan", factory=AbbAcs580,
                    validate=AbbAcs580Settings.from_table)
