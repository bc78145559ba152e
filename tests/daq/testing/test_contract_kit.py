"""The driver author's kit fails a driver that breaks the contract, and passes one that keeps it.

The drivers are the PTB330 barometer driver against its simulator over a real loopback
transport, and subclasses of it that break one rule each: a missing channel, a wrong dtype, a
gap not reported, settings kept where the engine does not look for the poll period.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

import numpy as np
import pytest

from daq.config import InstrumentConfig, load_rig_config
from daq.errors import ConfigError, PluginError
from daq.instruments import registry
from daq.instruments.build import build_driver
from daq.instruments.reading import Reading
from daq.instruments.vaisala_ptb330.driver import VaisalaPtb330
from daq.sim.rig import start_simulated_rig
from daq.testing.contract import (
    check_driver,
    construction_problems,
    reading_problems,
    sequence_problems,
)
from daq.transports.byte_transport import open_transport

from support.configs import SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

CONFIG = SIM_FLAT_PLATE
ENTRY = registry.driver_entry("vaisala_ptb330")


class MissingDensity(VaisalaPtb330):
    """Delivers no ``density`` (nor describes it)."""

    def describe(self):
        return {k: v for k, v in super().describe().items() if k != "density"}

    def read(self):
        r = super().read()
        return dataclasses.replace(r, channels={k: v for k, v in r.channels.items()
                                                if k != "density"})


class Float32Pressure(VaisalaPtb330):
    """Describes float64 but delivers float32 pressures."""

    def read(self):
        r = super().read()
        return dataclasses.replace(r, channels={**r.channels,
                                                "pressure": r.channels["pressure"].astype("f4")})


class SilentGap(VaisalaPtb330):
    """Skips every other poll number without reporting the gap."""

    def read(self):
        r = super().read()
        return dataclasses.replace(r, counter=r.counter * 2, gaps=())


class SettingsElsewhere(VaisalaPtb330):
    """Keeps its validated settings as ``config``: the engine would not see poll_interval_s."""

    def __init__(self, transport, settings):
        super().__init__(transport, settings)
        self.config = self.__dict__.pop("settings")


@pytest.fixture(scope="module")
def barometer() -> Iterator[tuple[dict, str]]:
    with start_simulated_rig(load_rig_config(CONFIG)) as rig:
        inst = rig.config.instrument("barometer")
        yield dict(inst.settings), inst.url


def entry_of(cls: type) -> object:
    return dataclasses.replace(ENTRY, factory=cls)


def test_a_driver_that_keeps_the_contract_passes(barometer):
    settings, url = barometer
    readings = check_driver(ENTRY, settings, open_transport(url), n=3)
    assert len(readings) == 3


@pytest.mark.parametrize("cls, expected", [
    (MissingDensity, "missing channel 'density' of the barometer role"),
    (Float32Pressure, "pressure: dtype float32 != described float64"),
    (SilentGap, "1 row(s) missing after counter 2 but 0 reported as a gap"),
])
def test_a_driver_that_breaks_the_contract_fails(barometer, cls, expected):
    settings, url = barometer
    with pytest.raises(AssertionError) as info:
        check_driver(entry_of(cls), settings, open_transport(url), n=3)
    assert expected in str(info.value)


def test_construction_problems_name_a_missing_role_channel():
    problems = construction_problems(entry_of(MissingDensity), {})
    assert problems == ["missing channel 'density' of the barometer role"]


def test_reading_and_sequence_checks_can_fail():
    described = {"pressure": {"units": "Pa", "dtype": "float64", "shape": ()}}
    inside = Reading(channels={"pressure": np.zeros(3)}, host_time_ns=np.arange(3),
                     counter=np.array([1, 2, 5]))
    assert reading_problems(described, inside, "barometer")[-1] == \
        "2 row(s) missing after counter 2 but 0 reported as a gap"
    later = Reading(channels={"pressure": np.zeros(1)}, host_time_ns=np.arange(1),
                    counter=np.array([4]))
    assert sequence_problems([inside, later]) == ["counter goes back: 4 after 5"]


def test_hardware_tests_skip_without_a_device_url(pytester):
    pytester.makepyfile("def test_device(windrig_device_url):\n    assert windrig_device_url\n")
    pytester.runpytest("-p", "no:cacheprovider").assert_outcomes(skipped=1)
    result = pytester.runpytest("-p", "no:cacheprovider", "--windrig-device-url",
                                "tcp://127.0.0.1:23")
    result.assert_outcomes(passed=1)


def test_a_polled_driver_without_its_settings_attribute_is_caught_by_the_kit():
    problems = construction_problems(entry_of(SettingsElsewhere), {"poll_interval_s": 5.0})
    assert len(problems) == 1
    assert "poll_interval_s = 5.0" in problems[0] and "`self.settings`" in problems[0]
    assert construction_problems(ENTRY, {"poll_interval_s": 5.0}) == []


def test_building_a_polled_driver_without_its_settings_attribute_is_refused():
    """Not polled every 1 s without a word: build_driver says which driver and why."""
    entry = dataclasses.replace(entry_of(SettingsElsewhere), name="test_settings_elsewhere")
    registry.register(entry)
    try:
        inst = InstrumentConfig(role="barometer", name="barometer",
                                driver="test_settings_elsewhere", url="socket://127.0.0.1:9",
                                settings={"poll_interval_s": 5.0})
        with pytest.raises(PluginError, match=r"driver 'test_settings_elsewhere' of instrument "
                           r"'barometer': its settings set poll_interval_s = 5\.0"):
            build_driver(inst, load_rig_config(CONFIG).limits)
        ok = dataclasses.replace(inst, driver="vaisala_ptb330")
        assert build_driver(ok, load_rig_config(CONFIG).limits).settings.poll_interval_s == 5.0
    finally:
        registry.unregister("test_settings_elsewhere")


def test_a_misspelt_transport_default_is_a_config_error_on_every_scheme():
    """Refused on the simulator's socket:// too, not only on the real serial port."""
    for url in ("socket://127.0.0.1:9", "serial:///dev/ttyUSB0"):
        with pytest.raises(ConfigError, match=r"unknown line setting\(s\) \['baud'\]"):
            open_transport(url, baud=9600)
