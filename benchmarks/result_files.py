"""Result files of the benchmarks: one JSON and one Markdown table per benchmark and mode.

Every benchmark script takes ``--quick`` (a small run, for CI: it shows the script works, not
the figures) and ``--results DIR`` (write ``DIR/<name>.json`` and ``DIR/<name>.md`` besides
printing its tables). ``benchmarks/run.py`` runs them all (``make bench``). The documentation's
validation pages include the Markdown files of ``docs/validation/results/``; the Markdown is
rendered from the JSON by :func:`render_markdown` alone, so that every figure on those pages
comes from a result file (``tests/test_validation_pages.py`` renders each one again and compares).

The JSON holds the benchmark's name and title, the mode, the parameters it ran with, the
commit, the date, the host (CPUs, machine, Python), its tables (caption, columns, rows of
numbers or text, optional per-column formats), notes and warnings.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
import os
import platform
import subprocess
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
#: Where the documentation's validation pages find the result files (of a full run).
DOCS_RESULTS = ROOT / "docs" / "validation" / "results"
MODES = ("quick", "full")


@dataclass
class Table:
    """One table of a benchmark's results.

    Parameters
    ----------
    caption : str
        What the table shows, one sentence (units in the column names).
    columns : sequence of str
        Column names, with units (``"time (s)"``, ``"error (%)"``).
    rows : sequence of sequence
        One row per case: numbers (int, float; NaN or None for a gap) or text.
    formats : mapping of str to str, optional
        A format spec per column (``".2f"``, ``".3g"``); floats default to ``".4g"``.
    """

    caption: str
    columns: Sequence[str]
    rows: Sequence[Sequence[Any]]
    formats: Mapping[str, str] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """Return the JSON form (NaN as None), checking the rows' widths."""
        for row in self.rows:
            if len(row) != len(self.columns):
                raise ValueError(f"table {self.caption!r}: a row of {len(row)} cells for "
                                 f"{len(self.columns)} columns")
        unknown = set(self.formats) - set(self.columns)
        if unknown:
            raise ValueError(f"table {self.caption!r}: formats for unknown columns {unknown}")
        return {"caption": self.caption, "columns": list(self.columns),
                "rows": [[_plain(v) for v in row] for row in self.rows],
                "formats": dict(self.formats)}


def _plain(value: Any) -> Any:
    """Return a JSON value: numpy scalars as Python ones, NaN as None."""
    if hasattr(value, "item"):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, (bool, int, float, str)) or value is None:
        return value
    return str(value)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--quick`` and ``--results DIR`` to a benchmark's parser."""
    parser.add_argument("--quick", action="store_true",
                        help="a small run that shows the benchmark works (CI), not its figures")
    parser.add_argument("--results", type=Path, default=None, metavar="DIR",
                        help="also write DIR/<name>.json and DIR/<name>.md")


def add_workers(parser: argparse.ArgumentParser, default: int = 2) -> None:
    """Add ``--workers N``, the worker processes of a benchmark's pool (an integer >= 1)."""
    parser.add_argument("--workers", type=_at_least_one, default=default,
                        help=f"worker processes ({default})")


