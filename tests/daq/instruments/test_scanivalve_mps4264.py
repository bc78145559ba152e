"""Scanivalve MPS4264 driver: settings, scripted command bytes, frame decoder and block assembly.

Packets here are built with ``struct`` from the layouts of docs/reference/wire_formats.md, "Pressure
scanner" (mps-protocol.h): a third encoding, independent of the driver's decoder and of the
simulator's encoder.
"""

from __future__ import annotations

import logging
import math
import struct
import time
from unittest.mock import MagicMock

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from daq.config import parse_rig_config
from daq.errors import (
    ConfigError,
    DeviceError,
    ProtocolError,
    SafetyError,
    TransportError,
    TransportTimeout,
)
from daq.instruments import registry
from daq.instruments.reading import Gap
from daq.instruments.scanivalve_mps4264.blocks import (
    STATUS_MISSING,
    STATUS_OK,
    STATUS_VALVE_CAL,
    ScanBlock,
)
from daq.instruments.scanivalve_mps4264.driver import ScanivalveMps4264
from daq.instruments.scanivalve_mps4264.frames import Mps4264Decoder
from daq.instruments.scanivalve_mps4264.settings import Mps4264Settings
from daq.transports.scripted import ScriptedTransport, expected_exchange

pytestmark = pytest.mark.realtime

PA_PER_PSI = 6894.75977  # mps-protocol.h units table, PA factor
TABLE = {"modules": 1, "rate_hz": 500.0, "byte_order": "big", "pitot_channel": 63}


def eu_packet(frame: int, t_s: int = 100, t_ns: int = 0, *, order: str = ">",
              pressures: list[float] | None = None, temps: list[float] | None = None) -> bytes:
    """MPS-4264 EU packet 0x6D, 304 B: int32 type, uint32 frame, s, ns, float32 T[8], P[64]."""
    p = pressures if pressures is not None else [frame + 0.5 * i for i in range(64)]
    t = temps if temps is not None else [20.0 + i for i in range(8)]
    return struct.pack(order + "iIII8f64f", 0x6D, frame, t_s, t_ns, *t, *p)


def legacy_packet(frame: int, t_s: int = 5, t_ns: int = 250_000_000, *, order: str = ">",
                  serial: int = 4264001, rate: float = 500.0, valve: int = 0, unit: int = 23,
                  conv: float = PA_PER_PSI, start: tuple[int, int] = (1000, 500_000_000),
                  ext: tuple[int, int] = (0, 0), pressures: list[float] | None = None,
                  size: int = 348) -> bytes:
    """Legacy packet 0x0A, 348 B, field by field (docs/reference/wire_formats.md, "Pressure")."""
    p = pressures if pressures is not None else [float(frame + i) for i in range(64)]
    ext_us = (ext[0] * 1_000_000 + ext[1] // 1000) % 2**32
    return struct.pack(order + "iiIifiifIII8f64fIIII", 0x0A, size, frame, serial, rate, valve,
                       unit, conv, start[0], start[1], ext_us, *[21.0] * 8, *p, t_s, t_ns,
                       ext[0], ext[1])


def test_test_encoder_follows_the_manual_layout():
    """Bytes of docs/reference/wire_formats.md: type word 0x6D, then the frame, s, ns; 304/348 B."""
    packet = eu_packet(7, 3, 9, order=">")
    assert len(packet) == 304 and len(legacy_packet(1)) == 348
    assert packet[:16] == bytes.fromhex("0000006d 00000007 00000003 00000009")
    assert eu_packet(7, 3, 9, order="<")[:8] == bytes.fromhex("6d000000 07000000")


# -- settings ----------------------------------------------------------------------------------
def test_settings_from_table_with_defaults():
    s = Mps4264Settings.from_table(TABLE, "[scanner]")
    assert (s.modules, s.rate_hz, s.byte_order, s.pitot_channel) == (1, 500.0, "big", 63)
    assert s.data_port == 503 and s.command_timeout_s == 2.0 and s.n_channels == 64
    assert s.min_block_s == 0.02  # 10 frames at 500 Hz per read_block
    assert Mps4264Settings.from_table({**TABLE, "min_block_s": 0}, "t").min_block_s == 0.0


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"modules": 9}, r"\[scanner\] modules = 9 is outside the allowed range \[1, 8\]"),
        ({"modules": 1.0}, r"modules must be an integer in \[1, 8\]"),
        ({"rate_hz": 0}, r"rate_hz = 0.0 is outside the allowed range \(0.0, 2000.0\]"),
        ({"rate_hz": 2500}, r"rate_hz = 2500.0 is outside"),
        ({"byte_order": "middle"}, "byte_order must be 'big' or 'little'"),
        ({"pitot_channel": 64}, r"pitot_channel = 64 is outside the allowed range \[0, 63\]"),
        ({"data_port": 0}, r"data_port = 0 is outside the allowed range \[1, 65535\]"),
        ({"modules": 2, "data_port": 65535}, "no room for 2 consecutive module ports"),
        ({"command_timeout_s": -1}, r"command_timeout_s = -1.0 is outside"),
        ({"speed": 1}, r"unknown key\(s\) \['speed'\]"),
        ({"min_block_s": -0.01},
         r"\[scanner\] min_block_s = -0.01 is outside the allowed range \[0.0, 0.25\]"),
        ({"min_block_s": 0.5}, r"min_block_s = 0.5 is outside the allowed range \[0.0, 0.25\]"),
        ({"min_block_s": math.inf}, r"min_block_s = inf is outside"),
        ({"min_block_s": "20 ms"}, r"\[scanner\] min_block_s must be a number, got '20 ms'"),
        ({"min_block_s": True}, r"min_block_s must be a number, got True"),
    ],
)
def test_bad_settings_name_the_key_and_range(change, match):
    with pytest.raises(ConfigError, match=match):
        Mps4264Settings.from_table({**TABLE, **change}, "[scanner]")


def test_missing_key_is_named():
    table = dict(TABLE)
    del table["pitot_channel"]
    with pytest.raises(ConfigError, match=r"missing required key\(s\) \['pitot_channel'\]"):
        Mps4264Settings.from_table(table, "[scanner]")


