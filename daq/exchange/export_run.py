"""``windrig export RUN.h5 --to csv|mat|netcdf|tdms [--out PATH]``: the command.

Responsibility: check the command's values (the format, an output that must not exist yet and
whose folder must), read the run file (:func:`daq.exchange.export_contents.read_contents`),
hand it to the format's writer (:data:`daq.exchange.export_writers.WRITERS`) and say what was
written, with a ``warning:`` line for each part the file lacks and for an output name that does
not fit the format.

Not responsible for: the formats (:mod:`daq.exchange.export_writers`), reading the run file
(:mod:`daq.exchange.export_contents`).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from daq.errors import UsageError
from daq.exchange.export_contents import RunContents, read_contents
from daq.exchange.export_writers import WRITERS

__all__ = ["FORMATS", "default_output", "export_run", "run_export"]

#: Formats and the suffix of what each writes (a CSV export is a folder).
FORMATS = {"csv": "_csv", "mat": ".mat", "netcdf": ".nc", "tdms": ".tdms"}


def default_output(path: Path, to: str) -> Path:
    """Return where ``to`` goes by default: beside the run (``RUN_csv/``, ``RUN.mat``, ...)."""
    return path.with_name(path.stem + FORMATS[to])


def export_run(path: str | os.PathLike[str], to: str,
               out: str | os.PathLike[str] | None = None) -> tuple[list[Path], RunContents]:
    """Export a run file to ``to`` (one of :data:`FORMATS`).

    Parameters
    ----------
    path : path-like
        The run file.
    to : {"csv", "mat", "netcdf", "tdms"}
        The format.
    out : path-like, optional
        The file (a folder for CSV) to create; default :func:`default_output`. It must not exist:
        an export never overwrites.

    Returns
    -------
    (list of Path, RunContents)
        The files written, and what was read (with its ``warnings``, the export's included).

    Raises
    ------
    UsageError
        An unknown format, or an output that exists already or whose folder is missing.
    NotARunFileError
        The run file cannot be exported (:func:`read_contents`).
    """
    if to not in FORMATS:
        raise UsageError(f"--to {to!r}: not a format; one of {', '.join(FORMATS)}")
    source = Path(path)
    target = default_output(source, to) if out is None else Path(out)
    if target.exists():
        raise UsageError(f"{target}: exists already; an export never overwrites (remove it or "
                         "give another --out)")
    if not target.parent.is_dir():
        raise UsageError(f"{target}: its folder {target.parent} does not exist")
    contents = read_contents(source)
    suffix = FORMATS[to]
    if to != "csv" and target.suffix.lower() != suffix:
        contents.warnings.append(f"{target}: a {to} file is usually named *{suffix}; written "
                                 f"as {to} all the same (is --to {to} what you meant?)")
    if to == "csv" and target.suffix:
        contents.warnings.append(f"{target}: a CSV export is a folder of .csv files; the "
                                 f"folder is named {target.name} (a file name was meant?)")
    written = WRITERS[to](contents, target)
    return written, contents


def run_export(path: Path, to: str, out: Path | None) -> int:
    """``windrig export``: write the export, print what it holds; exit status 0.

    Warnings (what the file lacks, a suffix that does not fit the format) go to stderr as
    ``warning:`` lines; errors are raised for the command line's error boundary.
    """
    written, contents = export_run(path, to, out)
    for line in contents.warnings:
        print(f"warning: {line}", file=sys.stderr)
    where = written[0].parent if to == "csv" else written[0]
    print(f"wrote {where} ({to}, {len(written)} file(s)): {contents.n_rows} sync rows of "
          f"{len(contents.columns)} columns, {contents.releases.size} release(s), "
          f"{contents.events['time'].size} event(s), {len(contents.calibrations)} "
          "calibration(s)")
    return 0
