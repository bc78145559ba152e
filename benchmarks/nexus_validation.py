"""NeXus validation of a recorded run: punx and nexusformat's nxcheck, counts per severity.

What it does
------------
Records a short run with ``windrig acquire --simulate`` on a simulated rig (or takes the run
files given with ``--file``), then runs

- ``punx validate FILE`` (punx reports OK, NOTE, WARN, ERROR, TODO, OPTIONAL, ... per item);
- ``nxcheck FILE`` (nexusformat: errors and warnings against the NeXus base classes),

and prints the counts per severity and every ERROR and WARN line.

punx needs PyQt5 (imported at start-up), which must not be installed beside PySide6 in
windrig's own venv (the console and pytest-qt would have two Qt bindings to choose from). So
punx runs from a venv of its own, given with ``--punx``::

    python3 -m venv /tmp/punx-venv && /tmp/punx-venv/bin/pip install punx
    .venv/bin/python benchmarks/nexus_validation.py --punx /tmp/punx-venv/bin/punx

nxcheck comes with nexusformat (in windrig's test extra) and is taken from this interpreter's
folder.

Without ``--punx`` the script takes ``$WINDRIG_PUNX``, else a ``punx`` on the ``PATH`` (so that
``benchmarks/run.py`` can reach it); with none of them only nxcheck is run, and the result file
says so. ``--quick`` (CI) records a 1 s run instead of 4 s; ``--results DIR`` writes the counts
(``benchmarks/result_files.py``).

Measured (2026-11, punx 0.3.5 with NeXus definitions v2018.5, nexusformat 2.1.0), a 4 s run of
``sim_flat_plate.toml``:

=============================  =========================  ==========================
layout                         punx                       nxcheck
=============================  =========================  ==========================
before issue 17                16 ERROR, 146 WARN, 1 NOTE  0 errors, 8 warnings
raw streams NXlog (tried)      0 ERROR, 0 WARN, 1 NOTE     0 errors, 73 warnings
raw streams NXdata             0 ERROR, 0 WARN, 1 NOTE     0 errors, 8 warnings
calibrations NXcollection      0 ERROR, 14 WARN, 1 NOTE    0 errors, 8 warnings
calibrations NXparameters      0 ERROR, 0 WARN, 1 NOTE     0 errors, 8 warnings
=============================  =========================  ==========================

The ERRORs were the dots in per-device attribute names (``clock_offset_s.scanner``), the WARNs
every member of an ``NXcollection`` (punx does not validate them): the metadata's before issue
17, the calibrations' (issue 18, ``/entry/calibration``, 4 groups and 10 fields) before issue
37; both are ``NXparameters`` now. The NOTE is the field name
``U``, which only NeXus's relaxed name pattern allows. nxcheck's 8 warnings are windrig's own
attributes of ``/`` (``created``, ``windrig_version``) and ``/entry`` (``rig_name``,
``operator_notes``, ``start_time``) and its fields ``config``, ``releases`` and ``events``:
allowed, not defined by ``NXroot``/``NXentry``.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import result_files  # noqa: E402 - beside this script

REPO = Path(__file__).resolve().parents[1]
#: Length of the recorded run, s: full run and --quick.
DURATION_S = 4.0
QUICK_DURATION_S = 1.0
#: punx's severities shown in the summary table (all of them go to the second table).
PUNX_SHOWN = ("ERROR", "WARN", "NOTE")
#: The NeXus definitions' versions punx reported (filled by :func:`punx_counts`).
PUNX_DEFINITIONS: set[str] = set()


def record(out: Path, config: Path, duration_s: float) -> Path:
    """Record a run with ``windrig acquire --simulate``; return its path."""
    subprocess.run([sys.executable, "-m", "daq.cli", "acquire", "--config", str(config),
                    "--simulate", "--duration", f"{duration_s:g}", "--out", str(out)],
                   cwd=REPO, check=True, capture_output=True)
    return out


def punx_counts(punx: str, path: Path) -> tuple[dict[str, int], list[str]]:
    """Return punx's count per severity and its ERROR, WARN and NOTE lines.

    The NeXus definitions punx validated against go to :data:`PUNX_DEFINITIONS`.
    """
    done = subprocess.run([punx, "validate", str(path)], capture_output=True, text=True,
                          timeout=900, check=False)
    counts = {k: int(v) for k, v in re.findall(r"^([A-Z]+)\s+(\d+)\s+\S", done.stdout, re.M)}
    lines = [line.rstrip() for line in done.stdout.splitlines()
             if re.search(r"\s(ERROR|WARN|NOTE)\s", line)]
    found = re.search(r"^NeXus definitions: (\S+)", done.stdout, re.M)
    if found:
        PUNX_DEFINITIONS.add(found.group(1).rstrip(","))
    if not counts:
        raise RuntimeError(f"punx gave no summary:\n{done.stdout[-2000:]}{done.stderr[-2000:]}")
    return counts, lines


def nxcheck_counts(path: Path) -> tuple[int, int, str]:
    """Return nxcheck's numbers of errors and warnings, and its report (colours removed)."""
    nxcheck = Path(sys.executable).with_name("nxcheck")
    done = subprocess.run([str(nxcheck), str(path)], capture_output=True, text=True,
                          timeout=900, check=False)
    text = re.sub(r"\x1b\[[0-9;]*m", "", done.stdout + done.stderr)
    errors = re.search(r"Total number of errors: (\d+)", text)
    warnings = re.search(r"Total number of warnings: (\d+)", text)
    if errors is None or warnings is None:
        raise RuntimeError(f"nxcheck gave no summary:\n{text[-2000:]}")
    return int(errors.group(1)), int(warnings.group(1)), text


