"""Vaisala PTB330 driver: settings, line decoding, units, and scripted byte exchanges.

Wire bytes come from docs/reference/wire_formats.md, "Barometer": ``SEND [addr]``, ``FORM``,
``OPEN``/ ``CLOSE`` (PTB330 manual p.101), the PTU300-style line ``P= 1013.2 hPa T= 31.1 'C RH= 38.3
%RH`` (PTU300 manual p.103) and the factory line ``pressure = 1013.02 hPa`` (PTB330 manual p.101).
"""

from __future__ import annotations

import inspect
import math
import threading
import time
from unittest.mock import MagicMock

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from daq.errors import ConfigError, ProtocolError, TransportError, TransportTimeout
from daq.instruments import registry
from daq.instruments.reading import Gap
from daq.instruments.vaisala_ptb330.decoder import (
    BarometerReading,
    Ptb330BadLine,
    Ptb330Line,
    Ptb330LineDecoder,
    parse_line,
    reading_from_line,
)
from daq.instruments.vaisala_ptb330.driver import FORM_STRING, SERIAL_DEFAULTS, VaisalaPtb330
from daq.instruments.vaisala_ptb330.settings import Ptb330Settings
from daq.transports.byte_transport import SerialTransport, open_transport
from daq.transports.scripted import ScriptedTransport, expected_exchange
from ident.physics.air import R_DRY_AIR

pytestmark = pytest.mark.realtime

FORM_CMD = b"FORM " + FORM_STRING.encode() + b"\r"
LINE = b"P=  1013.250 hPa    T= 21.34 'C \r\n"  # what FORM_STRING gives (widths [unverified])
OPEN_PLAIN = [(b"S\r", b""), (FORM_CMD, b"OK\r\n"), (b"SEND\r", LINE)]


def driver(transport, **settings_kw):
    return VaisalaPtb330(transport, Ptb330Settings(**settings_kw))


# -- settings ----------------------------------------------------------------------------------
def test_settings_defaults_and_registry_entry():
    """An empty table gives the documented defaults; the registry knows the driver and role."""
    s = Ptb330Settings.from_table({}, "[barometer]")
    assert (s.poll_interval_s, s.timeout_s, s.address) == (1.0, 2.0, None)
    entry = registry.driver_entry("vaisala_ptb330")
    assert entry.role == "barometer" and entry.factory is VaisalaPtb330
    got = registry.validate_settings("vaisala_ptb330", "barometer",
                                     {"poll_interval_s": 0.5, "address": 7}, "[barometer]")
    assert got == Ptb330Settings(poll_interval_s=0.5, address=7)
    with pytest.raises(ConfigError, match="is a barometer driver, not a fan"):
        registry.validate_settings("vaisala_ptb330", "fan", {}, "[fan]")


@pytest.mark.parametrize(
    ("table", "match"),
    [
        ({"poll_interval_s": 0.05}, r"poll_interval_s = 0.05 is outside the allowed range \[0.1"),
        ({"poll_interval_s": 61}, r"poll_interval_s = 61.0 is outside"),
        ({"timeout_s": 0.0}, r"timeout_s = 0.0 is outside the allowed range \[0.05, 30"),
        ({"timeout_s": "2"}, r"timeout_s must be a number"),
        ({"address": 256}, r"address = 256 must be an integer in \[0, 255\]"),
        ({"address": 1.0}, r"address = 1.0 must be an integer"),
        ({"address": True}, r"address = True must be an integer"),
        ({"baudrate": 9600}, r"unknown key\(s\) \['baudrate'\]"),
    ],
)
def test_settings_errors_name_the_key_and_range(table, match):
    with pytest.raises(ConfigError, match=r"\[barometer\].*" + match):
        Ptb330Settings.from_table(table, "[barometer]")


def test_settings_object_validates_itself():
    with pytest.raises(ConfigError, match="timeout_s"):
        Ptb330Settings(timeout_s=100.0)


def test_serial_line_defaults_are_7e1_xonxoff_and_the_url_query_overrides_them():
    """9600 baud, 7 data bits, even parity, 1 stop, XON/XOFF (docs/reference/wire_formats.md)."""
    t = open_transport("serial:///dev/ttyUSB3", **SERIAL_DEFAULTS)
    assert isinstance(t, SerialTransport)
    assert t._settings["baudrate"] == 9600 and t._settings["bytesize"] == 7
    assert t._settings["parity"] == "E" and t._settings["stopbits"] == 1
    assert t._settings["xonxoff"] is True
    t = open_transport("serial:///dev/ttyUSB3?baudrate=4800&bytesize=8", **SERIAL_DEFAULTS)
    assert isinstance(t, SerialTransport)
    assert t._settings["baudrate"] == 4800 and t._settings["bytesize"] == 8
    assert t._settings["parity"] == "E"


