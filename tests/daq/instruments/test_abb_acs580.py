"""The ABB drive driver: settings, scaling, the CW sequences and SW decoding, register by register.

Register words from docs/reference/wire_formats.md, "Fan drive" (CW 0x0476 / 0x047F / 0x0000, REF1
0..20000 = max speed) and the
ABB Drives profile Status word table (FDNA-01 manual p.91: bit 0 RDY_ON, 1 RDY_RUN, 2 RDY_REF,
3 TRIPPED, 4 OFF_2_STA, 5 OFF_3_STA, 6 SWC_ON_INHIB, 8 AT_SETPOINT, 9 REMOTE).
"""

from __future__ import annotations

import math
from unittest.mock import MagicMock

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from daq.config import parse_rig_config
from daq.errors import ConfigError, DeviceError, SafetyError
from daq.instruments.abb_acs580.driver import AbbAcs580
from daq.instruments.abb_acs580.profile import DriveStatus
from daq.instruments.abb_acs580.settings import AbbAcs580Settings
from daq.instruments.registry import driver_entry
from daq.transports.scripted import ScriptedBus, expected_bus_calls

TABLE = {
    "max_rpm": 1500.0,
    "registers": {"control_word": 0, "reference_1": 1, "status_word": 3, "actual_1": 4},
}
SETTINGS = AbbAcs580Settings.from_table(TABLE)
CW, REF1, SW, ACT1 = 0, 1, 3, 4
# Status words of the profile's states (bits named in the module docstring).
SW_SWITCH_ON_INHIBITED = 0x0270  # SWC_ON_INHIB | OFF_2_STA | OFF_3_STA | REMOTE
SW_READY_TO_SWITCH_ON = 0x0231  # RDY_ON | OFF_2_STA | OFF_3_STA | REMOTE
SW_OPERATION_ENABLED = 0x0337  # RDY_ON | RDY_RUN | RDY_REF | OFF_2/3_STA | AT_SETPOINT | REMOTE
SW_TRIPPED = 0x0238  # TRIPPED | OFF_2_STA | OFF_3_STA | REMOTE


def drive(bus, limit_rpm=900.0):
    return AbbAcs580(bus, SETTINGS, limit_rpm=limit_rpm)


# -- settings ------------------------------------------------------------------------------------
def test_settings_defaults_and_registry():
    assert SETTINGS.poll_timeout_s == 1.0 and SETTINGS.ramp_rpm_per_s == 100.0
    assert SETTINGS.registers.status_word == 3
    entry = driver_entry("abb_acs580")
    assert entry.role == "fan" and entry.validate(TABLE, "[fan]") == SETTINGS


@pytest.mark.parametrize(("change", "message"), [
    ({"max_rpm": 0.0}, r"\[fan\] max_rpm = 0.0 is outside the allowed range \(0.0, 100000.0\]"),
    ({"poll_timeout_s": 100}, r"poll_timeout_s = 100.0 is outside the allowed range"),
    ({"ramp_rpm_per_s": -1}, r"ramp_rpm_per_s = -1.0 is outside"),
    ({"speed": 3}, r"unknown key\(s\) \['speed'\]"),
    ({"registers": {"control_word": 0, "reference_1": 1, "status_word": 3}},
     r"registers: missing required key\(s\) \['actual_1'\]"),
    ({"registers": {"control_word": 0, "reference_1": 1, "status_word": 3, "actual_1": 70000}},
     r"registers.actual_1 = 70000 must be an integer register address in \[0, 65535\]"),
    ({"registers": {"control_word": 0, "reference_1": 1, "status_word": 3, "actual_1": 4.0}},
     r"registers.actual_1 = 4.0 must be an integer"),
    ({"registers": {"control_word": 0, "reference_1": 0, "status_word": 3, "actual_1": 4}},
     "addresses must be distinct"),
])
def test_bad_settings_name_key_and_range(change, message):
    with pytest.raises(ConfigError, match=message):
        AbbAcs580Settings.from_table({**TABLE, **change}, "[fan]")


