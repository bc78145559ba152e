"""Accuracy and speed of E2RFC against the indirect flutter-derivative route (not a test).

For two sections (the flat-plate demo section, and a heavier deck with another mass and frequency
ratio), both with flat-plate aerodynamics (Jones's exact Roger model, so the truth is known in
closed form), releases are simulated by ``simulators.tunnel`` from (4 mm, 0.02 rad), 20 s at
500 Hz, with Gaussian noise of 0, 2 and 5 % of each channel's RMS on all four channels:

- E2RFC: 3 wind speeds (0.4, 0.6, 0.8 of the true flutter speed), structure chosen by evidence;
- FD route (``ident.identification.fd_method``): 10 wind speeds from 0.3 to 0.85 of the flutter
speed;
- E2RFC raw: the ablation of E2RFC's noise design (regressors differentiated from the noisy
  displacements instead of computed from the modal fit), 3 wind speeds.

Printed per case: flutter-speed error (median and 90th percentile of |error| over the seeds),
flutter-derivative error over the reduced frequencies the releases cover (mean over the eight
derivatives of max |error| / max |true|), median identification time, and for E2RFC the median of
|error| / predicted standard deviation (1 means honest error bars). A final table times E2RFC on
5 releases of 30 s at 500 Hz.

A second part, "in a real tunnel" (``--part tunnel``), asks whether E2RFC holds where its model is
not exact and the flow not smooth: 3 wind speeds (0.4/0.6/0.8 U_F) x 2 releases (two holds),
20 s at 500 Hz, 2 % noise, on

- the flat plate with Jones's aerodynamics (exactly Roger's form) and the deck section with it;
- the exact-Theodorsen flat plate (an eight-lag fit of Theodorsen's function; truth from the
  frequency-domain analysis with the exact flutter derivatives);
- the bluff deck of :mod:`simulators.decks` (its entries have lags of their own: ten in all);
- vertical turbulence of 1 % and 3 % (von Karman, 0.3 m length scale, span-wise coherence over a
  1 m span, quasi-steady buffeting from the static coefficients) on the plate and on the bluff
  deck.

The turbulence rows' releases are recorded with a hold of ``TUNNEL_HOLD_S`` (10 s) before each
(a real release always has one: the operator holds the model in the wind before letting go);
E2RFC then runs its turbulence branch (refined IV with the holds' noise model,
``ident.identification._turbulent_fit``). ``--tunnel-mode before`` identifies the same releases with
their holds taken away (today's estimator), ``both`` prints the two; ``--rows turbulent|clean``
runs a subset, ``--rows variants`` the turbulence rows changed in one thing (:data:`VARIANT_ROWS`)
and ``--rows sections`` those on sections the closed-loop branch was not developed on
(:data:`SECTION_ROWS`);
``--turbulent-motion filter|smoother|smoother-sg`` selects how the branch builds its regressors'
motion (``ident.identification._turbulent_fit.MOTION``; docs/development/e2rfc_turbulence.md
measures the three); ``--turbulent-estimator ml`` runs the closed-loop maximum-likelihood branch
instead (``ident.identification.closed_loop_ml``; with and without holds), and
``--closed-loop-buffeting fourth-order`` its two-section buffeting model on exact block means
(``e2rfc.CLOSED_LOOP_BUFFETING``). The "branch" column
counts the identifications the turbulence branch (either) ran.

Printed per row: the median and 90th percentile of |error| (beside the median, that of an
estimator at the Cramer-Rao bound of the row's own releases, :func:`row_bound`, to first order
and over coefficients drawn from the bound's covariance, and the ratios; n/a in smooth flow,
and the sampled one where the draws leave the section's models), the coverage of the 2-std interval
(``IdentifiedModel.flutter``'s std: noise, structure, extrapolation, one lag more, release
scatter, below a decaying release; on the tunnel rows ``FlutterUncertainty.interval``, drawn
in the log of the distance beyond the highest speed the releases show stable, and the
estimate +- 2 std beside it), the median std, the median time of identification plus
uncertainty, and the count of identifications without flutter below the searched speeds
(counted as not covered); then, over all rows, the coverage and the median of every error
over its own row's first-order bound median (:func:`bound_note` says how far that pooled
ratio scatters for an estimator at the bound). ``benchmarks/flutter_crb.py`` gives
the Cramer-Rao bound on its own; docs/development/e2rfc_turbulence.md the table before
and after, and the estimators tried.

Run: ``.venv/bin/python benchmarks/ident_accuracy.py [--seeds 20] [--workers 2] [--part all]
[--tunnel-mode after|before|both] [--rows all|turbulent|clean]``;
``--part timing [--repeats 9]`` prints only the timing table. BLAS is kept single-threaded in
every process, so the times are one-core times. The timing table gives wall and CPU time
(``time.process_time``), minimum and median over the repeats: the host is shared, and the CPU
time is what the identification itself costs (docs/development/e2rfc_speed.md: the times before and
after the speed work, and what it changed).

``--quick`` (CI): one seed, one timed repeat; of the tunnel rows the first clean and the first
turbulent one of those asked (all of them with an explicit ``--rows``); of the smooth rows the
flat plate at 2 % noise; the ablation on the plate. ``--results DIR`` also writes the tables to
``DIR/<name>.json`` and ``.md`` (:mod:`result_files`): ``ident_accuracy`` for the default run,
else the name says what ran: ``ident_accuracy_<part>[_<rows>][_<estimator>]...`` (only the
options that differ from the defaults, :func:`result_name`; ``--part tunnel --rows turbulent
--tunnel-mode both``: ``ident_accuracy_tunnel_turbulent``, both modes' tables in it; with
``--seeds 40``, ``..._seeds40``).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: one-core timings
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import math  # noqa: E402
import re  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from functools import partial  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.signal import lfilter  # noqa: E402
from tqdm import tqdm  # noqa: E402

from ident import Release, SectionModel
from ident.identification import _turbulent_fit, closed_loop_ml, e2rfc
from ident.identification._e2rfc_turbulence import bounded_at
from ident.identification._regressors import PreparedRelease, RegressorView, prepare
from ident.identification.modal import fit_modes
from ident.identification.uncertainty import FlutterUncertainty
from ident.model import flat_plate
from ident.model import flutter as fl
from ident.model.conventions import FLUTTER_DERIVATIVE_NAMES
from ident.model.quasi_steady import StaticCoefficients
from ident.physics.turbulence import TurbulenceSpec
from simulators import simulate_release  # noqa: E402
from simulators.campaigns import scaled  # noqa: E402
from simulators.decks import BLUFF_DECK, BLUFF_DECK_STATIC, bluff_deck_model  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import flutter_crb  # noqa: E402 - beside this script
import result_files  # noqa: E402 - beside this script

SECTIONS = {
    "flat plate (mu 35, fa/fh 2.0)": SectionModel(
        B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005),
    "deck (mu 41, fa/fh 3.0)": SectionModel(
        B=0.45, m=8.0, I=0.16, fh=1.2, fa=3.6, zeta_h=0.003, zeta_a=0.003),
}
TRUTH = flat_plate.jones_model()
NOISES = (0.0, 0.02, 0.05)
E2RFC_SPEEDS = (0.4, 0.6, 0.8)
FD_SPEEDS = tuple(np.linspace(0.3, 0.85, 10))
#: The turbulence branch's options as imported (``one_run`` restores them in a shared worker).
TURBULENT_DEFAULTS = (e2rfc.TURBULENT_A3, _turbulent_fit.MOTION, e2rfc.TURBULENT_ESTIMATOR,
                      e2rfc.CLOSED_LOOP_BUFFETING)
#: "E2RFC raw" is the ablation of the noise design: the same estimator with regressors built from
#: the measured displacements by central differences instead of from the modal fit.
METHODS = ("E2RFC", "E2RFC raw", "FD route")


def make_releases(section, U_F, fractions, noise, seed, duration=20.0):
    return [
        Release.from_simulation(simulate_release(
            section, TRUTH, f * U_F, 0.004, 0.02, duration=duration, fs=500.0, noise=noise,
            rng=(seed, i, int(1000 * noise))))
        for i, f in enumerate(fractions)
    ]


@dataclass(frozen=True, eq=False)
class _RawView(RegressorView):
    """Regressors from the measured displacements themselves (the naive construction)."""

    q: np.ndarray = None  # full-rate measured q
    rows: slice = None

    def lag_columns(self, d):
        dt = float(self.t[1] - self.t[0]) / (self.rows.step or 1)
        columns = []
        for d_l in d:
            # Exact first-order recursion for piecewise-linear q, from x = 0 at the release.
            mu = self.rate * d_l
            a = np.exp(-mu * dt)
            g = (1 - a) / (mu * dt)
            columns.append(lfilter([g, -g], [1.0, -a], self.q - self.q[0], axis=0)[self.rows])
        return np.hstack(columns) if columns else np.zeros((self.t.size, 0))

    def lag_derivatives(self, d):
        """Return the lag columns' derivatives in log d (central differences, step 1e-6)."""
        d = np.asarray(d, dtype=float)
        columns = []
        for l in range(d.size):
            up, down = d.copy(), d.copy()
            up[l] *= np.exp(1e-6)
            down[l] *= np.exp(-1e-6)
            columns.append((self.lag_columns(up)[:, 2 * l:2 * l + 2]
                            - self.lag_columns(down)[:, 2 * l:2 * l + 2]) / 2e-6)
        return np.hstack(columns) if columns else np.zeros((self.t.size, 0))