# -- pure decoding -----------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("text", "pa"),
    [
        (b"P= 1013.25 hPa T= 20.00 'C", 101325.0),
        (b"P= 1013.25 mbar T= 20.00 'C", 101325.0),
        (b"P= 101.325 kPa T= 20.00 'C", 101325.0),
        (b"P= 101325 Pa T= 20.00 'C", 101325.0),
        (b"P= 1.01325 bar T= 20.00 'C", 101325.0),
        (b"P= 760.00 torr T= 20.00 'C", 101325.0),
        # conventional mmHg/inHg differ from torr by 1.4e-7 relative: 0.014 Pa at 1 atm
        (b"P= 760.00 mmHg T= 20.00 'C", 101325.0144354),
        (b"P= 29.9213 inHg T= 20.00 'C", 101325.0 - 0.0114),
        (b"P= 14.6959 psi T= 20.00 'C", 101325.0 - 0.5),
    ],
)
def test_every_pressure_unit_is_converted_to_pascal(text, pa):
    """The unit is read from each line (the simulator's fault 'unit_change').

    Tolerance 1e-5 relative: the rounding of the printed values (14.6959 psi is 101324.5 Pa).
    """
    line = parse_line(text)
    assert isinstance(line, Ptb330Line)
    assert line.pressure_pa == pytest.approx(pa, rel=1e-5)


@pytest.mark.parametrize(("text", "kelvin"),
                         [(b"20.00 'C", 293.15), (b"68.00 'F", 293.15), (b"293.15 K", 293.15),
                          (b"-40.0 'C", 233.15)])
def test_temperature_units_are_converted_to_kelvin(text, kelvin):
    line = parse_line(b"P= 1013.25 hPa T= " + text)
    assert isinstance(line, Ptb330Line)
    assert line.temperature_k == pytest.approx(kelvin, abs=1e-9)


def test_manual_example_lines():
    """PTU300 p.103 line (with RH) decodes; the factory line of PTB330 p.101 is refused."""
    line = parse_line(b"P= 1013.2 hPa T= 31.1 'C RH= 38.3 %RH")
    assert isinstance(line, Ptb330Line)
    assert (line.pressure_pa, line.temperature_k, line.relative_humidity) == pytest.approx(
        (101320.0, 304.25, 38.3))
    assert line.resolution_pa == pytest.approx(5.0)  # 0.1 hPa printed: +-0.05 hPa
    assert isinstance(parse_line(b"pressure = 1013.02 hPa"), Ptb330BadLine)


def test_the_humidity_of_a_ptu300_line_reaches_the_reading_as_a_fraction():
    """A PTU300-class line's humidity is a channel of the reading.

    RH= 38.3 %RH becomes 0.383 in the reading's ``relative_humidity`` channel; a PTB330 line
    (no RH) gives NaN, and an impossible humidity is NaN with the reason in ``status``.
    """
    line = parse_line(b"P= 1013.2 hPa T= 31.1 'C RH= 38.3 %RH")
    assert isinstance(line, Ptb330Line)
    reading = reading_from_line(line, 0, 1)
    assert reading.values()["relative_humidity"] == pytest.approx(0.383)
    assert reading.ok
    ptb = parse_line(b"P= 1013.2 hPa T= 31.1 'C")
    assert isinstance(ptb, Ptb330Line)
    assert math.isnan(reading_from_line(ptb, 0, 1).relative_humidity)
    wet = parse_line(b"P= 1013.2 hPa T= 31.1 'C RH= 130.0 %RH")
    assert isinstance(wet, Ptb330Line)
    bad = reading_from_line(wet, 0, 1)
    assert math.isnan(bad.relative_humidity) and "relative humidity 130" in bad.status


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        (b"P= 1013.25 mmH2O T= 20.00 'C", "unknown pressure unit 'mmH2O'"),
        (b"P= 1013.25 inH2O T= 20.00 'C", "unknown pressure unit 'inH2O'"),
        (b"P= 1013.25 atm T= 20.00 'C", "unknown pressure unit 'atm'"),
        (b"P= 1013.25 hPa T= 20.00 'X", "unknown temperature unit"),
        (b"P= 10?3.25 hPa T= 20.00 'C", "not a"),
        (b"P= 1013.25 hPa T= 2", "not a"),
        (b"P= 1013.25 hPa", "not a"),
        (b"", "not a"),
    ],
)
def test_unknown_units_and_garbled_lines_are_refused(text, reason):
    """Never a silently wrong number: an unknown unit or a damaged field is a bad line."""
    bad = parse_line(text)
    assert isinstance(bad, Ptb330BadLine) and reason in bad.reason
    err = bad.error()
    assert isinstance(err, ProtocolError) and text.hex(" ") in str(err)


