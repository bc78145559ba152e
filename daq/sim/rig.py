"""Start every simulated instrument of a rig config from one call.

Builds the virtual tunnel from the config's section, taps, tunnel calibration and ``[simulation]``
truth, starts one simulator per configured instrument (loopback only), and returns the URLs to
point drivers at, together with a copy of the rig config whose ``"auto"`` URLs are filled in.
Responsible for translating config tables into simulator arguments; each driver's simulator is
found by its driver name (:mod:`daq.sim.devices`, the ``windrig.simulators`` entry points: a
plugin may contribute its own), and the simulators themselves know nothing of rig configs.

The rig config's calibrations (:mod:`daq.calibration`) are built into the simulated sensors as
their errors, so that the calibrations undo them: the scanner puts each tap on its wired channel
(``[taps] channels``), the Pitot reads the inverse of ``[tunnel.pitot]``, and each laser with a
``[lasers.calibration]`` reads along its tilted beam with the inverse gain and offset.

Instruments read through NI-DAQmx (``nidaqmx://`` URLs) share one simulated DAQ device per
device name (:class:`simulators.devices.ni_daqmx.SimNiDaqmx`), each of its analog inputs wired to
what the instrument on it measures (a laser's distance through the inverse of its scale, a
Pitot's dynamic pressure); their URLs keep the task's channels and get the simulated device's
``standin=127.0.0.1:PORT``, read through the stand-in of the nidaqmx API, which this module
registers (:func:`daq.instruments.ni_daqmx.runtime.register_standin`). Their simulation
settings are the first instrument's table of each device.

Simulators bind to loopback only, a plugin's as much as windrig's own: a simulator whose URL
names another host, or whose ports answer on one of this host's other addresses (bound to
``0.0.0.0``), is stopped and refused (:func:`_refuse_exposed`): a simulated release PLC or fan
drive must not be reachable from the lab's network.

Per-instrument simulation settings come from ``[simulation.devices.<name>]``: ``clock_offset_s``,
``clock_drift_ppm`` and ``seed`` (with the instrument's place in the config: equal seeds give
different instruments different noise) for every device, and any further keyword the device's
simulator accepts (noise levels, fault options); an unknown one is a ConfigError naming it.
"""

from __future__ import annotations

import dataclasses
import inspect
import ipaddress
import logging
import math
import socket
import urllib.parse
from collections.abc import Mapping
from typing import Any

import numpy as np

from daq.config import InstrumentConfig, RigConfig
from daq.errors import ConfigError, PluginError
from daq.instruments.ni_daqmx.address import TaskAddress
from daq.instruments.ni_daqmx.runtime import register_standin
from daq.instruments.ni_daqmx.settings import (
    UNITS,
    LinearScale,
    NiAnalogSettings,
    NiLaserSettings,
)
from daq.sim.devices import simulator_entry
from ident.physics.tubing import Air, tubing_set
from simulators.clock import Clock, DeviceClock
from simulators.devices.ni_daqmx import SimNiDaqmx
from simulators.nidaqmx_standin import standin_api
from simulators.virtual_tunnel import AirState, VirtualTunnel

__all__ = ["SimulatedRig", "start_simulated_rig"]

log = logging.getLogger(__name__)

_COMMON_KEYS = {"clock_offset_s", "clock_drift_ppm", "seed"}

# The simulated rig's NI devices are read through the stand-in of the nidaqmx API (this process
# and any that imports the simulated rig, e.g. the parent of a rig in its own process).
register_standin(standin_api)

#: Drivers whose instruments are inputs of a simulated NI DAQ device (not simulators of their own).
NI_DRIVERS = ("ni_daqmx_laser", "ni_daqmx_analog")