@dataclass(frozen=True, eq=False)
class _RawPrepared(PreparedRelease):
    """A release whose regressors differentiate the noisy displacements (central differences)."""

    q: np.ndarray = None

    def view(self, which):
        if which not in self._views:
            rows = slice(None) if which == "full" else self.search_rows()
            self._views[which] = _RawView(
                t=self.release.t[rows], fixed=self.fixed[rows], force=self.force[rows],
                exponentials=None, fit=self.fit, rate=self.U / self.B, q=self.q, rows=rows)
        return self._views[which]


def identify_raw(releases, section):
    """E2RFC with naive regressors: same estimator, displacements differentiated directly."""
    prepared = []
    for r in releases:
        p = prepare(r, section)
        q = np.column_stack([r.h / section.B, r.alpha])
        qd = np.gradient(q, r.dt, axis=0)
        c = section.B / r.U
        fixed = np.hstack([q - q.mean(axis=0), c * qd, c**2 * np.gradient(qd, r.dt, axis=0)])
        prepared.append(_RawPrepared(release=r, fit=p.fit, B=p.B, qd=p.qd, fixed=fixed,
                                     force=p.force, force_noise=p.force_noise, q=q))
    return e2rfc._identify_prepared(prepared, section, None, None)


def fd_error(section, model, releases):
    """Mean over the eight derivatives of max |error| / max |true| on the covered K range."""
    K = [2 * np.pi * fr * section.B / r.U for r in releases
         for fr in fit_modes(r.t, np.column_stack([r.h / section.B, r.alpha])).frequencies]
    grid = np.linspace(min(K), max(K), 50)
    true, found = TRUTH.flutter_derivatives(grid), model.flutter_derivatives(grid)
    return float(np.mean([np.abs(found[n] - true[n]).max() / np.abs(true[n]).max()
                          for n in FLUTTER_DERIVATIVE_NAMES]))


def one_run(args):
    # A worker that ran tunnel jobs before holds their turbulence options: back to the defaults
    # (smooth releases do not reach the turbulence branch, but a fresh worker would have them).
    (e2rfc.TURBULENT_A3, _turbulent_fit.MOTION, e2rfc.TURBULENT_ESTIMATOR,
     e2rfc.CLOSED_LOOP_BUFFETING) = TURBULENT_DEFAULTS
    section_name, method, noise, seed = args
    section = SECTIONS[section_name]
    U_F = fl.analyze(section, TRUTH).speed
    fractions = FD_SPEEDS if method == "FD route" else E2RFC_SPEEDS
    releases = make_releases(section, U_F, fractions, noise, seed)
    start = time.perf_counter()
    if method == "E2RFC":
        model = e2rfc.identify(releases, section)
    elif method == "E2RFC raw":
        model = identify_raw(releases, section)
    else:
        from ident.identification import fd_method

        model = fd_method.identify(releases, section)
    elapsed = time.perf_counter() - start
    if method.startswith("E2RFC"):
        result, std = model.flutter(section)
    else:
        result, std = fl.analyze(section, model), None
    error = np.inf if result.speed is None else result.speed / U_F - 1.0
    z = abs(error) * U_F / std if std else np.nan  # error is relative, std in m/s
    return section_name, method, noise, error, fd_error(section, model, releases), elapsed, z


