"""``windrig reprocess`` on 40 simulated run files: 1 against 2 local Dask workers.

The files: four campaigns (the flat-plate rig with structural damping 0.4, 0.5, 0.6 and 0.7 %,
so that each is its own section model), ten files each, one wind speed per file (0.4 to 0.85 of
the flutter speed), two 7.5 s releases per file at 500 Hz with 2 % noise, written by the
acquisition's recorder. Each worker count starts from an empty output directory (no cache), then
the 2-worker run is repeated on its own output (everything from the cache). Printed: wall time
per phase (cluster start, per-file tasks, per-campaign tasks, outputs), the speed-up, and the
flutter speeds found (equal between the runs).

Run: ``.venv/bin/python benchmarks/reprocess_scaling.py`` (about 3 minutes on two cores).
``--quick`` (CI): one campaign of three files with 3 s releases; ``--results DIR`` writes the
tables (``benchmarks/result_files.py``).
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from daq.config import parse_rig_config
from daq.offline.reprocess import reprocess
from daq.recording.synthetic import write_release_run
from ident.model import flat_plate, flutter
from ident.records.release import Release
from simulators.campaigns import HOLDS, SECTION
from simulators.tunnel import simulate_release

sys.path.insert(0, str(Path(__file__).resolve().parent))
import result_files  # noqa: E402 - beside this script

CONFIG = Path(__file__).resolve().parents[1] / "rig_configs" / "sim_flat_plate.toml"
DAMPING = (0.004, 0.005, 0.006, 0.007)
FILES_PER_CAMPAIGN = 10
#: Length of each release, s.
DECAY_S = 7.5
#: Defaults: (full run, --quick) per option.
DEFAULTS = {"campaigns": (len(DAMPING), 1), "files": (FILES_PER_CAMPAIGN, 3),
            "decay": (DECAY_S, 3.0)}


def write_files(root: Path, campaigns: int = len(DAMPING),
                files_per_campaign: int = FILES_PER_CAMPAIGN,
                decay_s: float = DECAY_S) -> list[Path]:
    """Write the run files (40 by default); return their paths."""
    root.mkdir(parents=True, exist_ok=True)
    text = CONFIG.read_text()
    truth = flat_plate.jones_model()
    paths = []
    for c, zeta in enumerate(DAMPING[:campaigns]):
        section = SECTION.replace(zeta_h=zeta, zeta_a=zeta)
        # Each campaign's stored config carries its own damping (the grouping key).
        config_text = text.replace("zeta_h = 0.005", f"zeta_h = {zeta}").replace(
            "zeta_a = 0.005", f"zeta_a = {zeta}")
        config = parse_rig_config(config_text, "benchmark")
        U_F = flutter.analyze(section, truth).speed
        assert U_F is not None
        rng = np.random.default_rng(c)
        for i, fraction in enumerate(np.linspace(0.4, 0.85, files_per_campaign)):
            releases = [Release.from_simulation(simulate_release(
                section, truth, fraction * U_F, h0, a0, duration=decay_s, fs=500.0, noise=0.02,
                rng=rng)) for h0, a0 in HOLDS]
            path = root / f"c{c}_run{i:02d}.h5"
            write_release_run(path, config, releases)
            paths.append(path)
    return paths


def _speed(campaign: dict) -> float:
    """Return a campaign's flutter speed, NaN when it has none."""
    value = campaign.get("flutter_speed")
    return math.nan if value is None else float(value)


