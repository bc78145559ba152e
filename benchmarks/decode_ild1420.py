"""Throughput of the ILD1420 decoder and driver read path, on one core.

A realistic stream: 10 s at the full 4 kHz with the default block (distance, counter, two
timestamp words, status: 15 bytes), i.e. 40 000 blocks, 600 kB. It is fed to the decoder in chunks
of several sizes (a serial port hands over whatever arrived: from a few bytes to kilobytes), then
again with one byte lost every 100 blocks (resynchronisation cost), then through the whole driver
read path (decoder, counter/timestamp unwrapping, block building) from an in-memory transport.

Run: ``.venv/bin/python benchmarks/decode_ild1420.py [--seconds 10]``. Needs 4 000 frames/s to
keep up. ``--quick`` (CI) streams 1 s; ``--results DIR`` writes the tables
(``benchmarks/result_files.py``).
"""

from __future__ import annotations

import os

os.environ["OPENBLAS_NUM_THREADS"] = "1"  # one core, before numpy is imported

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from daq.errors import TransportTimeout  # noqa: E402
from daq.instruments.microepsilon_ild1420.decoder import Ild1420Decoder
from daq.instruments.microepsilon_ild1420.driver import MicroEpsilonIld1420
from daq.instruments.microepsilon_ild1420.settings import Ild1420Settings

sys.path.insert(0, str(Path(__file__).resolve().parent))
import result_files  # noqa: E402 - beside this script

RATE_HZ = 4000.0
SECONDS = 10.0
#: Stream length of a --quick run, s.
QUICK_SECONDS = 1.0


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
    n, t_last = 0, t0
    try:
        while True:
            # The in-memory transport never waits, so the timeout only lets a read gather the
            # rest of a frame split over several chunks; the end of the data ends the loop
            # (after the driver's wait for more, which is why the clock stops at the last
            # frame delivered).
            n += len(driver.read(timeout_s=1.0, max_samples=max_samples))
            t_last = time.perf_counter()
    except TransportTimeout:
        pass
    return t_last - t0, n


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=None,
                        help=f"stream length at {RATE_HZ:g} Hz, s (default {SECONDS:g}; "
                        f"--quick: {QUICK_SECONDS:g})")
    result_files.add_arguments(parser)
    args = parser.parse_args(argv)
    seconds = args.seconds if args.seconds is not None else (
        QUICK_SECONDS if args.quick else SECONDS)
    if not seconds > 0:
        parser.error("--seconds must be > 0")
    n = int(RATE_HZ * seconds)
    data = stream(n)
    print(f"ILD1420 stream: {n} blocks ({seconds:g} s at {RATE_HZ:g} Hz), {len(data)} bytes")
    print("decoder alone:")
    decoder_rows = []
    for chunk in (15, 256, 4096, 65536):
        elapsed, got, _ = run_decoder(data, chunk)
        print(f"  chunks of {chunk:6d} B: {got / elapsed:12,.0f} frames/s "
              f"({elapsed * 1e3:7.1f} ms for {got} frames)")
        decoder_rows.append(["intact", chunk, got / elapsed, got / elapsed / RATE_HZ,
                             elapsed * 1e3, got, 0])
    bad = damaged(data, 15, 100)
    elapsed, got, skipped = run_decoder(bad, 4096)
    print(f"  1 byte lost per 100 blocks, chunks of 4096 B: {got / elapsed:12,.0f} frames/s "
          f"({got} frames, {skipped} bytes skipped)")
    decoder_rows.append(["1 byte lost per 100 blocks", 4096, got / elapsed,
                         got / elapsed / RATE_HZ, elapsed * 1e3, got, skipped])
    print("driver read path (decode, unwrap, gaps, block):")
    driver_rows = []
    for chunk, max_samples in ((4096, 100_000), (65536, 100_000), (4096, 40)):
        elapsed, got = run_driver(data, chunk, max_samples)
        print(f"  chunks of {chunk:6d} B, blocks of <= {max_samples:6d}: "
              f"{got / elapsed:12,.0f} frames/s")
        driver_rows.append([chunk, max_samples, got / elapsed, got / elapsed / RATE_HZ, got])
    rate = "throughput (frames/s)"
    tables = [
        result_files.Table(
            f"ILD1420 decoder alone on one core, {n} blocks fed in chunks of each size.",
            ["stream", "chunk (B)", rate, "x real time", "time (ms)", "frames",
             "bytes skipped"], decoder_rows,
            formats={rate: ",.0f", "x real time": ",.0f", "time (ms)": ".1f"}),
        result_files.Table(
            "ILD1420 driver read path (decode, unwrap, gaps, block) from an in-memory "
            "transport, one core.",
            ["chunk (B)", "block size (samples, at most)", rate, "x real time", "frames"],
            driver_rows, formats={rate: ",.0f", "x real time": ",.0f"}),
    ]
    worst = min(row[2] for row in decoder_rows + driver_rows)
    result_files.write(
        "decode_ild1420", "ILD1420 laser decoder throughput", tables, results=args.results,
        quick=args.quick,
        parameters={"seconds": seconds, "rate_hz": RATE_HZ, "blocks": n, "bytes": len(data),
                    "block_bytes": 15},
        warnings=[f"driver read path, chunks of {chunk} B, blocks of <= {max_samples}: "
                  f"{got} of {n} frames delivered; the rate counts those frames only"
                  for chunk, max_samples, _, _, got in driver_rows if got < n],
        notes=[f"x real time is the throughput over the {RATE_HZ:g} frames/s of one laser at "
               f"its full rate; the slowest case here ran at {worst / RATE_HZ:,.0f} x.",
               "One byte is lost mid-word in every hundredth block of the damaged stream; the "
               "decoder resynchronises and skips the rest of that block."])
    if args.results is not None:
        print(f"results: {args.results / 'decode_ild1420.json'} and .md")


if __name__ == "__main__":
    main()
