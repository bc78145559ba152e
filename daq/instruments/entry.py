"""What a driver tells the registry about itself: :class:`DriverEntry`.

Responsibility: the record each driver module exports as its ``DRIVER`` constant (its name in
rig configs, the role it fills, how to build it and how to validate its settings, the line
settings its transport needs), and the roles a driver can fill. Kept apart from
:mod:`daq.instruments.registry` so that a driver module (a plugin's too) imports only this.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["ROLES", "DriverEntry"]

#: The roles an instrument fills in a rig config (one table each, ``[[lasers]]`` an array);
#: docs/guides/drivers.md writes down what each role's driver must deliver.
ROLES = ("scanner", "lasers", "fan", "plc", "barometer", "analog")


@dataclass(frozen=True)
class DriverEntry:
    """A registered driver.

    Attributes
    ----------
    name : str
        The ``driver`` value in rig configs.
    role : str
        The instrument role it fills, one of :data:`ROLES` (``scanner``, ``lasers``, ``fan``,
        ``plc``, ``barometer``, ``analog``).
    factory : callable
        Builds the driver from ``(transport_or_bus, settings)`` (a fan's also gets
        ``limit_rpm``); a polled driver keeps ``settings`` as its ``settings`` attribute.
    validate : callable
        ``validate(table, where)``: the instrument's raw table into the settings object, or a
        ConfigError whose message starts with ``where`` (``"<config path> [barometer]"``).
    transport_defaults : mapping
        Line settings the device needs (e.g. 7E1 at 9600 baud), passed to
        :func:`daq.transports.byte_transport.open_transport`; a ``serial://`` URL's query
        overrides them. Keys: those of
        :data:`daq.transports.byte_transport.LINE_SETTINGS`, any other a ConfigError.
    link : callable or None
        For a driver that reaches its device through a vendor library rather than bytes or
        registers (NI-DAQmx): ``link(url)`` returns what the factory takes instead of a
        transport (parsed from the URL, no I/O). None: a byte transport or a Modbus bus.
    """

    name: str
    role: str
    factory: Callable[..., Any]
    validate: Callable[[Mapping[str, Any], str], Any]
    transport_defaults: Mapping[str, Any] = field(default_factory=dict)
    link: Callable[[str], Any] | None = None
