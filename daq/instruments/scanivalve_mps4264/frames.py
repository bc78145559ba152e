"""Scanivalve MPS4264-class binary frames: packet layouts and a pure decoder (no I/O).

Responsibility: know the binary packets a scanner's TCP binary server sends (their types, sizes,
field layouts and byte orders), find them in a byte stream that may hold garbage or partial packets,
check their fields, and decode them into :class:`PacketBatch` es (:class:`Mps4264Decoder`), one
stream at a time or the streams of several modules in one numpy pass
(:meth:`Mps4264Decoder.feed_many`, or joined for modules in step:
:meth:`Mps4264Decoder.feed_in_step`). Not responsible for: connections and reads or host arrival
times (:mod:`daq.instruments.scanivalve_mps4264.driver`), counter unwrapping
(:mod:`daq.instruments.scanivalve_mps4264.streams`), or merging the modules frame by frame
(:mod:`daq.instruments.scanivalve_mps4264.merge`). Pure: no I/O, no threads, no clock.

Packets (docs/reference/wire_formats.md, "Pressure scanner"; Scanivalve's mps-protocol.h;
[unverified] marks our choices where the facts stop):

- Every field is a 4-byte word, big- or little-endian, detected per packet from the non-zero
  byte of the type word as ``mps_peek()`` does:
  0x6D MPS4264 EU, 304 bytes: ``int32 type, uint32 frame, uint32 frame_time_s,
  uint32 frame_time_ns, float32 T[8], float32 P[64]``;
  0x0A legacy, 348 bytes: ``int32 type, int32 size (=348), int32 frame, int32 serial_number,
  float32 framerate_Hz, int32 valve_status (0 Px, 1 Cal), int32 unit_index, float32
  unit_conversion, uint32 ptp_scan_start_s, uint32 ptp_scan_start_ns, uint32 ext_trigger_time_us,
  float32 T[8], float32 P[64], uint32 frame_time_s, uint32 frame_time_ns, uint32 ext_trigger_s,
  uint32 ext_trigger_ns``. The other packet types of the table (0x5D/0x5B 96 B, 0x65/0x63 160 B,
  0x69 304 B) are recognised by size, skipped and counted.
- Frame time is "a time relative to 0 (when PTP is disabled), or an absolute PTP time" (decoded
  as sent; the driver tells the two apart). The external trigger time ``ext_trigger_s/ns`` is
  relative to the scan start; the decoder adds ``ptp_scan_start`` so that it is on the
  frame-time base. Both zero means "no trigger yet" [design] (NaN).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = [
    "CHANNELS_PER_MODULE",
    "TEMPERATURES_PER_MODULE",
    "TYPE_EU64",
    "TYPE_LEGACY",
    "Mps4264Decoder",
    "PacketBatch",
]

#: The decoder's records keep the driver's logger name (they were logged there before the
#: decoder had a module of its own), so that log filters and levels set for the scanner still
#: apply to them.
log = logging.getLogger("daq.instruments.scanivalve_mps4264.driver")

#: Pressure channels per MPS4264 module (mps-protocol.h: at most 64 pressure channels).
CHANNELS_PER_MODULE = 64
#: Temperature channels per module (mps-protocol.h: 8 temperature channels).
TEMPERATURES_PER_MODULE = 8

#: Pa per EU unit when ``unit_conversion`` is the PA factor (mps-protocol.h units table:
#: EU = counts x calibration (PSI) x conversion, PA factor 6894.75977).
_PA_FACTOR = float(np.float32(6894.75977))
_UNIT_RAW = 27  # Appendix A: 27 RAW (counts, not pressures)

#: Packet type -> size in bytes (docs/reference/wire_formats.md, "Pressure scanner",
#: mps-protocol.h).
PACKET_SIZES: Mapping[int, int] = {
    0x5D: 96, 0x5B: 96, 0x65: 160, 0x63: 160, 0x6D: 304, 0x69: 304, 0x0A: 348,
}
TYPE_EU64 = 0x6D
TYPE_LEGACY = 0x0A
_SUPPORTED = (TYPE_EU64, TYPE_LEGACY)
_NS_LIMIT = 1_000_000_000
U32 = 1 << 32


def _eu_dtype(order: str) -> np.dtype[Any]:
    return np.dtype([
        ("type", order + "i4"), ("frame", order + "u4"), ("time_s", order + "u4"),
        ("time_ns", order + "u4"), ("T", order + "f4", (8,)), ("P", order + "f4", (64,)),
    ])


def _legacy_dtype(order: str) -> np.dtype[Any]:
    return np.dtype([
        ("type", order + "i4"), ("size", order + "i4"), ("frame", order + "u4"),
        ("serial", order + "i4"), ("rate", order + "f4"), ("valve", order + "i4"),
        ("unit", order + "i4"), ("conv", order + "f4"), ("start_s", order + "u4"),
        ("start_ns", order + "u4"), ("ext_us", order + "u4"), ("T", order + "f4", (8,)),
        ("P", order + "f4", (64,)), ("time_s", order + "u4"), ("time_ns", order + "u4"),
        ("ext_s", order + "u4"), ("ext_ns", order + "u4"),
    ])


_DTYPES = {(kind, order): make(">" if order == "big" else "<")
           for kind, make in ((TYPE_EU64, _eu_dtype), (TYPE_LEGACY, _legacy_dtype))
           for order in ("big", "little")}
assert all(dt.itemsize == PACKET_SIZES[kind] for (kind, _), dt in _DTYPES.items())
#: Word (4-byte) index of each field of the supported packets, from the layouts above.
_WORD = {kind: {name: _DTYPES[(kind, "big")].fields[name][1] // 4  # type: ignore[index]
                for name in _DTYPES[(kind, "big")].names or ()}
         for kind in _SUPPORTED}
_EU_W, _LEG_W = _WORD[TYPE_EU64], _WORD[TYPE_LEGACY]
_LEG_NS_WORDS = [_LEG_W["start_ns"], _LEG_W["time_ns"], _LEG_W["ext_ns"]]


# ------------------------------------------------------------------------------------------------
# Decoder
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class PacketBatch:
    """Decoded packets of one stream, one row per packet (struct of arrays).

    Attributes
    ----------
    kind : ndarray of int16, (n,)
        Packet type (0x6D or 0x0A).
    big_endian : ndarray of bool, (n,)
        Byte order each packet was sent in.
    frame : ndarray of int64, (n,)
        Frame counter as sent (uint32, not unwrapped).
    frame_time : ndarray of float64, (n,)
        ``frame_time_s + 1e-9 frame_time_ns``, s (device clock).
    trigger_time : ndarray of float64, (n,)
        Last external trigger on the frame-time base (``ptp_scan_start + ext_trigger``), s; NaN
        without a trigger or in a 0x6D packet.
    rate_hz : ndarray of float64, (n,)
        Frame rate the packet reports (legacy), Hz; NaN for 0x6D.
    serial : ndarray of int64, (n,)
        Module serial number (legacy); -1 for 0x6D.
    valve_cal : ndarray of bool, (n,)
        Calibration valve in the Cal position (legacy ``valve_status`` 1).
    temperature : ndarray of float64, (n, 8)
        Module temperatures, degC.
    pressure : ndarray of float64, (n, 64)
        Pressures, Pa (legacy: converted with the packet's own ``unit_conversion``; 0x6D: as
        sent, in the units set with ``SET UNITS PA``).
    """

    kind: npt.NDArray[np.int16]
    big_endian: npt.NDArray[np.bool_]
    frame: npt.NDArray[np.int64]
    frame_time: npt.NDArray[np.float64]
    trigger_time: npt.NDArray[np.float64]
    rate_hz: npt.NDArray[np.float64]
    serial: npt.NDArray[np.int64]
    valve_cal: npt.NDArray[np.bool_]
    temperature: npt.NDArray[np.float64]
    pressure: npt.NDArray[np.float64]

    def __len__(self) -> int:
        return int(self.frame.size)

    @classmethod
    def empty(cls) -> PacketBatch:
        """Return a batch of no packets."""
        return cls.concatenate([])

    @classmethod
    def concatenate(cls, batches: Sequence[PacketBatch]) -> PacketBatch:
        """Stack batches in order."""
        if len(batches) == 1:
            return batches[0]
        if not batches:
            return cls(
                kind=np.zeros(0, np.int16), big_endian=np.zeros(0, bool),
                frame=np.zeros(0, np.int64), frame_time=np.zeros(0), trigger_time=np.zeros(0),
                rate_hz=np.zeros(0), serial=np.zeros(0, np.int64), valve_cal=np.zeros(0, bool),
                temperature=np.zeros((0, TEMPERATURES_PER_MODULE)),
                pressure=np.zeros((0, CHANNELS_PER_MODULE)),
            )
        return cls(**{name: np.concatenate([getattr(b, name) for b in batches])
                      for name in cls.__dataclass_fields__})

    def take(self, index: Any) -> PacketBatch:
        """Rows selected by ``index`` (a slice, boolean mask or integer array)."""
        return PacketBatch(**{name: getattr(self, name)[index]
                              for name in self.__dataclass_fields__})


def _peek(buf: bytes, pos: int) -> tuple[int, str] | None:
    """Type and byte order of the 4-byte word at ``pos``, or None.

    As ``mps_peek()`` in mps-protocol.h: the type fits in one byte, so exactly one end of the
    word is non-zero.
    """
    word = buf[pos:pos + 4]
    if len(word) < 4:
        return None
    big = int.from_bytes(word, "big")
    if big in PACKET_SIZES:
        return big, "big"
    little = int.from_bytes(word, "little")
    if little in PACKET_SIZES:
        return little, "little"
    return None


class Mps4264Decoder:
    """Pure decoder of a scanner data stream: feed bytes, get :class:`PacketBatch` es.

    Packets are found by their type word (either byte order) and accepted only when the next
    packet's type word follows them, or when the bytes end exactly at their end; a packet whose
    successor is not a valid type word is rejected (``bad_packets``) and the decoder searches for
    the next valid packet from its second byte. When not in step (at garbage) a candidate packet
    must be confirmed by a valid type word right after it. Field checks (legacy ``size`` = 348,
    nanoseconds < 1e9, a positive unit conversion) reject corrupted headers. It never raises on
    input bytes and always makes progress.

    Attributes
    ----------
    bytes_skipped : int
        Bytes discarded while searching for a packet (garbage, rejected packets).
    packets : int
        Packets decoded and returned.
    bad_packets : int
        Packets with a valid type word rejected by their field checks or their successor.
    unsupported_packets : int
        Well-formed packets of types this decoder does not return (RAW, 16/32-channel models,
        legacy RAW units); skipped.
    """

    #: Bytes kept back when no candidate is found (a type word may straddle two feeds).
    _KEEP = 3

    def __init__(self) -> None:
        self._rest = b""
        self._base = 0  # stream offset of the first byte of _rest (bytes fed before it)
        self._synced = True  # a fresh stream starts at a packet boundary
        self.bytes_skipped = 0
        self.packets = 0
        self.bad_packets = 0
        self.unsupported_packets = 0

    @property
    def pending_bytes(self) -> int:
        """Measure the bytes held back for the next feed (a partial packet)."""
        return len(self._rest)

    def reset(self) -> int:
        """Forget buffered bytes (a new connection); return how many were discarded."""
        discarded = len(self._rest)
        self.bytes_skipped += discarded
        self._base += discarded
        self._rest = b""
        self._synced = True
        return discarded

    @property
    def offset(self) -> int:
        """Measure the stream offset of the bytes held back: bytes fed minus ``pending_bytes``."""
        return self._base

    def feed(self, data: bytes) -> PacketBatch:
        """Decode as many packets as ``data`` completes; keep the remainder for the next call."""
        return self.feed_with_ends(data)[0]

    def feed_with_ends(self, data: bytes) -> tuple[PacketBatch, npt.NDArray[np.int64]]:
        """As :meth:`feed`, and also return each packet's end as a stream offset.

        The stream offset counts every byte fed since the decoder was made (across
        :meth:`reset`): a packet ending at offset ``e`` was completed by the byte ``e - 1``,
        which tells the caller which read delivered it.
        """
        buf = self._rest + bytes(data) if self._rest else bytes(data)
        out: list[PacketBatch] = []
        ends: list[npt.NDArray[np.int64]] = []
        base = self._base
        pos, end = 0, len(buf)
        while True:
            if not self._synced:
                pos = self._search(buf, pos)
                if not self._synced:
                    break  # no candidate, or one awaiting its confirming word
            if end - pos < 4:
                break
            head = _peek(buf, pos)
            if head is None:
                self._synced = False
                continue
            kind, order = head
            size = PACKET_SIZES[kind]
            count = (end - pos) // size
            if count == 0:
                break
            ok = self._run_ok(buf, pos, kind, order, size, count)
            run = count if ok.all() else int(np.argmin(ok))
            if run == 0:  # a type word, but corrupt fields
                pos = self._reject(pos)
                continue
            after = pos + run * size
            if after == end:
                confirmed, accept = True, run
            elif end - after < 4:  # 1..3 bytes of the next word: hold the last packet back
                confirmed, accept = True, run - 1
            else:
                confirmed = _peek(buf, after) is not None
                accept = run if confirmed else run - 1
            if accept:
                self._emit(buf, pos, kind, order, accept, out, ends, base)
                pos += accept * size
            if not confirmed:  # the run's last packet is not followed by a packet: reject it
                pos = self._reject(pos)
                continue
            if accept < run:
                break
        self._rest = buf[pos:]
        self._base = base + pos
        if len(out) == 1:
            return out[0], ends[0]
        return PacketBatch.concatenate(out), (np.concatenate(ends) if ends
                                              else np.zeros(0, np.int64))

    @staticmethod
    def feed_many(decoders: Sequence[Mps4264Decoder], chunks: Sequence[bytes],
                  ) -> list[tuple[PacketBatch, npt.NDArray[np.int64]]]:
        """:meth:`feed_with_ends` of each decoder with its chunk, in one numpy pass if possible.

        The one pass (one check and one conversion of all the streams' packets together) is
        taken when every decoder is in step and its bytes are whole packets of one supported
        type and byte order, the same for all (the usual case: the modules of one scanner);
        otherwise each decoder decodes its own chunk. The results are the same either way.
        """
        plan = _in_step(decoders, chunks)
        if plan is None:
            return [d.feed_with_ends(c) for d, c in zip(decoders, chunks, strict=True)]
        (kind, order), bufs, checked, accepted = plan
        size = PACKET_SIZES[kind]
        total = sum(checked)
        batch = PacketBatch.empty()
        if total:
            joined = b"".join(buf[:n * size] for buf, n in zip(bufs, checked, strict=True))
            if not Mps4264Decoder._run_ok(joined, 0, kind, order, size, total).all():
                return [d.feed_with_ends(c) for d, c in zip(decoders, chunks, strict=True)]
            batch, keep = _decode_packets(joined, 0, kind, order, total)
            if keep is not None:  # RAW units: let each decoder count what it skips
                return [d.feed_with_ends(c) for d, c in zip(decoders, chunks, strict=True)]
        out = []
        first = 0
        for d, buf, n, count in zip(decoders, bufs, checked, accepted, strict=True):
            part = batch if count == total else batch.take(slice(first, first + count))
            first += n
            out.append((part, np.arange(d._base + size, d._base + (count + 1) * size, size,
                                        dtype=np.int64)))
            d._rest = buf[count * size:]
            d._base += count * size
            d.packets += count
        return out

    @staticmethod
    def feed_in_step(decoders: Sequence[Mps4264Decoder], chunks: Sequence[bytes],
                     ) -> tuple[PacketBatch, npt.NDArray[np.int64]] | None:
        """:meth:`feed_many` when every decoder completes the same number of packets, joined.

        Returns the packets of all the decoders as one batch, decoder after decoder (``n``
        rows each), and their ends as stream offsets, ``(decoders, n)``; the decoders are then
        where :meth:`feed_many` would leave them. None, with no decoder touched, when
        :meth:`feed_many` would do anything else (a decoder out of step, a packet held back,
        unequal counts, a packet failing its checks, RAW units): call it then.
        """
        plan = _in_step(decoders, chunks)
        if plan is None:
            return None
        (kind, order), bufs, checked, accepted = plan
        n = accepted[0]
        if n == 0 or checked != accepted or any(a != n for a in accepted):
            return None
        size = PACKET_SIZES[kind]
        joined = b"".join([buf[:n * size] for buf in bufs])
        total = n * len(bufs)
        if not Mps4264Decoder._run_ok(joined, 0, kind, order, size, total).all():
            return None
        batch, keep = _decode_packets(joined, 0, kind, order, total)
        if keep is not None:
            return None
        step = np.arange(size, (n + 1) * size, size, dtype=np.int64)
        ends = np.array([d._base for d in decoders], np.int64)[:, None] + step
        for d, buf in zip(decoders, bufs, strict=True):
            d._rest = buf[n * size:]
            d._base += n * size
            d.packets += n
        return batch, ends

    # -- internals ---------------------------------------------------------------------------------
    def _reject(self, pos: int) -> int:
        """Count the packet at ``pos`` as bad and search again from its second byte."""
        self.bad_packets += 1
        self.bytes_skipped += 1
        self._synced = False
        return pos + 1

    def _search(self, buf: bytes, pos: int) -> int:
        """Find the next confirmed packet start at or after ``pos`` and set ``_synced``.

        Returns the start; or, still unsynced, the candidate that awaits its confirming word or
        the offset from which bytes are kept (no candidate: a type word may straddle two feeds).
        """
        start = pos
        while True:
            cand = _find_candidate(buf, pos)
            if cand < 0:
                keep = max(len(buf) - self._KEEP, start)
                self.bytes_skipped += keep - start
                return keep
            head = _peek(buf, cand)
            assert head is not None
            kind, order = head
            size = PACKET_SIZES[kind]
            if len(buf) - cand < size + 4:
                self.bytes_skipped += cand - start
                return cand
            if self._run_ok(buf, cand, kind, order, size, 1)[0] and \
                    _peek(buf, cand + size) is not None:
                self.bytes_skipped += cand - start
                self._synced = True
                return cand
            pos = cand + 1

    @staticmethod
    def _run_ok(buf: bytes, pos: int, kind: int, order: str, size: int,
                count: int) -> npt.NDArray[np.bool_]:
        """Per packet of a stride-``size`` run: same type word, and sane fields."""
        o = ">" if order == "big" else "<"
        # One row of 4-byte words per packet (a view of the buffer, no copy).
        w = np.ndarray((count, size // 4), dtype=o + "u4", buffer=buf, offset=pos,
                       strides=(size, 4))
        ok: npt.NDArray[np.bool_] = w[:, 0] == kind
        if kind == TYPE_EU64:
            ok &= w[:, _EU_W["time_ns"]] < _NS_LIMIT
        elif kind == TYPE_LEGACY:
            ok &= w[:, _LEG_W["size"]] == 348
            ok &= w[:, _LEG_NS_WORDS].max(axis=1) < _NS_LIMIT  # start_ns, time_ns, ext_ns
            conv = w[:, _LEG_W["conv"]].view(o + "f4")
            ok &= (conv > 0) & (conv < np.inf)  # finite and positive (NaN compares false)
        return ok

    def _emit(self, buf: bytes, pos: int, kind: int, order: str, n: int,
              out: list[PacketBatch], ends: list[npt.NDArray[np.int64]], base: int) -> None:
        if kind not in _SUPPORTED:
            self.unsupported_packets += n
            log.debug("skipped %d unsupported packets of type 0x%02X", n, kind)
            return
        size = PACKET_SIZES[kind]
        end = np.arange(base + pos + size, base + pos + (n + 1) * size, size, dtype=np.int64)
        batch, keep = _decode_packets(buf, pos, kind, order, n)
        if keep is not None:
            self.unsupported_packets += n - len(batch)
            end = end[keep]
        if len(batch):
            out.append(batch)
            ends.append(end)
            self.packets += len(batch)


def _decode_packets(buf: bytes, pos: int, kind: int, order: str, n: int,
                    ) -> tuple[PacketBatch, npt.NDArray[np.bool_] | None]:
    """Decode ``n`` checked packets of a supported ``kind`` stored back to back from ``pos``.

    Returns the batch and, when legacy packets in RAW units (counts, not pressures: not
    decodable to Pa here) were left out, the mask of the packets kept (else None).
    """
    size = PACKET_SIZES[kind]
    o = ">" if order == "big" else "<"
    # The packets' 4-byte words, one row per packet: as integers (uint32 -> int64, exact) and
    # as float32 (the float fields); _WORD gives each field's word.
    words = np.ndarray((n, size // 4), dtype=o + "u4", buffer=buf, offset=pos)
    w = words.astype(np.int64)
    f = words.view(o + "f4")
    i = _WORD[kind]
    t, p = i["T"], i["P"]
    keep: npt.NDArray[np.bool_] | None = None
    if kind == TYPE_EU64:
        trigger = np.full(n, np.nan)
        rate = np.full(n, np.nan)
        serial = np.full(n, -1, np.int64)
        valve = np.zeros(n, bool)
        pressure = f[:, p:p + CHANNELS_PER_MODULE].astype(np.float64)
    else:
        raw = w[:, i["unit"]] == _UNIT_RAW
        if raw.any():
            keep = ~raw
            w, f = w[keep], f[keep]
            n = int(keep.sum())
        ext_s, ext_ns = w[:, i["ext_s"]], w[:, i["ext_ns"]]
        start = w[:, i["start_s"]] + 1e-9 * w[:, i["start_ns"]]
        trigger = start + (ext_s + 1e-9 * ext_ns)
        trigger[(ext_s | ext_ns) == 0] = np.nan  # no trigger yet
        rate = f[:, i["rate"]].astype(np.float64)
        sn = w[:, i["serial"]]
        serial = np.where(sn >= 1 << 31, sn - U32, sn)  # an int32 field
        valve = w[:, i["valve"]] == 1
        factor = _PA_FACTOR / f[:, i["conv"]].astype(np.float64)  # EU = PSI x conversion
        pressure = f[:, p:p + CHANNELS_PER_MODULE] * factor[:, None]
    frame_time = w[:, i["time_s"]] + 1e-9 * w[:, i["time_ns"]]
    temperature = f[:, t:t + TEMPERATURES_PER_MODULE].astype(np.float64)
    return PacketBatch(
        kind=np.full(n, kind, np.int16), big_endian=np.full(n, order == "big"),
        frame=w[:, i["frame"]].copy(), frame_time=frame_time, trigger_time=trigger,
        rate_hz=rate, serial=serial, valve_cal=valve, temperature=temperature,
        pressure=pressure,
    ), keep


def _in_step(decoders: Sequence[Mps4264Decoder], chunks: Sequence[bytes],
             ) -> tuple[tuple[int, str], list[bytes], list[int], list[int]] | None:
    """Plan the one pass of :meth:`Mps4264Decoder.feed_many`, or None.

    Returns the common (type, order), every decoder's bytes, how many whole packets
    :meth:`~Mps4264Decoder.feed_with_ends` would check in them and how many of those it would
    accept if all pass their checks (one fewer when 1..3 bytes of a next type word follow);
    None when a decoder would have more to do (resynchronise, switch type or byte order,
    reject a packet that no type word follows).
    """
    head: tuple[int, str] | None = None
    bufs, checked, accepted = [], [], []
    for d, data in zip(decoders, chunks, strict=True):
        buf = d._rest + bytes(data) if d._rest else bytes(data)
        h = _peek(buf, 0) if d._synced else None
        if h is None or h[0] not in _SUPPORTED or (head is not None and h != head):
            return None
        head = h
        size = PACKET_SIZES[h[0]]
        count, rest = divmod(len(buf), size)
        accept = count
        if count and 0 < rest < 4:
            accept -= 1  # 1..3 bytes of the next type word: the last packet waits (as in feed)
        elif rest >= 4:
            after = _peek(buf, count * size)  # the next packet's type word, incomplete packet
            if after is None or PACKET_SIZES[after[0]] <= rest:
                return None
        bufs.append(buf)
        checked.append(count)
        accepted.append(accept)
    if head is None:
        return None
    return head, bufs, checked, accepted


_PATTERNS = tuple(kind.to_bytes(4, order) for kind in PACKET_SIZES for order in ("big", "little"))


def _find_candidate(buf: bytes, pos: int) -> int:
    """First offset >= ``pos`` holding any known type word (either order), or -1."""
    best = -1
    for pattern in _PATTERNS:
        at = buf.find(pattern, pos, best + 4 if best >= 0 else len(buf))
        if at >= 0 and (best < 0 or at < best):
            best = at
    return best
