"""E2RFC identification from simulated releases: accuracy, model choice and refusals."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from ident import RankDeficiencyError, RationalFunctionModel, Release, roger_fit
from ident.identification import e2rfc, results
from ident.identification._e2rfc_problem import MAX_CONDITION
from ident.model import flat_plate, flutter
from ident.numerics.selection import structure_label, within_one_se
from simulators import simulate_release

from support.sections import FLAT_PLATE

JONES = flat_plate.jones_model()
U_F = flutter.analyze(FLAT_PLATE, JONES).speed


def releases(model, fractions=(0.4, 0.6, 0.8), *, U_ref=U_F, noise=0.0, seed=0, duration=20.0,
             fs=500.0):
    """Releases of the section from (4 mm, 0.02 rad) at fractions of a reference speed."""
    return [
        Release.from_simulation(simulate_release(
            FLAT_PLATE, model, f * U_ref, 0.004, 0.02, duration=duration, fs=fs, noise=noise,
            rng=seed * 101 + i))
        for i, f in enumerate(fractions)
    ]


def test_noise_free_releases_give_the_exact_rfcs():
    """Without noise, two wind speeds recover Jones's lags and coefficients to round-off level."""
    model = e2rfc.identify(releases(JONES, (0.5, 0.8), duration=10.0, fs=250.0), FLAT_PLATE,
                           n_lags=2, with_A3=True)
    assert isinstance(model, RationalFunctionModel)
    # The regressors are exact closed forms of an exactly fitted decay; what is left is the
    # nonlinear solver's tolerance (1e-10 in log d) amplified by the conditioning (~50).
    np.testing.assert_allclose(model.d, JONES.d, rtol=1e-6)
    np.testing.assert_allclose(model.A, JONES.A, atol=1e-5 * np.abs(JONES.A).max())
    assert flutter.analyze(FLAT_PLATE, model).speed == pytest.approx(U_F, rel=1e-7)


@pytest.mark.parametrize("seed", [0, 1])
def test_two_percent_noise_gives_the_flutter_speed_within_one_and_a_half_percent(seed):
    """The issue's case (2 % noise, 3 speeds, structure by evidence) is within 1.5 %.

    Wind speeds 0.4, 0.6 and 0.8 U_F, 20 s at 500 Hz, noise on all four channels.
    """
    model = e2rfc.identify(releases(JONES, noise=0.02, seed=seed), FLAT_PLATE)
    result, std = model.flutter(FLAT_PLATE)
    assert result.speed == pytest.approx(U_F, rel=0.015)
    assert model.diagnostics.n_lags == 2 and model.diagnostics.with_A3  # the true structure
    assert std is not None and 0.0 < std < 0.01 * U_F
    # Residuals sit at the noise level: 2 % of each force channel's RMS (within 10 %).
    np.testing.assert_allclose(model.diagnostics.release_residuals, 0.02, rtol=0.1)


def test_selection_prefers_the_simplest_adequate_structure():
    """A one-lag truth without added mass is identified as one lag without A3."""
    K = np.linspace(0.2, 3.0, 40)
    one_lag = roger_fit(K, flat_plate.flutter_derivatives(K), [0.25], with_A3=False)
    U_ref = flutter.analyze(FLAT_PLATE, one_lag).speed
    model = e2rfc.identify(releases(one_lag, U_ref=U_ref, noise=0.02, seed=3), FLAT_PLATE)
    diagnostics = model.diagnostics
    assert (diagnostics.n_lags, diagnostics.with_A3) == (1, False)
    assert model.d[0] == pytest.approx(0.25, rel=0.02)  # ~0.3 % observed; 2 % is 6 sigma-ish
    assert "simplest structure" in diagnostics.reason
    tried = {(c.n_lags, c.with_A3) for c in diagnostics.candidates}
    assert {(0, True), (0, False), (1, True), (1, False)} <= tried
    zero_lag = min((c for c in diagnostics.candidates if c.n_lags == 0),
                   key=lambda c: c.cv_error)
    # Quasi-steady forces cannot describe lagged ones: far worse than the noise level.
    assert zero_lag.cv_error > 10 * min(c.cv_error for c in diagnostics.candidates)


def test_a_record_starting_after_the_release_is_handled():
    """Lag states start at the release (t = 0) even if the record starts 50 ms later."""
    late = []
    for rel in releases(JONES, duration=10.0, fs=500.0):
        keep = rel.t >= 0.05
        late.append(Release(t=rel.t[keep], h=rel.h[keep], alpha=rel.alpha[keep],
                            lift=rel.lift[keep], moment=rel.moment[keep], U=rel.U))
    model = e2rfc.identify(late, FLAT_PLATE, n_lags=2, with_A3=True)
    # The modal fit extrapolates exactly back to t = 0 on noise-free data.
    np.testing.assert_allclose(model.d, JONES.d, rtol=1e-5)


