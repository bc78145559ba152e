"""Build the driver of a configured instrument: transport from its URL, settings, safety limits.

The one place that turns an :class:`~daq.config.InstrumentConfig` into a driver object (not yet
opened: drivers do no I/O until ``open()``). Modbus URLs get a
:class:`~daq.transports.modbus.ModbusBus`; a driver whose entry has a ``link`` (a vendor
library's device, e.g. ``nidaqmx://``) gets what that builds from the URL; everything else a
byte transport with the driver's line defaults (a ``serial://`` query overrides them). The fan
drive always receives the rig's fan-speed limit. A polled driver (fan, PLC, barometer) whose
settings set ``poll_interval_s`` must keep them as its ``settings`` attribute, where the engine
reads the period (:func:`daq.acquisition.adapters.make_adapter`): one that does not is refused
here rather than polled at the default period without a word. The driver's own code (its
``validate``, ``link`` and ``factory``) is called through
:func:`daq.instruments.registry.call_driver_code`: an exception that is not windrig's is a
PluginError naming the driver and its distribution, not a traceback.
"""

from __future__ import annotations

from typing import Any

from daq.config import InstrumentConfig, Limits
from daq.errors import ConfigError, PluginError
from daq.instruments import registry
from daq.transports.byte_transport import open_transport
from daq.transports.modbus import ModbusBus

__all__ = ["POLLED_ROLES", "build_driver", "poll_settings_problem"]

#: The roles the engine polls (``read()`` every poll period) rather than streams.
POLLED_ROLES = ("fan", "plc", "barometer")


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
    where = f"instrument {inst.name!r}"
    settings = registry.call_driver_code(entry, f"validate of {where}", entry.validate,
                                         inst.settings, where)
    link: Any
    if entry.link is not None:
        link = registry.call_driver_code(entry, f"link({inst.url!r}) of {where}", entry.link,
                                         inst.url)
    elif inst.url.startswith("modbus+"):
        link = ModbusBus(inst.url)
    else:
        link = open_transport(inst.url, **dict(entry.transport_defaults))
    extra = {"limit_rpm": limits.max_fan_rpm} if inst.role == "fan" else {}
    driver = registry.call_driver_code(entry, f"factory of {where}", entry.factory, link,
                                       settings, **extra)
    problem = poll_settings_problem(inst.role, driver, settings)
    if problem is not None:
        raise PluginError(f"driver {entry.name!r} of instrument {inst.name!r}: {problem}")
    return driver


def poll_settings_problem(role: str, driver: Any, settings: Any) -> str | None:
    """Say why the engine would miss a polled driver's own poll period (None: it would not).

    The engine polls a fan, PLC or barometer every ``driver.settings.poll_interval_s`` s where
    that exists, else every default period of the role. A driver that keeps its validated
    settings under another name would be polled at the default without a word, so where the
    settings set ``poll_interval_s`` the driver's ``settings.poll_interval_s`` must equal it.
    """
    own = getattr(settings, "poll_interval_s", None)
    if role not in POLLED_ROLES or own is None:
        return None
    seen = getattr(getattr(driver, "settings", None), "poll_interval_s", None)
    if seen == own:
        return None
    return (f"its settings set poll_interval_s = {own!r} but the driver "
            f"{type(driver).__name__} has no `settings` attribute holding them (found "
            f"{seen!r} there), so the engine would poll it at its default period; a polled "
            "driver keeps its validated settings as `self.settings` (docs/guides/drivers.md)")
