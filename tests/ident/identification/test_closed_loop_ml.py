"""Closed-loop maximum likelihood of releases in turbulence (ident.identification.closed_loop_ml).

Checked against independent results: the Riccati solution against scipy's generalised-Schur
solver; the steady-state predictor's likelihood against the exact time-varying Kalman filter
(:mod:`ident.identification.innovations`, itself checked against the dense normal density);
the estimate against the truth on records drawn from the model class itself (where the Fisher
information's standard deviation is the right yardstick), and on the virtual tunnel's
turbulence (von Karman gusts, span-wise coherence: a buffeting spectrum the shaping filter only
approximates).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg
import scipy.signal

from ident import Release, SectionModel
from ident.errors import PlausibilityError
from ident.identification import (
    _closed_loop_parameters,
    _closed_loop_starts,
    _e2rfc_turbulence,
    closed_loop_ml,
    e2rfc,
    innovation_checks,
    steady_predictor,
)
from ident.identification.innovations import ReleaseModel, ShapingFilter, kalman_filter
from ident.identification.results import IdentifiedModel
from ident.model import flat_plate
from ident.model import flutter as fl
from ident.model.quasi_steady import StaticCoefficients, quasi_steady_model
from ident.model.rfc import RationalFunctionModel
from ident.physics.turbulence import GustField, TurbulenceSpec
from simulators import simulate_release
from simulators.campaigns import scaled
from simulators.decks import BLUFF_DECK, BLUFF_DECK_STATIC, bluff_deck_model

PLATE = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)
HOLDS = ((0.004, 0.02), (-0.003, 0.012))
NOISE = np.array([1e-5, 2e-4, 0.05, 0.002])  # m, rad, N/m, N m/m


def shaping(U):
    """Return a buffeting force growing as U^2, the moment mostly one gust's with the lift."""
    q = U**2 / 100.0
    return ShapingFilter([4.0, 4.0], [0.8, 0.8], [[0.02 * q, 0.0], [0.003 * q, 0.0005 * q]])


def own_model_releases(seed, duration=20.0, fs=500.0):
    """3 speeds x 2 releases drawn from ReleaseModel itself (the estimator's model class)."""
    truth = flat_plate.jones_model()
    U_F = fl.analyze(PLATE, truth).speed
    rng = np.random.default_rng(seed)
    releases = []
    for fraction in (0.4, 0.6, 0.8):
        U = fraction * U_F
        model = ReleaseModel(PLATE, truth, U, fs, shaping(U), NOISE)
        for h0, a0 in HOLDS:
            x0 = model.initial_state(h0, a0)
            n = int(duration * fs)
            y = model.sample(x0, model.initial_covariance(), n, rng)
            releases.append(Release(t=np.arange(n) / fs, h=y[:, 0], alpha=y[:, 1],
                                    lift=y[:, 2], moment=y[:, 3], U=U))
    return releases, truth, U_F


def tunnel_releases_seed_2():
    """Return the plate releases at 1 % turbulence (seed 2, no holds) and their U_F, m/s."""
    truth = flat_plate.jones_model()
    U_F = fl.analyze(PLATE, truth).speed
    wind = {"static": StaticCoefficients.flat_plate(), "span": 1.0,
            "turbulence": TurbulenceSpec(Iu=0.0, Iw=0.01, Lux=1.0, Lwx=0.3, Cuy=10.0, Cwy=8.0)}
    releases = [Release.from_simulation(simulate_release(
        PLATE, truth, f * U_F, h0, a0, duration=20.0, fs=500.0, noise=0.02,
        rng=(2, i, j, 10), **wind))
        for i, f in enumerate((0.4, 0.6, 0.8)) for j, (h0, a0) in enumerate(HOLDS)]
    return releases, U_F


def flutter_std(fit):
    """Return the flutter speed and its std from the fit's covariance (first order), m/s."""
    result = fl.analyze(PLATE, fit.model)
    dU_dA, dU_dd = fl.speed_sensitivity(PLATE, fit.model, result.speed, result.frequency)
    gradient = np.array([dU_dA[k, i, j] for k, i, j in fit.parameter_index]
                        + list(dU_dd * fit.model.d))
    return result.speed, math.sqrt(gradient @ fit.covariance @ gradient)


def test_doubling_solves_the_riccati_equation_as_scipy_does():
    """Relative agreement 1e-10: both are exact to round-off on this well-conditioned case."""
    U = 8.0
    m = ReleaseModel(PLATE, flat_plate.jones_model(), U, 100.0, shaping(U), NOISE)
    ours = steady_predictor.riccati(m.Phi, m.C, m.Qd, m.R)
    theirs = scipy.linalg.solve_discrete_are(m.Phi.T, m.C.T, m.Qd, m.R)
    assert np.abs(ours - theirs).max() <= 1e-10 * np.abs(theirs).max()


def nearby_models(U):
    """Return a model and three 1e-4 away in each parameter kind: a coefficient, U, noise."""
    truth = flat_plate.jones_model()
    base = ReleaseModel(PLATE, truth, U, 100.0, shaping(U), NOISE)
    A = truth.A.copy()
    A[1, 0, 1] *= 1 + 1e-4
    return base, [ReleaseModel(PLATE, type(truth)(A, truth.d), U, 100.0, shaping(U), NOISE),
                  ReleaseModel(PLATE, truth, U * (1 + 1e-4), 100.0, shaping(U), NOISE),
                  ReleaseModel(PLATE, truth, U, 100.0, shaping(U), NOISE * (1 + 1e-4))]


def test_the_predictor_s_change_solves_the_nearby_riccati_equation_to_first_order():
    """The Fisher information's shortcut: one Stein equation instead of a Riccati solution.

    For the matrices of a model 1e-4 away in every parameter kind the first-order Riccati
    solution must leave an error that is of the second order: under 1e-3 of the change it
    predicts (measured 1e-5 to 1e-4: the step times the solution's curvature).
    """
    U = 0.6 * fl.analyze(PLATE, flat_plate.jones_model()).speed
    base, nearby = nearby_models(U)
    predictor = steady_predictor.SteadyPredictor(base.Phi, base.Qd, base.C, base.R)
    for m in nearby:
        exact = steady_predictor.riccati(m.Phi, m.C, m.Qd, m.R)
        first_order = predictor.change(m.Phi, m.Qd, m.C, m.R).P
        change = np.abs(exact - predictor.P).max()
        assert change > 0.0
        assert np.abs(first_order - exact).max() <= 1e-3 * change


