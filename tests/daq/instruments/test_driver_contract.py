"""Contract tests over every registered driver (pymeasure's test_all_instruments pattern).

Construction does no I/O, unknown keywords are refused, every described channel has units, and
property docstrings follow the Measure/Control rule.
"""

from __future__ import annotations

import inspect
from pathlib import Path
from unittest.mock import MagicMock

import pytest

from daq.config import load_rig_config
from daq.instruments import registry

CONFIG = load_rig_config(Path(__file__).resolve().parents[3] / "rig_configs" /
                         "sim_flat_plate.toml")
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
    """Scanner, lasers, fan, PLC and barometer: all five instruments of docs/wire_formats.md."""
    roles = {registry.driver_entry(d).role for d in INSTRUMENTS}
    assert roles == {"scanner", "lasers", "fan", "plc", "barometer"}
