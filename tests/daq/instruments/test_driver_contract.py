"""Contract tests over every built-in driver, with the driver author's kit (:mod:`daq.testing`).

The kit's checks, as a plugin's tests run them: construction does no I/O, unknown keywords are
refused, the role's methods and channels (units, dtypes, ranks) are there
(:func:`~daq.testing.contract.construction_problems`), and what ``read()`` returns against the
simulated instruments over their real transports (TCP, serial-over-socket, Modbus TCP) is a
``Reading`` as described, with every counter jump a reported gap
(:func:`~daq.testing.contract.reading_problems`, :func:`~daq.testing.contract.sequence_problems`).
Here besides: property docstrings follow the Measure/Control rule (pymeasure's
test_all_instruments pattern).
"""

from __future__ import annotations

import inspect
from collections.abc import Iterator
from unittest.mock import MagicMock

import numpy as np
import pytest

from daq.config import load_rig_config
from daq.instruments import registry
from daq.instruments.build import build_driver
from daq.instruments.reading import Reading, describe_mismatches
from daq.sim.rig import SimulatedRig, start_simulated_rig
from daq.testing.contract import construction_problems, reading_problems, sequence_problems

from support.configs import CONFIGS, SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

CONFIG = load_rig_config(SIM_FLAT_PLATE)
INSTRUMENTS = {inst.driver: inst for inst in CONFIG.instruments}


def make(driver: str, link: object, **extra: object) -> object:
    entry = registry.driver_entry(driver)
    inst = INSTRUMENTS[driver]
    settings = entry.validate(inst.settings, driver)
    if entry.role == "fan":
        extra.setdefault("limit_rpm", CONFIG.limits.max_fan_rpm)
    return entry.factory(link, settings, **extra)


def driver_class(driver: str) -> type:
    obj = make(driver, MagicMock())
    return type(obj)


@pytest.mark.parametrize("driver", sorted(INSTRUMENTS))
def test_construction_does_no_io(driver):
    """Building a driver never touches its transport (open() is where I/O starts)."""
    link = MagicMock()
    make(driver, link)
    assert link.method_calls == [] and link.mock_calls == []


@pytest.mark.parametrize("driver", sorted(INSTRUMENTS))
def test_unknown_keyword_is_refused(driver):
    """A misspelt option is a TypeError, never silently ignored."""
    cls = driver_class(driver)
    entry = registry.driver_entry(driver)
    settings = entry.validate(INSTRUMENTS[driver].settings, driver)
    extra = {"limit_rpm": 100.0} if entry.role == "fan" else {}
    with pytest.raises(TypeError):
        cls(MagicMock(), settings, no_such_option=1, **extra)


@pytest.mark.parametrize("driver", sorted(INSTRUMENTS))
def test_the_kit_finds_no_breach_of_the_role_contract(driver):
    """The kit's construction checks: no I/O, TypeError, role methods and channels."""
    entry = registry.driver_entry(driver)
    extra = {"limit_rpm": CONFIG.limits.max_fan_rpm} if entry.role == "fan" else {}
    assert construction_problems(entry, INSTRUMENTS[driver].settings, **extra) == []


@pytest.mark.parametrize("driver", sorted(INSTRUMENTS))
def test_describe_names_channels_with_units(driver):
    """Every described channel has units (read keys are checked in each driver's own tests)."""
    described = make(driver, MagicMock()).describe()  # type: ignore[attr-defined]
    assert described
    for channel, info in described.items():
        assert isinstance(channel, str) and "units" in info, (channel, info)


@pytest.mark.parametrize("driver", sorted(INSTRUMENTS))
def test_property_docstrings_follow_the_measure_control_rule(driver):
    """Read-only properties start with "Measure", settable ones with "Control"."""
    cls = driver_class(driver)
    for name, prop in inspect.getmembers(cls, lambda m: isinstance(m, property)):
        doc = (prop.__doc__ or "").strip()
        verb = "Control" if prop.fset is not None else "Measure"
        assert doc.startswith(verb), f"{cls.__name__}.{name}: {doc!r} should start with {verb}"