def test_registered_for_the_scanner_role_and_used_by_rig_configs():
    """The rig config validates a [scanner] table through the registry (role 'scanner')."""
    entry = registry.driver_entry("scanivalve_mps4264")
    assert entry.role == "scanner"
    with pytest.raises(ConfigError, match="is a scanner driver, not a fan"):
        registry.validate_settings("scanivalve_mps4264", "fan", TABLE, "[fan]")
    text = """
[rig]
name = "r"
[section]
B = 0.3
m = 3.0
I = 0.03
fh = 2.0
fa = 4.0
zeta_h = 0.005
zeta_a = 0.005
depth = 0.01
[taps]
shape = "rectangle"
B = 0.3
D = 0.01
taps_per_face = 16
[limits]
max_wind_speed = 14.0
max_fan_rpm = 1500.0
[tunnel]
wind_per_rpm = 0.01
[scanner]
driver = "scanivalve_mps4264"
url = "tcp://10.0.0.5:23"
modules = 1
rate_hz = 500.0
byte_order = "big"
pitot_channel = 63
"""
    rig = parse_rig_config(text, "rig.toml")
    assert rig.instrument("scanner").settings["pitot_channel"] == 63
    with pytest.raises(ConfigError, match=r"rig.toml \[scanner\] pitot_channel = 70"):
        parse_rig_config(text.replace("pitot_channel = 63", "pitot_channel = 70"), "rig.toml")


def test_construction_does_no_io_and_rejects_unknown_keywords():
    transport = MagicMock()
    settings_ = Mps4264Settings.from_table(TABLE, "t")
    driver = ScanivalveMps4264(transport, settings_)
    assert transport.method_calls == []
    with pytest.raises(TypeError):
        ScanivalveMps4264(transport, settings_, speed=3)  # type: ignore[call-arg]
    with pytest.raises(TypeError, match="Mps4264Settings"):
        ScanivalveMps4264(transport, TABLE)  # type: ignore[arg-type]
    assert driver.n_channels == 64 and driver.rate_hz == 500.0


def test_property_docstrings_follow_the_verb_rule():
    for name in ("rate_hz", "n_channels", "stats"):
        doc = getattr(ScanivalveMps4264, name).__doc__
        assert doc.startswith("Measure "), name


# -- commands, byte-exact ------------------------------------------------------------------------
# Bytes from docs/reference/wire_formats.md, "Pressure scanner" (commands SET FORMAT B B, SET SIM
# 0x40, SCAN, STOP, CALZ; the STATUS reply "STATUS: READY|SCAN|CALZ", mps-protocol.h; the INVALID
# COMMAND reply).
OPEN = [(b"STATUS\r\n", b"STATUS: READY\r\n")]


def fenced(command: bytes, state: bytes = b"READY", reply: bytes = b"") -> list:
    return [(command + b"\r\n", reply), (b"STATUS\r\n", b"STATUS: " + state + b"\r\n")]


def driver_on(transport, **kwargs) -> ScanivalveMps4264:
    return ScanivalveMps4264(transport, Mps4264Settings.from_table({**TABLE, **kwargs}, "t"))


def test_open_configure_scan_stop_bytes():
    script = (OPEN + fenced(b"SET FORMAT B B") + fenced(b"SET UNITS PA")
              + fenced(b"SET SIM 0x40") + fenced(b"SET RATE 500") + fenced(b"SCAN", b"SCAN")
              + fenced(b"STOP"))
    data = ScriptedTransport([])
    with expected_exchange(script) as t:
        driver = ScanivalveMps4264(t, Mps4264Settings.from_table(TABLE, "t"),
                                   data_transports=[data])
        driver.open()
        driver.configure()
        driver.scan()
        assert data.is_open
        driver.stop()
        driver.close()
        driver.close()  # idempotent


def test_eu_format_and_fractional_rate_bytes():
    script = (OPEN + fenced(b"SET FORMAT B B") + fenced(b"SET UNITS PA") + fenced(b"SET SIM 0")
              + fenced(b"SET RATE 312.5"))
    with expected_exchange(script) as t:
        driver = driver_on(t)
        driver.open()
        driver.set_format("eu")
        driver.set_rate(312.5)
        assert driver.rate_hz == 312.5
    with pytest.raises(ValueError, match="frame rate must be in"):
        driver.set_rate(0)


def test_calz_waits_for_ready_and_accepts_cr_only_replies():
    script = OPEN + [(b"CALZ\r\n", b""), (b"STATUS\r\n", b"STATUS: CALZ\r"),
                     (b"STATUS\r\n", b"STATUS: CALZ\r"), (b"STATUS\r\n", b"STATUS: READY\r")]
    with expected_exchange(script) as t:
        driver = driver_on(t)
        driver.open()
        driver.calz(wind_speed_now=0.0, poll_s=0.01)


@pytest.mark.parametrize("wind", [3.5, -0.1, math.nan])
def test_calz_with_the_wind_on_is_refused_before_any_byte(wind):
    """The MPS4264 has no calibration valve: a zero wind-on is a SafetyError, nothing is sent."""
    with expected_exchange(OPEN) as t:
        driver = driver_on(t)
        driver.open()
        with pytest.raises(SafetyError, match="refusing CALZ with wind speed"):
            driver.calz(wind_speed_now=wind)


def test_calz_that_never_finishes_is_a_device_error():
    script = OPEN + fenced(b"CALZ", b"CALZ") + [(b"STATUS\r\n", b"STATUS: CALZ\r\n")] * 3
    with expected_exchange(script) as t:
        driver = driver_on(t)
        driver.open()
        with pytest.raises(DeviceError, match="CALZ not finished after 0.025 s"):
            driver.calz(wind_speed_now=0.0, timeout_s=0.025, poll_s=0.01)


def test_invalid_command_reply_is_a_device_error():
    script = OPEN + fenced(b"SET RATE 1500", reply=b"INVALID COMMAND: SET RATE 1500\r\n")
    with expected_exchange(script) as t:
        driver = driver_on(t)
        driver.open()
        with pytest.raises(DeviceError, match=r"'SET RATE 1500' refused: 'INVALID COMMAND"):
            driver.set_rate(1500)
        assert driver.rate_hz == 500.0  # unchanged: the scanner refused


def test_unexpected_state_after_scan_and_missing_reply():
    script = OPEN + fenced(b"SCAN", b"CALZ")
    with expected_exchange(script) as t:
        driver = ScanivalveMps4264(t, Mps4264Settings.from_table(TABLE, "t"),
                                   data_transports=[ScriptedTransport([])])
        driver.open()
        with pytest.raises(DeviceError, match="state 'CALZ' after SCAN"):
            driver.scan()
    with expected_exchange([(b"STATUS\r\n", b"STATUS: REA")]) as t, \
            pytest.raises(TransportTimeout):
        driver_on(t).open()
    with expected_exchange([(b"STATUS\r\n", b"STATUS:\r\n")]) as t, \
            pytest.raises(ProtocolError, match="empty state"):
        driver_on(t).open()


