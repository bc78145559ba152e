"""The section and the identified model against the measured decays.

The still-air frequencies are checked on the modes the simulated releases ring at (the flat
plate of the tests, Jones's aerodynamics, 2 % noise), through both identification routes, and
in turbulence on the spectral peaks; the force scale on exact eigenvalues of the section with
the model.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from ident.errors import PlausibilityError
from ident.identification import e2rfc, fd_method
from ident.model import flat_plate, flutter
from ident.model.quasi_steady import StaticCoefficients
from ident.model.rfc import RationalFunctionModel
from ident.model.statespace import AeroelasticSystem
from ident.physics.turbulence import TurbulenceSpec
from ident.records import decay_checks
from ident.records.release import Release
from simulators.tunnel import simulate_release

from support.sections import FLAT_PLATE

JONES = flat_plate.jones_model()
U_F = flutter.analyze(FLAT_PLATE, JONES).speed
SWAY = dataclasses.replace(FLAT_PLATE, fp=1.3, zeta_p=0.004)
IN_RAD_S = dataclasses.replace(FLAT_PLATE, fh=2 * math.pi * FLAT_PLATE.fh,
                               fa=2 * math.pi * FLAT_PLATE.fa)
SWAPPED = dataclasses.replace(FLAT_PLATE, fh=FLAT_PLATE.fa, fa=FLAT_PLATE.fh)
#: The sections the identification refuses, with what its error says.
REFUSED_SECTIONS = pytest.mark.parametrize(
    ("section", "match"), [(IN_RAD_S, "look like rad/s"), (SWAPPED, "fh and fa look swapped")],
    ids=["rad/s", "swapped"])


@pytest.fixture(scope="module")
def releases():
    """Two releases at each of 0.4, 0.6 and 0.8 of the flutter speed, 10 s at 250 Hz, seeded."""
    return [Release.from_simulation(simulate_release(
        FLAT_PLATE, JONES, fraction * U_F, 0.004, 0.02, duration=10.0, fs=250.0, noise=0.02,
        rng=(7, j, i))) for i, fraction in enumerate((0.4, 0.6, 0.8)) for j in range(2)]


def test_still_air_frequencies_a_few_per_cent_off_pass():
    """The wind moves a mode by a few per cent at the lowest speed: no word."""
    assert decay_checks.check_frequencies(FLAT_PLATE, [4.7, 9.4], [[2.06, 3.87], [2.1, 3.3]]) == []


def test_a_first_release_near_flutter_is_not_refused():
    """The plate at 0.98 of its flutter speed: pitch at 0.75 fa, within the warning's factor."""
    assert decay_checks.check_frequencies(FLAT_PLATE, [11.5], [[2.06, 2.99]]) == []


@pytest.mark.parametrize(("section", "match"), [
    (IN_RAD_S, r"look like rad/s, not Hz.*fh = 2 Hz, fa = 4 Hz"),
    (dataclasses.replace(FLAT_PLATE, fh=FLAT_PLATE.fh / (2 * math.pi),
                         fa=FLAT_PLATE.fa / (2 * math.pi)), "divided by 2 pi once too often"),
    (SWAPPED, r"fh and fa look swapped.*swap them \(fh = 2 Hz, fa = 4 Hz\)"),
], ids=["rad/s", "divided twice", "swapped"])
def test_frequencies_in_a_wrong_unit_or_swapped_are_refused_naming_it(section, match):
    with pytest.raises(PlausibilityError, match=match):
        decay_checks.check_frequencies(section, [4.7, 4.7, 9.4],
                                       [[2.0, 3.87], [2.01, 3.88], [2.1, 3.2]])


def test_three_degrees_of_freedom_name_the_pair_swapped():
    swapped = dataclasses.replace(SWAY, fh=SWAY.fp, fp=SWAY.fh)
    with pytest.raises(PlausibilityError, match=r"fh and fp look swapped"):
        decay_checks.check_frequencies(swapped, [4.0], [[2.02, 3.9, 1.31]])
    assert decay_checks.check_frequencies(SWAY, [4.0], [[2.02, 3.9, 1.31]]) == []