def test_density_is_dry_air_ideal_gas():
    """ISA sea level: 101325 Pa, 15 degC gives 1.2250 kg/m^3."""
    line = parse_line(b"P= 1013.25 hPa T= 15.00 'C")
    assert isinstance(line, Ptb330Line)
    reading = reading_from_line(line, host_time_ns=123, counter=4)
    assert reading.density_kg_m3 == pytest.approx(101325.0 / (R_DRY_AIR * 288.15), rel=1e-12)
    assert reading.density_kg_m3 == pytest.approx(1.2250, abs=5e-5)
    assert reading.ok and reading.host_time_ns == 123 and reading.counter == 4


@pytest.mark.parametrize(
    ("text", "status"),
    [
        (b"P= 3000.00 hPa T= 20.00 'C", "pressure 300000 Pa outside"),
        (b"P= 1013.25 Pa T= 20.00 'C", "pressure 1013.25 Pa outside"),  # a truncated Pa value
        (b"P= 1013.25 hPa T= 150.00 'C", "temperature 423.15 K outside"),
        (b"P= ******* hPa T= 20.00 'C", "pressure not available"),
        (b"P= 1013.25 hPa T= ***** 'C", "temperature not available"),
    ],
)
def test_implausible_or_missing_values_are_nan_with_a_reason(text, status):
    """A well-formed line with an implausible value is kept, marked, and gives NaN density."""
    line = parse_line(text)
    assert isinstance(line, Ptb330Line)
    reading = reading_from_line(line, 0, 1)
    assert not reading.ok and status in reading.status
    assert math.isnan(reading.density_kg_m3)
    bad_value = reading.pressure_pa if "pressure" in status else reading.temperature_k
    assert math.isnan(bad_value)


def test_decoder_splits_resynchronises_and_bounds_its_buffer():
    dec = Ptb330LineDecoder()
    stream = b"> \r\n" + LINE + b"P=  10" + LINE + b"garbage\r\n" + LINE
    items = [item for byte in stream for item in dec.feed(bytes([byte]))]
    kinds = [type(item).__name__ for item in items]
    # prompt skipped; partial line resynchronised on the next 'P=' (fragment reported bad)
    assert kinds == ["Ptb330Line", "Ptb330BadLine", "Ptb330Line", "Ptb330BadLine", "Ptb330Line"]
    assert dec.lines_ok == 3 and dec.lines_bad == 2
    assert dec.bytes_skipped == len(b"P=  10") + len(b"garbage") + 2
    overlong = dec.feed(b"x" * 300)[0]
    assert isinstance(overlong, Ptb330BadLine)
    assert overlong.reason.startswith("no line end within 256")
    assert dec.pending == b""


valid_lines = st.builds(
    lambda p, t, unit: (f"P= {p:.3f} {unit} T= {t:.2f} 'C\r\n").encode(),
    st.floats(500.0, 1100.0), st.floats(-30.0, 50.0), st.sampled_from(["hPa", "mbar"]),
)


@settings(deadline=None, max_examples=200, database=None)
@given(garbage=st.binary(max_size=400), chunk=st.integers(1, 64), line=valid_lines)
def test_decoder_survives_garbage_and_resynchronises(garbage, chunk, line):
    """Random bytes never crash or hang the decoder; it resynchronises on the next line.

    The whole line after the garbage's line end decodes to exactly its values.
    """
    dec = Ptb330LineDecoder()
    stream = garbage + b"\r\n" + line
    items = []
    for i in range(0, len(stream), chunk):
        items += dec.feed(stream[i:i + chunk])
    assert isinstance(items[-1], Ptb330Line)
    expected = parse_line(line.rstrip(b"\r\n"))
    assert isinstance(expected, Ptb330Line)
    assert items[-1].pressure_pa == expected.pressure_pa
    assert len(dec.pending) == 0


