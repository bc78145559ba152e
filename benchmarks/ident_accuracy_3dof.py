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

``--part turbulent`` releases the same deck in vertical gusts (von Karman, 0.3 m scale, as
``ident_accuracy.py``'s tunnel rows; the lift, moment and drag buffeting from the static
coefficients its drag terms come from, ``BLUFF_DECK_3DOF_STATIC``) at Iw 1 % and 3 %, and with
along-wind gusts of 2 % (1 m scale) beside 1 % vertical ones, with a 10 s hold before each
release and without, noise 2 %, and prints per row how many campaigns
the turbulence branch took as turbulent, the flutter speed's median and mean error, p90, the
coverage of ``FlutterUncertainty.interval`` (structure and extrapolation parts included), the
median std and time, for the closed-loop likelihood (the default) and, where the holds allow
it, the refined-IV estimator it replaced on these releases. Beside them the median error of an
estimator at the Cramer-Rao bound of the same releases (``flutter_crb.py``'s Whittle bound, in
the fit's own class: the deck's two-lag approximant, every coefficient unknown; the median over
coefficients drawn from the bound's covariance, with the holds' information where the row has
holds) and the row's median error over it.

Run: ``.venv/bin/python benchmarks/ident_accuracy_3dof.py [--part smooth|turbulent]
[--seeds 10] [--workers 2] [--quick] [--results DIR]`` (``--quick``: one seed per row;
``--results``: also write ``DIR/ident_accuracy_3dof.json`` and ``.md``, or
``ident_accuracy_3dof_turbulent``'s, :mod:`result_files`).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: one-core timings
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import re  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from ident import Release
from ident.identification import e2rfc, results
from ident.model import flutter as fl
from ident.model.rfc import RationalFunctionModel
from ident.physics.turbulence import TurbulenceSpec
from simulators.decks import (  # noqa: E402
    BLUFF_DECK_3DOF,
    BLUFF_DECK_3DOF_STATIC,
    bluff_deck_3dof_model,
)
from simulators.tunnel import simulate_release  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import flutter_crb  # noqa: E402 - beside this script
import result_files  # noqa: E402

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


#: The turbulent part's rows: name -> (Iu, Iw, seconds of hold before each release). The last
#: two add along-wind gusts of twice the vertical intensity, which dominate this deck's drag
#: buffeting (``2 C_D u`` against ``(dC_D + C_L) w``) with a spectrum of their own (1 m scale):
#: a force spectrum that one filter shape per force follows only in part.
TURBULENT_HOLD_S = 10.0
TURBULENT_ROWS = {"Iw 1 %, holds": (0.0, 0.01, TURBULENT_HOLD_S),
                  "Iw 1 %, no holds": (0.0, 0.01, 0.0),
                  "Iw 3 %, holds": (0.0, 0.03, TURBULENT_HOLD_S),
                  "Iw 3 %, no holds": (0.0, 0.03, 0.0),
                  "Iu 2 %, Iw 1 %, holds": (0.02, 0.01, TURBULENT_HOLD_S),
                  "Iu 2 %, Iw 1 %, no holds": (0.02, 0.01, 0.0)}


def turbulent_case(args: tuple[str, int, str]) -> dict[str, float]:
    """Identify one seeded turbulent campaign with ``estimator``; return error, std, time."""
    row, seed, estimator = args
    Iu, Iw, hold_s = TURBULENT_ROWS[row]
    e2rfc.TURBULENT_ESTIMATOR = estimator  # set in each worker
    section, truth = BLUFF_DECK_3DOF, bluff_deck_3dof_model()
    U_F = float(fl.analyze(section, truth).speed)  # type: ignore[arg-type]
    gusts = TurbulenceSpec(Iu=Iu, Iw=Iw, Lux=1.0, Lwx=0.3, Cuy=10.0, Cwy=8.0)
    # The vertical-gust rows' draws do not depend on Iu (their seeds came first).
    draws = (int(1000 * Iw),) if not Iu else (int(1000 * Iw), int(1000 * Iu))
    releases = [
        Release.from_simulation(simulate_release(
            section, truth, f * U_F, h0, a0, p0=p0, duration=20.0, fs=500.0, noise=0.02,
            rng=(seed, i, j, *draws), static=BLUFF_DECK_3DOF_STATIC, turbulence=gusts,
            span=1.0, pre_s=hold_s))
        for i, f in enumerate(FRACTIONS) for j, (h0, a0, p0) in enumerate(HOLDS)]
    start = time.process_time()
    model = e2rfc.identify(releases, section)
    uncertainty = model.uncertainty(section)
    elapsed = time.process_time() - start
    # Whether the turbulence branch ran: under e2rfc's random-response limit E2RFC's own
    # estimate stands, with its warnings.
    branch = float(model.diagnostics.estimator in (e2rfc.ESTIMATOR_CLOSED_LOOP,
                                                   e2rfc.ESTIMATOR_TURBULENT))
    # Whether the closed-loop fit took the buffeting sources mixed after their filters.
    mixed = float(re.search(r"fourth-order-mixed[-a-z]* buffeting model",
                            model.diagnostics.reason) is not None)
    if uncertainty.speed is None:
        return {"error": np.nan, "covered": 0.0, "std": np.nan, "time": elapsed,
                "branch": branch, "mixed": mixed}
    low, high = uncertainty.interval()
    return {"error": 100 * (uncertainty.speed - U_F) / U_F,
            "covered": float(low <= U_F <= high), "std": 100 * uncertainty.total / U_F,
            "time": elapsed, "branch": branch, "mixed": mixed}


def gust_bound(args: tuple[float, float, int]) -> tuple[float, float]:
    """Return the sampled median error at the bound (% of U_F) without and with the holds.

    For the turbulent rows' releases in gusts of ``(Iu, Iw)``, ``samples`` draws
    (:func:`flutter_crb.flutter_speed_bound`), in the fit's class (:func:`approximant`).
    """
    Iu, Iw, samples = args
    gusts = TurbulenceSpec(Iu=Iu, Iw=Iw, Lux=1.0, Lwx=0.3, Cuy=10.0, Cwy=8.0)
    bound = flutter_crb.flutter_speed_bound(
        BLUFF_DECK_3DOF, approximant(), Iw, static=BLUFF_DECK_3DOF_STATIC, fractions=FRACTIONS,
        holds=HOLDS, gusts=gusts, hold_s=TURBULENT_HOLD_S, samples=samples)
    return (100 * bound.sampled_median / bound.U_F,
            100 * bound.sampled_median_with_holds / bound.U_F)


def approximant() -> RationalFunctionModel:
    """Return the 3-DOF deck's two-lag approximant with A3, the closed-loop fit's class.

    Fitted to the deck's 18 flutter derivatives over the still-air reduced frequencies of the
    lowest and highest speed, widened by a fifth (:func:`flutter_crb.two_lag_approximant`).
    """
    section, truth = BLUFF_DECK_3DOF, bluff_deck_3dof_model()
    U_F = float(fl.analyze(section, truth).speed)  # type: ignore[arg-type]
    f = [section.fh, section.fa, section.fp]
    K = (2 * np.pi * min(f) * section.B / (max(FRACTIONS) * U_F) / 1.25,
         2 * np.pi * max(f) * section.B / (min(FRACTIONS) * U_F) * 1.2)
    return flutter_crb.two_lag_approximant(truth, K)


def turbulent_part(seeds: int, workers: int, samples: int
                   ) -> tuple[list[tuple[object, ...]], int]:
    """Run and print the turbulent rows; return the table and the count without flutter."""
    print(f"{'row':<24} {'estimator':<26} {'n':>3} {'ran':>3} {'|err| med %':>11} "
          f"{'mean %':>7} {'p90 %':>7} {'cov':>5} {'std med %':>9} {'time s':>6} "
          f"{'where ran: |err| med %':>22} {'cov':>5} {'bound %':>7} {'ratio':>5} "
          f"{'mixed':>5}")
    table: list[tuple[object, ...]] = []
    no_flutter = 0
    with ProcessPoolExecutor(workers) as pool:
        gusts = sorted({(Iu, Iw) for Iu, Iw, _ in TURBULENT_ROWS.values()})
        bounds = dict(zip(gusts, pool.map(gust_bound, [(*g, samples) for g in gusts]),
                          strict=True))
        for row, (Iu, Iw, hold_s) in TURBULENT_ROWS.items():
            bound = bounds[Iu, Iw][1 if hold_s else 0]
            estimators = [("ml", "closed-loop likelihood")]
            if hold_s:  # refined IV needs the holds
                estimators.append(("iv", "refined IV (earlier)"))
            for estimator, label in estimators:
                found = list(pool.map(turbulent_case,
                                      [(row, s, estimator) for s in range(seeds)]))
                err = np.array([r["error"] for r in found])
                no_flutter += int(np.sum(~np.isfinite(err)))
                ran = [r for r in found if r["branch"]]
                line = (row, label, len(found), len(ran),
                        np.median(np.abs(err)), np.mean(err),
                        np.percentile(np.abs(err), 90), np.mean([r["covered"] for r in found]),
                        np.nanmedian([r["std"] for r in found]),
                        np.median([r["time"] for r in found]),
                        np.median([abs(r["error"]) for r in ran]) if ran else np.nan,
                        np.mean([r["covered"] for r in ran]) if ran else np.nan,
                        bound, np.median(np.abs(err)) / bound,
                        int(sum(r["mixed"] for r in found)))
                table.append(line)
                print(f"{row:<24} {label:<26} {line[2]:3d} {line[3]:3d} {line[4]:11.2f} "
                      f"{line[5]:+7.2f} {line[6]:7.2f} {line[7]:5.2f} {line[8]:9.2f} "
                      f"{line[9]:6.1f} {line[10]:22.2f} {line[11]:5.2f} {line[12]:7.2f} "
                      f"{line[13]:5.2f} {line[14]:5d}", flush=True)
    return table, no_flutter


def _fd_coverage(model: results.IdentifiedModel, truth: object, K: np.ndarray) -> float:
    """Fraction of the 18 derivatives' values at ``K`` within 2 reported std of the truth."""
    found, true = model.flutter_derivatives(K), truth.flutter_derivatives(K)  # type: ignore[attr-defined]
    sd = model.flutter_derivative_std(K)
    z = np.concatenate([(found[n] - true[n]) / np.maximum(sd[n], 1e-300) for n in found])
    return float(np.mean(np.abs(z) <= 2.0))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", choices=("smooth", "turbulent"), default="smooth",
                        help="smooth flow at two noise levels (default) or turbulence")
    parser.add_argument("--seeds", type=int, default=None, help="seeds per row (10)")
    result_files.add_workers(parser)
    result_files.add_arguments(parser)
    args = parser.parse_args()
    seeds = args.seeds if args.seeds is not None else (1 if args.quick else 10)
    if seeds < 1:
        parser.error("--seeds must be at least 1")
    if args.part == "turbulent":
        write_turbulent(args, seeds)
        return
    noises = (0.02, 0.05)
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


