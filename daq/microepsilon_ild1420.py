r"""Driver for the Micro-Epsilon optoNCDT ILD1420-class laser displacement sensor (RS-422).

Responsibility: the sensor's byte protocol (DEVICES.md A.2.1) and its rig-config settings. It
validates the ``[[lasers]]`` table (:class:`Ild1420Settings`), decodes the binary stream of 3-byte
words into blocks (:class:`Ild1420Decoder`, pure, no I/O), unwraps the 18-bit counter and the
32-bit timestamp, marks gaps and device restarts (:class:`Ild1420Sequencer`, pure), talks the
ASCII command set (``GETOUTINFO_RS422``, ``MASTERMV``, ``OUTPUT``, ``GETINFO``) and reconnects
with a bounded backoff when the line drops (:class:`MicroEpsilonIld1420`).

Not responsible for: opening ports (the transport is injected, see :mod:`daq.transport`;
:meth:`Ild1420Settings.line` gives its serial settings), converting distances into heave and
pitch (the acquisition does that with the ``x`` and ``standoff_mm`` settings), mapping the device
clock onto the host clock (the synchronisation), or threads and queues (the acquisition runs one
reader thread per sensor).

Manual facts (DEVICES.md A.2.1) and the choices made beyond them:

- 921.6 kBd 8N1 by default; one value is three bytes ``L = 00 D5..D0``, ``M = 01 D11..D6``,
  ``H = 1 f D17..D12``; ``f = 0`` for the first value of a block (the distance), 1 for the
  additional values. A block is the distance followed by the additional values in the order the
  sensor reports with ``GETOUTINFO_RS422`` (the ``output`` setting).
- Distance without mastering: 16 bits, ``d[mm] = (102 x / 65520 - 1) MR / 100``; with mastering:
  18 bits, ``d[mm] = (102 x / 65520 - 51) MR / 100``. Error values 262075..262082 replace the
  distance; they decode to NaN and the value is kept per sample as ``error_code``.
- Counter 18 bits (wraps at 262144); timestamp two 16-bit words, ``t[ms] = (65536 y + x) / 100``;
  [unverified] the low word ``x`` is sent before the high word ``y``. Status 18 bits, bit 15 =
  "value triggered". Exposure ``ET[us] = x / 10``; intensity ``I[%] = 100 x / 65472``.
- ASCII commands; "after processing a command always a return and a prompt (``->``) is returned",
  errors ``Exxx <text>`` before the prompt, warnings ``Wxxx`` (Micro-Epsilon ILD1320/1420 manual,
  A 3.1). [unverified] framing used here: the host sends ``<command>\r\n``; the sensor echoes
  ``<command>\r\n`` (ECHO ON), then reply lines each ending ``\r\n``, then ``->``; the reply
  sits between two binary blocks; the output names of ``GETOUTINFO_RS422`` are ``DIST1``,
  ``COUNTER``, ``TIMESTAMP``, ``STATE``, ``SHUTTER``, ``INTENSITY``.
- ``MASTERMV`` waits up to 2 s for the next value, else replies ``E104 Timeout``. [unverified] the
  first block after the reply of a successful ``MASTERMV`` is the first mastered one.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from daq.config import check_keys, number
from daq.errors import ConfigError, DeviceError, ProtocolError, TransportError, TransportTimeout
from daq.registry import DriverEntry, register
from daq.transport import Transport

__all__ = [
    "DEFAULT_OUTPUT",
    "ERROR_CODES",
    "Gap",
    "Ild1420Decoder",
    "Ild1420Samples",
    "Ild1420Sequencer",
    "Ild1420Settings",
    "LaserBlock",
    "MicroEpsilonIld1420",
    "error_reason",
]

log = logging.getLogger(__name__)

#: Measuring ranges of the ILD1420 family, mm (DEVICES.md A.2.1).
RANGES_MM: Final = (10, 25, 50, 100, 200, 500)
#: Highest measuring rate, Hz ("The maximum measuring rate is 4 kHz", A.2.1).
MAX_RATE_HZ: Final = 4000.0
#: Factory baud rate (A.2.1).
DEFAULT_BAUDRATE: Final = 921600
#: Baud rates accepted [unverified: the manual lists 9.6 kBd ... 1 MBd; only the bounds are used].
BAUDRATE_RANGE: Final = (9600, 1000000)
#: Line bits per value: 3 bytes x (start + 8 data + stop) (8N1; the ILD2300 sizing rule, A.2.2).
BITS_PER_VALUE: Final = 33
#: Default additional values, in block order.
DEFAULT_OUTPUT: Final = ("counter", "timestamp", "status")
#: Additional values the stream contract needs (gaps, device time, trigger flag).
REQUIRED_OUTPUT: Final = frozenset(DEFAULT_OUTPUT)
#: Words per additional value (the timestamp is two 16-bit words, A.2.1).
WORDS_PER_VALUE: Final = {"counter": 1, "timestamp": 2, "status": 1, "exposure": 1, "intensity": 1}
#: Names of the values in GETOUTINFO_RS422 replies [unverified].
OUTPUT_NAMES: Final = {"distance": "DIST1", "counter": "COUNTER", "timestamp": "TIMESTAMP",
                       "status": "STATE", "exposure": "SHUTTER", "intensity": "INTENSITY"}
#: Error values inside the distance word (A.2.1, manual p. 66).
ERROR_CODES: Final = {
    262075: "data amount too big for the selected baud rate",
    262076: "no peak available",
    262077: "peak before the measuring range",
    262078: "peak behind the measuring range",
    262080: "measurement value cannot be calculated",
    262081: "peak too large",
    262082: "laser is off",
}
COUNTER_MODULUS: Final = 1 << 18
TIMESTAMP_MODULUS: Final = 1 << 32
#: Timestamp resolution, s (t[ms] = ticks / 100).
TIMESTAMP_TICK_S: Final = 1e-5
STATUS_TRIGGERED: Final = 1 << 15
#: Largest 16-bit distance value (end of the EMR reserve) and first 18-bit error value.
MAX_DISTANCE_16: Final = 65520
FIRST_ERROR_VALUE: Final = 262075

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


def error_reason(code: int) -> str:
    """Return the manual's text for a distance error value (``""`` for 0, i.e. no error)."""
    if code == 0:
        return ""
    if code in ERROR_CODES:
        return ERROR_CODES[code]
    return f"not a distance value ({code})"


