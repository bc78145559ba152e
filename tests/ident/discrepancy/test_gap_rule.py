"""The gap rule (ident.discrepancy.gap_rule) on evidence built by hand, and its noise floor.

Pure and deterministic: the rule's arithmetic on given gaps, and the noise's gap of a clean
seeded campaign simulated with its own truth (the residual is the 2 % noise exactly).
"""

from __future__ import annotations

import math

import pytest

from ident.discrepancy.effect_selection import channels, simulate_channels
from ident.discrepancy.gap_rule import GAP_MARGIN, judge, noise_gap
from ident.model import flat_plate
from simulators.campaigns import SECTION, simulated_campaign


def test_a_gap_that_does_not_move_names_nothing():
    # The example: vortex_shedding was once named while the gap stayed 0.964 -> 0.964.
    step = judge(0.964, 0.964, 0.02)
    assert not step.accepted
    assert "0.9640 -> 0.9640" in step.text()


def test_the_shrink_must_reach_the_margin_of_the_noise_gap():
    noise = 0.02  # 2 % noise: the margin is GAP_MARGIN * 0.02 = 0.002 of gap
    assert GAP_MARGIN * noise == pytest.approx(0.002)
    assert not judge(0.1, 0.0990, noise).accepted  # 0.001 < 0.002: smaller than the margin
    assert judge(0.1, 0.0970, noise).accepted  # 0.003 >= 0.002
    assert not judge(0.1, 0.1010, noise).accepted  # the gap grew


def test_the_releases_changes_are_reported_but_the_total_decides():
    # Built by hand after the pair cubic spring + static unbalance: the true first effect
    # shrinks some releases a lot and others not at all (the other effect dominates them); the
    # total shrink (0.01, five times the margin) decides, the releases' spread is reported.
    per_release = [(0.5, 0.3), (0.5, 0.7), (0.5, 0.45), (0.5, 0.51)]
    step = judge(0.5, 0.49, 0.02, per_release)
    assert step.accepted
    assert step.release_mean == pytest.approx(0.01)  # (0.2 - 0.2 + 0.05 - 0.01) / 4
    assert step.release_se == pytest.approx(0.0828, rel=1e-3)  # sample sd 0.1655 / 2
    assert "per release +0.0100 +- 0.0828" in step.text()
    assert math.isnan(judge(0.5, 0.49, 0.02).release_se)  # nothing given: not reported


def test_a_diverging_trial_is_rejected_and_said_so():
    step = judge(0.3, math.nan, 0.02)
    assert not step.accepted
    assert "diverged" in step.text()
    assert not judge(0.3, math.inf, 0.02).accepted


def test_a_bad_noise_gap_is_refused():
    with pytest.raises(ValueError, match="noise gap"):
        judge(0.3, 0.2, -0.01)
    with pytest.raises(ValueError, match="gap before"):
        judge(math.nan, 0.2, 0.02)
    with pytest.raises(ValueError, match="at least one simulation"):
        noise_gap([])


def test_the_noise_gap_of_a_clean_campaign_is_its_noise():
    releases = simulated_campaign(None, 7, duration=2.0)
    truth = [simulate_channels(r, SECTION, flat_plate.jones_model(), ()) for r in releases]
    # simulated_campaign adds noise of 2 % of each channel's RMS; the first-difference
    # estimate over 1000 samples per release scatters by ~2 %, and the truth simulated from the
    # fitted initial state differs from the noise-free decay by a little: 10 % allowed.
    assert noise_gap(releases, truth) == pytest.approx(0.02, rel=0.10)
    # With a worse simulation beside it the smallest estimate is kept (one channel doubled:
    # a smooth error adds almost nothing to the difference estimate, so about the same).
    doubled = [{**c, "h": 2 * c["h"]} for c in truth]
    assert noise_gap(releases, truth, doubled) <= noise_gap(releases, truth)
    assert channels(releases[0])["h"] is releases[0].h
