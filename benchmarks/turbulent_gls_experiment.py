"""Experiment, measured and dropped: iterated GLS (prediction-error) fit of E2RFC in turbulence.

Issue 16's idea: regress the measured forces on regressors built from the MEASURED motion (q
low-passed zero-phase at ``PEM_FC`` times the highest still-air frequency, q' and q'' by
Savitzky-Golay, lag states by filtering q' through 1/(s + d U/B) from rest, decimated by
``PEM_DECIM``), so that F_se of the random response is in the regressors; model the residual
(buffeting plus noise) per release and force channel as AR(p) (p by BIC, up to 20), prewhiten
both sides, refit, three times (Cochrane-Orcutt); lag roots by a search of the whitened residual
norm; flutter-speed std from the leave-one-release-out jackknife (Student-scaled, as E2RFC).
Variants: ``PEM_IV=6,10,14`` two-stage least squares with the whitened regressors delayed by
those samples as instruments (refined IV); ``PEM_DOBJ=resid`` the lag roots by the whitened
residual of those IV coefficients (prediction error) instead of its projection on the
instruments; ``PEM_HOLD=10`` the releases simulated with a 10 s hold before each and the AR
noise model fitted to the held model's force (buffeting plus noise alone: no motion), fixed,
instead of iterated from the fit's residual; ``PEM_CAUSAL=1`` the same causal low-pass on both
sides instead of the zero-phase one; ``PEM_NOISE_FROM_FORCE=1`` the fixed AR noise model
fitted to each release's own measured force instead (no hold); ``PEM_PMAX`` the largest order of
a fixed AR noise model (20); ``PEM_TRUTH_D=1`` with an ``f`` variant: the simulated
model's lag roots, given (oracle). ``oracle`` mode: the true lag roots and the AR model of the
TRUE residual, on many releases pooled, with the whitened residual's correlation with each
regressor (the consistency condition).

Result (docs/development/e2rfc_turbulence.md, "Iterated GLS"): GLS as proposed is not consistent:
whitened q' and q'' stay correlated with the whitened innovation (0.1-0.15 and 0.2-0.3: velocity and
acceleration respond to the current force at once, and the narrow-band whitened regressors
carry little variance beside the broad-band innovation), flutter speed -99 %, and -58 % with
the true lag roots and noise model, unchanged from 6 to 144 releases. Refined IV with the
noise model iterated from the residual does not converge; with the noise model of a hold
before each release it does (see the doc's table).

Run: ``.venv/bin/python benchmarks/turbulent_gls_experiment.py "ROW;ROW" SEEDS "today;2a3;2"
[WORKERS]``
(a variant ``NaN``: N lags, ``a3`` fit A3, ``f`` lag roots not searched) or
``... oracle ROW N_SEEDS``. Without arguments: the four turbulence rows, seeds 0-3, variants
``today;2;2a3`` (:data:`DEFAULTS`), two workers. ``--quick`` (CI): the plate at 1 % turbulence,
seed 0, the variant ``1`` (one searched lag root), unless given. ``--results DIR`` also writes the
tables to ``DIR/turbulent_gls_experiment.json`` and ``.md`` (``turbulent_gls_experiment_oracle``
for the oracle mode; :mod:`result_files`), with the ``PEM_*`` settings among the parameters.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402
from scipy.signal import butter, lfilter, savgol_filter, sosfilt, sosfiltfilt  # noqa: E402
from scipy.stats import t as student_t  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import ident_accuracy as ia  # noqa: E402
import result_files  # noqa: E402 - beside this script

from ident import Release
from ident.identification import e2rfc
from ident.model import flutter as fl
from ident.model.rfc import RationalFunctionModel
from simulators import simulate_release  # noqa: E402

CAUSAL = os.environ.get("PEM_CAUSAL", "0") == "1"
D_LO = float(os.environ.get("PEM_DLO", "0.5"))
D_HI = float(os.environ.get("PEM_DHI", "1.0"))
DECIM = int(os.environ.get("PEM_DECIM", "10"))
FC = float(os.environ.get("PEM_FC", "3.0"))
D_OBJECTIVE = os.environ.get("PEM_DOBJ", "projected")
#: Largest order of the fixed AR noise models (a hold's or the force's own).
P_MAX = int(os.environ.get("PEM_PMAX", "20"))
#: Fit the fixed AR noise model to each release's own measured force (no hold needed).
NOISE_FROM_FORCE = os.environ.get("PEM_NOISE_FROM_FORCE", "0") == "1"
#: Seconds of hold recorded before each release (0: none); its force gives the noise model.
HOLD_S = float(os.environ.get("PEM_HOLD", "0"))
ORDER = int(os.environ.get("PEM_ORDER", "4"))


class Rel:
    """A release's low-passed, decimated signals."""

    def __init__(self, r, section, fc, hold=None):
        B = section.B
        rho = section.rho if r.rho is None else r.rho
        qd = 0.5 * rho * r.U**2
        q = r.coordinates(B)
        f = r.generalised_forces(B) / (qd * B**2)
        fs = 1.0 / r.dt
        sos = butter(ORDER, fc / (fs / 2), output="sos")
        if CAUSAL:
            # The same causal filter on both sides, from rest (q - q[0], the hold): the
            # regressors stay causal functions of the force, so the whitened innovation is
            # uncorrelated with them (but for the velocity's instantaneous response).
            qf = sosfilt(sos, q - q[0], axis=0) + q[0]
            ff = sosfilt(sos, f - f[0], axis=0) + f[0]
            qdot = np.gradient(qf, r.dt, axis=0)
            qdd = np.gradient(qdot, r.dt, axis=0)
        else:
            qf = sosfiltfilt(sos, q, axis=0)
            ff = sosfiltfilt(sos, f, axis=0)
            win = int(round(0.1 * fs)) | 1  # 0.1 s window, cubic
            qdot = savgol_filter(qf, win, 3, deriv=1, delta=r.dt, axis=0)
            qdd = savgol_filter(qf, win, 3, deriv=2, delta=r.dt, axis=0)
        self.U, self.B, self.dt = r.U, B, r.dt
        self.c = B / r.U
        self.qf, self.qdot = qf, qdot
        trim = int(0.2 * fs)  # filter and SG edge effects
        self.rows = slice(trim, q.shape[0] - trim, DECIM)
        self.fixed = np.hstack([qf, self.c * qdot, self.c**2 * qdd])[self.rows]
        self.force = ff[self.rows]
        # Noise level of each normalised force channel (for the weights): first differences.
        self.w = 1.0 / (np.std(np.diff(f, axis=0), axis=0) / math.sqrt(2))
        self.hold_ar = None
        if NOISE_FROM_FORCE:
            # No hold: the AR model of the release's own measured force (buffeting dominates it
            # in turbulence; the self-excited part is narrow-band at the modes).
            fd = ff[self.rows]
            self.hold_ar = [ar_fit(fd[:, i] - fd[:, i].mean(), P_MAX) for i in range(fd.shape[1])]
        elif hold is not None:
            # The held model's force is buffeting plus noise alone (no motion): its AR model,
            # after the same low-pass and decimation, is the noise model of the release.
            fh = hold / (qd * B**2)
            fh = (sosfiltfilt(sos, fh, axis=0) if not CAUSAL
                  else sosfilt(sos, fh - fh[0], axis=0))[::DECIM]
            self.hold_ar = [ar_fit(fh[:, i] - fh[:, i].mean(), P_MAX)
                            for i in range(fh.shape[1])]

    def lags(self, d):
        cols = []
        for d_l in d:
            mu = self.U / self.B * d_l
            a = math.exp(-mu * self.dt)
            # x' = q' - mu x from x(0) = 0, trapezoidal on q' (exact enough at 500 Hz).
            x = lfilter([self.dt / 2, self.dt / 2], [1.0, -a], self.qdot, axis=0)
            cols.append(x[self.rows])
        return np.hstack(cols) if cols else np.zeros((self.force.shape[0], 0))


