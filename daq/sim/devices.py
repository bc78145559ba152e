"""The simulators a simulated rig can start, one per driver name: :class:`SimulatorEntry`.

Responsibility: what :mod:`daq.sim.rig` needs to start the simulated device of a configured
instrument: a factory ``(tunnel, settings, **options) -> simulator`` (the simulator has
``start() -> url`` and ``stop()``, and serves its device's bytes on 127.0.0.1), the options it
accepts from ``[simulation.devices.<name>]``, and the settings the driver needs once it runs
(ephemeral ports). The five built-in entries below are the entry points of the group
:data:`GROUP` (``windrig.simulators``) of the ``windrig`` distribution; a plugin contributes
the simulator of its own device the same way (docs/guides/drivers.md), found by
:func:`simulator_entry`.

Not responsible for: the virtual tunnel or the sensor errors a rig config's calibrations undo
(:mod:`daq.sim.rig`), or the simulators themselves (:mod:`simulators.devices`).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Any

from daq.errors import ConfigError, PluginError
from simulators.devices.abb_acs580 import SimAbbAcs580
from simulators.devices.microepsilon_ild1420 import SimMicroEpsilonIld1420
from simulators.devices.modbus_plc import SimModbusPlc
from simulators.devices.scanivalve_mps4264.scanner import SimScanivalveMps4264
from simulators.devices.vaisala_ptb330 import SimVaisalaPtb330
from simulators.virtual_tunnel import VirtualTunnel

__all__ = ["ABB_ACS580", "GROUP", "MICROEPSILON_ILD1420", "MODBUS_PLC", "PASSED_OPTIONS",
           "SCANIVALVE_MPS4264", "VAISALA_PTB330", "SimulatorEntry", "simulator_entry"]

#: The entry-point group through which distributions contribute simulators.
GROUP = "windrig.simulators"

#: The keyword options windrig passes a simulator factory itself: ``clock`` and ``rng``
#: always, the sensor errors a rig's calibration undoes where it has them.
PASSED_OPTIONS = ("clock", "rng", "tap_channels", "pitot_error", "reading_error")


def _no_settings(settings: Mapping[str, Any], simulator: Any) -> Mapping[str, Any]:
    return settings


@dataclass(frozen=True)
class SimulatorEntry:
    """How to start the simulated device of one driver.

    Attributes
    ----------
    name : str
        The driver's name (the entry point's name, as in ``windrig.drivers``).
    factory : callable
        ``factory(tunnel, settings, **options)``: the simulator, not yet started. ``tunnel`` is
        the :class:`simulators.virtual_tunnel.VirtualTunnel` (the truth: pressures, motion, fan
        speed, air); ``settings`` the instrument's table of the rig config; ``options`` those
        of :attr:`options` given in ``[simulation.devices.<name>]`` plus ``clock`` (a
        :class:`simulators.clock.DeviceClock`) and ``rng`` (a seed or generator), and for a
        scanner ``tap_channels`` and ``pitot_error``, for a laser with a calibration
        ``reading_error`` (the errors the rig's calibration undoes).
    options : callable
        The simulator class (or any callable) whose keyword parameters are the options the
        simulator accepts; an option not among them is a ConfigError naming it.
    settings : callable
        ``settings(instrument_settings, started_simulator)``: the driver's settings once the
        simulator runs (e.g. its ephemeral data port); default: unchanged.
    """

    name: str
    factory: Callable[..., Any]
    options: Callable[..., Any]
    settings: Callable[[Mapping[str, Any], Any], Mapping[str, Any]] = _no_settings

    def accepted_options(self) -> set[str]:
        """Return the option names a rig config may give the simulator (its keyword parameters).

        Less those windrig always passes itself (:data:`PASSED_OPTIONS`): a ``seed`` or
        ``clock_offset_s`` in the config sets them; the same name in the config would
        otherwise be accepted and then silently replaced.
        """
        return set(inspect.signature(self.options).parameters) - {"tunnel", *PASSED_OPTIONS}


def simulator_entry(driver: str, where: str) -> SimulatorEntry:
    """Return the simulator entry of a driver, from the ``windrig.simulators`` entry points.

    Raises
    ------
    ConfigError
        No installed distribution gives a simulator for ``driver``.
    PluginError
        The entry point cannot be loaded, or is not a :class:`SimulatorEntry` of that name.
    """
    found = [ep for ep in entry_points(group=GROUP) if ep.name == driver]
    if not found:
        raise ConfigError(f"{where}: no simulator for driver {driver!r} (a plugin contributes "
                          f"one through the entry-point group {GROUP!r})")
    ep = found[0]
    dist = "(unknown distribution)" if ep.dist is None else f"{ep.dist.name} {ep.dist.version}"
    origin = f"distribution {dist}, entry point {ep.name} = {ep.value}"
    if len(found) > 1:
        raise PluginError(f"simulator {driver!r} is contributed by more than one distribution "
                          f"({origin}, and {len(found) - 1} more)")
    try:
        obj = ep.load()
    except Exception as exc:  # a plugin's import failure, reported in one line
        raise PluginError(f"simulator plugin {driver!r} cannot be imported ({origin}): "
                          f"{type(exc).__name__}: {' '.join(str(exc).split())}") from exc
    if not isinstance(obj, SimulatorEntry) or obj.name != driver:
        raise PluginError(f"simulator plugin {driver!r} is not the daq.sim.devices."
                          f"SimulatorEntry of that driver ({origin})")
    return obj


# -- windrig's own simulators ----------------------------------------------------------------------
def _scanner(tunnel: VirtualTunnel, s: Mapping[str, Any], **kw: Any) -> SimScanivalveMps4264:
    return SimScanivalveMps4264(tunnel, modules=int(s["modules"]), rate_hz=float(s["rate_hz"]),
                                byte_order=str(s.get("byte_order", "big")),
                                pitot_channel=int(s["pitot_channel"]), **kw)


def _scanner_settings(settings: Mapping[str, Any], sim: Any) -> Mapping[str, Any]:
    return {**settings, "data_port": sim.data_port}  # both ports are ephemeral here


def _laser(tunnel: VirtualTunnel, s: Mapping[str, Any], **kw: Any) -> SimMicroEpsilonIld1420:
    keys = ("range_mm", "rate_hz", "x", "standoff_mm", "baudrate", "output", "axis", "z")
    return SimMicroEpsilonIld1420(tunnel, **{k: s[k] for k in keys if k in s}, **kw)


def _fan(tunnel: VirtualTunnel, s: Mapping[str, Any], **kw: Any) -> SimAbbAcs580:
    extra: dict[str, Any] = (
        {"ramp_rpm_per_s": float(s["ramp_rpm_per_s"])} if "ramp_rpm_per_s" in s else {}
    )
    registers = s["registers"]
    return SimAbbAcs580(tunnel, control_word=int(registers["control_word"]),
                        reference_1=int(registers["reference_1"]),
                        status_word=int(registers["status_word"]),
                        actual_1=int(registers["actual_1"]), max_rpm=float(s["max_rpm"]),
                        **extra, **kw)


def _plc(tunnel: VirtualTunnel, s: Mapping[str, Any], **kw: Any) -> SimModbusPlc:
    coils, inputs, registers = s["coils"], s["discrete_inputs"], s["holding_registers"]
    return SimModbusPlc(tunnel, release=int(coils["release"]), arm=int(coils["arm"]),
                        trigger=int(coils["trigger"]), released=int(inputs["released"]),
                        trigger_count=int(registers["trigger_count"]), **kw)


def _barometer(tunnel: VirtualTunnel, s: Mapping[str, Any], **kw: Any) -> SimVaisalaPtb330:
    return SimVaisalaPtb330(tunnel, **kw)


SCANIVALVE_MPS4264 = SimulatorEntry("scanivalve_mps4264", _scanner, SimScanivalveMps4264,
                                    _scanner_settings)
MICROEPSILON_ILD1420 = SimulatorEntry("microepsilon_ild1420", _laser, SimMicroEpsilonIld1420)
ABB_ACS580 = SimulatorEntry("abb_acs580", _fan, SimAbbAcs580)
MODBUS_PLC = SimulatorEntry("modbus_plc", _plc, SimModbusPlc)
VAISALA_PTB330 = SimulatorEntry("vaisala_ptb330", _barometer, SimVaisalaPtb330)
