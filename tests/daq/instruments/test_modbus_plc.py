"""The PLC driver: settings, and the coil / input / register sequences of arm, release, trigger.

Signals from docs/reference/wire_formats.md, "PLC": coil RELEASE (FC05), discrete
input RELEASED (FC02), coil DAQ_TRIGGER (FC05), holding register TRIGGER_COUNT (FC03); the ARM
coil and the edge semantics are windrig's [design] (daq/instruments/modbus_plc/driver.py docstring).
"""

from __future__ import annotations

from unittest.mock import MagicMock

import pytest

from daq.errors import ConfigError, DeviceError, SafetyError, TransportError
from daq.instruments.modbus_plc.driver import ModbusPlc
from daq.instruments.modbus_plc.settings import ModbusPlcSettings
from daq.instruments.registry import driver_entry
from daq.transports.scripted import ScriptedBus, expected_bus_calls

TABLE = {
    "coils": {"release": 16, "arm": 17, "trigger": 18},
    "discrete_inputs": {"released": 3},
    "holding_registers": {"trigger_count": 100},
    "release_timeout_s": 0.05,
}
SETTINGS = ModbusPlcSettings.from_table(TABLE)
RELEASE, ARM, TRIGGER, RELEASED, COUNT = 16, 17, 18, 3, 100


def test_settings_defaults_and_registry():
    settings = ModbusPlcSettings.from_table({k: v for k, v in TABLE.items()
                                             if k != "release_timeout_s"})
    assert settings.release_timeout_s == 0.5 and settings.trigger_pulse_s == 0.01
    entry = driver_entry("modbus_plc")
    assert entry.role == "plc" and entry.validate(TABLE, "[plc]") == SETTINGS


@pytest.mark.parametrize(("change", "message"), [
    ({"release_timeout_s": 0}, r"\[plc\] release_timeout_s = 0.0 is outside the allowed range "
                               r"\(0.0, 10.0\]"),
    ({"trigger_pulse_s": 2.0}, r"trigger_pulse_s = 2.0 is outside the allowed range \(0.0, 1.0\]"),
    ({"coils": {"release": 0, "arm": 1}}, r"coils: missing required key\(s\) \['trigger'\]"),
    ({"coils": {"release": 0, "arm": 1, "trigger": 2, "lamp": 3}}, r"unknown key\(s\) \['lamp'\]"),
    ({"coils": {"release": 0, "arm": 0, "trigger": 2}}, "addresses must be distinct"),
    ({"discrete_inputs": {"released": -1}},
     r"discrete_inputs.released = -1 must be an integer address in \[0, 65535\]"),
    ({"holding_registers": {"trigger_count": True}}, "trigger_count = True must be an integer"),
    ({"input_registers": {}}, r"unknown key\(s\) \['input_registers'\]"),
])
def test_bad_settings_name_key_and_range(change, message):
    with pytest.raises(ConfigError, match=message):
        ModbusPlcSettings.from_table({**TABLE, **change}, "[plc]")


def test_constructor_does_no_io_and_rejects_unknown_keywords():
    bus = MagicMock()
    plc = ModbusPlc(bus, TABLE)
    assert plc.settings == SETTINGS and bus.method_calls == []
    with pytest.raises(TypeError):
        ModbusPlc(bus, SETTINGS, timeout=1)  # type: ignore[call-arg]
    assert set(plc.describe()) == {"armed", "released", "trigger_count"}


def test_release_when_armed_waits_for_released_and_returns_the_coil_to_zero():
    with expected_bus_calls([
        ("read_coils", ARM, 1, [True]),
        ("write_coil", RELEASE, True, None),
        ("read_discrete_inputs", RELEASED, 1, [False]),  # the armature is still moving
        ("read_discrete_inputs", RELEASED, 1, [True]),
        ("write_coil", RELEASE, False, None),
    ]) as bus:
        timing = ModbusPlc(bus, SETTINGS).release()
    assert timing.confirmed_ns >= timing.command_ns and timing.delay_s >= 0.0