# ------------------------------------------------------------------------------------------------
# Settings
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Ild1420Settings:
    """Validated settings of one ILD1420 laser (a ``[[lasers]]`` table without driver/url/name).

    Attributes
    ----------
    range_mm : int
        Measuring range MR, mm: one of 10, 25, 50, 100, 200, 500.
    rate_hz : float
        Measuring rate, Hz, in (0, 4000].
    x : float
        Chord position of the laser spot, m, in [-1, 1], positive downstream of the elastic axis.
    standoff_mm : float
        Distance reading at the model's rest position, mm, within [0, MR].
    baudrate : int
        RS-422 baud rate, in [9600, 1000000]; default 921600.
    output : tuple of str
        Additional values in block order; must contain ``counter``, ``timestamp`` and ``status``,
        may add ``exposure`` and ``intensity``. ``33 bits x values x rate_hz`` must fit in
        ``baudrate`` (else the sensor sends 262075).
    """

    range_mm: int
    rate_hz: float
    x: float
    standoff_mm: float
    baudrate: int = DEFAULT_BAUDRATE
    output: tuple[str, ...] = DEFAULT_OUTPUT

    def __post_init__(self) -> None:
        _validate_settings(where="ILD1420 settings", range_mm=self.range_mm,
                           rate_hz=self.rate_hz, x=self.x, standoff_mm=self.standoff_mm,
                           baudrate=self.baudrate, output=self.output)

    @classmethod
    def from_table(cls, table: Mapping[str, Any], where: str) -> Ild1420Settings:
        """Validate a rig-config table; raise ConfigError naming the key and its allowed range."""
        check_keys(table, where, {"range_mm", "rate_hz", "x", "standoff_mm"},
                   {"baudrate", "output"})
        range_mm = table["range_mm"]
        if (isinstance(range_mm, bool) or not isinstance(range_mm, (int, float))
                or range_mm not in RANGES_MM):
            raise ConfigError(f"{where} range_mm = {range_mm!r} is not one of {list(RANGES_MM)}")
        baudrate = table.get("baudrate", DEFAULT_BAUDRATE)
        if isinstance(baudrate, bool) or not isinstance(baudrate, int):
            raise ConfigError(f"{where} baudrate must be an integer, got {baudrate!r}")
        output = table.get("output", list(DEFAULT_OUTPUT))
        if not isinstance(output, (list, tuple)) or not all(isinstance(o, str) for o in output):
            raise ConfigError(f"{where} output must be a list of names, got {output!r}")
        settings: dict[str, Any] = {
            "range_mm": int(range_mm),
            "rate_hz": number(table, "rate_hz", where, lo=0.0, hi=MAX_RATE_HZ, lo_open=True),
            "x": number(table, "x", where, lo=-1.0, hi=1.0),
            "standoff_mm": number(table, "standoff_mm", where, lo=0.0, hi=float(range_mm)),
            "baudrate": baudrate,
            "output": tuple(output),
        }
        _validate_settings(where=where, **settings)
        return cls(**settings)

    @property
    def values_per_block(self) -> int:
        """Measure the number of 3-byte values in one block (distance plus additional values)."""
        return 1 + sum(WORDS_PER_VALUE[name] for name in self.output)

    @property
    def bits_per_second(self) -> float:
        """Measure the line load the settings need, bit/s (33 bits per value, 8N1)."""
        return BITS_PER_VALUE * self.values_per_block * self.rate_hz

    def line(self) -> dict[str, Any]:
        """Return the serial settings for :func:`daq.transport.open_transport` (8N1)."""
        return {"baudrate": self.baudrate, "bytesize": 8, "parity": "N", "stopbits": 1}