def test_the_innovations_change_as_the_nearby_predictors_innovations_do():
    """All changes through one filter pass against each nearby predictor run on its own.

    The nearby predictors are solved exactly (their own Riccati solutions, with a feedthrough
    as the block-means model has) and run on a record with offsets and an initial state held;
    their innovations' difference from the base's must match the first-order change to 1e-3
    of its size (the steps are 1e-4; measured 7e-6 to 2e-4: the second-order remainder).
    """
    U = 0.6 * fl.analyze(PLATE, flat_plate.jones_model()).speed
    base, nearby = nearby_models(U)
    rng = np.random.default_rng(5)
    y = base.sample(base.initial_state(0.004, 0.02), base.initial_covariance(), 600, rng)
    feedthrough = 1e-3 * rng.standard_normal((base.Phi.shape[0], 4))
    predictor = steady_predictor.SteadyPredictor(base.Phi, base.Qd, base.C, base.R,
                                                 feedthrough=feedthrough)
    _, _, nuisance = predictor.concentrated(y)
    e = predictor.innovations(y, nuisance)
    changes = [predictor.change(m.Phi, m.Qd, m.C, m.R, feedthrough=1.1 * feedthrough)
               for m in nearby]
    # The fit takes them in one batch: the same changes as one at a time (each a handful of
    # products of 16 x 16 matrices, so rounding stays near 1e-15 of each field's size).
    batch = predictor.changes(*(np.stack([getattr(m, name) for m in nearby])
                                for name in ("Phi", "Qd", "C", "R")),
                              feedthrough=np.stack([1.1 * feedthrough] * len(nearby)))
    for one, many in zip(changes, batch, strict=True):
        for name in ("P", "S", "closed_loop", "gain", "C"):
            want = getattr(one, name)
            np.testing.assert_allclose(getattr(many, name), want, rtol=0,
                                       atol=1e-12 * np.abs(want).max())
    de = predictor.innovation_changes(y, nuisance, batch)
    assert de.shape == (3, 600, 4)
    for m, first_order in zip(nearby, de, strict=True):
        exact = steady_predictor.SteadyPredictor(m.Phi, m.Qd, m.C, m.R,
                                                 feedthrough=1.1 * feedthrough)
        difference = exact.innovations(y, nuisance) - e
        assert np.abs(difference).max() > 0.0
        assert np.abs(first_order - difference).max() <= 1e-3 * np.abs(difference).max()


def test_steady_predictor_matches_the_exact_filter_and_its_innovations_are_white():
    """At the truth, the concentrated steady-state likelihood is the exact filter's.

    The steady gain loses a little over the first second and the concentration fits 16
    nuisance values (4 offsets, 12 initial states), which can only raise log L: by about 8
    (half a chi-square with 16 degrees of freedom); 40 is far beyond chance and far below any
    modelling error (a 1 % change of the buffeting level moves it by about 100). The
    standardised innovations' autocorrelation at lags 1-20 stays within 4/sqrt(n).
    """
    U = 0.6 * fl.analyze(PLATE, flat_plate.jones_model()).speed
    m = ReleaseModel(PLATE, flat_plate.jones_model(), U, 500.0, shaping(U), NOISE)
    x0 = m.initial_state(0.004, 0.02)
    y = m.sample(x0, m.initial_covariance(), 10000, np.random.default_rng(3))
    exact = kalman_filter(m, y, x0).log_likelihood
    predictor = steady_predictor.SteadyPredictor(m.Phi, m.Qd, m.C, m.R)
    e, _, _ = predictor.concentrated(y)
    steady = -steady_predictor.neg_log_likelihood(e, predictor.S)
    assert 0.0 <= steady - exact <= 40.0
    u = e @ np.linalg.inv(np.linalg.cholesky(predictor.S)).T
    u -= u.mean(axis=0)
    for lag in range(1, 21):
        acf = np.sum(u[lag:] * u[:-lag], axis=0) / np.sum(u * u, axis=0)
        assert np.all(np.abs(acf) < 4.0 / math.sqrt(u.shape[0]))


def test_channel_offsets_are_concentrated_out():
    """A constant added to every channel (a zero drift, a mean load) leaves log L unchanged."""
    releases, truth, _ = own_model_releases(seed=5, duration=6.0, fs=200.0)
    section, speeds = PLATE, closed_loop_ml.distinct_wind_speeds([r.U for r in releases])
    records = _closed_loop_parameters.records(releases[:2], section, speeds, 4.0, True)
    layout = _closed_loop_parameters.Layout(2, truth.n_lags, True, len(speeds), 2)
    objective = closed_loop_ml._Objective(records, section, layout)
    theta = _closed_loop_parameters.initial(records, layout, truth, section, 4.0)
    before = objective.evaluate(theta).nll
    for record in records:
        record.y = record.y + np.array([1e-3, 0.01, 0.5, 0.05])
    assert objective.evaluate(theta).nll == pytest.approx(before, rel=1e-9)


def test_a_release_starts_with_its_lag_states_at_zero_and_a_later_window_does_not():
    """The release from rest: its lag states are known, not concentrated out.

    A record from the release holds its lag states at zero (their columns leave the nuisance,
    their entries of the initial state are exactly zero) and keeps its displacements,
    velocities and buffeting states free; a hold has no lag states; a window that starts 5 s
    into the release knows nothing of its state there. At the truth, holding known entries
    can only lower log L, and by little: each costs about half a chi-square with one degree
    of freedom (8 entries here, about 4 on average; measured 0.13), so 20 is far beyond
    chance.
    """
    releases, truth, _ = own_model_releases(seed=5, duration=6.0, fs=200.0)
    section, speeds = PLATE, closed_loop_ml.distinct_wind_speeds([r.U for r in releases])
    records = _closed_loop_parameters.records(releases[:2], section, speeds, 4.0, True)
    later = _closed_loop_parameters.records(releases[:2], section, speeds, 4.0, True,
                                            window=(5.0, math.inf))
    assert [r.from_rest for r in records if not r.held] == [True, True]
    assert not any(r.from_rest for r in later)
    layout = _closed_loop_parameters.Layout(2, truth.n_lags, True, len(speeds), 2)
    objective = closed_loop_ml._Objective(records, section, layout)
    theta = _closed_loop_parameters.initial(records, layout, truth, section, 4.0)
    lags = range(4, 4 + 2 * truth.n_lags)  # [h, alpha, h', alpha', lag states, buffeting]
    for record in records:
        assert list(objective.at_zero(record)) == ([] if record.held else list(lags))
    held = objective.evaluate(theta)
    for record, nuisance, columns in zip(records, held.nuisance, held.columns, strict=True):
        if record.held:
            continue
        n_x = nuisance.size - 4
        assert columns.shape[1] == 4 + n_x - len(lags)
        assert np.all(nuisance[4:][list(lags)] == 0.0)
        assert np.all(nuisance[4:][:4] != 0.0)
    for record in records:
        record.from_rest = False
    free = objective.evaluate(theta)
    assert 0.0 <= held.nll - free.nll < 20.0


