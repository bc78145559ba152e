"""ILD1420 driver: settings, the word/block decoder, unwrapping, and scripted byte exchanges.

Byte sequences are written out by hand from docs/reference/wire_formats.md, "Laser displacement
sensors" (the manual's pp. 65-66, 84, 108): a value
is three bytes L = 00 D5..D0, M = 01 D11..D6, H = 1 f D17..D12 with f = 0 for the distance (the
first value of a block) and 1 for the additional values.
"""

from __future__ import annotations

import inspect
from unittest.mock import MagicMock

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from daq.errors import ConfigError, DeviceError, TransportTimeout
from daq.instruments import registry
from daq.instruments.microepsilon_ild1420.decoder import ERROR_CODES, Ild1420Decoder, error_reason
from daq.instruments.microepsilon_ild1420.driver import MicroEpsilonIld1420
from daq.instruments.microepsilon_ild1420.sequencer import Ild1420Sequencer
from daq.instruments.microepsilon_ild1420.settings import Ild1420Settings
from daq.instruments.reading import Gap
from daq.transports.scripted import expected_exchange

TABLE = {"range_mm": 10, "rate_hz": 4000.0, "x": 0.1, "standoff_mm": 5.0}

# Block 1 (bytes from docs/reference/wire_formats.md, "Laser displacement"): distance 32760 = 0x7FF8
# (0.5 MR), counter 262143,
# timestamp 0x0001_0002 ticks (low word first), status bits 15 (triggered) and 16.
BLOCK_1 = bytes.fromhex("38 7F 87  3F 7F FF  02 40 C0  01 40 C0  00 40 D8")
# Block 2: distance word 262077 = 0x3FFBD (peak before MR), counter 0 (wrapped), timestamp
# 0x0001_001B ticks, status bits 17 and 5 (red LED, before SMR).
BLOCK_2 = bytes.fromhex("3D 7E BF  00 40 C0  1B 40 C0  01 40 C0  20 40 E0")

OPEN_SCRIPT = [
    (b"MASTERMV NONE\r\n", b"MASTERMV NONE\r\n->"),
    (b"GETOUTINFO_RS422\r\n",
     b"GETOUTINFO_RS422\r\nGETOUTINFO_RS422 DIST1 COUNTER TIMESTAMP STATE\r\n->"),
    (b"OUTPUT RS422\r\n", b"OUTPUT RS422\r\n->"),
]


def encode(words: list[list[int]]) -> bytes:
    """Test-side encoder (a third, deliberately naive implementation of the wire format)."""
    out = bytearray()
    for block in words:
        for i, value in enumerate(block):
            flag = 0x40 if i else 0x00
            out += bytes([value & 0x3F, 0x40 | (value >> 6) & 0x3F,
                          0x80 | flag | (value >> 12) & 0x3F])
    return bytes(out)


def block_words(counter: int, ticks: int, distance: int = 32760, status: int = 0) -> list[int]:
    return [distance, counter % 262144, ticks & 0xFFFF, (ticks >> 16) & 0xFFFF, status]


def driver(transport: object, **table: object) -> MicroEpsilonIld1420:
    return MicroEpsilonIld1420(transport,  # type: ignore[arg-type]
                               Ild1420Settings.from_table({**TABLE, **table}, "test"))


# -- settings -----------------------------------------------------------------------------------
def test_settings_defaults_and_registry():
    """A minimal table gets the defaults; the registry validates [[lasers]] tables with it."""
    s = Ild1420Settings.from_table(TABLE, "[[lasers]] #0")
    assert (s.baudrate, s.output) == (921600, ("counter", "timestamp", "status"))
    assert s.values_per_block == 5 and s.bits_per_second == 33 * 5 * 4000
    assert s.line() == {"baudrate": 921600, "bytesize": 8, "parity": "N", "stopbits": 1}
    entry = registry.driver_entry("microepsilon_ild1420")
    assert entry.role == "lasers"
    assert registry.validate_settings("microepsilon_ild1420", "lasers", TABLE, "w") == s


