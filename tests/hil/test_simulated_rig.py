"""A whole simulated rig from one call: every driver reaches its simulator, one shared tunnel.

Drivers are built from the rig config and all of them see one consistent virtual tunnel.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from daq.config import load_rig_config, parse_rig_config
from daq.errors import ConfigError, SafetyError
from daq.instruments.build import build_driver
from daq.sim.rig import start_simulated_rig

from support.configs import CONFIGS, FAST_FAN, SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime


@pytest.mark.parametrize("name", ["sim_flat_plate.toml", "sim_streamlined_deck.toml"])
def test_every_driver_reaches_its_simulator_and_the_physics_is_shared(name):
    """Fan -> wind at the Pitot; PLC release -> lasers see the decay; barometer -> tunnel air."""
    # A fast fan ramp (a simulator option) keeps the test short.
    text = (CONFIGS / name).read_text() + FAST_FAN
    config = parse_rig_config(text, name)
    with start_simulated_rig(config) as rig:
        assert all(url.startswith(("tcp://127.0.0.1", "socket://127.0.0.1",
                                   "modbus+tcp://127.0.0.1")) for url in rig.urls.values())
        drivers = {inst.name: build_driver(inst, rig.config.limits)
                   for inst in rig.config.instruments}
        for driver in drivers.values():
            driver.open()
        try:
            baro = drivers["barometer"].read()
            # The simulator adds ~2 Pa noise and slow drift to the tunnel's air: 0.1 % is ample.
            assert baro.channels["density"][0] == pytest.approx(rig.tunnel.air.density, rel=1e-3)

            scanner = drivers["scanner"]
            scanner.configure()
            scanner.calz(wind_speed_now=0.0)  # zero the sensors wind-off, as operators must

            fan = drivers["fan"]
            with pytest.raises(SafetyError):
                fan.set_speed(rig.config.limits.max_fan_rpm + 1.0)
            fan.set_speed(800.0)
            fan.start()
            deadline = time.monotonic() + 10.0
            # The reference is quantised to max_rpm / 20000 (<= 0.1 rpm here): wait until the
            # ramp has ended within two counts of 800 rpm, then the wind is 8 m/s within 0.03 %.
            while abs(rig.tunnel.fan_rpm - 800.0) > 0.2 and time.monotonic() < deadline:
                time.sleep(0.02)
            assert rig.tunnel.wind_speed() == pytest.approx(800.0 * config.wind_per_rpm, rel=3e-4)

            scanner.scan()
            pitot: list[float] = []
            while len(pitot) < 100:  # 0.2 s at 500 Hz
                pitot.extend(scanner.read(timeout_s=2.0).channels["pitot"])
            scanner.stop()
            qd = 0.5 * rig.tunnel.air.density * rig.tunnel.wind_speed() ** 2
            # Pitot after a wind-off zero: qd (~38 Pa) plus 1 Pa frame noise, median of many
            # frames: within 3 Pa (the zero itself averages the same noise).
            assert np.nanmedian(pitot) == pytest.approx(qd, abs=3.0)

            plc = drivers["plc"]
            plc.arm()
            plc.release()
            assert rig.tunnel.release_times()  # the tunnel was released through Modbus
            laser = drivers["laser_front"]
            distance: list[float] = []
            deadline = time.monotonic() + 5.0
            # The stream is buffered since the simulators started: read through the held part
            # until the released model's motion shows (millimetres: released from 4-6 mm).
            while time.monotonic() < deadline and (not distance or np.ptp(distance) < 1e-3):
                distance.extend(laser.read(timeout_s=2.0).channels["distance"])
            assert np.isfinite(distance).mean() > 0.99
            assert np.ptp(distance) > 1e-3
        finally:
            for driver in drivers.values():
                driver.close()


def test_auto_urls_need_the_simulators():
    """A simulated rig's "auto" URL cannot be opened without starting the simulators."""
    config = load_rig_config(SIM_FLAT_PLATE)
    with pytest.raises(ConfigError, match="url = 'auto'"):
        build_driver(config.instrument("barometer"), config.limits)


TURBULENCE = """
[simulation.static]
C_D = 0.02
C_L = 0.0
C_M = 0.0
dC_D = 0.0
dC_L = -6.283
dC_M = 1.571

[simulation.turbulence]
Iu = 0.0
Iw = 0.05
Lux = 1.0
Lwx = 0.3
span = 1.0
seed = 1

[simulation.devices.fan]
ramp_rpm_per_s = 4000.0
"""


def _held_lift(config_text: str) -> tuple[np.ndarray, float, object]:
    """Lift integrated from 2 s of scanner frames over TCP, the model held at 8 m/s."""
    config = parse_rig_config(config_text, "turbulent.toml")
    with start_simulated_rig(config) as rig:
        scanner = build_driver(rig.config.instrument("scanner"), rig.config.limits)
        fan = build_driver(rig.config.instrument("fan"), rig.config.limits)
        scanner.open()
        fan.open()
        try:
            scanner.configure()
            scanner.calz(wind_speed_now=0.0)
            fan.set_speed(800.0)
            fan.start()
            deadline = time.monotonic() + 10.0
            while abs(rig.tunnel.fan_rpm - 800.0) > 0.2 and time.monotonic() < deadline:
                time.sleep(0.02)
            scanner.scan()
            frames = []
            while sum(len(b.counter) for b in frames) < 1000:  # 2 s at 500 Hz
                frames.append(scanner.read_block(timeout_s=2.0))
            scanner.stop()
        finally:
            scanner.close()
            fan.close()
        pressure = np.vstack([b.pressure for b in frames])[:, :config.taps.n_taps]
        lift, _ = config.taps.integrate(pressure)
        return lift, rig.tunnel.wind_speed(), config


def test_a_turbulent_virtual_tunnel_buffets_the_held_model_as_the_taps_see_it():
    """A turbulent virtual tunnel buffets the held model, and the taps show it over TCP.

    With [simulation.turbulence] the held model's lift, integrated from the scanner's taps,
    fluctuates with the quasi-steady buffeting's standard deviation; in smooth flow it does not.

    Theory: the std of ``L_b = qd B (dC_L - C_D) w_eff / U``, the effective gusts' spectrum
    integrated to the scanner's Nyquist rate. 2 s of 1 m of gust field at 8 m/s hold about 50
    correlation lengths (0.3 m), so the sample std scatters by ~10 %; 35 % is 3.5 of that.
    """
    from ident.model.quasi_steady import StaticCoefficients
    from ident.physics.turbulence import TurbulenceSpec

    text = SIM_FLAT_PLATE.read_text()
    lift, U, config = _held_lift(text + TURBULENCE)
    spec = TurbulenceSpec(Iu=0.0, Iw=0.05, Lux=1.0, Lwx=0.3, Cuy=10.0, Cwy=8.0)
    static = StaticCoefficients(C_D=0.02, C_L=0.0, C_M=0.0, dC_D=0.0, dC_L=-6.283, dC_M=1.571)
    f = np.linspace(0.01, 250.0, 25000)
    _, G_w = spec.effective_spectra(f, U, config.section.B, 1.0)
    rho = config.simulation.pressure_pa / (287.058 * (config.simulation.temperature_c + 273.15))
    qd = 0.5 * rho * U**2
    gain = qd * config.section.B * (static.dC_L - static.C_D) / U
    expected = abs(gain) * np.sqrt(np.trapezoid(G_w, f))
    assert np.std(lift) == pytest.approx(expected, rel=0.35)
    smooth, _, _ = _held_lift(text + FAST_FAN)
    assert np.std(smooth) < 0.2 * expected  # frame noise only
