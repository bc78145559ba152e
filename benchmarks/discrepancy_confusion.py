"""Confusion table of the discrepancy workflow: true hidden effect against the effect named.

Each row is ``--seeds`` seeded campaigns with one effect hidden, or none: the flat-plate rig at
0.5, 0.65 and 0.8 U_F, two 7.5 s releases each, 2 % noise. By default (issue 39) the data are
recorded from the virtual tunnel (:func:`simulators.tunnel_campaigns.tunnel_campaign`: the
tunnel's air, spline-sampled motion, forces integrated from 34 noisy taps) and each effect's
strength is drawn log-uniformly over its realistic range
(:data:`simulators.tunnel_campaigns.STRENGTH_RANGE`, from where the baseline visibly misses it
to three times the realistic strength; ``benchmarks/discrepancy_detectability.py``) with its
shape (phases, the floor's frequency, the Strouhal number, the tube's damping) drawn too. The
draw of row ``k``, campaign ``s`` comes from ``numpy.random.default_rng([seed0, k, s])``
(``--draw-seed``, default 39), the noise from the campaign's seed. ``--strengths realistic
--source library`` gives the earlier tables (one strength per effect,
:data:`simulators.campaigns.REALISTIC` x ``--factor``, :func:`simulators.campaigns.
simulated_campaign`).

Each is diagnosed by :func:`ident.discrepancy.workflow.diagnose` (E2RFC baseline). Printed: the
confusion table, the median gap before and after, the median and worst parameter error of the
correctly named cases, the strength factors of the misses, the time per campaign, and how many
named effects broke the gap rule (:mod:`ident.discrepancy.gap_rule`: their step shrank the gap
by less than the margin; target: none). Targets: >= 95 % named correctly, nothing named on clean
data.

Then pairs of effects that occur together, ``--pair-seeds`` campaigns each: a pair is *fully
right* when exactly its two effects are named and every strength parameter is within 20 %;
target >= 90 %. And campaigns with physics outside the library (:data:`OUTSIDE`: a laser's
drifting zero, free play in the pitch spring, a heave stop, a mass that grows between
releases; ``tests/support/outside_library.py``), the table "out of library": per case the
effects named, the gap before and after, how often explained (target: never) and the steps
tried and undone by the gap rule.

Run: ``.venv/bin/python benchmarks/discrepancy_confusion.py [--seeds 10] [--pair-seeds 5]
[--outside-seeds 5] [--strengths random|realistic] [--source tunnel|library] [--factor 1.0]
[--skip-singles] [--only outside]`` (about an hour on two idle cores with the defaults;
``--pair-seeds 0 --outside-seeds 0`` for the single-effect table only).

``--quick`` (CI): one campaign each of the rows "none" and "sensor_crosstalk" (unless ``--rows``)
and of the first case outside the library, no pairs (a pair's diagnosis alone takes as long as
the rest; ``--pair-seeds N`` runs N campaigns of one pair, a delay and crosstalk,
:data:`QUICK_PAIR`, as ``--only pairs`` does). Counts given explicitly win. ``--results DIR``
also writes the tables to ``DIR/<name>.json`` and ``.md`` (:mod:`result_files`):
``discrepancy_confusion`` for the default setup, else with the options that differ appended
(:func:`result_name`).
"""

from __future__ import annotations

import argparse
import cmath
import dataclasses
import math
import os
import sys
import time
from collections import Counter
from collections.abc import Callable

import numpy as np

from ident.discrepancy.residual_check import systematic_levels
from ident.discrepancy.workflow import DiscrepancyReport, diagnose
from ident.physics.effects import EFFECT_NAMES, Effect, TubingDistortion
from ident.records.release import Release
from simulators.campaigns import _STRENGTHS, SECTION, scaled, simulated_campaign
from simulators.tunnel_campaigns import STRENGTH_RANGE, random_effect, tunnel_campaign

