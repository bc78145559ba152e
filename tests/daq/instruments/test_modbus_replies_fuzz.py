"""The fan drive's register replies, fuzzed: every word decodes exactly or is refused by name.

The ABB ACS580 driver turns two holding registers (Status Word, Actual 1) into a status and a
speed. For every pair of 16-bit words hypothesis draws, :meth:`AbbAcs580.read` returns the
status whose bits rebuild the word and the speed of the word read as a signed count (no silent
wrong value); a word outside 0..65535 (a broken bus) is refused with a ValueError naming the
range, never decoded. The byte-stream decoders (scanner, lasers, barometer) are fuzzed in their
own test modules.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from daq.instruments.abb_acs580.driver import AbbAcs580
from daq.instruments.abb_acs580.profile import DriveStatus
from daq.instruments.abb_acs580.settings import AbbAcs580Settings
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
