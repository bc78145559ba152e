"""Settings of the release/trigger PLC driver: the ``[plc]`` table, validated.

Responsibility: :class:`ModbusPlcSettings` (the addresses of the ARM, RELEASE and DAQ_TRIGGER
coils, the RELEASED input and the TRIGGER_COUNT register, the time a release may take and the
width of a trigger pulse); each check raises a :class:`~daq.errors.ConfigError` naming the key.

Not responsible for: commanding the PLC (:mod:`daq.instruments.modbus_plc.driver`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from daq.errors import ConfigError
from daq.validation import check_keys, number

__all__ = ["ModbusPlcSettings"]


def _addresses(table: Any, where: str, names: tuple[str, ...]) -> dict[str, int]:
    check_keys(table, where, set(names))
    out = {}
    for name in names:
        value = table[name]
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFFFF:
            raise ConfigError(f"{where}.{name} = {value!r} must be an integer address in "
                              "[0, 65535]")
        out[name] = int(value)
    return out


@dataclass(frozen=True)
class ModbusPlcSettings:
    """Validated settings of the PLC (the rig config's ``[plc]`` table).

    Attributes
    ----------
    coils : dict
        ``release``, ``arm``, ``trigger``: zero-based coil addresses 0..65535, distinct.
    discrete_inputs : dict
        ``released``: zero-based discrete-input address.
    holding_registers : dict
        ``trigger_count``: zero-based holding-register address.
    release_timeout_s : float
        Time allowed for RELEASED after the release coil, s; in (0, 10], default 0.5.
    trigger_pulse_s : float
        Width of a trigger pulse, s; in (0, 1], default 0.01.
    """

    coils: Mapping[str, int]
    discrete_inputs: Mapping[str, int]
    holding_registers: Mapping[str, int]
    release_timeout_s: float = 0.5
    trigger_pulse_s: float = 0.01

    @classmethod
    def from_table(cls, table: Mapping[str, Any], where: str = "[plc]") -> ModbusPlcSettings:
        """Validate a rig-config table (without driver/url/name); raise ConfigError naming keys."""
        check_keys(table, where, {"coils", "discrete_inputs", "holding_registers"},
                   {"release_timeout_s", "trigger_pulse_s"})
        coils = _addresses(table["coils"], f"{where} coils", ("release", "arm", "trigger"))
        if len(set(coils.values())) != len(coils):
            raise ConfigError(f"{where} coils: addresses must be distinct, got {coils}")
        return cls(
            coils=coils,
            discrete_inputs=_addresses(table["discrete_inputs"], f"{where} discrete_inputs",
                                       ("released",)),
            holding_registers=_addresses(table["holding_registers"],
                                         f"{where} holding_registers", ("trigger_count",)),
            release_timeout_s=number(table, "release_timeout_s", where, lo=0.0, hi=10.0,
                                     lo_open=True, default=0.5),
            trigger_pulse_s=number(table, "trigger_pulse_s", where, lo=0.0, hi=1.0,
                                   lo_open=True, default=0.01),
        )