# -- decoder ----------------------------------------------------------------------------------
def test_decoder_eu_packets_in_both_byte_orders():
    for order in (">", "<"):
        decoder = Mps4264Decoder()
        batch = decoder.feed(eu_packet(1, 10, 5) + eu_packet(2, 10, 2_000_005, order=order))
        if order == ">":
            assert batch.frame.tolist() == [1, 2]
            assert batch.big_endian.tolist() == [True, True]
        else:  # a switch of order is still two valid packets
            assert batch.big_endian.tolist() == [True, False]
        np.testing.assert_allclose(batch.frame_time, [10 + 5e-9, 10 + 2_000_005e-9], rtol=0,
                                   atol=1e-12)
        np.testing.assert_array_equal(batch.pressure[1], [2 + 0.5 * i for i in range(64)])
        np.testing.assert_array_equal(batch.temperature[0], np.arange(8) + 20.0)
        assert np.isnan(batch.trigger_time).all() and (batch.serial == -1).all()
        assert decoder.bytes_skipped == 0 and decoder.packets == 2


def test_decoder_legacy_packet_trigger_time_units_and_valve():
    """0x0A: trigger = scan start + ext trigger; kPa scaled to Pa by the conversion factor."""
    kpa = [0.001 * i for i in range(64)]  # kPa values 0..0.063
    packet = legacy_packet(3, ext=(2, 125_000_000), unit=14, conv=6.894757, pressures=kpa)
    batch = Mps4264Decoder().feed(packet + legacy_packet(4, valve=1))
    assert batch.frame.tolist() == [3, 4] and batch.serial.tolist() == [4264001, 4264001]
    assert batch.trigger_time[0] == pytest.approx(1000.5 + 2.125, abs=1e-9)
    assert np.isnan(batch.trigger_time[1])  # no trigger yet: both fields zero
    assert batch.frame_time[0] == pytest.approx(5.25, abs=1e-12)
    # float32 of the kPa values and of the factor: ~1e-7 relative.
    np.testing.assert_allclose(batch.pressure[0], np.array(kpa) * 1000.0, rtol=1e-6, atol=1e-9)
    assert batch.valve_cal.tolist() == [False, True] and batch.rate_hz[0] == 500.0


def test_decoder_handles_split_packets_byte_by_byte():
    stream = b"".join(eu_packet(i) for i in range(1, 5))
    decoder = Mps4264Decoder()
    frames = []
    for i in range(len(stream)):
        frames += decoder.feed(stream[i:i + 1]).frame.tolist()
    assert frames == [1, 2, 3, 4] and decoder.bytes_skipped == 0


def test_decoder_resynchronises_after_garbage_and_rejects_corrupt_packets():
    garbage = bytes(range(7, 77))
    stream = (eu_packet(1) + garbage + eu_packet(2) + eu_packet(3)
              + legacy_packet(4, size=340) + legacy_packet(5) + legacy_packet(6))
    decoder = Mps4264Decoder()
    batch = decoder.feed(stream)
    # Packet 1 is not followed by a type word (garbage), so it is rejected rather than trusted;
    # the corrupt legacy packet 4 (size field 340) is rejected by its fields.
    assert batch.frame.tolist() == [2, 3, 5, 6]
    assert decoder.bad_packets == 2
    assert decoder.bytes_skipped == 304 + len(garbage) + 348


def test_decoder_skips_unsupported_packet_types_and_raw_units():
    raw64 = struct.pack(">iIII8f64i", 0x69, 9, 0, 0, *[0.0] * 8, *range(64))  # 0x69 RAW
    stream = eu_packet(1) + raw64 + legacy_packet(2, unit=27) + eu_packet(3)
    decoder = Mps4264Decoder()
    assert decoder.feed(stream).frame.tolist() == [1, 3]
    assert decoder.unsupported_packets == 2 and decoder.bytes_skipped == 0


def test_decoder_holds_a_packet_until_its_successor_can_be_checked():
    decoder = Mps4264Decoder()
    one, two = eu_packet(1), eu_packet(2)
    assert decoder.feed(one + two[:2]).frame.tolist() == []  # 2 bytes of a word: wait
    assert decoder.pending_bytes == 306
    assert decoder.feed(two[2:]).frame.tolist() == [1, 2]
    assert decoder.reset() == 0


@settings(max_examples=150, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(max_size=3000), st.lists(st.integers(1, 400), max_size=20))
def test_decoder_never_crashes_on_garbage_in_any_chunking(data, cuts):
    decoder = Mps4264Decoder()
    total = 0
    pieces = np.split(np.frombuffer(data, np.uint8), sorted({c for c in cuts if c < len(data)}))
    for piece in pieces:
        batch = decoder.feed(piece.tobytes())
        total += len(batch)
    consumed = decoder.bytes_skipped + decoder.pending_bytes
    assert consumed <= len(data) and total * 96 <= len(data)


@settings(max_examples=100, deadline=None, database=None)
@given(st.binary(max_size=700), st.integers(1, 1000), st.sampled_from([">", "<"]),
       st.integers(1, 700))
def test_decoder_resynchronises_on_the_next_valid_frames(garbage, first, order, chunk):
    """After any garbage, the valid frames that follow are decoded exactly.

    The first one may be consumed by garbage that happens to look like a packet header (no CRC
    in the protocol); the last three never are.
    """
    frames = list(range(first, first + 4))
    valid = b"".join(eu_packet(f, order=order) for f in frames)
    stream = garbage + valid
    decoder = Mps4264Decoder()
    out = []
    for i in range(0, len(stream), chunk):
        out += decoder.feed(stream[i:i + chunk]).frame.tolist()
    assert out[-3:] == frames[-3:]


# -- blocks from scripted data connections -------------------------------------------------------
def scanning(chunks_per_module: list[list[bytes]], *, table: dict | None = None,
             transports=None, **kwargs) -> ScanivalveMps4264:
    """Return a driver that has sent SCAN; module k's data connection replays its chunks."""
    table = {**TABLE, **(table or {})}
    data = transports or [ScriptedTransport([(b"", c) for c in chunks])
                          for chunks in chunks_per_module]
    command = ScriptedTransport(OPEN + fenced(b"SCAN", b"SCAN"))
    command.open()
    driver = ScanivalveMps4264(command, Mps4264Settings.from_table(table, "t"),
                               data_transports=data, **kwargs)
    driver.open()
    driver.scan()
    return driver


