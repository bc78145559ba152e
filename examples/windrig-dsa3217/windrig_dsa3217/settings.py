"""The ``[scanner]`` table of a rig config for a DSA3217, validated: :class:`Dsa3217Settings`."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from daq.errors import ConfigError
from daq.validation import check_keys, number

#: Pressure channels of one DSA3217 (the "17" is its 16 channels plus the reference, read as 16).
CHANNELS = 16
#: Pa per psi: the scanner's engineering units are psi unless told otherwise.
PSI_PA = 6894.757293168


@dataclass(frozen=True)
class Dsa3217Settings:
    """Settings of one DSA3217.

    Attributes
    ----------
    rate_hz : float
        Frames per second, (0, 500]; the unit averages and streams at this rate.
    modules : int
        Always 1: one DSA3217 is one module of 16 channels (a rig with more taps needs a
        scanner of more modules).
    pitot_channel : int
        The channel (0..15) whose pressure is the Pitot's; taps are on the others.
    units_pa : float
        Pa per engineering unit the scanner sends (default: psi).
    min_block_s : float
        Frames gathered into one reading, s (0: one frame per reading).
    timeout_s : float
        Longest wait for a command's reply, s.
    """

    rate_hz: float = 100.0
    modules: int = 1
    pitot_channel: int = CHANNELS - 1
    units_pa: float = PSI_PA
    min_block_s: float = 0.02
    timeout_s: float = 2.0

    @classmethod
    def from_table(cls, table: Mapping[str, Any], where: str = "[scanner]") -> Dsa3217Settings:
        """Validate a rig config's table (unknown keys and out-of-range values refused)."""
        check_keys(table, where, {"rate_hz"},
                   {"modules", "pitot_channel", "units_pa", "min_block_s", "timeout_s"})
        modules = table.get("modules", 1)
        if modules != 1 or isinstance(modules, bool):
            raise ConfigError(f"{where} modules = {modules!r}: a DSA3217 is one module of "
                              f"{CHANNELS} channels")
        pitot = table.get("pitot_channel", CHANNELS - 1)
        if isinstance(pitot, bool) or not isinstance(pitot, int) or not 0 <= pitot < CHANNELS:
            raise ConfigError(f"{where} pitot_channel = {pitot!r}: an integer in "
                              f"[0, {CHANNELS - 1}]")
        return cls(rate_hz=number(table, "rate_hz", where, lo=0.0, hi=500.0, lo_open=True),
                   pitot_channel=pitot,
                   units_pa=number(table, "units_pa", where, lo=0.0, lo_open=True,
                                   default=PSI_PA),
                   min_block_s=number(table, "min_block_s", where, lo=0.0, hi=1.0,
                                      default=0.02),
                   timeout_s=number(table, "timeout_s", where, lo=0.0, hi=60.0, lo_open=True,
                                    default=2.0))