def ar_fit(e, p_max=20):
    """AR coefficients [1, a1..ap] of a residual, order by BIC (least squares)."""
    e = e - e.mean()
    n = e.size
    best = (n * math.log(float(e @ e) / n), np.array([1.0]))
    for p in range(1, p_max + 1):
        X = np.column_stack([e[p - k - 1:n - k - 1] for k in range(p)])
        y = e[p:]
        a, *_ = np.linalg.lstsq(X, y, rcond=None)
        r = y - X @ a
        bic = y.size * math.log(float(r @ r) / y.size) + p * math.log(y.size)
        if bic < best[0]:
            best = (bic, np.concatenate([[1.0], -a]))
    return best[1]


def design(rels, d, with_A3):
    n = 2
    out = []
    for r in rels:
        fixed = r.fixed if with_A3 else r.fixed[:, :2 * n]
        out.append(np.hstack([fixed, r.lags(d)]))
    return out


IV_DELAYS = tuple(int(x) for x in os.environ.get("PEM_IV", "").split(",") if x)


def solve(rels, Xs, ar):
    """Return the GLS coefficients (k, 2) and the residual vectors the lag-root search minimises.

    Per force channel: whitened (AR per release and channel) and weighted; with IV_DELAYS,
    two-stage least squares with the whitened regressors delayed by those samples as
    instruments (the residual then projected on the instruments).
    """
    k = Xs[0].shape[1]
    coef = np.empty((k, 2))
    res = []
    K = max(IV_DELAYS) if IV_DELAYS else 0
    for i in range(2):
        rows_X, rows_y, rows_Z = [], [], []
        for j, (r, X) in enumerate(zip(rels, Xs, strict=True)):
            a = ar[j][i]
            Z = np.column_stack([X, r.force[:, i]])
            Z = Z - Z.mean(axis=0)
            Zw = lfilter(a, [1.0], Z, axis=0)[a.size - 1:] * r.w[i]
            n = Zw.shape[0]
            rows_X.append(Zw[K:, :k])
            rows_y.append(Zw[K:, k])
            if IV_DELAYS:
                rows_Z.append(np.hstack([Zw[K - L:n - L, :k] for L in IV_DELAYS]))
        X = np.vstack(rows_X)
        y = np.concatenate(rows_y)
        if IV_DELAYS:
            Q, _ = np.linalg.qr(np.vstack(rows_Z))
            Xp = Q @ (Q.T @ X)
            sol, *_ = np.linalg.lstsq(Xp, y, rcond=None)
            coef[:, i] = sol
            # The lag-root search's residual: projected on the instruments (GMM), or the
            # whitened residual of the IV coefficients (prediction error) with PEM_DOBJ=resid.
            res.append(y - X @ sol if D_OBJECTIVE == "resid" else Q.T @ (y - X @ sol))
        else:
            sol, *_ = np.linalg.lstsq(X, y, rcond=None)
            coef[:, i] = sol
            res.append(y - X @ sol)
    return coef, res


