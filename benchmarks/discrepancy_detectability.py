"""How strong each hidden effect must be before the linear baseline visibly misses it.

For every effect of :data:`simulators.campaigns.REALISTIC` and a grid of strength factors,
a campaign is recorded from the virtual tunnel (:func:`simulators.tunnel_campaigns.
tunnel_campaign`, 2 % noise), the linear baseline identified by E2RFC and simulated from each
release's start, and its residual split per channel into a systematic part and white noise
(:func:`ident.discrepancy.residual_check.systematic_levels`). Printed per effect and factor:
the baseline's gap, its excess over the clean campaign's, and the largest channel's
systematic-to-noise ratio. The effect is *detectable* from the factor where the gap excess
reaches the clean campaign's gap (the gap white noise leaves, about 0.02 at 2 % noise): the
effect doubles the baseline's gap. For the effects whose residual lies at the modes' frequencies
that is where the worst channel's systematic part is about twice the noise, which the honesty
check of :mod:`ident.discrepancy.residual_check` (at one noise) reports with room to spare;
weaker, the baseline's residual is hard to tell from white noise. (The ratio is no measure for
shedding: its line, far above the modes, survives the differencing that estimates the noise.)
The low ends of :data:`simulators.tunnel_campaigns.STRENGTH_RANGE` are these factors, rounded.

Run: ``.venv/bin/python benchmarks/discrepancy_detectability.py [--seeds 2] [--effects ...]
[--factors 0.02,0.03,...]`` (about 8 minutes on one core per seed). ``--quick`` (CI): one seed,
the first effect, the factors 0.1 and 1 (what is given still wins). ``--results DIR`` also
writes the tables to ``DIR/discrepancy_detectability.json`` and ``.md`` (:mod:`result_files`).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from ident.discrepancy.effect_selection import channels, gap, simulate_channels
from ident.discrepancy.residual_check import systematic_levels
from ident.identification import e2rfc
from simulators.campaigns import REALISTIC, SECTION, scaled
from simulators.tunnel_campaigns import STRENGTH_RANGE, tunnel_campaign

sys.path.insert(0, str(Path(__file__).resolve().parent))
import result_files  # noqa: E402 - beside this script

FACTORS = (0.02, 0.03, 0.05, 0.07, 0.1, 0.15, 0.2, 0.3, 0.5, 0.7, 1.0, 1.5, 2.0, 3.0)
#: What ``--quick`` scans (unless given).
QUICK_FACTORS = (0.1, 1.0)


def baseline_levels(effect: object, seed: int) -> tuple[float, float]:
    """Return the baseline's gap and its largest channel's systematic-to-noise ratio."""
    releases = tunnel_campaign(effect, seed)  # type: ignore[arg-type]
    model = e2rfc.identify(releases, SECTION)
    simulated = [simulate_channels(r, SECTION, model, ()) for r in releases]
    levels = systematic_levels(releases, simulated)
    ratio = max(sys / noise for sys, noise in levels.values() if noise > 0)
    return gap([channels(r) for r in releases], simulated), ratio


def main() -> None:
    """Scan the strengths and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=None,
                        help="campaigns per strength (2; --quick: 1)")
    parser.add_argument("--effects", nargs="*", default=None,
                        choices=list(REALISTIC),
                        help="effects to scan (default: all; --quick: the first)")
    parser.add_argument("--factors", default=None,
                        help="strength factors, comma-separated, ascending (default FACTORS; "
                             "--quick: 0.1,1)")
    result_files.add_arguments(parser)
    args = parser.parse_args()
    seeds = args.seeds if args.seeds is not None else (1 if args.quick else 2)
    effects = (args.effects if args.effects is not None
               else list(REALISTIC)[:1] if args.quick else list(REALISTIC))
    factors = (tuple(result_files.number_list(parser, "--factors", args.factors, 0.0, math.inf))
               if args.factors is not None else QUICK_FACTORS if args.quick else FACTORS)
    if seeds < 1:
        parser.error("--seeds must be >= 1")
    if list(factors) != sorted(factors) or not all(f > 0 for f in factors):
        parser.error("--factors must be positive and ascending")
    started = time.monotonic()
    clean = [baseline_levels(None, 7000 + s) for s in range(seeds)]
    clean_gap = float(np.mean([g for g, _ in clean]))
    clean_ratio = float(np.mean([r for _, r in clean]))
    print(f"clean: gap {clean_gap:.4f}, systematic/noise "
          f"{clean_ratio:.2f} ({seeds} seeds, 2 % noise)")
    print(f"{'effect':<26}" + "".join(f"{f:>7g}" for f in factors)
          + f"{'detectable from':>17}{'range used':>14}")
    scan, summary = [], []
    for name in effects:
        ratios = []
        excess = []
        for factor in factors:
            k = FACTORS.index(factor) if factor in FACTORS else len(FACTORS) + factors.index(factor)
            runs = [baseline_levels(scaled(name, factor), 7100 + 10 * k + s)
                    for s in range(seeds)]
            excess.append(float(np.mean([g for g, _ in runs])) - clean_gap)
            ratios.append(float(np.mean([r for _, r in runs])))
            scan.append((name, factor, excess[-1], ratios[-1]))
        low = _crossing(excess, clean_gap, factors)
        used = STRENGTH_RANGE[name]
        summary.append((name, low if math.isfinite(low) else None, used[0], used[1]))
        print(f"{name:<26}" + "".join(f"{r:>7.2f}" for r in ratios)
              + f"{'x' + format(low, '.2f') if math.isfinite(low) else 'never':>17}"
              + f"{'x' + format(used[0], 'g') + '-' + format(used[1], 'g'):>14}")
        print(f"{'  gap excess':<26}" + "".join(f"{e:>7.4f}" for e in excess), flush=True)
    elapsed = time.monotonic() - started
    print(f"rows: systematic/noise of the baseline's worst channel at each strength factor "
          f"(x of REALISTIC); 'gap excess': the baseline's gap minus the clean one; detectable "
          f"from: where the excess reaches the clean gap. "
          f"{elapsed:.0f} s")
    tables = [
        result_files.Table(
            "The clean campaigns (2 % noise): the linear baseline's gap and its worst "
            "channel's systematic-to-noise ratio, means over the campaigns.",
            ("campaigns", "gap", "systematic/noise"), [(seeds, clean_gap, clean_ratio)],
            formats={"gap": ".4f", "systematic/noise": ".2f"}),
        result_files.Table(
            "Per effect and strength factor (x of REALISTIC): the baseline's gap minus the "
            "clean one, and the systematic-to-noise ratio of its worst channel (means over the "
            "seeds).",
            ("effect", "strength factor", "gap excess", "systematic/noise"), scan,
            formats={"strength factor": "g", "gap excess": ".4f", "systematic/noise": ".2f"}),
        result_files.Table(
            "Per effect: the strength factor from which it is detectable (the gap excess "
            "reaches the clean gap, log-interpolated; n/a: never within the factors scanned) "
            "and the range simulators.tunnel_campaigns.STRENGTH_RANGE uses.",
            ("effect", "detectable from (x)", "range used from (x)", "range used to (x)"),
            summary, formats={"detectable from (x)": ".2f", "range used from (x)": "g",
                              "range used to (x)": "g"}),
    ]
    result_files.write(
        "discrepancy_detectability", "How strong a hidden effect must be to be detectable",
        tables, results=args.results, quick=args.quick,
        parameters={"seeds": seeds, "effects": effects, "factors": list(factors),
                    "noise": 0.02},
        notes=[f"The scan took {elapsed:.0f} s (campaigns recorded from the virtual tunnel, "
               "E2RFC baseline and its simulation)."])


def _crossing(values: list[float], level: float,
              factors: tuple[float, ...] = FACTORS) -> float:
    """Factor where ``values`` (over ``factors``) first reaches ``level``, log-interpolated."""
    for k, value in enumerate(values):
        if value >= level:
            if k == 0:
                return factors[0]
            lo, hi = values[k - 1], value
            w = (level - lo) / (hi - lo)
            return math.exp(math.log(factors[k - 1]) + w * math.log(factors[k] / factors[k - 1]))
    return math.inf


if __name__ == "__main__":
    main()