def test_every_role_of_the_design_has_a_registered_driver():
    """Scanner, lasers, fan, PLC and barometer: the five of docs/reference/wire_formats.md."""
    roles = {registry.driver_entry(d).role for d in INSTRUMENTS}
    assert roles == {"scanner", "lasers", "fan", "plc", "barometer"}


# -- the reading contract, against the simulated instruments ----------------------------------
@pytest.fixture(scope="module", params=["sim_flat_plate.toml", "sim_streamlined_deck.toml"])
def rig(request: pytest.FixtureRequest) -> Iterator[SimulatedRig]:
    """Start a simulated rig (every instrument on its loopback transport) for the module."""
    with start_simulated_rig(load_rig_config(CONFIGS / request.param)) as running:
        yield running


def read_twice(rig: SimulatedRig, driver_name: str) -> tuple[dict, Reading, Reading]:
    """Open the rig's driver of that name, start its data, and read two readings."""
    inst = next(i for i in rig.config.instruments if i.driver == driver_name)
    driver = build_driver(inst, rig.config.limits)
    driver.open()
    try:
        if registry.driver_entry(driver_name).role == "scanner":
            driver.start()  # configure and scan: the engine's begin
            try:
                return driver.describe(), driver.read(timeout_s=2.0), driver.read(timeout_s=2.0)
            finally:
                driver.stop()
        if registry.driver_entry(driver_name).role == "lasers":
            return driver.describe(), driver.read(timeout_s=2.0), driver.read(timeout_s=2.0)
        return driver.describe(), driver.read(), driver.read()
    finally:
        driver.close()


@pytest.mark.parametrize("driver", sorted(INSTRUMENTS))
def test_read_returns_a_reading_that_matches_describe(rig, driver):
    """Both readings: described channels only, each (n, *shape) of its dtype; counters go on."""
    described, first, second = read_twice(rig, driver)
    role = registry.driver_entry(driver).role
    for reading in (first, second):
        assert isinstance(reading, Reading) and len(reading) >= 1
        assert describe_mismatches(described, reading) == [], (driver, reading.channels.keys())
        assert reading_problems(described, reading, role) == []  # counters, times, gaps
    assert sequence_problems([first, second]) == []
    # The second reading continues the first: its counter after the first's, no rows missing
    # on an undisturbed simulator, its rows arrived later.
    assert int(second.counter[0]) == int(first.counter[-1]) + 1 and second.gaps == ()
    assert int(second.host_time_ns[-1]) >= int(first.host_time_ns[-1])
    clocked = registry.driver_entry(driver).role in ("scanner", "lasers")
    assert (first.device_time is not None) == clocked


def test_the_scanner_reading_is_as_wide_as_its_modules(rig):
    """The described shapes follow the config: 64 pressures, 8 temperatures per module."""
    described, reading, _ = read_twice(rig, "scanivalve_mps4264")
    modules = next(i for i in rig.config.instruments if i.role == "scanner").settings["modules"]
    assert reading.channels["pressure"].shape[1] == described["pressure"]["shape"][0] \
        == 64 * modules
    assert reading.channels["module_status"].shape[1] == modules


def test_describe_mismatches_names_every_difference():
    """The check itself can fail: a wrong dtype, a wrong shape, a missing and an extra channel."""
    described = {"x": {"units": "m", "dtype": "float64", "shape": ()},
                 "y": {"units": "Pa", "dtype": "float64", "shape": (3,)},
                 "z": {"units": "1", "dtype": "int8", "shape": ()}}
    reading = Reading(channels={"x": np.zeros(2, np.float32), "y": np.zeros((2, 4)),
                                "w": np.zeros(2)},
                      host_time_ns=np.zeros(2, np.int64), counter=np.arange(2))
    problems = describe_mismatches(described, reading)
    assert len(problems) == 3
    assert any("x: dtype float32" in p for p in problems)
    assert any("y: shape (2, 4)" in p for p in problems)
    assert any("'w'" in p and "'z'" in p for p in problems)