# The out-of-library physics lives with the tests that check it (tests/support); appended, so
# that the packages themselves are not shadowed by the tests' folders of the same names.
sys.path.append(os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                             "tests"))
from support.outside_library import (  # noqa: E402
    FreePlay,
    HeaveStop,
    growing_mass_campaign,
)

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import result_files  # noqa: E402 - beside this script

DEPTH = 0.03  # m, the flat plate's depth (the vortex effect's)

#: Pairs that occur together on one rig (tests/ident/discrepancy/test_discrepancy.py has eight
#: of them); the last four with the effects added by issue 20 (an aerodynamic nonlinearity, tubing).
PAIRS = [
    ("coulomb_friction", "channel_delay"),
    ("quadratic_damping", "sensor_crosstalk"),
    ("cubic_stiffness", "static_unbalance"),
    ("coulomb_friction", "cubic_stiffness"),
    ("channel_delay", "sensor_crosstalk"),
    ("quadratic_damping", "vortex_shedding"),
    ("static_unbalance", "channel_delay"),
    ("base_vibration", "coulomb_friction"),
    ("base_vibration", "channel_delay"),
    ("aerodynamic_nonlinearity", "coulomb_friction"),
    ("aerodynamic_nonlinearity", "static_unbalance"),
    ("tubing_distortion", "cubic_stiffness"),
    ("tubing_distortion", "quadratic_damping"),
]

def _drift(r: Release) -> Release:
    return dataclasses.replace(r, h=r.h + 5e-5 * r.t, meta=dict(r.meta))


#: Physics outside the library, each a campaign from a seed (5 s decays, three speeds): a laser
#: whose zero drifts by 0.05 mm/s (tests/ident/discrepancy/test_discrepancy.py has the same),
#: and the three of tests/ident/discrepancy/test_outside_library.py.
#: The first three come from the chosen source (the tunnel or the library's simulation); the
#: growing mass from the library's simulation only (the tunnel's model does not change mass).
OUTSIDE: dict[str, Callable[[int, Callable[..., list[Release]]], list[Release]]] = {
    "laser_drift_0.05mm/s": lambda seed, source: [_drift(r) for r in source(
        None, seed, duration=5.0)],
    "free_play_0.5mrad": lambda seed, source: source(FreePlay(), seed, duration=5.0),
    "heave_stop_2.5mm": lambda seed, source: source(HeaveStop(), seed, duration=5.0),
    "mass_growing_3%": lambda seed, source: growing_mass_campaign(seed, duration=5.0),
}

SOURCES: dict[str, Callable[..., list[Release]]] = {"tunnel": tunnel_campaign,
                                                     "library": simulated_campaign}

#: What ``--quick`` runs: these single-effect rows, this pair (by its index in :data:`PAIRS`:
#: its seeds are the full run's), the first case outside the library.
QUICK_ROWS = ["none", "sensor_crosstalk"]
QUICK_PAIR = 4
#: A summary row: what was counted, the count, out of how many, the rate (%), the target.
Summary = tuple[str, int, int, float, str]


@dataclasses.dataclass(frozen=True)
class Setup:
    """How the campaigns are made: the data's source and how strengths are drawn."""

    source: str = "tunnel"
    random: bool = True
    factor: float = 1.0
    draw_seed: int = 39

    def effects(self, names: tuple[str, ...], k: int, s: int) -> tuple[list[Effect], list[float]]:
        """Return the hidden effects of row ``k``, campaign ``s``, and their strength factors."""
        if not self.random:
            return [scaled(name, self.factor) for name in names], [self.factor] * len(names)
        rng = np.random.default_rng([self.draw_seed, k, s])
        drawn = [random_effect(name, rng) for name in names]
        return [effect for effect, _ in drawn], [factor for _, factor in drawn]

    def campaign(self, effects: list[Effect], seed: int, **kwargs: float) -> list[Release]:
        """Record or simulate the campaign of ``effects``."""
        return SOURCES[self.source](effects or None, seed, **kwargs)

    def describe(self) -> str:
        """Say in one phrase how strengths and data were made."""
        strengths = ("strengths log-uniform over STRENGTH_RANGE, shapes drawn, draw seed "
                     f"{self.draw_seed}" if self.random
                     else f"strength x{self.factor:g} of REALISTIC")
        source = "virtual tunnel" if self.source == "tunnel" else "library simulation"
        return f"{strengths}; data from the {source}, 2 % noise"


