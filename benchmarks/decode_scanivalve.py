"""Throughput of the Scanivalve MPS4264 frame decoder and block assembly, on one core.

A realistic stream is 10 s at 500 Hz (the issue's full rate): 5000 packets per module. The
decoder is fed as a TCP reader sees it (1448-byte segments, 64 KiB reads, or one packet per
read, the worst case); the driver's ``read_block`` path (decode, unwrap, merge two modules,
mark gaps) is timed on scripted data connections. Prints frames/s and the margin over the
real-time need (500 frames/s per module).

Run: ``.venv/bin/python benchmarks/decode_scanivalve.py``
"""

from __future__ import annotations

import os

os.environ["OPENBLAS_NUM_THREADS"] = "1"  # one core, before numpy is imported

import struct  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from daq.errors import TransportTimeout  # noqa: E402
from daq.instruments.scanivalve_mps4264.driver import ScanivalveMps4264
from daq.instruments.scanivalve_mps4264.frames import Mps4264Decoder
from daq.instruments.scanivalve_mps4264.settings import Mps4264Settings
from daq.transports.scripted import ScriptedTransport  # noqa: E402

RATE_HZ = 500.0
SECONDS = 10.0
N = int(RATE_HZ * SECONDS)
REPEATS = 5


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


def time_decoder(stream: bytes, chunk: int) -> float:
    """Best of REPEATS: seconds to decode ``stream`` fed in ``chunk``-byte pieces."""
    pieces = [stream[i:i + chunk] for i in range(0, len(stream), chunk)]
    best = float("inf")
    for _ in range(REPEATS):
        decoder = Mps4264Decoder()
        t0 = time.perf_counter()
        n = 0
        for piece in pieces:
            n += len(decoder.feed(piece))
        best = min(best, time.perf_counter() - t0)
        assert n == N and decoder.bytes_skipped == 0, (n, decoder.bytes_skipped)
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


def time_driver(stream: bytes, modules: int, chunk: int) -> float:
    """Best of REPEATS: seconds for ``read_block`` to deliver every frame of every module."""
    settings = Mps4264Settings(modules=modules, rate_hz=RATE_HZ, byte_order="big",
                               pitot_channel=64 * modules - 1)
    best = float("inf")
    for _ in range(REPEATS):
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
        while frames < N:
            try:
                frames += len(driver.read_block(0.0))
            except TransportTimeout:
                break
        best = min(best, time.perf_counter() - t0)
        assert frames == N, frames
    return best


def main() -> None:
    rng = np.random.default_rng(0)
    legacy, eu = legacy_stream(N, rng), eu_stream(N, rng)
    print(f"Scanivalve MPS4264 decoding, one core: {N} frames per module "
          f"({SECONDS:g} s at {RATE_HZ:g} Hz); best of {REPEATS}")
    print(f"{'case':<52}{'frames/s':>12}{'x real time':>13}")
    cases = [
        ("decoder, legacy 348 B, 1448-byte segments", legacy, 1448),
        ("decoder, legacy 348 B, 64 KiB reads", legacy, 65536),
        ("decoder, legacy 348 B, one packet per read", legacy, 348),
        ("decoder, EU 304 B (little-endian), 1448-byte segm.", eu, 1448),
    ]
    for label, stream, chunk in cases:
        seconds = time_decoder(stream, chunk)
        rate = N / seconds
        print(f"{label:<52}{rate:>12,.0f}{rate / RATE_HZ:>13,.0f}")
    for modules, chunk in ((1, 1448), (2, 1448), (8, 1448), (2, 348)):
        seconds = time_driver(legacy, modules, chunk)
        rate = N / seconds  # frame rows (each merges `modules` packets)
        label = f"read_block, {modules} module(s), {chunk}-byte reads"
        print(f"{label:<52}{rate:>12,.0f}{rate / RATE_HZ:>13,.0f}")


if __name__ == "__main__":
    main()
