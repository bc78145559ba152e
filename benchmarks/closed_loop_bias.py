"""Where the closed-loop fit's bias in turbulence comes from (not a test).

With eight releases per wind speed the closed-loop maximum-likelihood fit's flutter-speed
errors on the tunnel's plate in 1 % turbulence lean below the truth while its Fisher standard
deviation halves: a bias. This benchmark separates its causes by fitting two sources of
releases with four buffeting models:

- **own model**: releases drawn from the estimator's own model class
  (:class:`~ident.identification.innovations.ReleaseModel`: Jones's plate, a second-order
  shaping filter per force, white sensor noise) at 500 Hz, at the buffeting level, spectrum
  and noise that the fit found on the tunnel's releases (``BUFFETING``, ``NOISE``). The filter
  is one shape scaled with the speed as gusts of a fixed intensity and scale scale it (corner
  as ``U``, level as ``U ** 1.5``), so the source lies in every model's class: only the
  decimation to block means stands between it and each model;
- **tunnel**: the benchmark's row "plate, Iw 1 %, 8 releases" of ``ident_accuracy.py`` (von
  Karman gusts averaged over the span, holds of 10 s), whose buffeting spectrum no low-order
  filter matches exactly;

and the models of ``e2rfc.CLOSED_LOOP_BUFFETING_MODELS``: ``second-order`` (one section per
force, block means taken as samples of the state) and ``fourth-order`` (two sections with
zeros, the block means modelled exactly), each as one filter shared by the speeds (the
identification's) and as a filter per speed. Every fit starts from plain E2RFC's estimate on
the releases without their holds; 3 speeds (0.4, 0.6, 0.8 U_F) x 8 releases of 20 s.

Printed per source and model: the flutter-speed error of each seed, their mean and median
absolute value, the median Fisher std (the likelihood's own, without the structure and
extrapolation parts), the share of seeds within 2 Fisher std, and the median time of the fit.
A bias shows as a mean far from zero against the errors' spread.

Run: ``.venv/bin/python benchmarks/closed_loop_bias.py [--seeds 10] [--workers 2]``; ``--quick``:
one seed of the own-model source with 2 releases per speed, second-order only. ``--results
DIR`` writes ``DIR/closed_loop_bias.json`` and ``.md``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: one-core timings
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from ident import Release
from ident.identification import closed_loop_ml, e2rfc
from ident.identification.innovations import ReleaseModel, ShapingFilter
from ident.model import flutter as fl

sys.path.insert(0, str(Path(__file__).resolve().parent))
import ident_accuracy as ia  # noqa: E402 - beside this script
import result_files  # noqa: E402

ROW = "plate, Iw 1 %, 8 releases"
#: The buffeting the second-order fit found on the tunnel row's releases (seed 1, without
#: holds) at the middle speed, 0.6 U_F: corner frequency (Hz), damping ratio (one value for
#: the three speeds' 1.7-2.4) and the Cholesky factor of the white noise's intensity
#: (N m/m s^0.5); lift and moment one gust's. Scaled to the other speeds by
#: ``BUFFETING_EXPONENTS``.
BUFFETING = (5.22, 1.9, [[0.0503, 0.0], [-0.0125, 5.0e-6]])
#: Exponents of the speed in the corner frequency and in the intensity's factor: quasi-steady
#: buffeting by gusts of a fixed intensity and integral scale (Taylor's hypothesis). The
#: per-speed fits had found corners of 3.71, 5.22 and 5.85 Hz and factors 0.033, 0.050 and
#: 0.089 at 0.4, 0.6 and 0.8 U_F.
BUFFETING_EXPONENTS = (1.0, 1.5)
#: Sensor-noise std of h (m), alpha (rad), lift (N/m), moment (N m/m) at the decimated rate
#: (100 Hz) that the same fit found, per speed.
NOISE = ((2.25e-5, 1.08e-4, 3.20e-3, 2.23e-4),
         (2.40e-5, 1.11e-4, 6.85e-3, 5.58e-4),
         (3.11e-5, 1.23e-4, 1.40e-2, 9.33e-4))
SOURCES = ("own model", "tunnel")
MODELS = ("second-order", "fourth-order", "second-order-per-speed", "fourth-order-per-speed")
FS = 500.0
DECIMATED = 100.0


def own_model_releases(seed, per_speed=8):
    """Return 3 speeds x ``per_speed`` releases drawn from the estimator's model class, U_F."""
    section, make_model, *_ = ia.row_spec(ROW)
    truth = make_model()
    U_F = fl.analyze(section, truth).speed
    rng = np.random.default_rng((seed, 7))
    n = int(20.0 * FS)
    releases = []
    fc_mid, zeta, L_mid = BUFFETING
    a, b = BUFFETING_EXPONENTS
    for fraction, noise in zip(ia.E2RFC_SPEEDS, NOISE, strict=True):
        U = fraction * U_F
        scale = fraction / ia.E2RFC_SPEEDS[1]
        fc, L = fc_mid * scale ** a, np.asarray(L_mid) * scale ** b
        # White noise at 500 Hz whose block means of 5 have the decimated rate's std.
        model = ReleaseModel(section, truth, U, FS, ShapingFilter([fc, fc], [zeta, zeta], L),
                             np.asarray(noise) * math.sqrt(FS / DECIMATED))
        for j in range(per_speed):
            h0, alpha0 = ia.HOLDS[j % len(ia.HOLDS)]
            y = model.sample(model.initial_state(h0, alpha0), model.initial_covariance(), n,
                             rng)
            releases.append(Release(t=np.arange(n) / FS, h=y[:, 0], alpha=y[:, 1],
                                    lift=y[:, 2], moment=y[:, 3], U=U))
    return releases, U_F