def timing(section, repeats=9):
    """Time E2RFC on 5 releases of 30 s at 500 Hz; per structure option, CPU and wall times.

    The host is shared: wall time counts what other processes take from this one, the CPU time
    of this process (``time.process_time``, one BLAS thread) does not. Each is repeated
    ``repeats`` times after one untimed warm-up; the minimum is the least disturbed run, the
    median the typical one.
    """
    U_F = fl.analyze(section, TRUTH).speed
    releases = make_releases(section, U_F, (0.4, 0.5, 0.6, 0.7, 0.8), 0.02, 0, duration=30.0)
    rows = []
    for label, kwargs in (("structure chosen by evidence", {}),
                          ("structure given (2 lags, A3)", {"n_lags": 2, "with_A3": True})):
        e2rfc.identify(releases, section, **kwargs)  # warm-up: imports, caches of numpy
        wall, cpu = [], []
        for _ in range(repeats):
            start, start_cpu = time.perf_counter(), time.process_time()
            e2rfc.identify(releases, section, **kwargs)
            cpu.append(time.process_time() - start_cpu)
            wall.append(time.perf_counter() - start)
        rows.append((label, float(np.min(wall)), float(np.median(wall)), float(np.min(cpu)),
                     float(np.median(cpu))))
    return rows


def timing_part(repeats):
    """Print the timing table (``--part timing``, and the end of ``--part classic``); return it."""
    print(f"\nE2RFC time, 5 releases of 30 s at 500 Hz (2 % noise), one core (BLAS single-"
          f"threaded); {repeats} runs after a warm-up, min and median; wall = elapsed, CPU = "
          "this process's CPU time (the host is shared: CPU time is what the code costs):")
    header = f"  {'':<30}{'wall min':>10}{'wall med':>10}{'CPU min':>10}{'CPU med':>10}"
    print(header)
    rows = timing(SECTIONS["flat plate (mu 35, fa/fh 2.0)"], repeats)
    for label, wall_min, wall_med, cpu_min, cpu_med in rows:
        print(f"  {label:<30}{wall_min:>9.3f}s{wall_med:>9.3f}s{cpu_min:>9.3f}s{cpu_med:>9.3f}s")
    columns = ("structure", "wall min (s)", "wall median (s)", "CPU min (s)", "CPU median (s)")
    return result_files.Table(
        f"E2RFC's time on 5 releases of 30 s at 500 Hz (flat plate, 2 % noise), one core, "
        f"minimum and median of {_count(repeats, 'run')} after a warm-up: wall time and this "
        "process's CPU time.", columns, rows, formats=dict.fromkeys(columns[1:], ".3f"))


# -- E2RFC in a real tunnel ----------------------------------------------------------------------
PLATE = SECTIONS["flat plate (mu 35, fa/fh 2.0)"]
DECK = SECTIONS["deck (mu 41, fa/fh 3.0)"]
HOLDS = ((0.004, 0.02), (-0.003, 0.012))


def vertical_gusts(Iw):
    """Vertical turbulence of intensity Iw: von Karman, 0.3 m scale, coherence decay 8."""
    return TurbulenceSpec(Iu=0.0, Iw=Iw, Lux=1.0, Lwx=0.3, Cuy=10.0, Cwy=8.0)


def _theodorsen_truth():
    return fl.frequency_domain(PLATE, flat_plate.flutter_derivatives).speed


#: name -> (section, simulated model, static coefficients, Iw, truth function)
TUNNEL_ROWS = {
    "plate, Jones": (PLATE, flat_plate.jones_model, None, 0.0, None),
    "deck, Jones": (DECK, flat_plate.jones_model, None, 0.0, None),
    "plate, exact Theodorsen": (PLATE, flat_plate.theodorsen_model, None, 0.0, _theodorsen_truth),
    "bluff deck": (BLUFF_DECK, bluff_deck_model, None, 0.0, None),
    "plate, Jones, Iw 1 %": (PLATE, flat_plate.jones_model, StaticCoefficients.flat_plate(),
                             0.01, None),
    "plate, Jones, Iw 3 %": (PLATE, flat_plate.jones_model, StaticCoefficients.flat_plate(),
                             0.03, None),
    "bluff deck, Iw 1 %": (BLUFF_DECK, bluff_deck_model, BLUFF_DECK_STATIC, 0.01, None),
    "bluff deck, Iw 3 %": (BLUFF_DECK, bluff_deck_model, BLUFF_DECK_STATIC, 0.03, None),
}


#: Seconds of hold recorded before each release of the turbulence rows (issue 16).
TUNNEL_HOLD_S = 10.0

#: Rows that change one thing of a turbulence row (issue 38's robustness and information
#: rows): name -> (the row, its change). ``per_speed``: releases per wind speed (the holds
#: alternate; the first two at each speed are the row's own); ``gusts``: fields of the
#: turbulence spec replaced (an admittance and a larger scale give a force spectrum that the
#: closed-loop fit's second-order shaping filter matches worse than von Karman's at 0.3 m;
#: skewness and kurtosis give non-Gaussian gusts); ``effects``: physics the estimators do not
#: model, at the strength of ``simulators.campaigns.REALISTIC`` (the same plate).
VARIANT_ROWS = {
    "plate, Iw 1 %, 8 releases": ("plate, Jones, Iw 1 %", {"per_speed": 8}),
    "plate, Iw 1 %, Davenport, 1 m": ("plate, Jones, Iw 1 %",
                                      {"gusts": {"Lwx": 1.0, "admittance": "davenport"}}),
    "plate, Iw 1 %, non-Gaussian": ("plate, Jones, Iw 1 %",
                                    {"gusts": {"skewness": 0.5, "kurtosis": 4.5}}),
    "plate, Iw 1 %, friction": ("plate, Jones, Iw 1 %", {"effects": ("coulomb_friction",)}),
}


#: A section of lower frequencies and a wider chord than the plate's (mu 25, fa/fh 2.2).
LOW_FREQUENCY = SectionModel(B=0.45, m=6.0, I=0.1, fh=1.2, fa=2.6, zeta_h=0.004, zeta_a=0.004)

