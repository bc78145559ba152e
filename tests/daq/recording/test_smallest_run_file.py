"""The writer's contract: docs/reference/file_format.md's smallest run file, and each command on it.

The file is written with h5py alone, from the page (``support.run_files.write_smallest_run``:
``/entry/config`` with a ``[section]``, seven columns of ``/entry/sync``, ``/entry/releases``;
no attributes, raw streams or events), as a program other than windrig would write it. Every
command that reads run files must take it (``info`` refused it before issue 37: "has no
/entry/instrument"), and a file without a part a command needs must be refused with one
``error:`` line naming that part. The console's replay of it is in
``tests/daq/console/test_replay_smallest_file.py`` (Qt).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from daq.cli import main
from ident.model import flat_plate, flutter

from support.run_files import write_smallest_run
from support.sections import FLAT_PLATE


@pytest.fixture(scope="module")
def smallest(tmp_path_factory):
    path = tmp_path_factory.mktemp("smallest") / "run.h5"
    write_smallest_run(path)
    return path


def test_info_describes_it_and_names_what_it_lacks(smallest, capsys):
    assert main(["info", str(smallest), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["missing"] == ["/entry/instrument", "/entry/events"]
    assert [r["U"] for r in info["releases"]] == [5.0, 8.0]
    assert info["sync"]["rows"] == 1800 and info["sync"]["rate_hz"] == pytest.approx(200.0)
    assert info["devices"] == {} and info["section"]["B"] == FLAT_PLATE.B
    assert main(["info", str(smallest)]) == 0
    text = capsys.readouterr().out
    assert "missing    /entry/instrument, /entry/events" in text
    assert "devices    none (no raw streams" in text


def test_identify_and_diagnose_take_it(smallest, tmp_path, capsys):
    out = tmp_path / "identify.json"
    assert main(["identify", str(smallest), "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    truth = flutter.analyze(FLAT_PLATE, flat_plate.jones_model()).speed
    # Noise-free simulated decays of the model itself at two speeds: E2RFC recovers its
    # flutter speed to well within 1 % (the tolerance: a unit or sign slip would be far out).
    assert result["flutter_speed"] == pytest.approx(truth, rel=0.01)
    assert main(["diagnose", str(smallest), "--out", str(tmp_path / "diag"), "--json",
                 str(tmp_path / "diag.json")]) == 0
    assert json.loads((tmp_path / "diag.json").read_text())["files"] == [str(smallest)]
    capsys.readouterr()


@pytest.mark.realtime  # a local Dask cluster: worker processes talking over sockets
def test_reprocess_takes_it(smallest, tmp_path, capsys):
    assert main(["reprocess", str(smallest), "--out", str(tmp_path / "re"), "--workers", "1",
                 "--no-progress"]) == 0
    said = capsys.readouterr().out
    assert "1 file(s): 1 used, 0 not used" in said and "2 releases at [5.0, 8.0] m/s" in said


def test_export_takes_it_and_says_it_has_no_events(smallest, tmp_path, capsys):
    out = tmp_path / "run.mat"
    assert main(["export", str(smallest), "--to", "mat", "--out", str(out)]) == 0
    assert capsys.readouterr().err == \
        f"warning: {smallest} has no /entry/events: exported without events\n"
    import scipy.io

    m = scipy.io.loadmat(out, squeeze_me=True, struct_as_record=False)
    np.testing.assert_array_equal(m["releases"].U, [5.0, 8.0])


@pytest.mark.parametrize(("omit", "command", "message"), [
    ("releases", "identify", "has no /entry/releases: not a windrig run file"),
    ("sync/lift", "identify", "has no /entry/sync/lift: not a windrig run file"),
    ("config", "diagnose", "has no /entry/config: not a windrig run file"),
    ("sync/time", "info", "has no /entry/sync/time: not a windrig run file"),
    ("sync/time", "export", "has no /entry/sync/time: not a windrig run file"),
])
def test_a_missing_part_is_one_error_line_naming_it(tmp_path, capsys, omit, command, message):
    path = tmp_path / "run.h5"
    write_smallest_run(path, omit=(omit,))
    extra = {"diagnose": ["--out", str(tmp_path / "d")], "export": ["--to", "csv"]}
    assert main([command, str(path), *extra.get(command, [])]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {path}: {message}") and len(err.splitlines()) == 1


def test_info_lists_an_absent_config_and_releases_as_missing(tmp_path, capsys):
    path = tmp_path / "run.h5"
    write_smallest_run(path, omit=("config", "releases"))
    assert main(["info", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["missing"] == ["/entry/config", "/entry/instrument", "/entry/releases",
                               "/entry/events"]
    assert info["section"] == {} and info["releases"] == []
