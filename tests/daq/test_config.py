"""Rig configs: structure, ranges and names are validated with errors naming the key."""

from __future__ import annotations

from pathlib import Path

import pytest

from daq.config import SHIPPED_CONFIGS, parse_rig_config
from daq.errors import ConfigError

#: A minimal simulated rig (tests/daq/minimal_rig.toml, shared with the other config tests).
BASE = (Path(__file__).parent / "minimal_rig.toml").read_text(encoding="utf-8")


def test_a_valid_config_without_instruments_parses():
    """Section, taps, limits, tunnel calibration and simulation truth are read and kept."""
    rig = parse_rig_config(BASE, "base.toml")
    assert rig.section.B == 0.3 and rig.depth == 0.01
    assert rig.taps.n_taps == 2 * 16 + 2 * 2
    assert rig.limits.max_fan_rpm == 1500.0 and rig.wind_per_rpm == 0.01
    assert rig.simulation is not None and rig.simulation.pressure_pa == 101325.0
    assert rig.text == BASE  # verbatim, for the HDF5 file


@pytest.mark.parametrize(
    ("old", "new", "match"),
    [
        ("m = 3.0", "m = -3.0", r"\[section\]: m must be > 0"),
        ("zeta_h = 0.005", "zeta_h = 0.005\nzeta_x = 1",
         r"\[section\]: unknown key\(s\) \['zeta_x'\]"),
        ("depth = 0.01\n", "", r"\[section\]: missing required key\(s\) \['depth'\]"),
        ("depth = 0.01", "depth = 0.5", r"\[section\] depth = 0.5 is outside the allowed range"),
        ("max_fan_rpm = 1500.0", "max_fan_rpm = 1000.0", "cannot be reached below max_fan_rpm"),
        ("wind_per_rpm = 0.01", "wind_per_rpm = 0", r"\[tunnel\] wind_per_rpm = 0.0 is outside"),
        ("taps_per_face = 16", "taps_per_face = 1", r"\[taps\]: taps_per_face must be"),
        ('aerodynamics = "flat_plate_jones"', 'aerodynamics = "rfc"', r"\[simulation.rfc\]"),
        ("hold_alpha = 0.02", "hold_alpha = 0.5", "hold_alpha = 0.5 is outside"),
        ('name = "test rig"', 'name = "test rig"\n[fan]\nurl = "auto"',
         r"\[fan\]: missing required key 'driver'"),
        ('name = "test rig"', 'name = "test rig"\n[fan]\ndriver = "acme"\nurl = "auto"',
         r"\[fan\]: unknown driver 'acme'"),
        ("[tunnel]", "[tunnels]", r"unknown key\(s\) \['tunnels'\]"),
        ("m = 3.0", 'm = "three"', "m must be a number"),
        ('hold_alpha = 0.02',
         'hold_alpha = 0.02\n[simulation.rfc]\nA = [[[0, 0], [0, 0]]]\nd = []',
         r"\[simulation\]: an \[simulation.rfc\] table is required exactly when"),
    ],
)
def test_bad_configs_name_the_key_and_the_range(old, new, match):
    """Each mistake is a ConfigError whose message names the table, the key and the range."""
    assert old in BASE
    with pytest.raises(ConfigError, match=match):
        parse_rig_config(BASE.replace(old, new, 1), "bad.toml")


def test_invalid_toml_is_reported_with_its_source():
    """A TOML syntax error names the file."""
    with pytest.raises(ConfigError, match="broken.toml: not valid TOML"):
        parse_rig_config("[rig\nname=", "broken.toml")


def test_a_bad_rfc_table_is_refused_with_the_reason():
    """Simulated aerodynamics given as coefficients are validated like a RationalFunctionModel."""
    text = BASE.replace('aerodynamics = "flat_plate_jones"', 'aerodynamics = "rfc"')
    text += "\n[simulation.rfc]\nA = [[[0, 0], [0, 0]]]\nd = []\n"
    with pytest.raises(ConfigError, match=r"\[simulation.rfc\]: A must have shape"):
        parse_rig_config(text, "bad.toml")


TURBULENT = BASE + """
[simulation.static]
C_D = 0.02
C_L = 0.0
C_M = 0.0
dC_D = 0.0
dC_L = -6.283
dC_M = 1.571

[simulation.turbulence]
Iu = 0.0
Iw = 0.01
Lux = 1.0
Lwx = 0.3
span = 1.0
seed = 3
"""


