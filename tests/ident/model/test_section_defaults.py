"""The defaults a section file leaves to be taken, named so that a command records them."""

from __future__ import annotations

from ident.model.section import SectionModel, section_defaults

GIVEN = {"B": 31.0, "m": 22740.0, "I": 2.47e6, "fh": 0.10, "fa": 0.278, "zeta_h": 0.003,
         "zeta_a": 0.003}


def test_each_default_taken_is_named_with_its_value():
    lines = section_defaults(GIVEN, "deck.json")
    assert lines == ["deck.json: no air density rho: taken as 1.225 kg/m^3 (ISA sea level)",
                     "deck.json: no static unbalance S: taken as 0 kg m/m (the centre of mass "
                     "on the elastic axis)"]
    # The values named are those SectionModel takes.
    section = SectionModel.from_dict(GIVEN)
    assert section.rho == 1.225 and section.S == 0.0


def test_sway_defaults_are_named_and_a_full_section_takes_none():
    sway = {**GIVEN, "fp": 0.05}
    lines = section_defaults(sway)
    assert lines[2:] == ["no zeta_p: taken as 0 (no structural damping in sway)",
                         "no m_p: taken as m = 22740 kg/m (the sway carriage adds no mass)"]
    section = SectionModel.from_dict(sway)
    assert section.zeta_p == 0.0 and section.m_p == 22740.0
    full = {**sway, "rho": 1.22, "S": 0.0, "zeta_p": 0.005, "m_p": 23000.0}
    assert section_defaults(full) == []