@dataclasses.dataclass
class SimulatedRig:
    """A running simulated rig.

    Attributes
    ----------
    config : RigConfig
        The rig config with every ``"auto"`` URL replaced by the simulator's URL.
    tunnel : VirtualTunnel
        The shared physical truth.
    simulators : dict
        Simulator object by instrument name.
    urls : dict
        URL by instrument name.
    """

    config: RigConfig
    tunnel: VirtualTunnel
    simulators: dict[str, Any]
    urls: dict[str, str]

    def close(self) -> None:
        """Stop every simulator (idempotent); a failure is raised after all were stopped."""
        failures: list[BaseException] = []
        for name, sim in reversed(list(self.simulators.items())):
            try:
                sim.stop()
            except Exception as exc:  # stop the others first; re-raised below, never swallowed
                log.error("stopping simulator %s failed: %s", name, exc)
                failures.append(exc)
        if failures:
            raise failures[0]

    def __enter__(self) -> SimulatedRig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def start_simulated_rig(
    config: RigConfig, *, clock: Clock | None = None, serial: str = "socket"
) -> SimulatedRig:
    """Build the virtual tunnel of ``config`` and start all its simulated instruments.

    Parameters
    ----------
    config : RigConfig
        A rig config with a ``[simulation]`` table.
    clock : Clock, optional
        True time (default: real time).
    serial : {"socket", "pty"}
        How serial instruments are served: pyserial ``socket://`` or a pty pair.

    Returns
    -------
    SimulatedRig
        Use it as a context manager, or call ``close()``.
    """
    if config.simulation is None:
        raise ConfigError(f"{config.source}: not a simulated rig (no [simulation] table)")
    sim = config.simulation
    air = AirState(pressure_pa=sim.pressure_pa, temperature_k=sim.temperature_c + 273.15)
    tubing = None
    if sim.tubing:  # [simulation] tubing = true: the scanner sees the taps through the tubes
        tubing = tubing_set(config.tubing, config.taps.n_taps,
                            Air(pressure_pa=air.pressure_pa, temperature_k=air.temperature_k))
    tunnel = VirtualTunnel(
        config.section, config.aerodynamic_model(), config.taps,
        wind_per_rpm=config.wind_per_rpm,
        hold=(sim.hold_h, sim.hold_alpha, sim.hold_p)[:config.section.n_dof],
        air=air, clock=clock, static=sim.static, turbulence=sim.turbulence, span=sim.span,
        seed=None if sim.turbulence is None else sim.turbulence_seed, tubing=tubing,
    )
    rig = SimulatedRig(config=config, tunnel=tunnel, simulators={}, urls={})
    resolved: list[InstrumentConfig] = []
    try:
        daqs = _start_ni_devices(config, tunnel)
        for inst in config.instruments:  # first: rig.close() stops them whatever fails next
            if inst.driver in NI_DRIVERS:
                rig.simulators[inst.name] = daqs[TaskAddress.parse(inst.url).device][0]
        for index, inst in enumerate(config.instruments):
            if inst.driver in NI_DRIVERS:
                standin = daqs[TaskAddress.parse(inst.url).device][1]
                url = f"{inst.url}{'&' if '?' in inst.url else '?'}standin={standin}"
                rig.urls[inst.name] = url
                resolved.append(dataclasses.replace(inst, url=url))
                continue
            simulator = _build(inst, tunnel, sim.devices.get(inst.name, {}), index, config.source,
                               _sensor_errors(config, inst))
            rig.simulators[inst.name] = simulator
            start = simulator.start
            url = start(serial) if "transport" in inspect.signature(start).parameters else start()
            rig.urls[inst.name] = url
            settings = dict(simulator_entry(inst.driver, config.source).settings(
                inst.settings, simulator))
            _refuse_exposed(inst, url, settings, config.source)
            resolved.append(dataclasses.replace(inst, url=url, settings=settings))
    except BaseException:
        rig.close()
        raise
    rig.config = dataclasses.replace(config, instruments=tuple(resolved))
    return rig