#: Turbulence rows on sections the closed-loop branch was not developed on (``--rows
#: sections``): the plate's aerodynamics (Jones) and gusts on the smooth rows' deck and on
#: :data:`LOW_FREQUENCY`, whose modes sit elsewhere against the gusts' spectrum and whose
#: releases hold fewer cycles. ``section`` and ``Iw`` replace the row's own.
SECTION_ROWS = {
    "deck (mu 41), Iw 1 %": ("plate, Jones, Iw 1 %", {"section": DECK}),
    "deck (mu 41), Iw 3 %": ("plate, Jones, Iw 3 %", {"section": DECK}),
    "low-frequency, Iw 2 %": ("plate, Jones, Iw 1 %", {"section": LOW_FREQUENCY, "Iw": 0.02}),
}

#: The ``--rows`` choices whose rows change a turbulence row: choice -> its rows.
CHANGED_ROWS = {"variants": VARIANT_ROWS, "sections": SECTION_ROWS}


def row_spec(row):
    """Return the row's section, model maker, static coefficients, Iw, truth and change."""
    for changed in CHANGED_ROWS.values():
        if row in changed:
            base, change = changed[row]
            section, make_model, static, Iw, truth = TUNNEL_ROWS[base]
            return (change.get("section", section), make_model, static,
                    change.get("Iw", Iw), truth, change)
    return (*TUNNEL_ROWS[row], {})


def tunnel_releases(row, seed, hold_s=TUNNEL_HOLD_S):
    """Simulate the row's releases; in turbulence each with a hold of ``hold_s`` before it.

    The clean rows are drawn without a hold, exactly as before the holds were added (a hold
    changes the noise draws, and in smooth flow E2RFC does not use it). ``hold_s=0`` gives the
    turbulence rows' releases as drawn before issue 16's holds.
    """
    section, make_model, static, Iw, _, change = row_spec(row)
    model = make_model()
    U_F = fl.analyze(section, model).speed
    gusts = dataclasses.replace(vertical_gusts(Iw), **change.get("gusts", {}))
    wind = {} if not Iw else {"static": static, "turbulence": gusts, "span": 1.0,
                              "pre_s": hold_s}
    effects = [scaled(name, 1.0) for name in change.get("effects", ())]
    holds = [HOLDS[j % len(HOLDS)] for j in range(change.get("per_speed", len(HOLDS)))]
    return [
        Release.from_simulation(simulate_release(
            section, model, f * U_F, h0, alpha0, duration=20.0, fs=500.0, noise=0.02,
            rng=(seed, i, j, int(1000 * Iw)), effects=effects, **wind))
        for i, f in enumerate(E2RFC_SPEEDS) for j, (h0, alpha0) in enumerate(holds)
    ]


def tunnel_run(args):
    """One tunnel identification; an exception is reported as a failed row, not raised."""
    try:
        return _tunnel_run(args)
    except Exception as exc:  # noqa: BLE001 - a benchmark reports every failure and goes on
        row, seed, mode, *_ = args
        print(f"FAILED {row} seed {seed} {mode}: {exc!r}", flush=True)
        return row, mode, np.inf, np.nan, np.nan, False, seed, False, (np.nan, np.nan)


def _tunnel_run(args):
    row, seed, mode, a3, motion, estimator, buffeting = args
    e2rfc.TURBULENT_A3 = a3  # the turbulence branch's A3 option (set in each worker)
    _turbulent_fit.MOTION = motion  # and how its regressors' motion is estimated
    e2rfc.TURBULENT_ESTIMATOR = estimator  # and which estimator it runs
    e2rfc.CLOSED_LOOP_BUFFETING = buffeting  # and the closed-loop branch's buffeting model
    section, make_model, _, _, truth, _ = row_spec(row)
    U_F = truth() if truth is not None else fl.analyze(section, make_model()).speed
    releases = tunnel_releases(row, seed)
    if mode == "before":  # today's estimator: the same releases without their holds
        releases = [dataclasses.replace(r, hold=None) for r in releases]
    start = time.perf_counter()
    model = e2rfc.identify(releases, section)
    uncertainty = model.uncertainty(section)
    elapsed = time.perf_counter() - start
    branch = model.diagnostics.estimator in (e2rfc.ESTIMATOR_TURBULENT,
                                             e2rfc.ESTIMATOR_CLOSED_LOOP)
    # The closed-loop branch's note names its buffeting model (chosen by evidence or not).
    fourth = re.search(r"fourth-order[-a-z]* buffeting model",
                       model.diagnostics.reason) is not None
    if uncertainty.speed is None:
        return row, mode, np.inf, np.nan, elapsed, branch, seed, fourth, (np.nan, np.nan)
    low, high = uncertainty.interval()
    return (row, mode, uncertainty.speed / U_F - 1.0, uncertainty.total / U_F, elapsed, branch,
            seed, fourth, (low / U_F - 1.0, high / U_F - 1.0))


#: Median of a half-normal error over its std: an estimator at the bound has this median error.
HALF_NORMAL_MEDIAN = 0.6745


def row_bound(row, samples=flutter_crb.SAMPLES):
    """Return the median error (share of U_F) of an estimator at the Cramer-Rao bound, per mode.

    ``{"before": (first, sampled), "after": (first, sampled)}``: to first order (a half-normal
    error of the bound's std) and over ``samples`` draws of the coefficients from the bound's
    covariance (``flutter_crb.sampled_median``: the flutter speed is not linear in them over
    that spread). The bound is ``flutter_crb.flutter_speed_bound``'s for
    the row's releases: its speeds, releases per speed and their holds (initial displacements),
    the hold in the wind before each (mode "after") or none, and its gust spectrum (Gaussian:
    a non-Gaussian row's bound is its Gaussian twin's; physics the row adds, such as friction,
    is not in it). The plate's Roger coefficients are all unknown to the bound, the bluff
    deck's structure is known (its zeros), as in ``flutter_crb.py``. None for a row in smooth
    flow.
    """
    section, make_model, static, Iw, _, change = row_spec(row)
    if not Iw:
        return dict.fromkeys(TUNNEL_MODE_NAMES)
    model = make_model()
    gusts = dataclasses.replace(vertical_gusts(Iw), **change.get("gusts", {}))
    holds = [HOLDS[j % len(HOLDS)] for j in range(change.get("per_speed", len(HOLDS)))]
    bound = flutter_crb.flutter_speed_bound(
        section, model, Iw, static=static, fractions=E2RFC_SPEEDS, holds=holds,
        known_zeros=make_model is bluff_deck_model, gusts=gusts, hold_s=TUNNEL_HOLD_S,
        samples=samples)
    return {"before": (HALF_NORMAL_MEDIAN * bound.std / bound.U_F,
                       bound.sampled_median / bound.U_F),
            "after": (HALF_NORMAL_MEDIAN * bound.std_with_holds / bound.U_F,
                      bound.sampled_median_with_holds / bound.U_F)}


