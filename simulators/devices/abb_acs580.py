"""Simulated ABB ACS580 fan drive (ABB Drives profile) on a pymodbus TCP server at 127.0.0.1.

Responsibility: answer Modbus requests the way an ABB-drives-profile VFD does
(``docs/reference/wire_formats.md``, "Fan drive"): a Control Word (CW) state machine, Reference 1
scaled 0..20000 to the maximum speed, a ramped actual speed reported in Actual 1 with the same
scaling, a Status Word (SW) with the profile's bits, a Modbus exception for any address outside the
register map, and the faults of ``docs/reference/wire_formats.md``, "Faults the simulators inject":
a trip (TRIPPED bit, coast, reset on a CW bit 7 rising edge), a slow ramp, and requests that get no
reply. The actual speed drives the virtual tunnel's fan (:meth:`VirtualTunnel.set_fan_speed`). Not
responsible for decoding anything on the client side: the driver
(``daq.instruments.abb_acs580.driver``) has its own, independent implementation of the same facts,
and the HIL tests cross-check the two. This module imports nothing from ``daq``.

Also home of :class:`ModbusServerThread`, the server thread both Modbus simulators use.

ABB Drives profile facts used here (ACS580 firmware manual, "Contents of the fieldbus Control word"
and "... Status word"; FDNA-01 manual p.91; ACS880 manual p.635; ``docs/reference/wire_formats.md``,
"Fan drive"):

- CW bit 0 OFF1 (0: ramp stop), 1 OFF2 (0: coast stop), 2 OFF3 (0: emergency stop), 3 RUN
  (INHIBIT_OPERATION), 4 RAMP_OUT_ZERO, 5 RAMP_HOLD, 6 RAMP_IN_ZERO (each 0 forces its ramp
  action), 7 RESET (0->1: fault reset, proceed to SWITCH-ON INHIBITED), 10 REMOTE_CMD.
  0x0476 = prepare / ramp stop, 0x047F = run, 0x0000 = coast.
- SW bit 0 RDY_ON, 1 RDY_RUN, 2 RDY_REF, 3 TRIPPED, 4 OFF_2_STA (1: OFF2 inactive),
  5 OFF_3_STA, 6 SWC_ON_INHIB, 7 ALARM, 8 AT_SETPOINT, 9 REMOTE, 10 ABOVE_LIMIT.
- State machine: SWITCH-ON INHIBITED --(OFF1=0, OFF2=OFF3=1)--> READY TO SWITCH ON
  --(OFF1=1)--> READY TO OPERATE --(RUN=1)--> OPERATION ENABLED; OFF1=0 while running ramps to
  zero (OFF1 ACTIVE, SW RDY_RUN=0); RUN=0 inhibits operation (coast); OFF2=0 coasts, OFF3=0 stops
  fast, both to SWITCH-ON INHIBITED.

[design] choices the sources leave open: fast stops (OFF3, RAMP_OUT_ZERO=0) decelerate at 5x the
ramp rate; a coasting fan slows at ``coast_rpm_per_s``; AT_SETPOINT uses ``at_setpoint_rpm``;
negative references are treated as 0 (reverse disabled by drive parameter); REMOTE is always 1.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable, Coroutine, Mapping
from typing import Any

import numpy as np
from pymodbus.constants import ExcCodes
from pymodbus.simulator import DataType, SimData, SimDevice

from simulators.clock import DeviceClock
from simulators.devices._modbus_server import ModbusServerThread, ModbusSimulator
from simulators.virtual_tunnel import VirtualTunnel

__all__ = ["SimAbbAcs580"]

log = logging.getLogger(__name__)

_Action = Callable[[int, int, int, int, list[int], Any], Coroutine[None, None, ExcCodes | None]]


# -- the drive -------------------------------------------------------------------------------------
# Control Word bits (ABB Drives profile).
CW_OFF1, CW_OFF2, CW_OFF3, CW_RUN = 0x0001, 0x0002, 0x0004, 0x0008
CW_RAMP_OUT_ZERO, CW_RAMP_HOLD, CW_RAMP_IN_ZERO, CW_RESET = 0x0010, 0x0020, 0x0040, 0x0080
# Status Word bits (ABB Drives profile).
SW_RDY_ON, SW_RDY_RUN, SW_RDY_REF, SW_TRIPPED = 0x0001, 0x0002, 0x0004, 0x0008
SW_OFF_2_STA, SW_OFF_3_STA, SW_SWC_ON_INHIB, SW_ALARM = 0x0010, 0x0020, 0x0040, 0x0080
SW_AT_SETPOINT, SW_REMOTE, SW_ABOVE_LIMIT = 0x0100, 0x0200, 0x0400
#: Reference 1 / Actual 1 full scale: 20000 <-> maximum speed (docs/reference/wire_formats.md, "Fan
#: drive").
FULL_SCALE = 20000

SWITCH_ON_INHIBITED = "SWITCH-ON INHIBITED"
READY_TO_SWITCH_ON = "READY TO SWITCH ON"
READY_TO_OPERATE = "READY TO OPERATE"
OPERATION_ENABLED = "OPERATION ENABLED"
FAULT = "FAULT"

FAULTS = ("trip", "slow_ramp", "no_reply")


class SimAbbAcs580(ModbusSimulator):
    """A simulated ABB-drives-profile fan drive that turns the virtual tunnel's fan.

    Parameters
    ----------
    tunnel : VirtualTunnel
        Receives the actual fan speed (:meth:`VirtualTunnel.set_fan_speed`); its clock is the
        drive's time base for the ramps.
    control_word, reference_1, status_word, actual_1 : int
        Zero-based holding-register addresses (the rig config's ``registers`` table). Every
        other address answers with Modbus exception 2 (illegal data address).
    max_rpm : float
        Speed at Reference 1 = Actual 1 = 20000, rpm.
    ramp_rpm_per_s : float
        Acceleration and ramp-stop deceleration, rpm/s.
    coast_rpm_per_s : float, optional
        Deceleration of the coasting fan (OFF2, trip, inhibit), rpm/s; default half the ramp.
    at_setpoint_rpm : float, optional
        Speed error under which SW AT_SETPOINT is set, rpm; default 1 % of ``max_rpm``.
    speed_noise_rpm : float
        Standard deviation of the noise on the reported Actual 1, rpm (the tunnel gets the
        noiseless speed).
    unit : int
        Modbus unit id the drive answers to.
    clock : DeviceClock, optional
        Kept for the common simulator signature; the drive stamps nothing.
    rng : numpy Generator, int or None
        Noise source (or its seed).
    faults : mapping, optional
        Faults active from the start, ``{name: {param: value}}`` (see :meth:`inject`).
    tick_s : float
        Period at which the ramp is advanced and the tunnel updated, s.
    """

    def __init__(
        self,
        tunnel: VirtualTunnel,
        *,
        control_word: int,
        reference_1: int,
        status_word: int,
        actual_1: int,
        max_rpm: float,
        ramp_rpm_per_s: float = 100.0,
        coast_rpm_per_s: float | None = None,
        at_setpoint_rpm: float | None = None,
        speed_noise_rpm: float = 0.0,
        unit: int = 1,
        clock: DeviceClock | None = None,
        rng: np.random.Generator | int | None = None,
        faults: Mapping[str, Mapping[str, Any]] | None = None,
        tick_s: float = 0.005,
    ) -> None:
        self.registers = {"control_word": control_word, "reference_1": reference_1,
                          "status_word": status_word, "actual_1": actual_1}
        for key, address in self.registers.items():
            if isinstance(address, bool) or not isinstance(address, int) \
                    or not 0 <= address <= 0xFFFF:
                raise ValueError(f"{key} must be a register address 0..65535, got {address!r}")
        if len(set(self.registers.values())) != 4:
            raise ValueError(f"register addresses must be distinct, got {self.registers}")
        for key, value in (("max_rpm", max_rpm), ("ramp_rpm_per_s", ramp_rpm_per_s),
                           ("tick_s", tick_s)):
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{key} must be > 0, got {value!r}")
        if not 0 <= unit <= 247:
            raise ValueError(f"unit must be 0..247, got {unit!r}")
        self.tunnel = tunnel
        self.max_rpm = float(max_rpm)
        self.ramp_rpm_per_s = float(ramp_rpm_per_s)
        self.coast_rpm_per_s = float(coast_rpm_per_s or 0.5 * ramp_rpm_per_s)
        self.at_setpoint_rpm = float(at_setpoint_rpm or 0.01 * max_rpm)
        self.speed_noise_rpm = float(speed_noise_rpm)
        self.unit = unit
        self.clock = clock or DeviceClock()
        self._rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self._lock = threading.RLock()
        self._cw = 0
        self._ref_word = 0
        self._state = SWITCH_ON_INHIBITED
        self._stop_mode = "coast"  # how the motor decelerates when not running
        self._actual = 0.0
        self._t_last: float | None = None
        self._fault_code = 0
        self._fault_latched = False
        self._slow_ramp: float | None = None
        #: Every holding-register write received: (address, raw word), in order.
        self.write_log: list[tuple[int, int]] = []
        self._server = ModbusServerThread(f"SimAbbAcs580-u{unit}", self._device,
                                          ticks=[(tick_s, self._tick)])
        for name, params in (faults or {}).items():
            self.inject(name, **params)

    # -- truth for tests ---------------------------------------------------------------------------
    @property
    def state(self) -> str:
        """Measure the profile state (``"OPERATION ENABLED"``, ``"FAULT"``, ...)."""
        with self._lock:
            self._advance()
            return self._state

    @property
    def actual_rpm(self) -> float:
        """Measure the true (noiseless) fan speed, rpm."""
        with self._lock:
            self._advance()
            return self._actual

    @property
    def reference_rpm(self) -> float:
        """Measure the speed Reference 1 currently asks for, rpm."""
        with self._lock:
            return self._ref_rpm()

    def writes_to(self, name: str) -> list[int]:
        """Return every raw word written to register ``name`` (``"reference_1"``, ...)."""
        address = self.registers[name]
        with self._lock:
            return [word for a, word in self.write_log if a == address]

    # -- faults ----------------------------------------------------------------------------------
    def inject(self, fault: str, **params: Any) -> None:
        """Switch a fault on (``docs/reference/wire_formats.md``, "Faults the simulators inject").

        Parameters
        ----------
        fault : str
            - ``"trip"``: the drive trips now (SW TRIPPED, the fan coasts). ``code`` (int, the
              drive's fault code, informational) and ``latched`` (bool: the cause persists, a
              reset does not clear it until ``clear("trip")``).
            - ``"slow_ramp"``: the drive ramps at ``rpm_per_s`` instead of its ramp rate.
            - ``"no_reply"``: requests get no reply: the next ``count`` ones, or all of them
              until cleared when ``count`` is None.
        """
        allowed = {"trip": {"code", "latched"}, "slow_ramp": {"rpm_per_s"}, "no_reply": {"count"}}
        if fault not in allowed:
            raise ValueError(f"unknown fault {fault!r}; known: {list(FAULTS)}")
        unknown = set(params) - allowed[fault]
        if unknown:
            raise TypeError(f"fault {fault!r} takes {sorted(allowed[fault])}, "
                            f"got {sorted(unknown)}")
        with self._lock:
            self._advance()
            if fault == "trip":
                self._fault_code = int(params.get("code", 0x2310))  # 2310: overcurrent
                self._fault_latched = bool(params.get("latched", False))
                self._state = FAULT
                self._stop_mode = "coast"
            elif fault == "slow_ramp":
                rate = float(params["rpm_per_s"])
                if not (math.isfinite(rate) and rate > 0):
                    raise ValueError(f"slow_ramp rpm_per_s must be > 0, got {rate!r}")
                self._slow_ramp = rate
        if fault == "no_reply":
            count = params.get("count")
            self._server.drop_replies(None if count is None else int(count))

    def clear(self, fault: str | None = None) -> None:
        """Switch a fault off (all of them when ``fault`` is None).

        Clearing ``"trip"`` removes its cause; the drive stays in FAULT until reset.
        """
        if fault is not None and fault not in FAULTS:
            raise ValueError(f"unknown fault {fault!r}; known: {list(FAULTS)}")
        with self._lock:
            if fault in (None, "trip"):
                self._fault_latched = False
            if fault in (None, "slow_ramp"):
                self._slow_ramp = None
        if fault in (None, "no_reply"):
            self._server.drop_replies(0)

    # -- the drive's behaviour ------------------------------------------------------------------
    def _ref_rpm(self) -> float:
        ref = self._ref_word - 0x10000 if self._ref_word & 0x8000 else self._ref_word
        return min(max(ref, 0), FULL_SCALE) * self.max_rpm / FULL_SCALE

    def _evaluate(self) -> None:
        """Apply the CW to the state machine (ABB Drives profile state diagram)."""
        cw = self._cw
        if self._state == FAULT:
            return
        if not cw & CW_OFF2:
            self._state, self._stop_mode = SWITCH_ON_INHIBITED, "coast"
            return
        if not cw & CW_OFF3:
            if self._state != SWITCH_ON_INHIBITED:
                self._stop_mode = "fast"
            self._state = SWITCH_ON_INHIBITED
            return
        while True:
            state = self._state
            if state == SWITCH_ON_INHIBITED and not cw & CW_OFF1:
                self._state = READY_TO_SWITCH_ON
            elif state == READY_TO_SWITCH_ON and cw & CW_OFF1:
                self._state = READY_TO_OPERATE
            elif state == READY_TO_OPERATE and not cw & CW_OFF1:
                self._state = READY_TO_SWITCH_ON
            elif state == READY_TO_OPERATE and cw & CW_RUN:
                self._state = OPERATION_ENABLED
            elif state == OPERATION_ENABLED and not cw & CW_OFF1:
                self._state, self._stop_mode = READY_TO_SWITCH_ON, "ramp"  # OFF1 ACTIVE
            elif state == OPERATION_ENABLED and not cw & CW_RUN:
                self._state, self._stop_mode = READY_TO_OPERATE, "coast"  # operation inhibited
            else:
                return

    def _write_cw(self, word: int) -> None:
        rising_reset = bool(word & CW_RESET) and not self._cw & CW_RESET
        self._cw = word
        if self._state == FAULT and rising_reset and not self._fault_latched:
            # CW bit 7 0->1: fault reset, proceed to SWITCH-ON INHIBITED.
            self._state, self._fault_code = SWITCH_ON_INHIBITED, 0
        self._evaluate()

    def _motor_target(self) -> tuple[float, float | None]:
        """Return (target rpm, rate rpm/s; None = hold) for the motor now."""
        ramp = self._slow_ramp or self.ramp_rpm_per_s
        if self._state == OPERATION_ENABLED:
            cw = self._cw
            if not cw & CW_RAMP_OUT_ZERO:
                return 0.0, 5.0 * ramp
            if not cw & CW_RAMP_HOLD:
                return self._actual, None
            if not cw & CW_RAMP_IN_ZERO:
                return 0.0, ramp
            return self._ref_rpm(), ramp
        rates = {"ramp": ramp, "fast": 5.0 * ramp, "coast": self.coast_rpm_per_s}
        return 0.0, rates[self._stop_mode]

    def _advance(self) -> None:
        """Integrate the ramp up to now and hand the speed to the tunnel."""
        now = self.tunnel.clock.now()
        if self._t_last is None:
            self._t_last = now
        dt = max(now - self._t_last, 0.0)
        self._t_last = now
        target, rate = self._motor_target()
        if rate is not None and dt > 0:
            step = rate * dt
            delta = target - self._actual
            self._actual = target if abs(delta) <= step else self._actual + math.copysign(step,
                                                                                          delta)
        self.tunnel.set_fan_speed(self._actual)

    def _status_word(self) -> int:
        state, cw = self._state, self._cw
        sw = SW_REMOTE
        if state in (READY_TO_SWITCH_ON, READY_TO_OPERATE, OPERATION_ENABLED):
            sw |= SW_RDY_ON
        if state in (READY_TO_OPERATE, OPERATION_ENABLED):
            sw |= SW_RDY_RUN
        if state == OPERATION_ENABLED:
            sw |= SW_RDY_REF
            if abs(self._actual - self._ref_rpm()) <= self.at_setpoint_rpm:
                sw |= SW_AT_SETPOINT
        if state == FAULT:
            sw |= SW_TRIPPED
        if state == SWITCH_ON_INHIBITED:
            sw |= SW_SWC_ON_INHIB
        if cw & CW_OFF2:
            sw |= SW_OFF_2_STA
        if cw & CW_OFF3:
            sw |= SW_OFF_3_STA
        return sw

    def _actual_word(self) -> int:
        rpm = self._actual
        if self.speed_noise_rpm > 0:
            rpm += float(self._rng.normal(0.0, self.speed_noise_rpm))
        counts = int(round(rpm * FULL_SCALE / self.max_rpm))
        return max(-0x8000, min(0x7FFF, counts)) & 0xFFFF

    def _tick(self) -> None:
        with self._lock:
            self._advance()

    # -- the Modbus side ------------------------------------------------------------------------
    def _device(self) -> SimDevice:
        hr = [SimData(address, values=0, datatype=DataType.REGISTERS,
                      readonly=name in ("status_word", "actual_1"))
              for name, address in sorted(self.registers.items(), key=lambda kv: kv[1])]
        # Coils and discrete inputs need a block each in pymodbus; the action refuses them.
        bits = [SimData(0, values=False, datatype=DataType.BITS)]
        no_input_registers = [SimData(0, datatype=DataType.INVALID)]
        return SimDevice(self.unit, simdata=(bits, list(bits), hr, no_input_registers),
                         action=self._action)

    async def _action(self, function_code: int, start_address: int, address: int, count: int,
                      registers: list[int], set_values: Any) -> ExcCodes | None:
        # Called by pymodbus for every valid-address request before it reads or stores the block.
        if function_code not in (3, 6, 16):
            return ExcCodes.ILLEGAL_ADDRESS  # this drive exposes holding registers only
        with self._lock:
            self._advance()
            if set_values is not None:
                for i, value in enumerate(set_values):
                    self._write(address + i, int(value))
            words = {
                self.registers["control_word"]: self._cw,
                self.registers["reference_1"]: self._ref_word,
                self.registers["status_word"]: self._status_word(),
                self.registers["actual_1"]: self._actual_word(),
            }
        for reg, word in words.items():
            registers[reg - start_address] = word
        return None

    def _write(self, address: int, word: int) -> None:
        self.write_log.append((address, word))
        if address == self.registers["control_word"]:
            self._write_cw(word)
        elif address == self.registers["reference_1"]:
            self._ref_word = word