def run(args):
    """One fit; returns (source, model, seed, error, Fisher std over U_F, converged, time)."""
    source, name, seed, per_speed = args
    section, *_ = ia.row_spec(ROW)
    if source == "own model":
        releases, U_F = own_model_releases(seed, per_speed)
    else:
        releases = ia.tunnel_releases(ROW, seed)
        U_F = fl.analyze(section, ia.row_spec(ROW)[1]()).speed
    e2rfc.TURBULENT_ESTIMATOR = "iv"  # without holds: plain E2RFC's estimate, the start
    start = e2rfc.identify([dataclasses.replace(r, hold=None) for r in releases], section)
    began = time.perf_counter()
    try:
        fit = closed_loop_ml.fit_closed_loop(releases, section, start, n_lags=2,
                                             **e2rfc.CLOSED_LOOP_BUFFETING_MODELS[name])
        found = fl.analyze(section, fit.model)
    except ValueError as exc:
        print(f"FAILED {source} {name} seed {seed}: {exc}", flush=True)
        return source, name, seed, math.inf, math.nan, False, math.nan
    elapsed = time.perf_counter() - began
    if found.speed is None:
        return source, name, seed, math.inf, math.nan, fit.converged, elapsed
    std = ia.fisher_flutter_std(section, fit, found)
    return (source, name, seed, found.speed / U_F - 1.0, std / U_F, fit.converged, elapsed)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=None, help="seeds per case (10; --quick 1)")
    result_files.add_workers(parser)
    result_files.add_arguments(parser)
    args = parser.parse_args()
    seeds = args.seeds if args.seeds is not None else (1 if args.quick else 10)
    if seeds < 1:
        parser.error("--seeds must be at least 1")
    sources, models = (SOURCES[:1], MODELS[:1]) if args.quick else (SOURCES, MODELS)
    per_speed = 2 if args.quick else 8
    jobs = [(s, m, seed, per_speed) for s in sources for m in models for seed in range(seeds)]
    results = []
    with ProcessPoolExecutor(args.workers) as pool:
        for result in pool.map(run, jobs):
            source, name, seed, err, std, converged, elapsed = result
            print(f"  {source:<10} {name:<22} seed {seed:2d} err {100 * err:+8.2f} % Fisher std "
                  f"{100 * std:6.2f} %{'' if converged else ' (not converged)'} "
                  f"{elapsed:6.1f} s", flush=True)
            results.append(result)
    rows = []
    for source in sources:
        for name in models:
            got = [r for r in results if r[:2] == (source, name)]
            err = np.array([r[3] for r in got]) * 100
            std = np.array([r[4] for r in got]) * 100
            finite = np.isfinite(err)
            rows.append((source, name, " ".join(f"{e:+.2f}" for e in err),
                         float(np.mean(err[finite])) if finite.any() else math.nan,
                         float(np.median(np.abs(err))),
                         float(np.nanmedian(std)),
                         100.0 * float(np.mean(finite & (np.abs(err) <= 2 * std))),
                         float(np.nanmedian([r[6] for r in got]))))
    table = result_files.Table(
        f"The closed-loop fit's flutter-speed error (%) by source of releases and buffeting "
        f"model, {seeds} seed(s), 3 speeds x 8 releases of 20 s; std the Fisher information's "
        "alone; time of the fit on one core",
        ["source", "buffeting model", "errors (%)", "mean error (%)", "median |error| (%)",
         "median Fisher std (%)", "within 2 std (%)", "median time (s)"], rows,
        formats={"mean error (%)": "+.2f", "median |error| (%)": ".2f",
                 "median Fisher std (%)": ".2f", "within 2 std (%)": ".0f",
                 "median time (s)": ".1f"})
    print()
    for row in rows:
        print(f"{row[0]:<10} {row[1]:<22} mean {row[3]:+6.2f} % median |err| {row[4]:5.2f} % "
              f"std {row[5]:5.2f} % within 2 std {row[6]:3.0f} % time {row[7]:5.1f} s")
    result_files.write(
        "closed_loop_bias", "Where the closed-loop fit's bias in turbulence comes from",
        [table], results=args.results, quick=args.quick,
        parameters={"seeds": seeds, "workers": args.workers, "row": ROW,
                    "releases per speed": per_speed},
        notes=["Times are wall times on one core (BLAS single-threaded) of a shared host."])


if __name__ == "__main__":
    main()