def test_describe_keys_equal_the_reading_channels():
    driver = scanning([[eu_packet(1) + eu_packet(2)], [eu_packet(1) + eu_packet(2)]],
                      table={"modules": 2, "pitot_channel": 100})
    reading = driver.read(0.05)
    described = driver.describe()
    arrays = reading.channels
    assert set(described) == set(arrays)
    for name, spec in described.items():
        assert arrays[name].dtype == np.dtype(spec["dtype"]), name
        assert arrays[name].shape == (len(reading), *spec["shape"]), name
    np.testing.assert_array_equal(arrays["pitot"], arrays["pressure"][:, 100])
    assert arrays["pitot"][0] == 1 + 0.5 * 36  # module 1, channel 36 of packet 1
    assert reading.counter.tolist() == [1, 2] and reading.device_time is not None


def test_counter_gap_is_marked_with_its_length():
    driver = scanning([[b"".join(eu_packet(i, 0, 2_000_000 * i) for i in (1, 2, 3, 7, 8))]])
    block = driver.read_block(0.05)
    assert block.counter.tolist() == [1, 2, 3, 7, 8]
    assert block.gaps == (Gap(3, 3, "missing"),)
    assert block.clock_steps == () and block.time_base == "relative"
    assert (block.module_status == STATUS_OK).all()
    assert block.host_time_ns.dtype == np.int64 and (block.host_time_ns > 0).all()


def test_frames_missing_at_the_start_and_a_duplicate():
    driver = scanning([[eu_packet(3) + eu_packet(4) + eu_packet(4) + eu_packet(5)]])
    block = driver.read_block(0.05)
    assert block.counter.tolist() == [3, 4, 5] and block.gaps == (Gap(0, 2, "missing"),)
    assert driver.stats["duplicates"] == 1


def test_module_missing_a_frame_is_nan_with_its_reason():
    m0 = b"".join(eu_packet(i) for i in (1, 2, 3, 4))
    m1 = b"".join(legacy_packet(i, valve=int(i == 4)) for i in (1, 3, 4))
    driver = scanning([[m0], [m1]], table={"modules": 2, "pitot_channel": 64})
    block = driver.read_block(0.05)
    assert block.counter.tolist() == [1, 2, 3, 4] and block.gaps == ()
    assert block.module_status.tolist() == [[0, 0], [0, STATUS_MISSING], [0, 0],
                                            [0, STATUS_VALVE_CAL]]
    assert np.isnan(block.pressure[1, 64:]).all() and np.isnan(block.temperature[1, 8:]).all()
    assert np.isnan(block.pressure[3, 64:]).all() and not np.isnan(block.pressure[3, :64]).any()
    assert np.isfinite(block.pressure[[0, 2], :]).all()
    assert np.isnan(block.pitot[[1, 3]]).all()


def test_counter_wrap_and_restart_are_unwrapped():
    top = 2**32
    frames = [top - 2, top - 1, 0, 1, 2]
    driver = scanning([[b"".join(eu_packet(f % top, 0, 0) for f in frames)
                        + eu_packet(1) + eu_packet(2)]])
    block = driver.read_block(0.05)
    start = top - 2
    assert block.counter.tolist() == [start + i for i in range(7)]
    assert block.gaps == (Gap(0, start - 1, "missing"), Gap(start + 4, -1, "restart"))


def test_byte_order_mismatch_is_decoded_and_reported(caplog):
    driver = scanning([[eu_packet(1, order="<") + eu_packet(2, order="<")]])
    with caplog.at_level(logging.WARNING, logger="daq.instruments.scanivalve_mps4264.driver"):
        block = driver.read_block(0.05)
    assert block.counter.tolist() == [1, 2]
    assert driver.stats["byte_order_mismatches"] == 2
    assert "sends little-endian packets but byte_order = 'big'" in caplog.text


def test_clock_step_and_epoch0_time_base():
    times = [(0, 0), (0, 2_000_000), (1_767_225_600, 6_000_000), (1_767_225_600, 8_000_000)]
    driver = scanning([[b"".join(eu_packet(i + 1, s, ns) for i, (s, ns) in enumerate(times))]])
    block = driver.read_block(0.05)
    assert block.time_base == "mixed"
    assert [s.counter for s in block.clock_steps] == [3]
    assert block.clock_steps[0].step_s == pytest.approx(1_767_225_600.002, abs=1e-6)


def test_frames_held_for_a_silent_module_are_flushed_on_timeout():
    driver = scanning([[eu_packet(1) + eu_packet(2) + eu_packet(3)], [eu_packet(1)]],
                      table={"modules": 2, "pitot_channel": 64})
    assert driver.read_block(0.05).counter.tolist() == [1]
    block = driver.read_block(0.05)  # module 1 stays silent: 2 and 3 come out marked missing
    assert block.counter.tolist() == [2, 3]
    assert (block.module_status[:, 1] == STATUS_MISSING).all()
    assert driver.stats["forced_emissions"] == 1
    with pytest.raises(TransportTimeout, match="no complete frame within"):
        driver.read_block(0.02)


class PushTransport(ScriptedTransport):
    """A data connection whose bytes arrive when the test pushes them."""

    def __init__(self) -> None:
        super().__init__([])

    def push(self, data: bytes) -> None:
        self._readable += data


def test_a_silent_module_is_not_waited_for_and_its_late_frames_are_counted():
    m0, m1 = PushTransport(), PushTransport()
    driver = scanning([], transports=[m0, m1], table={"modules": 2, "pitot_channel": 64},
                      module_silence_s=0.05)
    m0.push(eu_packet(1) + eu_packet(2))
    m1.push(eu_packet(1))
    assert driver.read_block(0.01).counter.tolist() == [1]  # 2 waits for module 1
    time.sleep(0.06)  # module 1 now silent for longer than module_silence_s
    m0.push(eu_packet(3))
    block = driver.read_block(0.01)
    assert block.counter.tolist() == [2, 3]
    assert block.module_status[:, 1].tolist() == [STATUS_MISSING, STATUS_MISSING]
    m1.push(eu_packet(2) + eu_packet(3) + eu_packet(4))  # module 1 is back, 2 and 3 too late
    m0.push(eu_packet(4))
    block = driver.read_block(0.01)
    assert block.counter.tolist() == [4] and (block.module_status == STATUS_OK).all()
    assert driver.stats["late_frames"] == 2 and driver.stats["forced_emissions"] == 1


