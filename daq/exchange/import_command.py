"""``windrig import SOURCE... --map MAP.toml --out DIR``: a lab's files into run files.

Responsibility: :func:`add_parser` registers the subcommand on :mod:`daq.cli`'s parser (this
module imports no numerics, so ``windrig --help`` stays fast); :func:`run` imports the sources
(:func:`daq.exchange.importing.import_sources`), prints one line per run file written (its
releases and wind speeds) and any warnings, and with ``--json`` writes the same as JSON
(``files``: source, run file, release instants s, U m/s; ``warnings``). Errors are one
:class:`~daq.errors.UsageError` line through :mod:`daq.cli`'s boundary (exit 2).

Not responsible for: the import itself (:mod:`daq.exchange.importing`).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    """Register the ``import`` subcommand on the subparsers ``sub`` of :mod:`daq.cli`."""
    p = sub.add_parser(
        "import", help="turn a lab's CSV, MATLAB (.mat v5/v7.3) or TDMS files into run files, "
                       "through an import map (docs/guides/import_export.md)")
    p.add_argument("sources", type=Path, nargs="+", metavar="SOURCE",
                   help="CSV, .mat or .tdms files (one run file per file, or per TDMS group)")
    p.add_argument("--map", type=Path, required=True, metavar="MAP.toml",
                   help="the import map: channels, units, signs, wind, releases, rig config")
    p.add_argument("--out", type=Path, required=True, metavar="DIR",
                   help="folder of the run files (created if missing; files are never "
                        "overwritten)")
    p.add_argument("--json", type=Path, default=None,
                   help="write what was imported (files, release instants, wind speeds, "
                        "warnings) to this file")


def run(args: argparse.Namespace) -> int:
    """Run ``windrig import``; returns the exit code (0)."""
    from daq.exchange.importing import import_sources  # per-subcommand import: fast --help

    runs = import_sources(args.sources, args.map, args.out)
    warnings = [w for r in runs for w in r.warnings]
    for r in runs:
        speeds = ", ".join(f"{u:.2f}" for u in r.speeds)
        print(f"{r.source} -> {r.path}: {len(r.speeds)} release(s) at U = {speeds} m/s")
    for w in warnings:
        print(f"warning: {w}")
    if args.json is not None:
        doc = {"files": [{"source": r.source, "run_file": str(r.path),
                          "release_times_s": list(r.release_times), "U_m_per_s": list(r.speeds)}
                         for r in runs],
               "units": {"release_times_s": "s, on the source's time base", "U_m_per_s": "m/s"},
               "warnings": warnings}
        args.json.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    return 0
