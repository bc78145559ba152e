"""The driver author's kit fails a driver that breaks the contract, and passes one that keeps it.

The drivers are the PTB330 barometer driver against its simulator over a real loopback
transport, and subclasses of it that break one rule each: a missing channel, a wrong dtype, a
gap not reported.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

import numpy as np
import pytest

from daq.config import load_rig_config
from daq.instruments import registry
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
