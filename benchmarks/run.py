"""Run every benchmark and collect its result files: ``make bench`` (quick) and full runs.

``python benchmarks/run.py --mode quick|full [--out DIR] [--only NAME ...]`` runs each script of
:data:`BENCHMARKS` as ``python benchmarks/<name>.py --results DIR`` with ``--quick``, or in full
with its defaults and the parts of :data:`FULL_EXTRA`, in turn, one at a
time (several benchmarks measure time, and two at once would slow each other; a quick run,
whose figures do not count, may run ``--jobs 2`` at once, as ``make bench`` does), and writes
``DIR/index.json``: each benchmark's mode, exit status, wall time and, for a failure, its last
lines of output. The quick mode (CI) shows that every benchmark runs and writes its files, in
a few minutes on two cores; its figures are not the documented ones. The full mode is the
benchmarks' own defaults, which produce the figures of the validation pages
(``docs/validation/results``, the default ``--out`` of a full run); some take hours.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import result_files  # noqa: E402 - beside this script

#: Every benchmark, by the stem of its script, in the order they run.
BENCHMARKS = (
    "decode_ild1420", "decode_ptb330", "decode_scanivalve", "modbus_latency", "daq_throughput",
    "console_frame_rate", "nexus_validation", "ident_speed_compare", "ident_accuracy",
    "ident_accuracy_3dof", "flutter_crb", "flutter_crb_exact", "closed_loop_bias",
    "turbulent_gls_experiment", "campaign_efficiency",
    "turbulent_campaign", "discrepancy_detectability", "discrepancy_confusion",
    "reprocess_scaling", "bridge_speed", "bridge_uncertainty",
)
#: The full mode's runs besides each script's defaults: the parts and variants the validation
#: pages show, each writing a result file of its own name.
FULL_EXTRA = {
    "ident_accuracy": (
        ("--part", "tunnel", "--rows", "turbulent", "--tunnel-mode", "both",
         "--turbulent-estimator", "ml", "--seeds", "20"),
        ("--part", "tunnel", "--rows", "turbulent", "--tunnel-mode", "both",
         "--turbulent-estimator", "ml", "--seeds", "40"),
        # The fourth-order model alone is the default's on these rows (the evidence takes it
        # on every seed): only the second-order one has a table of its own.
        ("--part", "tunnel", "--rows", "turbulent", "--tunnel-mode", "both",
         "--turbulent-estimator", "ml", "--closed-loop-buffeting", "second-order",
         "--seeds", "20"),
        ("--part", "tunnel", "--rows", "variants", "--tunnel-mode", "both",
         "--turbulent-estimator", "ml", "--seeds", "20"),
        ("--part", "tunnel", "--rows", "variants", "--turbulent-estimator", "ml",
         "--closed-loop-buffeting", "fourth-order", "--seeds", "20"),
        ("--part", "tunnel", "--rows", "variants", "--tunnel-mode", "both",
         "--turbulent-estimator", "ml", "--closed-loop-buffeting", "second-order",
         "--seeds", "20"),
        ("--part", "ablation", "--seeds", "20"),
    ),
    "ident_accuracy_3dof": (("--part", "turbulent", "--seeds", "20"),),
    "flutter_crb": (("--deck", "bluff"),),
    "ident_speed_compare": (("--flow", "turbulent"),),
}
#: Longest a quick run of one benchmark may take, s (a hung benchmark fails, not CI's clock).
QUICK_TIMEOUT = 300.0


def jobs(name: str, mode: str) -> list[tuple[str, ...]]:
    """Return the argument lists ``name`` runs with in ``mode`` (one per result file)."""
    if mode == "quick":
        return [("--quick",)]
    return [(), *FULL_EXTRA.get(name, ())]


def _run(name: str, arguments: tuple[str, ...], mode: str, out: Path) -> dict[str, object]:
    """Run one benchmark job into a folder of its own, then move its result files to ``out``.

    The folder of its own tells which files this job wrote when several run at once.
    """
    label = " ".join((name, *arguments))
    scratch = Path(tempfile.mkdtemp(prefix=f".{name}-", dir=out))
    command = [sys.executable, str(HERE / f"{name}.py"), "--results", str(scratch), *arguments]
    start = time.perf_counter()
    entry: dict[str, object] = {"benchmark": name, "arguments": list(arguments), "mode": mode}
    try:
        done = subprocess.run(command, capture_output=True, text=True, check=False,
                              timeout=QUICK_TIMEOUT if mode == "quick" else None)
    except subprocess.TimeoutExpired as exc:
        tail = exc.stdout[-2000:] if isinstance(exc.stdout, str) else ""
        entry.update(status="timed out", seconds=round(time.perf_counter() - start, 1),
                     output=tail, label=label)
        shutil.rmtree(scratch)
        return entry
    written = sorted(p.stem for p in scratch.glob("*.json"))
    for path in scratch.iterdir():
        path.replace(out / path.name)
    shutil.rmtree(scratch)
    entry.update(seconds=round(time.perf_counter() - start, 1), results=written, label=label,
                 status=("ok" if done.returncode == 0 and written
                         else "no result file" if done.returncode == 0
                         else f"exit {done.returncode}"))
    if entry["status"] != "ok":
        entry["output"] = (done.stdout + done.stderr)[-2000:]
    return entry


def main(argv: list[str] | None = None) -> int:
    """Run the benchmarks; return 0 when every one ran and wrote its files."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mode", choices=result_files.MODES, default="quick")
    parser.add_argument("--out", type=Path, default=None,
                        help="result folder (default: benchmarks/results/quick for a quick "
                             "run, docs/validation/results for a full one)")
    parser.add_argument("--only", nargs="+", choices=BENCHMARKS, default=None, metavar="NAME")
    parser.add_argument("--jobs", type=int, default=1,
                        help="benchmarks run at once (quick mode only: a full run's timings "
                             "need the host to themselves)")
    args = parser.parse_args(argv)
    if args.jobs < 1 or (args.jobs > 1 and args.mode == "full"):
        parser.error("--jobs: at least 1, and 1 in full mode (benchmarks time themselves)")
    out = args.out or (HERE / "results" / "quick" if args.mode == "quick"
                       else result_files.DOCS_RESULTS)
    out.mkdir(parents=True, exist_ok=True)
    index_path = out / "index.json"
    index = json.loads(index_path.read_text()) if index_path.exists() else {}
    todo = [(name, arguments) for name in args.only or BENCHMARKS
            for arguments in jobs(name, args.mode)]
    failed = []
    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        running = [pool.submit(_run, name, arguments, args.mode, out)
                   for name, arguments in todo]
        for future in as_completed(running):
            entry = future.result()
            label = str(entry.pop("label"))
            index[label] = entry
            index_path.write_text(json.dumps(index, indent=1, sort_keys=True) + "\n")
            print(f"{label} ({args.mode}): {entry['status']} in {entry['seconds']} s: "
                  f"{', '.join(entry.get('results', [])) or 'nothing written'}", flush=True)
            if entry["status"] != "ok":
                failed.append(label)
                print(str(entry.get("output", "")), file=sys.stderr)
    if failed:
        print(f"error: {len(failed)} benchmark(s) did not run through: {', '.join(failed)}",
              file=sys.stderr)
        return 1
    print(f"all {len(todo)} benchmark runs done; results in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