@pytest.mark.parametrize(("change", "message"), [
    ({"range_mm": 30}, r"range_mm = 30 is not one of \[10, 25, 50, 100, 200, 500\]"),
    ({"range_mm": True}, "range_mm = True"),
    ({"rate_hz": 0.0}, r"rate_hz = 0.0 is outside the allowed range \(0.0, 4000.0\]"),
    ({"rate_hz": 4001}, r"rate_hz = 4001.0 is outside"),
    ({"x": 1.5}, r"x = 1.5 is outside the allowed range \[-1.0, 1.0\]"),
    ({"standoff_mm": 10.5}, r"standoff_mm = 10.5 is outside the allowed range \[0.0, 10.0\]"),
    ({"baudrate": 921600.0}, "baudrate must be an integer"),
    ({"baudrate": 100}, r"baudrate = 100 is outside \[9600, 1000000\]"),
    ({"output": ["counter", "timestamp", "status", "speed"]}, r"unknown value\(s\) \['speed'\]"),
    ({"output": ["counter", "counter", "timestamp", "status"]}, "names a value twice"),
    ({"output": ["counter", "timestamp"]}, r"lacks \['status'\]"),
    ({"colour": "red"}, r"unknown key\(s\) \['colour'\]"),
])
def test_settings_errors_name_the_key_and_range(change, message):
    with pytest.raises(ConfigError, match=message):
        Ild1420Settings.from_table({**TABLE, **change}, "[[lasers]] #0")


def test_baud_budget_is_checked():
    """33 bits x 7 values x 4 kHz = 924 kbit/s does not fit in 921.6 kBd: named, with numbers."""
    table = {**TABLE, "output": ["counter", "timestamp", "status", "exposure", "intensity"]}
    with pytest.raises(ConfigError, match=r"baudrate = 921600 is too low .* 924000 bit/s"):
        Ild1420Settings.from_table(table, "w")
    assert Ild1420Settings.from_table({**table, "baudrate": 1000000}, "w").values_per_block == 7
    with pytest.raises(ConfigError, match="baudrate = 115200 is too low"):
        Ild1420Settings.from_table({**TABLE, "baudrate": 115200}, "w")


# -- decoder ------------------------------------------------------------------------------------
def test_decoder_decodes_the_manual_words():
    """Distance, error value, counter, two-word timestamp and status bits, from hand-made bytes."""
    dec = Ild1420Decoder(range_mm=10)
    out = dec.feed(BLOCK_1 + BLOCK_2)
    # d = (102 x / 65520 - 1) MR / 100 with x = 32760: exactly MR / 2.
    assert out.distance_mm[0] == pytest.approx(5.0, abs=1e-12)
    assert np.isnan(out.distance_mm[1]) and list(out.error_code) == [0, 262077]
    assert list(out.counter) == [262143, 0]
    assert list(out.timestamp) == [0x10002, 0x1001B]
    assert list(out.status) == [0x18000, 0x20020]
    assert (dec.blocks_decoded, dec.bytes_skipped, dec.blocks_with_errors) == (2, 0, 1)
    assert error_reason(262077) == "peak before the measuring range" == ERROR_CODES[262077]


def test_decoder_range_ends_and_mastered_words():
    """Words 0 and 65520 are -0.01 MR and 1.01 MR; mastered words are 18-bit, shifted by 51."""
    dec = Ild1420Decoder(range_mm=100)
    out = dec.feed(encode([block_words(1, 0, distance=0), block_words(2, 0, distance=65520),
                           block_words(3, 0, distance=65521)]))
    np.testing.assert_allclose(out.distance_mm[:2], [-1.0, 101.0], atol=1e-9)
    assert out.error_code[2] == 65521 and np.isnan(out.distance_mm[2])
    mastered = Ild1420Decoder(range_mm=10, mastered=True)
    out = mastered.feed(encode([block_words(1, 0, distance=32760 * 3)]))
    # (102 * 98280 / 65520 - 51) * 10 / 100 = (153 - 51) / 10
    assert out.distance_mm[0] == pytest.approx(10.2)


