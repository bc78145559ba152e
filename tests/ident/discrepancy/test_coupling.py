"""Heave-pitch coupling at zero wind that the model lacks (``ident.discrepancy.coupling``).

Simulated campaigns of the flat-plate rig (:mod:`simulators.campaigns`: three wind speeds, two
7.5 s releases each, 2 % noise, seeded) against the true aerodynamic model (R.T. Jones's), so
that what is left is the effect hidden in the data alone.
"""

from __future__ import annotations

import math

import pytest

from ident.discrepancy.coupling import COUPLING_FLOOR, coupling_verdict, zero_wind_coupling
from ident.model import flat_plate
from simulators.campaigns import REALISTIC, SECTION, simulated_campaign


def test_laser_crosstalk_shows_as_the_coupling_it_puts_in_the_heave_mode():
    crosstalk = REALISTIC["sensor_crosstalk"]
    releases = simulated_campaign(crosstalk, seed=1)
    heave, pitch = zero_wind_coupling(releases, SECTION, flat_plate.jones_model())
    # The measured pitch is alpha + alpha_from_h h: in the heave mode (h alone, to the first
    # order) that is alpha_from_h B per unit h/B, mass-normalised by sqrt(I / (m B^2)). The
    # modes are fitted from 2 % noise and the line extrapolated from three wind speeds: 10 %.
    mass_ratio = math.sqrt(SECTION.I / (SECTION.m * SECTION.B ** 2))
    expected = crosstalk.alpha_from_h * SECTION.B * mass_ratio
    assert heave.in_phase == pytest.approx(expected, rel=0.10)
    assert heave.significant and pitch.significant
    assert abs(heave.quadrature) < COUPLING_FLOOR  # a sensor mixes in phase
    assert coupling_verdict((heave, pitch)).startswith("in-phase coupling in both modes")
    assert heave.qd.size == 6 and heave.per_release.size == 6


@pytest.mark.parametrize("seed", [1, 2])
def test_a_clean_campaign_has_no_coupling_at_zero_wind(seed):
    couplings = zero_wind_coupling(simulated_campaign(None, seed), SECTION,
                                   flat_plate.jones_model())
    assert [c.mode for c in couplings] == ["heave", "pitch"]
    for c in couplings:
        assert abs(c.in_phase) < COUPLING_FLOOR and not c.significant, c.text()
        assert "not significant" in c.text()
    assert coupling_verdict(couplings) == "no in-phase coupling in both modes beyond the model's"


def test_releases_at_one_wind_speed_give_no_estimate():
    releases = simulated_campaign(REALISTIC["static_unbalance"], seed=1)
    one_speed = [r for r in releases if r.U == releases[0].U]
    assert len(one_speed) == 2
    assert zero_wind_coupling(one_speed * 2, SECTION, flat_plate.jones_model()) == ()
    assert coupling_verdict(()).startswith("not estimated")