def raw_residuals(rels, Xs, coef):
    out = []
    for r, X in zip(rels, Xs, strict=True):
        e = r.force - X @ coef
        out.append(e - e.mean(axis=0))
    return out


def fit(rels, n_lags, with_A3, d0, iters=3, search=True):
    held = all(r.hold_ar is not None for r in rels)
    if held:  # the noise model measured on the held model: no iteration needed
        ar, iters = [r.hold_ar for r in rels], 0
    else:
        ar = [[np.array([1.0]), np.array([1.0])] for _ in rels]
    d = np.asarray(d0, float)
    for it in range(iters + 1):
        if n_lags and search:
            def resid(th, ar=ar):
                _, res = solve(rels, design(rels, np.exp(th), with_A3), ar)
                return np.concatenate(res)
            sol = least_squares(resid, np.log(d), method="trf", x_scale=1.0,
                                bounds=(np.log(1e-3), np.log(20.0)))
            d = np.exp(sol.x)
        Xs = design(rels, d, with_A3)
        coef, _ = solve(rels, Xs, ar)
        if it < iters:
            ar = [[ar_fit(e[:, i]) for i in range(2)] for e in raw_residuals(rels, Xs, coef)]
    terms = ([0, 1, 2] if with_A3 else [0, 1]) + [3 + l for l in range(n_lags)]
    A = np.zeros((3 + n_lags, 2, 2))
    for i in range(2):
        for col, (term, j) in enumerate((t, j) for t in terms for j in range(2)):
            A[term, i, j] = coef[col, i]
    return RationalFunctionModel(A, d), ar


def releases_with_holds(row, seed, pre_s):
    """Simulate the tunnel row's releases with a hold of ``pre_s`` s before each release.

    Returns the releases (t >= 0) and the held records' generalised forces (N m/m).
    """
    section, make_model, static, Iw, _ = ia.TUNNEL_ROWS[row]
    model = make_model()
    U_F = fl.analyze(section, model).speed
    wind = {} if not Iw else {"static": static, "turbulence": ia.vertical_gusts(Iw), "span": 1.0}
    releases, holds = [], []
    for i, f in enumerate(ia.E2RFC_SPEEDS):
        for j, (h0, alpha0) in enumerate(ia.HOLDS):
            sim = simulate_release(section, model, f * U_F, h0, alpha0, duration=20.0, fs=500.0,
                                   noise=0.02, rng=(seed, i, j, int(1000 * Iw)), pre_s=pre_s,
                                   **wind)
            releases.append(Release.from_simulation(sim))
            before = sim.t < 0.0
            holds.append(np.column_stack([sim.lift[before] * section.B, sim.moment[before]]))
    return releases, holds