def test_decoder_resynchronises_after_a_lost_byte_and_counts_skips():
    """A block missing one byte is dropped whole; the next block decodes; skips are counted."""
    blocks = [encode([block_words(c, 25 * c)]) for c in range(4)]
    damaged = blocks[1][:4] + blocks[1][5:]  # lose the M byte of the counter (mid-word)
    dec = Ild1420Decoder()
    out = dec.feed(blocks[0] + damaged + blocks[2] + blocks[3])
    assert list(out.counter) == [0, 2, 3]
    assert dec.bytes_skipped == 14 and dec.resyncs == 1
    # Starting mid-block (a port opened mid-stream) skips to the first whole block.
    dec = Ild1420Decoder()
    assert list(dec.feed(blocks[0][7:] + blocks[1]).counter) == [1]
    assert dec.bytes_skipped == 8


def test_decoder_keeps_an_unfinished_block_across_feeds():
    data = encode([block_words(c, 25 * c) for c in range(3)])
    dec = Ild1420Decoder()
    assert len(dec.feed(data[:20])) == 1 and dec.pending_bytes == 5
    assert list(dec.feed(data[20:]).counter) == [1, 2]
    assert dec.bytes_skipped == 0
    assert dec.reset() == 0


@settings(deadline=None, max_examples=150, database=None)
@given(st.binary(max_size=600), st.lists(st.integers(0, 600), max_size=8))
def test_decoder_never_fails_on_garbage_and_accounts_for_every_byte(data, cuts):
    """Any bytes, cut anywhere: no exception, and every byte is decoded, skipped or pending."""
    dec = Ild1420Decoder(("counter", "timestamp", "status", "exposure"))
    pieces = [data[a:b] for a, b in zip([0, *sorted(cuts)], [*sorted(cuts), len(data)],
                                        strict=True)]
    n = sum(len(dec.feed(p)) for p in pieces)
    assert n == dec.blocks_decoded
    assert dec.bytes_received == len(data)
    assert n * dec.block_bytes + dec.bytes_skipped + dec.pending_bytes == len(data)
    assert dec.pending_bytes < dec.block_bytes


@settings(deadline=None, max_examples=150, database=None)
@given(st.binary(max_size=300), st.integers(1, 6), st.integers(0, 262143),
       st.integers(1, 40))
def test_decoder_resynchronises_on_the_next_valid_block_after_garbage(garbage, k, c0, chunk):
    """After garbage, every following valid block is decoded exactly, whatever the chunking."""
    words = [block_words(c0 + i, 25 * (c0 + i), distance=(1000 * i) % 65521, status=i)
             for i in range(k)]
    data = garbage + encode(words)
    dec = Ild1420Decoder()
    parts = [dec.feed(data[i:i + chunk]) for i in range(0, len(data), chunk)]
    counters = np.concatenate([p.counter for p in parts if p.counter is not None])
    statuses = np.concatenate([p.status for p in parts if p.status is not None])
    # Garbage may itself hold block-shaped bytes (decoded first); the real blocks come last.
    assert list(counters[-k:]) == [(c0 + i) % 262144 for i in range(k)]
    assert list(statuses[-k:]) == list(range(k))
    assert dec.pending_bytes == 0


# -- sequencer ----------------------------------------------------------------------------------
def ns(n: int, t0: int = 0) -> np.ndarray:
    return np.full(n, t0, dtype=np.int64)