def test_the_pooled_portmanteau_statistic_sums_every_record_s_lagged_products():
    """Against a direct sum over lags and records, and chi-square for white innovations.

    Six records of 2000 samples, as 3 speeds x 2 releases at the decimated rate. Each record's
    innovations have their own covariance (a channel with ten times the std, correlated ones):
    standardised by it, they are white. The statistic is chi-square with 20 degrees of freedom
    there: over 200 draws of four channels its mean is within 4 standard errors (0.22) of 20,
    and at most 3 draws exceed the limit on some channel (chance 1 in 1000 per draw: 0.2
    expected). A moving average of coefficient 0.1 on one channel (lag-1 autocorrelation 0.1)
    adds about N 0.1^2 = 120 there alone.
    """
    rng = np.random.default_rng(7)
    L = np.array([[1.0, 0, 0, 0], [0.5, 1.0, 0, 0], [0, 0, 10.0, 0], [0, 0, 3.0, 2.0]])
    S = L @ L.T

    def records(coefficient=0.0):
        out = []
        for _ in range(6):
            w = rng.standard_normal((2000, 4))
            w[1:, 2] += coefficient * w[:-1, 2]  # a moving average: lag-1 correlation ~ 0.1
            out.append(w @ L.T)
        return out

    e = records()
    found = innovation_checks.pooled_portmanteau(e, [S] * 6)
    u = [x @ np.linalg.inv(L).T for x in e]
    u = [x - x.mean(axis=0) for x in u]
    N = sum(x.shape[0] for x in u)
    for c in range(4):
        power = sum(float(x[:, c] @ x[:, c]) for x in u)
        rho = [sum(float(x[lag:, c] @ x[:-lag, c]) for x in u) / power for lag in range(1, 21)]
        assert found[c] == pytest.approx(N * sum(r * r for r in rho), rel=1e-12)
    limit = innovation_checks.portmanteau_limit()
    assert 45.0 < limit < 55.0  # chi-square(20) at 1 - 0.001 / 4: 49.6
    draws = np.array([innovation_checks.pooled_portmanteau(records(), [S] * 6)
                      for _ in range(200)])
    assert abs(draws.mean() - 20.0) < 4 * math.sqrt(40.0 / 800)
    assert np.sum(np.any(draws > limit, axis=1)) <= 3
    coloured = innovation_checks.pooled_portmanteau(records(0.1), [S] * 6)
    assert coloured[2] > 2 * limit
    assert np.all(np.delete(coloured, 2) < limit)
    # The warning names the channel and the remedies: the fourth-order model and, where no
    # record is a hold, holds (the buffeting spectrum is otherwise learnt from the motion).
    (warning,) = innovation_checks.portmanteau_warning(coloured, 6, 1, n_holds=0)
    assert "lift" in warning and "fourth-order" in warning and "record holds" in warning
    (held,) = innovation_checks.portmanteau_warning(coloured, 12, 1, n_holds=6)
    assert "record holds" not in held and "12 records" in held
    assert innovation_checks.portmanteau_warning(np.minimum(coloured, limit), 6, 1,
                                                 n_holds=0) == []


def test_recovers_the_flutter_speed_of_data_from_its_own_model():
    """Started from E2RFC's estimate, the flutter speed within 2.5 std of the truth.

    With 20 s records seeds 0-2 give errors of +1.5, -0.1 and -3.0 % against Fisher stds of
    3.4, 3.3 and 2.1 % (|z| 0.4, 0.0, 1.4); 12 s records here keep the suite short (seed 0:
    -1.1 %, std 2.5 %). 2.5 std
    leaves room for the seed-to-seed spread while still failing a biased estimator (the random
    response taken for noise biases E2RFC by 10 % or more here). The std itself must be below
    10 % (a covariance that blew up would pass any coverage).
    """
    releases, truth, U_F = own_model_releases(seed=0, duration=12.0)
    start = e2rfc.identify(releases, PLATE)
    fit = closed_loop_ml.fit_closed_loop(releases, PLATE, start, n_lags=2)
    assert fit.converged
    speed, std = flutter_std(fit)
    assert std < 0.10 * U_F
    assert abs(speed - U_F) <= 2.5 * std
    assert np.all(fit.whiteness < 0.12)  # 2000 samples: chance stays below about 0.09
    assert np.all(fit.portmanteau < innovation_checks.portmanteau_limit())
    assert not any("portmanteau" in w for w in fit.warnings)
    # Schwarz's criterion counts what was estimated: 20 A entries and 2 lag roots, 7 shaping
    # parameters per speed, 4 noise stds per release and per record 4 offsets at ln N / 2
    # each; each record's initial state (12 states: 4 of the structure, 4 lag states, 4 of
    # the shaping filter) at one per entry, less the lag states, zero at the release; N: 12 s
    # of block means at 100 Hz on 4 channels.
    n_states = ReleaseModel(PLATE, truth, 5.0, 100.0, shaping(5.0), NOISE).n_states
    assert n_states == 12
    assert fit.n_parameters == 22 + 3 * 7 + 6 * 4 + 6 * 4
    assert fit.n_initial_states == 6 * (n_states - 4)
    assert fit.n_samples == 6 * 1200 * 4
    assert fit.schwarz == pytest.approx(
        fit.neg_log_likelihood + 0.5 * fit.n_parameters * math.log(fit.n_samples)
        + fit.n_initial_states, rel=1e-12)
    for sf in fit.shaping:  # the buffeting's corner frequency, within 15 %
        assert np.allclose(sf.frequencies, 4.0, rtol=0.15)


#: A buffeting filter's frequencies (Hz), zeros (s) and Cholesky factor per degrees of freedom.
FILTERS = {2: ([[3.0, 6.5], [4.2, 9.0]], [[0.05, 0.02], [0.04, 0.01]],
               [[0.02, 0.0], [-0.004, 0.001]]),
           3: ([[3.0, 6.5], [4.2, 9.0], [2.5, 7.0]], [[0.05, 0.02], [0.04, 0.01], [0.03, 0.02]],
               [[0.02, 0.0, 0.0], [-0.004, 0.001, 0.0], [0.003, -0.0005, 0.002]])}


@pytest.mark.parametrize("n_dof", [2, 3])
@pytest.mark.parametrize("sections", [1, 2])
def test_a_shaping_filter_written_into_the_parameters_reads_back_as_itself(sections, n_dof):
    """``Layout.set_shaping`` is ``Layout.shaping``'s inverse (the warm start's encoding)."""
    layout = _closed_loop_parameters.Layout(n_dof, 2, True, 3, 6, sections)
    f_all, zeros_all, L = FILTERS[n_dof]
    f = np.array(f_all)[:, :sections]
    zeros = np.array(zeros_all)[:, :sections] if sections > 1 else None
    filt = ShapingFilter(f, np.full((n_dof, sections), 0.6), L, zeros)
    theta = np.zeros(layout.size)
    layout.set_shaping(theta, 1, filt)
    back = layout.shaping(theta, 1)
    for name in ("frequencies", "damping", "L"):
        assert np.allclose(getattr(back, name), getattr(filt, name), rtol=1e-12), name
    if sections > 1:
        assert np.allclose(back.zeros, filt.zeros, rtol=1e-12)
    assert not np.any(theta[layout.shaping0:layout.shaping0 + layout.n_shaping])  # group 0
    other = ShapingFilter(f[:, :1] if sections > 1 else np.c_[f, f], np.full(
        (n_dof, 1 if sections > 1 else 2), 0.6), L)
    with pytest.raises(ValueError, match="section"):
        layout.set_shaping(theta, 0, other)


@pytest.mark.parametrize("n_dof", [2, 3])
def test_a_shared_shaping_filter_scales_with_the_wind_speed_and_reads_back(n_dof):
    """One filter for every speed: frequencies as ``U^a``, level as ``rho U^b``, the rest shared.

    Exact to round-off: a written filter reads back as itself at its speed, and the other
    speeds' are its scaled copies; with sway (three forces) every force's sections scale.
    """
    U, rho = np.array([8.0, 12.0, 16.0]), np.array([1.2, 1.2, 1.1])
    U_ref = float(np.exp(np.mean(np.log(U))))
    scaled = np.column_stack([np.log(U / U_ref), np.log(rho / 1.2)])
    layout = _closed_loop_parameters.Layout(n_dof, 2, True, 3, 6, 2, scaled)
    assert layout.noise0 == layout.n_aero + layout.n_shaping + 2
    theta = np.zeros(layout.size)
    theta[layout.noise0 - 2:layout.noise0] = 1.1, 1.6  # the exponents a, b
    f, zeros, L = FILTERS[n_dof]
    filt = ShapingFilter(f, np.full((n_dof, 2), 0.6), L, zeros)
    layout.set_shaping(theta, 1, filt)
    for g in range(3):
        back = layout.shaping(theta, g)
        ratio = U[g] / U[1]
        assert np.allclose(back.frequencies, filt.frequencies * ratio**1.1, rtol=1e-12)
        assert np.allclose(back.L, filt.L * (rho[g] / rho[1]) * ratio**1.6, rtol=1e-12)
        assert np.allclose(back.damping, filt.damping, rtol=1e-12)
        # The zeros keep tau w: they move with the frequencies.
        assert np.allclose(back.zeros * back.frequencies, filt.zeros * filt.frequencies,
                           rtol=1e-12)
    n_y = 2 * n_dof
    assert layout.affecting(_closed_loop_parameters.Record(
        np.zeros((1, n_y)), 100.0, 5, 8.0, 1.2, 2, 0, False)) == [
        *range(layout.n_aero), *range(layout.shaping0, layout.noise0),
        *range(layout.noise0, layout.noise0 + n_y)]


