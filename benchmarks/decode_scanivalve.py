"""Throughput of the Scanivalve MPS4264 frame decoder and block assembly, on one core.

A realistic stream is 10 s at 500 Hz (the issue's full rate): 5000 packets per module. The
decoder is fed as a TCP reader sees it (1448-byte segments, 64 KiB reads, or one packet per
read, the worst case); the driver's ``read_block`` path (decode, unwrap, merge two modules,
mark gaps) is timed on scripted data connections. Prints frames/s and the margin over the
real-time need (500 frames/s per module).

Run: ``.venv/bin/python benchmarks/decode_scanivalve.py [--seconds 10] [--repeats 5]``.
``--quick`` (CI) decodes 1 s, best of 2; ``--results DIR`` writes the table
(``benchmarks/result_files.py``).
"""

from __future__ import annotations

import os

os.environ["OPENBLAS_NUM_THREADS"] = "1"  # one core, before numpy is imported

import argparse  # noqa: E402
import struct  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from daq.errors import TransportTimeout  # noqa: E402
from daq.instruments.scanivalve_mps4264.driver import ScanivalveMps4264
from daq.instruments.scanivalve_mps4264.frames import Mps4264Decoder
from daq.instruments.scanivalve_mps4264.settings import Mps4264Settings
from daq.transports.scripted import ScriptedTransport  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import result_files  # noqa: E402 - beside this script

RATE_HZ = 500.0
SECONDS = 10.0
N = int(RATE_HZ * SECONDS)
REPEATS = 5
#: A --quick run: seconds of stream, repeats.
QUICK_SECONDS = 1.0
QUICK_REPEATS = 2