def test_sequencer_unwraps_counter_and_timestamp_and_marks_gaps():
    seq = Ild1420Sequencer(rate_hz=4000.0)
    c = np.array([262142, 262143, 0, 1, 5])  # wrap, then 3 samples lost after 1
    ts = (np.array([-2, -1, 0, 1, 5]) * 25 + (1 << 32) - 10) % (1 << 32)  # wraps too
    counter, t, epoch, gaps = seq.process(c, ts, ns(5))
    assert list(counter) == [262142, 262143, 262144, 262145, 262149]
    # Device times near 42950 s: float64 spacing there is 7e-12 s, hence atol.
    np.testing.assert_allclose(np.diff(t), [25e-5, 25e-5, 25e-5, 100e-5], atol=1e-10)
    assert gaps == [Gap(after_counter=262145, length=3)] and set(epoch) == {0}
    # The next batch continues from the state; a lost block across batches is a gap too.
    counter, t, _, gaps = seq.process(np.array([7]), ts[-1:] + 50, ns(1))
    assert list(counter) == [262151] and gaps == [Gap(262149, 1)]


@settings(max_examples=80, deadline=None, database=None)
@given(st.one_of(st.integers((1 << 18) - 600, (1 << 18) - 1), st.integers(0, (1 << 18) - 1)),
       st.one_of(st.integers((1 << 32) - 30_000, (1 << 32) - 1), st.integers(0, (1 << 32) - 1)),
       st.lists(st.integers(1, 300), min_size=1, max_size=8), st.sets(st.integers(0, 1500)),
       st.sets(st.integers(0, 1500), max_size=2))
def test_sequencer_shortcut_for_consecutive_batches_equals_the_general_path(c0, ts0, sizes,
                                                                           lost, jumps):
    """The consecutive-batch shortcut gives the general path's counters, times and gaps.

    Batches that continue sample by sample (counter and timestamp wraps included) take it;
    lost samples and long timestamp jumps send a batch the general way.
    """
    n = sum(sizes) + len(lost)
    keep = np.array([i not in lost for i in range(n)])
    ticks = np.cumsum(np.where(np.isin(np.arange(n), list(jumps)), 2_000_000, 25))
    counter = ((c0 + np.arange(n)) % (1 << 18))[keep]
    timestamp = ((ts0 + ticks) % (1 << 32))[keep]
    host = (np.arange(n) * 250_000)[keep]

    def run(shortcut: bool) -> list:
        seq = Ild1420Sequencer(rate_hz=4000.0)
        if not shortcut:
            seq._consecutive = lambda *args: None  # type: ignore[method-assign]
        out, start = [], 0
        for size in sizes:
            sl = slice(start, start + size)
            if counter[sl].size:
                out.append(seq.process(counter[sl], timestamp[sl], host[sl]))
            start += size
        return out

    for (c1, t1, e1, g1), (c2, t2, e2, g2) in zip(run(True), run(False), strict=True):
        np.testing.assert_array_equal(c1, c2)
        np.testing.assert_array_equal(t1, t2)
        np.testing.assert_array_equal(e1, e2)
        assert g1 == g2


def test_sequencer_resolves_a_gap_longer_than_the_counter_period_with_the_timestamp():
    seq = Ild1420Sequencer(rate_hz=4000.0)
    seq.process(np.array([10]), np.array([1000]), ns(1))
    skipped = 262144 + 3  # 65.5 s at 4 kHz: the counter alone would say 3
    counter, _, _, gaps = seq.process(np.array([(10 + skipped + 1) % 262144]),
                                      np.array([1000 + 25 * (skipped + 1)]), ns(1))
    assert gaps == [Gap(10, skipped)] and counter[0] == 10 + skipped + 1


def test_sequencer_detects_a_restart_and_estimates_the_gap_from_host_time():
    """The timestamp going backwards is a restart: new epoch, gap estimated (not exact)."""
    seq = Ild1420Sequencer(rate_hz=1000.0)
    seq.process(np.array([500, 501]), np.array([900000, 900100]), ns(2, 0))
    counter, t, epoch, gaps = seq.process(np.array([0, 1]), np.array([0, 100]),
                                          ns(2, 300_000_000))
    # 0.3 s at 1 kHz: about 299 samples between the last old and the first new one.
    assert gaps == [Gap(after_counter=501, length=299, kind="restart")]
    assert list(counter) == [801, 802] and list(epoch) == [1, 1]
    np.testing.assert_allclose(t, [0.0, 1e-3])