def test_one_shaping_filter_shared_by_the_speeds_fits_the_buffeting_s_scaling():
    """The shared filter finds how the buffeting scales, and the flutter speed as before.

    The test's buffeting keeps its corner at 4 Hz at every speed and grows as ``U^2``
    (:func:`shaping`): exponents 0 and 2, where quasi-steady gusts would give 1 and 1.5 (the
    search's start). Over seeds 0-4 (12 s records) the fitted exponents were -0.13 to
    +0.07 and 1.93 to 2.18 (spreads about 0.08 and 0.1): the bounds of 0.3 are three to
    four of them. The flutter speed within 2.5 std as in the per-speed test above (seeds 0-4:
    within 0.2 points of the per-speed fit's); parameters counted: 7 shaping parameters and
    2 exponents in all, against 7 per speed.
    """
    releases, _, U_F = own_model_releases(seed=0, duration=12.0)
    start = e2rfc.identify(releases, PLATE)
    fit = closed_loop_ml.fit_closed_loop(releases, PLATE, start, n_lags=2,
                                         shared_buffeting=True)
    assert fit.converged
    a, b = fit.shaping_exponents
    assert abs(a) < 0.3 and abs(b - 2.0) < 0.3
    # One section's exponents are not checked (they absorb its misfit of a gust spectrum's
    # shape); two sections' are: not frozen gusts (1 and 1.5), said, with the remedy.
    assert not any("shared by the wind speeds scales as" in w for w in fit.warnings)
    two = closed_loop_ml.fit_closed_loop(releases, PLATE, start, n_lags=2,
                                         shared_buffeting=True, shaping_sections=2)
    a2, _ = two.shaping_exponents
    (note,) = [w for w in two.warnings if "shared by the wind speeds scales as" in w]
    assert f"U^{a2:.2f}" in note and "fourth-order-per-speed" in note
    for sf in fit.shaping:
        assert np.allclose(sf.frequencies, 4.0, rtol=0.15)
    speed, std = flutter_std(fit)
    assert std < 0.10 * U_F
    assert abs(speed - U_F) <= 2.5 * std
    assert fit.n_parameters == 22 + 7 + 2 + 6 * 4 + 6 * 4


def test_the_shared_filter_s_exponents_are_warned_of_only_far_from_frozen_gusts():
    """Beyond the tolerance and three std either exponent warns; within either, none."""
    tol, warn = _closed_loop_parameters.EXPONENT_TOLERANCE, _closed_loop_parameters.exponent_warning
    assert warn((1.0, 1.5), (0.05, 0.05)) == []
    assert warn((1.0 + 0.9 * tol, 1.5 - 0.9 * tol), (0.01, 0.01)) == []
    assert warn((1.0, 1.5 + 1.1 * tol), (0.01, 0.01))
    assert warn((1.0 - 1.1 * tol, 1.5), (0.01, 0.01))
    # Far, but within three of a large std (short records): the data do not say it.
    assert warn((1.0, 1.5 + 2.0 * tol), (tol, tol)) == []


def test_the_refit_without_the_top_speed_starts_from_the_full_fit_s_nuisance():
    """The extrapolation part's refit reaches the same maximum in fewer steps.

    Its shaping filters and noise start from the full fit's (``nuisance_from``), not from the
    records' statistics. Same maximum: -log L within 0.05, and the flutter speed within 0.32
    of its std. The search stops when a full scoring step could gain less than
    ``closed_loop_ml.TOLERANCE`` (0.05) in log L, and a move of k std along the flutter
    speed's direction costs k^2 / 2 of it, so two stopping points can lie sqrt(2 x 0.05) =
    0.32 std apart (measured here: 0.10 std, the warm start in fewer steps).
    """
    releases, _, _ = own_model_releases(seed=0, duration=12.0)
    start = e2rfc.identify(releases, PLATE)
    full = closed_loop_ml.fit_closed_loop(releases, PLATE, start, n_lags=2)
    kept = [0, 1, 2, 3]  # the two lower speeds
    below = [releases[i] for i in kept]
    cold = closed_loop_ml.fit_closed_loop(below, PLATE, full.model)
    warm = closed_loop_ml.fit_closed_loop(below, PLATE, full.model, nuisance_from=(full, kept))
    assert cold.converged and warm.converged
    assert warm.iterations < cold.iterations, (warm.iterations, cold.iterations)
    assert warm.neg_log_likelihood == pytest.approx(cold.neg_log_likelihood, abs=0.05)
    speed_cold, std = flutter_std(cold)
    speed_warm, _ = flutter_std(warm)
    assert abs(speed_warm - speed_cold) < math.sqrt(2 * closed_loop_ml.TOLERANCE) * std
    with pytest.raises(ValueError, match="releases' noise"):
        closed_loop_ml.fit_closed_loop(below, PLATE, full.model, nuisance_from=(full, [0, 1]))


def test_the_fourth_order_buffeting_model_recovers_its_own_model_s_flutter_speed():
    """Two sections per force on exact block means nest the one-section truth: within 2.5 std.

    Seed 0 with 12 s records as the test above (the default model: -1.1 %, std 2.5 %; this one
    +0.8 %, std 3.4 %); the
    richer model fits more parameters and must still cover and converge. Measured on the
    tunnel's von Karman buffeting (plate, 8 releases per speed, 5 seeds) it moved the errors
    from -1.96 to -4.64 % to -2.45 to +0.98 % (docs/development/e2rfc_turbulence.md).
    """
    releases, truth, U_F = own_model_releases(seed=0, duration=12.0)
    start = e2rfc.identify(releases, PLATE)
    fit = closed_loop_ml.fit_closed_loop(releases, PLATE, start, n_lags=2, shaping_sections=2,
                                         exact_block_means=True)
    assert fit.converged
    assert all(sf.n_states == 8 for sf in fit.shaping)
    speed, std = flutter_std(fit)
    assert std < 0.10 * U_F
    assert abs(speed - U_F) <= 2.5 * std
    assert np.all(fit.whiteness < 0.12)
    assert np.all(fit.portmanteau < innovation_checks.portmanteau_limit())