@pytest.mark.parametrize("duration", [1.6, 2.4])
def test_short_releases_are_identified(duration):
    """Releases of 3-5 heave periods (a campaign that ends each decay once it has settled).

    Such a record used to be refused as "too few samples" (its modal fit's blocks were sized
    for the slowest mode alone) or crash the structure search (a cross-validation fold with no
    rows). Noise-free, the model is exact (round-off); at 2 % noise within 1 %, about five
    times the flutter-speed std measured on these records (0.15-0.18 %).
    """
    exact = e2rfc.identify(releases(JONES, duration=duration, seed=1), FLAT_PLATE)
    assert exact.flutter(FLAT_PLATE)[0].speed == pytest.approx(U_F, rel=1e-9)
    noisy = e2rfc.identify(releases(JONES, duration=duration, noise=0.02, seed=1), FLAT_PLATE)
    result, std = noisy.flutter(FLAT_PLATE)
    assert result.speed == pytest.approx(U_F, rel=0.01)
    assert std is not None and 0.0 < std < 0.01 * U_F


def test_one_wind_speed_is_refused_with_a_clear_message():
    """Several releases at one wind speed are rank deficient: an error, never numbers."""
    same_speed = releases(JONES, (0.6, 0.605), duration=10.0, fs=250.0)  # within 2 %
    with pytest.raises(RankDeficiencyError, match="two or more wind speeds"):
        e2rfc.identify(same_speed, FLAT_PLATE)
    with pytest.raises(RankDeficiencyError, match="no releases given"):
        e2rfc.identify([], FLAT_PLATE)


def test_bad_arguments_are_refused():
    """Non-Release inputs are a TypeError; an impossible lag count a ValueError."""
    good = releases(JONES, (0.5, 0.8), duration=10.0, fs=250.0)
    with pytest.raises(TypeError, match="ident.Release"):
        e2rfc.identify([good[0], "release.h5"], FLAT_PLATE)
    with pytest.raises(ValueError, match="n_lags must be an integer in 0..3"):
        e2rfc.identify(good, FLAT_PLATE, n_lags=5)


def test_diagnostics_are_complete_and_consistent():
    """Covariance, parameter index, modal fits and wind speeds describe the same fit."""
    data = releases(JONES, noise=0.02, seed=5, duration=12.0)
    model = e2rfc.identify(data, FLAT_PLATE, n_lags=2, with_A3=True)
    diagnostics = model.diagnostics
    n_coef = len(diagnostics.parameter_index)
    assert n_coef == 2 * 2 * (3 + 2)  # two force rows x (A1, A2, A3, A4, A5) x two columns
    assert diagnostics.covariance.shape == (n_coef + 2, n_coef + 2)
    assert np.all(np.diag(diagnostics.covariance) > 0)
    np.testing.assert_allclose(diagnostics.wind_speeds, [r.U for r in data])
    assert len(diagnostics.modal_fits) == len(data)
    assert diagnostics.reason == "given by the caller"
    assert 1.0 <= diagnostics.condition_number < MAX_CONDITION
    for k, i, j in diagnostics.parameter_index:
        assert model.A[k, i, j] != 0.0


