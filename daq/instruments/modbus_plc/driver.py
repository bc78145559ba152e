"""Driver of the release/trigger PLC: arm and release the electromagnet, pulse the trigger line.

Responsibility: the release and trigger PLC (docs/reference/wire_formats.md, "PLC") through a
:class:`RegisterBus` (:mod:`daq.transports.modbus`): coils ARM, RELEASE, DAQ_TRIGGER; discrete input
RELEASED (the armature limit switch); holding register TRIGGER_COUNT. It writes only those three
coils and reads only those coils, that input and that register (addresses from the rig config).

Safety: :meth:`ModbusPlc.release` releases only when the ARM coil reads set (else
:class:`~daq.errors.SafetyError`, nothing written), and confirms the release by the RELEASED input
within ``release_timeout_s``; a release that never comes (a fault the simulated PLC injects,
docs/reference/wire_formats.md, "Faults") is a :class:`~daq.errors.DeviceError` naming RELEASED. It
is a DeviceError rather than a TransportTimeout on purpose: the PLC answered every request, the
armature did not move, and a generic transport retry must never repeat a release.

PLC logic assumed ([design]: docs/reference/wire_formats.md, "PLC"; the sources name the signals
only): ARM 0->1 energises the magnet and permits one release; RELEASE 0->1 while armed de-energises
it and the PLC clears ARM; DAQ_TRIGGER 0->1 pulses the trigger line and increments TRIGGER_COUNT (16
bits, wraps). The driver returns RELEASE and DAQ_TRIGGER to 0 after use, so that the next command is
an edge.

Not responsible for Modbus transport, retries and error normalisation (the bus), nor for
time-aligning the release with the other streams (it returns host timestamps for that).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from daq.errors import DeviceError, ProtocolError, SafetyError
from daq.instruments.entry import DriverEntry
from daq.instruments.modbus_plc.settings import ModbusPlcSettings
from daq.instruments.reading import PollSequence, Reading
from daq.transports.modbus import RegisterBus

__all__ = ["DRIVER", "POLL_S", "ModbusPlc", "ReleaseTiming"]

#: Interval between polls of RELEASED while a release is confirmed, s.
POLL_S = 0.002


@dataclass(frozen=True)
class ReleaseTiming:
    """Host times of one release (``time.monotonic_ns()``).

    Attributes
    ----------
    command_ns : int
        When the PLC acknowledged the RELEASE coil write: it acted on it before (a real PLC
        switches its output within a scan, the simulated one computes the decay first), so
        this is late by the acknowledgement's way back at most.
    confirmed_ns : int
        When RELEASED was first read set (polled every 2 ms, so up to one poll late).
    round_trip_ns : int
        The write's round trip, timed while holding the bus (not counting a poll's wait):
        the release happened within it, before ``command_ns``.
    """

    command_ns: int
    confirmed_ns: int
    round_trip_ns: int = 0

    @property
    def delay_s(self) -> float:
        """Measure the time from the command to the confirmation, s."""
        return (self.confirmed_ns - self.command_ns) * 1e-9


#: dtypes of the channels of :meth:`ModbusPlc.read`.
_DTYPES = {"armed": "bool", "released": "bool", "trigger_count": "uint16"}


class ModbusPlc:
    """The release/trigger PLC on a Modbus bus.

    Parameters
    ----------
    bus : RegisterBus
        The PLC's Modbus bus (:class:`daq.transports.modbus.ModbusBus`), not yet open.
    settings : ModbusPlcSettings or mapping
        Validated settings, or a rig-config table to validate.

    Notes
    -----
    The constructor does no I/O; :meth:`open` connects.
    """

    def __init__(self, bus: RegisterBus, settings: ModbusPlcSettings | Mapping[str, Any]) -> None:
        if not isinstance(settings, ModbusPlcSettings):
            settings = ModbusPlcSettings.from_table(settings)
        self.bus = bus
        self._polls = PollSequence()
        self.settings = settings
        self._coil = dict(settings.coils)
        self._released_di = settings.discrete_inputs["released"]
        self._count_hr = settings.holding_registers["trigger_count"]
        self._trigger_low = False  # DAQ_TRIGGER known to be 0 (unknown until written)
        #: Round trip of the last trigger pulse's rising-edge write, ns (0: no pulse yet).
        self.last_trigger_round_trip_ns = 0

    # -- lifecycle -----------------------------------------------------------------------------
    def open(self) -> None:
        """Connect the bus; idempotent."""
        self.bus.open()

    def close(self) -> None:
        """Disconnect; idempotent (the PLC keeps its outputs)."""
        self.bus.close()

    def __enter__(self) -> ModbusPlc:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- readings ----------------------------------------------------------------------------------
    def armed(self) -> bool:
        """Read the ARM coil (True: the magnet holds and one release is permitted)."""
        return self.bus.read_coils(self._coil["arm"], 1)[0]

    def released(self) -> bool:
        """Read the RELEASED discrete input (True: the armature has left the magnet)."""
        return self.bus.read_discrete_inputs(self._released_di, 1)[0]

    def trigger_count(self) -> int:
        """Read TRIGGER_COUNT (0..65535, wraps).

        Raises
        ------
        ProtocolError
            The register's value is not a 16-bit word (a broken bus or bridge): never wrapped or
            clipped into a count that would pair the wrong trigger pulses.
        """
        word = self.bus.read_holding_registers(self._count_hr, 1)[0]
        if not 0 <= word <= 0xFFFF:
            raise ProtocolError(f"{self.bus.url}: TRIGGER_COUNT (holding register "
                                f"{self._count_hr}) = {word} is outside 0..65535")
        return int(word)

    def describe(self) -> dict[str, dict[str, Any]]:
        """Describe the channels of :meth:`read`: units, dtype, shape (one row per poll).

        ``armed`` (the magnet holds), ``released`` (the RELEASED input) and ``trigger_count``
        (the PLC's count of trigger pulses, wrapping at 2**16).
        """
        return {name: {"units": "1", "dtype": dtype, "shape": ()}
                for name, dtype in _DTYPES.items()}

    def read(self) -> Reading:
        """Read every channel of :meth:`describe` once: a one-row reading.

        Its host time is the host's ``time.monotonic_ns()`` when the last reply arrived; its
        counter the poll number (a failed poll leaves a gap before the next reading).
        """
        number = self._polls.next()
        values = {"armed": self.armed(), "released": self.released(),
                  "trigger_count": self.trigger_count()}
        return self._polls.reading(number, values, _DTYPES)

    # -- commands --------------------------------------------------------------------------------
    def arm(self, timeout_s: float | None = None) -> None:
        """Energise the magnet and permit one release; wait until RELEASED clears.

        Writes RELEASE 0 (so that the next release is an edge) and ARM 1.

        Raises
        ------
        DeviceError
            RELEASED is still set after ``timeout_s`` (default ``release_timeout_s``): the
            armature did not return to the magnet.
        """
        timeout_s = self.settings.release_timeout_s if timeout_s is None else timeout_s
        self.bus.write_coil(self._coil["release"], False)
        self.bus.write_coil(self._coil["arm"], True)
        deadline = time.monotonic() + timeout_s
        while self.released():
            if time.monotonic() >= deadline:
                raise DeviceError(
                    f"{self.bus.url}: RELEASED (discrete input {self._released_di}) still set "
                    f"{timeout_s:g} s after ARM: the armature is not on the magnet")
            time.sleep(POLL_S)

    def disarm(self) -> None:
        """Withdraw the release permission (ARM 0); the magnet keeps holding."""
        self.bus.write_coil(self._coil["arm"], False)

    def release(self) -> ReleaseTiming:
        """Release the model: RELEASE 0->1, confirmed by RELEASED; return the host times.

        Raises
        ------
        SafetyError
            The ARM coil is not set (nothing is written).
        DeviceError
            RELEASED did not come within ``release_timeout_s`` (the magnet may still hold).
        """
        if not self.armed():
            raise SafetyError(f"{self.bus.url}: release refused: the PLC is not armed "
                              f"(ARM coil {self._coil['arm']} is 0); arm() first")
        timeout_s = self.settings.release_timeout_s
        sent, command_ns = self._timed_set(self._coil["release"])
        try:
            deadline = time.monotonic() + timeout_s
            while not self.released():
                if time.monotonic() >= deadline:
                    raise DeviceError(
                        f"{self.bus.url}: RELEASED (discrete input {self._released_di}) not set "
                        f"within {timeout_s:g} s of the release command: the magnet may still "
                        "hold the model")
                time.sleep(POLL_S)
            return ReleaseTiming(command_ns=command_ns, confirmed_ns=time.monotonic_ns(),
                                 round_trip_ns=command_ns - sent)
        finally:
            # Back to 0 so that the next release is an edge (the PLC acts on 0->1 only).
            self.bus.write_coil(self._coil["release"], False)

    def _timed_set(self, coil: int) -> tuple[int, int]:
        """Set ``coil`` to 1; return the host times (ns) of sending it and of its acknowledgement.

        Timed while holding the bus: the round trip of this write alone, not a wait for
        another thread's request (the engine polls the PLC at 10 Hz on the same bus).
        """
        with self.bus.exclusive():
            sent = time.monotonic_ns()
            self.bus.write_coil(coil, True)
            return sent, time.monotonic_ns()

    def trigger_pulse(self, width_s: float | None = None) -> int:
        """Pulse DAQ_TRIGGER (1 for ``width_s``, default ``trigger_pulse_s``, then 0).

        Returns
        -------
        int
            Host time of the rising edge, ``time.monotonic_ns()`` clock: the midpoint between
            sending the write and its acknowledgement (the PLC switches the line in between;
            the midpoint is off by at most half the round trip, kept in
            :attr:`last_trigger_round_trip_ns` so that a caller can refuse an uncertain one).
        """
        width_s = self.settings.trigger_pulse_s if width_s is None else width_s
        if not (math.isfinite(width_s) and 0 < width_s <= 1.0):
            raise ValueError(f"width_s must be in (0, 1] s, got {width_s!r}")
        if not self._trigger_low:
            # After a pulse whose end was not acknowledged, 1 might not be an edge.
            self.bus.write_coil(self._coil["trigger"], False)
            self._trigger_low = True
        self._trigger_low = False
        sent, acknowledged = self._timed_set(self._coil["trigger"])
        self.last_trigger_round_trip_ns = acknowledged - sent
        t_ns = (sent + acknowledged) // 2
        try:
            time.sleep(width_s)
        finally:
            self.bus.write_coil(self._coil["trigger"], False)
            self._trigger_low = True
        return t_ns


#: This driver's registry entry (collected by :mod:`daq.instruments.registry`).
DRIVER = DriverEntry(name="modbus_plc", role="plc", factory=ModbusPlc,
                    validate=ModbusPlcSettings.from_table)