def test_e2rfc_runs_the_closed_loop_branch_in_the_tunnel_s_turbulence():
    """The benchmark's plate campaign at 1 % turbulence (its seed-2 draws), without holds.

    Plain E2RFC (the refined-IV branch without holds keeps its estimate) is +11.1 % off here,
    std 135 %; the closed-loop branch gives -2.9 %, std 3.6 % (all of it the Fisher
    information's, no jackknife part). Bounds: within 2 std, and under 8 % (the benchmark
    row's 90th percentile without holds is 8.4 %, its median 3.3 %).
    """
    releases, U_F = tunnel_releases_seed_2()
    # The second-order model alone, whose pooled warning this checks; the default, by
    # evidence, then fits the fourth-order model (the test below).
    model = e2rfc.identify(releases, PLATE, turbulent_estimator="ml",
                           closed_loop_buffeting="second-order-per-speed")
    assert model.diagnostics.estimator == e2rfc.ESTIMATOR_CLOSED_LOOP
    assert model.n_lags == e2rfc.CLOSED_LOOP_LAGS
    # E2RFC's turbulence warning says its std is the releases' scatter; here it is not.
    warnings = model.diagnostics.warnings
    assert not any("release-to-release scatter" in w for w in warnings)
    assert any("random response" in w and "Fisher information" in w for w in warnings)
    u = model.uncertainty(PLATE)
    assert u.turbulence == 0.0 and u.parametric > 0.0
    # The fit passes its own checks: no cross-check ran, none joins the std.
    assert u.cross_check == 0.0 and model.diagnostics.cross_check is None
    assert not any("failed its own checks" in w for w in warnings)
    # Pooled over the six records the innovations are not white (pitch 117 against a limit
    # of 50; the fourth-order model's are, 12-31 on the benchmark's rows): said, with the
    # remedy.
    (pooled,) = [w for w in warnings if "portmanteau" in w]
    assert "pitch" in pooled and "fourth-order" in pooled and "record holds" in pooled
    assert abs(u.speed - U_F) <= 2.0 * u.total
    assert abs(u.speed / U_F - 1.0) < 0.08
    # No release grew, so the data bound the flutter speed from below at the top speed: a
    # fit fluttering below it (one benchmark seed of the bluff deck did, at 1 % of U_F with
    # a Fisher std of 0.6 %) is widened to reach it and says so.
    top = max(r.U for r in releases)
    assert model.diagnostics.bounded_at == top and model.diagnostics.decayed_at == top
    assert u.below_decay == 0.0
    # The interval is drawn beyond that speed: longer above the estimate than below.
    lower, upper = u.interval()
    assert u.floor == top and top < lower <= U_F <= upper
    assert upper - u.speed > u.speed - lower
    low = IdentifiedModel(model.A, model.d, replace(model.diagnostics, bounded_at=1.5 * u.speed))
    widened = low.uncertainty(PLATE)
    assert widened.below_decay == pytest.approx(0.5 * u.speed)
    assert widened.floor is None  # the speed lies below the stable one: speed +- 2 std
    assert any("no release grew" in w for w in widened.warnings)
    # Had the fit failed its checks, the cross-check's distance would join the std: a second
    # route whose aerodynamic forces are a fifth stronger flutters lower, and the systematic
    # part grows by that distance (to the flutter search's precision, 0.05 m/s).
    stronger = RationalFunctionModel(1.2 * model.A, model.d)
    U_other = fl.analyze(PLATE, stronger).speed
    refits = {**model.diagnostics._refits, "cross_check": ("refined IV", stronger)}
    checked = IdentifiedModel(model.A, model.d, replace(model.diagnostics, _refits=refits))
    crossed = checked.uncertainty(PLATE)
    assert abs(U_other - u.speed) > 0.5
    assert crossed.cross_check == pytest.approx(abs(U_other - u.speed), abs=0.05)
    assert crossed.total**2 == pytest.approx(u.total**2 + crossed.cross_check**2, rel=1e-6)
    assert any(w.startswith("refined IV on the same releases puts the flutter speed at")
               for w in crossed.warnings)


@pytest.mark.slow
def test_the_evidence_takes_the_fourth_order_model_only_where_the_data_ask_for_it():
    """``closed_loop_buffeting="by-evidence"`` on the estimator's own model class and the tunnel.

    Drawn from the second-order model itself (12 s, seed 0), the pooled statistic is 17-27
    against the limit of 50, and the fourth-order fit gains 20-32 in log-likelihood on seeds
    0-3, against the 37 that chance gives its 48 parameters more at the 1 % level: the
    second-order fit stands. On the
    tunnel's 1 % turbulence (the draws of the tunnel test above) the second-order model's pitch
    innovations reach 117: the fourth-order model is fitted too, ends 291 higher in
    log-likelihood (pooled statistic 22), and is kept. It gives -2.8 %, std 5.2 % (the
    second-order model -2.9 %, std 3.6 %): within 2 std and 8 % as there.
    """
    releases, _, _ = own_model_releases(seed=0, duration=12.0)
    model = e2rfc.identify(releases, PLATE, closed_loop_buffeting="by-evidence")
    (note,) = [w for w in model.diagnostics.warnings if "chosen by evidence" in w]
    assert "second-order buffeting model" in note and "are white" in note
    gain = float(note.split("the fourth-order fit is only ")[1].split(" higher")[0])
    needed = float(note.split("(needed: ")[1].split(" for")[0])
    assert 0.0 < gain <= needed
    assert not any("portmanteau" in w for w in model.diagnostics.warnings if w != note)

    releases, U_F = tunnel_releases_seed_2()
    model = e2rfc.identify(releases, PLATE, closed_loop_buffeting="by-evidence")
    (note,) = [w for w in model.diagnostics.warnings if "chosen by evidence" in w]
    assert "fourth-order buffeting model" in note and "not white" in note
    # The tunnel's gusts are frozen (fixed intensity and scale): no word of the scaling.
    assert not any("shared by the wind speeds scales as" in w
                   for w in model.diagnostics.warnings)
    gain = float(note.split("the fourth-order fit is ")[1].split(" higher")[0])
    assert gain > 0.0
    # The chosen fit's own innovations are white pooled: no warning of them remains.
    assert not any("portmanteau" in w for w in model.diagnostics.warnings if w != note)
    u = model.uncertainty(PLATE)
    assert abs(u.speed - U_F) <= 2.0 * u.total
    assert abs(u.speed / U_F - 1.0) < 0.08


@pytest.mark.slow
def test_weak_buffeting_with_white_innovations_takes_the_fourth_order_model_by_likelihood():
    """The bluff deck at Iw 0.5 % (no holds, seed 1): white innovations, a biased second order.

    Under the sensors' noise the buffeting's misfit leaves the second-order model's pooled
    innovations white (statistic 33 < 50), yet it biased the flutter speed low: over seeds 0-16
    a mean of -3.3 %, 14 of 17 below the truth, 3 outside 2 std (this seed -8.8 %, std 3.3 %).
    The fourth-order fit is 44 higher in log-likelihood, beyond the 37 that chance gives its
    extra parameters, and is kept: mean +0.1 %, 8 of 17 below, all 17 within 2 std (this seed
    -5.3 %, std 4.1 %). The bound: 2 std, as for any seed; 7 % is this seed's error with room
    for the last digits of a search that stops on a stall rule.
    """
    truth = bluff_deck_model()
    U_F = fl.analyze(BLUFF_DECK, truth).speed
    wind = {"static": BLUFF_DECK_STATIC, "span": 1.0,
            "turbulence": TurbulenceSpec(Iu=0.0, Iw=0.005, Lux=1.0, Lwx=0.3, Cuy=10.0, Cwy=8.0)}
    releases = [Release.from_simulation(simulate_release(
        BLUFF_DECK, truth, f * U_F, h0, a0, duration=20.0, fs=500.0, noise=0.02,
        rng=(1, i, j, 5), **wind))
        for i, f in enumerate((0.4, 0.6, 0.8)) for j, (h0, a0) in enumerate(HOLDS)]
    model = e2rfc.identify(releases, BLUFF_DECK)
    (note,) = [w for w in model.diagnostics.warnings if "chosen by evidence" in w]
    assert "fourth-order buffeting model" in note and "are white" in note
    assert "beyond the" in note
    u = model.uncertainty(BLUFF_DECK)
    assert abs(u.speed - U_F) <= 2.0 * u.total
    assert abs(u.speed / U_F - 1.0) < 0.07