def _validate_settings(*, where: str, range_mm: Any, rate_hz: Any, x: Any, standoff_mm: Any,
                       baudrate: Any, output: Any) -> None:
    """Check every setting (shared by ``from_table`` and direct construction)."""
    if isinstance(range_mm, bool) or range_mm not in RANGES_MM:
        raise ConfigError(f"{where} range_mm = {range_mm!r} is not one of {list(RANGES_MM)}")
    if not (isinstance(rate_hz, (int, float)) and 0.0 < rate_hz <= MAX_RATE_HZ):
        raise ConfigError(f"{where} rate_hz = {rate_hz!r} is outside (0, {MAX_RATE_HZ}]")
    if not (isinstance(x, (int, float)) and -1.0 <= x <= 1.0):
        raise ConfigError(f"{where} x = {x!r} m is outside [-1, 1]")
    if not (isinstance(standoff_mm, (int, float)) and 0.0 <= standoff_mm <= range_mm):
        raise ConfigError(f"{where} standoff_mm = {standoff_mm!r} is outside the measuring "
                          f"range [0, {range_mm}]")
    lo, hi = BAUDRATE_RANGE
    if isinstance(baudrate, bool) or not isinstance(baudrate, int) or not lo <= baudrate <= hi:
        raise ConfigError(f"{where} baudrate = {baudrate!r} is outside [{lo}, {hi}] (integer)")
    if not isinstance(output, tuple) or not all(isinstance(o, str) for o in output):
        raise ConfigError(f"{where} output must be a tuple of names, got {output!r}")
    unknown = [o for o in output if o not in WORDS_PER_VALUE]
    if unknown:
        raise ConfigError(f"{where} output: unknown value(s) {unknown}; allowed: "
                          f"{sorted(WORDS_PER_VALUE)}")
    if len(set(output)) != len(output):
        raise ConfigError(f"{where} output = {list(output)} names a value twice")
    missing = sorted(REQUIRED_OUTPUT - set(output))
    if missing:
        raise ConfigError(f"{where} output = {list(output)} lacks {missing}: the stream needs "
                          "the counter (gaps), the timestamp (device time) and the status "
                          "(trigger flag)")
    values = 1 + sum(WORDS_PER_VALUE[name] for name in output)
    needed = BITS_PER_VALUE * values * rate_hz
    if needed > baudrate:
        raise ConfigError(
            f"{where} baudrate = {baudrate} is too low for rate_hz = {rate_hz:g} with {values} "
            f"values per block: 33 bits x {values} x {rate_hz:g} Hz = {needed:.0f} bit/s "
            f"(the sensor would send 262075, 'data amount too big for the selected baud rate')"
        )


# ------------------------------------------------------------------------------------------------
# Decoder (pure)
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Ild1420Samples:
    """Decoded samples of a byte chunk (raw device values, not yet unwrapped).

    Attributes
    ----------
    distance_mm : ndarray of float64, shape (n,)
        Distance, mm; NaN where the sensor sent an error value.
    error_code : ndarray of int32, shape (n,)
        The error value (262075..262082, or any other non-distance value), 0 where valid.
    counter, timestamp, status, exposure, intensity : ndarray of int64, shape (n,), or None
        Raw additional values (counter 18-bit, timestamp in 10 us ticks mod 2**32, status bits,
        exposure in 0.1 us, intensity in 1/65472); None when not in the block layout.
    """

    distance_mm: FloatArray
    error_code: npt.NDArray[np.int32]
    counter: IntArray | None = None
    timestamp: IntArray | None = None
    status: IntArray | None = None
    exposure: IntArray | None = None
    intensity: IntArray | None = None

    def __len__(self) -> int:
        return int(self.distance_mm.shape[0])

    @staticmethod
    def concatenate(parts: Sequence[Ild1420Samples]) -> Ild1420Samples:
        """Join decoded chunks in order (all from one layout)."""
        def cat(name: str) -> Any:
            arrays = [getattr(p, name) for p in parts]
            return None if arrays[0] is None else np.concatenate(arrays)
        return Ild1420Samples(**{name: cat(name) for name in (
            "distance_mm", "error_code", "counter", "timestamp", "status", "exposure",
            "intensity")})