def test_turbulence_and_static_coefficients_of_the_virtual_tunnel_are_read():
    """[simulation.static] and [simulation.turbulence]: defaults for coherence and admittance."""
    sim = parse_rig_config(TURBULENT, "turbulent.toml").simulation
    assert sim is not None and sim.static is not None and sim.turbulence is not None
    assert sim.static.dC_L == -6.283 and sim.turbulence.Iw == 0.01
    assert (sim.turbulence.Cuy, sim.turbulence.Cwy, sim.turbulence.admittance) == (10.0, 8.0,
                                                                                     "none")
    assert sim.span == 1.0 and sim.turbulence_seed == 3
    assert sim.turbulence.gaussian  # unless skewness or kurtosis are given
    gusty = parse_rig_config(TURBULENT.replace("seed = 3", "seed = 3\nkurtosis = 4.5\n"
                                               "skewness = -0.3"), "gusty.toml").simulation
    assert gusty is not None and gusty.turbulence is not None
    assert (gusty.turbulence.skewness, gusty.turbulence.kurtosis) == (-0.3, 4.5)
    smooth = parse_rig_config(BASE, "base.toml").simulation
    assert smooth is not None and smooth.turbulence is None and smooth.static is None


@pytest.mark.parametrize(
    ("old", "new", "match"),
    [
        ("Iw = 0.01", "Iw = 0.9", r"\[simulation.turbulence\] Iw = 0.9 is outside"),
        ("Lwx = 0.3", "Lwx = 0.0", r"\[simulation.turbulence\] Lwx = 0.0 is outside"),
        ("span = 1.0\n", "", r"\[simulation.turbulence\]: missing required key\(s\) \['span'\]"),
        ("seed = 3", "seed = -1", r"\[simulation.turbulence\] seed must be an integer >= 0"),
        ("seed = 3", 'admittance = "sears"', "admittance must be 'none' or 'davenport'"),
        ("seed = 3", "kurtosis = 2.5", r"\[simulation.turbulence\] kurtosis = 2.5 is outside"),
        ("dC_M = 1.571", "dC_M = 1.571\nC_X = 1", r"\[simulation.static\]: unknown key"),
        ("[simulation.static]\nC_D = 0.02\nC_L = 0.0\nC_M = 0.0\ndC_D = 0.0\ndC_L = -6.283\n"
         "dC_M = 1.571\n", "", r"turbulence\] needs a \[simulation.static\] table"),
    ],
)
def test_bad_turbulence_tables_name_the_key(old, new, match):
    assert old in TURBULENT
    with pytest.raises(ConfigError, match=match):
        parse_rig_config(TURBULENT.replace(old, new, 1), "bad.toml")


def test_max_fan_rpm_may_not_exceed_the_drives_full_scale():
    """A rig limit the fan drive can never be sent is the config's mistake, named on loading."""
    text = (SHIPPED_CONFIGS / "sim_flat_plate.toml").read_text(encoding="utf-8")
    assert "max_fan_rpm = 1300.0" in text and "max_rpm = 1500.0" in text
    with pytest.raises(ConfigError, match=r"rig.toml \[limits\] max_fan_rpm = 1600 is above "
                                          r"\[fan\] max_rpm = 1500.*max_fan_rpm <= 1500"):
        parse_rig_config(text.replace("max_fan_rpm = 1300.0", "max_fan_rpm = 1600.0"), "rig.toml")
    rig = parse_rig_config(text.replace("max_fan_rpm = 1300.0", "max_fan_rpm = 1500.0"))
    assert rig.limits.max_fan_rpm == 1500.0  # up to the full scale itself


@pytest.mark.parametrize("old, new, laser, swing", [
    ("hold_h = 0.008", "hold_h = 0.045", "laser_front", "41"),  # 45 mm - 0.1 m x 0.04 rad
    ("hold_h = 0.008", "hold_h = -0.03", "laser_front", "34"),  # the other side: -30 - 4 mm
])
def test_a_simulated_hold_beyond_the_lasers_range_is_refused(old, new, laser, swing):
    """The hold (and the decay's swing the other way) must stay in every laser's range.

    Before, the simulated model was held where the lasers read error values: the device check
    failed on three lasers without naming the hold, and ``--skip-check`` recorded no release.
    """
    text = (SHIPPED_CONFIGS / "sim_flat_plate.toml").read_text(encoding="utf-8")
    assert old in text and "standoff_mm = 25.0" in text and "range_mm = 50" in text
    with pytest.raises(ConfigError, match=rf"rig.toml \[simulation\] hold_h, hold_alpha: the hold "
                                          rf"moves {laser}'s reading {swing} mm from its standoff "
                                          r"25 mm.*0..50 mm; allowed: at most 25 mm"):
        parse_rig_config(text.replace(old, new), "rig.toml")
    parse_rig_config(text.replace(old, "hold_h = 0.02"), "rig.toml")  # 24 mm at most: fine
