"""``windrig export RUN.h5 --to csv|mat|netcdf|tdms [--out PATH]``: the subcommand's parser.

Responsibility: :func:`add_parser` registers the subcommand on :mod:`daq.cli`'s parser (this
module imports no numerics, so ``windrig --help`` stays fast); :func:`run` hands the parsed
arguments to :func:`daq.exchange.export_run.run_export`.

Not responsible for: the export itself (:mod:`daq.exchange.export_run`).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    """Register the ``export`` subcommand on the subparsers ``sub`` of :mod:`daq.cli`."""
    p = sub.add_parser(
        "export", help="a run file's sync view, releases, events and calibrations, with units, "
                       "as CSV, MATLAB (.mat v5), netCDF-4 or TDMS")
    p.add_argument("file", type=Path, help="a windrig HDF5 run file")
    p.add_argument("--to", required=True, choices=("csv", "mat", "netcdf", "tdms"),
                   help="the format")
    p.add_argument("--out", type=Path, default=None,
                   help="file (csv: folder) to create; never overwritten (default: beside the "
                        "run: RUN_csv/, RUN.mat, RUN.nc, RUN.tdms)")


def run(args: argparse.Namespace) -> int:
    """Run ``windrig export`` from parsed arguments; return the exit status."""
    from daq.exchange.export_run import run_export

    return run_export(args.file, args.to, args.out)
