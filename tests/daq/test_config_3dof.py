"""Rig configs of three degrees of freedom: the sway spring in [section] and the sway laser.

A rig is 3-DOF exactly when its ``[section]`` has ``fp``; then one laser with ``axis = "sway"``
gives p, and a sway laser on a 2-DOF rig is refused. Each mistake is one ConfigError naming the
key. The shipped ``sim_bluff_deck_3dof.toml`` is the simulated bluff deck of
:mod:`simulators.decks` exactly.
"""

from __future__ import annotations

import numpy as np
import pytest

from daq.config import SHIPPED_CONFIGS, is_sway_laser, load_rig_config, parse_rig_config
from daq.errors import ConfigError
from daq.instruments.microepsilon_ild1420.settings import Ild1420Settings
from ident.model import flutter as fl
from simulators.decks import BLUFF_DECK_3DOF, bluff_deck_3dof_model

SHIPPED = SHIPPED_CONFIGS / "sim_bluff_deck_3dof.toml"
TEXT = SHIPPED.read_text(encoding="utf-8")
SWAY_LASER = '''[[lasers]]
name = "laser_sway"         # downstream of the model, looking upwind at its trailing face
driver = "microepsilon_ild1420"
url = "auto"
axis = "sway"
z = 0.0                     # m: the spot at the elastic axis' height
range_mm = 50
rate_hz = 4000.0
standoff_mm = 25.0
'''


def test_the_shipped_3dof_config_is_the_simulated_bluff_deck():
    rig = load_rig_config("sim_bluff_deck_3dof")
    assert rig.section == BLUFF_DECK_3DOF  # fp 2.6 Hz, zeta_p 0.003, m_p = m
    assert rig.section.n_dof == 3
    truth = bluff_deck_3dof_model()
    model = rig.aerodynamic_model()
    # The config stores the model's numbers; the model's Theodorsen lags come from a fit
    # (ident.model.flat_plate.theodorsen_model) whose optimum moves by ~1e-6 with the host's BLAS
    # (3e-6 measured on a fresh host): equal to 1e-5, and the same flutter speed to 1e-8.
    np.testing.assert_allclose(model.A, truth.A, rtol=1e-5, atol=1e-12)
    np.testing.assert_allclose(model.d, truth.d, rtol=1e-5, atol=0)
    assert model.A.shape == truth.A.shape and np.array_equal(model.A == 0, truth.A == 0)
    speeds = [fl.analyze(BLUFF_DECK_3DOF, m).speed for m in (model, truth)]
    assert speeds[0] == pytest.approx(speeds[1], rel=1e-8)
    assert rig.sway_laser is not None and rig.sway_laser.name == "laser_sway"
    assert [inst.name for inst in rig.heave_pitch_lasers] == ["laser_front", "laser_rear"]
    assert rig.taps.carries_drag  # the rectangle's end faces
    assert rig.simulation is not None and rig.simulation.hold_p == 0.004


def test_a_2dof_rig_has_no_sway_laser_and_no_hold_p():
    rig = load_rig_config("sim_flat_plate")
    assert rig.section.n_dof == 2 and rig.sway_laser is None
    assert len(rig.heave_pitch_lasers) == 3
    assert rig.simulation is not None and rig.simulation.hold_p == 0.0


@pytest.mark.parametrize(
    ("old", "new", "match"),
    [
        (SWAY_LASER, "", r'\[section\] fp = 2.6 Hz makes the rig 3-DOF: it needs a sway laser'),
        ("fp = 2.6", "fp = -1.0", r"\[section\] fp = -1.0 is outside the allowed range \(0.0"),
        ("fp = 2.6", 'fp = "fast"', r"\[section\] fp must be a number"),
        ("zeta_p = 0.003", "zeta_p = 0.9", r"\[section\] zeta_p = 0.9 is outside"),
        ("zeta_p = 0.003", "zeta_p = 0.003\nm_p = 0.0", r"\[section\] m_p = 0.0 is outside"),
        ("fp = 2.6           # Hz: the sway spring (three degrees of freedom)\n", "",
         r"\[section\] zeta_p needs fp"),
        ('axis = "sway"', 'axis = "sideways"',
         r"\[\[lasers\]\] #2 axis = 'sideways' is not one of \['vertical', 'sway'\]"),
        ('axis = "sway"\n', 'axis = "sway"\nx = 0.1\n',
         r"\[\[lasers\]\] #2: unknown key\(s\) \['x'\]"),
        ("z = 0.0  ", "z = 2.0  ", r"\[\[lasers\]\] #2 z = 2.0 is outside the allowed range"),
        ("hold_p = 0.004", "hold_p = 0.2", r"\[simulation\] hold_p = 0.2 is outside"),
    ],
)
def test_bad_3dof_configs_name_the_key(old, new, match):
    assert old in TEXT
    with pytest.raises(ConfigError, match=match):
        parse_rig_config(TEXT.replace(old, new, 1), "bad3.toml")


def test_a_sway_laser_or_hold_p_on_a_2dof_rig_is_refused():
    two_dof = TEXT.replace("fp = 2.6           # Hz: the sway spring (three degrees of freedom)\n"
                           "zeta_p = 0.003\n", "")
    with pytest.raises(ConfigError, match=r"'laser_sway' axis = \"sway\" needs the sway spring "
                                          r"in \[section\] \(fp, Hz\)"):
        parse_rig_config(two_dof, "two.toml")
    with pytest.raises(ConfigError, match=r"\[simulation\] hold_p needs the sway spring"):
        parse_rig_config(two_dof.replace(SWAY_LASER, ""), "two.toml")
    # Without both, the same text is a valid 2-DOF rig.
    rig = parse_rig_config(two_dof.replace(SWAY_LASER, "").replace("hold_p = 0.004", ""), "t")
    assert rig.section.n_dof == 2


def test_two_sway_lasers_are_refused():
    twice = TEXT.replace(SWAY_LASER, SWAY_LASER + "\n" + SWAY_LASER.replace(
        '"laser_sway"', '"laser_sway2"'))
    with pytest.raises(ConfigError, match=r"one sway laser .* got 2: \['laser_sway', "):
        parse_rig_config(twice, "twice.toml")


def test_the_laser_settings_know_the_axis():
    rig = load_rig_config(SHIPPED)
    sway = rig.sway_laser
    assert sway is not None and is_sway_laser(sway)
    settings = Ild1420Settings.from_table(sway.settings, "[[lasers]]")
    assert (settings.axis, settings.x, settings.z) == ("sway", 0.0, 0.0)
    vertical = Ild1420Settings.from_table(rig.heave_pitch_lasers[0].settings, "[[lasers]]")
    assert (vertical.axis, vertical.x) == ("vertical", -0.15)
    with pytest.raises(ConfigError, match="only a sway laser has a spot height z"):
        Ild1420Settings(range_mm=50, rate_hz=1000.0, x=0.1, standoff_mm=25.0, z=0.1)
    with pytest.raises(ConfigError, match="a sway laser has no chord position x"):
        Ild1420Settings(range_mm=50, rate_hz=1000.0, x=0.1, standoff_mm=25.0, axis="sway")
