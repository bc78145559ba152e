"""The ILD1420-class laser's binary stream: 3-byte words into samples (pure, no I/O).

Responsibility: :class:`Ild1420Decoder` finds the block boundaries in the stream of 3-byte words
(marker bits ``00``, ``01``, ``1f``), converts the distance (16 bits, 18 when mastered) into
millimetres with its error values (:data:`ERROR_CODES`, :func:`error_reason`) and the additional
values (counter, timestamp, status, exposure, intensity) into :class:`Ild1420Samples`.

Not responsible for: unwrapping the counter and timestamp or marking gaps
(:mod:`daq.instruments.microepsilon_ild1420.blocks`), or the line itself
(:mod:`daq.instruments.microepsilon_ild1420.driver`). The wire format is described in
``docs/reference/wire_formats.md``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from daq.instruments.microepsilon_ild1420.settings import DEFAULT_OUTPUT, RANGES_MM, WORDS_PER_VALUE

__all__ = ["COUNTER_MODULUS", "ERROR_CODES", "FIRST_ERROR_VALUE", "MAX_DISTANCE_16",
           "STATUS_TRIGGERED", "TIMESTAMP_MODULUS", "TIMESTAMP_TICK_S", "Ild1420Decoder",
           "Ild1420Samples", "error_reason"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: Error values inside the distance word (manual p. 66).
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


#: Weights of a word's 6-bit parts (low, middle, high): the word is their weighted sum.
_PART_WEIGHTS: Final = np.array([1, 1 << 6, 1 << 12], dtype=np.int64)

#: Largest 16-bit distance value (end of the EMR reserve) and first 18-bit error value.
MAX_DISTANCE_16: Final = 65520


FIRST_ERROR_VALUE: Final = 262075


def error_reason(code: int) -> str:
    """Return the manual's text for a distance error value (``""`` for 0, i.e. no error)."""
    if code == 0:
        return ""
    if code in ERROR_CODES:
        return ERROR_CODES[code]
    return f"not a distance value ({code})"


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
    value (docs/reference/wire_formats.md, "Laser displacement sensors"). A byte that breaks the
    pattern (lost or inserted byte, a start mid-block) makes it skip forward to the next position
    where a whole block pattern starts; the skipped bytes are counted. It never raises on any input
    and always consumes what it is given.

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
            match = rows == self._pattern
            if match.all():  # the usual chunk: every block whole (one check, no search)
                ok = k
            else:
                ok = int(np.argmin(match.all(axis=1)))  # the first block that breaks it
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
        rows_all = (good[0] if len(good) == 1 else np.concatenate(good) if good
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
        """Assemble 18-bit words (L | M << 6 | H << 12) and convert them."""
        count = rows.shape[0]
        self.blocks_decoded += count
        # Each word's three 6-bit parts, weighted 1, 2**6, 2**12 and summed (L | M << 6 | H << 12:
        # the parts do not overlap, so the sum is the bitwise or).
        words = (rows & 0x3F).reshape(count, self.values_per_block, 3) @ _PART_WEIGHTS
        raw = words[:, 0]
        if self.mastered:
            valid = raw < FIRST_ERROR_VALUE
            shift = 51.0
        else:
            valid = raw <= MAX_DISTANCE_16
            shift = 1.0
        distance = np.asarray((102.0 * raw / 65520.0 - shift) * self.range_mm / 100.0,
                              dtype=np.float64)  # float64 already: no copy
        errors = count - int(np.count_nonzero(valid))
        if errors:
            distance[~valid] = np.nan
            code = np.where(valid, 0, raw).astype(np.int32)
        else:  # the usual chunk: every distance valid
            code = np.zeros(count, np.int32)
        self.blocks_with_errors += errors
        extra: dict[str, IntArray] = {}
        for name, column in self._columns.items():
            if name == "timestamp":
                extra[name] = (words[:, column] & 0xFFFF) | ((words[:, column + 1] & 0xFFFF) << 16)
            else:
                extra[name] = words[:, column]
        return Ild1420Samples(distance_mm=distance, error_code=code, **extra)
