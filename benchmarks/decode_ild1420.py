"""Throughput of the ILD1420 decoder and driver read path, on one core.

A realistic stream: 10 s at the full 4 kHz with the default block (distance, counter, two
timestamp words, status: 15 bytes), i.e. 40 000 blocks, 600 kB. It is fed to the decoder in chunks
of several sizes (a serial port hands over whatever arrived: from a few bytes to kilobytes), then
again with one byte lost every 100 blocks (resynchronisation cost), then through the whole driver
read path (decoder, counter/timestamp unwrapping, block building) from an in-memory transport.

Run: ``.venv/bin/python benchmarks/decode_ild1420.py``. Needs 4 000 frames/s to keep up.
"""

from __future__ import annotations

import os

os.environ["OPENBLAS_NUM_THREADS"] = "1"  # one core, before numpy is imported

import time  # noqa: E402

import numpy as np  # noqa: E402

from daq.errors import TransportTimeout  # noqa: E402
from daq.instruments.microepsilon_ild1420.decoder import Ild1420Decoder
from daq.instruments.microepsilon_ild1420.driver import MicroEpsilonIld1420
from daq.instruments.microepsilon_ild1420.settings import Ild1420Settings

RATE_HZ = 4000.0
SECONDS = 10.0


def stream(n: int, seed: int = 0) -> bytes:
    """Encode n blocks as L, M, H bytes (docs/reference/wire_formats.md, "Laser")."""
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    ticks = 25 * k + 123456
    words = np.column_stack([
        np.clip(32760 + rng.normal(0, 2000, n).astype(np.int64), 0, 65520),
        k % 262144, ticks & 0xFFFF, (ticks >> 16) & 0xFFFF, np.full(n, 1 << 16),
    ])
    out = np.empty((n, words.shape[1], 3), dtype=np.uint8)
    out[..., 0] = words & 0x3F
    out[..., 1] = 0x40 | ((words >> 6) & 0x3F)
    out[..., 2] = 0x80 | ((words >> 12) & 0x3F)
    out[:, 1:, 2] |= 0x40
    return out.tobytes()


def damaged(data: bytes, block: int, every: int) -> bytes:
    """Drop the second byte of every ``every``-th block (a lost byte mid-word)."""
    out = bytearray()
    for start in range(0, len(data), block * every):
        piece = data[start:start + block * every]
        out += piece[:1] + piece[2:]
    return bytes(out)


def run_decoder(data: bytes, chunk: int) -> tuple[float, int, int]:
    decoder = Ild1420Decoder()
    t0 = time.perf_counter()
    n = 0
    for i in range(0, len(data), chunk):
        n += len(decoder.feed(data[i:i + chunk]))
    return time.perf_counter() - t0, n, decoder.bytes_skipped


class MemoryTransport:
    """Hands out a byte string in fixed chunks, then times out."""

    url = "memory://"

    def __init__(self, data: bytes, chunk: int) -> None:
        self._data, self._chunk, self._pos = data, chunk, 0

    @property
    def is_open(self) -> bool:
        return True

    def open(self) -> None:
        pass

    def close(self) -> None:
        pass

    def write(self, data: bytes) -> None:
        pass

    def reset_input(self) -> None:
        pass

    def read(self, max_bytes: int, timeout_s: float) -> bytes:
        if self._pos >= len(self._data):
            raise TransportTimeout("memory://: end of data")
        out = self._data[self._pos:self._pos + min(max_bytes, self._chunk)]
        self._pos += len(out)
        return out


def run_driver(data: bytes, chunk: int, max_samples: int) -> tuple[float, int]:
    settings = Ild1420Settings(range_mm=10, rate_hz=RATE_HZ, x=0.1, standoff_mm=5.0)
    driver = MicroEpsilonIld1420(MemoryTransport(data, chunk), settings)  # type: ignore[arg-type]
    driver._open = True  # the stream only: no command exchange with an in-memory transport
    t0 = time.perf_counter()
    n = 0
    try:
        while True:
            n += len(driver.read(timeout_s=0.0 if n else 1.0, max_samples=max_samples))
    except TransportTimeout:
        pass
    return time.perf_counter() - t0, n


def main() -> None:
    n = int(RATE_HZ * SECONDS)
    data = stream(n)
    print(f"ILD1420 stream: {n} blocks ({SECONDS:g} s at {RATE_HZ:g} Hz), {len(data)} bytes")
    print("decoder alone:")
    for chunk in (15, 256, 4096, 65536):
        elapsed, got, _ = run_decoder(data, chunk)
        print(f"  chunks of {chunk:6d} B: {got / elapsed:12,.0f} frames/s "
              f"({elapsed * 1e3:7.1f} ms for {got} frames)")
    bad = damaged(data, 15, 100)
    elapsed, got, skipped = run_decoder(bad, 4096)
    print(f"  1 byte lost per 100 blocks, chunks of 4096 B: {got / elapsed:12,.0f} frames/s "
          f"({got} frames, {skipped} bytes skipped)")
    print("driver read path (decode, unwrap, gaps, block):")
    for chunk, max_samples in ((4096, 100_000), (65536, 100_000), (4096, 40)):
        elapsed, got = run_driver(data, chunk, max_samples)
        print(f"  chunks of {chunk:6d} B, blocks of <= {max_samples:6d}: "
              f"{got / elapsed:12,.0f} frames/s")


if __name__ == "__main__":
    main()