def flutter_speed(section, model, U_max):
    try:
        s = fl.analyze(section, model, U_max, n_points=150).speed
    except (fl.StillAirModesError, ValueError):
        return U_max
    return U_max if s is None else float(s)


def pem(releases, section, n_lags, with_A3, d0, search=True, holds=None):
    fc = FC * max(section.fh, section.fa)
    holds = holds or [None] * len(releases)
    rels = [Rel(r, section, fc, h) for r, h in zip(releases, holds, strict=True)]
    if d0 is None:  # fixed lag roots spread over the covered reduced frequencies
        K = [2 * math.pi * f * section.B / r.U for r in releases for f in (section.fh, section.fa)]
        d0 = np.geomspace(min(K) * D_LO, max(K) * D_HI, n_lags)
    model, _ = fit(rels, n_lags, with_A3, d0, search=search)
    try:
        res = fl.analyze(section, model)
    except (fl.StillAirModesError, ValueError):
        return None, math.nan, model
    U_max = res.U_max
    speed = U_max if res.speed is None else float(res.speed)
    pseudo = []
    for j in range(len(rels)):
        others = rels[:j] + rels[j + 1:]
        m, _ = fit(others, n_lags, with_A3, model.d, iters=2, search=search)
        pseudo.append(flutter_speed(section, m, U_max))
    pseudo = np.array(pseudo)
    n = pseudo.size
    jack = math.sqrt((n - 1) / n * np.sum((pseudo - pseudo.mean()) ** 2))
    jack *= student_t.ppf(0.975, n - 1) / 1.96
    return (None if res.speed is None else speed), jack, model


def run(args):
    try:
        return _run(args)
    except Exception as exc:  # noqa: BLE001 - report and go on (scratch)
        return (*args, math.nan, math.nan, 0.0, f"failed: {exc!r}"[:80])


def _run(args):
    row, seed, variant = args
    section, make_model, _, _, truth = ia.TUNNEL_ROWS[row]
    U_F = truth() if truth is not None else fl.analyze(section, make_model()).speed
    holds = None
    if HOLD_S:
        releases, holds = releases_with_holds(row, seed, HOLD_S)
    else:
        releases = ia.tunnel_releases(row, seed, hold_s=0.0)
    t0 = time.perf_counter()
    if variant == "today":
        model = e2rfc.identify(releases, section)
        u = model.uncertainty(section)
        s, std = u.speed, u.total
        diag = model.diagnostics
        info = f"lags={diag.n_lags} A3={diag.with_A3} turb={diag.turbulent}"
    else:
        n_lags, a3, fixed = variant
        d0 = None if fixed else (np.geomspace(0.1, 1.0, n_lags) if n_lags else np.zeros(0))
        if fixed and os.environ.get("PEM_TRUTH_D") == "1":  # oracle: the simulated model's roots
            d0 = make_model().d[:n_lags]
        s, std, m = pem(releases, section, n_lags, a3, d0, search=not fixed, holds=holds)
        info = f"d={np.round(m.d, 3)}"
    el = time.perf_counter() - t0
    err = math.inf if s is None else s / U_F - 1
    return row, seed, variant, err, std / U_F if s is not None else math.nan, el, info