def bound_note(seeds, rows=None):
    """Say how far the median of ``seeds`` errors of an estimator at the bound scatters.

    ``rows``: the number of rows with a bound in one table; the note then also gives the
    scatter of the ratio pooled over them (the "all rows" line, :func:`_tunnel_table`) and how
    often every row of an estimator at the bound would lie within 1.2 times it.
    """
    low, high, above = _median_ratio_scatter(seeds)
    note = (f"The bound's median error is {HALF_NORMAL_MEDIAN:.3f} times its std (a "
            "half-normal error). Over "
            f"{_count(seeds, 'seed')}, an estimator at the bound would show a median error "
            f"between {low:.2f} and {high:.2f} times it in 80 % of rows (its sampling "
            "scatter, by simulation): a ratio within that is as good as the bound.")
    if rows:
        pooled_low, pooled_high, _ = _median_ratio_scatter(seeds * rows)
        note += (f" Such an estimator's ratio exceeds 1.2 in {100 * above:.0f} % of rows, so "
                 f"all {rows} rows of a table lie within 1.2 in only "
                 f"{100 * (1 - above) ** rows:.0f} % of runs; the all-rows ratio (the median, "
                 "over every identification of the rows, of its error over its own row's "
                 f"bound median) falls between {pooled_low:.2f} and {pooled_high:.2f} in 80 % "
                 "of runs.")
    return note


def _median_ratio_scatter(count):
    """Return how the median of ``count`` half-normal errors scatters about the bound's.

    The 10th and 90th percentiles of that median over the half-normal's own, and how often it
    exceeds 1.2 (by simulation, seeded: the same figures every run).
    """
    errors = np.abs(np.random.default_rng(0).normal(size=(100_000 if count <= 40 else 20_000,
                                                          count)))
    ratios = np.median(errors, axis=1) / HALF_NORMAL_MEDIAN
    low, high = np.percentile(ratios, [10, 90])
    return float(low), float(high), float(np.mean(ratios > 1.2))


def tunnel_rows(which="all", quick=False):
    """Return the names of the tunnel rows ``which`` asks (``quick``: one clean, one turbulent)."""
    names = (list(CHANGED_ROWS[which]) if which in CHANGED_ROWS else
             [row for row in TUNNEL_ROWS
              if which == "all" or (which == "turbulent") == (TUNNEL_ROWS[row][3] > 0)])
    if quick and which not in CHANGED_ROWS:
        clean = [row for row in names if TUNNEL_ROWS[row][3] == 0]
        turbulent = [row for row in names if TUNNEL_ROWS[row][3] > 0]
        names = clean[:1] + turbulent[:1]
    elif quick:
        names = names[:1]
    return names


#: What each tunnel mode is, in a result table's caption.
TUNNEL_MODE_NAMES = {"after": "with holds", "before": "without holds"}


def tunnel_jobs(names, seeds, modes=("after",), a3="fitted-or-zero", first_seed=0,
                motion="filter", estimator="iv", buffeting="second-order"):
    """Return the jobs of :func:`tunnel_run` for the rows ``names``, every mode and seed."""
    return [(row, seed, mode, a3, motion, estimator, buffeting) for row in names
            for mode in modes
            for seed in range(first_seed, first_seed + seeds)]


def tunnel_report(found, names, seeds, modes, bounds):
    """Print the tunnel runs ``found`` yields as they come, then their tables; return them.

    ``bounds``: (row, mode) -> the median errors at the Cramer-Rao bound (:func:`row_bound`).
    """
    results = []
    # Each result printed as it arrives: a long run stopped halfway keeps what it measured.
    for result in found:
        row, mode, err, std, elapsed, branch, seed, fourth, (low, high) = result
        print(f"  {row:<24} {mode:<6} seed {seed:2d} err {100 * err:+8.2f} % std "
              f"{100 * std:7.2f} % interval {100 * low:+7.2f} to {100 * high:+7.2f} % "
              f"{elapsed:5.1f} s{' branch' if branch else ''}"
              f"{' fourth-order' if fourth else ''}", flush=True)
        results.append(result)
    tables = [_tunnel_table([r for r in results if r[1] == mode], names, seeds, mode,
                            {row: bounds[row, mode] for row in names})
              for mode in modes]
    # A failed identification (an exception, tunnel_run) is the one without a time.
    failed = [f"{r[0]} ({r[1]}) seed {r[6]}" for r in results if np.isnan(r[4])]
    warnings = ([f"{len(failed)} identification(s) raised an exception and count as without "
                 f"flutter: {'; '.join(failed)}."] if failed else [])
    return tables, warnings


