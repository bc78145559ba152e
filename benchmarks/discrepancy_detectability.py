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

Run: ``.venv/bin/python benchmarks/discrepancy_detectability.py [--seeds 2] [--effects ...]``
(about 8 minutes on one core per seed).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from ident.discrepancy.effect_selection import channels, gap, simulate_channels
from ident.discrepancy.residual_check import systematic_levels
from ident.identification import e2rfc
from simulators.campaigns import REALISTIC, SECTION, scaled
from simulators.tunnel_campaigns import STRENGTH_RANGE, tunnel_campaign

FACTORS = (0.02, 0.03, 0.05, 0.07, 0.1, 0.15, 0.2, 0.3, 0.5, 0.7, 1.0, 1.5, 2.0, 3.0)


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
    parser.add_argument("--seeds", type=int, default=2, help="campaigns per strength")
    parser.add_argument("--effects", nargs="*", default=list(REALISTIC),
                        choices=list(REALISTIC), help="effects to scan (default: all)")
    args = parser.parse_args()
    if args.seeds < 1:
        parser.error("--seeds must be >= 1")
    started = time.monotonic()
    clean = [baseline_levels(None, 7000 + s) for s in range(args.seeds)]
    clean_gap = float(np.mean([g for g, _ in clean]))
    print(f"clean: gap {clean_gap:.4f}, systematic/noise "
          f"{np.mean([r for _, r in clean]):.2f} ({args.seeds} seeds, 2 % noise)")
    print(f"{'effect':<26}" + "".join(f"{f:>7g}" for f in FACTORS)
          + f"{'detectable from':>17}{'range used':>14}")
    for name in args.effects:
        ratios = []
        excess = []
        for k, factor in enumerate(FACTORS):
            runs = [baseline_levels(scaled(name, factor), 7100 + 10 * k + s)
                    for s in range(args.seeds)]
            excess.append(float(np.mean([g for g, _ in runs])) - clean_gap)
            ratios.append(float(np.mean([r for _, r in runs])))
        low = _crossing(excess, clean_gap)
        used = STRENGTH_RANGE[name]
        print(f"{name:<26}" + "".join(f"{r:>7.2f}" for r in ratios)
              + f"{'x' + format(low, '.2f') if math.isfinite(low) else 'never':>17}"
              + f"{'x' + format(used[0], 'g') + '-' + format(used[1], 'g'):>14}")
        print(f"{'  gap excess':<26}" + "".join(f"{e:>7.4f}" for e in excess), flush=True)
    print(f"rows: systematic/noise of the baseline's worst channel at each strength factor "
          f"(x of REALISTIC); 'gap excess': the baseline's gap minus the clean one; detectable "
          f"from: where the excess reaches the clean gap. "
          f"{time.monotonic() - started:.0f} s")


def _crossing(values: list[float], level: float) -> float:
    """Factor where ``values`` (over :data:`FACTORS`) first reaches ``level``, log-interpolated."""
    for k, value in enumerate(values):
        if value >= level:
            if k == 0:
                return FACTORS[0]
            lo, hi = values[k - 1], value
            w = (level - lo) / (hi - lo)
            return math.exp(math.log(FACTORS[k - 1]) + w * math.log(FACTORS[k] / FACTORS[k - 1]))
    return math.inf


if __name__ == "__main__":
    main()
