"""E2RFC's turbulence branch: refined IV with the noise model of the hold before each release.

(``turbulent_estimator="iv"`` throughout: the default is the closed-loop branch,
test_closed_loop_ml.py.)

Seeded cases of ``benchmarks/ident_accuracy.py --part tunnel``'s plate campaign (0.4/0.6/0.8 U_F
x 2 holds, 20 s at 500 Hz, 2 % noise, vertical turbulence, a 10 s hold before each release).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.signal import lfilter

from ident import Release
from ident.identification import e2rfc, results
from ident.identification._turbulent_fit import MIN_HOLD_S, ar_fit
from ident.model import flat_plate
from ident.model import flutter as fl
from ident.model.quasi_steady import StaticCoefficients
from ident.physics.turbulence import TurbulenceSpec
from ident.records.release import ReleaseHold
from simulators import simulate_release
from simulators.decks import BLUFF_DECK, BLUFF_DECK_STATIC, bluff_deck_model

from support.sections import FLAT_PLATE

HOLDS = ((0.004, 0.02), (-0.003, 0.012))
#: The smooth-flow campaign's flutter speed (seed 0, no holds) identified by main at 235df92,
#: before the branch existed, m/s (repr of the float).
SMOOTH_BEFORE = 11.754930947127962


def campaign(*, seed, Iw, hold_s, deck="plate"):
    """Return the benchmark's campaign; each release with a hold of ``hold_s`` s.

    ``deck``: ``"plate"`` (Jones's aerodynamics, a flat plate's static coefficients) or
    ``"bluff"`` (:mod:`simulators.decks`' bluff deck, outside Roger's form).
    """
    section, model, static = ((FLAT_PLATE, flat_plate.jones_model(),
                               StaticCoefficients.flat_plate())
                              if deck == "plate" else
                              (BLUFF_DECK, bluff_deck_model(), BLUFF_DECK_STATIC))
    U_F = fl.analyze(section, model).speed
    wind = {}
    if Iw:
        wind = {"static": static, "span": 1.0,
                "turbulence": TurbulenceSpec(Iu=0.0, Iw=Iw, Lux=1.0, Lwx=0.3, Cuy=10.0, Cwy=8.0)}
    if hold_s:
        wind["pre_s"] = hold_s
    return [Release.from_simulation(simulate_release(
        section, model, f * U_F, h0, a0, duration=20.0, fs=500.0, noise=0.02,
        rng=(seed, i, j, int(1000 * Iw)), **wind))
        for i, f in enumerate((0.4, 0.6, 0.8)) for j, (h0, a0) in enumerate(HOLDS)]


@pytest.fixture(scope="module")
def turbulent_releases():
    return campaign(seed=0, Iw=0.01, hold_s=10.0)


def test_the_branch_finds_the_flutter_speed_in_1_percent_turbulence(turbulent_releases):
    """Plate, Iw 1 %, seed 0: within 8 % of the truth and covered by 2 std.

    Tolerance from the measured scatter (benchmark, 32 seeds of this row with the branch):
    median |error| 4.7 %, 90th percentile 27.8 %; this seed gives 2.1 %, and 8 % lies between
    the median and the 90th percentile (a regression to today's estimator, 11.7 % median,
    would likely fail it). Today's estimator on the same releases misses by more (checked
    below), and its interval says nothing (a median std of 146 %). Truth: the frequency-domain
    flutter analysis of the simulated (Jones) model, independent of the identification.
    """
    U_F = fl.analyze(FLAT_PLATE, flat_plate.jones_model()).speed
    model = e2rfc.identify(turbulent_releases, FLAT_PLATE, turbulent_estimator="iv")
    diagnostics = model.diagnostics
    assert diagnostics.turbulent
    assert diagnostics.estimator == e2rfc.ESTIMATOR_TURBULENT
    assert diagnostics.n_lags in (1, 2)
    assert len(diagnostics.jackknife) == len(turbulent_releases)
    u = model.uncertainty(FLAT_PLATE)
    assert u.speed is not None
    error = abs(u.speed / U_F - 1.0)
    assert error < 0.08
    assert abs(u.speed - U_F) <= 2 * u.total
    assert u.turbulence > 0.0  # the jackknife's part, Student-scaled
    # The interval is not a blanket: under half the speed (today's median std exceeds 100 %).
    assert u.total < 0.5 * U_F
    # releases_needed still answers: more releases shrink the scatter part.
    needed = u.releases_needed(max(u.systematic * 1.1, 0.5 * u.total))
    assert needed is None or needed >= len(turbulent_releases)
    before = e2rfc.identify([dataclasses.replace(r, hold=None) for r in turbulent_releases],
                            FLAT_PLATE, turbulent_estimator="iv").uncertainty(FLAT_PLATE)
    before_error = np.inf if before.speed is None else abs(before.speed / U_F - 1.0)
    assert before_error > error


@pytest.mark.slow
@pytest.mark.parametrize(("deck", "Iw"), [("bluff", 0.03)])
def test_the_branch_holds_on_other_turbulent_rows_of_the_benchmark(deck, Iw):
    """Another turbulence row, seeds 0-2: median error, 2-std cover, intervals not blankets.

    Refined IV is the alternative to the closed-loop default since that became the default:
    the other deck at the other intensity is checked here (the plate at Iw 1 % above); the
    plate at 3 % and the bluff deck at 1 % (about a minute each of the CI's time) are left to
    the benchmark, which runs every row over 20 seeds.

    Bounds from the benchmark's 20 seeds per row (median / p90 |error|, cover): plate Iw 3 %
    7.4 / 36 %, 90 %; bluff Iw 1 % 10.5 / 25 %, 95 %; bluff Iw 3 % 8.6 / 33 %, 85 %. A median
    below 20 % over three seeds sits between the rows' medians and their 90th percentiles;
    the estimator without the holds had medians of 49-55 %, 34-41 % and 56-76 % on these rows
    and would fail it. Two of three covered: the rows' cover of 85-95 % makes a miss in three
    likely enough. These seeds (measured): plate Iw 3 % -11.2 % (not covered), -2.1 %, -0.0 %;
    bluff Iw 1 % -8.4, +25.0, -0.6 %; bluff Iw 3 % +2.7, -12.5, -11.1 %. Truth: the state-space
    flutter analysis of the simulated model, independent of the identification.
    """
    section, model = ((FLAT_PLATE, flat_plate.jones_model()) if deck == "plate"
                      else (BLUFF_DECK, bluff_deck_model()))
    U_F = fl.analyze(section, model).speed
    errors, stds, covered = [], [], 0
    for seed in range(3):
        identified = e2rfc.identify(campaign(seed=seed, Iw=Iw, hold_s=10.0, deck=deck), section,
                                    turbulent_estimator="iv")
        assert identified.diagnostics.estimator == e2rfc.ESTIMATOR_TURBULENT
        u = identified.uncertainty(section)
        assert u.speed is not None
        errors.append(abs(u.speed / U_F - 1.0))
        stds.append(u.total / U_F)
        covered += abs(u.speed - U_F) <= 2 * u.total
    assert float(np.median(errors)) < 0.20
    assert covered >= 2
    # Not a blanket: the estimator without holds had median stds of 46-235 % on these rows.
    assert float(np.median(stds)) < 0.5


def test_short_holds_leave_todays_estimator_with_a_warning(turbulent_releases):
    """Holds of 3 s (under MIN_HOLD_S): today's estimator runs and says what turbulence needs."""
    short = []
    for r in turbulent_releases:
        h = r.hold
        keep = h.t >= -3.0 - 1e-9
        cut = ReleaseHold(t=h.t[keep], h=h.h[keep], alpha=h.alpha[keep], lift=h.lift[keep],
                          moment=h.moment[keep])
        short.append(dataclasses.replace(r, hold=cut))
    model = e2rfc.identify(short, FLAT_PLATE, turbulent_estimator="iv")
    assert model.diagnostics.estimator == results.ESTIMATOR_E2RFC
    assert any(f">= {MIN_HOLD_S:g} s before each release" in w
               for w in model.diagnostics.warnings)


def test_smooth_flow_identification_is_unchanged():
    """Smooth flow: the flutter speed is main's before the branch, to 1e-12 relative.

    And a hold changes nothing in smooth flow: the same releases with and without their holds
    give the identical model.
    """
    u = e2rfc.identify(campaign(seed=0, Iw=0.0, hold_s=0.0), FLAT_PLATE,
                       turbulent_estimator="iv").uncertainty(FLAT_PLATE)
    assert u.speed == pytest.approx(SMOOTH_BEFORE, rel=1e-12, abs=0.0)
    held = campaign(seed=1, Iw=0.0, hold_s=MIN_HOLD_S)
    with_hold = e2rfc.identify(held, FLAT_PLATE, turbulent_estimator="iv")
    without = e2rfc.identify([dataclasses.replace(r, hold=None) for r in held], FLAT_PLATE,
                             turbulent_estimator="iv")
    assert with_hold.diagnostics.estimator == results.ESTIMATOR_E2RFC
    np.testing.assert_array_equal(with_hold.A, without.A)
    np.testing.assert_array_equal(with_hold.d, without.d)


def test_the_hold_noise_model_recovers_a_known_ar_process():
    """ar_fit on an AR(2) process (poles 0.9 e^{+-0.5i}): coefficients within 0.05.

    The estimates' standard deviation is about sqrt((1 - a2^2) / n) = 0.006 for n = 5000, so
    0.05 is far outside the scatter; BIC must pick order 2 (or a little more, with tiny extra
    coefficients).
    """
    a1, a2 = -2 * 0.9 * np.cos(0.5), 0.81
    rng = np.random.default_rng(3)
    x = lfilter([1.0], [1.0, a1, a2], rng.normal(size=5000))
    a = ar_fit(x, 20)
    assert a[0] == 1.0 and a.size >= 3
    assert a[1] == pytest.approx(a1, abs=0.05) and a[2] == pytest.approx(a2, abs=0.05)
    assert np.all(np.abs(a[3:]) < 0.05)


def test_the_smoother_follows_the_true_velocity_closer_than_the_filter(monkeypatch):
    """Plate, Iw 1 %, 0.6 U_F, seed 5: the smoother's q' errs well under half the filter's.

    Both estimates, and the truth (the noise-free simulated displacements, differentiated by a
    cubic spline), low-passed by the branch's own zero-phase filter. Measured on this release:
    the Savitzky-Golay rate of the low-passed lasers errs by 1.9 % (heave) and 2.2 % (pitch) of
    the velocity's RMS, the smoother (the structure driven by the measured force) by 0.28 % and
    0.64 %. A smoother that lost the force (or took it with the wrong sign or units) would err
    by far more than the filter.
    """
    from scipy.interpolate import CubicSpline
    from scipy.signal import sosfiltfilt

    from ident.identification import _turbulent_fit

    model = flat_plate.jones_model()
    U_F = fl.analyze(FLAT_PLATE, model).speed
    sim = simulate_release(
        FLAT_PLATE, model, 0.6 * U_F, 0.004, 0.02, duration=20.0, fs=500.0, noise=0.02,
        rng=(5, 1, 0, 10), static=StaticCoefficients.flat_plate(), span=1.0, pre_s=MIN_HOLD_S,
        turbulence=TurbulenceSpec(Iu=0.0, Iw=0.01, Lux=1.0, Lwx=0.3, Cuy=10.0, Cwy=8.0))
    release = Release.from_simulation(sim)
    after = sim.t >= 0.0
    truth = np.column_stack([sim.clean["h"][after] / FLAT_PLATE.B, sim.clean["alpha"][after]])
    errors = {}
    for motion in ("filter", "smoother"):
        monkeypatch.setattr(_turbulent_fit, "MOTION", motion)
        signals = _turbulent_fit._Signals(release, FLAT_PLATE)
        velocity = sosfiltfilt(signals.sos, CubicSpline(release.t, truth)(release.t, 1), axis=0)
        core = slice(signals.rows.start, signals.rows.stop)
        errors[motion] = (np.sqrt(np.mean((signals.qdot[core] - velocity[core]) ** 2, axis=0))
                          / np.std(velocity[core], axis=0))
    assert np.all(errors["smoother"] < 0.4 * errors["filter"]), errors
    assert np.all(errors["smoother"] < 0.01), errors
