"""``windrig info`` on a closed run file with releases (crashed, recovered: test_recover.py)."""

from __future__ import annotations

import json

import h5py
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
from support.run_files import write_smallest_run
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


@pytest.mark.parametrize(("part", "value", "said"), [
    ("releases", np.zeros((2, 6)), "/entry/releases is a float64 array of shape (2, 6), not a "
                                   "table of rows with the fields release_time, start_index, "
                                   "stop_index, U (docs/reference/file_format.md)"),
    ("sync/h", np.array([b"x"] * 1800), "/entry/sync/h holds |S1 values, not numbers"),
], ids=["releases as a plain array", "h as text"])
def test_info_names_a_part_another_program_wrote_in_another_layout(tmp_path, capsys, part,
                                                                    value, said):
    # Before: an IndexError (a release table of plain numbers) or a TypeError (a text column)
    # with a traceback.
    path = tmp_path / "foreign.h5"
    write_smallest_run(path)
    with h5py.File(path, "r+") as f:
        del f[f"entry/{part}"]
        f[f"entry/{part}"] = value
    assert main(["info", str(path)]) == 2
    assert capsys.readouterr().err == f"error: {path}: {said}\n"


def test_info_shows_a_release_table_without_h0_and_alpha0(tmp_path):
    # They are shown, not needed to identify: a converter that leaves them out is described.
    path = tmp_path / "foreign.h5"
    write_smallest_run(path)
    with h5py.File(path, "r+") as f:
        table = f["entry/releases"][()]
        del f["entry/releases"]
        keep = ("release_time", "start_index", "stop_index", "U")
        f["entry/releases"] = np.array([tuple(row[n] for n in keep) for row in table],
                                       dtype=[(n, table.dtype[n]) for n in keep])
    info = run_info(path)
    assert [r["U"] for r in info["releases"]] == [5.0, 8.0]
    assert info["releases"][0]["h0"] is None and info["releases"][0]["alpha0"] is None


def test_info_warns_of_the_release_rows_identify_refuses_or_leaves_out(tmp_path, capsys):
    # Before: a release listed twice, a negative wind speed or an empty row were listed as
    # any other, and the JSON's warnings were empty; identify then refused the file.
    path = tmp_path / "foreign.h5"
    write_smallest_run(path)
    with h5py.File(path, "r+") as f:
        table = f["entry/releases"][()]
        table["U"][0] = -5.0
        empty = table[1:].copy()
        # As the recorder writes a release commanded as the recording ends: U unknown.
        empty["release_time"], empty["stop_index"] = 8.9, empty["start_index"]
        empty["U"] = np.nan
        del f["entry/releases"]
        f["entry/releases"] = np.concatenate([table, table[1:], empty])
    assert main(["info", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    expected = [f"{path}: releases 1 and 2 of /entry/releases have the same release_time 5 s: "
                "one release listed twice? (each release is one row)",
                f"{path}: release 0 has U = -5 m/s: a wind speed must be > 0 m/s",
                f"{path}: release 3 holds no rows of /entry/sync (released as the recording "
                "ended?): identify leaves it out"]
    assert info["warnings"] == info["release_problems"] == expected
    assert main(["info", str(path)]) == 0
    text = capsys.readouterr().out
    assert all(f"  warning: {w}\n" in text for w in expected)