def test_frequencies_off_in_no_known_way_are_warned_of():
    """Pitch at half its still-air frequency: no unit explains it, so a warning, not an error."""
    warnings = decay_checks.check_frequencies(FLAT_PLATE, [4.7], [[2.0, 2.0]])
    assert len(warnings) == 1 and "not the releases'" in warnings[0]
    assert "2 Hz (pitch)" in warnings[0] and "fa = 4 Hz" in warnings[0]


@REFUSED_SECTIONS
def test_e2rfc_refuses_a_section_whose_frequencies_the_decays_deny(releases, section, match):
    """Unguarded, rad/s gave +528 % with a std of 0.3 %, swapped "no flutter"; each a misfit."""
    with pytest.raises(PlausibilityError, match=match):
        e2rfc.identify(releases, section)


@REFUSED_SECTIONS
def test_the_displacement_route_refuses_them_too(releases, section, match):
    with pytest.raises(PlausibilityError, match=match):
        fd_method.identify(releases, section)


def test_both_routes_accept_the_right_section(releases):
    assert fd_method.flutter_derivatives(releases, FLAT_PLATE).warnings == ()
    model = e2rfc.identify(releases, FLAT_PLATE)
    assert not [w for w in model.diagnostics.warnings if "frequencies" in w]


def test_damping_in_per_cent_is_refused_naming_the_values():
    """0.5 meant as 0.5 %: 50 % of critical against a 1.9 % pitch decay at the lowest speed."""
    per_cent = dataclasses.replace(FLAT_PLATE, zeta_h=0.5)
    with pytest.raises(PlausibilityError, match=r"per cent.*zeta_h = 0\.5 \(50 %\).*give "
                                                 r"zeta_h = 0\.005$"):
        decay_checks.check_damping(per_cent, [4.7, 4.7, 9.4],
                                   [[0.053, 0.019], [0.054, 0.018], [0.18, 0.02]])


def test_damping_above_the_measured_total_is_warned_of_and_near_it_passes():
    """Warn of 5 % against a 1.9 % decay; not of 0.5 % against 0.1 %.

    The second is a pitch near torsional flutter at the lowest speed: within the excess a
    warning needs (1 % of critical).
    """
    heavy = dataclasses.replace(FLAT_PLATE, zeta_a=0.05)
    (warning,) = decay_checks.check_damping(heavy, [4.7], [[0.053, 0.019]])
    assert "zeta_a = 0.05 (5 % of critical)" in warning and "1.9 % of critical (pitch)" in warning
    assert decay_checks.check_damping(FLAT_PLATE, [4.7], [[0.053, 0.001]]) == []
    assert decay_checks.check_damping(FLAT_PLATE, [4.7], [[0.053, 0.019]]) == []


def test_a_mode_growing_at_the_lowest_speed_blames_the_releases_not_the_damping():
    """A heave decaying at -2.3 % of critical is not a free decay: zeta_h is not checked."""
    (warning,) = decay_checks.check_damping(FLAT_PLATE, [4.7], [[-0.023, 0.019]])
    assert warning.startswith("the heave mode grows at the lowest wind speed")
    assert "-2.3 % of critical (heave)" in warning and "zeta_h is not checked" in warning
    assert "check the section's damping" not in warning


def test_e2rfc_refuses_damping_in_per_cent(releases):
    """Unguarded, 50 % of critical gave a warning that blamed the forces' sign or unit."""
    per_cent = dataclasses.replace(FLAT_PLATE, zeta_h=0.5, zeta_a=0.5)
    with pytest.raises(PlausibilityError, match="looks given in per cent"):
        e2rfc.identify(releases, per_cent)
    with pytest.raises(PlausibilityError, match="looks given in per cent"):
        fd_method.identify(releases, per_cent)


