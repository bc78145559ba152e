"""``windrig info`` on a closed run file with releases (crashed, recovered: test_recover.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from daq.cli import main
from daq.config import load_rig_config
from daq.recording.info import run_info
from daq.recording.synthetic import write_release_run
from ident import Release
from ident.model import flat_plate
from ident.model import flutter as fl
from simulators import simulate_release

from support.configs import SIM_FLAT_PLATE
from support.sections import FLAT_PLATE

CONFIG = SIM_FLAT_PLATE


def test_info_lists_the_releases_section_and_state(tmp_path, capsys):
    config = load_rig_config(CONFIG)
    section = FLAT_PLATE
    U_F = fl.analyze(section, flat_plate.jones_model()).speed
    releases = [Release.from_simulation(simulate_release(
        section, flat_plate.jones_model(), f * U_F, h0, 0.02, duration=4.0, fs=250.0))
        for f, h0 in ((0.5, 0.004), (0.7, -0.002))]
    path = tmp_path / "run.h5"
    write_release_run(path, config, releases)

    info = run_info(path)
    assert info["state"] == "closed" and info["rig"] == config.name
    assert info["section"]["B"] == 0.3 and info["section"]["fa"] == 4.0
    assert info["sync"]["rows"] == sum(r.t.size for r in releases)
    assert info["sync"]["rate_hz"] == pytest.approx(250.0)
    assert [r["U"] for r in info["releases"]] == pytest.approx([r.U for r in releases])
    assert [r["h0"] for r in info["releases"]] == pytest.approx([0.004, -0.002], abs=1e-6)
    assert [r["alpha0"] for r in info["releases"]] == pytest.approx([0.02, 0.02], abs=1e-6)
    assert info["releases"][0]["decay_s"] == pytest.approx(4.0, abs=0.01)
    assert info["recovery"] is None and info["calz"] == {}
    assert info["warnings"] == []  # no warning event in this file

    assert main(["info", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == json.loads(json.dumps(info))
    assert main(["info", str(path)]) == 0
    text = capsys.readouterr().out
    assert text.splitlines()[0].endswith("closed by its writer")
    assert "releases   2" in text
    U = [f"U = {r.U:6.3f} m/s" for r in releases]
    assert all(u in text for u in U) and "h0 =  +4.000 mm" in text
    assert np.isfinite(info["sync"]["duration_s"])
