"""Settings of the ABB ACS580-class fan drive driver: the ``[fan]`` table, validated.

Responsibility: :class:`AbbAcs580Settings` (the speed at full-scale reference, the drive's ramp
rate, the Modbus reply timeout) and its :class:`RegisterMap` (the four holding registers the
driver uses, distinct); each check raises a :class:`~daq.errors.ConfigError` naming the key.

Not responsible for: the profile's words (:mod:`daq.instruments.abb_acs580.profile`) or driving
the fan (:mod:`daq.instruments.abb_acs580.driver`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from daq.errors import ConfigError
from daq.validation import check_keys, number

__all__ = ["AbbAcs580Settings", "RegisterMap"]


@dataclass(frozen=True)
class RegisterMap:
    """Zero-based holding-register addresses of the drive (rig config ``registers``)."""

    control_word: int
    reference_1: int
    status_word: int
    actual_1: int


@dataclass(frozen=True)
class AbbAcs580Settings:
    """Validated settings of the fan drive (the rig config's ``[fan]`` table).

    Attributes
    ----------
    max_rpm : float
        Speed at Reference 1 = 20000, rpm; in (0, 100000].
    registers : RegisterMap
        Register addresses, ints 0..65535, distinct.
    poll_timeout_s : float
        Reply timeout of one Modbus request, s; in (0, 60], default 1.0.
    ramp_rpm_per_s : float
        The drive's ramp rate, rpm/s (informational; sizes default waits); in (0, 100000],
        default 100.
    """

    max_rpm: float
    registers: RegisterMap
    poll_timeout_s: float = 1.0
    ramp_rpm_per_s: float = 100.0

    @classmethod
    def from_table(cls, table: Mapping[str, Any], where: str = "[fan]") -> AbbAcs580Settings:
        """Validate a rig-config table (without driver/url/name); raise ConfigError naming keys."""
        check_keys(table, where, {"max_rpm", "registers"}, {"poll_timeout_s", "ramp_rpm_per_s"})
        registers = table["registers"]
        names = ("control_word", "reference_1", "status_word", "actual_1")
        check_keys(registers, f"{where} registers", set(names))
        for name in names:
            value = registers[name]
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFFFF:
                raise ConfigError(f"{where} registers.{name} = {value!r} must be an integer "
                                  "register address in [0, 65535]")
        if len({registers[name] for name in names}) != len(names):
            raise ConfigError(f"{where} registers: addresses must be distinct, got "
                              f"{ {name: registers[name] for name in names} }")
        return cls(
            max_rpm=number(table, "max_rpm", where, lo=0.0, hi=100000.0, lo_open=True),
            registers=RegisterMap(**{name: int(registers[name]) for name in names}),
            poll_timeout_s=number(table, "poll_timeout_s", where, lo=0.0, hi=60.0, lo_open=True,
                                  default=1.0),
            ramp_rpm_per_s=number(table, "ramp_rpm_per_s", where, lo=0.0, hi=100000.0,
                                  lo_open=True, default=100.0),
        )