@settings(deadline=None, max_examples=200, database=None)
@given(line=valid_lines, data=st.data())
def test_a_damaged_character_never_decodes(line, data):
    """A line with one character replaced by a stray symbol never decodes.

    The symbols cannot belong to a number, unit or label: no silently wrong number from this
    kind of garbling, neither from the line parser nor through the stream decoder.
    """
    body = bytearray(line.rstrip(b"\r\n"))
    index = data.draw(st.integers(0, len(body) - 1))
    body[index] = data.draw(st.sampled_from(b"?!$%&@~^|`#"))
    assert isinstance(parse_line(bytes(body)), Ptb330BadLine)
    items = Ptb330LineDecoder().feed(bytes(body) + b"\r\n")
    assert items and all(isinstance(item, Ptb330BadLine) for item in items)


# -- driver: construction and contract ---------------------------------------------------------
def test_construction_does_no_io_and_rejects_unknown_keywords():
    mock = MagicMock()
    drv = VaisalaPtb330(mock)
    assert mock.method_calls == [] and not drv.is_open
    with pytest.raises(TypeError):
        VaisalaPtb330(mock, Ptb330Settings(), baudrate=9600)  # type: ignore[call-arg]
    with pytest.raises(TypeError, match="Ptb330Settings"):
        VaisalaPtb330(mock, {"timeout_s": 1.0})  # type: ignore[arg-type]
    with pytest.raises(TransportError, match="not open"):
        drv.read()


def test_describe_keys_equal_the_reading_channels_and_property_docstrings_follow_the_rule():
    with expected_exchange(OPEN_PLAIN + [(b"SEND\r", LINE)]) as t:
        drv = driver(t)
        drv.open()
        reading = drv.read()
    assert set(drv.describe()) == set(reading.channels)
    assert reading.channels["pressure"][0] == pytest.approx(101325.0)
    assert drv.describe()["density"]["units"] == "kg/m^3"
    for cls in (VaisalaPtb330, BarometerReading, Ptb330LineDecoder):
        for name, member in inspect.getmembers(cls, lambda m: isinstance(m, property)):
            assert member.__doc__.startswith(("Measure ", "Control ")), (cls, name)


# -- driver: scripted exchanges (bytes from docs/reference/wire_formats.md, "Barometer"; PTB330
# p.101) -----
def test_open_sets_the_format_and_reads_are_polled_with_send():
    with expected_exchange(OPEN_PLAIN + [(b"SEND\r", LINE), (b"SEND\r", LINE)]) as t:
        with driver(t) as drv:
            assert drv.is_open
            first, second = drv.measure(), drv.measure()
    assert first.pressure_pa == pytest.approx(101325.0) and first.counter == 1
    assert first.temperature_k == pytest.approx(294.49) and second.counter == 2
    assert first.pressure_unit == "hPa" and first.raw == LINE.rstrip(b"\r\n")
    assert not t.is_open  # the context manager closed it


def test_addressed_poll_mode_opens_the_line_for_form_and_sends_with_the_address():
    """PTB330 p.101: OPEN aa gives a POLL-mode unit temporary command access; SEND aa."""
    script = [
        (b"S\r", b""),
        (b"OPEN 7\r", b"PTB330: 7 line opened for operator commands\r\n"),
        (FORM_CMD, b"OK\r\n"),
        (b"CLOSE\r", b"line closed\r\n"),
        (b"SEND 7\r", LINE),
        (b"SEND 7\r", LINE),
    ]
    with expected_exchange(script) as t:
        with driver(t, address=7) as drv:
            assert drv.measure().pressure_pa == pytest.approx(101325.0)


def test_open_fails_when_the_format_is_not_adopted():
    """A unit still in its factory format (PTB330 p.101 line) is refused with the bytes."""
    factory = b"pressure = 1013.02 hPa\r\n"
    script = OPEN_PLAIN[:2] + [(b"SEND\r", factory)] * 3
    with expected_exchange(script) as t:
        drv = driver(t)
        with pytest.raises(ProtocolError, match=r"pressure = 1013.02 hPa.*after 3 attempts"):
            drv.open()
    assert not drv.is_open and not t.is_open


def test_garbled_then_good_reply_is_retried_and_counted(caplog):
    garbled = b"P=  10?3.250 hPa    T= 21.34 'C \r\n"
    with expected_exchange(OPEN_PLAIN + [(b"SEND\r", garbled), (b"SEND\r", LINE)]) as t:
        with driver(t) as drv:
            reading = drv.measure()
    assert reading.pressure_pa == pytest.approx(101325.0)
    assert drv.stats["protocol_errors"] == 1 and drv.stats["retries"] == 1
    assert drv.bad_lines == [garbled.rstrip(b"\r\n")]
    assert "attempt 2 of 3" in caplog.text