def oracle(row, n_seeds):
    """GLS with the true lag roots and the true residual's AR model, on pooled releases.

    Return the correlation rows (U, then one per regressor) and the flutter-speed error (%).
    """
    section, make_model, _, _, truth = ia.TUNNEL_ROWS[row]
    model = make_model()
    U_F = truth() if truth is not None else fl.analyze(section, model).speed
    raw = [r for s in range(100, 100 + n_seeds) for r in ia.tunnel_releases(row, s, hold_s=0.0)]
    rels = [Rel(r, section, FC * max(section.fh, section.fa)) for r in raw]
    terms = [0, 1, 2] + [3 + l for l in range(model.d.size)]
    coef_true = np.zeros((2 * len(terms), 2))
    for i in range(2):
        for col, (term, j) in enumerate((t, j) for t in terms for j in range(2)):
            coef_true[col, i] = model.A[term, i, j]
    Xs = design(rels, model.d, True)
    res = raw_residuals(rels, Xs, coef_true)
    ar = [[ar_fit(e[:, i]) for i in range(2)] for e in res]
    names = ["h", "a", "h'", "a'", "h''", "a''"] + [f"x{l}{c}" for l in range(model.d.size)
                                                     for c in "ha"]
    correlations = []
    for j in (0, 2, 4):  # the first seed at 0.4, 0.6 and 0.8 U_F
        a = ar[j][0]
        ew = lfilter(a, [1.0], res[j][:, 0])[a.size:]
        Xw = lfilter(a, [1.0], Xs[j], axis=0)[a.size:]
        corr = [np.corrcoef(ew, Xw[:, c])[0, 1] for c in range(Xw.shape[1])]
        correlations.append((rels[j].U, *corr))
        print(f"U {rels[j].U:.2f} m/s: corr(whitened lift residual, whitened regressor) "
              + ", ".join(f"{n} {c:+.2f}" for n, c in zip(names, corr, strict=True)))
    coef, _ = solve(rels, Xs, ar)
    found = RationalFunctionModel(np.array([[[coef[c * 2 + j, i] for j in range(2)]
                                             for i in range(2)] for c in range(len(terms))]),
                                  model.d)
    speed = flutter_speed(section, found, 4 * U_F)
    print(f"{len(rels)} releases, true lag roots and noise model: flutter-speed error "
          f"{100 * (speed / U_F - 1):+.1f} % (U_max counts as no flutter)")
    return names, correlations, len(rels), 100 * (speed / U_F - 1)


#: The run without arguments (the table's GLS row of docs/development/e2rfc_turbulence.md):
#: rows, seeds, variants; and what ``--quick`` runs instead.
DEFAULTS = ("plate, Jones, Iw 1 %;plate, Jones, Iw 3 %;bluff deck, Iw 1 %;bluff deck, Iw 3 %",
            "0,1,2,3", "today;2;2a3")
QUICK = ("plate, Jones, Iw 1 %", "0", "1")


