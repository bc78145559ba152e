"""The section's uncertainty at the bridge: delta method against 1000 Monte Carlo samples.

The example bridge (``rig_configs/bridges/example_bridge.json``, six modes) with the flat plate
identified by E2RFC from six seeded simulated releases (0.4, 0.6 and 0.8 of its flutter speed,
two holds each, 6 s at 500 Hz, 20 % measurement noise, two lags with ``A3``: the same
identification as the tests' ``support.identified``), written as ``windrig identify --json``
writes it. Printed: the delta-method std, the Monte Carlo std of 1000 samples (the std of that
std is ``1 / sqrt(2 * 999)``, 2.2 %), their ratio, and the time of the 1000 samples serially
(the fast route in this process), on a local Dask cluster of one worker and of two
(``windrig bridge --uncertainty --workers N``, end to end; the cluster's start-up apart; in
the order 1, 2, 2, 1 so that a drift of a shared host's load cancels in the means), with the
speed-up of two workers over one.

Run: ``.venv/bin/python benchmarks/bridge_uncertainty.py [--samples N]`` (about 8 minutes on
two idle cores). ``--quick`` (CI): 20 samples (unless ``--samples``) and one cluster run, of one
worker (no speed-up then). ``--results DIR`` also writes the tables to
``DIR/bridge_uncertainty.json`` and ``.md`` (:mod:`result_files`).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

from daq.cli import main
from ident import Release
from ident.bridge import uncertainty as bu
from ident.bridge.flutter import default_U_max
from ident.bridge.model import BridgeModel
from ident.identification import e2rfc
from ident.identification.covariance import ModelCovariance
from ident.model import flat_plate
from ident.model import flutter as fl
from ident.model.section import SectionModel
from simulators import simulate_release

sys.path.insert(0, str(Path(__file__).resolve().parent))
import result_files  # noqa: E402 - beside this script

BRIDGE = Path(__file__).resolve().parents[1] / "rig_configs" / "bridges" / "example_bridge.json"
SECTION = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)
HOLDS = ((0.004, 0.02), (-0.003, 0.012))


def identify_json() -> dict:
    """Return the seeded identification as ``windrig identify --json`` holds it (its parts)."""
    truth = flat_plate.jones_model()
    U_F = fl.analyze(SECTION, truth).speed
    releases = [Release.from_simulation(simulate_release(
        SECTION, truth, f * U_F, h0, a0, duration=6.0, fs=500.0, noise=0.2, rng=(40, i, j)))
        for i, f in enumerate((0.4, 0.6, 0.8)) for j, (h0, a0) in enumerate(HOLDS)]
    model = e2rfc.identify(releases, SECTION, n_lags=2, with_A3=True)
    u = model.uncertainty(SECTION)
    return {"model": model.to_dict(), "model_covariance": ModelCovariance.of(model).to_dict(),
            "flutter_speed": u.speed, "flutter_speed_std_parts": u.parts(),
            "warnings": list(u.warnings)}


def main_benchmark(samples: int, order: tuple[int, ...] = (1, 2, 2, 1)
                   ) -> tuple[list[result_files.Table], list[str]]:
    """Run the comparison and print its table; return the tables and notes for the result file.

    ``order``: the workers of each cluster run, in turn.
    """
    data = identify_json()
    bridge = BridgeModel.from_json(BRIDGE)
    from ident.model.rfc import RationalFunctionModel

    model = RationalFunctionModel.from_dict(data["model"])
    cov = ModelCovariance.from_dict(data["model_covariance"])
    t0 = time.perf_counter()
    delta = bu.delta_method(bridge, model, cov)
    t_delta = time.perf_counter() - t0
    assert delta is not None
    models = bu.sample_models(bridge, model, cov, samples, seed=0)
    t0 = time.perf_counter()
    outcomes = bu.flutter_speeds(bridge, models, bu.search_top(default_U_max(bridge), delta))
    t_serial = time.perf_counter() - t0
    result = bu.summarise("model covariance", delta.speed, delta, outcomes, 0.0, 0)
    mc = result.mc_std
    assert mc is not None
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        aero = Path(tmp) / "identified.json"
        aero.write_text(json.dumps(data))
        # 1, 2, 2, 1 workers: a drift of the shared host's load over the runs cancels in the
        # mean of each.
        for run, workers in enumerate(order):
            out = Path(tmp) / f"run{run}_w{workers}.json"
            code = main(["bridge", str(BRIDGE), "--aero", str(aero), "--uncertainty",
                         "--samples", str(samples), "--workers", str(workers), "--json",
                         str(out)])
            assert code == 0
            u = json.loads(out.read_text())["uncertainty"]
            wall = u["wall_time_s"]
            rows.append((workers, wall["monte_carlo"], wall["cluster_start"],
                         wall["monte_carlo"] - wall["cluster_start"], u["monte_carlo"]["std"]))
    print()
    print(f"example bridge, identified flat plate; {samples} samples; host load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"section: U_F = {data['flutter_speed']:.4f} m/s, noise std "
          f"{data['flutter_speed_std_parts']['noise']:.4g} m/s")
    print(f"bridge:  U_F = {delta.speed:.4f} m/s (delta method in {t_delta:.3g} s)")
    print()
    print("| delta std (m/s) | MC std (m/s) | delta / MC | MC std's own std |")
    print("|---|---|---|---|")
    print(f"| {delta.std:.4f} | {mc:.4f} | {delta.std / mc:.3f} | "
          f"{100 / math.sqrt(2 * (samples - 1)):.1f} % |")
    print()
    print("| run | wall (s) | cluster start (s) | samples (s) | MC std (m/s) |")
    print("|---|---|---|---|---|")
    print(f"| serial (this process) | {t_serial:.1f} | - | {t_serial:.1f} | {mc:.4f} |")
    for workers, total, start, work, std in rows:
        print(f"| local cluster, {workers} worker{'s' if workers > 1 else ''} | {total:.1f} | "
              f"{start:.1f} | {work:.1f} | {std:.4f} |")
    one = [r for r in rows if r[0] == 1]
    two = [r for r in rows if r[0] == 2]
    order_text = ", ".join(str(w) for w in order)
    speed_up = []
    if one and two:
        work = [sum(r[3] for r in runs) / len(runs) for runs in (one, two)]
        total = [sum(r[1] for r in runs) / len(runs) for runs in (one, two)]
        speed_up = [(work[0] / work[1], total[0] / total[1])]
        print()
        print(f"2 workers against 1 (means of {len(one)} run{'s' * (len(one) != 1)} each, in "
              f"the order {order_text}): {work[0] / work[1]:.2f}x on the samples, "
              f"{total[0] / total[1]:.2f}x with the cluster's start")
    tables = [
        result_files.Table(
            f"The example bridge's flutter speed with the identified flat plate: the delta "
            f"method's std against the Monte Carlo std of {samples} samples, their ratio, and "
            "the Monte Carlo std's own relative std.",
            ("samples", "delta std (m/s)", "MC std (m/s)", "delta / MC",
             "MC std's own std (%)"),
            [(samples, delta.std, mc, delta.std / mc, 100 / math.sqrt(2 * (samples - 1)))],
            formats={"delta std (m/s)": ".4f", "MC std (m/s)": ".4f", "delta / MC": ".3f",
                     "MC std's own std (%)": ".1f"}),
        result_files.Table(
            "The section's flutter speed and the std of its noise part (the identification), "
            "the bridge's flutter speed and the delta method's time.",
            ("section U_F (m/s)", "section noise std (m/s)", "bridge U_F (m/s)",
             "delta method time (s)"),
            [(data["flutter_speed"], data["flutter_speed_std_parts"]["noise"], delta.speed,
              t_delta)],
            formats={"section U_F (m/s)": ".4f", "bridge U_F (m/s)": ".4f",
                     "delta method time (s)": ".3g"}),
        result_files.Table(
            f"The {samples} samples' time serially (in this process) and on a local Dask "
            f"cluster (windrig bridge --uncertainty, end to end; workers per run, in turn: "
            f"{order_text}): wall time, the cluster's start, the samples' time after it, and "
            "the Monte Carlo std each found.",
            ("run", "wall (s)", "cluster start (s)", "samples (s)", "MC std (m/s)"),
            [("serial (this process)", t_serial, None, t_serial, mc)]
            + [(f"local cluster, {w} worker{'s' if w > 1 else ''}", wall, start, work_s, std)
               for w, wall, start, work_s, std in rows],
            formats={"wall (s)": ".1f", "cluster start (s)": ".1f", "samples (s)": ".1f",
                     "MC std (m/s)": ".4f"}),
    ]
    if speed_up:
        tables.append(result_files.Table(
            f"Two workers against one (means of the runs of each; workers per run, in turn: "
            f"{order_text}).",
            ("on the samples (x)", "with the cluster's start (x)"), speed_up,
            formats={"on the samples (x)": ".2f", "with the cluster's start (x)": ".2f"}))
    notes = [f"Host load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores at the "
             "end (the cluster's speed-up falls on a loaded host)."]
    return tables, notes


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=None, help="1000 (--quick: 20)")
    result_files.add_arguments(parser)
    args = parser.parse_args()
    samples = args.samples if args.samples is not None else (20 if args.quick else 1000)
    if samples < 2:
        parser.error("--samples must be at least 2")
    order = (1,) if args.quick else (1, 2, 2, 1)
    found, notes = main_benchmark(samples, order)
    result_files.write(
        "bridge_uncertainty", "The section's uncertainty at the bridge: delta method and Monte "
        "Carlo", found, results=args.results, quick=args.quick,
        parameters={"samples": samples, "cluster runs (workers, in order)": list(order),
                    "bridge": BRIDGE.name, "releases": "0.4/0.6/0.8 U_F x 2 holds, 6 s at "
                    "500 Hz, 20 % noise, 2 lags with A3"},
        notes=notes)