def test_sequencer_checks_continuity_after_a_reconnect():
    """After a reconnect a step inconsistent with the host time is a restart, else a plain gap."""
    seq = Ild1420Sequencer(rate_hz=1000.0)
    seq.process(np.array([10]), np.array([5_000_000]), ns(1, 0))
    seq.expect_discontinuity()  # 2 s later: counter +2000, timestamp +2 s: the line just dropped
    _, _, epoch, gaps = seq.process(np.array([2010]), np.array([5_200_000]), ns(1, 2 * 10**9))
    assert gaps == [Gap(10, 1999)] and epoch[0] == 0
    seq.expect_discontinuity()  # 1 s later the timestamp claims 60 s: a restart
    _, _, epoch, gaps = seq.process(np.array([20]), np.array([11_200_000]), ns(1, 3 * 10**9))
    assert epoch[0] == 1 and gaps[0].exact is False and gaps[0].length == 999


# -- driver, scripted bytes ---------------------------------------------------------------------
def test_constructor_does_no_io_and_rejects_unknown_keywords():
    transport = MagicMock()
    drv = driver(transport)
    assert transport.mock_calls == [] and not drv.is_open
    with pytest.raises(TypeError):
        MicroEpsilonIld1420(transport, drv.settings, speed=3)  # type: ignore[call-arg]


def test_property_docstrings_follow_the_verb_rule():
    for name, member in inspect.getmembers(MicroEpsilonIld1420):
        if isinstance(member, property):
            assert member.__doc__.split()[0] in ("Measure", "Control"), name


def test_open_then_read_the_manual_blocks():
    """open(): MASTERMV NONE, GETOUTINFO_RS422 check, OUTPUT RS422; then two decoded samples."""
    with expected_exchange([*OPEN_SCRIPT, (b"", BLOCK_1 + BLOCK_2)]) as t:
        drv = driver(t)
        drv.open()
        block = drv.read(timeout_s=0.5)
        assert set(block.channels) == set(drv.describe())
        distance = block.channels["distance"]
        assert distance[0] == pytest.approx(0.005) and np.isnan(distance[1])
        assert list(block.channels["error_code"]) == [0, 262077]
        assert [error_reason(int(c)) for c in block.channels["error_code"]] == [
            "", "peak before the measuring range"]
        assert list(block.counter) == [262143, 262144]  # unwrapped across the 18-bit wrap
        np.testing.assert_allclose(block.device_time, [0x10002 * 1e-5, 0x1001B * 1e-5])
        assert list(block.channels["triggered"]) == [True, False] and block.gaps == ()
        assert block.host_time_ns.dtype == np.int64 and block.host_time_ns[0] > 0
        for key, spec in drv.describe().items():
            assert block.channels[key].dtype == np.dtype(spec["dtype"]), key
        with pytest.raises(TransportTimeout, match="no ILD1420 block"):
            drv.read(timeout_s=0.01)
        drv.close()
        drv.close()  # idempotent


def test_gaps_are_reported_with_their_length():
    stream = encode([block_words(c, 25 * c) for c in (100, 101, 105, 106)])
    with expected_exchange([*OPEN_SCRIPT, (b"", stream)]) as t:
        drv = driver(t)
        drv.open()
        block = drv.read(0.5)
        assert list(block.counter) == [100, 101, 105, 106]
        assert block.gaps == (Gap(after_counter=101, length=3),)