def test_release_refused_when_not_armed_writes_nothing():
    with expected_bus_calls([("read_coils", ARM, 1, [False])]) as bus:
        with pytest.raises(SafetyError, match="not armed"):
            ModbusPlc(bus, SETTINGS).release()


def test_release_that_never_comes_names_released_and_resets_the_coil():
    script = [("read_coils", ARM, 1, [True]), ("write_coil", RELEASE, True, None)]
    script += [("read_discrete_inputs", RELEASED, 1, [False])] * 1000
    bus = ScriptedBus(script)
    bus.open()
    plc = ModbusPlc(bus, SETTINGS)
    # The trailing RELEASE 0 write is not in the script: catch it to prove it is attempted.
    with pytest.raises(AssertionError, match=r"got \('write_coil', 16, False\)") as info:
        plc.release()
    cause = info.value.__context__
    assert isinstance(cause, DeviceError)
    assert "RELEASED (discrete input 3) not set within 0.05 s" in str(cause)


def test_arm_clears_release_sets_arm_and_waits_for_the_armature():
    with expected_bus_calls([
        ("write_coil", RELEASE, False, None),
        ("write_coil", ARM, True, None),
        ("read_discrete_inputs", RELEASED, 1, [True]),
        ("read_discrete_inputs", RELEASED, 1, [False]),
        ("write_coil", ARM, False, None),  # disarm
    ]) as bus:
        plc = ModbusPlc(bus, SETTINGS)
        plc.arm()
        plc.disarm()
    script = [("write_coil", RELEASE, False, None), ("write_coil", ARM, True, None)]
    bus = ScriptedBus(script + [("read_discrete_inputs", RELEASED, 1, [True])] * 1000)
    bus.open()
    with pytest.raises(DeviceError, match="still set 0.01 s after ARM"):
        ModbusPlc(bus, SETTINGS).arm(timeout_s=0.01)


def test_trigger_pulses_make_edges_and_the_count_is_read():
    with expected_bus_calls([
        ("write_coil", TRIGGER, False, None),  # first pulse: make sure 1 is an edge
        ("write_coil", TRIGGER, True, None),
        ("write_coil", TRIGGER, False, None),
        ("write_coil", TRIGGER, True, None),   # known low now: no extra write
        ("write_coil", TRIGGER, False, None),
        ("read_holding_registers", COUNT, 1, [2]),
        ("read_coils", ARM, 1, [True]),
        ("read_discrete_inputs", RELEASED, 1, [False]),
        ("read_holding_registers", COUNT, 1, [2]),
    ]) as bus:
        plc = ModbusPlc(bus, SETTINGS)
        plc.trigger_pulse(0.001)
        plc.trigger_pulse(0.001)
        assert plc.trigger_count() == 2
        reading = plc.read()
    assert {k: v.tolist() for k, v in reading.channels.items()} == {
        "armed": [True], "released": [False], "trigger_count": [2]}
    assert list(reading.counter) == [1] and reading.gaps == ()
    with pytest.raises(ValueError, match="width_s"):
        plc.trigger_pulse(0.0)


def test_a_pulse_whose_end_failed_starts_the_next_from_zero():
    with expected_bus_calls([
        ("write_coil", TRIGGER, False, None),
        ("write_coil", TRIGGER, True, None),
        ("write_coil", TRIGGER, False, TransportError("reset")),  # the end of pulse is lost
        ("write_coil", TRIGGER, False, None),                     # next pulse: 0 first
        ("write_coil", TRIGGER, True, None),
        ("write_coil", TRIGGER, False, None),
    ]) as bus:
        plc = ModbusPlc(bus, SETTINGS)
        with pytest.raises(TransportError):
            plc.trigger_pulse(0.001)
        plc.trigger_pulse(0.001)
