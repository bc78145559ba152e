"""Registry of instrument drivers, keyed by the ``driver`` name used in rig configs.

Each driver module exports its :class:`~daq.instruments.entry.DriverEntry` as ``DRIVER`` (its
class, its settings validator and the role it can fill); this module imports the five driver
modules windrig ships, statically, and collects their entries (the NI-DAQmx module exports two,
``LASER_DRIVER`` and ``ANALOG_DRIVER``). The rig config asks the registry
to validate an instrument table (:func:`validate_settings`), and
:func:`daq.instruments.build.build_driver` asks it for the factory. No ``eval`` and no import of
arbitrary strings: the drivers are the imports below, and :func:`register` adds an entry built
in code.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from daq.errors import ConfigError
from daq.instruments.abb_acs580 import driver as abb_acs580
from daq.instruments.entry import DriverEntry
from daq.instruments.microepsilon_ild1420 import driver as microepsilon_ild1420
from daq.instruments.modbus_plc import driver as modbus_plc
from daq.instruments.ni_daqmx import driver as ni_daqmx
from daq.instruments.scanivalve_mps4264 import driver as scanivalve_mps4264
from daq.instruments.vaisala_ptb330 import driver as vaisala_ptb330

__all__ = ["DRIVER_MODULES", "driver_entry", "register", "validate_settings"]

_SHIPPED = (vaisala_ptb330, abb_acs580, modbus_plc, scanivalve_mps4264, microepsilon_ild1420)
#: The driver modules windrig ships (each exports its entry as ``DRIVER``).
DRIVER_MODULES: tuple[str, ...] = tuple(module.__name__ for module in _SHIPPED)

_REGISTRY: dict[str, DriverEntry] = {module.DRIVER.name: module.DRIVER for module in _SHIPPED}
# The NI-DAQmx module has two entries (lasers and scaled analog inputs); it imports nidaqmx only
# when one of its drivers is built (an optional extra).
_REGISTRY.update({entry.name: entry for entry in (ni_daqmx.LASER_DRIVER, ni_daqmx.ANALOG_DRIVER)})


def register(entry: DriverEntry) -> None:
    """Register a further driver (one built in code; the shipped ones are registered already)."""
    if entry.name in _REGISTRY and _REGISTRY[entry.name] != entry:
        raise RuntimeError(f"driver {entry.name!r} registered twice")
    _REGISTRY[entry.name] = entry


def driver_entry(name: str) -> DriverEntry:
    """Return the registered driver called ``name``."""
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
