"""The Modbus devices' replies, fuzzed: every word decodes exactly or is refused by name.

The ABB ACS580 driver turns two holding registers (Status Word, Actual 1) into a status and a
speed. For every pair of 16-bit words hypothesis draws, :meth:`AbbAcs580.read` returns the
status whose bits rebuild the word and the speed of the word read as a signed count (no silent
wrong value); a word outside 0..65535 (a broken bus) is refused with a ValueError naming the
range, never decoded. Likewise the release PLC's coils, RELEASED input and trigger counter
become one row of exactly those values, and a counter outside 0..65535 a ProtocolError naming
the register. The byte-stream decoders (scanner, lasers, barometer) are fuzzed in their
own test modules.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from daq.errors import ProtocolError
from daq.instruments.abb_acs580.driver import AbbAcs580
from daq.instruments.abb_acs580.profile import DriveStatus
from daq.instruments.abb_acs580.settings import AbbAcs580Settings
from daq.instruments.modbus_plc.driver import ModbusPlc
from daq.instruments.modbus_plc.settings import ModbusPlcSettings
from daq.instruments.reading import Reading
from daq.transports.scripted import expected_bus_calls

TABLE = {
    "max_rpm": 1500.0,
    "registers": {"control_word": 0, "reference_1": 1, "status_word": 3, "actual_1": 4},
}
SW = 3
#: Status Word bits 0-10 in order (the profile's, as the drive manual lists them).
BITS = ("rdy_on", "rdy_run", "rdy_ref", "tripped", "off_2_sta", "off_3_sta", "swc_on_inhib",
        "alarm", "at_setpoint", "remote", "above_limit")


def reading(words: list[int]) -> Reading:
    with expected_bus_calls([("read_holding_registers", SW, 2, words)]) as bus:
        return AbbAcs580(bus, AbbAcs580Settings.from_table(TABLE), limit_rpm=900.0).read()


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 0xFFFF), st.integers(0, 0xFFFF))
def test_every_reply_decodes_exactly(word, counts):
    out = reading([word, counts])
    assert out.channels["status_word"][0] == word
    status = DriveStatus.decode(word)
    rebuilt = sum(int(getattr(status, name)) << bit for bit, name in enumerate(BITS))
    assert rebuilt == word & 0x07FF
    assert len(status.active()) == bin(word & 0x07FF).count("1")
    signed = counts - 0x10000 if counts >= 0x8000 else counts
    rpm = out.channels["speed"][0]
    assert isinstance(rpm, float) and math.isfinite(rpm)
    assert rpm == signed * 1500.0 / 20000.0


@settings(max_examples=100, deadline=None)
@given(st.sampled_from([0, 1]),
       st.one_of(st.integers(max_value=-1), st.integers(min_value=0x10000)))
def test_a_word_out_of_range_is_refused_by_name(which, bad):
    words = [0x0237, 1000]
    words[which] = bad
    with pytest.raises(ValueError, match=r"0\.\.65535"):
        reading(words)


# -- the release PLC: coils, the RELEASED input and the trigger counter ------------------------
PLC_TABLE = {
    "coils": {"release": 16, "arm": 17, "trigger": 18},
    "discrete_inputs": {"released": 3},
    "holding_registers": {"trigger_count": 100},
}


def plc_reading(armed: bool, released: bool, count: int, polls: int = 1) -> Reading:
    script = [("read_coils", 17, 1, [armed]), ("read_discrete_inputs", 3, 1, [released]),
              ("read_holding_registers", 100, 1, [count])] * polls
    with expected_bus_calls(script) as bus:
        plc = ModbusPlc(bus, ModbusPlcSettings.from_table(PLC_TABLE))
        readings = [plc.read() for _ in range(polls)]
    return readings[-1]


@settings(max_examples=200, deadline=None)
@given(st.booleans(), st.booleans(), st.integers(0, 0xFFFF), st.integers(1, 3))
def test_every_plc_reply_is_one_row_of_exactly_those_values(armed, released, count, polls):
    out = plc_reading(armed, released, count, polls)
    assert len(out) == 1 and out.counter.tolist() == [polls]  # the poll number, from 1
    assert out.channels["armed"].tolist() == [armed]
    assert out.channels["released"].tolist() == [released]
    assert out.channels["trigger_count"].dtype == np.uint16
    assert out.channels["trigger_count"].tolist() == [count]
    assert out.gaps == ()


@settings(max_examples=100, deadline=None)
@given(st.one_of(st.integers(max_value=-1), st.integers(min_value=0x10000)))
def test_a_trigger_count_out_of_range_is_refused_by_name(bad):
    with pytest.raises(ProtocolError, match=r"TRIGGER_COUNT \(holding register 100\) = .* "
                                            r"outside 0\.\.65535"):
        plc_reading(True, False, bad)