def test_rig_config_fan_table_is_validated_by_the_driver():
    text = """
[rig]
name = "t"
[section]
B = 0.3
m = 3.0
I = 0.03
fh = 2.0
fa = 4.0
zeta_h = 0.005
zeta_a = 0.005
depth = 0.03
[taps]
shape = "rectangle"
B = 0.3
D = 0.03
taps_per_face = 4
[limits]
max_wind_speed = 9.0
max_fan_rpm = 900.0
[tunnel]
wind_per_rpm = 0.01
[fan]
driver = "abb_acs580"
url = "modbus+tcp://10.0.0.5:502?unit=1"
max_rpm = 1500.0
registers = { control_word = 0, reference_1 = 1, status_word = 3, actual_1 = 4 }
"""
    rig = parse_rig_config(text)
    assert rig.instrument("fan").settings["max_rpm"] == 1500.0
    with pytest.raises(ConfigError, match=r"\[fan\] max_rpm = -5.0 is outside"):
        parse_rig_config(text.replace("max_rpm = 1500.0", "max_rpm = -5.0"))


def test_constructor_does_no_io_needs_a_limit_and_rejects_unknown_keywords():
    bus = MagicMock()
    d = AbbAcs580(bus, TABLE, limit_rpm=900.0)  # a table is validated on the way in
    assert d.settings == SETTINGS
    assert bus.method_calls == []
    with pytest.raises(TypeError):
        AbbAcs580(bus, SETTINGS)  # type: ignore[call-arg]  # no default limit, on purpose
    with pytest.raises(TypeError):
        AbbAcs580(bus, SETTINGS, limit_rpm=900.0, speed=3)  # type: ignore[call-arg]
    for bad in (0.0, -1.0, math.inf, math.nan):
        with pytest.raises(ConfigError, match="limit_rpm"):
            AbbAcs580(bus, SETTINGS, limit_rpm=bad)
    assert set(d.describe()) == {"speed", "status_word"}


# -- scaling and the safety limit ----------------------------------------------------------------
def test_reference_scaling_and_refusals_send_nothing():
    with expected_bus_calls([
        ("write_register", REF1, 8000, None),   # 600 rpm / 1500 rpm * 20000
        ("write_register", REF1, 12000, None),  # the limit itself, 900 rpm
        ("write_register", REF1, 0, None),
    ]) as bus:
        d = drive(bus)
        d.set_speed(600.0)
        for bad in (900.001, 2000.0, -0.5, math.nan, math.inf, True):
            with pytest.raises(SafetyError):
                d.set_speed(bad)  # type: ignore[arg-type]
        d.set_speed(900.0)
        d.set_speed(0)


def test_reference_never_rounds_above_the_limit():
    # 1 count = 0.075 rpm; a limit between counts must not be passed by rounding up.
    d = drive(MagicMock(), limit_rpm=600.05)
    assert d.reference_counts(600.05) == 8000  # 8001 counts would be 600.075 rpm
    assert drive(MagicMock(), limit_rpm=2000.0).reference_counts(1500.0) == 20000
    with pytest.raises(SafetyError, match="above the drive's max_rpm 1500"):
        drive(MagicMock(), limit_rpm=2000.0).set_speed(1600.0)


@settings(deadline=None, max_examples=200, database=None)
@given(limit=st.floats(1.0, 1500.0), fraction=st.floats(0.0, 1.0))
def test_any_allowed_reference_is_sent_within_the_limit(limit, fraction):
    d = drive(MagicMock(), limit_rpm=limit)
    rpm = limit * fraction
    counts = d.reference_counts(rpm)
    assert 0 <= counts <= 20000
    assert counts * 1500.0 / 20000 <= limit
    assert abs(counts * 1500.0 / 20000 - rpm) <= 0.075 + 1e-9  # at most one count off


# -- sequences ------------------------------------------------------------------------------------
def test_start_sequence_prepare_then_run():
    with expected_bus_calls([
        ("read_holding_registers", REF1, 1, [8000]),       # stored reference within the limit
        ("read_holding_registers", SW, 1, [SW_SWITCH_ON_INHIBITED]),
        ("write_register", CW, 0x0476, None),              # prepare
        ("read_holding_registers", SW, 1, [SW_READY_TO_SWITCH_ON]),
        ("write_register", CW, 0x047F, None),              # run
        ("read_holding_registers", SW, 1, [SW_OPERATION_ENABLED]),
        ("write_register", CW, 0x0476, None),              # stop: ramp stop
        ("write_register", CW, 0x0000, None),              # coast
    ]) as bus:
        d = drive(bus)
        d.start()
        d.stop()
        d.coast()