def _at_least_one(text: str) -> int:
    """``argparse`` type: an integer >= 1, else argparse's one ``error:`` line."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"an integer is needed, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"at least 1 is needed, got {value}")
    return value


def number_list(parser: argparse.ArgumentParser, option: str, text: str, low: float,
                high: float, hint: str = "") -> list[float]:
    """Return ``text``'s comma-separated numbers, each in ``(low, high)``, or exit with one line.

    A word that is not a number, or a number outside the range (a percentage typed for a
    fraction, a speed at or beyond flutter), is ``parser.error``'s one line naming ``option``
    (and ``hint``, what the numbers are, after the range).
    """
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        parser.error(f"{option} takes numbers separated by commas, got {text!r}")
    if not all(low < v < high for v in values):
        parser.error(f"{option} takes numbers between {low:g} and {high:g} (exclusive"
                     f"{'; ' + hint if hint else ''}), got {text!r}")
    return values


def resolve_defaults(args: argparse.Namespace,
                     defaults: Mapping[str, tuple[Any, Any]]) -> None:
    """Give each option left unset (None) its full or, with ``--quick``, its quick default.

    ``defaults`` maps an option's attribute name to ``(full, quick)``; an option given on the
    command line wins over both. A list default is copied, so that runs do not share it.
    """
    for name, (full, quick) in defaults.items():
        if getattr(args, name) is None:
            value = quick if args.quick else full
            setattr(args, name, list(value) if isinstance(value, list) else value)


def _commit() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=ROOT, check=True,
                             capture_output=True, text=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                               cwd=ROOT, check=True, capture_output=True, text=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return out + ("+changes" if dirty.strip() else "")


def write(name: str, title: str, tables: Sequence[Table], *, results: Path | None,
          quick: bool, parameters: Mapping[str, Any] | None = None,
          notes: Sequence[str] = (), warnings: Sequence[str] = (),
          script: str | None = None) -> dict[str, Any]:
    """Return the result record, and write it (JSON and Markdown) when ``results`` is given.

    Parameters
    ----------
    name : str
        The result's name: its script's stem, with a suffix for a run of one part or variant.
    title : str
        A title for the validation page's section.
    tables : sequence of Table
        The results.
    results : Path or None
        Folder to write ``<name>.json`` and ``<name>.md`` into (made if missing).
    quick : bool
        The run was ``--quick``.
    parameters : mapping, optional
        What the run was asked (seeds, sizes, rows), JSON-serialisable.
    notes, warnings : sequence of str
        What a reader needs besides the tables; what may make a figure wrong.
    script : str, optional
        The script's stem, when ``name`` is not it.
    """
    record = {
        "benchmark": name, "script": script or name, "title": title,
        "mode": "quick" if quick else "full",
        "parameters": {k: _plain(v) if not isinstance(v, (list, tuple)) else [_plain(x) for x in v]
                       for k, v in (parameters or {}).items()},
        "commit": _commit(),
        "date": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d"),
        "host": {"cpus": os.cpu_count(), "machine": platform.machine(),
                 "python": platform.python_version()},
        "tables": [t.as_dict() for t in tables],
        "notes": list(notes), "warnings": list(warnings),
    }
    if results is not None:
        results.mkdir(parents=True, exist_ok=True)
        (results / f"{name}.json").write_text(json.dumps(record, indent=1) + "\n",
                                              encoding="utf-8")
        (results / f"{name}.md").write_text(render_markdown(record), encoding="utf-8")
    return record


def format_cell(value: Any, spec: str | None) -> str:
    """Return one cell's text: ``spec`` for numbers (``.4g`` for floats), "n/a" for a gap."""
    if value is None:
        return "n/a"
    if isinstance(value, bool) or isinstance(value, str):
        return str(value)
    if isinstance(value, int) and spec is None:
        return str(value)
    return format(value, spec or ".4g")


def render_markdown(record: Mapping[str, Any]) -> str:
    """Return the Markdown of a result record: its tables, notes, warnings and provenance."""
    lines = [f"<!-- written by benchmarks/{record.get('script', record['benchmark'])}.py from "
             f"{record['benchmark']}.json; do not edit -->", ""]
    if record["mode"] == "quick":
        lines += ["**A quick run: these figures show that the benchmark runs, not what windrig "
                  "achieves; a full run (`make bench BENCH_MODE=full`) replaces them.**", ""]
    for table in record["tables"]:
        columns, formats = table["columns"], table.get("formats", {})
        lines += [f"**{table['caption']}**", "",
                  "| " + " | ".join(c.replace("|", "\\|") for c in columns) + " |",
                  "|" + "---|" * len(columns)]
        for row in table["rows"]:
            cells = [format_cell(v, formats.get(c)).replace("|", "\\|")
                     for c, v in zip(columns, row, strict=True)]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    lines += [f"- {note}" for note in record.get("notes", [])]
    lines += [f"- **warning**: {w}" for w in record.get("warnings", [])]
    if record.get("notes") or record.get("warnings"):
        lines.append("")
    host = record["host"]
    lines.append(f"*{record['mode']} run of commit {record['commit']} on {record['date']}, "
                 f"{host['cpus']} CPUs ({host['machine']}), Python {host['python']}.*")
    return "\n".join(lines) + "\n"