def first_order_gust_releases(seed):
    """Return the bluff deck's releases in gusts of exponential correlation, without holds.

    The gusts' spectrum falls as ``f^-2`` (first order, Dryden's longitudinal form), where one
    shaping section falls as ``f^-4``; std 0.0186 U (about that of the span-averaged 3 % von
    Karman gusts of ``benchmarks/ident_accuracy.py`` on this deck), scale 0.3 m. Each release
    is simulated with 10 s in the wind before it, which is then dropped.
    """
    truth = bluff_deck_model()
    U_F = fl.analyze(BLUFF_DECK, truth).speed
    spec = TurbulenceSpec(Iu=0.0, Iw=0.03, Lux=1.0, Lwx=0.3, Cuy=10.0, Cwy=8.0)
    releases = []
    for i, fraction in enumerate((0.4, 0.6, 0.8)):
        U = fraction * U_F
        for j, (h0, a0) in enumerate(HOLDS):
            rng = np.random.default_rng((seed, i, j, 777))
            dx = U / 2000.0  # four points per sample at 500 Hz: the interpolation is exact
            n = math.ceil(31.0 * U / dx)
            a = math.exp(-dx / 0.3)
            sigma = 0.0186
            w = scipy.signal.lfilter([1.0], [1.0, -a],
                                     rng.standard_normal(n) * sigma * math.sqrt(1 - a * a),
                                     zi=[a * sigma * rng.standard_normal()])[0]
            values = np.column_stack([np.zeros(n), w])
            values.flags.writeable = False
            field = GustField(spec=spec, B=BLUFF_DECK.B, span=1.0, dx=dx, values=values,
                              x0=10.5 * U)
            releases.append(replace(Release.from_simulation(simulate_release(
                BLUFF_DECK, truth, U, h0, a0, duration=20.0, fs=500.0, noise=0.02, rng=rng,
                static=BLUFF_DECK_STATIC, turbulence=field, pre_s=10.0)), hold=None))
    return releases, U_F


@pytest.mark.slow
def test_the_evidence_does_not_take_a_maximum_the_releases_refute():
    """First-order gusts (seed 25): every second-order maximum is refuted, the fourth-order not.

    One section per force cannot follow an ``f^-2`` force spectrum: with a filter per speed
    the second-order searches (three starts) all end at maxima that flutter below 10.9 m/s,
    where no release grew (the kept one at 0.73 m/s, std 75 % of U_F), 9117 higher in
    log-likelihood than the fourth-order fit with a filter per speed (773 lower than the
    shared one's). The likelihood ratio alone had kept them (on these draws and seed 39's;
    with a two-lag truth on 3 of seeds 20-39); the rule is checked on them. By default (both
    models with one filter shared by the speeds) the second-order model's pooled innovations
    call for the fourth-order one, which gives +2.1 %, std 7.9 % (with a filter per speed:
    +4.6 %, std 6.7 %). Bounds: the truth within 2 std, and 12 %, about the 80th percentile
    of the errors by evidence on seeds 20-39 of a two-lag truth in these gusts (median 5.9 %).
    """
    releases, U_F = first_order_gust_releases(25)
    model = e2rfc.identify(releases, BLUFF_DECK)
    (note,) = [w for w in model.diagnostics.warnings if "chosen by evidence" in w]
    assert "fourth-order buffeting model" in note
    u = model.uncertainty(BLUFF_DECK)
    assert abs(u.speed - U_F) <= 2.0 * u.total
    assert abs(u.speed / U_F - 1.0) < 0.12
    # The rule itself, given the second-order searches with a filter per speed: refuted.
    start = e2rfc.identify(releases, BLUFF_DECK, turbulent_estimator="iv")  # plain E2RFC's
    stable_to = _e2rfc_turbulence.bounded_at(releases)
    second = _e2rfc_turbulence._searched(start, releases, BLUFF_DECK, "second-order-per-speed",
                                         stable_to)
    _, _, chosen, why = _e2rfc_turbulence._by_evidence(start, releases, BLUFF_DECK, stable_to,
                                                       second)
    assert chosen == "fourth-order"
    assert "every second-order maximum found flutters below" in why


@pytest.mark.slow
def test_a_first_maximum_that_the_releases_refute_is_searched_again():
    """The bluff deck in 3 % turbulence without holds (the benchmark row's seed-1 draws).

    With the second-order buffeting model, plain E2RFC's start leads the closed-loop search to
    a maximum fluttering at 0.48 m/s (4 % of U_F), below 8.17 m/s, where no release grew. The
    search runs again from its own coefficients and from the flat plate's; on these draws every
    maximum is refuted (the best flutters at 0.69 m/s), so the one of highest likelihood is
    kept, and the uncertainty takes the distance to 8.17 m/s as its below-decay part: the
    interval (std 75 % of U_F) covers the truth and a warning says why. (Seed 0 had led to such
    a maximum too, before the lag states were held at zero at the release; measured seeds 2-5
    no longer do.) Bounds: the first maximum below a tenth of U_F (what made the search run
    again), the std's below-decay part at least the distance from the kept flutter speed to
    the speed where no release grew, and the truth within 2 std.
    """
    truth = bluff_deck_model()
    U_F = fl.analyze(BLUFF_DECK, truth).speed
    wind = {"static": BLUFF_DECK_STATIC, "span": 1.0, "pre_s": 10.0,
            "turbulence": TurbulenceSpec(Iu=0.0, Iw=0.03, Lux=1.0, Lwx=0.3, Cuy=10.0, Cwy=8.0)}
    releases = [replace(Release.from_simulation(simulate_release(
        BLUFF_DECK, truth, f * U_F, h0, a0, duration=20.0, fs=500.0, noise=0.02,
        rng=(1, i, j, 30), **wind)), hold=None)
        for i, f in enumerate((0.4, 0.6, 0.8)) for j, (h0, a0) in enumerate(HOLDS)]
    # The second-order model alone: by evidence its pooled innovations call for the
    # fourth-order one, whose search starts well and would leave nothing to search again.
    model = e2rfc.identify(releases, BLUFF_DECK, turbulent_estimator="ml",
                           closed_loop_buffeting="second-order-per-speed")
    (note,) = [w for w in model.diagnostics.warnings if "first maximum fluttered" in w]
    first = float(note.split("fluttered at ")[1].split(" m/s")[0])
    assert first < 0.1 * U_F
    assert "from its own coefficients" in note and "from the flat plate's aerodynamics" in note
    bounded = model.diagnostics.bounded_at
    assert bounded is not None and first < bounded
    u = model.uncertainty(BLUFF_DECK)
    assert u.below_decay >= bounded - u.speed > 0.0
    assert abs(u.speed - U_F) <= 2.0 * u.total
    assert any("contradicts the data" in w for w in u.warnings)


def test_a_release_above_flutter_is_not_counted_as_bounded():
    """The records' own growth: at 1.03 U_F the pitch more than doubles, at 0.9 U_F it decays."""
    truth = flat_plate.jones_model()
    U_F = fl.analyze(PLATE, truth).speed
    releases = [Release.from_simulation(simulate_release(
        PLATE, truth, f * U_F, 0.0, 0.01, duration=20.0, fs=500.0, noise=0.02, rng=(5, i)))
        for i, f in enumerate((0.6, 0.9, 1.03))]
    assert _e2rfc_turbulence.bounded_at(releases) == pytest.approx(0.9 * U_F)
    assert _e2rfc_turbulence.bounded_at(releases[2:]) is None