def _first_line(exc: BaseException) -> str:
    """Return an exception's first line of text, with its type."""
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}"


def punx_version(punx: str) -> str:
    """Return ``punx -v``'s version, or "unknown"."""
    try:
        done = subprocess.run([punx, "-v"], capture_output=True, text=True, timeout=300,
                              check=False)
    except (OSError, subprocess.TimeoutExpired):
        return "unknown"
    found = re.findall(r"^\s*(\d+(?:\.\d+)+\S*)\s*$", done.stdout, re.M)
    return found[-1] if found else "unknown"


def _version(package: str) -> str:
    try:
        return importlib.metadata.version(package)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--file", type=Path, action="append", default=[],
                        help="validate this run file (repeatable; default: record one)")
    parser.add_argument("--config", type=Path,
                        default=REPO / "rig_configs" / "sim_flat_plate.toml")
    parser.add_argument("--duration", type=float, default=None,
                        help=f"s, of the recorded run (default {DURATION_S:g}; --quick: "
                        f"{QUICK_DURATION_S:g})")
    parser.add_argument("--punx", default=None,
                        help="the punx executable (default: $WINDRIG_PUNX, else punx on the "
                        "PATH; see the docstring)")
    parser.add_argument("--verbose", action="store_true", help="print nxcheck's whole report")
    result_files.add_arguments(parser)
    args = parser.parse_args(argv)
    if args.duration is None:
        args.duration = QUICK_DURATION_S if args.quick else DURATION_S
    warnings: list[str] = []
    if not args.punx:
        args.punx = os.environ.get("WINDRIG_PUNX") or shutil.which("punx")
    if not args.punx:
        warnings.append("punx was not run (no --punx, no $WINDRIG_PUNX, no punx on the PATH: "
                        "punx needs PyQt5 and so a venv of its own, see the script's "
                        "docstring); its columns are empty and only nxcheck's counts were "
                        "measured.")
    summary: list[list[object]] = []
    severities: list[list[object]] = []
    items: list[list[object]] = []
    failed = False
    with tempfile.TemporaryDirectory() as tmp:
        files = list(args.file)
        labels = {path: path.name for path in files}
        if not files:
            try:
                path = record(Path(tmp) / "run.h5", args.config, args.duration)
            except subprocess.CalledProcessError as exc:
                tail = (exc.stderr or b"").decode(errors="replace").strip().splitlines()[-1:]
                print(f"recording failed: {' '.join(tail)}", file=sys.stderr)
                warnings.append(f"no run was recorded ({args.config.name}: windrig acquire "
                                f"exited {exc.returncode}); nothing was validated.")
                failed = True
            else:
                files = [path]
                labels[path] = f"recorded run ({args.config.name}, {args.duration:g} s)"
        for path in files:
            print(f"== {path.name}")
            counts: dict[str, int] | None = None
            if args.punx:
                try:
                    counts, lines = punx_counts(args.punx, path)
                except (OSError, RuntimeError, subprocess.TimeoutExpired) as exc:
                    print(f"punx:    failed: {_first_line(exc)}", file=sys.stderr)
                    warnings.append(f"punx failed on {labels[path]}: {_first_line(exc)}")
                    failed = True
                else:
                    print("punx:    " + ", ".join(f"{k} {v}" for k, v in counts.items()))
                    for line in lines:
                        print("  " + " ".join(line.split()))
                    severities += [[labels[path], k, v] for k, v in counts.items()]
                    items += [[labels[path], " ".join(line.split())] for line in lines]
            nx: tuple[int | None, int | None] = (None, None)
            try:
                errors, nx_warnings, text = nxcheck_counts(path)
            except (OSError, RuntimeError, subprocess.TimeoutExpired) as exc:
                print(f"nxcheck: failed: {_first_line(exc)}", file=sys.stderr)
                warnings.append(f"nxcheck failed on {labels[path]}: {_first_line(exc)}")
                failed = True
            else:
                nx = (errors, nx_warnings)
                print(f"nxcheck: {errors} errors, {nx_warnings} warnings")
                if args.verbose:
                    print(text)
            shown = [None if counts is None else counts.get(k, 0) for k in PUNX_SHOWN]
            summary.append([labels[path], *shown, *nx])
    tables = [result_files.Table(
        "NeXus validation of each run file: punx's items per severity and nxcheck's errors "
        "and warnings.",
        ["file", *(f"punx {k} (items)" for k in PUNX_SHOWN), "nxcheck errors",
         "nxcheck warnings"], summary)]
    if severities:
        tables.append(result_files.Table(
            "punx's count of items per severity, every severity it reported.",
            ["file", "punx severity", "items"], severities))
    if items:
        tables.append(result_files.Table(
            "punx's ERROR, WARN and NOTE items.", ["file", "punx item"], items))
    result_files.write(
        "nexus_validation", "NeXus validation of a recorded run", tables,
        results=args.results, quick=args.quick,
        parameters={"files": [str(p) for p in args.file], "config": args.config.name,
                    "duration_s": args.duration,
                    "punx": punx_version(args.punx) if args.punx else "not run",
                    "punx_nexus_definitions": ", ".join(sorted(PUNX_DEFINITIONS)) or "n/a",
                    "nexusformat": _version("nexusformat")},
        notes=["nxcheck's warnings include windrig's own attributes and fields that the NeXus "
               "base classes allow but do not define (the script's docstring lists them)."],
        warnings=warnings)
    if args.results is not None:
        print(f"results: {args.results / 'nexus_validation.json'} and .md")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
