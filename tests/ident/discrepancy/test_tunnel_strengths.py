"""The discrepancy workflow on campaigns recorded from the virtual tunnel, at other strengths.

Issue 39: the workflow must name effects of other strengths and shapes than its own test cases
(``benchmarks/discrepancy_confusion.py`` draws them at random over each effect's realistic
range, :data:`simulators.tunnel_campaigns.STRENGTH_RANGE`). Here seeded cases at the edges of
those ranges and of the shapes drawn: each recorded from the tunnel (its air, spline-sampled
motion, forces integrated from noisy taps), 2 % noise.
"""

from __future__ import annotations

import cmath
import math

import pytest

from ident.discrepancy.residual_check import systematic_levels
from ident.discrepancy.workflow import diagnose
from ident.physics.effects import BaseVibration, TubingDistortion
from simulators.campaigns import SECTION, scaled
from simulators.tunnel_campaigns import STRENGTH_RANGE, tunnel_campaign

DEPTH = 0.03  # m, the flat plate's


def test_friction_at_the_low_end_of_its_range_is_named_and_what_is_left_is_white():
    low = STRENGTH_RANGE["coulomb_friction"][0]
    effect = scaled("coulomb_friction", low)
    releases = tunnel_campaign(effect, 5)
    report = diagnose(releases, SECTION, depth=DEPTH)
    assert [step.name for step in report.effects] == ["coulomb_friction"], report.summary()
    # At the low end the friction force is 5 mN/m: its heave part is fitted within 20 % (the
    # benchmark's worst over both parts: 11 %), the pitch part, a tenth of the pitch damping
    # force, looser.
    assert report.parameters["force_h"] == pytest.approx(effect.force_h, rel=0.2)
    assert report.parameters["moment_a"] == pytest.approx(effect.moment_a, rel=0.4)
    assert report.explained, report.summary()
    left = systematic_levels(releases, report.simulated_after)
    assert all(sys <= noise for sys, noise in left.values()), left


def test_a_floor_line_near_the_band_edge_is_fitted_at_its_full_amplitude():
    # 8.9 Hz lies at 0.89 of the equation error's 10 Hz low-pass: the residual holds the floor's
    # force filtered by |H|^2 = 0.72 there, and unscaled columns fitted it 28 % low.
    floor = BaseVibration(frequency_hz=8.9, accel=0.1, phase=1.0)
    report = diagnose(tunnel_campaign(floor, 1), SECTION, depth=DEPTH)
    assert [step.name for step in report.effects] == ["base_vibration"], report.summary()
    assert report.parameters["frequency_hz"] == pytest.approx(8.9, rel=1e-3)
    # 0.1 % seen; 5 % leaves room for the noise of other seeds, far below the 28 % bias.
    assert report.parameters["accel"] == pytest.approx(0.1, rel=0.05)
    assert report.explained, report.summary()


def test_a_tube_far_above_the_modes_is_named_as_the_delay_it_is():
    # A 0.06 x realistic tube resonates at 280 Hz: at the modes its gain is 1 within 0.02 %,
    # its phase that of a delay. The right answer is channel_delay with the tube's delay.
    tube = TubingDistortion(frequency_hz=280.0, damping=1.0)
    report = diagnose(tunnel_campaign(tube, 2), SECTION, depth=DEPTH)
    assert [step.name for step in report.effects] == ["channel_delay"], report.summary()
    w = 2 * math.pi * SECTION.fa
    wn = 2 * math.pi * tube.frequency_hz
    delay = -cmath.phase(wn**2 / (wn**2 - w**2 + 2j * tube.damping * wn * w)) / w  # 1.14 ms
    # The fitted delay: within 20 % (the benchmark's criterion; a 1 ms delay is half a sample).
    assert report.parameters["delay_s"] == pytest.approx(delay, rel=0.2)
    assert report.explained, report.summary()
