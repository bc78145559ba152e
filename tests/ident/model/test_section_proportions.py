"""A section whose width, mass and inertia do not fit together: the unit slip named.

The sections windrig's tests, benchmarks and rigs use, and a full-scale deck, pass; each unit
slip of :data:`ident.model.section._UNIT_SLIPS` applied to the tests' flat plate is warned
of, naming the field and the value it would have in SI units. A slip changes the proportions
by 10 to 10^7 times; the ranges are three times wider than any section model's.
"""

from __future__ import annotations

import re

import pytest

from ident.model.section import SectionModel, proportion_warnings

from support.sections import FLAT_PLATE

#: The Great Belt East Bridge's deck (B 31 m, 22.74 t/m, 2.47e6 kg m^2/m): full scale.
GREAT_BELT = SectionModel(B=31.0, m=22740.0, I=2.47e6, fh=0.10, fa=0.278, zeta_h=0.003,
                          zeta_a=0.003)


@pytest.mark.parametrize("section", [
    FLAT_PLATE, GREAT_BELT,
    SectionModel(B=0.4, m=8.0, I=0.12, fh=1.5, fa=3.5, zeta_h=0.003, zeta_a=0.003),
    SectionModel(B=0.5, m=8.0, I=8.0 * (0.3 * 0.5) ** 2, fh=1.0, fa=2.5, zeta_h=0.02,
                 zeta_a=0.02, rho=1.18),
], ids=["plate", "Great Belt", "cli section", "flutter test section"])
def test_real_sections_pass(section):
    assert proportion_warnings(section) == []


@pytest.mark.parametrize(("change", "named"), [
    ({"B": 300.0}, "B looks like millimetres (B = 0.3 m?)"),
    ({"B": 30.0}, "B looks like centimetres (B = 0.3 m?)"),
    ({"m": 3000.0}, "m looks like g/m (m = 3 kg/m?)"),
    ({"m": 0.003}, "m looks like t/m (m = 3 kg/m?)"),
    ({"I": 300.0}, "I looks like kg cm^2/m (I = 0.03 kg m^2/m?)"),
    ({"I": 3.0e5}, "I looks like g cm^2/m (I = 0.03 kg m^2/m?)"),
    ({"m": 3000.0, "I": 30.0}, "m and I look like grams (g/m, g m^2/m) (m = 3 kg/m, "
                               "I = 0.03 kg m^2/m?)"),
], ids=["B mm", "B cm", "m g", "m t", "I kg cm2", "I g cm2", "m and I g"])
def test_each_unit_slip_is_named_with_the_value_in_si(change, named):
    (warning,) = proportion_warnings(FLAT_PLATE.replace(**change), source="deck.json")
    assert warning.startswith("deck.json: the section's proportions are not a section model's")
    assert named in warning


def test_two_slips_that_fit_name_the_nearer_and_say_so():
    """I in g m^2/m (x1000) also fits kg cm^2/m (x10^4) at a gyration of 0.1 of B."""
    (warning,) = proportion_warnings(FLAT_PLATE.replace(I=30.0))
    assert "I looks like g m^2/m (I = 0.03 kg m^2/m?), or another unit" in warning


def test_no_slip_explains_it_then_the_units_are_listed():
    (warning,) = proportion_warnings(FLAT_PLATE.replace(I=1e-4))
    assert re.search(r"is 0\.019 of the width .*check their units \(B in m, m in kg/m", warning)
