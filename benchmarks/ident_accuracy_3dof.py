"""Accuracy, honesty and speed of E2RFC with three degrees of freedom (not a test).

The simulated 3-DOF bluff deck of :mod:`simulators.decks` (heave 1.2 Hz, pitch 3.6 Hz, sway
2.6 Hz; the bluff deck's ten-lag aerodynamics completed with quasi-steady drag terms, so the
truth is not of Roger's form with few lags): releases at 0.45, 0.65 and 0.8 of the flutter speed,
two per speed from holds ``(h, alpha, p) = (10 mm, 0.03 rad, 10 mm)`` and ``(-8 mm, 0.02 rad,
-12 mm)``, 20 s at 500 Hz, Gaussian noise of 2 % and 5 % of each channel's RMS on all six
channels (h, alpha, p, lift, moment, drag).

Printed per noise level: flutter-speed error (median and 90th percentile of |error| over the
seeds, %), the coverage of the 2-std interval of ``IdentifiedModel.flutter``, the median std
(%), the 18 flutter derivatives' coverage (the fraction of derivative values at seven reduced
frequencies across the range the releases measured whose error is within 2 of
``IdentifiedModel.flutter_derivative_std``; and on that range widened by 20 % on each side, as
the plots show it), and the median identification time (one core).

Run: ``.venv/bin/python benchmarks/ident_accuracy_3dof.py [--seeds 10] [--workers 2]
[--quick] [--results DIR]`` (``--quick``: one seed per noise level; ``--results``: also write
``DIR/ident_accuracy_3dof.json`` and ``.md``, :mod:`result_files`).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: one-core timings
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from ident import Release
from ident.identification import e2rfc, results
from ident.model import flutter as fl
from simulators.decks import BLUFF_DECK_3DOF, bluff_deck_3dof_model  # noqa: E402
from simulators.tunnel import simulate_release  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import result_files  # noqa: E402 - beside this script

HOLDS = ((0.010, 0.03, 0.010), (-0.008, 0.02, -0.012))
FRACTIONS = (0.45, 0.65, 0.8)


def one_case(args: tuple[float, int]) -> dict[str, float]:
    """Identify one seeded campaign; return its errors, coverage and time."""
    noise, seed = args
    section, truth = BLUFF_DECK_3DOF, bluff_deck_3dof_model()
    U_F = float(fl.analyze(section, truth).speed)  # type: ignore[arg-type]
    rng = np.random.default_rng(seed)
    releases = [
        Release.from_simulation(simulate_release(
            section, truth, f * U_F, h0, a0, p0=p0, duration=20.0, fs=500.0, noise=noise,
            rng=rng))
        for f in FRACTIONS for h0, a0, p0 in HOLDS]
    start = time.process_time()
    model = e2rfc.identify(releases, section)
    elapsed = time.process_time() - start
    result, std = model.flutter(section)
    wide = e2rfc.reduced_frequency_span(releases, section, 7)
    # The span is widened 20 % on both sides; the measured range itself is inside it.
    measured = np.linspace(wide[0] / 0.8, wide[-1] / 1.2, 7)
    speed = np.nan if result.speed is None else float(result.speed)
    return {"error": 100 * (speed - U_F) / U_F,
            "covered": float(std is not None and abs(speed - U_F) <= 2 * std),
            "std": np.nan if std is None else 100 * std / U_F,
            "fd_covered": _fd_coverage(model, truth, measured),
            "fd_wide": _fd_coverage(model, truth, wide), "time": elapsed}


def _fd_coverage(model: results.IdentifiedModel, truth: object, K: np.ndarray) -> float:
    """Fraction of the 18 derivatives' values at ``K`` within 2 reported std of the truth."""
    found, true = model.flutter_derivatives(K), truth.flutter_derivatives(K)  # type: ignore[attr-defined]
    sd = model.flutter_derivative_std(K)
    z = np.concatenate([(found[n] - true[n]) / np.maximum(sd[n], 1e-300) for n in found])
    return float(np.mean(np.abs(z) <= 2.0))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=None, help="seeds per noise level (10)")
    result_files.add_workers(parser)
    result_files.add_arguments(parser)
    args = parser.parse_args()
    seeds = args.seeds if args.seeds is not None else (1 if args.quick else 10)
    noises = (0.02, 0.05)
    if seeds < 1:
        parser.error("--seeds must be at least 1")
    print(f"{'noise':>6} {'n':>3} {'|err| med %':>11} {'|err| p90 %':>11} {'2-std cov':>9} "
          f"{'std med %':>9} {'FD cov':>6} {'FD cov +-20%':>12} {'time med s':>10}")
    table = []
    no_flutter = 0
    with ProcessPoolExecutor(args.workers) as pool:
        for noise in noises:
            rows = list(pool.map(one_case, [(noise, s) for s in range(seeds)]))
            err = np.abs([r["error"] for r in rows])
            no_flutter += int(np.sum(~np.isfinite(err)))
            line = (100 * noise, len(rows), np.median(err), np.percentile(err, 90),
                    np.mean([r["covered"] for r in rows]),
                    np.nanmedian([r["std"] for r in rows]),
                    np.mean([r["fd_covered"] for r in rows]),
                    np.mean([r["fd_wide"] for r in rows]),
                    np.median([r["time"] for r in rows]))
            table.append(line)
            print(f"{line[0]:5.0f}% {line[1]:3d} {line[2]:11.3f} {line[3]:11.3f} {line[4]:9.2f} "
                  f"{line[5]:9.3f} {line[6]:6.3f} {line[7]:12.3f} {line[8]:10.2f}")
    columns = ("noise (%)", "campaigns", "median error (%)", "p90 error (%)",
               "2-std coverage", "median std (%)", "FD coverage", "FD coverage, range +-20 %",
               "median time (s)")
    result_files.write(
        "ident_accuracy_3dof", "E2RFC with three degrees of freedom (3-DOF bluff deck)",
        [result_files.Table(
            "E2RFC on the 3-DOF bluff deck, 3 speeds (0.45/0.65/0.8 U_F) x 2 releases of 20 s "
            "at 500 Hz, seeded campaigns: the flutter speed's absolute error (median, 90th "
            "percentile), the 2-std coverage (fraction), the median std, the 18 flutter "
            "derivatives' 2-std coverage (fraction) and the median identification time.",
            columns, table,
            formats={"noise (%)": ".0f", "median error (%)": ".3f",
                     "p90 error (%)": ".3f", "2-std coverage": ".2f",
                     "median std (%)": ".3f", "FD coverage": ".3f",
                     "FD coverage, range +-20 %": ".3f", "median time (s)": ".2f"})],
        results=args.results, quick=args.quick,
        parameters={"seeds": seeds, "noises": list(noises), "workers": args.workers,
                    "fractions of U_F": list(FRACTIONS), "duration (s)": 20.0, "fs (Hz)": 500.0},
        notes=["Times are the process CPU time of one identification, BLAS on one thread.",
               "FD coverage: the fraction of the flutter derivatives' values across the measured "
               "reduced frequencies within two reported standard deviations of the truth; the "
               "next column on that range widened on each side, as the plots show it."],
        warnings=([f"{no_flutter} identification(s) found no flutter speed: their error is "
                   "undefined (NaN), and so are the median and p90 of their noise level."]
                  if no_flutter else []))


if __name__ == "__main__":
    main()
