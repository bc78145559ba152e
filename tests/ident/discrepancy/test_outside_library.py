"""Physics outside the library (issue 39): never explained, nothing named unless the gap shrank.

Three kinds (``support.outside_library``): a pitch spring with a dead zone of 0.5 mrad (free
play), a heave stop at 2.5 mm (an impact with the frame), a heave mass that grows 3 % per
release (water collecting); and a linear damping of the suspension the section's still-air
damping misses (:class:`ExtraViscousDamping`, here), alone and beside a friction. Each
campaign: the flat-plate rig at 0.5 and 0.8 of its flutter speed, two 5 s releases each, 2 %
noise, seeded (four releases keep each test near 10 s).
Whatever the workflow names must have passed the gap rule (``ident.discrepancy.gap_rule``):
its step shrank the simulated gap by the margin, consistently over the releases, and the gap
after is never larger than before; every step tried and undone is in ``report.rejected``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pytest

from ident.discrepancy.workflow import DiscrepancyReport, diagnose
from ident.physics.effects import Effect
from simulators.campaigns import REALISTIC, SECTION, simulated_campaign

from support.outside_library import FreePlay, HeaveStop, growing_mass_campaign

DEPTH = 0.03  # m, the flat plate's (the vortex candidate's depth)
FRACTIONS = (0.5, 0.8)


def _assert_the_rule(report: DiscrepancyReport) -> None:
    """Every named effect passed the gap rule; the gap never grew; undone steps are listed."""
    named = [step.name for step in report.effects]
    gaps = [report.gap_before] + [step.gap_after for step in report.effects]
    for k, step in enumerate(report.effects):
        trial = step.trial  # two effects named together share their step
        assert trial is not None and trial.accepted, report.summary()
        assert trial.after == gaps[k + 1]
        assert trial.shrink >= trial.required > 0
    assert all(b <= a for a, b in zip(gaps, gaps[1:], strict=False)), gaps
    assert report.gap_after <= report.gap_before
    for name, step in report.rejected:
        assert not step.accepted
        assert f"tried and undone: {name}" in report.summary()
    assert len(named) == len(set(named))
    # Not white at the noise level: the honest answer to physics outside the library.
    assert not report.explained and report.unexplained, report.summary()
    assert "explained: NO" in report.summary()


def test_free_play_in_the_pitch_spring_is_not_explained_and_a_supported_spring_undone():
    releases = simulated_campaign(FreePlay(), 1, duration=5.0, fractions=FRACTIONS)
    report = diagnose(releases, SECTION, depth=DEPTH)
    # The dead zone lowers the pitch frequency as the decay dies: the baseline misses it by
    # far more than the noise (0.66 seen against 0.02).
    assert report.gap_before > 10 * 0.02, report.summary()
    _assert_the_rule(report)
    # The rule's own case: a cubic spring is supported by its residual fit (held-out ratio
    # clear of 1 by more than two standard errors: 0.935 +- 0.020 seen) but the simulated gap
    # grows with it (0.6585 -> 0.9536 with the aerodynamic model identified again beside it):
    # tried and undone with both gaps. (What is named later, beside others, passed the rule:
    # with what is left far from white a candidate is tried at one standard error, and a
    # crosstalk then a spring each shrank the gap by the margin, 0.6585 -> 0.5922 seen.)
    cubic = next(ev for ev in report.rounds[0] if ev.effect == "cubic_stiffness")
    assert cubic.cv_ratio <= 0.98 and 1 - cubic.cv_ratio > 2 * cubic.cv_ratio_se
    assert cubic.trial is not None and cubic.trial.after > cubic.trial.before
    assert dict(report.rejected)["cubic_stiffness"] is cubic.trial
    assert "cubic_stiffness" in dict(report.rejected), report.summary()
    assert (f"tried and undone: cubic_stiffness (gap {cubic.trial.before:.4f} -> "
            f"{cubic.trial.after:.4f}") in report.summary()


def test_a_heave_stop_is_not_explained_and_every_step_passed_the_rule():
    releases = simulated_campaign(HeaveStop(), 2, duration=5.0, fractions=FRACTIONS)
    report = diagnose(releases, SECTION, depth=DEPTH)
    assert report.gap_before > 10 * 0.02, report.summary()
    _assert_the_rule(report)
    # A hardening spring takes up part of the stop (0.79 -> 0.50 seen): it shrank the gap, so
    # the rule lets it be named; what is left is far from white.
    assert report.gap_after < report.gap_before
    assert max(f.systematic for f in report.unexplained) > 10 * 0.02


def test_a_mass_that_changes_between_releases_is_not_explained():
    releases = growing_mass_campaign(2, fractions=FRACTIONS)
    report = diagnose(releases, SECTION, depth=DEPTH)
    # Heave 3.5 % lower in frequency at the fourth release: the gap is 3.5 times the noise.
    assert report.gap_before > 2 * 0.02, report.summary()
    _assert_the_rule(report)
    heave = next(f for f in report.unexplained if f.channel == "h")
    assert heave.systematic > 3 * heave.noise, heave.text()


@dataclass(frozen=True)
class ExtraViscousDamping(Effect):
    """A linear damping of the suspension the section's still-air damping misses (outside).

    Adds ``dzeta`` to both damping ratios: ``[-2 m dzeta w_h h' B, -2 I dzeta w_a alpha']``
    (generalised, N m/m; ``q' = [h'/B, alpha']``).
    """

    name: ClassVar[str] = "extra_viscous_damping"
    nonlinear: ClassVar[bool] = True
    dzeta: float = 0.004

    def structural_force(self, q: np.ndarray, qd: np.ndarray, B: float) -> np.ndarray:
        """Return the extra generalised force ``[F_h B, M]``, N m/m."""
        c_h = 2 * SECTION.m * self.dzeta * 2 * math.pi * SECTION.fh  # N s/m^2
        c_a = 2 * SECTION.I * self.dzeta * 2 * math.pi * SECTION.fa  # N m s/m
        return np.array([-c_h * qd[0] * B * B, -c_a * qd[1]])


def _linear_damping_verdict(report: DiscrepancyReport, name: str) -> tuple[float, float]:
    """Return the zeta_h, zeta_a a candidate's rejection says a linear damping adds."""
    verdict = next(ev.verdict for rnd in report.rounds for ev in rnd if ev.effect == name
                   and "not clear of a linear damping" in ev.verdict)
    number = r"([-+.\de]+) \+- [.\de]+"
    found = re.search(rf"adds {number} to zeta_h and {number} to zeta_a", verdict)
    assert found is not None, verdict
    return float(found.group(1)), float(found.group(2))


def test_an_unknown_viscous_damping_is_not_named_as_drag_or_friction():
    # The still-air damping ratios 0.004 too low. Quadratic damping (0.85 of the held-out
    # residual) and friction each took it up before the fix and both were named; beside a
    # linear damping neither explains anything (1.001 and 1.002 seen).
    releases = simulated_campaign(ExtraViscousDamping(), 3, duration=5.0, fractions=FRACTIONS)
    report = diagnose(releases, SECTION, depth=DEPTH)
    assert report.effects == (), report.summary()
    assert not report.explained, report.summary()
    # The verdict gives the linear damping that would explain it: the hidden 0.004 in pitch
    # (0.0040 +- 0.0002 seen); heave's aerodynamic damping is ten times its own, so the
    # heave ratio is loose (0.0031 +- 0.001 seen).
    zeta_h, zeta_a = _linear_damping_verdict(report, "quadratic_damping")
    assert zeta_a == pytest.approx(0.004, rel=0.15)
    assert zeta_h == pytest.approx(0.004, abs=0.0025)


def test_friction_beside_an_unknown_viscous_damping_is_named_alone_and_not_explained():
    # Before the fix, quadratic damping was named second (c2_a 0.023, a realistic drag's
    # strength, none hidden) and the report said explained.
    releases = simulated_campaign([REALISTIC["coulomb_friction"], ExtraViscousDamping()], 2,
                                  duration=5.0, fractions=FRACTIONS)
    report = diagnose(releases, SECTION, depth=DEPTH)
    assert [step.name for step in report.effects] == ["coulomb_friction"], report.summary()
    assert not report.explained, report.summary()
    _linear_damping_verdict(report, "quadratic_damping")