def write_turbulent(args: argparse.Namespace, seeds: int) -> None:
    """Run the turbulent part and write its results."""
    samples = flutter_crb.QUICK_SAMPLES if args.quick else flutter_crb.SAMPLES
    table, no_flutter = turbulent_part(seeds, args.workers, samples)
    columns = ("row", "estimator", "campaigns", "branch ran", "median error (%)",
               "mean error (%)", "p90 error (%)", "interval coverage", "median std (%)",
               "median time (s)", "where it ran: median error (%)", "where it ran: coverage",
               "median error at the bound (%)", "median error / bound",
               "mixed buffeting sources")
    result_files.write(
        "ident_accuracy_3dof_turbulent",
        "E2RFC with three degrees of freedom in turbulence (3-DOF bluff deck)",
        [result_files.Table(
            "The 3-DOF bluff deck in gusts (vertical; along-wind too in the last rows), 3 "
            "speeds (0.45/0.65/0.8 U_F) x 2 releases of 20 s at 500 Hz, noise 2 %, seeded "
            "campaigns: the flutter speed's "
            "absolute error (median, 90th percentile), its mean signed error, the coverage of "
            "the reported interval (fraction), the median std and the median time of the "
            "identification with its uncertainty; then the median error and the coverage "
            "over the campaigns the turbulence branch ran on; last the median error of an "
            "estimator at the Cramer-Rao bound of the same releases, the row's median "
            "error over it, and the campaigns whose closed-loop fit took the buffeting "
            "sources mixed after their filters.",
            columns, table,
            formats={"median error (%)": ".2f", "mean error (%)": "+.2f",
                     "p90 error (%)": ".2f", "interval coverage": ".2f",
                     "median std (%)": ".2f", "median time (s)": ".1f",
                     "where it ran: median error (%)": ".2f",
                     "where it ran: coverage": ".2f",
                     "median error at the bound (%)": ".2f", "median error / bound": ".2f"})],
        results=args.results, quick=args.quick, script="ident_accuracy_3dof",
        parameters={"part": "turbulent", "seeds": seeds, "workers": args.workers,
                    "rows": {name: {"Iu": Iu, "Iw": Iw, "hold (s)": hold}
                             for name, (Iu, Iw, hold) in TURBULENT_ROWS.items()},
                    "fractions of U_F": list(FRACTIONS), "duration (s)": 20.0,
                    "fs (Hz)": 500.0, "noise": 0.02, "bound draws": samples},
        notes=["Times are the process CPU time of the identification and its uncertainty, "
               "BLAS on one thread.",
               "Branch ran: the campaigns whose releases the turbulence branch took as "
               "turbulent (the modal fits' residual above ten times the noise, or above five "
               "with holds whose forces show the wind's load); on the others E2RFC's own "
               "estimate stands, with its warnings, and enters the row's figures.",
               "The deck's truth has ten lags and quasi-steady drag terms; the fits have two "
               "lags and A3. The refined-IV rows are the estimator that ran on 3-DOF releases "
               "in turbulence before the closed-loop likelihood took three degrees of freedom; "
               "it needs the holds, so it has no rows without them.",
               "The bound (flutter_crb.py, Whittle) is taken in the fit's own class: the "
               "deck's two-lag approximant with A3 (fitted to its flutter derivatives; it "
               "flutters 0.1 % above the deck), every coefficient unknown, the buffeting's "
               "3 x 3 level, a shape and each release's held displacement as nuisances; the "
               "median error over coefficients drawn from its covariance. It treats the "
               "random response as stationary from the release, which makes it somewhat "
               "optimistic (8-18 % on a planar surrogate, flutter_crb_exact.py)."],
        warnings=([f"{no_flutter} identification(s) found no flutter speed: their error is "
                   "undefined (NaN), and so are the median and p90 of their row."]
                  if no_flutter else []))


if __name__ == "__main__":
    main()
