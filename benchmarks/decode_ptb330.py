"""Throughput of the PTB330 line decoder on one core (not a test).

The barometer sends about one line per second, so any decoder is fast enough; this measures the
headroom and guards against a pathological regression (e.g. quadratic buffering). The stream is
lines as the driver's FORM produces them (``P=  1013.250 hPa    T= 21.34 'C`` CR LF), with the
pressure unit changing every 1000 lines (the simulator's fault "unit_change"), fed in 64-byte chunks
as a serial port returns them. A second stream has 10 % garbled and 5 % truncated lines.

Run: ``.venv/bin/python benchmarks/decode_ptb330.py [--lines 200000]``. ``--quick`` (CI)
decodes 10 000 lines; ``--results DIR`` writes the tables (``benchmarks/result_files.py``).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: one-core timings
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from daq.instruments.vaisala_ptb330.decoder import (
    Ptb330Line,
    Ptb330LineDecoder,
    parse_line,
    reading_from_line,
)

sys.path.insert(0, str(Path(__file__).resolve().parent))
import result_files  # noqa: E402 - beside this script

#: Lines per stream: full run and --quick.
LINES = 200_000
QUICK_LINES = 10_000
#: What a real barometer sends, lines/s (for the notes).
LINE_RATE_HZ = 1.0

UNITS = [("hPa", 100.0), ("kPa", 1000.0), ("mmHg", 133.322387415), ("inHg", 3386.388640341),
         ("psi", 6894.757293168), ("Pa", 1.0), ("mbar", 100.0)]


def make_stream(n: int, rng: np.random.Generator, garbled: float = 0.0,
                partial: float = 0.0) -> tuple[bytes, int]:
    """Return the byte stream of ``n`` lines and the number of intact lines in it."""
    pressure = 101325.0 + rng.normal(0.0, 2.0, n)
    temperature = 21.0 + rng.normal(0.0, 0.02, n)
    draw = rng.random(n)
    lines, intact = [], 0
    for i in range(n):
        unit, factor = UNITS[(i // 1000) % len(UNITS)]
        line = f"P={pressure[i] / factor:10.3f} {unit:<6}T={temperature[i]:6.2f} 'C \r\n".encode()
        if draw[i] < garbled:
            body = bytearray(line)
            body[int(rng.integers(0, len(line) - 2))] = ord("?")
            line = bytes(body)
        elif draw[i] < garbled + partial:
            line = line[: int(rng.integers(1, len(line) - 2))]
        else:
            intact += 1
        lines.append(line)
    return b"".join(lines), intact


def time_decoder(stream: bytes, chunk: int) -> tuple[float, int, Ptb330LineDecoder]:
    decoder = Ptb330LineDecoder()
    ok = 0
    start = time.perf_counter()
    for i in range(0, len(stream), chunk):
        for item in decoder.feed(stream[i:i + chunk]):
            if isinstance(item, Ptb330Line):
                reading_from_line(item, 0, ok)
                ok += 1
    return time.perf_counter() - start, ok, decoder


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lines", type=int, default=None,
                        help=f"lines per stream (default {LINES}; --quick: {QUICK_LINES})")
    parser.add_argument("--chunk", type=int, default=64, help="bytes per transport read")
    result_files.add_arguments(parser)
    args = parser.parse_args(argv)
    if args.lines is None:
        args.lines = QUICK_LINES if args.quick else LINES
    if args.lines < 1 or args.chunk < 1:
        parser.error("--lines and --chunk must be >= 1")
    rng = np.random.default_rng(0)
    rate, mbs = "throughput (lines/s)", "throughput (MB/s)"
    rows = []

    clean, n_clean = make_stream(args.lines, rng)
    elapsed, ok, dec = time_decoder(clean, args.chunk)
    assert ok == n_clean == args.lines and dec.lines_bad == 0
    print(f"clean stream:  {args.lines} lines, {len(clean) / 1e6:.1f} MB, chunks of "
          f"{args.chunk} B: {ok / elapsed:,.0f} lines/s ({len(clean) / elapsed / 1e6:.1f} MB/s) "
          "decode + plausibility + density")
    rows.append(["clean", args.lines, len(clean) / 1e6, n_clean, ok, dec.lines_bad,
                 dec.bytes_skipped, ok / elapsed, len(clean) / elapsed / 1e6])

    faulty, n_intact = make_stream(args.lines, rng, garbled=0.10, partial=0.05)
    elapsed, ok, dec = time_decoder(faulty, args.chunk)
    assert ok == n_intact, (ok, n_intact)  # every intact line survives its damaged neighbours
    print(f"faulty stream: {ok / elapsed:,.0f} good lines/s; {dec.lines_bad} bad lines flagged, "
          f"{dec.bytes_skipped} bytes skipped, {ok} of {n_intact} intact lines decoded")
    rows.append(["10 % garbled, 5 % truncated", args.lines, len(faulty) / 1e6, n_intact, ok,
                 dec.lines_bad, dec.bytes_skipped, ok / elapsed, len(faulty) / elapsed / 1e6])

    bodies = clean.split(b"\r\n")[: min(args.lines, 50_000)]
    start = time.perf_counter()
    for body in bodies:
        parse_line(body)
    elapsed = time.perf_counter() - start
    print(f"parse_line alone: {len(bodies) / elapsed:,.0f} lines/s "
          f"(real barometer: ~1 line/s)")

    tables = [
        result_files.Table(
            f"PTB330 line decoder on one core (decode, plausibility, density), fed in chunks "
            f"of {args.chunk} B.",
            ["stream", "lines", "size (MB)", "intact lines", "good lines decoded",
             "bad lines flagged", "bytes skipped", rate, mbs], rows,
            formats={"size (MB)": ".2f", rate: ",.0f", mbs: ".1f"}),
        result_files.Table(
            "PTB330 parse_line alone on one core, lines of the clean stream.",
            ["lines", rate], [[len(bodies), len(bodies) / elapsed]], formats={rate: ",.0f"}),
    ]
    result_files.write(
        "decode_ptb330", "PTB330 barometer decoder throughput", tables, results=args.results,
        quick=args.quick,
        parameters={"lines": args.lines, "chunk_bytes": args.chunk, "seed": 0,
                    "unit_change_every_lines": 1000, "garbled_fraction": 0.10,
                    "truncated_fraction": 0.05},
        notes=[f"A real barometer sends about {LINE_RATE_HZ:g} line/s; the slowest case here "
               f"decoded {min(r[7] for r in rows):,.0f} lines/s.",
               "good lines decoded counts the lines decoded and turned into readings; every "
               "intact line of the faulty stream is checked to survive its damaged "
               "neighbours."])
    if args.results is not None:
        print(f"results: {args.results / 'decode_ptb330.json'} and .md")


if __name__ == "__main__":
    main()
