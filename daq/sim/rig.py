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

Per-instrument simulation settings come from ``[simulation.devices.<name>]``: ``clock_offset_s``,
``clock_drift_ppm`` and ``seed`` (with the instrument's place in the config: equal seeds give
different instruments different noise) for every device, and any further keyword the device's
simulator accepts (noise levels, fault options); an unknown one is a ConfigError naming it.
"""

from __future__ import annotations

import dataclasses
import inspect
import logging
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from daq.config import InstrumentConfig, RigConfig
from daq.errors import ConfigError
from daq.sim.devices import simulator_entry
from ident.physics.tubing import Air, tubing_set
from simulators.clock import Clock, DeviceClock
from simulators.virtual_tunnel import AirState, VirtualTunnel

__all__ = ["SimulatedRig", "start_simulated_rig"]

log = logging.getLogger(__name__)

_COMMON_KEYS = {"clock_offset_s", "clock_drift_ppm", "seed"}


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
        for index, inst in enumerate(config.instruments):
            simulator = _build(inst, tunnel, sim.devices.get(inst.name, {}), index, config.source,
                               _sensor_errors(config, inst))
            rig.simulators[inst.name] = simulator
            start = simulator.start
            url = start(serial) if "transport" in inspect.signature(start).parameters else start()
            rig.urls[inst.name] = url
            settings = dict(simulator_entry(inst.driver, config.source).settings(
                inst.settings, simulator))
            resolved.append(dataclasses.replace(inst, url=url, settings=settings))
    except BaseException:
        rig.close()
        raise
    rig.config = dataclasses.replace(config, instruments=tuple(resolved))
    return rig


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
