"""One module's data stream of the Scanivalve MPS4264-class scanner: its bytes, decoder, keys.

Responsibility: :class:`ModuleStream` holds what the driver keeps per module (one TCP data
connection each): the bytes read and the host time of each read, the decoder
(:class:`~daq.instruments.scanivalve_mps4264.frames.Mps4264Decoder`), and the unwrapping of the
module's frame counter into merge keys (``epoch << KEY_BITS | u``); :func:`aligned` tells the
driver when the modules' frames need no merging, :func:`in_step` and :func:`continue_in_step`
when a block can be built at once without holding them per module. Pure bookkeeping: no I/O
(the driver reads the transport and hands the bytes over) and no clock of its own (the driver
passes its times in).

Not responsible for: reading or reconnecting the data connection, merging the modules' frames
into blocks (:mod:`daq.instruments.scanivalve_mps4264.driver`), or decoding packets
(:mod:`daq.instruments.scanivalve_mps4264.frames`).
"""

from __future__ import annotations

import logging

import numpy as np
import numpy.typing as npt

from daq.instruments.scanivalve_mps4264.frames import (
    PACKET_SIZES,
    TYPE_EU64,
    U32,
    Mps4264Decoder,
    PacketBatch,
)
from daq.transports.byte_transport import Transport

__all__ = ["KEY_BITS", "KEY_MASK", "ModuleStream", "aligned"]

log = logging.getLogger(__name__)

KEY_BITS = 40  # unwrapped counter bits within one counter epoch (2^40 frames ~ 17 years at 2 kHz)


KEY_MASK = (1 << KEY_BITS) - 1


#: A module's frames for one block: keys, packets, host arrival times (ns).
Part = tuple[npt.NDArray[np.int64], PacketBatch, npt.NDArray[np.int64]]