def test_start_refuses_a_stored_reference_above_the_limit_or_a_tripped_drive():
    with expected_bus_calls([
        ("read_holding_registers", REF1, 1, [16000]),  # 1200 rpm > 900 rpm limit
        ("read_holding_registers", REF1, 1, [0xB1E0]),  # -20000: reverse
        ("read_holding_registers", REF1, 1, [0]),
        ("read_holding_registers", SW, 1, [SW_TRIPPED]),
    ]) as bus:
        d = drive(bus)
        with pytest.raises(SafetyError, match=r"16000 counts = 1200.0 rpm"):
            d.start()
        with pytest.raises(SafetyError, match=r"-20000 counts"):
            d.start()
        with pytest.raises(DeviceError, match="tripped"):
            d.start()


def test_reset_is_a_rising_edge_of_cw_bit_7():
    with expected_bus_calls([
        ("write_register", CW, 0x0476, None),
        ("write_register", CW, 0x04F6, None),  # bit 7 set: the 0->1 edge resets the fault
        ("write_register", CW, 0x0476, None),
        ("read_holding_registers", SW, 1, [SW_READY_TO_SWITCH_ON]),
    ]) as bus:
        status = drive(bus).reset_trip()
    assert not status.tripped and status.rdy_on


def test_reset_that_does_not_clear_is_a_device_error():
    script = [("write_register", CW, w, None) for w in (0x0476, 0x04F6, 0x0476)]
    script += [("read_holding_registers", SW, 1, [SW_TRIPPED])] * 200
    bus = ScriptedBus(script)  # not every poll is used: no completeness check
    bus.open()
    with pytest.raises(DeviceError, match="TRIPPED cleared after a reset within 0.01 s"):
        drive(bus).reset_trip(timeout_s=0.01)


def test_status_speed_and_read_use_one_request_when_adjacent():
    with expected_bus_calls([
        ("read_holding_registers", SW, 1, [SW_OPERATION_ENABLED]),
        ("read_holding_registers", ACT1, 1, [8000]),
        ("read_holding_registers", ACT1, 1, [0xFFEC]),  # -20 counts: signed
        ("read_holding_registers", SW, 2, [SW_TRIPPED, 4000]),
    ]) as bus:
        d = drive(bus)
        status = d.status()
        assert status.rdy_on and status.rdy_run and status.rdy_ref and status.at_setpoint
        assert not status.tripped and status.remote
        assert d.speed() == 600.0
        assert d.speed() == -1.5
        reading = d.read()
    assert set(reading.channels) == set(d.describe())
    assert reading.channels["speed"][0] == 300.0
    assert reading.channels["status_word"][0] == SW_TRIPPED
    assert reading.host_time_ns.dtype == np.int64 and reading.host_time_ns[0] > 0
    assert list(reading.counter) == [1] and reading.gaps == ()


def test_wait_for_speed_returns_when_within_tolerance_and_raises_on_trip():
    with expected_bus_calls([
        ("read_holding_registers", SW, 2, [SW_OPERATION_ENABLED, 4000]),
        ("read_holding_registers", SW, 2, [SW_OPERATION_ENABLED, 7990]),
        ("read_holding_registers", SW, 2, [SW_TRIPPED, 7000]),
    ]) as bus:
        d = drive(bus)
        assert d.wait_for_speed(600.0, tolerance_rpm=1.0, poll_s=0.0) == 599.25
        with pytest.raises(DeviceError, match="tripped while waiting for 600"):
            d.wait_for_speed(600.0, tolerance_rpm=1.0)
    with pytest.raises(ValueError, match="tolerance_rpm"):
        d.wait_for_speed(600.0, tolerance_rpm=0.0)


def test_status_word_decoding_covers_every_bit():
    for bit, name in enumerate(("rdy_on", "rdy_run", "rdy_ref", "tripped", "off_2_sta",
                                "off_3_sta", "swc_on_inhib", "alarm", "at_setpoint", "remote",
                                "above_limit")):
        status = DriveStatus.decode(1 << bit)
        assert getattr(status, name) and status.active() == [name.upper()]
    with pytest.raises(ValueError):
        DriveStatus.decode(0x10000)