def _tunnel_table(results, names, seeds, mode, bounds):
    print(f"\nE2RFC in a real tunnel ({mode}): 3 wind speeds (0.4/0.6/0.8 U_F) x 2 releases "
          "(the variant rows: as named), 20 s"
          f" at 500 Hz, 2 % noise, turbulence rows with a {TUNNEL_HOLD_S:g} s hold before each "
          f"release; {seeds} seeds per row; std = IdentifiedModel.flutter's (total).\n")
    header = (f"{'case':<26}{'|err| med':>10}{'at CRB':>8}{'ratio':>7}{'sampled':>9}"
              f"{'ratio':>7}{'|err| p90':>10}"
              f"{'2-std cover':>12}{'std med':>9}{'time med':>10}{'no flutter':>11}"
              f"{'branch':>10}{'4th ord':>8}")
    print(header)
    print("-" * len(header))
    covered = symmetric = total = 0
    table, pooled = [], []  # pooled: each error over its own row's first-order bound median
    for row in names:
        rows = [(r[0], r[2], r[3], r[4], r[5], r[7], r[8]) for r in results if r[0] == row]
        err = np.abs([r[1] for r in rows]) * 100
        std = np.array([r[2] for r in rows]) * 100
        # IdentifiedModel's 2-std interval (FlutterUncertainty.interval: longer above), and
        # the estimate +- 2 std beside it.
        inside = np.array([low <= 0.0 <= high for low, high in (r[6] for r in rows)])
        plain = np.isfinite(err) & (err <= 2 * std)
        covered += int(inside.sum())
        symmetric += int(plain.sum())
        total += len(rows)
        first, sampled = (None, None) if bounds[row] is None else (
            100 * bounds[row][0], 100 * bounds[row][1])
        if sampled is not None and math.isnan(sampled):  # the draws leave the deck's models
            sampled = None
        median = float(np.median(err))
        ratio = None if first is None else median / first
        if first is not None:
            pooled.extend(err / first)  # no flutter (inf) counts as a large error
        sampled_ratio = None if sampled is None else median / sampled
        line = (row, median, first, ratio, sampled, sampled_ratio, np.percentile(err, 90),
                100 * inside.mean(), np.nanmedian(std), np.median([r[3] for r in rows]),
                int(np.sum(~np.isfinite(err))), int(np.sum(np.isnan([r[3] for r in rows]))),
                sum(r[4] for r in rows), sum(r[5] for r in rows), int(inside.sum()),
                len(rows), 100 * plain.mean())
        table.append(line)
        shown = ["n/a" if v is None else f"{v:.2f}{unit}"
                 for v, unit in ((first, "%"), (ratio, ""), (sampled, "%"), (sampled_ratio, ""))]
        print(f"{row:<26}{median:>9.2f}%{shown[0]:>8}{shown[1]:>7}{shown[2]:>9}{shown[3]:>7}"
              f"{line[6]:>9.2f}%{line[7]:>11.0f}%{line[8]:>8.2f}%{line[9]:>9.2f}s"
              f"{line[10]:>11d}{line[12]:>10d}{line[13]:>8d}")
    print(f"\ncoverage of the 2-std interval over all rows: {covered}/{total} "
          f"({100 * covered / total:.0f} %; the estimate +- 2 std: {symmetric}/{total})")
    pooled_ratio = float(np.median(pooled)) if pooled else None
    if pooled_ratio is not None:
        print(f"the median of every error over its row's bound median: {pooled_ratio:.2f}")
    table.append(("all rows", None, None, pooled_ratio, None, None, None, 100 * covered / total,
                  None, None, sum(r[10] for r in table), sum(r[11] for r in table),
                  sum(r[12] for r in table), sum(r[13] for r in table), covered, total,
                  100 * symmetric / total))
    columns = ("case", "median error (%)", "median error at the bound (%)", "error / bound",
               "sampled median error at the bound (%)", "error / sampled bound",
               "p90 error (%)", "2-std coverage (%)", "median std (%)", "median time (s)",
               "no flutter", "failed", "branch", "fourth-order", "covered", "cases",
               "+- 2 std coverage (%)")
    holds = (f"the turbulence rows with a {TUNNEL_HOLD_S:g} s hold before each release"
             if mode == "after" else "the same releases without their holds")
    return result_files.Table(
        f"E2RFC in a real tunnel ({TUNNEL_MODE_NAMES[mode]}): 3 wind speeds (0.4/0.6/0.8 U_F) "
        "x 2 releases (the variant rows: as named), 20 s at 500 Hz, 2 % noise, "
        f"{holds}, {_count(seeds, 'seed')} per row: the "
        "flutter speed's absolute error, beside it the median error of an estimator at the "
        "Cramer-Rao bound of the same releases (flutter_crb.py; to first order, and over "
        "coefficients drawn from the bound's covariance) and the ratios, the coverage "
        "of the 2-std interval (FlutterUncertainty.interval: symmetric in the log of the "
        "distance beyond the highest speed the releases show stable) and, last, of the "
        "estimate +- 2 std, the median std, the median time of identification plus "
        "uncertainty, the cases without flutter (failed ones included), those the "
        "turbulence branch ran and those whose closed-loop fit has the fourth-order "
        "buffeting model.",
        columns, table, formats={"median error (%)": ".2f",
                                 "median error at the bound (%)": ".2f",
                                 "error / bound": ".2f",
                                 "sampled median error at the bound (%)": ".2f",
                                 "error / sampled bound": ".2f", "p90 error (%)": ".2f",
                                 "2-std coverage (%)": ".0f", "median std (%)": ".2f",
                                 "median time (s)": ".2f", "+- 2 std coverage (%)": ".0f"})


#: The ablation's variants: (name, window of each release in s, holds used).
ABLATION = (("decay only (0-5 s)", (0.0, 5.0), False),
            ("random only (5-20 s + holds)", (5.0, math.inf), True),
            ("both (0-20 s + holds)", None, True))
#: The ablation's buffeting model: the one the evidence takes on every seed of its rows (the
#: tunnel tables' "fourth-order" column), fitted alone so that each part is fitted alike.
ABLATION_BUFFETING = "fourth-order"


def ablation_run(args):
    """One closed-loop fit of a variant: error, Fisher std over U_F, and its interval covers."""
    row, seed, variant = args
    name, window, holds = ABLATION[variant]
    section, make_model, *_ = row_spec(row)
    U_F = fl.analyze(section, make_model()).speed
    releases = tunnel_releases(row, seed)
    start = e2rfc.identify([dataclasses.replace(r, hold=None) for r in releases], section)
    try:
        fit = closed_loop_ml.fit_closed_loop(
            releases, section, start, n_lags=2, use_holds=holds, window=window,
            **e2rfc.CLOSED_LOOP_BUFFETING_MODELS[ABLATION_BUFFETING])
        found = fl.analyze(section, fit.model)
    except ValueError as exc:
        print(f"FAILED {row} seed {seed} {name}: {exc}", flush=True)
        return row, name, np.inf, np.nan, False
    if found.speed is None:
        return row, name, np.inf, np.nan, False
    std = fisher_flutter_std(section, fit, found)
    # The interval as the identification draws it (FlutterUncertainty.interval), beyond the
    # highest speed the whole releases show stable, with the Fisher std as its only part.
    floor = bounded_at(releases)
    low, high = FlutterUncertainty(
        found.speed, std, 0.0, 0.0, 0.0, 0.0, len(releases),
        floor=floor if floor is not None and found.speed > floor else None).interval()
    return row, name, found.speed / U_F - 1.0, std / U_F, bool(low <= U_F <= high)


def fisher_flutter_std(section, fit, found):
    """Return the flutter speed's std (m/s) from a closed-loop fit's Fisher covariance."""
    dU_dA, dU_dd = fl.speed_sensitivity(section, fit.model, found.speed, found.frequency)
    gradient = np.array([dU_dA[k, i, j] for k, i, j in fit.parameter_index]
                        + list(dU_dd * fit.model.d))
    return math.sqrt(max(float(gradient @ fit.covariance @ gradient), 0.0))