def settings():
    """Return the ``PEM_*`` settings this process runs with (the result file's parameters)."""
    return {"PEM_CAUSAL": CAUSAL, "PEM_DLO": D_LO, "PEM_DHI": D_HI, "PEM_DECIM": DECIM,
            "PEM_FC": FC, "PEM_DOBJ": D_OBJECTIVE, "PEM_PMAX": P_MAX,
            "PEM_NOISE_FROM_FORCE": NOISE_FROM_FORCE, "PEM_HOLD": HOLD_S, "PEM_ORDER": ORDER,
            "PEM_IV": ",".join(str(d) for d in IV_DELAYS) or "none",
            "PEM_TRUTH_D": os.environ.get("PEM_TRUTH_D") == "1"}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rows", nargs="?", default=None,
                        help='tunnel rows, "ROW;ROW" (ident_accuracy.TUNNEL_ROWS), or "oracle"')
    parser.add_argument("seeds", nargs="?", default=None,
                        help="seeds, comma-separated (oracle: the row)")
    parser.add_argument("variants", nargs="?", default=None,
                        help='"today;2a3;2": N lags, a3 fit A3, f lag roots not searched '
                             "(oracle: the number of seeds pooled)")
    parser.add_argument("workers", nargs="?", type=int, default=2, help="processes (2)")
    result_files.add_arguments(parser)
    args = parser.parse_args()
    if args.rows == "oracle":
        if args.seeds is None or args.variants is None:
            parser.error("oracle needs a row and a number of seeds: oracle ROW N_SEEDS")
        _oracle(args)
        return
    defaults = QUICK if args.quick else DEFAULTS
    rows_text, seeds_text, variants_text = (given if given is not None else default
                                            for given, default in zip(
                                                (args.rows, args.seeds, args.variants), defaults,
                                                strict=True))
    rows = rows_text.split(";")
    unknown = [r for r in rows if r not in ia.TUNNEL_ROWS]
    if unknown:
        parser.error(f"unknown rows {unknown}; ident_accuracy.TUNNEL_ROWS has "
                     f"{list(ia.TUNNEL_ROWS)}")
    seeds = [int(x) for x in seeds_text.split(",")]
    variants = []
    for v in variants_text.split(";"):
        variants.append("today" if v == "today" else (int(v[0]), "a3" in v, v.endswith("f")))
    labels = dict(zip(variants, variants_text.split(";"), strict=True))
    jobs = [(r, s, v) for r in rows for s in seeds for v in variants]
    runs = []
    with ProcessPoolExecutor(args.workers) as pool:
        for row, seed, variant, err, std, el, info in pool.map(run, jobs):
            print(f"{row:<24} seed {seed:2d} {str(variant):<14} err {100 * err:8.2f} % "
                  f"std {100 * std:8.2f} %  {el:6.1f} s  {info}", flush=True)
            outcome = ("failed" if info.startswith("failed") else
                       "no flutter" if math.isinf(err) else "flutter")
            runs.append((row, seed, labels[variant], outcome,
                         100 * err if math.isfinite(err) else None,
                         100 * std if math.isfinite(std) else None, el, info))
    summary = []
    for row in rows:
        for label in labels.values():
            mine = [r for r in runs if r[0] == row and r[2] == label]
            # No flutter counts as an infinite error; a failed run has none.
            err = [abs(r[4]) if r[3] == "flutter" else math.inf for r in mine
                   if r[3] != "failed"]
            summary.append((row, label, len(mine), sum(r[3] == "flutter" for r in mine),
                            sum(r[3] == "no flutter" for r in mine),
                            sum(r[3] == "failed" for r in mine),
                            float(np.median(err)) if err else None,
                            float(np.median([r[6] for r in mine]))))
    tables = [
        result_files.Table(
            "Per row and variant (today = E2RFC as it ships; N = GLS with N lags, a3 = A3 "
            "fitted, f = lag roots not searched): the runs, those that found a flutter speed, "
            "found none below the searched speeds or failed, the median absolute error (no "
            "flutter counted as infinite) and the median time.",
            ("row", "variant", "runs", "flutter", "no flutter", "failed",
             "median error (%)", "median time (s)"),
            summary, formats={"median error (%)": ".1f", "median time (s)": ".1f"}),
        result_files.Table(
            "Every run: the flutter speed's signed error and its jackknife (or E2RFC's) std as "
            "shares of the truth, the time of identification plus std, and what was found "
            "(structure or lag roots).",
            ("row", "seed", "variant", "outcome", "error (%)", "std (%)", "time (s)", "found"),
            runs, formats={"error (%)": "+.2f", "std (%)": ".2f", "time (s)": ".1f"}),
    ]
    warnings = [f"{row} seed {seed} variant {label}: {info}"
                for row, seed, label, outcome, *_, info in runs if outcome == "failed"]
    result_files.write(
        "turbulent_gls_experiment", "Iterated GLS and refined IV of E2RFC in turbulence "
        "(an experiment, dropped)", tables, results=args.results, quick=args.quick,
        script="turbulent_gls_experiment",
        parameters={"rows": rows, "seeds": seeds, "variants": list(labels.values()),
                    "workers": args.workers, **settings()},
        notes=["Each tunnel row's releases as ident_accuracy.py draws them, without holds "
               "unless PEM_HOLD is set; the settings of the estimator are the PEM_* "
               "parameters."],
        warnings=warnings)


def _oracle(args):
    """Run the oracle mode and write its tables."""
    row, n_seeds = args.seeds, int(args.variants)
    names, correlations, n_releases, error = oracle(row, n_seeds)
    tables = [
        result_files.Table(
            f"Oracle, {row}: the correlation of the whitened lift residual with each whitened "
            "regressor, for the first seed's release at each wind speed.",
            ("U (m/s)", *(f"corr {n}" for n in names)), correlations,
            formats={"U (m/s)": ".2f", **{f"corr {n}": "+.2f" for n in names}}),
        result_files.Table(
            f"Oracle, {row}: GLS with the true lag roots and the true residual's AR model on "
            "pooled releases; the flutter speed's error (no flutter counts as the searched "
            "top speed).",
            ("releases", "error (%)"), [(n_releases, error)], formats={"error (%)": "+.1f"}),
    ]
    result_files.write(
        "turbulent_gls_experiment_oracle", "Iterated GLS in turbulence: the oracle", tables,
        results=args.results, quick=args.quick, script="turbulent_gls_experiment",
        parameters={"row": row, "seeds pooled": n_seeds, **settings()})


if __name__ == "__main__":
    main()