def test_the_structures_the_data_cannot_tell_apart_are_fitted_and_their_spread_reported():
    """Every structure within one SE of the best is fitted; its flutter speed is reported.

    Short releases (4 s, one per speed, 2 % noise): seed 1 leaves 2 and 3 lags within one
    standard error of each other (found by trying seeds 0-11: 1 and 11 do, the others give one
    structure).
    """
    data = releases(JONES, (0.46, 0.59, 0.72), noise=0.02, seed=1, duration=4.0)
    model = e2rfc.identify(data, FLAT_PLATE)
    diagnostics = model.diagnostics
    usable = [c for c in diagnostics.candidates if not c.note]
    plausible = {c.label for c in within_one_se(usable)}
    assert len(plausible) >= 2  # the case this test is about
    spread = model.structure_spread(FLAT_PLATE)
    chosen = structure_label(diagnostics.n_lags, diagnostics.with_A3)
    assert spread.labels[0] == chosen and set(spread.labels) == plausible
    assert len(spread.labels) == len(diagnostics.alternatives) + 1
    result, std = model.flutter(FLAT_PLATE)
    uncertainty = model.uncertainty(FLAT_PLATE)
    # The spread reports each structure's own (parametric) deviation; the model's flutter()
    # deviation is the total, which holds the structures' spread too.
    assert (spread.speeds[0], spread.stds[0]) == (result.speed, uncertainty.parametric)
    assert std == uncertainty.total and uncertainty.structure > 0.0
    assert uncertainty.structure == pytest.approx(
        float(np.std([s for s in spread.speeds if s is not None], ddof=1)), rel=1e-3)
    for alternative, label in zip(diagnostics.alternatives, spread.labels[1:], strict=True):
        alt = alternative.diagnostics
        assert label == structure_label(alt.n_lags, alt.with_A3)
        assert alt.alternatives == () and "not chosen" in alt.reason
        # Fitted on every sample as the chosen one is: force residuals at the 2 % noise level
        # (10 %: the spread of a noise RMS estimate over these ~2000 samples is ~2 %, plus the
        # structure's own misfit, which within one SE of the best is small).
        np.testing.assert_allclose(alt.release_residuals, 0.02, rtol=0.1)
    assert spread.low == min(spread.speeds) and spread.high == max(spread.speeds)
    assert spread.low < spread.high
    assert spread.summary() == (f"{spread.low:.2f}-{spread.high:.2f} m/s over "
                                f"{len(plausible)} structures within one SE")


def test_a_structure_given_by_the_caller_has_no_alternatives():
    data = releases(JONES, (0.5, 0.8), duration=6.0, fs=250.0)
    model = e2rfc.identify(data, FLAT_PLATE, n_lags=2, with_A3=True)
    assert model.diagnostics.alternatives == ()
    spread = model.structure_spread(FLAT_PLATE)
    assert spread.labels == ("n_lags=2, A3=fitted",)
    assert spread.low == spread.high == pytest.approx(U_F, rel=1e-6)
    assert spread.summary() == "one structure within one SE"


def test_an_alternative_without_still_air_modes_widens_the_spread_instead_of_failing():
    """A wild alternative (an added mass that overturns the structure's) has no flutter search.

    Seen in a campaign's first two speeds: the spread and the flutter speed's structure term
    then count it as "no flutter below U_max", as the refits do, rather than raising.
    """
    data = releases(JONES, (0.5, 0.8), duration=6.0, fs=250.0)
    model = e2rfc.identify(data, FLAT_PLATE, n_lags=2, with_A3=True)
    A = model.A.copy()
    A[2] = 1e3 * np.eye(2)  # A3 1000 times the plate's: the heave and pitch inertia overturned
    wild = results.IdentifiedModel(A, model.d, model.diagnostics)
    with pytest.raises(flutter.StillAirModesError, match="oscillatory still-air modes"):
        flutter.analyze(FLAT_PLATE, wild)
    with_wild = results.IdentifiedModel(model.A, model.d, dataclasses.replace(
        model.diagnostics, alternatives=(wild,)))
    spread = with_wild.structure_spread(FLAT_PLATE)
    assert spread.speeds[0] == pytest.approx(U_F, rel=1e-6) and spread.speeds[1] is None
    assert spread.high == np.inf
    uncertainty = with_wild.uncertainty(FLAT_PLATE)
    # The wild one counted at U_max: the structure term is the spread of (U_F, U_max).
    assert uncertainty.structure == pytest.approx(
        float(np.std([U_F, spread.U_max], ddof=1)), rel=1e-3)


