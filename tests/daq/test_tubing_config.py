"""The rig config's [[taps.tubing]] tables: parsed into tubing groups, bad values named."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from daq.config import load_rig_config, parse_rig_config
from daq.errors import ConfigError
from daq.tubing_config import tubing_metadata
from ident.physics.tubing import TableResponse, Tube

#: A minimal simulated rig (tests/daq/minimal_rig.toml, shared with the other config tests).
BASE = (Path(__file__).parent / "minimal_rig.toml").read_text(encoding="utf-8")

TUBES = """
[[taps.tubing]]
taps = [0, 1, 2]
length = 1.0
diameter = 1.0e-3
volume = 300e-9

[[taps.tubing]]
taps = [3]
length = 0.5
diameter = 1.5e-3
volume = 0.0
k = 1.0
"""


def _with(extra: str, simulation: str = "") -> str:
    head, tail = BASE.split("[limits]")
    return head + extra + "\n[limits]" + tail + simulation


def test_without_tubing_tables_a_config_has_none():
    assert parse_rig_config(BASE).tubing == ()


def test_tubing_groups_are_read_with_their_taps_and_tubes():
    config = parse_rig_config(_with(TUBES))
    assert config.taps.n_taps == 36  # the tubing did not disturb the layout
    first, second = config.tubing
    assert first.taps == (0, 1, 2)
    assert first.model == Tube(length=1.0, diameter=1e-3, volume=300e-9)
    assert second.taps == (3,) and second.model == Tube(0.5, 1.5e-3, 0.0, k=1.0)
    meta = tubing_metadata(config.tubing, config.taps.n_taps)
    assert meta["group_0"]["taps"] == [0, 1, 2] and meta["group_1"]["k"] == 1.0


def test_a_measured_table_is_read_relative_to_the_config_file(tmp_path):
    (tmp_path / "tube.csv").write_text("frequency,gain,phase_deg\n10,1.0,-5\n100,0.5,-90\n")
    path = tmp_path / "rig.toml"
    path.write_text(_with('[[taps.tubing]]\ntaps = "all"\ntable = "tube.csv"\n'))
    (group,) = load_rig_config(path).tubing
    assert group.taps is None
    assert isinstance(group.model, TableResponse)
    np.testing.assert_allclose(group.model.frequency, [10.0, 100.0])


def test_simulation_tubing_applies_the_configs_tubes():
    config = parse_rig_config(_with(TUBES, "tubing = true\n"))
    assert config.simulation is not None and config.simulation.tubing


@pytest.mark.parametrize("extra, simulation, match", [
    ('[[taps.tubing]]\nlength = -1.0\ndiameter = 1e-3\nvolume = 0.0\n', "",
     r"\[\[taps.tubing\]\] #0 length = -1.0 is outside the allowed range"),
    ('[[taps.tubing]]\nlength = 1.0\ndiameter = 1e-3\n', "",
     r"#0: missing required key\(s\) \['volume'\]"),
    ('[[taps.tubing]]\nlength = 1.0\ndiameter = "thin"\nvolume = 0.0\n', "",
     r"#0 diameter must be a number"),
    ('[[taps.tubing]]\nlength = 1.0\ndiameter = 1e-3\nvolume = 0.0\nbore = 1\n', "",
     r"#0: unknown key\(s\) \['bore'\]"),
    ('[[taps.tubing]]\ntaps = [40]\nlength = 1.0\ndiameter = 1e-3\nvolume = 0.0\n', "",
     r"#0 taps: \[40\] outside the layout's taps 0..35"),
    ('[[taps.tubing]]\ntaps = "some"\nlength = 1.0\ndiameter = 1e-3\nvolume = 0.0\n', "",
     r"#0 taps must be \"all\" or a non-empty list"),
    (TUBES + '[[taps.tubing]]\ntaps = [2]\nlength = 1.0\ndiameter = 1e-3\nvolume = 0.0\n', "",
     r"#2 taps: tap 2 is already in \[\[taps.tubing\]\] #0"),
    ('[[taps.tubing]]\ntable = "no_such.csv"\n', "", r"#0 table: cannot read .*no_such.csv"),
    ('[[taps.tubing]]\ntable = "t.csv"\nlength = 1.0\n', "", r"#0: unknown key\(s\) \['length'\]"),
    ('tubing = 3\n', "", r"\[taps\] tubing must be an array of tables"),
    ("", "tubing = true\n", r"\[simulation\] tubing = true needs \[\[taps.tubing\]\]"),
    (TUBES, "tubing = 1\n", r"\[simulation\] tubing must be true or false"),
])
def test_bad_tubing_tables_name_the_key(extra, simulation, match):
    with pytest.raises(ConfigError, match=match):
        parse_rig_config(_with(extra, simulation))