def test_command_replies_inside_the_stream_lose_no_samples():
    """Blocks before the echo and after the prompt are all decoded (bytes from the wire format)."""
    before = encode([block_words(c, 25 * c) for c in (1, 2)])
    after = encode([block_words(c, 25 * c) for c in (3, 4)])
    reply = before + b"GETINFO\r\nName: ILD1420-10\r\nMeasuring range: 10.00mm\r\n->" + after
    with expected_exchange([*OPEN_SCRIPT, (b"GETINFO\r\n", reply)]) as t:
        drv = driver(t)
        drv.open()
        assert drv.info() == {"Name": "ILD1420-10", "Measuring range": "10.00mm"}
        block = drv.read(0.5)
        assert list(block.counter) == [1, 2, 3, 4] and drv.bytes_skipped == 0


def test_error_replies_raise_device_error_and_master_switches_decoding():
    """E104 Timeout (manual p. 108) raises; a successful MASTERMV switches to 18-bit words."""
    mastered_block = encode([block_words(7, 175, distance=64235)])
    with expected_exchange([
        *OPEN_SCRIPT,
        (b"MASTERMV MASTER 5.000000\r\n", b"MASTERMV MASTER 5.000000\r\nE104 Timeout\r\n->"),
        (b"MASTERMV MASTER 5.000000\r\n", b"MASTERMV MASTER 5.000000\r\n->" + mastered_block),
    ]) as t:
        drv = driver(t)
        drv.open()
        with pytest.raises(DeviceError, match="E104 Timeout"):
            drv.master(5.0)
        assert not drv.mastered
        drv.master(5.0)
        assert drv.mastered
        # (102 * 64235 / 65520 - 51) * 10 / 100 mm
        assert drv.read(0.5).channels["distance"][0] == pytest.approx(
            (102 * 64235 / 65520 - 51) * 1e-4, abs=1e-12)
        with pytest.raises(ValueError, match="outside"):
            drv.master(25.0)


def test_open_refuses_a_sensor_whose_output_differs_from_the_config():
    script = [OPEN_SCRIPT[0], (b"GETOUTINFO_RS422\r\n",
                               b"GETOUTINFO_RS422\r\nGETOUTINFO_RS422 DIST1 COUNTER STATE\r\n->")]
    with expected_exchange(script) as t:
        drv = driver(t)
        with pytest.raises(ConfigError, match=r"sensor sends \['distance', 'counter', 'status'\]"):
            drv.open()
        assert not drv.is_open and not t.is_open


def test_a_missing_prompt_times_out():
    with expected_exchange([(b"MASTERMV NONE\r\n", b"MASTERMV NONE\r\n")]) as t:
        drv = driver(t)
        drv._open = True  # skip open(): exercise one command
        drv.command_timeout_s = 0.05
        with pytest.raises(TransportTimeout, match="no reply to 'MASTERMV NONE'"):
            drv.unmaster()


def test_exposure_and_intensity_when_selected():
    """ET[us] = x / 10 and I[%] = 100 x / 65472 (manual p. 65), in the configured block order."""
    output = ["intensity", "counter", "timestamp", "status", "exposure"]
    script = [OPEN_SCRIPT[0],
              (b"GETOUTINFO_RS422\r\n", b"GETOUTINFO_RS422\r\nGETOUTINFO_RS422 DIST1 INTENSITY "
                                        b"COUNTER TIMESTAMP STATE SHUTTER\r\n->"),
              OPEN_SCRIPT[2],
              (b"", encode([[32760, 65472, 3, 75, 0, 0, 5000], [32760, 32736, 4, 100, 0, 0, 1]]))]
    with expected_exchange(script) as t:
        drv = driver(t, output=output, baudrate=1000000)
        drv.open()
        block = drv.read(0.5)
    assert set(block.channels) == set(drv.describe()) >= {"exposure", "intensity"}
    np.testing.assert_allclose(block.channels["intensity"], [100.0, 50.0])
    np.testing.assert_allclose(block.channels["exposure"], [500e-6, 0.1e-6])
    assert list(block.counter) == [3, 4]