def rule_broken(report: DiscrepancyReport) -> int:
    """Count the named effects whose step did not pass the gap rule (should be none)."""
    return sum(step.trial is None or not step.trial.accepted for step in report.effects)


def result_name(args: argparse.Namespace) -> str:
    """Return the result file's name: ``discrepancy_confusion`` and the options that differ.

    In the order: the part (``--only``, ``--skip-singles``), the strengths (and factor), the
    source, the draw seed, the rows asked and the pairs' first seed.
    """
    parts = []
    if args.only:
        parts.append(args.only)
    elif args.skip_singles:
        parts.append("no_singles")
    if args.strengths != "random":
        parts.append(args.strengths + (f"_x{args.factor:g}" if args.factor != 1.0 else ""))
    if args.source != "tunnel":
        parts.append(args.source)
    if args.draw_seed != 39:
        parts.append(f"draw{args.draw_seed}")
    if args.rows:
        parts.append("rows_" + "_".join(args.rows))
    if args.pair_first_seed:
        parts.append(f"pairs_from{args.pair_first_seed}")
    return "_".join(["discrepancy_confusion", *parts]).replace(".", "_")


def main() -> None:
    """Run the campaigns and print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=None,
                        help="campaigns per effect (10; --quick: 1)")
    parser.add_argument("--strengths", choices=("random", "realistic"), default="random",
                        help="draw strengths over each effect's range (default) or take the "
                             "realistic one times --factor")
    parser.add_argument("--source", choices=tuple(SOURCES), default="tunnel",
                        help="record from the virtual tunnel (default) or take the library's "
                             "simulation")
    parser.add_argument("--factor", type=float, default=1.0,
                        help="with --strengths realistic: strength as a multiple of the "
                             "realistic one (default 1)")
    parser.add_argument("--draw-seed", type=int, default=39, help="seed of the strength draws")
    parser.add_argument("--pair-seeds", type=int, default=None,
                        help="campaigns per pair (5; --quick: none, or 1 of one pair with "
                             "--only pairs)")
    parser.add_argument("--outside-seeds", type=int, default=None,
                        help="campaigns per effect outside the library (5; --quick: 1)")
    parser.add_argument("--pair-first-seed", type=int, default=0,
                        help="seed number of the first campaign of each pair (to extend a run)")
    parser.add_argument("--rows", nargs="*", choices=["none", *EFFECT_NAMES],
                        help="only these rows of the single-effect table (to split a run)")
    parser.add_argument("--skip-singles", action="store_true",
                        help="only the pairs and the effects outside the library")
    parser.add_argument("--only", choices=("outside", "pairs"),
                        help="run one part only: the out-of-library table or the pairs")
    result_files.add_arguments(parser)
    args = parser.parse_args()
    name = result_name(args)
    quick = args.quick
    if args.seeds is None:
        args.seeds = 1 if quick else 10
    if args.pair_seeds is None:
        args.pair_seeds = (1 if args.only == "pairs" else 0) if quick else 5
    if args.outside_seeds is None:
        args.outside_seeds = 1 if quick else 5
    if args.seeds < 0 or args.pair_seeds < 0 or args.outside_seeds < 0:
        parser.error("--seeds, --pair-seeds and --outside-seeds must be >= 0")
    if not args.factor > 0:
        parser.error("--factor must be > 0")
    setup = Setup(source=args.source, random=args.strengths == "random", factor=args.factor,
                  draw_seed=args.draw_seed)
    rows = args.rows if args.rows or not quick else QUICK_ROWS
    pairs = [QUICK_PAIR] if quick else None
    outside = list(OUTSIDE)[:1] if quick else None
    tables: list[result_files.Table] = []
    summary: list[Summary] = []
    notes = [f"Load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}."]
    parameters = {"strengths": args.strengths, "source": args.source, "draw seed": args.draw_seed,
                  "factor": args.factor if args.strengths == "realistic" else None}

    def collect(part: tuple[list[result_files.Table], list[Summary], list[str]]) -> None:
        tables.extend(part[0])
        summary.extend(part[1])
        notes.extend(part[2])

    if args.only == "outside":
        if args.outside_seeds == 0:
            parser.error("--only outside needs --outside-seeds >= 1")
        collect(_outside(args.outside_seeds, setup, outside))
        parameters.update({"outside seeds": args.outside_seeds, "outside cases": outside
                           or list(OUTSIDE)})
    elif args.only == "pairs":
        collect(_pairs(args.pair_seeds, args.pair_first_seed, setup, pairs))
        parameters.update({"pair seeds": args.pair_seeds, "pair first seed": args.pair_first_seed,
                           "pairs": _pair_names(pairs)})
    else:
        if not args.skip_singles:
            collect(_singles(args.seeds, setup, rows))
            parameters.update({"seeds": args.seeds, "rows": rows or ["none", *EFFECT_NAMES]})
        if args.pair_seeds:
            collect(_pairs(args.pair_seeds, args.pair_first_seed, setup, pairs))
            parameters.update({"pair seeds": args.pair_seeds,
                               "pair first seed": args.pair_first_seed,
                               "pairs": _pair_names(pairs)})
        if args.outside_seeds:
            collect(_outside(args.outside_seeds, setup, outside))
            parameters.update({"outside seeds": args.outside_seeds,
                               "outside cases": outside or list(OUTSIDE)})
    if quick and not args.pair_seeds and not args.only:
        notes.append("This quick run leaves the pairs out (--pair-seeds runs one).")
    if summary:
        tables.insert(0, result_files.Table(
            "Against the targets: what was counted, out of how many campaigns, as a rate.",
            ("measure", "count", "campaigns", "rate (%)", "target"), summary,
            formats={"rate (%)": ".1f"}))
    notes.append(f"Load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}.")
    result_files.write(name, "Discrepancy workflow: the effect named against the effect hidden",
                       tables, results=args.results, quick=quick, parameters=parameters,
                       script="discrepancy_confusion",
                       notes=notes)


def _pair_names(which: list[int] | None) -> list[str]:
    """Return the pairs run (``which``: their indices in :data:`PAIRS`; None: all)."""
    return ["+".join(PAIRS[k]) for k in (range(len(PAIRS)) if which is None else which)]


def _singles(seeds: int, setup: Setup, only: list[str] | None = None
             ) -> tuple[list[result_files.Table], list[Summary], list[str]]:
    """One effect (or none) per campaign: the confusion table (``only``: these rows).

    Return its tables, its summary rows and notes for the result file.
    """
    columns = ["none", *EFFECT_NAMES]
    rows = [row for row in columns if not only or row in only]
    counts: dict[str, Counter[str]] = {row: Counter() for row in rows}
    gaps: dict[str, list[tuple[float, float]]] = {row: [] for row in rows}
    errors: dict[str, list[float]] = {row: [] for row in rows}
    misses: dict[str, list[str]] = {row: [] for row in rows}
    explained: Counter[str] = Counter()
    as_delay: Counter[str] = Counter()
    left: dict[str, list[float]] = {row: [] for row in rows}
    broken = 0
    started = time.monotonic()
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    for row in rows:
        k = columns.index(row)  # the seeds of a row do not depend on which rows run
        for seed in range(seeds):
            names = () if row == "none" else (row,)
            effects, factors = setup.effects(names, k, seed)
            releases = setup.campaign(effects, 1000 * (k + 1) + seed)
            report = diagnose(releases, SECTION, depth=DEPTH)
            broken += rule_broken(report)
            explained[row] += report.explained
            left[row].append(_left_over(releases, report))
            named = report.effect or "none"
            if len(report.effects) > 1:
                named = "+".join(step.name for step in report.effects)
            if row == "none" and not report.explained:
                named = "none, unexplained"
            counts[row][named] += 1
            gaps[row].append((report.gap_before, report.gap_after))
            if effects and named == row:
                errors[row].extend(abs(report.parameters[p] / getattr(effects[0], p) - 1.0)
                                   for p in _STRENGTHS[row])
            elif effects and _as_its_delay(effects[0], report):
                as_delay[row] += 1
            elif named != row:
                misses[row].append(f"x{factors[0]:.2f} -> {named}" if factors else named)
        print(f"  {row}: {dict(counts[row])}", flush=True)
    elapsed = time.monotonic() - started
    n_campaigns = len(rows) * seeds

    width = max(len(c) for c in columns) + 1
    print()
    print(f"Confusion table: {seeds} campaigns per row, {setup.describe()}; rows = hidden "
          "effect, columns = effect named")
    short = {c: c.split("_")[0][:8] for c in columns}
    print(f"{'hidden':<{width}}" + "".join(f"{short[c]:>9}" for c in columns)
          + f"{'correct':>9}{'gap before':>12}{'gap after':>11}{'param err med/max':>19}"
          + f"{'explained':>10}{'left/noise':>11}{'range':>10}")
    correct_total = strict_total = 0
    table = []
    for row in rows:
        strict_total += counts[row][row]
        correct = counts[row][row] + as_delay[row]
        correct_total += correct
        before = float(np.median([g[0] for g in gaps[row]]))
        after = float(np.median([g[1] for g in gaps[row]]))
        err = errors[row]
        err_text = "-" if not err else f"{np.median(err):.1%} / {max(err):.1%}"
        span = "-" if row == "none" or not setup.random else \
            f"x{STRENGTH_RANGE[row][0]:g}-{STRENGTH_RANGE[row][1]:g}"
        print(f"{row:<{width}}" + "".join(f"{counts[row][c]:>9}" for c in columns)
              + f"{correct / seeds:>9.0%}{before:>12.4f}{after:>11.4f}{err_text:>19}"
              + f"{explained[row]:>10}{max(left[row]):>11.2f}{span:>10}")
        table.append((row, *(counts[row][c] for c in columns), 100 * correct / seeds, before,
                      after, 100 * float(np.median(err)) if err else None,
                      100 * max(err) if err else None, explained[row], max(left[row]),
                      span.lstrip("x") if span != "-" else None))
    print("left/noise: the largest systematic residual left in a channel after the named "
          "effects, over the noise's RMS there (worst campaign of the row; 1 = at the noise)")
    print("correct: the hidden effect named alone, or a tube named channel_delay with its "
          "phase delay where its gain is within the noise of 1 at the modes (a delay for every "
          f"purpose of the model: {sum(as_delay.values())} such)")
    rate = correct_total / n_campaigns
    print()
    print(f"named correctly: {correct_total}/{n_campaigns} = {rate:.1%} (target >= 95 %): "
          f"{'met' if rate >= 0.95 else 'MISSED'}; the hidden effect's own name: "
          f"{strict_total}/{n_campaigns} = {strict_total / n_campaigns:.1%}")
    if "none" in rows:
        false_alarms = seeds - counts["none"]["none"]
        print(f"false alarms on clean data: {false_alarms} (target 0): "
              f"{'met' if false_alarms == 0 else 'MISSED'}")
    print(f"named effects that did not pass the gap rule: {broken} (target 0)")
    print("misses (strength factor -> named): " + ("; ".join(
        f"{row}: {', '.join(m)}" for row, m in misses.items() if m) or "none"))
    print(f"time: {elapsed:.0f} s, {elapsed / n_campaigns:.1f} s per campaign (data and "
          "diagnosis); load average after: "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    names = [f"named {c}" for c in columns]
    tables = [result_files.Table(
        f"Confusion table, {seeds} campaign{'s' * (seeds != 1)} per row, {setup.describe()}: "
        "per hidden effect the campaigns by the effect named, the share named correctly, the "
        "median gap before and after, the parameter error of the correctly named, how many "
        "were explained, the worst systematic residual left over the noise, and the strength "
        "range drawn.",
        ("hidden", *names, "correct (%)", "gap before", "gap after", "param error median (%)",
         "param error max (%)", "explained", "left/noise", "range (x REALISTIC)"), table,
        formats={"correct (%)": ".0f", "gap before": ".4f", "gap after": ".4f",
                 "param error median (%)": ".1f", "param error max (%)": ".1f",
                 "left/noise": ".2f"})]
    miss_rows = [(row, float(m.split(" -> ")[0][1:]) if m.startswith("x") else None,
                  m.split(" -> ")[-1]) for row, found in misses.items() for m in found]
    if miss_rows:
        tables.append(result_files.Table(
            "The single-effect campaigns not named correctly: the hidden effect, its strength "
            "factor, and what was named.",
            ("hidden", "strength factor (x REALISTIC)", "named"), miss_rows,
            formats={"strength factor (x REALISTIC)": ".2f"}))
    summary: list[Summary] = [
        ("single effects named correctly", correct_total, n_campaigns,
         100 * correct_total / n_campaigns, ">= 95 %"),
        ("single effects named by their own name", strict_total, n_campaigns,
         100 * strict_total / n_campaigns, "-"),
        ("single effects: named effects that did not pass the gap rule", broken, n_campaigns,
         math.nan, "0")]
    if "none" in rows:
        false_alarms = seeds - counts["none"]["none"]
        summary.insert(2, ("false alarms on clean data", false_alarms, seeds,
                           100 * false_alarms / seeds, "0"))
    notes = [f"Single effects: {elapsed:.0f} s, {elapsed / n_campaigns:.1f} s per campaign "
             f"(data and diagnosis); {sum(as_delay.values())} tube(s) named channel_delay with "
             "their phase delay counted as correct (a delay for every purpose of the model)."]
    return tables, summary, notes


def _as_its_delay(effect: Effect, report: DiscrepancyReport, others: tuple[str, ...] = (),
                  noise: float = 0.02) -> bool:
    """Say whether a tube was named ``channel_delay`` as the delay it is within the noise.

    A tube's gain at the modes differs from 1 by about ``(2 damping^2 - 1) (f / f_tube)^2``:
    where that stays below the noise at both still-air modal frequencies the data cannot tell
    it from a delay, and the delay named must then be the tube's phase delay at the pitch
    frequency within 20 %. ``others``: the other effects hidden with it, which must be named
    too (and nothing else).
    """
    named = sorted(s.name for s in report.effects)
    if not isinstance(effect, TubingDistortion) or named != sorted(["channel_delay", *others]):
        return False
    gain, pitch = effect.response([SECTION.fh, SECTION.fa])
    if max(abs(1.0 - abs(gain)), abs(1.0 - abs(pitch))) >= noise:
        return False
    delay = -cmath.phase(pitch) / (2 * math.pi * SECTION.fa)
    return abs(report.parameters["delay_s"] / delay - 1.0) <= 0.2


def _left_over(releases: list[Release], report: DiscrepancyReport) -> float:
    """Largest channel's systematic residual after the named effects, over its noise."""
    levels = systematic_levels(releases, report.simulated_after)
    return max(sys / noise for sys, noise in levels.values() if noise > 0)