@pytest.mark.parametrize("finer_kind, rejected, expected", [
    ("none", True, "zero"),          # no flutter below U_max, rejected: fitting the noise
    ("none", False, "to U_max"),     # no flutter, as good as the best: counts to U_max
    ("low", True, "zero"),           # flutters below a decayed release, rejected
    ("low", False, "to stable"),     # flutters below a decayed release: counted from there
    ("in range", True, "its move"),  # flutters where the data allow: its move counts
])
def test_one_lag_more_counts_only_where_the_data_allow_it(finer_kind, rejected, expected):
    """The refinement part of the flutter speed's std (the model with one lag more).

    Seen in campaigns of one short release per speed: a four-lag refit, rejected by the held-out
    error, fluttered at 0.1 m/s (or not at all) and made the std as large as the speed. Such a
    refit counts only when the held-out error does not reject it, and never below the highest
    wind speed where a release decayed on both modes (the data bound the flutter speed there).
    """
    model = e2rfc.identify(releases(JONES, noise=0.02, seed=2), FLAT_PLATE)
    diag = model.diagnostics
    stable = diag.decayed_at
    assert stable == pytest.approx(0.8 * U_F)
    finer = {"none": RationalFunctionModel(np.zeros_like(JONES.A), JONES.d),
             "low": RationalFunctionModel(10.0 * JONES.A, JONES.d),
             "in range": RationalFunctionModel(1.05 * JONES.A, JONES.d)}[finer_kind]
    finer_speed = flutter.analyze(FLAT_PLATE, finer).speed
    injected = results.IdentifiedModel(model.A, model.d, dataclasses.replace(
        diag, _refits={**diag._refits, "finer": finer, "finer_rejected": rejected}))
    u = injected.uncertainty(FLAT_PLATE)
    move = {"zero": 0.0, "to U_max": flutter.analyze(FLAT_PLATE, model).U_max - u.speed,
            "to stable": u.speed - stable,
            "its move": abs((finer_speed or math.nan) - u.speed)}[expected]
    # The refit's speed comes from a coarser grid (REFIT_GRID points) than the chosen model's.
    assert u.refinement == pytest.approx(move, rel=1e-3, abs=1e-9)
    if finer_kind == "low":
        assert finer_speed is not None and finer_speed < stable
    if finer_kind == "none":
        assert finer_speed is None


def test_the_rejection_of_one_lag_more_is_the_candidates_held_out_error():
    """``finer_rejected`` scores the refit as the structure search scores its candidates."""
    from ident.identification._e2rfc_problem import Problem

    model = e2rfc.identify(releases(JONES, noise=0.02, seed=2), FLAT_PLATE)
    diag = model.diagnostics
    problem = Problem(list(diag._prepared))
    for c in diag.candidates:
        if math.isfinite(c.cv_error):
            assert problem.held_out_error(np.array(c.d), c.with_A3) == pytest.approx(
                c.cv_error, rel=1e-9)
    best = min((c for c in diag.candidates if math.isfinite(c.cv_error)),
               key=lambda c: c.cv_error)
    assert diag.finer is not None
    error = problem.held_out_error(diag.finer.d, diag.with_A3)
    assert diag.finer_rejected == (error > best.cv_error + best.cv_se)


def test_a_structure_without_flutter_leaves_the_spread_open_above():
    """No flutter below U_max for one structure: the high end is infinite, and said so."""
    spread = results.StructureSpread(("n_lags=1, A3=zero", "n_lags=2, A3=zero"), (12.0, None),
                                   (0.1, None), 40.0)
    assert (spread.low, spread.high) == (12.0, np.inf)
    assert spread.summary() == ("12.00 m/s to no flutter below 40 m/s over 2 structures within "
                                "one SE")
    none = results.StructureSpread(("a", "b"), (None, None), (None, None), 40.0)
    assert (none.low, none.high) == (None, None)
    assert none.summary() == "no flutter below 40 m/s over 2 structures within one SE"


def test_the_lag_roots_of_an_ill_determined_alternative_are_converged_on_all_the_data():
    """The 3-lag alternative at 5 % noise ends at a stationary point of the full-data cost.

    The search converges on a subsample and then takes one Gauss-Newton step on every sample.
    For this alternative (the accuracy benchmark's plate at 5 % noise, seed 1) that step was
    0.71 in log d, not the small move it assumes, and where it landed depended on round-off
    (the alternative's flutter speed, hence the structure spread, moved 2 %). Stationary: a
    further step predicts a relative cost decrease below 1e-8 (converged: 3e-11; after the one
    step: 3.5e-4).
    """
    from ident.identification._e2rfc_problem import Problem
    from ident.identification._regressors import prepare

    section = FLAT_PLATE
    U_flutter = flutter.analyze(section, JONES).speed
    data = [Release.from_simulation(simulate_release(
        section, JONES, f * U_flutter, 0.004, 0.02, duration=20.0, fs=500.0, noise=0.05,
        rng=(1, i, 50))) for i, f in enumerate((0.4, 0.6, 0.8))]
    model = e2rfc.identify(data, section)
    alternatives = model.diagnostics.alternatives
    assert [a.diagnostics.n_lags for a in alternatives] == [3]  # the case this test is about
    problem = Problem([prepare(r, section) for r in data])
    full = problem._stacked(alternatives[0].diagnostics.with_A3, "full")
    theta = np.log(alternatives[0].d)
    J, r = full.jacobian(theta), full.residual(theta)
    step, *_ = np.linalg.lstsq(J, -r, rcond=None)
    assert np.sum((J @ step) ** 2) / np.sum(r**2) < 1e-8