class Ild1420Decoder:
    """Turn the sensor's byte stream into samples; resynchronise on the marker bits.

    Feed it bytes in chunks of any size; it returns the samples of every complete block and keeps
    the bytes of an unfinished one. A block is ``3 x values`` bytes whose top two bits follow the
    pattern ``00 01 10`` (first value: distance, ``f = 0``) then ``00 01 11`` for each additional
    value (DEVICES.md A.2.1). A byte that breaks the pattern (lost or inserted byte, a start
    mid-block) makes it skip forward to the next position where a whole block pattern starts; the
    skipped bytes are counted. It never raises on any input and always consumes what it is given.

    The protocol has no checksum: an inserted byte of the right class exactly in front of a
    genuine one of the same class is indistinguishable from it, and the value it lands in is wrong
    in its low bits. Lost bytes always cost the damaged block (the counter marks the gap).

    Parameters
    ----------
    output : sequence of str
        Additional values in block order (see :class:`Ild1420Settings`); need not contain the
        required ones (for tests and benchmarks).
    range_mm : int
        Measuring range MR, mm.
    mastered : bool
        Whether the sensor is mastered (18-bit distance with the shift of 51).
    """

    #: Rows checked at once on the fast path (bounds the cost of each resynchronisation).
    _CHUNK_ROWS = 8192
    #: Candidate start positions examined at once while resynchronising.
    _SCAN_WINDOW = 4096

    def __init__(self, output: Sequence[str] = DEFAULT_OUTPUT, *, range_mm: int = 10,
                 mastered: bool = False) -> None:
        unknown = [o for o in output if o not in WORDS_PER_VALUE]
        if unknown or len(set(output)) != len(output):
            raise ValueError(f"output must name distinct values of {sorted(WORDS_PER_VALUE)}, "
                             f"got {list(output)}")
        if range_mm not in RANGES_MM:
            raise ValueError(f"range_mm must be one of {list(RANGES_MM)}, got {range_mm!r}")
        self.output = tuple(output)
        self.range_mm = int(range_mm)
        self.mastered = bool(mastered)
        self.values_per_block = 1 + sum(WORDS_PER_VALUE[o] for o in self.output)
        self.block_bytes = 3 * self.values_per_block
        # Top-two-bit class of each byte of a block: L = 0, M = 1, H(first) = 2, H(other) = 3.
        self._pattern = np.array([0, 1, 2] + [0, 1, 3] * (self.values_per_block - 1),
                                 dtype=np.uint8)
        columns: dict[str, int] = {}
        column = 1
        for name in self.output:
            columns[name] = column
            column += WORDS_PER_VALUE[name]
        self._columns = columns
        self._pending = b""
        #: Bytes fed in total.
        self.bytes_received = 0
        #: Bytes dropped because they did not belong to a whole block.
        self.bytes_skipped = 0
        #: Times the decoder lost and searched for the block pattern.
        self.resyncs = 0
        #: Blocks decoded.
        self.blocks_decoded = 0
        #: Blocks whose distance was an error value.
        self.blocks_with_errors = 0

    @property
    def pending_bytes(self) -> int:
        """Measure how many bytes of an unfinished block are held back."""
        return len(self._pending)

    def reset(self) -> int:
        """Forget the unfinished block (after a reconnect); return the bytes dropped (counted)."""
        dropped = len(self._pending)
        self.bytes_skipped += dropped
        self._pending = b""
        return dropped

    def feed(self, data: bytes) -> Ild1420Samples:
        """Decode ``data`` (appended to any unfinished block); return the complete samples."""
        self.bytes_received += len(data)
        buf = self._pending + bytes(data)
        arr = np.frombuffer(buf, dtype=np.uint8)
        cls = arr >> 6
        n, size = arr.size, self.block_bytes
        pos = 0
        good: list[npt.NDArray[np.uint8]] = []
        while n - pos >= size:
            k = min((n - pos) // size, self._CHUNK_ROWS)
            rows = cls[pos:pos + k * size].reshape(k, size)
            bad = np.flatnonzero((rows != self._pattern).any(axis=1))
            ok = k if bad.size == 0 else int(bad[0])
            if ok:
                good.append(arr[pos:pos + ok * size].reshape(ok, size))
                pos += ok * size
            if ok == k:
                continue
            start = self._find_start(cls, pos + 1)
            self.bytes_skipped += start - pos
            self.resyncs += 1
            pos = start
        if pos < n:  # fewer than a block left: keep it only if it is a block's beginning
            start = self._find_start(cls, pos)
            if start > pos:
                self.bytes_skipped += start - pos
                self.resyncs += 1
            pos = start
        self._pending = buf[pos:]
        rows_all = (np.concatenate(good) if good
                    else np.empty((0, size), dtype=np.uint8))
        return self._convert(rows_all)

    def _find_start(self, cls: npt.NDArray[Any], start: int) -> int:
        """First index >= start where the block pattern begins (whole, or cut by the end)."""
        n, size, pattern = cls.size, self.block_bytes, self._pattern
        i = start
        while i < n:
            stop = min(n, i + self._SCAN_WINDOW)
            width = stop - i
            segment = cls[i:min(n, stop + size - 1)]
            match = np.ones(width, dtype=bool)
            for q in range(size):
                part = segment[q:q + width]
                # Positions whose block would run past the data compare only what exists.
                match[:part.size] &= part == pattern[q]
            hits = np.flatnonzero(match)
            if hits.size:
                return i + int(hits[0])
            i = stop
        return n

    def _convert(self, rows: npt.NDArray[np.uint8]) -> Ild1420Samples:
        """Assemble 18-bit words (L | M << 6 | H << 12) and convert them (A.2.1)."""
        count = rows.shape[0]
        self.blocks_decoded += count
        low = (rows[:, 0::3] & 0x3F).astype(np.int64)
        mid = (rows[:, 1::3] & 0x3F).astype(np.int64)
        high = (rows[:, 2::3] & 0x3F).astype(np.int64)
        words = low | (mid << 6) | (high << 12)
        raw = words[:, 0]
        if self.mastered:
            valid = raw < FIRST_ERROR_VALUE
            shift = 51.0
        else:
            valid = raw <= MAX_DISTANCE_16
            shift = 1.0
        distance = np.where(valid, (102.0 * raw / 65520.0 - shift) * self.range_mm / 100.0,
                            np.nan)
        code = np.where(valid, 0, raw).astype(np.int32)
        self.blocks_with_errors += int(count - np.count_nonzero(valid))
        extra: dict[str, IntArray] = {}
        for name, column in self._columns.items():
            if name == "timestamp":
                extra[name] = (words[:, column] & 0xFFFF) | ((words[:, column + 1] & 0xFFFF) << 16)
            else:
                extra[name] = words[:, column]
        return Ild1420Samples(distance_mm=distance, error_code=code, **extra)


# ------------------------------------------------------------------------------------------------
# Counter / timestamp unwrapping, gaps and restarts (pure)
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Gap:
    """Samples missing from the stream.

    Attributes
    ----------
    after_counter : int
        Unwrapped counter of the last sample before the gap.
    length : int
        Number of samples missing.
    exact : bool
        True when counted from the device counter; False when the sensor restarted (counter and
        timestamp began again) and the length is estimated from the host time and ``rate_hz``.
    """

    after_counter: int
    length: int
    exact: bool = True


class Ild1420Sequencer:
    """Unwrap the 18-bit counter and the 32-bit timestamp across chunks; find gaps and restarts.

    Within one epoch (one run of the sensor since power-on) counter steps are taken modulo 2**18
    and timestamp steps modulo 2**32; a counter step that disagrees with the timestamp step by a
    whole number of counter periods (a gap longer than 2**18 samples) is corrected with the
    timestamp. A timestamp that goes backwards is a restart: a new epoch begins, the unwrapped
    counter continues after an estimated gap (host time x ``rate_hz``), and the device time
    restarts with the device. After a reconnect the first step is also checked against the host
    time elapsed, so a restart that happened while the line was down is found.

    Parameters
    ----------
    rate_hz : float
        Nominal measuring rate, Hz (to resolve counter wraps and estimate restart gaps).
    """

    #: Slack when checking a step against the host time elapsed, s.
    RESTART_SLACK_S = 1.0

    def __init__(self, rate_hz: float) -> None:
        self.rate_hz = float(rate_hz)
        self.epoch = 0
        self._last: tuple[int, int, int, int, int] | None = None  # raw c, raw ts, c, ticks, ns
        self._check_next = False

    def expect_discontinuity(self) -> None:
        """Check the next step against the host time (call after a reconnect)."""
        self._check_next = True

    def process(self, counter: IntArray, timestamp: IntArray, host_ns: IntArray,
                ) -> tuple[IntArray, FloatArray, npt.NDArray[np.int32], list[Gap]]:
        """Unwrap one batch; return (counter, device time s, epoch per sample, gaps).

        ``counter`` and ``timestamp`` are the raw values, ``host_ns`` the arrival times (ns).
        """
        n = int(counter.size)
        out_c = np.empty(n, dtype=np.int64)
        out_t = np.empty(n, dtype=np.int64)
        epochs = np.empty(n, dtype=np.int32)
        gaps: list[Gap] = []
        if n == 0:
            return out_c, out_t.astype(np.float64), epochs, gaps
        first_ever = self._last is None
        if self._last is None:
            prev = (int(counter[0]), int(timestamp[0]), 0, 0, int(host_ns[0]))
        else:
            prev = self._last
        raw_c = np.concatenate(([prev[0]], counter))
        ns = np.concatenate(([prev[4]], host_ns))
        dc = np.diff(raw_c) % COUNTER_MODULUS
        dt = np.diff(np.concatenate(([prev[1]], timestamp))) % TIMESTAMP_MODULUS
        # A gap longer than a counter period: the timestamp tells how many periods passed.
        expected = dt * (TIMESTAMP_TICK_S * self.rate_hz)
        dc = dc + COUNTER_MODULUS * np.maximum(
            np.round((expected - dc) / COUNTER_MODULUS), 0).astype(np.int64)
        restart = dt >= TIMESTAMP_MODULUS // 2  # the timestamp went backwards: a restart
        if first_ever:
            restart[0] = True
        elif self._check_next:
            restart[0] |= not self._continues(int(dc[0]), int(dt[0]), int(ns[1] - ns[0]))
        self._check_next = False
        c, t = prev[2], prev[3]
        bounds = sorted({0, n, *np.flatnonzero(restart).tolist()})
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            if restart[a]:  # sample a starts an epoch
                if first_ever and a == 0:
                    c, t = int(counter[0]), int(timestamp[0])
                else:
                    self.epoch += 1
                    elapsed_s = max(0.0, (int(ns[a + 1]) - int(ns[a])) * 1e-9)
                    missing = max(0, round(elapsed_s * self.rate_hz) - 1)
                    log.warning("ILD1420 restarted (counter %d, timestamp %d): epoch %d, about "
                                "%d samples missing", int(counter[a]), int(timestamp[a]),
                                self.epoch, missing)
                    gaps.append(Gap(after_counter=c, length=missing, exact=False))
                    c, t = c + 1 + missing, int(timestamp[a])
                out_c[a], out_t[a], epochs[a] = c, t, self.epoch
                a += 1
            if b > a:  # samples a..b-1 continue from (c, t)
                run = c + np.cumsum(dc[a:b])
                out_c[a:b] = run
                out_t[a:b] = t + np.cumsum(dt[a:b])
                epochs[a:b] = self.epoch
                for j in np.flatnonzero(dc[a:b] != 1).tolist():
                    step = int(dc[a + j])
                    if step > 1:
                        gaps.append(Gap(after_counter=int(run[j]) - step, length=step - 1))
                    else:
                        log.warning("ILD1420 counter %d repeated", int(run[j]))
                c, t = int(run[-1]), int(out_t[b - 1])
        self._last = (int(counter[-1]), int(timestamp[-1]), c, t, int(host_ns[-1]))
        return out_c, out_t.astype(np.float64) * TIMESTAMP_TICK_S, epochs, gaps  # ticks -> s

    def _continues(self, dc: int, dt: int, elapsed_ns: int) -> bool:
        """Whether a step across a reconnect is consistent with the host time elapsed."""
        dt_s = dt * TIMESTAMP_TICK_S
        if dt_s > elapsed_ns * 1e-9 + self.RESTART_SLACK_S:
            return False
        expected = dt_s * self.rate_hz
        return abs(dc - expected) <= 0.05 * expected + 2


# ------------------------------------------------------------------------------------------------
# Blocks returned by the driver
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LaserBlock:
    """Samples read in one call, self-describing (keys of ``channels`` = ``describe()`` keys).

    Attributes
    ----------
    channels : dict of str to ndarray, each shape (n,)
        ``distance`` (m, NaN on error), ``error_code`` (0 = valid, else the sensor's error value,
        see :data:`ERROR_CODES`), ``counter`` (unwrapped int64), ``device_time`` (s, unwrapped
        within an epoch), ``epoch`` (restarts of the sensor seen so far), ``triggered`` (status
        bit 15), ``status`` (raw status bits), ``host_time_ns`` (``time.monotonic_ns()`` when the
        chunk that completed the sample arrived); plus ``exposure`` (s) and ``intensity`` (%)
        when selected.
    gaps : tuple of Gap
        Samples missing before or inside this block (counter jumps, restarts).
    bytes_skipped : int
        Bytes the decoder discarded while producing this block (resynchronisations).
    """

    channels: Mapping[str, npt.NDArray[Any]]
    gaps: tuple[Gap, ...] = ()
    bytes_skipped: int = 0

    def __len__(self) -> int:
        return int(self.channels["counter"].shape[0])

    @property
    def distance(self) -> FloatArray:
        """Measure the distances, m (NaN where the sensor reported an error)."""
        return self.channels["distance"]

    @property
    def error_code(self) -> npt.NDArray[np.int32]:
        """Measure the error value per sample (0 = valid)."""
        return self.channels["error_code"]

    @property
    def counter(self) -> IntArray:
        """Measure the unwrapped sample counter."""
        return self.channels["counter"]

    @property
    def device_time(self) -> FloatArray:
        """Measure the device time, s (unwrapped; restarts with the sensor)."""
        return self.channels["device_time"]

    @property
    def triggered(self) -> BoolArray:
        """Measure the "value triggered" flag (status bit 15) per sample."""
        return self.channels["triggered"]

    @property
    def host_time_ns(self) -> IntArray:
        """Measure the host arrival time of each sample, ns (``time.monotonic_ns``)."""
        return self.channels["host_time_ns"]

    def reasons(self) -> list[str]:
        """Return the error text per sample (``""`` where valid)."""
        return [error_reason(int(code)) for code in self.error_code]


# ------------------------------------------------------------------------------------------------
# Driver
# ------------------------------------------------------------------------------------------------
class MicroEpsilonIld1420:
    """An ILD1420 laser on a serial line: ASCII commands and the binary stream.

    Parameters
    ----------
    transport : Transport
        A closed transport (e.g. ``open_transport(url, **settings.line())``); the driver opens it.
    settings : Ild1420Settings
        Measuring range, rate, output layout and geometry.
    command_timeout_s : float
        Longest wait for a command's reply, s (MASTERMV alone may take 2 s).
    reconnect_attempts : int
        Reopen attempts after the line fails, before giving up with TransportError.
    reconnect_backoff_s : float
        First wait before reopening, s; doubled after each failed attempt.

    Notes
    -----
    ``open()`` ends mastering (``MASTERMV NONE``: the acquisition relies on absolute distances),
    checks that ``GETOUTINFO_RS422`` matches ``settings.output`` and selects ``OUTPUT RS422``.
    Commands may be sent while the sensor streams: the stream bytes around the reply are kept and
    decoded, nothing is lost. Not thread-safe: send commands from the thread that reads.
    """

    #: Longest time a read keeps collecting data that has already arrived, s.
    DRAIN_S = 0.02

    def __init__(self, transport: Transport, settings: Ild1420Settings, *,
                 command_timeout_s: float = 3.0, reconnect_attempts: int = 5,
                 reconnect_backoff_s: float = 0.1) -> None:
        if not isinstance(settings, Ild1420Settings):
            raise TypeError(f"settings must be Ild1420Settings, got {type(settings).__name__}")
        if command_timeout_s <= 0 or reconnect_attempts < 0 or reconnect_backoff_s < 0:
            raise ValueError("command_timeout_s must be > 0, reconnect_attempts and "
                             "reconnect_backoff_s >= 0")
        self._transport = transport
        self._settings = settings
        self.command_timeout_s = float(command_timeout_s)
        self.reconnect_attempts = int(reconnect_attempts)
        self.reconnect_backoff_s = float(reconnect_backoff_s)
        self._decoder = Ild1420Decoder(settings.output, range_mm=settings.range_mm)
        self._sequencer = Ild1420Sequencer(settings.rate_hz)
        self._backlog: list[tuple[Ild1420Samples, IntArray]] = []
        self._backlog_size = 0
        self._skipped_reported = 0
        self._open = False
        #: Reconnections made so far.
        self.reconnects = 0

    # -- properties -------------------------------------------------------------------------
    @property
    def settings(self) -> Ild1420Settings:
        """Measure the settings this driver was built with (read-only)."""
        return self._settings

    @property
    def is_open(self) -> bool:
        """Measure whether the driver has opened its transport."""
        return self._open

    @property
    def mastered(self) -> bool:
        """Measure whether the sensor is mastered (18-bit distances shifted by the master)."""
        return self._decoder.mastered

    @property
    def bytes_skipped(self) -> int:
        """Measure the bytes discarded while resynchronising, since construction."""
        return self._decoder.bytes_skipped

    @property
    def decoder(self) -> Ild1420Decoder:
        """Measure the decoder's counters (``bytes_skipped``, ``resyncs``, ``blocks_decoded``)."""
        return self._decoder

    # -- life cycle ---------------------------------------------------------------------------
    def open(self) -> None:
        """Open the transport, end mastering, check the output layout, select RS422 output."""
        if self._open:
            return
        self._transport.open()
        self._open = True
        try:
            self.unmaster()
            reported = self.output_info()
            expected = ("distance", *self._settings.output)
            if reported != expected:
                raise ConfigError(
                    f"{self._transport.url}: the sensor sends {list(reported)} per block but the "
                    f"rig config says output = {list(self._settings.output)} (after the distance)"
                )
            self.set_output("RS422")
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Close the transport; idempotent."""
        self._open = False
        self._transport.close()

    def __enter__(self) -> MicroEpsilonIld1420:
        self.open()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def describe(self) -> dict[str, dict[str, Any]]:
        """Return channel -> {units, dtype, shape} (shape of one sample) for :meth:`read`."""
        out: dict[str, dict[str, Any]] = {
            "distance": {"units": "m", "dtype": "float64", "shape": []},
            "error_code": {"units": "", "dtype": "int32", "shape": []},
            "counter": {"units": "", "dtype": "int64", "shape": []},
            "device_time": {"units": "s", "dtype": "float64", "shape": []},
            "epoch": {"units": "", "dtype": "int32", "shape": []},
            "triggered": {"units": "", "dtype": "bool", "shape": []},
            "status": {"units": "", "dtype": "int64", "shape": []},
            "host_time_ns": {"units": "ns", "dtype": "int64", "shape": []},
        }
        if "exposure" in self._settings.output:
            out["exposure"] = {"units": "s", "dtype": "float64", "shape": []}
        if "intensity" in self._settings.output:
            out["intensity"] = {"units": "%", "dtype": "float64", "shape": []}
        return out

    # -- ASCII commands -----------------------------------------------------------------------
    def command(self, text: str, timeout_s: float | None = None) -> list[str]:
        """Send one ASCII command; return its reply lines (without echo and prompt).

        Raises
        ------
        DeviceError
            The sensor answered ``Exxx <text>`` (e.g. ``E104 Timeout``).
        TransportTimeout
            No echo and prompt within ``timeout_s`` (default ``command_timeout_s``).
        """
        if not self._open:
            raise TransportError(f"{self._transport.url}: not open")
        if not text or any(c in text for c in "\r\n") or not text.isascii():
            raise ValueError(f"a command is one line of ASCII, got {text!r}")
        timeout = self.command_timeout_s if timeout_s is None else float(timeout_s)
        echo = text.encode("ascii") + b"\r\n"
        self._transport.write(echo)
        deadline = time.monotonic() + timeout
        buf = bytearray()
        start = -1
        while True:
            if start < 0:
                start = buf.find(echo)
                if start < 0 and len(buf) >= len(echo):
                    # Stream bytes before the echo: decode them now, keep the tail that may be
                    # the echo's beginning.
                    cut = len(buf) - len(echo) + 1
                    self._ingest(bytes(buf[:cut]), time.monotonic_ns())
                    del buf[:cut]
                elif start > 0:
                    self._ingest(bytes(buf[:start]), time.monotonic_ns())
                    del buf[:start]
                    start = 0
            if start >= 0:
                prompt = buf.find(b"->", len(echo))
                if prompt >= 0:
                    break
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TransportTimeout(
                    f"{self._transport.url}: no reply to {text!r} within {timeout:g} s "
                    f"(last bytes {bytes(buf[-64:]).hex(' ')})")
            try:
                buf += self._transport.read(65536, remaining)
            except TransportTimeout:
                continue  # the deadline check above raises, naming the command
        reply = bytes(buf[len(echo):prompt])
        rest = bytes(buf[prompt + 2:])
        lines = [line.strip() for line in reply.decode("ascii", "replace").split("\r\n")]
        lines = [line for line in lines if line]
        for line in lines:
            if _is_code(line, "E"):
                if rest:
                    self._ingest(rest, time.monotonic_ns())
                raise DeviceError(f"{self._transport.url}: {text!r} failed: {line}")
            if _is_code(line, "W"):
                log.warning("%s: %r: sensor warning %s", self._transport.url, text, line)
        self._after_reply(text)
        if rest:
            self._ingest(rest, time.monotonic_ns())
        return [line for line in lines if not _is_code(line, "W")]

    def _after_reply(self, text: str) -> None:
        """Track state that changes the decoding (mastering) once a command succeeded."""
        words = text.upper().split()
        if words[:1] == ["MASTERMV"] and len(words) >= 2:
            self._decoder.mastered = words[1] == "MASTER"

    def output_info(self) -> tuple[str, ...]:
        """Return the values per block the sensor reports (``GETOUTINFO_RS422``), in order."""
        lines = self.command("GETOUTINFO_RS422")
        tokens = " ".join(lines).split()
        if tokens[:1] == ["GETOUTINFO_RS422"]:
            tokens = tokens[1:]
        names = {v: k for k, v in OUTPUT_NAMES.items()}
        unknown = [t for t in tokens if t not in names]
        if unknown or not tokens:
            raise ProtocolError(f"{self._transport.url}: GETOUTINFO_RS422 reply {lines!r} has "
                                f"unknown or no output names {unknown}")
        return tuple(names[t] for t in tokens)

    def set_output(self, interface: str) -> None:
        """Select the measurement output: ``RS422``, ``NONE`` or ``ANALOG`` (``OUTPUT``)."""
        if interface not in ("RS422", "NONE", "ANALOG"):
            raise ValueError(f"interface must be RS422, NONE or ANALOG, got {interface!r}")
        self.command(f"OUTPUT {interface}")

    def master(self, master_value_mm: float) -> None:
        """Master the next value to ``master_value_mm`` (``MASTERMV MASTER``), mm in [0, 2 MR].

        Afterwards distances are 18-bit values relative to the master (A.2.1). Raises
        DeviceError (``E104 Timeout``) when no value comes within 2 s.
        """
        mv = float(master_value_mm)
        if not (math.isfinite(mv) and 0.0 <= mv <= 2.0 * self._settings.range_mm):
            raise ValueError(f"master value {mv!r} mm is outside [0, "
                             f"{2 * self._settings.range_mm}]")
        self.command(f"MASTERMV MASTER {mv:.6f}")

    def unmaster(self) -> None:
        """End mastering (``MASTERMV NONE``): absolute 16-bit distances again."""
        self.command("MASTERMV NONE")

    def info(self) -> dict[str, str]:
        """Return the sensor information of ``GETINFO`` as ``{field: value}``."""
        out: dict[str, str] = {}
        for line in self.command("GETINFO"):
            key, sep, value = line.partition(":")
            if sep:
                out[key.strip()] = value.strip()
        return out

    # -- stream -------------------------------------------------------------------------------
    def read(self, timeout_s: float = 1.0) -> dict[str, npt.NDArray[Any]]:
        """Return the channels of :meth:`read_block` (keys as in :meth:`describe`)."""
        return dict(self.read_block(timeout_s).channels)

    def read_block(self, timeout_s: float = 1.0, *, max_samples: int = 100_000) -> LaserBlock:
        """Return the samples received so far (at least one), waiting up to ``timeout_s``.

        After the first sample it keeps reading what has already arrived, without waiting, for
        at most :attr:`DRAIN_S` and up to ``max_samples``. A failed line is reopened (bounded
        attempts with backoff, logged); after a reopen the first step is checked for a sensor
        restart.

        Raises
        ------
        TransportTimeout
            Nothing decodable arrived within ``timeout_s`` (sensor quiet, output off, stalled).
        TransportError
            The line failed and did not come back after ``reconnect_attempts`` attempts.
        """
        if not self._open:
            raise TransportError(f"{self._transport.url}: not open")
        deadline = time.monotonic() + timeout_s
        while self._backlog_size == 0:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TransportTimeout(f"{self._transport.url}: no ILD1420 block within "
                                       f"{timeout_s:g} s")
            try:
                data = self._transport.read(65536, remaining)
            except TransportTimeout:
                continue  # the deadline check above raises, naming the sensor
            except TransportError as exc:
                self._reconnect(exc)
                continue
            self._ingest(data, time.monotonic_ns())
        # Drain what has already arrived, for at most DRAIN_S (data keeps coming), and decode it
        # in one go (the transport may return a few bytes per call), stamped with the time of
        # its last read.
        pending = bytearray()
        stamp = time.monotonic_ns()
        limit = (max_samples - self._backlog_size) * self._decoder.block_bytes
        drain_end = stamp + int(self.DRAIN_S * 1e9)
        while len(pending) < limit and stamp < drain_end:
            try:
                pending += self._transport.read(65536, 0.0)
            except TransportTimeout:
                break
            except TransportError as exc:
                self._ingest(bytes(pending), time.monotonic_ns())
                pending.clear()
                self._reconnect(exc)
                break
            stamp = time.monotonic_ns()
        if pending:
            self._ingest(bytes(pending), stamp)
        return self._build_block()

    def _reconnect(self, cause: TransportError) -> None:
        url = self._transport.url
        log.warning("%s: line failed (%s); reopening", url, cause)
        delay = self.reconnect_backoff_s
        last: TransportError = cause
        for attempt in range(1, self.reconnect_attempts + 1):
            time.sleep(delay)
            delay *= 2
            try:
                self._transport.close()
                self._transport.open()
            except TransportError as exc:
                last = exc
                log.warning("%s: reopen attempt %d of %d failed: %s", url, attempt,
                            self.reconnect_attempts, exc)
                continue
            dropped = self._decoder.reset()
            self._sequencer.expect_discontinuity()
            self.reconnects += 1
            log.warning("%s: reopened after %d attempt(s); %d bytes of a cut block dropped",
                        url, attempt, dropped)
            return
        self._open = False
        self._transport.close()
        raise TransportError(f"{url}: the ILD1420 did not come back after "
                             f"{self.reconnect_attempts} reopen attempts") from last

    def _ingest(self, data: bytes, host_ns: int) -> None:
        samples = self._decoder.feed(data)
        if len(samples):
            self._backlog.append((samples, np.full(len(samples), host_ns, dtype=np.int64)))
            self._backlog_size += len(samples)

    def _build_block(self) -> LaserBlock:
        parts, self._backlog, self._backlog_size = self._backlog, [], 0
        samples = Ild1420Samples.concatenate([p for p, _ in parts])
        host_ns = np.concatenate([h for _, h in parts])
        assert samples.counter is not None and samples.timestamp is not None
        assert samples.status is not None  # required by the settings
        counter, device_time, epoch, gaps = self._sequencer.process(
            samples.counter, samples.timestamp, host_ns)
        channels: dict[str, npt.NDArray[Any]] = {
            "distance": samples.distance_mm * 1e-3,
            "error_code": samples.error_code,
            "counter": counter,
            "device_time": device_time,
            "epoch": epoch,
            "triggered": (samples.status & STATUS_TRIGGERED) != 0,
            "status": samples.status,
            "host_time_ns": host_ns,
        }
        if samples.exposure is not None:
            channels["exposure"] = samples.exposure * 1e-7  # ET[us] = x / 10
        if samples.intensity is not None:
            channels["intensity"] = samples.intensity * (100.0 / 65472.0)
        skipped = self._decoder.bytes_skipped - self._skipped_reported
        self._skipped_reported = self._decoder.bytes_skipped
        for gap in gaps:
            log.info("%s: %d sample(s) missing after counter %d%s", self._transport.url,
                     gap.length, gap.after_counter, "" if gap.exact else " (estimated)")
        return LaserBlock(channels=channels, gaps=tuple(gaps), bytes_skipped=skipped)

    def blocks(self, timeout_s: float = 1.0) -> Iterator[LaserBlock]:
        """Yield blocks until the transport times out or fails (for simple readers)."""
        while True:
            yield self.read_block(timeout_s)


def _is_code(line: str, letter: str) -> bool:
    """Whether a reply line is an error (``E``) or warning (``W``) message: letter + digits."""
    head = line.split(" ", 1)[0]
    return len(head) > 1 and head[0] == letter and head[1:].isdigit()


def _build(transport: Transport, settings: Ild1420Settings) -> MicroEpsilonIld1420:
    return MicroEpsilonIld1420(transport, settings)


register(DriverEntry(name="microepsilon_ild1420", role="lasers", factory=_build,
                     validate=Ild1420Settings.from_table))
