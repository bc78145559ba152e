"""Simulated release/trigger PLC (Modbus TCP coils, discrete input, register) at 127.0.0.1.

Responsibility: the PLC of ``docs/reference/wire_formats.md``, "Release and trigger PLC over
Modbus", on a pymodbus TCP server: coils ARM, RELEASE and DAQ_TRIGGER, the discrete input RELEASED
(the armature's limit switch) and the holding register TRIGGER_COUNT, wired to the virtual tunnel's
magnet and trigger line; and the PLC's faults (``docs/reference/wire_formats.md``, "Faults the
simulators inject"): a release that never happens (RELEASED never set: the driver must time out) and
a disconnect. Not responsible for the driver side (``daq.instruments.modbus_plc.driver``); imports
nothing from ``daq``.

PLC logic ([design]: the sources name the signals, not the ladder):

- ARM coil 0->1: energise the magnet, which pulls the model back to its hold position
  (:meth:`VirtualTunnel.arm`); RELEASED clears; the release is armed (permitted).
- RELEASE coil 0->1 while armed: de-energise the magnet (:meth:`VirtualTunnel.release`); the PLC
  clears ARM (one arming permits one release); RELEASED is set once the armature has moved, 10-50
  ms later (a seeded uniform delay). While not armed the PLC ignores it (interlock) and counts it.
- ARM coil 1->0: withdraw the permission; the magnet keeps holding.
- DAQ_TRIGGER coil 0->1: pulse the trigger line (:meth:`VirtualTunnel.trigger`) and increment
  TRIGGER_COUNT (16 bits, wraps).
- TRIGGER_COUNT is read-only; writes to coils other than the three are refused (exception 2).
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from typing import Any

import numpy as np
from pymodbus.constants import ExcCodes
from pymodbus.simulator import DataType, SimData, SimDevice

from simulators.clock import DeviceClock
from simulators.devices._modbus_server import (
    ModbusServerThread,
    ModbusSimulator,
    bits_into_registers,
)
from simulators.virtual_tunnel import VirtualTunnel

__all__ = ["SimModbusPlc"]

FAULTS = ("release_stuck", "disconnect", "no_reply")


class SimModbusPlc(ModbusSimulator):
    """A simulated Modbus TCP PLC that holds, releases and triggers in the virtual tunnel.

    Parameters
    ----------
    tunnel : VirtualTunnel
        The magnet and trigger line it drives.
    release, arm, trigger : int
        Zero-based coil addresses (the rig config's ``coils`` table).
    released : int
        Zero-based discrete-input address of the RELEASED limit switch.
    trigger_count : int
        Zero-based holding-register address of TRIGGER_COUNT.
    release_delay_s : (float, float)
        Range of the delay from the release to RELEASED, s (10-50 ms by default).
    unit : int
        Modbus unit id the PLC answers to.
    clock : DeviceClock, optional
        Kept for the common simulator signature; the PLC stamps nothing.
    rng : numpy Generator, int or None
        Source (or seed) of the release delays.
    faults : mapping, optional
        Faults active from the start, ``{name: {param: value}}`` (see :meth:`inject`).
    """

    def __init__(
        self,
        tunnel: VirtualTunnel,
        *,
        release: int,
        arm: int,
        trigger: int,
        released: int,
        trigger_count: int,
        release_delay_s: tuple[float, float] = (0.010, 0.050),
        unit: int = 1,
        clock: DeviceClock | None = None,
        rng: np.random.Generator | int | None = None,
        faults: Mapping[str, Mapping[str, Any]] | None = None,
    ) -> None:
        self.coils = {"release": release, "arm": arm, "trigger": trigger}
        self.discrete_inputs = {"released": released}
        self.holding_registers = {"trigger_count": trigger_count}
        for key, address in {**self.coils, **self.discrete_inputs,
                             **self.holding_registers}.items():
            if isinstance(address, bool) or not isinstance(address, int) \
                    or not 0 <= address <= 0xFFFF:
                raise ValueError(f"{key} must be an address 0..65535, got {address!r}")
        if len(set(self.coils.values())) != 3:
            raise ValueError(f"coil addresses must be distinct, got {self.coils}")
        lo, hi = release_delay_s
        if not 0 <= lo <= hi:
            raise ValueError(f"release_delay_s must be (lo, hi) with 0 <= lo <= hi, "
                             f"got {release_delay_s!r}")
        if not 0 <= unit <= 247:
            raise ValueError(f"unit must be 0..247, got {unit!r}")
        self.tunnel = tunnel
        self.release_delay_s = (float(lo), float(hi))
        self.unit = unit
        self.clock = clock or DeviceClock()
        self._rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self._lock = threading.RLock()
        armed = tunnel.armed  # the PLC powers up agreeing with the magnet it drives
        self._coil = {"release": False, "arm": armed, "trigger": False}
        self._released = not armed
        self._magnet_on = armed
        self._count = 0
        self._release_token = 0
        self._stuck = False
        #: Every coil write received: (name, value), in order.
        self.write_log: list[tuple[str, bool]] = []
        #: Truth counters of what the PLC did.
        self.events = {"releases": 0, "releases_refused": 0, "releases_stuck": 0, "arms": 0,
                       "triggers": 0}
        #: Release delays drawn so far, s (one per release that happened).
        self.release_delays: list[float] = []
        self._server = ModbusServerThread(f"SimModbusPlc-u{unit}", self._device)
        for name, params in (faults or {}).items():
            self.inject(name, **params)

    # -- truth for tests ---------------------------------------------------------------------------
    @property
    def released(self) -> bool:
        """Measure the RELEASED discrete input."""
        with self._lock:
            return self._released

    @property
    def armed(self) -> bool:
        """Measure the ARM coil."""
        with self._lock:
            return self._coil["arm"]

    @property
    def trigger_count(self) -> int:
        """Measure TRIGGER_COUNT."""
        with self._lock:
            return self._count

    # -- faults ----------------------------------------------------------------------------------
    def inject(self, fault: str, **params: Any) -> None:
        """Switch a fault on (``docs/reference/wire_formats.md``, "Faults the simulators inject").

        Parameters
        ----------
        fault : str
            - ``"release_stuck"``: the magnet does not let go: a release changes nothing and
              RELEASED is never set (until cleared).
            - ``"disconnect"``: every connection is closed now and new ones are refused for
              ``outage_s`` (default 0: the server accepts again at once).
            - ``"no_reply"``: the next ``count`` requests (all while None) get no reply.
        """
        allowed = {"release_stuck": set(), "disconnect": {"outage_s"}, "no_reply": {"count"}}
        if fault not in allowed:
            raise ValueError(f"unknown fault {fault!r}; known: {list(FAULTS)}")
        unknown = set(params) - allowed[fault]
        if unknown:
            raise TypeError(f"fault {fault!r} takes {sorted(allowed[fault])}, "
                            f"got {sorted(unknown)}")
        if fault == "release_stuck":
            with self._lock:
                self._stuck = True
        elif fault == "disconnect":
            self._server.disconnect(float(params.get("outage_s", 0.0)))
        else:
            count = params.get("count")
            self._server.drop_replies(None if count is None else int(count))

    def clear(self, fault: str | None = None) -> None:
        """Switch a fault off (all of them when ``fault`` is None; a disconnect just ends)."""
        if fault is not None and fault not in FAULTS:
            raise ValueError(f"unknown fault {fault!r}; known: {list(FAULTS)}")
        if fault in (None, "release_stuck"):
            with self._lock:
                self._stuck = False
        if fault in (None, "no_reply"):
            self._server.drop_replies(0)

    # -- the PLC logic -------------------------------------------------------------------------
    def _write_coil(self, name: str, value: bool) -> None:
        self.write_log.append((name, value))
        rising = value and not self._coil[name]
        self._coil[name] = value
        if name == "arm" and rising:
            self._release_token += 1  # a RELEASED still on its way is void now
            self._magnet_on = True
            self._released = False
            self.events["arms"] += 1
            self.tunnel.arm()
        elif name == "release" and rising:
            if not (self._coil["arm"] and self._magnet_on):
                self.events["releases_refused"] += 1  # interlock: not armed
            elif self._stuck:
                self.events["releases_stuck"] += 1  # the fault: nothing moves, no RELEASED
            else:
                self._coil["arm"] = False  # one arming permits one release
                self._magnet_on = False
                self.events["releases"] += 1
                delay = float(self._rng.uniform(*self.release_delay_s))
                self.release_delays.append(delay)
                self._release_token += 1
                token = self._release_token
                # The timer starts at the release: the armature moves while the tunnel computes.
                self._server.call_later(delay, lambda: self._set_released(token))
                self.tunnel.release()
        elif name == "trigger" and rising:
            self._count = (self._count + 1) & 0xFFFF
            self.events["triggers"] += 1
            self.tunnel.trigger()

    def _set_released(self, token: int) -> None:
        with self._lock:
            if token == self._release_token and not self._magnet_on:
                self._released = True

    # -- the Modbus side ------------------------------------------------------------------------
    def _device(self) -> SimDevice:
        coils = [SimData(a, values=False, datatype=DataType.BITS)
                 for a in sorted(self.coils.values())]
        inputs = [SimData(self.discrete_inputs["released"], values=False,
                          datatype=DataType.BITS)]
        registers = [SimData(self.holding_registers["trigger_count"], values=0,
                             datatype=DataType.REGISTERS, readonly=True)]
        no_input_registers = [SimData(0, datatype=DataType.INVALID)]
        return SimDevice(self.unit, simdata=(coils, inputs, registers, no_input_registers),
                         action=self._action)

    async def _action(self, function_code: int, start_address: int, address: int, count: int,
                      registers: list[int], set_values: Any) -> ExcCodes | None:
        # Called by pymodbus for every valid-address request before it reads or stores the block.
        names = {a: n for n, a in self.coils.items()}
        with self._lock:
            if function_code in (5, 15) and set_values is not None:
                targets = [address + i for i in range(len(set_values))]
                if any(a not in names for a in targets):
                    return ExcCodes.ILLEGAL_ADDRESS
                for a, value in zip(targets, set_values, strict=True):
                    self._write_coil(names[a], bool(value))
            if function_code in (1, 5, 15):
                bits_into_registers(registers, start_address,
                                    {a: self._coil[n] for n, a in self.coils.items()})
            elif function_code == 2:
                bits_into_registers(registers, start_address,
                                    {self.discrete_inputs["released"]: self._released})
            elif function_code == 3:
                registers[self.holding_registers["trigger_count"] - start_address] = self._count
            else:
                return ExcCodes.ILLEGAL_FUNCTION
        return None