class ModuleStream:
    """One module's data connection, decoder and counter unwrapping (keys for merging).

    Key = ``epoch << 40 | u``: ``u`` is the unwrapped counter within a counter epoch; an epoch
    ends when the device counter goes back (not a uint32 wrap), i.e. the scan restarted.

    Bytes read are first stashed with the host time of their read (:meth:`stash`) and decoded
    when a block is due (:meth:`take_raw`, then :meth:`arrival_times` and :meth:`ingest`): one
    decoder call per block instead of one per TCP read. Each packet keeps the time of the read
    that delivered its last byte.
    """

    def __init__(self, index: int, transport: Transport, opened_s: float) -> None:
        self.index = index
        self.transport = transport
        self.decoder = Mps4264Decoder()
        self.last_raw: int | None = None
        self.epoch = 0
        self.u_last = 0
        self.watermark = -1
        self.keys: list[npt.NDArray[np.int64]] = []
        self.batches: list[PacketBatch] = []
        self.hosts: list[npt.NDArray[np.int64]] = []
        self.n_pending = 0  # rows in keys/batches/hosts
        self.duplicates = 0
        self.order_mismatches = 0
        self.serial: int | None = None
        self.last_arrival = opened_s  # the driver's monotonic clock, s
        self.silent = False
        # Undecoded bytes, and per read (oldest first) the stream offset after it and its time.
        self.raw: list[bytes] = []
        self.raw_bytes = 0
        self.fed = 0
        self.read_ends: list[int] = []
        self.read_ns: list[int] = []
        self.packet_size = PACKET_SIZES[TYPE_EU64]  # of the last packets decoded (estimates)

    def stash(self, data: bytes, host_ns: int) -> None:
        """Keep the bytes of one read, which returned at ``host_ns``, until they are decoded."""
        self.raw.append(data)
        self.raw_bytes += len(data)
        self.fed += len(data)
        self.read_ends.append(self.fed)
        self.read_ns.append(host_ns)

    def frames_ahead(self) -> int:
        """Estimate the frames held: decoded ones plus the whole packets in undecoded bytes."""
        return self.n_pending + (self.raw_bytes + self.decoder.pending_bytes) // self.packet_size

    def take_raw(self) -> bytes:
        """Remove and return the stashed bytes (for the decoder)."""
        data = self.raw[0] if len(self.raw) == 1 else b"".join(self.raw)
        self.raw, self.raw_bytes = [], 0
        return data

    def arrival_times(self, ends: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
        """Host times of the reads that completed packets ending at ``ends`` (stream offsets).

        Call after the decoder took the bytes: the times of reads whose bytes it no longer
        holds are forgotten.
        """
        read_ends = self.read_ends
        if len(read_ends) == 1:
            hosts = np.full(ends.size, self.read_ns[0], np.int64)
        else:
            # The read that delivered a packet's last byte (offset end - 1) is the first read
            # whose end offset is >= the packet's end.
            idx = np.searchsorted(np.asarray(read_ends, np.int64), ends)
            hosts = np.asarray(self.read_ns, np.int64)[idx]
        held = self.decoder.offset  # bytes from here on are still in the decoder
        first = 0
        while first < len(read_ends) and read_ends[first] <= held:
            first += 1
        if first:
            del self.read_ends[:first], self.read_ns[:first]
        return hosts

    def ingest(self, batch: PacketBatch, hosts: npt.NDArray[np.int64]) -> None:
        """Unwrap the counters of decoded packets and hold them (``hosts``: arrival, ns)."""
        raw = batch.frame
        n = raw.size
        if (n and self.last_raw is not None and (int(raw[0]) - self.last_raw) % U32 == 1
                and bool((raw[1:] - raw[:-1] == 1).all())):
            # The common case, frames that continue the previous ones one by one: the keys
            # follow directly (no restart, wrap or duplicate to look for).
            keys = (self.epoch << KEY_BITS) + self.u_last + np.arange(1, n + 1, dtype=np.int64)
            self.u_last += n
            self.last_raw = int(raw[-1])
            self._hold(keys, batch, hosts)
            return
        d = np.empty(n, np.int64)
        d[1:] = np.diff(raw) % U32
        d[0] = -1 if self.last_raw is None else (raw[0] - self.last_raw) % U32
        restart = (d < 0) | (d >= U32 // 2)
        keep = d != 0
        self.duplicates += int(n - keep.sum())
        u = np.empty(n, np.int64)
        epoch = np.empty(n, np.int64)
        bounds = [*np.flatnonzero(restart).tolist(), n]
        if bounds[0] != 0:
            bounds.insert(0, 0)
        for s, e in zip(bounds[:-1], bounds[1:], strict=True):
            if restart[s]:
                if d[s] >= 0:  # a real restart, not the stream's first frame
                    self.epoch += 1
                    log.warning("module %d: frame counter restarted (%d after %d)",
                                self.index, int(raw[s]), self.last_raw)
                base = int(raw[s])
                u[s:e] = base + np.concatenate([[0], np.cumsum(d[s + 1:e])])
            else:
                u[s:e] = self.u_last + np.cumsum(d[s:e])
            epoch[s:e] = self.epoch
            self.u_last = int(u[e - 1])
            self.last_raw = int(raw[e - 1])
        keys = (epoch << KEY_BITS) | u
        if not keep.all():
            keys, batch, hosts = keys[keep], batch.take(keep), hosts[keep]
        self._hold(keys, batch, hosts)

    def _hold(self, keys: npt.NDArray[np.int64], batch: PacketBatch,
              hosts: npt.NDArray[np.int64]) -> None:
        if keys.size:
            self.keys.append(keys)
            self.batches.append(batch)
            self.hosts.append(hosts)
            self.n_pending += int(keys.size)
            self.watermark = int(keys[-1])

    def drop_upto(self, limit: int) -> int:
        """Discard pending rows with key <= ``limit`` (late frames); return how many."""
        if not self.keys or self.keys[0][0] > limit:
            return 0
        keys, _, _ = self.take_upto(limit)
        return int(keys.size)

    def take_upto(self, limit: int) -> Part:
        """Remove and return pending rows with key <= ``limit``."""
        if not self.keys:
            return np.zeros(0, np.int64), PacketBatch.empty(), np.zeros(0, np.int64)
        keys = self.keys[0] if len(self.keys) == 1 else np.concatenate(self.keys)
        batch = PacketBatch.concatenate(self.batches)
        hosts = self.hosts[0] if len(self.hosts) == 1 else np.concatenate(self.hosts)
        cut = int(np.searchsorted(keys, limit, side="right"))
        if cut == keys.size:
            self.keys, self.batches, self.hosts = [], [], []
            self.n_pending = 0
            return keys, batch, hosts
        self.keys, self.batches, self.hosts = [keys[cut:]], [batch.take(slice(cut, None))], \
            [hosts[cut:]]
        self.n_pending = int(keys.size) - cut
        return keys[:cut], batch.take(slice(0, cut)), hosts[:cut]


def aligned(parts: list[Part]) -> bool:
    """Whether every module holds the same frames, consecutive (no merging to do).

    A module's keys increase strictly, so equal sizes, first and last keys spanning exactly
    ``size`` keys mean equal key arrays.
    """
    keys = parts[0][0]
    n = int(keys.size)
    if not n:
        return False
    lo, hi = int(keys[0]), int(keys[-1])
    if hi - lo != n - 1:
        return False
    return all(k.size == n and int(k[0]) == lo and int(k[-1]) == hi for k, _, _ in parts[1:])


def in_step(streams: list[ModuleStream], last_key: int | None) -> bool:
    """Whether every module has bytes, holds no frame and is at the last frame emitted.

    Then, if every module's bytes continue its counter one by one with the same frame numbers
    (:func:`continue_in_step`), their frames need no per-module holding or merging: the driver
    builds the block at once.
    """
    if last_key is None:
        return False
    for s in streams:
        if (not s.raw or s.n_pending or s.last_raw is None
                or (s.epoch << KEY_BITS) + s.u_last != last_key):
            return False
    return True


def continue_in_step(streams: list[ModuleStream], frames: npt.NDArray[np.int64],
                     ) -> npt.NDArray[np.int64] | None:
    """Take frames that continue every module's counter one by one, the same for all modules.

    ``frames`` are the raw counters, ``(modules, n)``, of modules :func:`in_step`. Returns their
    merge keys, with each module's unwrapping advanced as :meth:`ModuleStream.ingest` and
    :meth:`ModuleStream.take_upto` of them would leave it; None, touching nothing, otherwise.
    """
    s0 = streams[0]
    n = frames.shape[1]
    assert s0.last_raw is not None  # in_step
    start = s0.last_raw + 1
    # The frames after the last one, one by one (a uint32 wrap inside goes the general way).
    if (start + n > U32 or any(s.last_raw != s0.last_raw for s in streams)
            or not bool((frames == np.arange(start, start + n, dtype=np.int64)).all())):
        return None
    keys = (s0.epoch << KEY_BITS) + s0.u_last + np.arange(1, n + 1, dtype=np.int64)
    last_raw, last_key = int(frames[0, -1]), int(keys[-1])
    for s in streams:
        s.u_last += n
        s.last_raw = last_raw
        s.watermark = last_key
    return keys