def test_partial_line_is_a_protocol_error_with_its_bytes_then_recovers():
    with expected_exchange(OPEN_PLAIN + [(b"SEND\r", b"P=  1013.2"), (b"SEND\r", LINE)]) as t:
        with driver(t) as drv:
            assert drv.measure().pressure_pa == pytest.approx(101325.0)
    assert drv.bad_lines == [b"P=  1013.2"]


def test_no_reply_raises_transport_timeout_after_bounded_attempts():
    with expected_exchange(OPEN_PLAIN + [(b"SEND\r", b"")] * 3) as t:
        with driver(t) as drv:
            start = time.monotonic()
            with pytest.raises(TransportTimeout, match=r"no reply to 'SEND'.*after 3 attempts"):
                drv.measure()
            # two backoffs of 0.05 and 0.1 s; the scripted transport times out at once
            assert time.monotonic() - start < 1.0
    assert drv.stats["timeouts"] == 3


def test_a_failed_first_poll_is_a_gap_before_the_first_reading():
    """Poll 1 fails: reading 2 carries Gap(0, 1), so the lost row is not invisible."""
    with expected_exchange(OPEN_PLAIN + [(b"SEND\r", b"")] * 3 + [(b"SEND\r", LINE)]) as t:
        with driver(t) as drv:
            with pytest.raises(TransportTimeout):
                drv.read()
            reading = drv.read()
    assert reading.counter.tolist() == [2]
    assert reading.gaps == (Gap(after_counter=0, length=1),)


def test_unit_change_mid_run_is_converted_and_an_unknown_unit_is_refused():
    in_mmhg = b"P=   760.000 mmHg   T= 68.00 'F \r\n"
    in_water = b"P= 10332.275 mmH2O  T= 20.00 'C \r\n"
    script = OPEN_PLAIN + [(b"SEND\r", in_mmhg)] + [(b"SEND\r", in_water)] * 3
    with expected_exchange(script) as t:
        with driver(t) as drv:
            reading = drv.measure()
            assert reading.pressure_pa == pytest.approx(101325.0144, abs=1e-3)
            assert reading.temperature_k == pytest.approx(293.15)
            with pytest.raises(ProtocolError, match="unknown pressure unit 'mmH2O'"):
                drv.measure()


def test_echo_of_the_command_is_skipped():
    """With ECHO ON a unit repeats the command before its reply (PTB330 p.83 example)."""
    with expected_exchange(OPEN_PLAIN + [(b"SEND\r", b"SEND\r\n" + LINE)]) as t:
        with driver(t) as drv:
            assert drv.measure().pressure_pa == pytest.approx(101325.0)


class _DropsOnce(ScriptedTransport):
    """Scripted transport whose first data read fails like a lost connection."""

    def __init__(self, exchanges):
        super().__init__(exchanges)
        self.fail_next_read = False
        self.opens = 0

    def open(self):
        self.opens += 1
        super().open()

    def read(self, max_bytes, timeout_s):
        if self.fail_next_read:
            self.fail_next_read = False
            raise TransportError(f"{self.url}: connection reset")
        return super().read(max_bytes, timeout_s)


def test_a_lost_connection_is_reopened():
    t = _DropsOnce(OPEN_PLAIN + [(b"SEND\r", LINE), (b"SEND\r", LINE)])
    with driver(t) as drv:
        t.fail_next_read = True
        assert drv.measure().pressure_pa == pytest.approx(101325.0)
    assert drv.stats["reconnects"] == 1 and t.opens == 2
    t.assert_complete()


def test_poll_keeps_its_period_and_stops_on_request():
    script = OPEN_PLAIN + [(b"SEND\r", LINE)] * 4
    with expected_exchange(script) as t:
        with driver(t, poll_interval_s=0.1) as drv:
            start = time.monotonic()
            readings = list(drv.poll(count=3))
            elapsed = time.monotonic() - start
            # 3 reads, 2 waits of 0.1 s; generous upper bound for a loaded CI machine
            assert 0.19 <= elapsed < 0.6
            assert [r.counter for r in readings] == [1, 2, 3]
            stop = threading.Event()
            polled = []
            for reading in drv.poll(stop=stop):
                polled.append(reading)
                stop.set()
            assert [r.counter for r in polled] == [4]
