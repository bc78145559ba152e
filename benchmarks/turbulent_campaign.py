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
second; ``--max-releases``, 4), until the std is within ``--target`` of U_F (2 %) or
``--max-speeds`` (8); ``--closed-loop-buffeting fourth-order`` (or ``second-order``) fits that
buffeting model alone rather than the one chosen by evidence, E2RFC's default (written to
``turbulent_campaign_adaptive_fourth_order``, ``..._second_order``).

Run: ``.venv/bin/python benchmarks/turbulent_campaign.py [--seeds 1 2 3] [--iw 0.01]
[--adaptive [--target 0.02] [--max-speeds 8] [--max-releases 4] [--closed-loop-buffeting
fourth-order]] [--log FILE] [--speeds 0.4,0.6,0.8] [--releases 2] [--hold 11] [--decay 20]``
(the fixed plan's speeds as fractions of U_F, its releases per speed, each release's hold and
decay in s; the adaptive plan's first two speeds, its largest number of speeds and of releases
at one speed). ``--quick`` (CI): one seed, a campaign of two speeds (0.4 and 0.6 U_F; E2RFC
says nothing before two) with one release each, a hold of 1 s and a decay of 5 s (the adaptive
one: holds of 1 s, decays of 5 s, at most three speeds), which the turbulence branch identifies
without holds: the same rig, drivers, recorder and files, about a minute of wall time where a
full seed takes four. ``--results DIR`` also writes the table to ``DIR/turbulent_campaign.json``
and ``.md`` (``turbulent_campaign_adaptive`` with ``--adaptive``; :mod:`result_files`).
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

from daq.campaign.plan import parse_plan
from daq.campaign.runner import run_plan
from daq.config import parse_rig_config
from daq.errors import ConfigError
from ident.identification.e2rfc import CLOSED_LOOP_BUFFETING, CLOSED_LOOP_BUFFETING_CHOICES

sys.path.insert(0, str(Path(__file__).resolve().parent))
import result_files  # noqa: E402 - beside this script

REPO = Path(__file__).resolve().parents[1]
RIG = REPO / "rig_configs" / "sim_flat_plate.toml"
U_F = 11.849  # m/s, the rig's flutter speed (its comment; checked against the outcome's truth)
PLAN = """[campaign]
mode = "fixed"
releases_per_speed = {releases}
hold_s = {hold}
decay_s = {decay}
settle_s = 1.0
calz_end = false

[speeds]
wind_speeds = [{speeds}]
"""

ADAPTIVE_PLAN = """[campaign]
mode = "adaptive"
releases_per_speed = {releases}
hold_s = {hold}
decay_s = {decay}
settle_s = 1.0
calz_end = false
turbulent_estimator = "ml"
closed_loop_buffeting = "{buffeting}"

[speeds]
wind_speeds = [{speeds}]

[adaptive]
target_std = {target}
candidate_min = 4.0
candidate_max = 10.5
candidate_step = 0.5
max_speeds = {max_speeds}
max_releases_per_speed = {max_releases}
"""
#: Options whose default differs in a quick run: (fixed plan, adaptive plan, --quick).
DEFAULTS = {"speeds": ("0.4,0.6,0.8", "0.4,0.6", "0.4,0.6"), "releases": (2, 2, 1),
            "hold": (11.0, 5.0, 1.0), "decay": (20.0, 20.0, 5.0), "max_speeds": (8, 8, 3),
            "max_releases": (4, 4, 4)}


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
    parser.add_argument("--seeds", type=int, nargs="+", default=None,
                        help="gust-field seeds (1 2 3; --quick: 1)")
    parser.add_argument("--iw", type=float, default=0.01, help="vertical intensity (fraction)")
    parser.add_argument("--log", type=Path, help="write every campaign's progress lines here")
    parser.add_argument("--adaptive", action="store_true",
                        help="an adaptive campaign identified by closed-loop ML (docstring)")
    parser.add_argument("--target", type=float, default=0.02,
                        help="--adaptive: the target std as a fraction of U_F")
    parser.add_argument("--speeds", default=None,
                        help="the plan's wind speeds as fractions of U_F (0.4,0.6,0.8; "
                             "adaptive: the first two, 0.4,0.6)")
    parser.add_argument("--releases", type=int, default=None,
                        help="releases per speed (2; --quick: 1)")
    parser.add_argument("--hold", type=float, default=None,
                        help="s held in the wind before each release (11, adaptive 5; "
                             "--quick: 1)")
    parser.add_argument("--decay", type=float, default=None,
                        help="s of decay recorded per release (20; --quick: 5)")
    parser.add_argument("--max-speeds", type=int, default=None,
                        help="--adaptive: most speeds in all (8; --quick: 3)")
    parser.add_argument("--max-releases", type=int, default=None,
                        help="--adaptive: most releases at one chosen speed (4)")
    parser.add_argument("--closed-loop-buffeting",
                        choices=CLOSED_LOOP_BUFFETING_CHOICES,
                        default=CLOSED_LOOP_BUFFETING,
                        help="--adaptive: the closed-loop estimator's buffeting model")
    result_files.add_arguments(parser)
    args = parser.parse_args()
    column = 2 if args.quick else 1 if args.adaptive else 0
    for name, values in DEFAULTS.items():
        if getattr(args, name) is None:
            setattr(args, name, values[column])
    if args.seeds is None:
        args.seeds = [1] if args.quick else [1, 2, 3]
    # Fractions of the flutter speed: a campaign stops short of flutter.
    fractions = result_files.number_list(parser, "--speeds", args.speeds, 0.0, 1.0,
                                         "fractions of U_F")
    if args.log is not None and not args.log.parent.is_dir():
        parser.error(f"--log {args.log}: folder {args.log.parent} does not exist")
    log: list[str] = []
    try:  # every seed's rig first: a wrong value is one error line, before any wind blows
        configs = {seed: parse_rig_config(rig_text(seed, args.iw), f"flat plate, Iw {args.iw:g}")
                   for seed in args.seeds}
        speeds = ", ".join(f"{f * U_F:.2f}" for f in fractions)
        values = {"speeds": speeds, "releases": args.releases, "hold": args.hold,
                  "decay": args.decay}
        if args.adaptive:
            plan = parse_plan(ADAPTIVE_PLAN.format(
                target=args.target, max_speeds=args.max_speeds, max_releases=args.max_releases,
                buffeting=args.closed_loop_buffeting, **values),
                              "adaptive turbulent plan")
        else:
            plan = parse_plan(PLAN.format(**values), "turbulent plan")
    except ConfigError as exc:
        parser.error(str(exc))
    rows = []
    table = []
    started = time.monotonic()
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
        table.append((seed, n, truth, speed, std, err, cover, estimator, steps,
                      outcome.wind_on_s, outcome.stopped_because))
    what = (f"adaptive to a {100 * args.target:g} % std, closed-loop ML "
            f"({args.closed_loop_buffeting} buffeting model; {args.hold:g} s holds, "
            f"{args.decay:g} s decays)" if args.adaptive else
            f"{len(fractions)} speeds x {args.releases} release{'s' * (args.releases != 1)} "
            f"({args.hold:g} s hold, {args.decay:g} s decay)")
    print(f"\nflat plate, Iw {100 * args.iw:g} %, {what}, recorded on the simulated rig")
    print("seed rel  truth   U_F      std    error  2-std  estimator")
    print("\n".join(rows))
    if args.log is not None:
        args.log.write_text("\n".join(log) + "\n")
    _write(args, what, table, fractions, time.monotonic() - started)


