"""The selection's paths beyond one clear effect per round, on campaigns from the virtual tunnel.

Each case is a pair of the confusion benchmark (``benchmarks/discrepancy_confusion.py``, random
strengths, draw seed 39) that one effect per round got wrong: the same effects and campaign
seed, recorded from the tunnel with 2 % noise. Every named effect must pass the gap rule
(:mod:`ident.discrepancy.gap_rule`), with the step that named it on record.
"""

from __future__ import annotations

import pytest

from ident.discrepancy.workflow import DiscrepancyReport, diagnose
from ident.physics.effects import (
    AerodynamicNonlinearity,
    ChannelDelay,
    CoulombFriction,
    SensorCrosstalk,
    StaticUnbalance,
)
from simulators.campaigns import SECTION
from simulators.tunnel_campaigns import tunnel_campaign

DEPTH = 0.03  # m, the flat plate's


def _named(report: DiscrepancyReport) -> list[str]:
    for step in report.effects:
        assert step.trial is not None and step.trial.accepted, report.summary()
        assert step.trial.after == step.gap_after
        assert step.trial.shrink >= step.trial.required > 0
    return sorted(step.name for step in report.effects)


def test_two_effects_that_neither_shrink_the_gap_alone_are_named_together():
    # Benchmark pair "static_unbalance+channel_delay", campaign 4 (x2.28, x1.94): alone the
    # unbalance takes the gap 0.458 -> 0.476, the delay to 0.537; together to the noise.
    unbalance, delay = StaticUnbalance(S=0.034249628314201364), ChannelDelay(delay_s=0.0194312)
    report = diagnose(tunnel_campaign([unbalance, delay], 50_604), SECTION, depth=DEPTH)
    assert _named(report) == ["channel_delay", "static_unbalance"], report.summary()
    first, second = report.effects
    assert first.trial is second.trial  # one step named both
    together = [ev for ev in report.rounds[0] if ev.effect in ("channel_delay",
                                                                 "static_unbalance")]
    # Both needed: each verdict keeps the gap with the other one alone, larger by the margin.
    assert all("together with" in ev.verdict and "without it: gap" in ev.verdict
               for ev in together), report.summary()
    assert all(ev.trial is first.trial for ev in together)
    # Parameters: 0.3 % and 0.2 % seen; 5 % is far below the 20 % a pair must meet and leaves
    # room for the noise.
    assert report.parameters["S"] == pytest.approx(unbalance.S, rel=0.05)
    assert report.parameters["delay_s"] == pytest.approx(delay.delay_s, rel=0.05)
    assert report.explained, report.summary()


def test_a_delay_beside_crosstalk_is_not_named_as_the_tube_that_looks_like_it():
    # Benchmark pair "channel_delay+sensor_crosstalk", campaign 0 (x1.18, x0.52): in round 1
    # a 19 Hz tube with damping 0.71 (a delay's look-alike) took part of the crosstalk and was
    # clear of the delay; beside the crosstalk it is not, and the second search names the delay.
    delay = ChannelDelay(delay_s=0.011777603522837805)
    crosstalk = SensorCrosstalk(h_from_alpha=0.0015543009435350838,
                                alpha_from_h=0.15543009435350838)
    report = diagnose(tunnel_campaign([delay, crosstalk], 50_400), SECTION, depth=DEPTH)
    assert _named(report) == ["channel_delay", "sensor_crosstalk"], report.summary()
    tube = next(ev for ev in report.rounds[0] if ev.effect == "tubing_distortion")
    assert tube.verdict.startswith("rejected: beside sensor_crosstalk"), tube.verdict
    # 0.03 % and 1.2 % seen.
    assert report.parameters["delay_s"] == pytest.approx(delay.delay_s, rel=0.05)
    assert report.parameters["alpha_from_h"] == pytest.approx(crosstalk.alpha_from_h, rel=0.05)
    assert report.explained, report.summary()


def test_an_aerodynamic_nonlinearity_not_clear_by_its_chunks_is_tried_when_the_rest_is_not_white():
    # Benchmark pair "aerodynamic_nonlinearity+coulomb_friction", campaign 3 (x2.09, x1.17):
    # beside the friction the nonlinearity's held-out ratio is 0.33 +- 0.36 (its evidence is
    # in the first seconds of the fastest releases), under two standard errors.
    aero = AerodynamicNonlinearity(e_h=-6.264202937427273, e_a=-0.3132101468713636)
    friction = CoulombFriction(force_h=0.034990653336026765, moment_a=0.0011663551112008922)
    report = diagnose(tunnel_campaign([aero, friction], 50_903), SECTION, depth=DEPTH)
    assert _named(report) == ["aerodynamic_nonlinearity", "coulomb_friction"], report.summary()
    chosen = next(ev for ev in report.rounds[1] if ev.effect == "aerodynamic_nonlinearity")
    assert "what is left is not white" in chosen.verdict, chosen.verdict
    assert not (1.0 - chosen.cv_ratio > 2.0 * chosen.cv_ratio_se)  # not clear by the chunks
    # e_h 2 %, e_a 3 %, friction 1-4 % seen; 10 % is half the pair's 20 %.
    for name in ("e_h", "e_a"):
        assert report.parameters[name] == pytest.approx(getattr(aero, name), rel=0.1)
    for name in ("force_h", "moment_a"):
        assert report.parameters[name] == pytest.approx(getattr(friction, name), rel=0.1)
    assert report.explained, report.summary()