def ablation_part(seeds, workers, rows=("plate, Jones, Iw 1 %", "bluff deck, Iw 1 %")):
    """Closed-loop ML on the decay alone, the random response alone, and both; return it."""
    jobs = [(row, seed, v) for row in rows for v in range(len(ABLATION))
            for seed in range(seeds)]
    with ProcessPoolExecutor(workers) as pool:
        results = list(pool.map(ablation_run, jobs))
    print(f"\nClosed-loop ML, what each part of the record tells ({seeds} seeds; std = the "
          "Fisher information's alone):\n")
    header = (f"{'case':<24}{'data':<30}{'|err| med':>10}{'|err| p90':>10}{'interval':>9}"
              f"{'2-std':>7}{'std med':>9}")
    print(header)
    print("-" * len(header))
    table = []
    for row in rows:
        for name, *_ in ABLATION:
            got = [(e, sd, inside) for r, n, e, sd, inside in results if (r, n) == (row, name)]
            err = np.abs([e for e, _, _ in got]) * 100
            std = np.array([sd for _, sd, _ in got]) * 100
            cover = np.mean(np.isfinite(err) & (err <= 2 * std))
            interval = np.mean([inside for *_, inside in got])
            table.append((row, name, np.median(err), np.percentile(err, 90), 100 * interval,
                          100 * cover, np.nanmedian(std), int(np.sum(~np.isfinite(err)))))
            print(f"{row:<24}{name:<30}{np.median(err):>9.2f}%{np.percentile(err, 90):>9.2f}%"
                  f"{100 * interval:>8.0f}%{100 * cover:>6.0f}%{np.nanmedian(std):>8.2f}%")
    return result_files.Table(
        f"Closed-loop ML, what each part of the record tells ({_count(seeds, 'seed')} per "
        f"case; the {ABLATION_BUFFETING} buffeting model, one filter for every speed): the "
        "flutter speed's absolute error, the coverage of the 2-std interval (drawn as "
        "FlutterUncertainty.interval draws it, beyond the highest speed the releases show "
        "stable) and, next, of the estimate +- 2 std, and the median std, all from the Fisher "
        "information alone, when fitted on the decay alone, on the random response alone, "
        "and on both.",
        ("case", "data", "median error (%)", "p90 error (%)", "2-std coverage (%)",
         "+- 2 std coverage (%)", "median std (%)", "no flutter or failed"),
        table, formats={"median error (%)": ".2f", "p90 error (%)": ".2f",
                        "2-std coverage (%)": ".0f", "+- 2 std coverage (%)": ".0f",
                        "median std (%)": ".2f"})


#: Seeds per row of a full run: the issue's tables (more, ``--seeds``, settle the medians).
SEEDS = 20


