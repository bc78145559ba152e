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
import re
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def record(out: Path, config: Path, duration_s: float) -> Path:
    """Record a run with ``windrig acquire --simulate``; return its path."""
    subprocess.run([sys.executable, "-m", "daq.cli", "acquire", "--config", str(config),
                    "--simulate", "--duration", f"{duration_s:g}", "--out", str(out)],
                   cwd=REPO, check=True, capture_output=True)
    return out


def punx_counts(punx: str, path: Path) -> tuple[dict[str, int], list[str]]:
    """Return punx's count per severity and its ERROR, WARN and NOTE lines."""
    done = subprocess.run([punx, "validate", str(path)], capture_output=True, text=True,
                          timeout=900, check=False)
    counts = {k: int(v) for k, v in re.findall(r"^([A-Z]+)\s+(\d+)\s+\S", done.stdout, re.M)}
    lines = [line.rstrip() for line in done.stdout.splitlines()
             if re.search(r"\s(ERROR|WARN|NOTE)\s", line)]
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


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--file", type=Path, action="append", default=[],
                        help="validate this run file (repeatable; default: record one)")
    parser.add_argument("--config", type=Path,
                        default=REPO / "rig_configs" / "sim_flat_plate.toml")
    parser.add_argument("--duration", type=float, default=4.0, help="s, of the recorded run")
    parser.add_argument("--punx", default=None, help="the punx executable (see the docstring)")
    parser.add_argument("--verbose", action="store_true", help="print nxcheck's whole report")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        files = args.file or [record(Path(tmp) / "run.h5", args.config, args.duration)]
        for path in files:
            print(f"== {path.name}")
            if args.punx:
                counts, lines = punx_counts(args.punx, path)
                print("punx:    " + ", ".join(f"{k} {v}" for k, v in counts.items()))
                for line in lines:
                    print("  " + " ".join(line.split()))
            errors, warnings, text = nxcheck_counts(path)
            print(f"nxcheck: {errors} errors, {warnings} warnings")
            if args.verbose:
                print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
