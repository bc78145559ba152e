"""The ABB Drives profile as the fan driver speaks it: Control Word values, Status Word bits.

Responsibility: the Control Word values the driver writes (:data:`CW_PREPARE`, :data:`CW_RUN`,
:data:`CW_COAST`, the :data:`CW_RESET_BIT`), the Reference 1 / Actual 1 scaling
(:data:`FULL_SCALE` counts at the maximum speed) and the decoded Status Word
(:class:`DriveStatus`). Pure: no I/O. The sources of each value are in
``docs/reference/wire_formats.md``.

Not responsible for: the register addresses (:mod:`daq.instruments.abb_acs580.settings`) or the
command sequences and safety checks (:mod:`daq.instruments.abb_acs580.driver`).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["CW_COAST", "CW_PREPARE", "CW_RESET_BIT", "CW_RUN", "FULL_SCALE", "DriveStatus"]

#: Control Word values (docs/reference/wire_formats.md, "Fan drive") and the RESET bit (ABB Drives
#: profile CW bit 7).
CW_PREPARE = 0x0476


CW_RUN = 0x047F


CW_COAST = 0x0000


CW_RESET_BIT = 0x0080


#: Reference 1 / Actual 1 counts at the maximum speed (docs/reference/wire_formats.md, "Fan drive").
FULL_SCALE = 20000


_SW_BITS = ("rdy_on", "rdy_run", "rdy_ref", "tripped", "off_2_sta", "off_3_sta",
            "swc_on_inhib", "alarm", "at_setpoint", "remote", "above_limit")


@dataclass(frozen=True)
class DriveStatus:
    """The decoded Status Word of the ABB Drives profile.

    Attributes
    ----------
    word : int
        The raw Status Word.
    rdy_on, rdy_run, rdy_ref, tripped, off_2_sta, off_3_sta, swc_on_inhib, alarm,
    at_setpoint, remote, above_limit : bool
        Bits 0 to 10 (ready to switch on, ready to operate, operation enabled, fault, OFF2
        inactive, OFF3 inactive, switch-on inhibited, warning, at setpoint, remote control,
        above the supervision limit).
    """

    word: int
    rdy_on: bool
    rdy_run: bool
    rdy_ref: bool
    tripped: bool
    off_2_sta: bool
    off_3_sta: bool
    swc_on_inhib: bool
    alarm: bool
    at_setpoint: bool
    remote: bool
    above_limit: bool

    @classmethod
    def decode(cls, word: int) -> DriveStatus:
        """Decode a Status Word (bit n of ``word`` is the n-th field above).

        >>> DriveStatus.decode(0x0237).rdy_ref, DriveStatus.decode(0x0237).tripped
        (True, False)
        """
        if not 0 <= word <= 0xFFFF:
            raise ValueError(f"a status word is 0..65535, got {word!r}")
        flags = {name: bool(word >> bit & 1) for bit, name in enumerate(_SW_BITS)}
        return cls(word=word, **flags)

    def active(self) -> list[str]:
        """Return the names of the bits that are set (for messages)."""
        return [name.upper() for name in _SW_BITS if getattr(self, name)]
