"""E2RFC's flutter-speed uncertainty where its model is not exact and the flow not smooth.

Seeded cases of each kind the identification meets in a real tunnel: releases in turbulence
(vertical gusts, quasi-steady buffeting), the exact-Theodorsen flat plate (not of Roger's form),
and a bluff deck whose entries have lags of their own. Each asserts the error and that the
2-std interval covers the truth; the turbulence cases over several seeds, with the count that a
95 % interval must reach (at least 4 of 5 covered has probability 0.98 when the coverage is
95 %, and 0.92 at 90 %; the seeds are fixed, so the count is deterministic).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from ident import Release
from ident.identification import e2rfc, results
from ident.identification.results import RANDOM_RESPONSE_LIMIT
from ident.identification.uncertainty import FlutterUncertainty
from ident.model import flat_plate
from ident.model import flutter as fl
from ident.model.quasi_steady import StaticCoefficients
from ident.physics.turbulence import TurbulenceSpec
from simulators import simulate_release
from simulators.decks import BLUFF_DECK, bluff_deck_model

from support.sections import FLAT_PLATE

HOLDS = ((0.004, 0.02), (-0.003, 0.012))


def campaign(section, model, *, seed, Iw=0.0, static=None, holds=HOLDS, duration=12.0):
    """Releases at 0.4, 0.6 and 0.8 of the flutter speed, one per hold, 2 % noise."""
    U_F = fl.analyze(section, model).speed
    wind = {}
    if Iw:
        wind = {"static": static, "span": 1.0,
                "turbulence": TurbulenceSpec(Iu=0.0, Iw=Iw, Lux=1.0, Lwx=0.3, Cuy=10.0, Cwy=8.0)}
    return [Release.from_simulation(simulate_release(
        section, model, f * U_F, h0, a0, duration=duration, fs=500.0, noise=0.02,
        rng=(seed, i, j), **wind))
        for i, f in enumerate((0.4, 0.6, 0.8)) for j, (h0, a0) in enumerate(holds)]


def test_releases_in_turbulence_are_flagged_and_their_interval_holds_the_truth():
    """1 % vertical turbulence: the random response is found, the interval covers the truth.

    Plain E2RFC (the refined-IV branch without holds keeps its estimate): the least-squares
    covariance of such releases is no measure (the buffeting is correlated over whole
    periods); the release-to-release scatter is. Error: the median over the seeds
    within 10 % (benchmarks/ident_accuracy.py: median 3 %, 90th percentile 14 % over 10 seeds;
    the Cramer-Rao bound of the case is 2.9 % std and 10 % for an estimator that treats the
    random response as noise, benchmarks/flutter_crb.py).
    """
    model = flat_plate.jones_model()
    U_F = fl.analyze(FLAT_PLATE, model).speed
    covered, errors = 0, []
    for seed in range(5):
        identified = e2rfc.identify(
            campaign(FLAT_PLATE, model, seed=seed, Iw=0.01, static=StaticCoefficients.flat_plate(),
                     duration=20.0), FLAT_PLATE, turbulent_estimator="iv")
        diagnostics = identified.diagnostics
        assert diagnostics.turbulent
        assert np.median(diagnostics.random_response) > RANDOM_RESPONSE_LIMIT
        assert len(diagnostics.jackknife) == 6
        assert any("random response" in w for w in diagnostics.warnings)
        u = identified.uncertainty(FLAT_PLATE)
        if u.speed is None:  # no flutter below the searched speeds: a miss, not a crash
            errors.append(math.inf)
            continue
        assert u.turbulence > 0 and u.statistical == u.turbulence
        errors.append(abs(u.speed / U_F - 1))
        covered += abs(u.speed - U_F) <= 2 * u.total
    assert covered >= 4
    assert float(np.median(errors)) < 0.10


def test_smooth_flow_releases_are_not_taken_for_turbulence():
    """2 % white noise only: no random response, no jackknife, a tight interval on the truth."""
    model = flat_plate.jones_model()
    U_F = fl.analyze(FLAT_PLATE, model).speed
    identified = e2rfc.identify(campaign(FLAT_PLATE, model, seed=1), FLAT_PLATE)
    diagnostics = identified.diagnostics
    assert not diagnostics.turbulent and diagnostics.jackknife == ()
    assert np.all(diagnostics.random_response < 2.0)  # ~1: the residual is the white noise
    u = identified.uncertainty(FLAT_PLATE)
    assert u.turbulence == 0.0
    assert abs(u.speed - U_F) <= 2 * u.total
    assert u.total < 0.002 * U_F  # 2 % noise, 72 s of data: a few hundredths of a per cent


def test_the_exact_theodorsen_plate_is_identified_within_half_a_percent_and_covered():
    """Theodorsen's function is not rational: E2RFC approximates it, and the interval says so.

    Truth: the frequency-domain analysis with the exact flutter derivatives.
    """
    truth = fl.frequency_domain(FLAT_PLATE, flat_plate.flutter_derivatives).speed
    identified = e2rfc.identify(campaign(FLAT_PLATE, flat_plate.theodorsen_model(), seed=2),
                                FLAT_PLATE)
    u = identified.uncertainty(FLAT_PLATE)
    assert abs(u.speed / truth - 1) < 0.005
    assert abs(u.speed - truth) <= 2 * u.total


def test_a_bluff_deck_outside_rogers_form_is_covered_and_its_extrapolation_reported():
    """Ten lags of its own per entry, flutter below the covered reduced frequencies.

    Three shared lags approximate it to about 0.2 %; one lag more moves the flutter speed by
    as much, and that is in the interval. The flutter reduced frequency (0.59) is below what
    releases at 0.8 U_F cover on the pitch branch (0.8): a warning says so.
    """
    model = bluff_deck_model()
    U_F = fl.analyze(BLUFF_DECK, model).speed
    identified = e2rfc.identify(campaign(BLUFF_DECK, model, seed=3, holds=HOLDS[:1],
                                         duration=20.0), BLUFF_DECK)
    u = identified.uncertainty(BLUFF_DECK)
    assert abs(u.speed / U_F - 1) < 0.01
    assert abs(u.speed - U_F) <= 2 * u.total
    assert u.refinement > 0 and u.systematic > u.parametric
    assert any("extrapolated" in w and "pitch branch" in w for w in u.warnings)


def test_releases_needed_scale_the_statistical_part_only():
    """Releases needed: n s_stat^2 / (target^2 - s_sys^2); None when s_sys alone is too large."""
    u = FlutterUncertainty(speed=12.0, parametric=0.1, structure=0.03, extrapolation=0.04,
                           refinement=0.0, turbulence=0.6, n_releases=6)
    assert u.statistical == 0.6  # the release scatter replaces the least-squares part
    assert u.systematic == pytest.approx(0.05)
    assert u.total == pytest.approx(math.sqrt(0.36 + 0.0025))
    assert u.releases_needed(0.3) == math.ceil(6 * 0.36 / (0.09 - 0.0025))
    assert u.releases_needed(0.04) is None  # below the systematic part
    assert u.releases_needed(1.0) == 6  # met already


def test_the_interval_is_symmetric_in_the_log_of_the_distance_beyond_the_floor():
    """Closed form: ``floor + d exp(+-2 total / d)``; symmetric without a floor.

    The benchmark's case that made it (plate, Iw 1 %, seed 5 without holds, in units of U_F):
    an estimate 8 % low, std 3.2 %, releases up to 0.8. Symmetric, the interval ends at 0.984
    and misses the truth; in the log of the distance its upper end is 1.005, its lower end
    0.870 (not 0.856): longer above than below, never below the stable speed.
    """
    u = FlutterUncertainty(speed=0.920, parametric=0.0322, structure=0.0, extrapolation=0.0,
                           refinement=0.0, turbulence=0.0, n_releases=6, floor=0.8)
    low, high = u.interval()
    assert (low, high) == pytest.approx((0.8 + 0.12 * math.exp(-0.0644 / 0.12),
                                         0.8 + 0.12 * math.exp(0.0644 / 0.12)), rel=1e-12)
    assert high > 1.0 > 0.920 + 2 * 0.0322 and low == pytest.approx(0.870, abs=5e-4)
    assert high - u.speed > u.speed - low and low > u.floor
    assert u.interval(1.0)[1] < high  # k std of log d
    # Without a floor (no release seen stable, or the speed below one): speed +- k total.
    free = FlutterUncertainty(speed=0.920, parametric=0.0322, structure=0.0, extrapolation=0.0,
                              refinement=0.0, turbulence=0.0, n_releases=6)
    assert free.interval() == pytest.approx((0.920 - 0.0644, 0.920 + 0.0644), rel=1e-12)
    # A std many times the distance: no upper end, and no overflow either.
    wide = FlutterUncertainty(speed=0.81, parametric=50.0, structure=0.0, extrapolation=0.0,
                              refinement=0.0, turbulence=0.0, n_releases=6, floor=0.8)
    assert wide.interval()[1] > 1e250 and wide.interval()[0] >= 0.8
    assert "2-std interval 0.870 to 1.005" in u.summary()


def test_a_systematic_misfit_is_reported_as_residuals_that_are_not_white():
    """Coulomb friction the model lacks: the force residuals are correlated, and said so."""
    from simulators.campaigns import REALISTIC, SECTION, simulated_campaign

    identified = e2rfc.identify(simulated_campaign(REALISTIC["coulomb_friction"], 1), SECTION)
    assert any("not white" in w for w in identified.diagnostics.warnings)
    clean = e2rfc.identify(simulated_campaign(None, 1), SECTION)
    assert not any("not white" in w for w in clean.diagnostics.warnings)


def test_a_failed_refit_without_the_top_speed_is_named_not_taken_for_no_extrapolation():
    """The bluff deck above (flutter beyond the covered reduced frequencies, 3 speeds).

    Its extrapolation part comes from the fit without the top speed. When another estimator's
    refit (a :class:`~ident.identification.results.Deferred`, as the closed-loop branch
    supplies) gives none, the part is zero, and a warning says the std is too small by it.
    """
    from dataclasses import replace

    from ident.identification.results import Deferred, IdentifiedModel

    model = bluff_deck_model()
    identified = e2rfc.identify(campaign(BLUFF_DECK, model, seed=3, holds=HOLDS[:1],
                                         duration=20.0), BLUFF_DECK)
    assert identified.uncertainty(BLUFF_DECK).extrapolation > 0.0
    diag = identified.diagnostics
    failed = IdentifiedModel(identified.A, identified.d, replace(
        diag, _refits={**diag._refits, "reduced": Deferred(lambda: None)}))
    u = failed.uncertainty(BLUFF_DECK)
    assert u.extrapolation == 0.0
    assert any("refit without the highest wind speed failed" in w for w in u.warnings)
    assert not any("refit without the highest" in w
                   for w in identified.uncertainty(BLUFF_DECK).warnings)


def test_the_extrapolation_part_takes_the_refits_statistical_scatter_off():
    """Hausman's argument: the refit's move less what its own statistics would move it.

    The bluff deck above (smooth flow: its refit gives no covariance, so the whole move
    counts). Given a covariance for the refit (as the closed-loop branch's Fisher information
    gives), the move's square loses ``std(refit)^2 - std(full)^2``: nothing with a refit known
    exactly or as well as the full fit (the whole move stays), all of it with one known a
    thousand times worse in variance (the move is then statistics), and in between part of
    it, the more the less the refit is known (measured: 1.09 % of U_F whole, 1.00 % at 3
    times the full fit's covariance, 0.61 % at 10, none at 30).
    """
    from dataclasses import replace

    from ident.identification.results import IdentifiedModel

    model = bluff_deck_model()
    identified = e2rfc.identify(campaign(BLUFF_DECK, model, seed=3, holds=HOLDS[:1],
                                         duration=20.0), BLUFF_DECK)
    whole = identified.uncertainty(BLUFF_DECK).extrapolation
    assert whole > 0.0
    diag = identified.diagnostics

    def extrapolation(scale):
        covariance = scale * diag.covariance
        refit = IdentifiedModel(identified.A, identified.d, replace(
            diag, _refits={**diag._refits, "reduced_covariance": covariance}))
        return refit.uncertainty(BLUFF_DECK).extrapolation

    assert extrapolation(0.0) == pytest.approx(whole, rel=1e-12)
    assert extrapolation(1.0) == pytest.approx(whole, rel=1e-12)
    parts = [extrapolation(scale) for scale in (3.0, 10.0, 1e3)]
    assert whole > parts[0] > parts[1] > parts[2] == 0.0


@pytest.mark.parametrize(("random_response", "held_load", "turbulent"), [
    ([12.0, 9.0, 11.0], [], True),            # the decays alone: median 11 > 10
    ([9.0, 8.0, 9.5], [], False),             # weak, no holds: the rule of 10 alone
    ([9.0, 8.0, 9.5], [5.0, 4.8, 5.2], True),  # weak, and the holds show the wind's load
    ([9.0, 8.0, 9.5], [1.01, 1.0, 1.02], False),  # weak, the holds at their noise (a floor)
    ([1.0, 1.02, 1.01], [24.0, 23.0, 25.0], False),  # vortex shedding in smooth flow
    ([], [5.0], False),                       # nothing to judge
])
def test_releases_count_as_turbulent_by_their_decays_or_weakly_with_loaded_holds(
        random_response, held_load, turbulent):
    """The rule of :func:`results.is_turbulent`, at the measured values its limits sit between."""
    assert results.is_turbulent(random_response, held_load) is turbulent


@pytest.mark.parametrize("factor", [1.0, 2.237], ids=["m/s", "mph read as m/s"])
def test_wind_speeds_in_another_unit_scale_the_flutter_speed_and_are_named(factor):
    # Identification is self-similar in the speed's unit: the releases' speeds all a factor
    # off give the flutter speed times that factor, with no misfit; only the flutter point's
    # reduced velocity (the plate's 9.8, in mph 22, against decks' 5-15) can tell.
    releases = [dataclasses.replace(r, U=r.U * factor)
                for r in campaign(FLAT_PLATE, flat_plate.jones_model(), seed=3, duration=6.0)]
    u = e2rfc.identify(releases, FLAT_PLATE).uncertainty(FLAT_PLATE)
    truth = fl.analyze(FLAT_PLATE, flat_plate.jones_model()).speed
    # 2 % noise on six 6 s decays: the plate's estimate lies within 1 % of the truth.
    assert u.speed == pytest.approx(factor * truth, rel=0.01)
    named = [w for w in u.warnings if "km/h or mph" in w]
    assert len(named) == (0 if factor == 1.0 else 1), u.warnings
