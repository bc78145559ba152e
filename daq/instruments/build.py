"""Build the driver of a configured instrument: transport from its URL, settings, safety limits.

The one place that turns an :class:`~daq.config.InstrumentConfig` into a driver object (not yet
opened: drivers do no I/O until ``open()``). Modbus URLs get a
:class:`~daq.transports.modbus.ModbusBus`; a driver whose entry has a ``link`` (a vendor
library's device, e.g. ``nidaqmx://``) gets what that builds from the URL; everything else a
byte transport with the driver's line defaults (a ``serial://`` query overrides them). The fan
drive always receives the rig's fan-speed limit.
"""

from __future__ import annotations

from typing import Any

from daq.config import InstrumentConfig, Limits
from daq.errors import ConfigError
from daq.instruments import registry
from daq.transports.byte_transport import open_transport
from daq.transports.modbus import ModbusBus

__all__ = ["build_driver"]


def build_driver(inst: InstrumentConfig, limits: Limits) -> Any:
    """Create (do not open) the driver of ``inst``.

    Raises
    ------
    ConfigError
        Unknown driver, invalid settings, or a URL still ``"auto"`` (a simulated rig whose
        simulators were not started: use :func:`daq.sim.rig.start_simulated_rig`).
    """
    if inst.url == "auto":
        raise ConfigError(f"instrument {inst.name!r} has url = 'auto': start the simulated rig "
                          "(windrig simulate) or give the instrument's real URL")
    entry = registry.driver_entry(inst.driver)
    settings = entry.validate(inst.settings, f"instrument {inst.name!r}")
    link: Any
    if entry.link is not None:
        link = entry.link(inst.url)
    elif inst.url.startswith("modbus+"):
        link = ModbusBus(inst.url)
    else:
        link = open_transport(inst.url, **dict(entry.transport_defaults))
    extra = {"limit_rpm": limits.max_fan_rpm} if inst.role == "fan" else {}
    return entry.factory(link, settings, **extra)
