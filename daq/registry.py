"""Registry of instrument drivers, keyed by the ``driver`` name used in rig configs.

Each driver module registers its class, its settings validator and the role it can fill; the
rig config asks the registry to validate an instrument table, and the acquisition asks it to build
the driver. No ``eval`` and no import of arbitrary strings (STYLE.md, "Configuration"): only the
modules listed in :data:`DRIVER_MODULES` are ever imported.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from daq.errors import ConfigError

__all__ = ["DRIVER_MODULES", "DriverEntry", "driver_entry", "register", "validate_settings"]

#: The driver modules windrig ships; importing one registers its driver(s).
DRIVER_MODULES: tuple[str, ...] = (
    "daq.vaisala_ptb330",
    "daq.abb_acs580",
    "daq.modbus_plc",
    "daq.scanivalve_mps4264",
    "daq.microepsilon_ild1420",
)


@dataclass(frozen=True)
class DriverEntry:
    """A registered driver.

    Attributes
    ----------
    name : str
        The ``driver`` value in rig configs.
    role : str
        The instrument role it fills (``scanner``, ``lasers``, ``fan``, ``plc``, ``barometer``).
    factory : callable
        Builds the driver from ``(transport_or_bus, settings)``.
    validate : callable
        ``validate(settings, where)`` returning the settings object or raising ConfigError.
    transport_defaults : mapping
        Line settings the device needs (e.g. 7E1 at 9600 baud), passed to
        :func:`daq.transport.open_transport`; a ``serial://`` URL's query overrides them.
    """

    name: str
    role: str
    factory: Callable[..., Any]
    validate: Callable[[Mapping[str, Any], str], Any]
    transport_defaults: Mapping[str, Any] = field(default_factory=dict)


_REGISTRY: dict[str, DriverEntry] = {}


def register(entry: DriverEntry) -> None:
    """Register a driver (called by the driver modules at import)."""
    if entry.name in _REGISTRY and _REGISTRY[entry.name] != entry:
        raise RuntimeError(f"driver {entry.name!r} registered twice")
    _REGISTRY[entry.name] = entry


def _load_all() -> None:
    for module in DRIVER_MODULES:
        importlib.import_module(module)


def driver_entry(name: str) -> DriverEntry:
    """Return the registered driver called ``name``."""
    _load_all()
    if name not in _REGISTRY:
        raise ConfigError(f"unknown driver {name!r}; known drivers: {sorted(_REGISTRY)}")
    return _REGISTRY[name]


def validate_settings(driver: str, role: str, settings: Mapping[str, Any], where: str) -> Any:
    """Validate an instrument table's driver-specific settings; return the settings object."""
    try:
        entry = driver_entry(driver)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from exc
    if entry.role != role:
        raise ConfigError(f"{where}: driver {driver!r} is a {entry.role} driver, not a {role}")
    return entry.validate(settings, where)
