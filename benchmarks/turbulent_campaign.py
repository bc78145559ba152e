"""E2RFC in turbulence end to end: campaigns recorded on the simulated rig (not a test).

``benchmarks/ident_accuracy.py --part tunnel`` measures E2RFC's turbulence branch on releases
simulated directly (:func:`simulators.simulate_release`). This script asks the same of what an
operator would record: the flat-plate rig (``rig_configs/sim_flat_plate.toml``, U_F 11.85 m/s)
with ``[simulation.static]`` (a flat plate's coefficients) and ``[simulation.turbulence]``
(vertical gusts of intensity ``--iw``, von Karman, 0.3 m length scale, 1 m span), a fixed plan
of 3 speeds (0.4, 0.6, 0.8 U_F) x 2 releases, each held 11 s in the wind first (the turbulence
branch's noise model) and recorded for 20 s: every instrument simulated in a process of its own
on loopback, the real drivers, engine, recorder and files, E2RFC after each speed
(:func:`daq.campaign.runner.run_plan`). Per gust-field seed: the flutter speed, its std, the
error against the simulated tunnel's truth, the estimator that ran, the number of releases and
why the campaign stopped (a plan stops short of a speed above 0.9 (U_F - 3 std) of its estimate
so far: in turbulence a two-speed std is often wide enough for that).
About 4 minutes per seed (wind on 225 s).

``--adaptive``: an adaptive campaign instead (issue 38), identified by closed-loop maximum
likelihood (``turbulent_estimator = "ml"``, holds of 5 s as extra data): two releases at 0.4 and
0.6 U_F, then :mod:`daq.campaign.adaptive` chooses each next speed (4-10.5 m/s, within the
safety bound) and how many releases to take there (1-4, by the predicted gain per wind-on
second), until the std is within ``--target`` of U_F (2 %) or 8 speeds.

Run: ``.venv/bin/python benchmarks/turbulent_campaign.py [--seeds 1 2 3] [--iw 0.01]
[--adaptive [--target 0.02]] [--log FILE]``
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

from daq.campaign.plan import parse_plan
from daq.campaign.runner import run_plan
from daq.config import parse_rig_config
from daq.errors import ConfigError

REPO = Path(__file__).resolve().parents[1]
RIG = REPO / "rig_configs" / "sim_flat_plate.toml"
U_F = 11.849  # m/s, the rig's flutter speed (its comment; checked against the outcome's truth)
PLAN = """[campaign]
mode = "fixed"
releases_per_speed = 2
hold_s = 11.0
decay_s = 20.0
settle_s = 1.0
calz_end = false

[speeds]
wind_speeds = [{speeds}]
"""

ADAPTIVE_PLAN = """[campaign]
mode = "adaptive"
releases_per_speed = 2
hold_s = 5.0
decay_s = 20.0
settle_s = 1.0
calz_end = false
turbulent_estimator = "ml"

[speeds]
wind_speeds = [{speeds}]

[adaptive]
target_std = {target}
candidate_min = 4.0
candidate_max = 10.5
candidate_step = 0.5
max_speeds = 8
max_releases_per_speed = 4
"""


def rig_text(seed: int, iw: float) -> str:
    """Return the flat-plate rig's TOML in vertical turbulence of intensity ``iw``."""
    return RIG.read_text() + f"""
[simulation.static]
C_D = 0.02
C_L = 0.0
C_M = 0.0
dC_D = 0.0
dC_L = -6.283
dC_M = 1.571

[simulation.turbulence]
Iu = 0.0
Iw = {iw}
Lux = 1.0
Lwx = 0.3
span = 1.0
seed = {seed}
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--iw", type=float, default=0.01, help="vertical intensity (fraction)")
    parser.add_argument("--log", type=Path, help="write every campaign's progress lines here")
    parser.add_argument("--adaptive", action="store_true",
                        help="an adaptive campaign identified by closed-loop ML (docstring)")
    parser.add_argument("--target", type=float, default=0.02,
                        help="--adaptive: the target std as a fraction of U_F")
    args = parser.parse_args()
    if args.log is not None and not args.log.parent.is_dir():
        parser.error(f"--log {args.log}: folder {args.log.parent} does not exist")
    log: list[str] = []
    try:  # every seed's rig first: a wrong value is one error line, before any wind blows
        configs = {seed: parse_rig_config(rig_text(seed, args.iw), f"flat plate, Iw {args.iw:g}")
                   for seed in args.seeds}
    except ConfigError as exc:
        parser.error(str(exc))
    if args.adaptive:
        speeds = ", ".join(f"{f * U_F:.2f}" for f in (0.4, 0.6))
        plan = parse_plan(ADAPTIVE_PLAN.format(speeds=speeds, target=args.target),
                          "adaptive turbulent plan")
    else:
        speeds = ", ".join(f"{f * U_F:.2f}" for f in (0.4, 0.6, 0.8))
        plan = parse_plan(PLAN.format(speeds=speeds), "turbulent plan")
    rows = []
    for seed in args.seeds:
        config = configs[seed]
        with tempfile.TemporaryDirectory() as out:
            log.append(f"--- seed {seed}")
            outcome = run_plan(plan, config, out, simulate=True, say=log.append)
        truth = outcome.truth_flutter_speed or math.nan
        analysis = outcome.analysis
        speed, std = outcome.flutter_speed, outcome.flutter_std
        estimator = "-" if analysis is None else analysis.model.diagnostics.estimator
        n = 0 if analysis is None else analysis.n_releases
        err = math.nan if speed is None else 100 * (speed / truth - 1)
        cover = "-" if speed is None or std is None else (
            "yes" if abs(speed - truth) <= 2 * std else "no")
        steps = " ".join(f"{step.U:.2f}x{step.releases}" for step in outcome.steps)
        log.append(f"seed {seed}: speeds x releases {steps}; wind on {outcome.wind_on_s:.0f} s")
        print(log[-1], flush=True)
        rows.append(f"{seed:>4} {n:>3} {truth:8.3f} "
                    + ("    none" if speed is None else f"{speed:8.3f}")
                    + ("      -" if std is None else f" {std:6.3f}")
                    + f" {err:+8.2f}% {cover:>5}  {estimator}; {outcome.stopped_because}")
        print(rows[-1], flush=True)
    what = (f"adaptive to a {100 * args.target:g} % std, closed-loop ML (5 s holds, 20 s decays)"
            if args.adaptive else "3 speeds x 2 releases (11 s hold, 20 s decay)")
    print(f"\nflat plate, Iw {100 * args.iw:g} %, {what}, recorded on the simulated rig")
    print("seed rel  truth   U_F      std    error  2-std  estimator")
    print("\n".join(rows))
    if args.log is not None:
        args.log.write_text("\n".join(log) + "\n")


if __name__ == "__main__":
    main()