def _write(args: argparse.Namespace, what: str, table: list[tuple[object, ...]],
           fractions: list[float], wall: float) -> None:
    """Write the result file (``--results``) of the campaigns in ``table``."""
    columns = ("seed", "releases", "truth (m/s)", "U_F (m/s)", "std (m/s)", "error (%)",
               "2-std covers", "estimator", "speeds (m/s) x releases", "wind on (s)",
               "stopped because")
    warnings = [f"seed {row[0]}: no flutter speed identified ({row[-1]})." for row in table
                if row[3] is None]
    if args.hold < 10.0 and not args.adaptive:
        warnings.append(f"The holds ({args.hold:g} s) are too short for the refined-IV "
                        "branch's noise model; the closed-loop branch (the plan's default "
                        "estimator) takes holds as optional data.")
    name = "turbulent_campaign_adaptive" if args.adaptive else "turbulent_campaign"
    if args.adaptive and args.closed_loop_buffeting != CLOSED_LOOP_BUFFETING:
        name += "_" + args.closed_loop_buffeting.replace("-", "_")
    result_files.write(
        name,
        "E2RFC in turbulence end to end on the simulated rig",
        [result_files.Table(
            f"Flat plate, Iw {100 * args.iw:g} %, {what}, recorded on the simulated rig: per "
            "gust-field seed the identified flutter speed and its std against the simulated "
            "tunnel's truth, whether the 2-std interval covers it, the estimator, the speeds "
            "tested and why the campaign stopped.",
            columns, table, formats={"truth (m/s)": ".3f", "U_F (m/s)": ".3f",
                                     "std (m/s)": ".3f", "error (%)": "+.2f",
                                     "wind on (s)": ".0f"})],
        results=args.results, quick=args.quick, script="turbulent_campaign",
        parameters={"seeds": args.seeds, "iw": args.iw, "adaptive": args.adaptive,
                    "target std": args.target if args.adaptive else None,
                    "speeds (fractions of U_F)": fractions, "releases per speed": args.releases,
                    "hold (s)": args.hold, "decay (s)": args.decay,
                    "max speeds": args.max_speeds if args.adaptive else None,
                    "max releases per speed": args.max_releases if args.adaptive else None,
                    "closed-loop buffeting": (args.closed_loop_buffeting if args.adaptive
                                              else None)},
        notes=[f"The campaigns took {wall:.0f} s of wall time in all: the rig runs in real "
               "time, every instrument simulated in a process of its own.",
               "The same seed gives a different campaign each time: the gust field is fixed by "
               "the seed, but which stretch of it each decay meets depends on the release "
               "instants."],
        warnings=warnings)


if __name__ == "__main__":
    main()
