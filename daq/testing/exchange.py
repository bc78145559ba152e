"""Scripted byte exchanges and Modbus calls for a driver's tests, without a device.

Responsibility: give a driver author the scripted transports of :mod:`daq.transports.scripted`
under the kit's name: :func:`expected_exchange` (a byte transport that plays ``(sent, reply)``
pairs, failing at once on a write that differs, and on exit if a pair was left) and
:func:`expected_bus_calls` (a register bus that plays ``(method, address, value, result)``
calls), and :func:`scripted_driver`, a driver built on such a transport through its registry
entry, as :func:`daq.instruments.build.build_driver` would build it.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import Any

from daq.instruments.entry import DriverEntry
from daq.transports.scripted import (
    ScriptedBus,
    ScriptedTransport,
    expected_bus_calls,
    expected_exchange,
)

__all__ = ["ScriptedBus", "ScriptedTransport", "expected_bus_calls", "expected_exchange",
           "scripted_driver"]


@contextmanager
def scripted_driver(entry: DriverEntry, settings: Mapping[str, Any],
                    exchanges: Sequence[tuple[bytes, bytes]], **extra: Any) -> Iterator[Any]:
    """Build a byte-transport driver from its entry on a scripted exchange; yield it.

    The settings table is validated by the entry (as a rig config's would be). On exit the
    script must have been played to its end.

    Parameters
    ----------
    entry : DriverEntry
        The driver's registry entry.
    settings : mapping
        The instrument's table of a rig config (without ``driver``, ``url``, ``name``).
    exchanges : sequence of (bytes, bytes)
        What the driver must send and what the device answers (``b""`` sent: unsolicited).
    extra
        Keyword arguments of the factory (a fan driver's ``limit_rpm``).
    """
    validated = entry.validate(settings, f"driver {entry.name!r}")
    with expected_exchange(exchanges) as transport:
        yield entry.factory(transport, validated, **extra)