#: The benchmark's variant rows (``benchmarks/ident_accuracy.py --rows variants``, 20 seeds):
#: the plate at Iw 1 % with holds, changed in one thing. name -> (change, |error| bound, std
#: multiple the error must lie within). Measured rows with the default buffeting model, chosen
#: by evidence, the lag states held at zero at the release (median / p90 |error|, 2-std
#: cover): non-Gaussian gusts (skewness 0.5, kurtosis 4.5) 4.02 / 5.82 %, 85 %; Coulomb friction
#: at its realistic strength 2.94 / 8.97 %, 100 %; a Davenport admittance with a 1 m scale (a
#: force spectrum the second-order filter matches worse, the fourth-order one taken on every
#: seed) 4.49 / 8.51 %, 85 %. Seed 0 of each (not chosen: the first): -5.39 % (std 4.45 %),
#: +8.93 % (8.88 %), -6.49 % (3.80 %). The error bounds lie at or above the rows' 90th
#: percentiles; the std multiple is 2, the rows having covered 85-100 %.
VARIANTS = {
    "non-Gaussian gusts": ({"gusts": {"skewness": 0.5, "kurtosis": 4.5}}, 0.08, 2.0),
    "friction": ({"effects": ("coulomb_friction",)}, 0.10, 2.0),
    "Davenport, 1 m": ({"gusts": {"Lwx": 1.0, "admittance": "davenport"}}, 0.09, 2.0),
}


@pytest.mark.slow
@pytest.mark.parametrize("variant", list(VARIANTS))
def test_the_branch_holds_where_the_tunnel_is_not_its_model(variant):
    """The closed-loop branch's error and interval where the tunnel is not its model.

    Gusts that are not Gaussian, friction the model lacks, a buffeting spectrum further from
    the shaping filter's (bounds at :data:`VARIANTS`).
    """
    change, bound, multiple = VARIANTS[variant]
    truth = flat_plate.jones_model()
    U_F = fl.analyze(PLATE, truth).speed
    gusts = TurbulenceSpec(**{"Iu": 0.0, "Iw": 0.01, "Lux": 1.0, "Lwx": 0.3, "Cuy": 10.0,
                              "Cwy": 8.0, **change.get("gusts", {})})
    effects = [scaled(name, 1.0) for name in change.get("effects", ())]
    releases = [Release.from_simulation(simulate_release(
        PLATE, truth, f * U_F, h0, a0, duration=20.0, fs=500.0, noise=0.02,
        rng=(0, i, j, 10), effects=effects, static=StaticCoefficients.flat_plate(), span=1.0,
        turbulence=gusts, pre_s=10.0))
        for i, f in enumerate((0.4, 0.6, 0.8)) for j, (h0, a0) in enumerate(HOLDS)]
    model = e2rfc.identify(releases, PLATE, turbulent_estimator="ml")
    assert model.diagnostics.estimator == e2rfc.ESTIMATOR_CLOSED_LOOP
    u = model.uncertainty(PLATE)
    assert u.speed is not None
    assert abs(u.speed / U_F - 1.0) < bound
    assert abs(u.speed - U_F) <= multiple * u.total
    assert u.total < 0.25 * U_F  # not a blanket: the rows' median stds are 3.8-7.5 %
    # Friction fails the fit's own checks (force innovations far from white, 0.52-0.71 over
    # the benchmark's seeds): refined IV on the same releases checks it, and the distance
    # joins the std, said in a warning. The other variants pass (0.06-0.18).
    failed = any("failed its own checks" in w for w in model.diagnostics.warnings)
    assert failed == (variant == "friction")
    if failed:
        assert model.diagnostics.cross_check is not None and u.cross_check > 0.0
        assert any(w.startswith("refined IV on the same releases ") and "the deviation "
                   "includes the difference" in w for w in u.warnings)
    else:
        assert u.cross_check == 0.0


@pytest.mark.slow
@pytest.mark.parametrize("force", ["lift", "moment"])
def test_a_force_of_the_wrong_sign_in_turbulence_is_refused_naming_it(force):
    """The plate at 1 % turbulence (seed-2 draws, no holds), a force negated.

    Unguarded, the branch gave -0.3 % (std 5.5 %) here, its failed checks warned of but not the
    sign, and flutter derivatives whose lift row has it flipped (on the benchmark's seed 1:
    -99 %). In closed loop the fitted H1* stays negative, the motion's own damping speaking for
    it. With the lift negated back, the fit passes the checks the given one fails, far higher
    in log L (the friction variant above, which fails them too, is not refused: negating a
    force makes its fit no better). A flipped moment had stopped the branch on scipy's
    bracketing error (a restart's maximum unstable in still air).
    """
    releases, _ = tunnel_releases_seed_2()
    flipped = [_e2rfc_turbulence._negated(r, force) for r in releases]
    with pytest.raises(PlausibilityError, match=rf"the {force}'s sign looks flipped.*negate "
                                                rf"the {force}$"):
        e2rfc.identify(flipped, PLATE, turbulent_estimator="ml")


def test_a_channel_measured_almost_without_noise_is_not_trusted_beyond_the_floor():
    """Lasers far cleaner than the sync view's alignment: the noise floor binds.

    Releases of the model class with the displacements' noise 10^-4 of the other tests': the
    fitted noise of h and alpha is the floor (NOISE_FLOOR of each channel's std over its
    release, at the decimated rate), never below it, and the forces' noise (above the floor)
    is fitted freely. The floor is what kept the simulated rig's fixed plan at +0.6 % instead
    of -7.6 % (the constant's note). Such data also drove a forward difference of the Fisher
    information out of the stable models (no Riccati solution): a backward one is taken there.
    """
    truth = flat_plate.jones_model()
    U_F = fl.analyze(PLATE, truth).speed
    clean = NOISE * np.array([1e-4, 1e-4, 1.0, 1.0])
    rng = np.random.default_rng(4)
    releases = []
    for fraction in (0.4, 0.6, 0.8):
        U = fraction * U_F
        model = ReleaseModel(PLATE, truth, U, 200.0, shaping(U), clean)
        for h0, a0 in HOLDS:
            y = model.sample(model.initial_state(h0, a0), model.initial_covariance(), 1200, rng)
            releases.append(Release(t=np.arange(1200) / 200.0, h=y[:, 0], alpha=y[:, 1],
                                    lift=y[:, 2], moment=y[:, 3], U=U))
    fit = closed_loop_ml.fit_closed_loop(releases, PLATE, truth, n_lags=2)
    factor = _closed_loop_parameters.block_size(200.0, max(PLATE.fh, PLATE.fa))
    for r, noise in zip(releases, fit.noise_std, strict=True):
        y = _closed_loop_parameters.decimate(np.column_stack([r.h, r.alpha, r.lift, r.moment]),
                                             factor)
        floor = _closed_loop_parameters.NOISE_FLOOR * np.std(y, axis=0)
        assert np.all(noise >= floor * (1 - 1e-9))
        np.testing.assert_allclose(noise[:2], floor[:2], rtol=1e-6)
        assert np.all(noise[2:] > floor[2:])


