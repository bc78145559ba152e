"""Confusion table of the discrepancy workflow: true hidden effect against the effect named.

Each row is 10 seeded simulated campaigns (:func:`simulators.campaigns.simulated_campaign`: the
flat-plate rig at 0.5, 0.65 and 0.8 U_F, two 7.5 s releases each, 2 % noise) with one effect
hidden at its realistic strength (:data:`simulators.campaigns.REALISTIC`), or none. Each is
diagnosed by :func:`ident.discrepancy.diagnose` (E2RFC baseline). Printed: the confusion table,
the median gap before and after, the median and worst parameter error of the correctly named
cases, how often the zero-wind coupling look (:mod:`ident.coupling`) found in-phase coupling in
both modes, the time per campaign. Targets (issue 7): >= 95 % named correctly, no false alarm on
clean data.

Run: ``.venv/bin/python benchmarks/discrepancy_confusion.py [--seeds 10] [--factor 1.0]``
(about 5 minutes on two cores).
"""

from __future__ import annotations

import argparse
import os
import time
from collections import Counter

import numpy as np

from ident.discrepancy import diagnose
from ident.effects import EFFECT_NAMES
from simulators.campaigns import _STRENGTHS, SECTION, scaled, simulated_campaign

DEPTH = 0.03  # m, the flat plate's depth (the vortex effect's)


def main() -> None:
    """Run the campaigns and print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10, help="campaigns per effect")
    parser.add_argument("--factor", type=float, default=1.0,
                        help="strength as a multiple of the realistic one (default 1)")
    args = parser.parse_args()
    rows = ["none", *EFFECT_NAMES]
    columns = [*rows]
    counts: dict[str, Counter[str]] = {row: Counter() for row in rows}
    gaps: dict[str, list[tuple[float, float]]] = {row: [] for row in rows}
    errors: dict[str, list[float]] = {row: [] for row in rows}
    coupled: Counter[str] = Counter()
    started = time.monotonic()
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    for row in rows:
        for seed in range(args.seeds):
            effect = None if row == "none" else scaled(row, args.factor)
            report = diagnose(simulated_campaign(effect, 1000 * (rows.index(row) + 1) + seed),
                              SECTION, depth=DEPTH)
            named = report.effect or "none"
            counts[row][named] += 1
            gaps[row].append((report.gap_before, report.gap_after))
            if report.zero_wind_coupling and all(c.significant
                                                 for c in report.zero_wind_coupling):
                coupled[row] += 1
            if effect is not None and named == row:
                errors[row].extend(abs(report.parameters[p] / getattr(effect, p) - 1.0)
                                   for p in _STRENGTHS[row])
        print(f"  {row}: {dict(counts[row])}", flush=True)
    elapsed = time.monotonic() - started
    n_campaigns = len(rows) * args.seeds

    width = max(len(c) for c in columns) + 1
    print()
    print(f"Confusion table: {args.seeds} campaigns per row, strength x{args.factor:g} of "
          "REALISTIC, 2 % noise; rows = hidden effect, columns = effect named")
    short = {c: c.split("_")[0][:8] for c in columns}
    print(f"{'hidden':<{width}}" + "".join(f"{short[c]:>9}" for c in columns)
          + f"{'correct':>9}{'gap before':>12}{'gap after':>11}{'param err med/max':>19}"
          + f"{'coupled':>9}")
    correct_total = 0
    for row in rows:
        correct = counts[row][row]
        correct_total += correct
        before = float(np.median([g[0] for g in gaps[row]]))
        after = float(np.median([g[1] for g in gaps[row]]))
        err = errors[row]
        err_text = "-" if not err else f"{np.median(err):.1%} / {max(err):.1%}"
        print(f"{row:<{width}}" + "".join(f"{counts[row][c]:>9}" for c in columns)
              + f"{correct / args.seeds:>9.0%}{before:>12.4f}{after:>11.4f}{err_text:>19}"
              + f"{coupled[row]:>9}")
    print("coupled = campaigns whose baseline lacks in-phase heave-pitch coupling at zero wind in "
          "both modes (ident.coupling)")
    false_alarms = args.seeds - counts["none"]["none"]
    rate = correct_total / n_campaigns
    print()
    print(f"named correctly: {correct_total}/{n_campaigns} = {rate:.1%} (target >= 95 %): "
          f"{'met' if rate >= 0.95 else 'MISSED'}")
    print(f"false alarms on clean data: {false_alarms} (target 0): "
          f"{'met' if false_alarms == 0 else 'MISSED'}")
    print(f"time: {elapsed:.0f} s, {elapsed / n_campaigns:.1f} s per campaign (simulation and "
          "diagnosis); load average after: "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