def legacy_stream(n: int, rng: np.random.Generator) -> bytes:
    """``n`` legacy 0x0A packets (348 B, big-endian), pressures ~N(0, 50) Pa."""
    p = rng.normal(0.0, 50.0, (n, 64)).astype(np.float32)
    out = []
    for k in range(n):
        t_ns = 1_767_225_600 * 10**9 + round(k * 1e9 / RATE_HZ)
        out.append(struct.pack(">iiIifiifIII8f64fIIII", 0x0A, 348, k + 1, 4264001, RATE_HZ, 0,
                               23, 6894.75977, 1_767_225_600, 0, 0, *[21.0] * 8, *p[k],
                               t_ns // 10**9, t_ns % 10**9, 0, 0))
    return b"".join(out)


def eu_stream(n: int, rng: np.random.Generator) -> bytes:
    """``n`` MPS-4264 EU 0x6D packets (304 B, little-endian)."""
    p = rng.normal(0.0, 50.0, (n, 64)).astype(np.float32)
    return b"".join(struct.pack("<iIII8f64f", 0x6D, k + 1, k // 500, (k % 500) * 2_000_000,
                                *[21.0] * 8, *p[k]) for k in range(n))


def time_decoder(stream: bytes, chunk: int, n_frames: int = N, repeats: int = REPEATS) -> float:
    """Best of ``repeats``: seconds to decode ``stream`` (``n_frames``) in ``chunk``-byte pieces."""
    pieces = [stream[i:i + chunk] for i in range(0, len(stream), chunk)]
    best = float("inf")
    for _ in range(repeats):
        decoder = Mps4264Decoder()
        t0 = time.perf_counter()
        n = 0
        for piece in pieces:
            n += len(decoder.feed(piece))
        best = min(best, time.perf_counter() - t0)
        assert n == n_frames and decoder.bytes_skipped == 0, (n, decoder.bytes_skipped)
    return best


class ChunkedTransport(ScriptedTransport):
    """Data connection whose reads return one TCP segment each (as a socket would)."""

    def __init__(self, chunks: list[bytes]) -> None:
        super().__init__([])
        self._chunks = chunks
        self._next_chunk = 0

    def read(self, max_bytes: int, timeout_s: float) -> bytes:
        if self._next_chunk >= len(self._chunks):
            raise TransportTimeout("no more segments")
        self._next_chunk += 1
        return self._chunks[self._next_chunk - 1]


def time_driver(stream: bytes, modules: int, chunk: int, n_frames: int = N,
                repeats: int = REPEATS) -> float:
    """Best of ``repeats``: seconds for ``read_block`` to deliver every frame of every module."""
    settings = Mps4264Settings(modules=modules, rate_hz=RATE_HZ, byte_order="big",
                               pitot_channel=64 * modules - 1)
    best = float("inf")
    for _ in range(repeats):
        data: list[ScriptedTransport] = [
            ChunkedTransport([stream[i:i + chunk] for i in range(0, len(stream), chunk)])
            for _ in range(modules)]
        command = ScriptedTransport([(b"STATUS\r\n", b"STATUS: READY\r\n"),
                                     (b"SCAN\r\n", b""), (b"STATUS\r\n", b"STATUS: SCAN\r\n")])
        driver = ScanivalveMps4264(command, settings, data_transports=data)
        driver.open()
        driver.scan()
        frames = 0
        t0 = time.perf_counter()
        while frames < n_frames:
            try:
                frames += len(driver.read_block(0.0))
            except TransportTimeout:
                break
        best = min(best, time.perf_counter() - t0)
        assert frames == n_frames, frames
    return best


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=None,
                        help=f"stream length at {RATE_HZ:g} Hz, s (default {SECONDS:g}; "
                        f"--quick: {QUICK_SECONDS:g})")
    parser.add_argument("--repeats", type=int, default=None,
                        help=f"best of this many runs per case (default {REPEATS}; --quick: "
                        f"{QUICK_REPEATS})")
    result_files.add_arguments(parser)
    args = parser.parse_args(argv)
    seconds = args.seconds if args.seconds is not None else (
        QUICK_SECONDS if args.quick else SECONDS)
    repeats = args.repeats if args.repeats is not None else (
        QUICK_REPEATS if args.quick else REPEATS)
    n = int(RATE_HZ * seconds)
    if n < 1 or repeats < 1:
        parser.error("--seconds must give at least one frame, --repeats must be >= 1")
    rng = np.random.default_rng(0)
    legacy, eu = legacy_stream(n, rng), eu_stream(n, rng)
    print(f"Scanivalve MPS4264 decoding, one core: {n} frames per module "
          f"({seconds:g} s at {RATE_HZ:g} Hz); best of {repeats}")
    print(f"{'case':<52}{'frames/s':>12}{'x real time':>13}")
    cases = [
        ("decoder, legacy 348 B, 1448-byte segments", legacy, 1448),
        ("decoder, legacy 348 B, 64 KiB reads", legacy, 65536),
        ("decoder, legacy 348 B, one packet per read", legacy, 348),
        ("decoder, EU 304 B (little-endian), 1448-byte segm.", eu, 1448),
    ]
    rows = []
    for label, stream, chunk in cases:
        seconds_taken = time_decoder(stream, chunk, n, repeats)
        rate = n / seconds_taken
        print(f"{label:<52}{rate:>12,.0f}{rate / RATE_HZ:>13,.0f}")
        rows.append([label, 1, chunk, rate, rate / RATE_HZ])
    for modules, chunk in ((1, 1448), (2, 1448), (8, 1448), (2, 348)):
        seconds_taken = time_driver(legacy, modules, chunk, n, repeats)
        rate = n / seconds_taken  # frame rows (each merges `modules` packets)
        label = f"read_block, {modules} module(s), {chunk}-byte reads"
        print(f"{label:<52}{rate:>12,.0f}{rate / RATE_HZ:>13,.0f}")
        rows.append([label, modules, chunk, rate, rate / RATE_HZ])
    rate_col, real = "throughput (frames/s)", "x real time"
    table = result_files.Table(
        f"Scanivalve MPS4264 decoder and read_block path on one core, {n} frames per module, "
        f"best of {repeats}.",
        ["case", "modules", "read size (B)", rate_col, real], rows,
        formats={rate_col: ",.0f", real: ",.0f"})
    result_files.write(
        "decode_scanivalve", "Scanivalve MPS4264 decoder throughput", [table],
        results=args.results, quick=args.quick,
        parameters={"seconds": seconds, "rate_hz": RATE_HZ, "frames_per_module": n,
                    "repeats": repeats},
        notes=[f"x real time is the throughput over the {RATE_HZ:g} frames/s one module sends "
               "at its full rate; a read_block frame row merges one packet of every module.",
               f"The slowest case ran at {min(r[4] for r in rows):,.0f} x real time."])
    if args.results is not None:
        print(f"results: {args.results / 'decode_scanivalve.json'} and .md")


if __name__ == "__main__":
    main()