@pytest.mark.parametrize(("change", "match"), [
    ("one speed", "two or more wind speeds"),
    ("three dof", "differ in their degrees of freedom"),
    ("no sections", "shaping_sections must be an integer >= 1"),
])
def test_bad_input_raises_one_clear_error(change, match):
    releases, truth, _ = own_model_releases(seed=1, duration=2.0, fs=200.0)
    section, options = PLATE, {}
    if change == "one speed":
        releases = releases[:2]
    elif change == "three dof":
        section = PLATE.replace(fp=1.5)
    else:
        options = {"shaping_sections": 0}
    with pytest.raises(ValueError, match=match):
        closed_loop_ml.fit_closed_loop(releases, section, truth, **options)


def with_time_axis(release, t):
    """Return ``release`` with the time axis ``t`` (the same samples)."""
    return Release(t=t, h=release.h, alpha=release.alpha, lift=release.lift,
                   moment=release.moment, U=release.U)


def test_a_rate_a_rounding_short_of_round_decimates_as_the_round_rate():
    """Records on a synchronised time base come out at 499.9999999999999 Hz for 500 Hz.

    The floor of 499.9999999999999 / 100 is 4, not 5: such releases were decimated by 4 and
    then discretised as if decimated by 5 (a rig campaign's fit landed at -33 % that way). The
    fit must not see the rounding: rates that differ by rounding share one discretisation, so
    the two fits are the same to round-off.
    """
    releases, truth, _ = own_model_releases(seed=2, duration=6.0, fs=500.0)
    rounded = [with_time_axis(r, r.t * (1.0 + 4e-16)) if i >= 2 else r
               for i, r in enumerate(releases)]
    assert rounded[2].fs < 500.0 and int(rounded[2].fs // 100.0) == 4  # the case bites
    exact = closed_loop_ml.fit_closed_loop(releases, PLATE, truth, n_lags=2)
    shifted = closed_loop_ml.fit_closed_loop(rounded, PLATE, truth, n_lags=2)
    assert shifted.neg_log_likelihood == pytest.approx(exact.neg_log_likelihood, rel=1e-12)
    np.testing.assert_allclose(shifted.model.A, exact.model.A, rtol=1e-9, atol=1e-12)


def test_releases_at_different_rates_are_each_discretised_at_their_own():
    """A release recorded at half the rate joins the others: each record at its own rate.

    Its decimated rate differs (125 Hz against 100 Hz), so the likelihood needs its own
    discretisation; with one shared one it would be a different system. Checked against the
    fit with every release at the full rate: the flutter speed moves by less than half its
    standard deviation (one release of six changed, and only in its sampling), and both lie
    within two standard deviations of the truth.
    """
    releases, truth, U_F = own_model_releases(seed=1, duration=8.0, fs=500.0)
    half = [with_time_axis(r, r.t) for r in releases]
    r = releases[0]
    half[0] = Release(t=r.t[::2], h=r.h[::2], alpha=r.alpha[::2], lift=r.lift[::2],
                      moment=r.moment[::2], U=r.U)
    full = closed_loop_ml.fit_closed_loop(releases, PLATE, truth, n_lags=2)
    mixed = closed_loop_ml.fit_closed_loop(half, PLATE, truth, n_lags=2)
    assert mixed.fs == pytest.approx(100.0)
    (U_full, std_full), (U_mixed, std_mixed) = flutter_std(full), flutter_std(mixed)
    assert abs(U_mixed - U_full) < 0.5 * std_full
    assert abs(U_mixed - U_F) < 2 * std_mixed and abs(U_full - U_F) < 2 * std_full


def test_the_plate_start_of_a_section_with_sway_keeps_the_fit_s_sway_terms():
    """The restart from Jones's plate, for a 3-DOF fit: the plate in heave and pitch.

    The plate has no drag: its heave-pitch block is Jones's (lags and roots too), the sway
    rows and columns of A1-A3 the fit's own, the sway's lag terms zero; a planar fit gets the
    plate itself.
    """
    plate = flat_plate.jones_model()
    found = plate.with_sway(quasi_steady_model(StaticCoefficients.flat_plate()))
    found = RationalFunctionModel(found.A * 1.3, found.d * 0.8)  # not the plate's
    start = _closed_loop_starts._plate_start(found)
    assert start.A.shape == (5, 3, 3)
    np.testing.assert_array_equal(start.A[:, :2, :2], plate.A)
    np.testing.assert_array_equal(start.d, plate.d)
    np.testing.assert_array_equal(start.A[:3, 2, :], found.A[:3, 2, :])
    np.testing.assert_array_equal(start.A[:3, :, 2], found.A[:3, :, 2])
    assert not np.any(start.A[3:, 2, :]) and not np.any(start.A[3:, :, 2])
    np.testing.assert_array_equal(_closed_loop_starts._plate_start(plate).A, plate.A)


def test_the_estimator_is_chosen_by_name_and_runs_on_a_3dof_section():
    """A wrong estimator name is one clear error; "ml" runs on a section with sway too.

    A plate with a lateral spring (Jones's lags with quasi-steady drag, of the fit's form) in
    1 % vertical gusts, short releases at 200 Hz with 3 s holds: the closed-loop likelihood
    runs (sway and drag among its channels) and its interval covers the truth. On the
    benchmark's 3-DOF bluff deck (``ident_accuracy_3dof.py --part turbulent``, 20 seeds of
    20 s releases) the interval covered 18-20 of 20 on each row (114 of 120), so one seed
    missing it would be a one-in-twenty event; this seed's error is well inside (-2.1 %,
    std 6.3 %).
    """
    releases, _, _ = own_model_releases(seed=1, duration=2.0, fs=200.0)
    with pytest.raises(ValueError, match=r"turbulent_estimator must be one of \('iv', 'ml'\)"):
        e2rfc.identify(releases, PLATE, turbulent_estimator="kalman")
    with pytest.raises(ValueError, match=r"closed_loop_buffeting must be one of "
                       r"\('second-order', 'fourth-order', 'second-order-per-speed', "
                       r"'fourth-order-per-speed', 'fourth-order-mixed', "
                       r"'fourth-order-mixed-per-speed', 'by-evidence'\), "
                       r"got 'sixth-order'"):
        e2rfc.identify(releases, PLATE, closed_loop_buffeting="sixth-order")
    sway = PLATE.replace(fp=1.3, zeta_p=0.004)
    truth = flat_plate.jones_model().with_sway(quasi_steady_model(StaticCoefficients.flat_plate()))
    U_F = fl.analyze(sway, truth).speed
    wind = {"static": StaticCoefficients.flat_plate(), "span": 1.0, "pre_s": 3.0,
            "turbulence": TurbulenceSpec(Iu=0.0, Iw=0.01, Lux=1.0, Lwx=0.3, Cuy=10.0, Cwy=8.0)}
    releases = [Release.from_simulation(simulate_release(
        sway, truth, f * U_F, h0, 0.02, p0=p0, duration=8.0, fs=200.0, noise=0.02,
        rng=(1, i, j), **wind)) for i, f in enumerate((0.4, 0.6, 0.8))
        for j, (h0, p0) in enumerate(((0.01, 0.008), (-0.008, -0.01)))]
    model = e2rfc.identify(releases, sway, turbulent_estimator="ml")
    assert model.diagnostics.turbulent
    assert model.diagnostics.estimator == e2rfc.ESTIMATOR_CLOSED_LOOP
    assert model.n_dof == 3
    uncertainty = model.uncertainty(sway)
    low, high = uncertainty.interval()
    assert low <= U_F <= high
