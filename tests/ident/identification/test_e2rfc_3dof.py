"""E2RFC with three degrees of freedom: the 3x3 RFCs from releases with sway and drag.

Independent checks: noise-free releases of an exact Roger model (the Jones flat plate completed
with quasi-steady drag terms) give back its coefficients and lag roots; releases of the bluff
deck (ten lags of its own: not of the fitted form) give the flutter speed of the state-space
analysis of the truth, within the reported deviation; the flutter derivatives of an exact
Roger model fall within their reported deviation about as often as a 2-std interval should.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from ident import Release
from ident.errors import RankDeficiencyError
from ident.identification import e2rfc
from ident.identification._regressors import prepare
from ident.model import flat_plate
from ident.model import flutter as fl
from ident.model.quasi_steady import StaticCoefficients, quasi_steady_model
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.physics.turbulence import TurbulenceSpec
from simulators.decks import BLUFF_DECK_3DOF, BLUFF_DECK_3DOF_STATIC, bluff_deck_3dof_model
from simulators.tunnel import simulate_release

SWAY = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005,
                    fp=1.3, zeta_p=0.004)
#: A bluff deck's static coefficients (drag and its slope couple sway to pitch).
BLUFF = StaticCoefficients(C_D=0.9, C_L=-0.15, C_M=0.02, dC_D=-0.4, dC_L=-4.5, dC_M=1.1)
#: Holds (h, alpha, p) of the two releases per wind speed: every mode displaced.
HOLDS = ((0.004, 0.02, 0.004), (-0.0032, 0.015, -0.0048))


def _plate() -> RationalFunctionModel:
    return flat_plate.jones_model().with_sway(quasi_steady_model(BLUFF))


def _campaign(section: SectionModel, truth: RationalFunctionModel, speeds: tuple[float, ...],
              noise: float, seed: int, holds: tuple[tuple[float, float, float], ...] = HOLDS,
              duration: float = 20.0) -> list[Release]:
    rng = np.random.default_rng(seed)
    return [Release.from_simulation(simulate_release(
        section, truth, U, h0, a0, p0=p0, duration=duration, fs=500.0, noise=noise, rng=rng))
        for U in speeds for h0, a0, p0 in holds]


def test_noise_free_releases_give_back_an_exact_roger_model():
    """The plate's two Jones lags and its 3x3 A_k (drag rows and columns too), to 1e-4.

    The regressors come from a modal fit of noise-free decays (exact to its tolerance), so the
    coefficients are recovered to far better than any noise would allow; 1e-4 of the largest
    coefficient leaves room for the fit's convergence tolerance.
    """
    truth = _plate()
    U_F = float(fl.analyze(SWAY, truth).speed)  # type: ignore[arg-type]
    releases = _campaign(SWAY, truth, (0.45 * U_F, 0.65 * U_F, 0.8 * U_F), 0.0, 0)
    model = e2rfc.identify(releases, SWAY, n_lags=2, with_A3=True)
    assert model.n_dof == 3 and model.A.shape == (5, 3, 3)
    np.testing.assert_allclose(model.d, truth.d, rtol=1e-4)
    np.testing.assert_allclose(model.A, truth.A, rtol=0, atol=1e-4 * np.abs(truth.A).max())


def test_bluff_deck_flutter_speed_within_one_percent_and_its_deviation():
    """2 % noise, 3 speeds x 2 releases: within 1 % (the issue's target) and within 2 std.

    The deck's aerodynamics have ten lags, so the fitted model (at most three) is not the
    truth's form: the benchmark (benchmarks/ident_accuracy_3dof.py) measures a median error
    of 0.12 % and a 90th percentile of 0.18 % over ten seeds; 1 % is the issue's target, and
    2 std the interval that should hold 95 % of the time (this seed is the benchmark's first).
    """
    truth = bluff_deck_3dof_model()
    result = fl.analyze(BLUFF_DECK_3DOF, truth)
    U_F = float(result.speed)  # type: ignore[arg-type]
    holds = ((0.010, 0.03, 0.010), (-0.008, 0.02, -0.012))
    releases = _campaign(BLUFF_DECK_3DOF, truth, (0.45 * U_F, 0.65 * U_F, 0.8 * U_F), 0.02, 0,
                         holds)
    model = e2rfc.identify(releases, BLUFF_DECK_3DOF)
    found, std = model.flutter(BLUFF_DECK_3DOF)
    assert found.critical_mode == result.critical_mode == "pitch"
    assert found.speed is not None and std is not None
    assert abs(found.speed - U_F) < 0.01 * U_F
    assert abs(found.speed - U_F) <= 2 * std
    # Every mode's reduced frequencies are known, sway's too.
    assert set(model.diagnostics.K_range) == {"heave", "pitch", "sway"}


def test_flutter_derivatives_fall_within_their_reported_deviation():
    """The 18 derivatives of an exact Roger model at seven K over the measured range.

    Four seeds x 126 values: a 2-std interval should hold about 95 % of them; the measured
    fraction is 94-98 % per seed (83-87 % with the covariance alone). Asserting 90 % over the
    504 values leaves room for the binomial scatter (one std of the fraction ~1 %) and still
    fails an interval that is too narrow by a fifth.
    """
    truth = _plate()
    U_F = float(fl.analyze(SWAY, truth).speed)  # type: ignore[arg-type]
    covered = []
    for seed in range(4):
        releases = _campaign(SWAY, truth, (0.45 * U_F, 0.65 * U_F, 0.8 * U_F), 0.02, seed)
        model = e2rfc.identify(releases, SWAY)
        wide = e2rfc.reduced_frequency_span(releases, SWAY, 7)
        K = np.linspace(wide[0] / 0.8, wide[-1] / 1.2, 7)  # the span, without its 20 % margins
        found, true, std = (model.flutter_derivatives(K), truth.flutter_derivatives(K),
                            model.flutter_derivative_std(K))
        assert len(found) == len(std) == 18
        covered += [np.abs(found[n] - true[n]) <= 2 * std[n] for n in found]
    assert np.mean(covered) >= 0.90


def test_the_rank_condition_is_enforced_with_reasons():
    """One wind speed, mixed or mismatched degrees of freedom, a sway mode not released."""
    truth = _plate()
    one_speed = _campaign(SWAY, truth, (6.0,), 0.0, 0, duration=6.0)
    with pytest.raises(RankDeficiencyError, match="one wind speed"):
        e2rfc.identify(one_speed, SWAY)
    two = _campaign(SWAY, truth, (5.0, 8.0), 0.0, 0, duration=6.0)
    planar = [Release(t=r.t, h=r.h, alpha=r.alpha, lift=r.lift, moment=r.moment, U=r.U)
              for r in two]
    with pytest.raises(ValueError, match="mix two and three degrees of freedom"):
        e2rfc.identify(two[:2] + planar[2:], SWAY)
    with pytest.raises(ValueError, match="no lateral spring"):
        e2rfc.identify(two, SWAY.planar())
    with pytest.raises(ValueError, match="planar"):
        e2rfc.identify(planar, SWAY)
    # Released without sway at a wind speed where nothing drives it (almost no wind), with a
    # laser's absolute noise of 20 um on p: the sway mode is not in the data.
    rng = np.random.default_rng(1)
    still = [simulate_release(SWAY, truth, U, 0.004, 0.02, p0=0.0, duration=10.0, fs=500.0,
                              noise={"h": 0.02, "alpha": 0.02, "lift": 0.02, "moment": 0.02,
                                     "drag": 0.02}, rng=rng)
             for U in (0.3, 8.0)]
    releases = []
    for sim in still:
        r = Release.from_simulation(sim)
        assert r.p is not None
        releases.append(Release(t=r.t, h=r.h, alpha=r.alpha, lift=r.lift, moment=r.moment,
                                U=r.U, p=r.p + rng.normal(0.0, 2e-5, r.t.size), drag=r.drag))
    with pytest.raises(RankDeficiencyError, match=r"at 0\.3 m/s .* sway mode"):
        e2rfc.identify(releases, SWAY)
    # In turbulence the closed-loop likelihood also reads the random response: the same
    # shortfall is then its warning, not a refusal.
    prepared = [prepare(r, SWAY) for r in releases]
    notes = e2rfc._check_modes_excited(prepared, SWAY, refuse=False)
    assert len(notes) == 1
    assert "at 0.3 m/s" in notes[0] and "sway mode's decay" in notes[0]


def test_a_2dof_identification_is_unchanged_by_the_generalisation():
    """The planar part of the same plate, identified as before (2x2, the Jones lags)."""
    truth = flat_plate.jones_model()
    section = SWAY.planar()
    U_F = float(fl.analyze(section, truth).speed)  # type: ignore[arg-type]
    rng = np.random.default_rng(0)
    releases = [Release.from_simulation(simulate_release(
        section, truth, f * U_F, 0.004, 0.02, duration=10.0, fs=500.0, noise=0.0, rng=rng))
        for f in (0.5, 0.8)]
    model = e2rfc.identify(releases, section, n_lags=2, with_A3=True)
    assert model.n_dof == 2
    np.testing.assert_allclose(model.d, truth.d, rtol=1e-4)
    assert math.isfinite(model.diagnostics.condition_number)


def test_weak_turbulence_is_taken_as_such_where_the_holds_show_it_and_named_where_not():
    """3-DOF bluff deck at Iu = Iw = 1 % with 10 s holds and 2 % noise (seed 1).

    Its decays' residuals are 8.5-21 times the noise (median 9.8, under the 10 at which
    releases alone count as turbulent). The holds' forces fluctuate at 4.8-5.6 times their
    white noise (smooth flow: 1.00-1.02), so with them the releases count as turbulent and the
    closed-loop likelihood runs; its interval covers the truth (measured -1.6 %, std 6.2 %; a
    2-std interval, which the benchmark's 3-DOF rows cover on 18-20 of 20 seeds). Without
    the holds plain E2RFC runs with smooth flow's checks: before, they blamed the section's
    zeta_h (a heave mode growing at 0.45 U_F, -2.3 % of critical) and friction; they name the
    growth as the releases' and buffeting among the causes.
    """
    truth = bluff_deck_3dof_model()
    U_F = float(fl.analyze(BLUFF_DECK_3DOF, truth).speed)  # type: ignore[arg-type]
    gusts = TurbulenceSpec(Iu=0.01, Iw=0.01, Lux=1.0, Lwx=0.3, Cuy=10.0, Cwy=8.0)
    releases = [Release.from_simulation(simulate_release(
        BLUFF_DECK_3DOF, truth, f * U_F, h0, a0, p0=p0, duration=20.0, fs=500.0, noise=0.02,
        rng=(1, i, j, 3), static=BLUFF_DECK_3DOF_STATIC, turbulence=gusts, span=1.0,
        pre_s=10.0))
        for i, f in enumerate((0.45, 0.65, 0.8))
        for j, (h0, a0, p0) in enumerate(((0.010, 0.03, 0.010), (-0.008, 0.02, -0.012)))]
    held = e2rfc.identify(releases, BLUFF_DECK_3DOF)
    assert held.diagnostics.turbulent
    assert held.diagnostics.estimator == e2rfc.ESTIMATOR_CLOSED_LOOP
    assert [w for w in held.diagnostics.warnings if "the holds' forces" in w]
    low, high = held.uncertainty(BLUFF_DECK_3DOF).interval()
    assert low <= U_F <= high

    bare = [dataclasses.replace(r, hold=None) for r in releases]
    warnings = e2rfc.identify(bare, BLUFF_DECK_3DOF).diagnostics.warnings
    assert not [w for w in warnings if "check the section's damping" in w], warnings
    assert [w for w in warnings if "heave mode grows at the lowest wind speed" in w], warnings
    assert [w for w in warnings if "not white" in w and "buffeting too weak" in w], warnings


def test_along_wind_gusts_take_the_buffeting_sources_mixed_after_their_filters():
    """3-DOF bluff deck in along-wind gusts of 2 % beside vertical ones of 1 %, no holds (seed 0).

    The drag is mostly the along-wind gust's (``2 C_D u``), lift and moment the vertical
    one's, each gust with a spectrum of its own: the forces' coherence changes with frequency,
    which each force filtered after the mix cannot follow. The evidence takes the sources
    mixed after their filters (same parameters; 26-35 higher in log L on seeds 0-3), and the
    estimate moves from -4.4 % to -0.6 % (measured). Asserted: the form chosen and named, and
    the interval covering the truth (the row covers on 19 of 20 seeds with the mixed form,
    ``benchmarks/ident_accuracy_3dof.py --part turbulent``).
    """
    truth = bluff_deck_3dof_model()
    U_F = float(fl.analyze(BLUFF_DECK_3DOF, truth).speed)  # type: ignore[arg-type]
    gusts = TurbulenceSpec(Iu=0.02, Iw=0.01, Lux=1.0, Lwx=0.3, Cuy=10.0, Cwy=8.0)
    releases = [Release.from_simulation(simulate_release(
        BLUFF_DECK_3DOF, truth, f * U_F, h0, a0, p0=p0, duration=20.0, fs=500.0, noise=0.02,
        rng=(0, i, j, 10, 20), static=BLUFF_DECK_3DOF_STATIC, turbulence=gusts, span=1.0))
        for i, f in enumerate((0.45, 0.65, 0.8))
        for j, (h0, a0, p0) in enumerate(((0.010, 0.03, 0.010), (-0.008, 0.02, -0.012)))]
    model = e2rfc.identify(releases, BLUFF_DECK_3DOF)
    assert model.diagnostics.estimator == e2rfc.ESTIMATOR_CLOSED_LOOP
    assert "fourth-order-mixed buffeting model" in model.diagnostics.reason
    assert "sources mixed into the forces after their filters" in model.diagnostics.reason
    low, high = model.uncertainty(BLUFF_DECK_3DOF).interval()
    assert low <= U_F <= high