def main(argv: list[str] | None = None) -> None:
    """Write the files, run 1 and 2 workers, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--campaigns", type=int, default=None,
                        help=f"campaigns, 1-{len(DAMPING)} (default {len(DAMPING)}; --quick: "
                        f"{DEFAULTS['campaigns'][1]})")
    parser.add_argument("--files", type=int, default=None,
                        help=f"run files per campaign (default {FILES_PER_CAMPAIGN}; --quick: "
                        f"{DEFAULTS['files'][1]})")
    parser.add_argument("--decay", type=float, default=None,
                        help=f"length of each release, s (default {DECAY_S:g}; --quick: "
                        f"{DEFAULTS['decay'][1]:g})")
    result_files.add_arguments(parser)
    args = parser.parse_args(argv)
    result_files.resolve_defaults(args, DEFAULTS)
    if not 1 <= args.campaigns <= len(DAMPING) or args.files < 3 or not args.decay > 0:
        parser.error(f"--campaigns must be 1-{len(DAMPING)}, --files >= 3, --decay > 0")
    root = Path(tempfile.mkdtemp(prefix="windrig_reprocess_bench_"))
    try:
        t0 = time.monotonic()
        paths = write_files(root / "runs", args.campaigns, args.files, args.decay)
        size = sum(p.stat().st_size for p in paths) / 2**20
        load_before = os.getloadavg()
        print(f"wrote {len(paths)} run files ({size:.0f} MiB) in {time.monotonic() - t0:.0f} s; "
              f"load average {' '.join(f'{x:.2f}' for x in load_before)}", flush=True)
        runs = {}
        workers_of = {}
        for label, workers, out in (("1 worker", 1, "out1"), ("2 workers", 2, "out2"),
                                    ("2 workers, cached", 2, "out2")):
            summary = reprocess([str(root / "runs")], root / out, workers=workers,
                                progress=False)
            runs[label] = summary
            workers_of[label] = workers
            print(f"  {label}: {summary.timings['total']:.1f} s", flush=True)
        phases = ("cluster start", "files", "campaigns", "outputs", "total")
        print()
        print(f"{'run':<20}" + "".join(f"{p:>15}" for p in phases) + f"{'files redone':>14}")
        phase_rows = []
        for label, summary in runs.items():
            redone = len(summary.files) - len(summary.reused)
            print(f"{label:<20}" + "".join(f"{summary.timings[p]:>14.1f}s" for p in phases)
                  + f"{redone:>14}")
            phase_rows.append([label, workers_of[label],
                               *(summary.timings[p] for p in phases), redone])
        one, two = runs["1 worker"].timings, runs["2 workers"].timings
        print()
        print(f"speed-up, 2 workers over 1: total {one['total'] / two['total']:.2f}x, per-file "
              f"tasks {one['files'] / two['files']:.2f}x, campaign tasks "
              f"{one['campaigns'] / two['campaigns']:.2f}x")
        speeds = {label: [_speed(c) for c in s.campaigns] for label, s in runs.items()}
        print("flutter speeds per campaign (m/s): "
              + "; ".join(f"{k}: {', '.join(f'{v:.3f}' for v in vals)}"
                          for k, vals in speeds.items()))
        same = all(np.allclose(vals, speeds["1 worker"]) for vals in speeds.values())
        print(f"same numbers with 1 and 2 workers and from the cache: {same}")
        load_after = os.getloadavg()
        print(f"load average after: {' '.join(f'{x:.2f}' for x in load_after)}")
    finally:
        shutil.rmtree(root, ignore_errors=True)

    seconds = [f"{p} (s)" for p in ("cluster start", "per-file tasks", "per-campaign tasks",
                                    "outputs", "total")]
    speed_cols = [f"flutter speed, {label} (m/s)" for label in runs]
    speed_rows = []
    for i, campaign in enumerate(runs["1 worker"].campaigns):
        damping = [DAMPING[int(Path(f).name[1])] for f in campaign.get("files", [])]
        zeta = 100 * damping[0] if damping and len(set(damping)) == 1 else math.nan
        speed_rows.append([campaign.get("name", f"campaign {i + 1}"), zeta,
                           len(campaign.get("files", [])),
                           *(vals[i] if i < len(vals) else math.nan
                             for vals in speeds.values())])
    failed = sum(len(s.failed) for s in runs.values())
    tables = [
        result_files.Table(
            f"Wall time per phase of windrig reprocess on {len(paths)} run files, from an empty "
            "output directory and then from the cache.",
            ["run", "workers", *seconds, "files redone"], phase_rows,
            formats=dict.fromkeys(seconds, ".1f")),
        result_files.Table(
            "Speed-up of 2 local Dask workers over 1 (both without the cache).",
            ["phase", "1 worker (s)", "2 workers (s)", "speed-up (x)"],
            [[name, one[key], two[key], one[key] / two[key]]
             for name, key in (("total", "total"), ("per-file tasks", "files"),
                               ("per-campaign tasks", "campaigns"))],
            formats={"1 worker (s)": ".1f", "2 workers (s)": ".1f", "speed-up (x)": ".2f"}),
        result_files.Table(
            "Flutter speed found per campaign by each run (the same numbers expected).",
            ["campaign", "structural damping (%)", "files", *speed_cols], speed_rows,
            formats={"structural damping (%)": ".1f", **dict.fromkeys(speed_cols, ".3f")}),
    ]
    warnings = []
    if not same:
        warnings.append("the flutter speeds differ between the runs (or a campaign found "
                        "none): see the last table.")
    if failed:
        warnings.append(f"{failed} run file(s) failed to reprocess over the three runs.")
    result_files.write(
        "reprocess_scaling", "windrig reprocess on 1 and 2 Dask workers", tables,
        results=args.results, quick=args.quick,
        parameters={"campaigns": args.campaigns, "files_per_campaign": args.files,
                    "files": len(paths), "release_s": args.decay, "releases_per_file": 2,
                    "fs_hz": 500.0, "noise": 0.02, "size_mib": size},
        notes=[f"Same flutter speeds with 1 and 2 workers and from the cache: {same}.",
               "Load average (1, 5, 15 min) before the runs "
               f"{' '.join(f'{x:.2f}' for x in load_before)}, after "
               f"{' '.join(f'{x:.2f}' for x in load_after)}: other work on the cores lowers "
               "the speed-up."],
        warnings=warnings)
    if args.results is not None:
        print(f"results: {args.results / 'reprocess_scaling.json'} and .md")


if __name__ == "__main__":
    main()
