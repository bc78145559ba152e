"""Settings of the Vaisala PTB330-class barometer driver: the ``[barometer]`` table, validated.

Responsibility: :class:`Ptb330Settings` (poll interval, reply timeout, the device address for
a shared line) with their ranges; each check raises a :class:`~daq.errors.ConfigError` naming
the key.

Not responsible for: the line format (:mod:`daq.instruments.vaisala_ptb330.decoder`) or polling
(:mod:`daq.instruments.vaisala_ptb330.driver`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from daq.errors import ConfigError
from daq.validation import check_keys, number

__all__ = ["Ptb330Settings"]


@dataclass(frozen=True)
class Ptb330Settings:
    """Driver settings of a ``[barometer]`` table with ``driver = "vaisala_ptb330"``.

    Attributes
    ----------
    poll_interval_s : float
        Period of :meth:`VaisalaPtb330.poll`, s, in [0.1, 60]; default 1.0.
    timeout_s : float
        Longest wait for one reply line, s, in [0.05, 30]; default 2.0.
    address : int or None
        Device address for ``SEND aa`` / ``OPEN aa`` (POLL mode on a shared line), 0..255
        (PTB330 manual p.101, ``OPEN [aa]``); None (default) sends a bare ``SEND``.
    """

    poll_interval_s: float = 1.0
    timeout_s: float = 2.0
    address: int | None = None

    def __post_init__(self) -> None:
        where = "vaisala_ptb330 settings"
        number({"poll_interval_s": self.poll_interval_s}, "poll_interval_s", where,
               lo=0.1, hi=60.0)
        number({"timeout_s": self.timeout_s}, "timeout_s", where, lo=0.05, hi=30.0)
        _check_address(self.address, where)

    @classmethod
    def from_table(cls, table: Mapping[str, Any], where: str) -> Ptb330Settings:
        """Validate a rig-config table (without driver/url/name) or raise ConfigError."""
        check_keys(table, where, set(), {"poll_interval_s", "timeout_s", "address"})
        address = table.get("address")
        _check_address(address, where)
        return cls(
            poll_interval_s=number(table, "poll_interval_s", where, lo=0.1, hi=60.0,
                                   default=1.0),
            timeout_s=number(table, "timeout_s", where, lo=0.05, hi=30.0, default=2.0),
            address=address,
        )


def _check_address(address: object, where: str) -> None:
    if address is None:
        return
    if isinstance(address, bool) or not isinstance(address, int) or not 0 <= address <= 255:
        raise ConfigError(f"{where} address = {address!r} must be an integer in [0, 255]")