def turbulent_releases(Lwx):
    """Simulate the plate at 0.4 and 0.6 of U_F in 1 % vertical turbulence, 20 s at 500 Hz.

    Two releases per speed (seeded), from the benchmark's two holds, 2 % noise; ``Lwx`` the
    gusts' length scale, m (0.3 the benchmark's, 1.0 its long-gust variant).
    """
    wind = {"static": StaticCoefficients.flat_plate(), "span": 1.0,
            "turbulence": TurbulenceSpec(Iu=0.0, Iw=0.01, Lux=1.0, Lwx=Lwx, Cuy=10.0, Cwy=8.0)}
    return [Release.from_simulation(simulate_release(
        FLAT_PLATE, JONES, fraction * U_F, h0, a0, duration=20.0, fs=500.0, noise=0.02,
        rng=(11, i, j), **wind))
        for i, fraction in enumerate((0.4, 0.6))
        for j, (h0, a0) in enumerate(((0.004, 0.02), (-0.003, 0.012)))]


@pytest.fixture(scope="module", params=[0.3, 1.0], ids=["Lwx 0.3 m", "Lwx 1 m"])
def buffeted(request):
    return turbulent_releases(request.param)


def test_in_turbulence_each_coordinate_rings_at_its_mode(buffeted):
    """At the lowest speed the spectral peaks lie within 10 % of fh and fa.

    The benchmark's turbulence rows without friction (plate and bluff deck at Iw 1 and 3 %,
    long and non-Gaussian gusts; 20 seeds, with and without holds) put the median at the
    lowest speed within 7.6 % of the still-air frequencies; the long gusts' quasi-static
    heave, which tops the displacement's spectrum at 0.12-0.25 Hz, does not top the
    velocity's.
    """
    lowest = [r for r in buffeted if r.U == min(r.U for r in buffeted)]
    for release in lowest:
        fh, fa = decay_checks.ringing_frequencies(release, 2)
        assert fh == pytest.approx(FLAT_PLATE.fh, rel=0.10)
        assert fa == pytest.approx(FLAT_PLATE.fa, rel=0.10)
    speeds = [r.U for r in buffeted]
    rung = [decay_checks.ringing_frequencies(r, 2) for r in buffeted]
    assert decay_checks.check_frequencies(FLAT_PLATE, speeds, rung) == []


@REFUSED_SECTIONS
def test_in_turbulence_e2rfc_refuses_them_as_well(buffeted, section, match):
    """Before, the modal fits of buffeted releases were not used, and nothing checked."""
    with pytest.raises(PlausibilityError, match=match):
        e2rfc.identify(buffeted, section)


def test_the_peak_lies_between_bins():
    """Two tones at 2.03 and 4.17 Hz, 10 s at 100 Hz: bins of 0.2 Hz, the peaks within 2 %.

    A Hann window's main lobe is nearly a Gaussian, whose logarithm the parabola fits; the
    velocity's weight f^2 tilts it up by a little (measured 0.8 and 0.1 %, 0.016 and 0.005
    Hz: a tenth of a bin at most; the nearest bins are 0.03 Hz off).
    """
    t = np.arange(1000) / 100.0
    release = Release(t=t, h=np.sin(2 * np.pi * 2.03 * t), alpha=np.cos(2 * np.pi * 4.17 * t),
                      lift=np.zeros(t.size), moment=np.zeros(t.size), U=5.0)
    fh, fa = decay_checks.ringing_frequencies(release, 2)
    assert fh == pytest.approx(2.03, rel=0.02) and fa == pytest.approx(4.17, rel=0.02)


def test_force_scale_of_the_true_model_is_one_and_of_a_scaled_one_its_inverse():
    """Eigenvalues of the section with the model: measured = predicted when the scale is 1."""
    speeds = [4.0, 8.0]
    measured = []
    for U in speeds:
        lam = AeroelasticSystem(FLAT_PLATE, JONES, U).eigenvalues()
        measured.append(np.sort_complex(lam[lam.imag > 1e-6]))
    k, misfit = decay_checks.force_scale(FLAT_PLATE, JONES, speeds, measured)
    # Exact eigenvalues: the bounded search's tolerance (1e-4 in log k).
    assert k == pytest.approx(1.0, abs=1e-4) and misfit < 1e-4
    scaled = RationalFunctionModel(0.8 * JONES.A, JONES.d)
    k, _ = decay_checks.force_scale(FLAT_PLATE, scaled, speeds, measured)
    assert k == pytest.approx(1 / 0.8, rel=1e-3)