def _pairs(seeds: int, first: int, setup: Setup, which: list[int] | None = None
           ) -> tuple[list[result_files.Table], list[Summary], list[str]]:
    """Pairs of effects: named exactly, each strength within 20 % (``which``: these pairs).

    Return the tables, the summary rows and notes for the result file.
    """
    started = time.monotonic()
    print()
    print(f"Pairs: {seeds} campaigns each, {setup.describe()}")
    print(f"{'pair':<40}{'fully right':>12}{'named both':>11}{'extra':>7}{'gap before':>12}"
          f"{'after 1':>9}{'after 2':>9}{'param err med/max':>19}{'explained':>10}")
    total = right_total = broken = as_delay = 0
    table, wrong = [], []
    for k, pair in enumerate(PAIRS):
        if which is not None and k not in which:
            continue
        right = both = extra = explained = 0
        gaps: list[list[float]] = []
        errors: list[float] = []
        for seed in range(first, first + seeds):
            truth, factors = setup.effects(pair, 100 + k, seed)
            report = diagnose(setup.campaign(truth, 50_000 + 100 * k + seed), SECTION,
                              depth=DEPTH)
            broken += rule_broken(report)
            names = [step.name for step in report.effects]
            named_both = sorted(names[:2]) == sorted(pair)
            both += named_both
            extra += len(names) > 2
            explained += report.explained
            err = [abs(report.parameters.get(p, np.nan) / getattr(e, p) - 1.0)
                   for e in truth for p in _STRENGTHS[e.name]]
            ok = sorted(names) == sorted(pair) and all(x <= 0.2 for x in err)
            if not ok and "tubing_distortion" in pair:
                # A tube that is a delay within the noise, named as that delay, is right (as
                # in the single-effect table), the other effect's strength within 20 % too.
                i = pair.index("tubing_distortion")
                other = truth[1 - i]
                ok = (_as_its_delay(truth[i], report, (other.name,))
                      and all(abs(report.parameters[p] / getattr(other, p) - 1.0) <= 0.2
                              for p in _STRENGTHS[other.name]))
                as_delay += ok
            right += ok
            if named_both:
                errors.extend(err)
            gaps.append([report.gap_before] + [s.gap_after for s in report.effects[:2]])
            if not ok:
                print(f"  {'+'.join(pair)} seed {seed} (x{factors[0]:.2f}, x{factors[1]:.2f}): "
                      f"named {names}, errors {[f'{x:.0%}' for x in err]}", flush=True)
                wrong.append(("+".join(pair), seed, factors[0], factors[1],
                              " + ".join(names) or "none",
                              ", ".join(f"{x:.0%}" for x in err)))
        total += seeds
        right_total += right
        med = [float(np.median([g[i] for g in gaps if len(g) > i])) if any(len(g) > i
               for g in gaps) else np.nan for i in range(3)]
        err_text = "-" if not errors else f"{np.median(errors):.1%} / {max(errors):.1%}"
        print(f"{'+'.join(pair):<40}{right:>12}{both:>11}{extra:>7}{med[0]:>12.4f}"
              f"{med[1]:>9.4f}{med[2]:>9.4f}{err_text:>19}{explained:>10}", flush=True)
        table.append(("+".join(pair), seeds, right, both, extra, *med,
                      100 * float(np.median(errors)) if errors else None,
                      100 * max(errors) if errors else None, explained))
    rate = right_total / max(total, 1)
    elapsed = time.monotonic() - started
    print(f"pairs fully right: {right_total}/{total} = {rate:.1%} (of them {as_delay} with a "
          "tube named as its delay; target >= 90 %): "
          f"{'met' if rate >= 0.9 else 'MISSED'}; named effects that did not pass the gap "
          f"rule: {broken} (target 0); {elapsed:.0f} s")
    tables = [result_files.Table(
        f"Pairs of effects, {seeds} campaign{'s' * (seeds != 1)} each, {setup.describe()}: "
        "fully right (exactly the two named, every strength within 20 %), both named, more "
        "than two named, the median gap before and after the first and second effect, the "
        "parameter error where both were named, and how many were explained.",
        ("pair", "campaigns", "fully right", "named both", "extra", "gap before",
         "gap after 1", "gap after 2", "param error median (%)", "param error max (%)",
         "explained"), table,
        formats={"gap before": ".4f", "gap after 1": ".4f", "gap after 2": ".4f",
                 "param error median (%)": ".1f", "param error max (%)": ".1f"})]
    if wrong:
        tables.append(result_files.Table(
            "The pair campaigns not fully right: the pair, the seed, both strength factors "
            "(x REALISTIC), what was named and each strength parameter's error.",
            ("pair", "seed", "factor 1", "factor 2", "named", "parameter errors"), wrong,
            formats={"factor 1": ".2f", "factor 2": ".2f"}))
    summary: list[Summary] = [
        ("pairs fully right", right_total, total, 100 * rate, ">= 90 %"),
        ("pairs: named effects that did not pass the gap rule", broken, total, math.nan, "0")]
    notes = [f"Pairs: {elapsed:.0f} s; {as_delay} of the fully right with a tube named as its "
             "delay."]
    return tables, summary, notes


