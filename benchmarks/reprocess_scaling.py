"""``windrig reprocess`` on 40 simulated run files: 1 against 2 local Dask workers.

The files: four campaigns (the flat-plate rig with structural damping 0.4, 0.5, 0.6 and 0.7 %,
so that each is its own section model), ten files each, one wind speed per file (0.4 to 0.85 of
the flutter speed), two 7.5 s releases per file at 500 Hz with 2 % noise, written by the
acquisition's recorder. Each worker count starts from an empty output directory (no cache), then
the 2-worker run is repeated on its own output (everything from the cache). Printed: wall time
per phase (cluster start, per-file tasks, per-campaign tasks, outputs), the speed-up, and the
flutter speeds found (equal between the runs).

Run: ``.venv/bin/python benchmarks/reprocess_scaling.py`` (about 3 minutes on two cores).
"""

from __future__ import annotations

import os
import shutil
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

CONFIG = Path(__file__).resolve().parents[1] / "rig_configs" / "sim_flat_plate.toml"
DAMPING = (0.004, 0.005, 0.006, 0.007)
FILES_PER_CAMPAIGN = 10


def write_files(root: Path) -> list[Path]:
    """Write the 40 run files; return their paths."""
    root.mkdir(parents=True, exist_ok=True)
    text = CONFIG.read_text()
    truth = flat_plate.jones_model()
    paths = []
    for c, zeta in enumerate(DAMPING):
        section = SECTION.replace(zeta_h=zeta, zeta_a=zeta)
        # Each campaign's stored config carries its own damping (the grouping key).
        config_text = text.replace("zeta_h = 0.005", f"zeta_h = {zeta}").replace(
            "zeta_a = 0.005", f"zeta_a = {zeta}")
        config = parse_rig_config(config_text, "benchmark")
        U_F = flutter.analyze(section, truth).speed
        assert U_F is not None
        rng = np.random.default_rng(c)
        for i, fraction in enumerate(np.linspace(0.4, 0.85, FILES_PER_CAMPAIGN)):
            releases = [Release.from_simulation(simulate_release(
                section, truth, fraction * U_F, h0, a0, duration=7.5, fs=500.0, noise=0.02,
                rng=rng)) for h0, a0 in HOLDS]
            path = root / f"c{c}_run{i:02d}.h5"
            write_release_run(path, config, releases)
            paths.append(path)
    return paths


def main() -> None:
    """Write the files, run 1 and 2 workers, print the table."""
    root = Path(tempfile.mkdtemp(prefix="windrig_reprocess_bench_"))
    try:
        t0 = time.monotonic()
        paths = write_files(root / "runs")
        size = sum(p.stat().st_size for p in paths) / 2**20
        print(f"wrote {len(paths)} run files ({size:.0f} MiB) in {time.monotonic() - t0:.0f} s; "
              f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
        runs = {}
        for label, workers, out in (("1 worker", 1, "out1"), ("2 workers", 2, "out2"),
                                    ("2 workers, cached", 2, "out2")):
            summary = reprocess([str(root / "runs")], root / out, workers=workers,
                                progress=False)
            runs[label] = summary
            print(f"  {label}: {summary.timings['total']:.1f} s", flush=True)
        phases = ("cluster start", "files", "campaigns", "outputs", "total")
        print()
        print(f"{'run':<20}" + "".join(f"{p:>15}" for p in phases) + f"{'files redone':>14}")
        for label, summary in runs.items():
            redone = len(summary.files) - len(summary.reused)
            print(f"{label:<20}" + "".join(f"{summary.timings[p]:>14.1f}s" for p in phases)
                  + f"{redone:>14}")
        one, two = runs["1 worker"].timings, runs["2 workers"].timings
        print()
        print(f"speed-up, 2 workers over 1: total {one['total'] / two['total']:.2f}x, per-file "
              f"tasks {one['files'] / two['files']:.2f}x, campaign tasks "
              f"{one['campaigns'] / two['campaigns']:.2f}x")
        speeds = {label: [c.get("flutter_speed") for c in s.campaigns]
                  for label, s in runs.items()}
        print("flutter speeds per campaign (m/s): "
              + "; ".join(f"{k}: {', '.join(f'{v:.3f}' for v in vals)}"
                          for k, vals in speeds.items()))
        same = all(np.allclose(vals, speeds["1 worker"]) for vals in speeds.values())
        print(f"same numbers with 1 and 2 workers and from the cache: {same}")
        print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    finally:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