def _ni_source(inst: InstrumentConfig, source: str) -> dict[str, dict[str, Any]]:
    """Return what an NI instrument's inputs carry: analog input -> the simulator's source."""
    def inverse(scale: LinearScale, key: str) -> dict[str, Any]:
        # The simulated sensor's output is the inverse of the config's scale (in its unit).
        return {"gain": scale.gain, "offset": scale.offset, key: UNITS[scale.units][1]}

    where = f"{source} [{inst.role}] {inst.name!r}"
    if inst.driver == "ni_daqmx_laser":
        s = NiLaserSettings.from_table(inst.settings, where)
        return {s.channel: {"kind": "laser", "x": s.x, "z": s.z, "axis": s.axis,
                            "standoff_mm": s.standoff_mm, **inverse(s.scale, "unit_m")}}
    a = NiAnalogSettings.from_table(inst.settings, where)
    out: dict[str, dict[str, Any]] = {}
    for c in a.channels:
        if c.name == "pitot":
            out[c.channel] = {"kind": "pitot", **inverse(c.scale, "unit_pa")}
        else:  # a balance or another transducer: the simulated tunnel gives it nothing, 0 V
            out[c.channel] = {"kind": "constant", "volts": 0.0}
    return out


def _start_ni_devices(config: RigConfig, tunnel: VirtualTunnel,
                      ) -> dict[str, tuple[SimNiDaqmx, str]]:
    """Start one simulated DAQ device per NI device name; return device -> (simulator, address)."""
    sim = config.simulation
    assert sim is not None
    wiring: dict[str, dict[str, dict[str, Any]]] = {}
    options: dict[str, Mapping[str, Any]] = {}
    for inst in config.instruments:
        if inst.driver not in NI_DRIVERS:
            continue
        device = TaskAddress.parse(inst.url).device
        sources = _ni_source(inst, config.source)
        taken = sorted(set(sources) & set(wiring.get(device, {})))
        if taken:
            raise ConfigError(f"{config.source}: {device} input(s) {taken} wired to two "
                              f"instruments (the second is {inst.name!r})")
        wiring.setdefault(device, {}).update(sources)
        options.setdefault(device, sim.devices.get(inst.name, {}))
    started: dict[str, tuple[SimNiDaqmx, str]] = {}
    try:
        for index, (device, channels) in enumerate(wiring.items()):
            opts = dict(options[device])
            where = f"{config.source} [simulation.devices] ({device})"
            unknown = sorted(set(opts) - _COMMON_KEYS - {"noise_v", "pulse_width_s"})
            if unknown:
                raise ConfigError(f"{where}: unknown key(s) {unknown}; allowed: "
                                  f"{sorted(_COMMON_KEYS | {'noise_v', 'pulse_width_s'})}")
            clock = DeviceClock(offset_s=float(opts.pop("clock_offset_s", 0.0)),
                                drift_ppm=float(opts.pop("clock_drift_ppm", 0.0)))
            seed = opts.pop("seed", None)
            rng = np.random.default_rng([int(seed), 100 + index]) if seed is not None else \
                100 + index
            daq = SimNiDaqmx(tunnel, device=device, channels=channels, clock=clock, rng=rng,
                             **opts)
            started[device] = (daq, daq.start())
    except BaseException:
        for daq, _ in started.values():
            daq.stop()
        raise
    return started


def _sensor_errors(config: RigConfig, inst: InstrumentConfig) -> dict[str, Any]:
    """Return the simulator options that make a sensor need the config's calibration of it."""
    cal = config.calibration
    if inst.role == "scanner":
        p = cal.pitot
        pitot = (p.factor, p.offset_pa, p.fan_rpm) if p.fan_rpm else (p.factor[0], p.offset_pa)
        return {"tap_channels": cal.tap_channels(config.taps.n_taps), "pitot_error": pitot}
    if inst.role == "lasers" and inst.name in cal.lasers:
        laser = cal.lasers[inst.name]
        return {"reading_error": (laser.gain, 1e3 * laser.offset_m,
                                  math.degrees(laser.angle_rad))}
    return {}