def _outside(seeds: int, setup: Setup, which: list[str] | None = None
             ) -> tuple[list[result_files.Table], list[Summary], list[str]]:
    """Physics outside the library: never explained; every named effect passed the gap rule.

    ``which``: these cases of :data:`OUTSIDE` only. Return the tables, the summary rows and
    notes for the result file.
    """
    started = time.monotonic()
    source = SOURCES[setup.source]
    print()
    print(f"Out of library: {seeds} campaigns each, data from the "
          f"{'virtual tunnel' if setup.source == 'tunnel' else 'library simulation'} (the "
          "growing mass: library), 2 % noise, seeds 70000 + 100 k + seed")
    print(f"{'case':<22}{'seed':>5}  {'named effects':<34}{'gap before':>11}{'gap after':>10}"
          f"{'explained':>10}  tried and undone (gap before -> after)")
    explained_total = broken = 0
    table = []
    for k, (label, campaign) in enumerate(OUTSIDE.items()):
        if which is not None and label not in which:
            continue
        for seed in range(seeds):
            report = diagnose(campaign(70_000 + 100 * k + seed, source), SECTION, depth=DEPTH)
            explained_total += report.explained
            broken += rule_broken(report)
            named = " + ".join(step.name for step in report.effects) or "none"
            undone = "; ".join(f"{name} {step.before:.4f} -> {step.after:.4f}"
                               for name, step in report.rejected) or "-"
            print(f"{label:<22}{seed:>5}  {named:<34}{report.gap_before:>11.4f}"
                  f"{report.gap_after:>10.4f}{str(report.explained):>10}  {undone}", flush=True)
            table.append((label, seed, named, report.gap_before, report.gap_after,
                          report.explained, undone))
    total = seeds * len(OUTSIDE if which is None else which)
    elapsed = time.monotonic() - started
    print(f"explained: {explained_total}/{total} (target 0): "
          f"{'met' if explained_total == 0 else 'MISSED'}; named effects that did not pass the "
          f"gap rule: {broken} (target 0); {elapsed:.0f} s")
    source_text = "virtual tunnel" if setup.source == "tunnel" else "library simulation"
    tables = [result_files.Table(
        f"Out of library, {seeds} campaign{'s' * (seeds != 1)} each, data from the "
        f"{source_text} (the growing mass: library), 2 % noise: the effects named, the gap "
        "before and after, whether the campaign was called explained, and the steps tried "
        "and undone by the gap rule.",
        ("case", "seed", "named effects", "gap before", "gap after", "explained",
         "tried and undone (gap before -> after)"), table,
        formats={"gap before": ".4f", "gap after": ".4f"})]
    summary: list[Summary] = [
        ("out of library: explained", explained_total, total,
         100 * explained_total / max(total, 1), "0"),
        ("out of library: named effects that did not pass the gap rule", broken, total,
         math.nan, "0")]
    return tables, summary, [f"Out of library: {elapsed:.0f} s."]


if __name__ == "__main__":
    main()