def test_read_before_scan_is_an_error():
    with pytest.raises(TransportError, match="call scan"):
        driver_on(MagicMock()).read_block(0.01)


class DroppingTransport(ScriptedTransport):
    """Fails its first read with a connection reset, then replays its script."""

    def __init__(self, exchanges, fail_opens: int = 0):
        super().__init__(exchanges)
        self.failed = False
        self.opens = 0
        self.fail_opens = fail_opens

    def open(self):
        self.opens += 1
        if self.opens > 1 and self.fail_opens:
            self.fail_opens -= 1
            raise TransportError("connection refused")
        super().open()

    def read(self, max_bytes, timeout_s):
        if not self.failed:
            self.failed = True
            raise TransportError("connection reset by peer")
        return super().read(max_bytes, timeout_s)


def test_lost_data_connection_is_reopened_with_backoff(caplog):
    data = DroppingTransport([(b"", eu_packet(1) + eu_packet(2))], fail_opens=1)
    with caplog.at_level(logging.WARNING, logger="daq.instruments.scanivalve_mps4264.driver"):
        driver = scanning([], transports=[data], reconnect_backoff_s=0.001)
        block = driver.read_block(0.5)
    assert block.counter.tolist() == [1, 2]
    assert driver.stats["reconnects"] == 1 and data.opens == 3  # scan, 1 failed, 1 good
    assert "reconnect attempt 1 of 5 failed" in caplog.text


def test_a_data_connection_that_stays_away_raises():
    data = DroppingTransport([], fail_opens=10)
    driver = scanning([], transports=[data], reconnect_attempts=3, reconnect_backoff_s=0.0)
    with pytest.raises(TransportError, match="module 0 data connection stayed away after 3"):
        driver.read_block(0.5)


# -- batching: read_block collects for min_block_s (on a simulated clock) ------------------------
class FakeClock:
    """Stands in for the driver module's ``time``: advances only when a read waits or sleeps."""

    def __init__(self, t: float = 1000.0) -> None:
        self.t = t

    def monotonic(self) -> float:
        return self.t

    def monotonic_ns(self) -> int:
        return round(self.t * 1e9)

    def sleep(self, seconds: float) -> None:
        self.t += max(seconds, 0.0)


class TimedTransport(ScriptedTransport):
    """A data connection whose bytes arrive at set times of a FakeClock.

    ``read`` behaves as a socket's: it returns at once what has arrived, else waits (advances
    the clock) up to ``timeout_s`` for the next arrival, else times out.
    """

    def __init__(self, clock: FakeClock, arrivals: list[tuple[float, bytes]]) -> None:
        super().__init__([])
        self.clock = clock
        self.arrivals = sorted(arrivals, key=lambda a: a[0])

    def read(self, max_bytes: int, timeout_s: float) -> bytes:
        if not self.is_open:
            raise TransportError(f"{self.url}: not open")
        if not self.arrivals or self.arrivals[0][0] > self.clock.t:
            nxt = self.arrivals[0][0] if self.arrivals else math.inf
            if nxt > self.clock.t + timeout_s:
                self.clock.t += max(timeout_s, 0.0)
                raise TransportTimeout(f"{self.url}: nothing within {timeout_s:g} s")
            self.clock.t = nxt
        out = b""
        while self.arrivals and self.arrivals[0][0] <= self.clock.t:
            out += self.arrivals.pop(0)[1]
        return out


@pytest.fixture
def clock(monkeypatch):
    """Simulate the driver module's clock: the tests see exactly when a block comes out."""
    import daq.instruments.scanivalve_mps4264.driver as module

    fake = FakeClock()
    monkeypatch.setattr(module, "time", fake)
    return fake


def timed_driver(clock: FakeClock, arrivals: list[list[tuple[float, bytes]]], *,
                 min_block_s: float = 0.02, rate_hz: float = 500.0, **kwargs
                 ) -> ScanivalveMps4264:
    """Return a scanning driver whose module k receives ``arrivals[k]`` (times from now)."""
    t0 = clock.t
    data = [TimedTransport(clock, [(t0 + t, b) for t, b in module]) for module in arrivals]
    table = {"modules": len(arrivals), "pitot_channel": 0, "min_block_s": min_block_s,
             "rate_hz": rate_hz}
    return scanning([], transports=data, table=table, **kwargs)