def _count(n, noun):
    """Return ``"1 seed"`` or ``"3 seeds"``."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def result_name(args):
    """Return the result file's name for the options of a run.

    ``ident_accuracy``, then those of the part, rows, turbulent estimator, motion, A3 rule,
    first seed and number of seeds (of the tunnel rows) that differ from the defaults, joined by
    ``_``. Not the tunnel mode: the file holds one table per mode, each captioned with it
    (``--tunnel-mode both``: two).
    """
    parts = [] if args.part == "all" else [args.part]
    if args.part in ("all", "tunnel"):
        parts += [value for value, default in (
            (args.rows, "all"), (args.turbulent_estimator, e2rfc.TURBULENT_ESTIMATOR),
            (args.turbulent_motion, _turbulent_fit.MOTION),
            (args.closed_loop_buffeting, e2rfc.CLOSED_LOOP_BUFFETING)) if value != default]
        if args.turbulent_a3 != "fitted-or-zero":
            parts.append(f"a3-{args.turbulent_a3}")
        if args.first_seed:
            parts.append(f"from{args.first_seed}")
        if args.seeds not in (None, SEEDS):
            parts.append(f"seeds{args.seeds}")
    return "_".join(["ident_accuracy", *parts]).replace("-", "_")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=None, help="seeds per row (20; --quick: 1)")
    result_files.add_workers(parser)
    parser.add_argument("--part", choices=("all", "classic", "tunnel", "timing", "ablation"),
                        default="all")
    parser.add_argument("--repeats", type=int, default=None,
                        help="timed runs of the timing table (9; --quick: 1)")
    parser.add_argument("--tunnel-mode", choices=("after", "before", "both"), default="after",
                        help="tunnel rows: as shipped, with the holds taken away, or both")
    parser.add_argument("--rows", choices=("all", "turbulent", "clean", *CHANGED_ROWS),
                        default=None,
                        help="which tunnel rows to run (variants: the turbulence rows changed "
                             "in one thing, VARIANT_ROWS; sections: on other sections, "
                             "SECTION_ROWS; default all, --quick: one clean and one turbulent)")
    parser.add_argument("--first-seed", type=int, default=0,
                        help="tunnel rows: the first seed (more seeds in another run)")
    parser.add_argument("--turbulent-a3", choices=("fitted-or-zero", "fitted", "choose", "e2rfc"),
                        default="fitted-or-zero",
                        help="A3 in E2RFC's turbulence branch (e2rfc.TURBULENT_A3)")
    parser.add_argument("--turbulent-motion", choices=("filter", "smoother", "smoother-sg"),
                        default=_turbulent_fit.MOTION,
                        help="how the turbulence branch estimates its regressors' motion "
                             "(ident.identification._turbulent_fit.MOTION)")
    parser.add_argument("--turbulent-estimator", choices=("iv", "ml"),
                        default=e2rfc.TURBULENT_ESTIMATOR,
                        help="the turbulence branch's estimator (e2rfc.TURBULENT_ESTIMATOR): "
                             "refined IV (needs holds) or closed-loop maximum likelihood")
    parser.add_argument("--closed-loop-buffeting", default=e2rfc.CLOSED_LOOP_BUFFETING,
                        choices=e2rfc.CLOSED_LOOP_BUFFETING_CHOICES,
                        help="the closed-loop branch's buffeting model "
                             "(e2rfc.CLOSED_LOOP_BUFFETING)")
    result_files.add_arguments(parser)
    args = parser.parse_args()
    explicit_rows = args.rows is not None
    args.rows = args.rows or "all"
    seeds = args.seeds if args.seeds is not None else (1 if args.quick else SEEDS)
    repeats = args.repeats if args.repeats is not None else (1 if args.quick else 9)
    if seeds < 1 or repeats < 1:
        parser.error("--seeds and --repeats must be at least 1")
    if args.first_seed < 0:
        parser.error(f"--first-seed must be 0 or more (a seed), got {args.first_seed}")
    name = result_name(args)
    bounded_rows = None  # the tunnel rows with a bound, once known
    parameters = {"part": args.part, "seeds": seeds, "workers": args.workers}
    tables, warnings = [], []

    def write():
        what = f"{args.part} part" + (f", {args.rows} tunnel rows, {args.tunnel_mode}"
                                      if args.part in ("all", "tunnel") else "")
        result_files.write(
            name, f"E2RFC's accuracy and speed ({what})", tables, results=args.results,
            quick=args.quick, script="ident_accuracy", parameters=parameters,
            notes=[] if args.part == "ablation" else [
                "Times are on one core (BLAS single-threaded) of a shared host: the wall times "
                "move with its load, the CPU times of the timing table less so."]
            + ([bound_note(seeds, bounded_rows)] if args.part in ("all", "tunnel") else []),
            warnings=warnings)

    if args.part == "timing":
        parameters = {"part": args.part, "repeats": repeats}
        tables.append(timing_part(repeats))
        write()
        return
    if args.part == "ablation":
        rows = ("plate, Jones, Iw 1 %",) if args.quick else ("plate, Jones, Iw 1 %",
                                                             "bluff deck, Iw 1 %")
        parameters["rows"] = list(rows)
        tables.append(ablation_part(seeds, args.workers, rows))
        write()
        return
    # The tunnel jobs first, then the smooth rows' in the same pool: its processes never idle.
    with ProcessPoolExecutor(args.workers) as pool:
        found = smooth = None
        if args.part in ("all", "tunnel"):
            modes = ("before", "after") if args.tunnel_mode == "both" else (args.tunnel_mode,)
            names = tunnel_rows(args.rows, quick=args.quick and not explicit_rows)
            bounded_rows = sum(1 for row in names if row_spec(row)[3])  # turbulent: a bound
            parameters.update({"first seed": args.first_seed, "rows": names,
                               "tunnel mode": args.tunnel_mode,
                               "turbulent A3": args.turbulent_a3,
                               "turbulent motion": args.turbulent_motion,
                               "turbulent estimator": args.turbulent_estimator,
                               "closed-loop buffeting": args.closed_loop_buffeting,
                               "hold (s)": TUNNEL_HOLD_S})
            bounds = pool.map(partial(row_bound, samples=flutter_crb.QUICK_SAMPLES
                                      if args.quick else flutter_crb.SAMPLES), names)
            found = pool.map(tunnel_run, tunnel_jobs(
                names, seeds, modes, args.turbulent_a3, args.first_seed, args.turbulent_motion,
                args.turbulent_estimator, args.closed_loop_buffeting))
        if args.part in ("all", "classic"):
            sections = list(SECTIONS)[:1] if args.quick else list(SECTIONS)
            noises = (0.02,) if args.quick else NOISES
            parameters.update({"sections": sections, "noises": list(noises),
                               "repeats": repeats})
            jobs = [(s, m, n, seed) for s in sections for m in METHODS for n in noises
                    for seed in range(seeds)]
            smooth = pool.map(one_run, jobs)
        if found is not None:
            tables_found, failed = tunnel_report(
                found, names, seeds, modes,
                {(row, mode): b[mode] for row, b in zip(names, bounds, strict=True)
                 for mode in modes})
            tables += tables_found
            warnings += failed
        if smooth is None:
            write()
            return
        results = list(tqdm(smooth, total=len(jobs), desc="identifications"))

    print(f"\nE2RFC: 3 wind speeds (0.4/0.6/0.8 U_F); FD route: 10 wind speeds (0.30..0.85 U_F);"
          f" 20 s at 500 Hz; {seeds} seeds per row; times on one core.\n'E2RFC raw' is the"
          " same estimator with regressors differentiated from the noisy displacements.\n")
    header = (f"{'section':<30}{'method':<11}{'noise':>6}{'U_F err med':>13}{'U_F err p90':>13}"
              f"{'FD err med':>12}{'time med':>10}{'|err|/std':>11}")
    print(header)
    print("-" * len(header))
    classic = []
    for s in sections:
        for m in METHODS:
            for n in noises:
                rows = [r for r in results if r[:3] == (s, m, n)]
                err = np.abs([r[3] for r in rows]) * 100
                fde = np.array([r[4] for r in rows]) * 100
                t = np.array([r[5] for r in rows])
                z = np.array([r[6] for r in rows])
                # Without noise both error and std are round-off: their ratio means nothing.
                meaningful = n > 0 and np.any(np.isfinite(z))
                z_text = f"{np.nanmedian(z):>11.2f}" if meaningful else f"{'-':>11}"
                print(f"{s:<30}{m:<11}{100 * n:>5.0f}%{np.median(err):>12.3f}%"
                      f"{np.percentile(err, 90):>12.3f}%{np.median(fde):>11.2f}%"
                      f"{np.median(t):>9.2f}s{z_text}")
                classic.append((s, m, 100 * n, np.median(err), np.percentile(err, 90),
                                np.median(fde), np.median(t),
                                np.nanmedian(z) if meaningful else None))
    columns = ("section", "method", "noise (%)", "median U_F error (%)", "p90 U_F error (%)",
               "median FD error (%)", "median time (s)", "median error/std")
    tables.append(result_files.Table(
        "E2RFC (3 wind speeds, 0.4/0.6/0.8 U_F), E2RFC with regressors differentiated from the "
        "noisy displacements ('E2RFC raw') and the FD route (10 wind speeds, 0.30-0.85 U_F), "
        f"20 s at 500 Hz, {_count(seeds, 'seed')} per row: the flutter speed's absolute "
        "error, the flutter derivatives' error (mean over the eight of max error / max true), "
        "the median identification time on one core and the median error over the predicted "
        "std.",
        columns, classic,
        formats={"noise (%)": ".0f", "median U_F error (%)": ".3f",
                 "p90 U_F error (%)": ".3f", "median FD error (%)": ".2f",
                 "median time (s)": ".2f", "median error/std": ".2f"}))
    tables.append(timing_part(repeats))
    write()


if __name__ == "__main__":
    main()