def _refuse_exposed(inst: InstrumentConfig, url: str, settings: Mapping[str, Any],
                    source: str) -> None:
    """Refuse a started simulator that can be reached from outside this host.

    Two checks, for a URL with a network host (``tcp://``, ``socket://``, ``modbus+tcp://``;
    a pty's ``serial://`` has none): the host must be a loopback address, and neither the URL's
    port nor a ``*_port`` of the driver's settings (the scanner's ``data_port``) may accept a
    connection on this host's own outward address, which a listener bound to ``0.0.0.0`` does
    whatever URL it returns. The probe connects to that address only: a simulator bound to
    127.0.0.1 refuses it at once and never sees it. A host without an outward address exposes
    nothing, so there is nothing to probe.

    Raises
    ------
    PluginError
        The simulator is exposed (the caller stops every simulator started).
    """
    parts = urllib.parse.urlsplit(url)
    if parts.hostname is None:
        return
    what = (f"{source}: the simulator of instrument {inst.name!r} (driver {inst.driver!r}) "
            f"serves {url}")
    rule = ("simulators bind to loopback only, so that a simulated instrument (a release PLC, a "
            "fan drive) cannot be reached from the lab's network: bind ('127.0.0.1', port) and "
            "return that URL")
    if not _is_loopback(parts.hostname):
        raise PluginError(f"{what}, not a loopback address: {rule}")
    outward = _outward_address()
    if outward is None:
        return
    ports = [parts.port] + [v for k, v in settings.items()
                            if k.endswith("_port") and isinstance(v, int)]
    for port in ports:
        if port is not None and _accepts(outward, port):
            raise PluginError(f"{what}, but its port {port} also accepts connections on this "
                              f"host's address {outward} (bound to every interface): {rule}")


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:  # a host name: not loopback unless it is "localhost"
        return False


def _outward_address() -> str | None:
    """Return this host's address towards other hosts (None: it has none but loopback).

    A UDP socket "connected" to a documentation address (RFC 5737) takes the address the
    routing table would send from; no packet is sent.
    """
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect(("192.0.2.1", 9))
        except OSError:  # no route at all: only loopback
            return None
        address = str(probe.getsockname()[0])
    return None if ipaddress.ip_address(address).is_loopback else address


def _accepts(address: str, port: int) -> bool:
    """Tell whether ``address:port`` accepts a TCP connection (closed again at once)."""
    try:
        with socket.create_connection((address, port), timeout=0.5):
            return True
    except OSError:  # refused (or no answer): not listening there
        return False


def _build(inst: InstrumentConfig, tunnel: VirtualTunnel, options: Mapping[str, Any],
           index: int, source: str, errors: Mapping[str, Any]) -> Any:
    entry = simulator_entry(inst.driver, source)
    factory = entry.factory
    where = f"{source} [simulation.devices.{inst.name}]"
    accepted = entry.accepted_options()
    unknown = sorted(set(options) - _COMMON_KEYS - accepted)
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {unknown}; allowed: "
                          f"{sorted(_COMMON_KEYS | accepted)}")
    kwargs = {k: v for k, v in options.items() if k not in _COMMON_KEYS}
    kwargs["clock"] = DeviceClock(offset_s=float(options.get("clock_offset_s", 0.0)),
                                  drift_ppm=float(options.get("clock_drift_ppm", 0.0)))
    if "seed" in options:
        # With the instrument's place: one seed given to every instrument (a benchmark's
        # "seed 3") still gives each its own noise; keyed noise (simulators.noise) from equal
        # seeds would be the same on every laser, and cancel in the pitch.
        kwargs["rng"] = np.random.default_rng([int(options["seed"]), index])
    else:
        kwargs["rng"] = index
    kwargs.update(errors)
    try:
        return factory(tunnel, inst.settings, **kwargs)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{where}: {exc}") from exc