def frames_at(times: dict[int, float], *, skip=()) -> list[tuple[float, bytes]]:
    """Arrivals of EU packets: frame -> arrival time, s (frames in ``skip`` never arrive)."""
    return [(t, eu_packet(f, 1_767_225_600 + f // 500, 2_000_000 * (f % 500)))
            for f, t in times.items() if f not in skip]


def read_all(driver: ScanivalveMps4264, clock: FakeClock,
             timeout_s: float = 1.0) -> list[tuple[ScanBlock, float]]:
    """Read blocks until a timeout; return (block, time it came out) pairs."""
    out: list[tuple[ScanBlock, float]] = []
    while True:
        try:
            block = driver.read_block(timeout_s)
        except TransportTimeout:
            return out
        out.append((block, clock.t))


def test_blocks_hold_min_block_s_of_frames_at_full_rate(clock):
    """500 Hz, 3 modules (module k 0.1k ms behind module 0): every block holds 10 frames.

    ``ceil(min_block_s * rate)`` = 10 complete frames end the collection early, so a block
    comes out as its 10th frame completes: never later than min_block_s after its first.
    """
    n = 500
    arrivals = [frames_at({f: 0.0005 + 0.002 * (f - 1) + 1e-4 * k for f in range(1, n + 1)})
                for k in range(3)]
    driver = timed_driver(clock, arrivals)
    t0 = clock.t
    blocks = read_all(driver, clock)
    counter = np.concatenate([b.counter for b, _ in blocks])
    np.testing.assert_array_equal(counter, np.arange(1, n + 1))
    assert [len(b) for b, _ in blocks] == [10] * 50
    for block, out in blocks:
        assert not block.gaps and (block.module_status == STATUS_OK).all()
        # A frame's host time is when its last module packet (module 2) was read: at once.
        arrived = t0 + 0.0005 + 0.002 * (block.counter - 1) + 2e-4
        np.testing.assert_allclose(block.host_time_ns * 1e-9, arrived, rtol=0, atol=1e-9)
        first_complete = block.host_time_ns[0] * 1e-9
        assert out - first_complete <= 0.02 + 1e-9
        assert out == pytest.approx(block.host_time_ns[-1] * 1e-9, abs=1e-9)  # no idle wait


def test_a_block_is_never_held_past_min_block_s(clock):
    """Frames slower than the configured rate (100 Hz for 500 Hz): out after min_block_s."""
    times = {f: 0.001 + 0.01 * (f - 1) for f in range(1, 31)}
    driver = timed_driver(clock, [frames_at(times), frames_at(times)], min_block_s=0.025)
    blocks = read_all(driver, clock, timeout_s=0.5)
    assert np.concatenate([b.counter for b, _ in blocks]).tolist() == list(range(1, 31))
    for block, out in blocks[:-1]:
        first_complete = block.host_time_ns[0] * 1e-9
        assert out == pytest.approx(first_complete + 0.025, abs=1e-9)  # the deadline itself
        assert len(block) == 3  # frames at +0, +10, +20 ms of its first
    assert len(blocks) == 10


def test_a_lagging_module_does_not_hold_blocks_and_its_gaps_are_marked(clock):
    """Module 1 lags 15 ms and loses frame 30; both lose frame 60 (a counter gap).

    Blocks still come out by their deadline with what is complete; frames waiting for module 1
    come in the next block; frame 30 is NaN with STATUS_MISSING there, as without batching.
    """
    n = 100
    m0 = frames_at({f: 0.0005 + 0.002 * (f - 1) for f in range(1, n + 1)}, skip={60})
    m1 = frames_at({f: 0.0155 + 0.002 * (f - 1) for f in range(1, n + 1)}, skip={30, 60})
    driver = timed_driver(clock, [m0, m1])
    blocks = read_all(driver, clock)
    counter = np.concatenate([b.counter for b, _ in blocks])
    np.testing.assert_array_equal(counter, np.setdiff1d(np.arange(1, n + 1), [60]))
    assert [g for b, _ in blocks for g in b.gaps] == [Gap(59, 1, "missing")]
    status = np.concatenate([b.module_status for b, _ in blocks])
    assert status[counter == 30].tolist() == [[STATUS_OK, STATUS_MISSING]]
    assert (status[counter != 30] == STATUS_OK).all()
    pressure = np.concatenate([b.pressure for b, _ in blocks])
    assert np.isnan(pressure[counter == 30, 64:]).all()
    assert np.isfinite(pressure[counter != 30]).all()
    for block, out in blocks:
        assert out - block.host_time_ns[0] * 1e-9 <= 0.02 + 1e-9
    assert driver.stats["late_frames"] == 0 and driver.stats["forced_emissions"] == 0


def test_a_module_far_behind_still_gets_blocks_out_by_the_deadline(clock):
    """Module 1 delivers in bursts of 40 ms (a stalling link): each block is out by its deadline.

    Module 0 holds the frames module 1 has not sent yet; they come in later blocks, complete.
    """
    n = 200
    m0 = frames_at({f: 0.0005 + 0.002 * (f - 1) for f in range(1, n + 1)})
    m1 = frames_at({f: 0.04 * ((f - 1) // 20 + 1) for f in range(1, n + 1)})
    driver = timed_driver(clock, [m0, m1])
    blocks = read_all(driver, clock)
    counter = np.concatenate([b.counter for b, _ in blocks])
    np.testing.assert_array_equal(counter, np.arange(1, n + 1))
    assert all((b.module_status == STATUS_OK).all() and not b.gaps for b, _ in blocks)
    for block, out in blocks:
        assert out - block.host_time_ns[0] * 1e-9 <= 0.02 + 1e-9


def test_timeout_semantics_are_kept_with_batching(clock):
    """No frame: TransportTimeout after exactly the timeout, as without batching.

    A frame completing just before the timeout comes out at the timeout, not min_block_s
    later; with timeout 0, what is there comes out without waiting.
    """
    driver = timed_driver(clock, [frames_at({1: 0.095, 2: 0.5})], min_block_s=0.02)
    start = clock.t
    block = driver.read_block(0.1)
    assert block.counter.tolist() == [1]
    assert clock.t - start == pytest.approx(0.1, abs=1e-9)  # capped by the read timeout
    start = clock.t
    with pytest.raises(TransportTimeout, match=r"no complete frame within 0.2 s"):
        driver.read_block(0.2)  # frame 2 arrives 0.3 s later
    assert clock.t - start == pytest.approx(0.2, abs=1e-9)
    clock.t += 1.0
    start = clock.t
    assert driver.read_block(0.0).counter.tolist() == [2]  # already there: at once
    assert clock.t == start
    with pytest.raises(TransportTimeout):
        driver.read_block(0.0)


def test_a_backlog_comes_out_at_once_in_one_block(clock):
    times = {f: 0.002 * f for f in range(1, 301)}
    driver = timed_driver(clock, [frames_at(times), frames_at(times)])
    clock.t += 1.0  # the reader was busy: 300 frames wait in the socket buffers
    start = clock.t
    block = driver.read_block(1.0)
    assert block.counter.tolist() == list(range(1, 301)) and clock.t == start


def test_min_block_s_zero_returns_each_frame_as_it_completes(clock):
    times = {f: 0.0005 + 0.002 * (f - 1) for f in range(1, 21)}
    driver = timed_driver(clock, [frames_at(times), frames_at(times)], min_block_s=0.0)
    blocks = read_all(driver, clock)
    assert [b.counter.tolist() for b, _ in blocks] == [[f] for f in range(1, 21)]
    assert all(out == pytest.approx(b.host_time_ns[0] * 1e-9, abs=1e-9) for b, out in blocks)


def test_a_silent_module_is_marked_missing_within_blocks_of_min_block_s(clock):
    """Module 1 stops after frame 50; after module_silence_s, blocks go on without it."""
    n = 300
    m0 = frames_at({f: 0.0005 + 0.002 * (f - 1) for f in range(1, n + 1)})
    m1 = frames_at({f: 0.0005 + 0.002 * (f - 1) for f in range(1, 51)})
    driver = timed_driver(clock, [m0, m1], module_silence_s=0.2)
    blocks = read_all(driver, clock)
    counter = np.concatenate([b.counter for b, _ in blocks])
    np.testing.assert_array_equal(counter, np.arange(1, n + 1))
    status = np.concatenate([b.module_status for b, _ in blocks])
    assert (status[:50] == STATUS_OK).all() and (status[50:, 1] == STATUS_MISSING).all()
    late = [(b, out) for b, out in blocks if b.counter[0] > 150]  # well after the silence
    assert late and all(len(b) == 10 for b, _ in late[:-1])


def test_host_time_is_the_read_that_completed_each_packet(clock):
    """Stamps follow the reads: a packet split over two reads takes the second read's time."""
    one, two, three = eu_packet(1), eu_packet(2), eu_packet(3)
    arrivals = [(0.001, one + two[:100]), (0.004, two[100:]), (0.0045, three[:3]),
                (0.006, three[3:])]
    driver = timed_driver(clock, [arrivals], min_block_s=0.02)
    t0 = clock.t
    block = driver.read_block(0.05)
    assert block.counter.tolist() == [1, 2, 3]
    np.testing.assert_allclose(block.host_time_ns * 1e-9 - t0, [0.001, 0.004, 0.006], atol=1e-9)


def test_settings_constructed_directly_validate_min_block_s():
    with pytest.raises(ConfigError, match=r"min_block_s = -1.0 is outside the allowed range"):
        Mps4264Settings(modules=1, rate_hz=500.0, byte_order="big", pitot_channel=0,
                        min_block_s=-1.0)


# -- the one-pass decoding of several streams ----------------------------------------------------
def test_feed_with_ends_gives_stream_offsets_across_splits_and_garbage():
    stream = eu_packet(1) + eu_packet(2) + legacy_packet(3) + eu_packet(4)
    ends = np.cumsum([304, 304, 348, 304])
    decoder = Mps4264Decoder()
    got, frames = [], []
    for i in range(0, len(stream), 100):
        batch, e = decoder.feed_with_ends(stream[i:i + 100])
        got += e.tolist()
        frames += batch.frame.tolist()
    assert frames == [1, 2, 3, 4] and got == ends.tolist()
    decoder.reset()
    batch, e = decoder.feed_with_ends(b"\x01\x02garbage" + eu_packet(5) + eu_packet(6))
    assert batch.frame.tolist() == [5, 6]
    assert e.tolist() == [len(stream) + 9 + 304, len(stream) + 9 + 608]


def _packets(kind: str, frames: list[int], order: str) -> bytes:
    if kind == "eu":
        return b"".join(eu_packet(f, order=order) for f in frames)
    return b"".join(legacy_packet(f, order=order, ext=(f % 3, 1000 * f), valve=f % 2,
                                  unit=27 if f % 7 == 0 else 23) for f in frames)


@settings(max_examples=200, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(1, 4), st.data())
def test_feed_many_equals_feeding_each_decoder(modules, data):
    """The one-pass decoding gives what each decoder gives alone, in any chunking and mix."""
    streams = []
    for _ in range(modules):
        parts = data.draw(st.lists(st.tuples(st.sampled_from(["eu", "legacy", "garbage"]),
                                             st.integers(1, 4), st.sampled_from([">", "<"])),
                                   min_size=1, max_size=4))
        out, frame = b"", 1
        for kind, count, order in parts:
            if kind == "garbage":
                out += bytes(data.draw(st.binary(min_size=1, max_size=20)))
            else:
                out += _packets(kind, list(range(frame, frame + count)), order)
                frame += count
        streams.append(out)
    cuts = [sorted(data.draw(st.lists(st.integers(0, len(s)), max_size=5))) + [len(s)]
            for s in streams]
    steps = []
    pos = [0] * modules
    for step in range(max(len(c) for c in cuts)):
        chunks = []
        for k, s in enumerate(streams):
            end = max(cuts[k][min(step, len(cuts[k]) - 1)], pos[k])
            chunks.append(s[pos[k]:end])
            pos[k] = end
        steps.append(chunks)
    assert_feed_many_equals_feeding_each(steps)


def assert_feed_many_equals_feeding_each(steps: list[list[bytes]]) -> None:
    """Feed each step's chunks (one per stream; b"" = nothing) both ways and compare."""
    alone = [Mps4264Decoder() for _ in steps[0]]
    together = [Mps4264Decoder() for _ in steps[0]]
    for chunks in steps:
        fed = [(d, c) for d, c in zip(together, chunks, strict=True) if c]
        many = Mps4264Decoder.feed_many([d for d, _ in fed], [c for _, c in fed]) if fed else []
        single = [d.feed_with_ends(c) for d, c in zip(alone, chunks, strict=True) if c]
        assert len(many) == len(single)
        for (b1, e1), (b2, e2) in zip(many, single, strict=True):
            np.testing.assert_array_equal(e1, e2)
            for name in b1.__dataclass_fields__:
                np.testing.assert_array_equal(getattr(b1, name), getattr(b2, name), err_msg=name)
        for d1, d2 in zip(together, alone, strict=True):
            assert (d1.packets, d1.bytes_skipped, d1.bad_packets, d1.unsupported_packets,
                    d1.pending_bytes, d1.offset) == (d2.packets, d2.bytes_skipped,
                                                     d2.bad_packets, d2.unsupported_packets,
                                                     d2.pending_bytes, d2.offset)


@pytest.mark.parametrize("stream", [
    eu_packet(1) + b"\x00" + eu_packet(2),  # packet 1 not followed by a type word: rejected
    eu_packet(1) + b"[" + eu_packet(2),  # "[\0\0\0" reads as type 0x5B (little-endian)
    eu_packet(1) + eu_packet(2)[:2],  # 2 bytes of the next type word: packet 1 waits
    legacy_packet(1) + legacy_packet(2, size=340) + legacy_packet(3)[:3],  # corrupt, waiting
    eu_packet(1) + legacy_packet(2)[:40],  # a type switch after the packets
])
def test_feed_many_equals_feeding_each_decoder_in_edge_cases(stream):
    assert_feed_many_equals_feeding_each([[stream, eu_packet(1)], [eu_packet(3), eu_packet(2)]])


def test_feed_many_takes_the_one_pass_for_modules_in_step(monkeypatch):
    """Whole packets of one type on every stream: one decode for all (no per-stream feed)."""
    decoders = [Mps4264Decoder() for _ in range(3)]
    chunks = [_packets("legacy", [1, 2, 3], ">") + legacy_packet(4)[:10] for _ in range(3)]

    def no_feed(self, data):  # pragma: no cover - must not be called
        raise AssertionError("fell back to the per-stream decoder")

    monkeypatch.setattr(Mps4264Decoder, "feed_with_ends", no_feed)
    out = Mps4264Decoder.feed_many(decoders, chunks)
    assert [b.frame.tolist() for b, _ in out] == [[1, 2, 3]] * 3
    assert [e.tolist() for _, e in out] == [[348, 696, 1044]] * 3
    assert [d.pending_bytes for d in decoders] == [10] * 3
    assert [d.packets for d in decoders] == [3] * 3


@settings(max_examples=60, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.integers(1, 3), st.integers(5, 80), st.data())
def test_batching_changes_the_blocks_not_the_frames(clock, modules, n, data):
    """Batching changes how frames are grouped into blocks, nothing else.

    With lost and duplicated packets, modules lagging each other and a counter restart, the
    same frames, statuses, gaps and counters come out with 20 ms blocks as with one block per
    frame (``min_block_s`` 0).
    """
    restart = data.draw(st.one_of(st.none(), st.integers(2, n)))
    arrivals = []
    for _ in range(modules):
        lost = data.draw(st.sets(st.integers(1, n), max_size=n // 4))
        dup = data.draw(st.sets(st.integers(1, n), max_size=3))
        lag = data.draw(st.floats(0.0, 0.03))
        module = []
        for i in range(1, n + 1):
            frame = i if restart is None or i < restart else i - restart + 1  # counter restart
            if i in lost:
                continue
            t = 0.0005 + 0.002 * i + lag
            packet = eu_packet(frame, 1_767_225_600, 2_000_000 * i)
            module += [(t, packet)] * (2 if i in dup else 1)
        arrivals.append(module)

    def run(min_block_s: float) -> tuple[list[ScanBlock], dict]:
        clock.t = 1000.0
        driver = timed_driver(clock, arrivals, min_block_s=min_block_s)
        return [b for b, _ in read_all(driver, clock, timeout_s=0.3)], driver.stats

    batched, stats_b = run(0.02)
    single, stats_s = run(0.0)
    assert sum(len(b) for b in batched) >= n // 2 and len(batched) <= len(single)
    for name in ("counter", "frame_time", "pressure", "temperature", "module_status"):
        np.testing.assert_array_equal(np.concatenate([getattr(b, name) for b in batched]),
                                      np.concatenate([getattr(b, name) for b in single]),
                                      err_msg=name)
    assert [g for b in batched for g in b.gaps] == [g for b in single for g in b.gaps]
    assert stats_b == stats_s


@settings(max_examples=60, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.integers(1, 3), st.integers(5, 60), st.sampled_from(["legacy", "eu"]), st.data())
def test_the_in_step_path_gives_the_blocks_and_state_of_the_general_one(clock, modules, n,
                                                                         kind, data):
    """Blocks built at once for modules in step equal those of the per-module merge.

    Lost, duplicated and split packets, garbage, lagging modules, a valve in calibration, a
    changed serial number or rate, a counter restart: read once as the driver does (taking the
    in-step path where it applies) and once with that path switched off, the blocks, stats, rate
    and serial numbers are the same.
    """
    restart = data.draw(st.one_of(st.none(), st.integers(2, n)))
    arrivals = []
    for _ in range(modules):
        lost = data.draw(st.sets(st.integers(1, n), max_size=2))
        dup = data.draw(st.sets(st.integers(1, n), max_size=2))
        valve = data.draw(st.sets(st.integers(1, n), max_size=2))
        serial_change = data.draw(st.one_of(st.none(), st.integers(1, n)))
        rate = data.draw(st.sampled_from([500.0, 250.0, float("nan")]))
        garbage = data.draw(st.one_of(st.none(), st.integers(1, n)))
        lag = data.draw(st.floats(0.0, 0.01))
        module = []
        for i in range(1, n + 1):
            frame = i if restart is None or i < restart else i - restart + 1
            if i in lost:
                continue
            t = 0.0005 + 0.002 * i + lag
            if kind == "eu":
                packet = eu_packet(frame, 1_767_225_600, 2_000_000 * i)
            else:
                serial = 4264001 if serial_change is None or i < serial_change else 4264009
                packet = legacy_packet(frame, 1_767_225_600, 2_000_000 * i, serial=serial,
                                       valve=int(i in valve), rate=rate if i == n else 500.0)
            if i == garbage:
                packet = b"\x00\x01\x02" + packet
            cut = data.draw(st.integers(0, len(packet)))
            module += [(t, packet[:cut]), (t + 1e-5, packet[cut:])] * (2 if i in dup else 1)
        arrivals.append(module)

    def run(general: bool) -> tuple[list[ScanBlock], dict, float, tuple]:
        clock.t = 1000.0
        driver = timed_driver(clock, arrivals)
        if general:
            driver._in_step_block = lambda: None  # type: ignore[method-assign]
        blocks = [b for b, _ in read_all(driver, clock, timeout_s=0.3)]
        return blocks, driver.stats, driver.rate_hz, driver.serial_numbers

    fast, stats_f, rate_f, serials_f = run(False)
    slow, stats_s, rate_s, serials_s = run(True)
    assert [len(b) for b in fast] == [len(b) for b in slow]
    for a, b in zip(fast, slow, strict=True):
        for name in ("counter", "frame_time", "trigger_time", "host_time_ns", "pressure",
                     "pitot", "temperature", "module_status"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
        assert (a.gaps, a.clock_steps, a.time_base) == (b.gaps, b.clock_steps, b.time_base)
    assert stats_f == stats_s
    assert (rate_f, serials_f) == (rate_s, serials_s) or math.isnan(rate_f) and math.isnan(rate_s)


def test_modules_in_step_take_the_in_step_path(clock):
    """Three modules sending the same frames: every block after the first is built at once."""
    n = 200
    arrivals = [[(0.0005 + 0.002 * f + 1e-4 * k, legacy_packet(f, 1_767_225_600, 2_000_000 * f))
                 for f in range(1, n + 1)] for k in range(3)]
    driver = timed_driver(clock, arrivals)
    built: list[bool] = []
    in_step_block = driver._in_step_block

    def counted():
        block = in_step_block()
        built.append(block is not None)
        return block

    driver._in_step_block = counted  # type: ignore[method-assign]
    blocks = [b for b, _ in read_all(driver, clock)]
    np.testing.assert_array_equal(np.concatenate([b.counter for b in blocks]),
                                  np.arange(1, n + 1))
    # The first block sets the merge keys and the serial numbers: the general path.
    assert built[0] is False and all(built[1:]) and len(built) == len(blocks) >= 20
