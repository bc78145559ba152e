"""Every command answers bad input with one ``error:`` line and the right exit status.

Exit 2 for what the user gave (a command-line value, a missing or malformed file, a bad config),
1 for a failure while running (data that cannot be identified); never a traceback unless
``--debug``. Each case runs the command line in-process (``daq.cli.main``) and reads stderr.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import pytest

from daq.cli import main
from daq.config import load_rig_config
from daq.recording.synthetic import write_release_run
from ident import Release, SectionModel
from ident.model import flat_plate
from ident.model import flutter as fl
from simulators import simulate_release

from support.configs import SIM_FLAT_PLATE

SIM_CONFIG = SIM_FLAT_PLATE
SECTION = {"B": 0.3, "m": 3.0, "I": 0.03, "fh": 2.0, "fa": 4.0, "zeta_h": 0.005,
           "zeta_a": 0.005}


@pytest.fixture
def files(tmp_path: Path) -> Path:
    """Return a folder of bad inputs: text, HDF5 without a run, TOML and JSON mistakes."""
    (tmp_path / "text.txt").write_text("hello\n")
    with h5py.File(tmp_path / "empty.h5", "w") as f:
        f.create_group("entry")
    (tmp_path / "broken.toml").write_text("[rig\nname=")
    (tmp_path / "missing_keys.toml").write_text('[rig]\nname = "x"\n')
    bad_mass = SIM_CONFIG.read_text().replace("m = 3.0 ", "m = -3.0 ", 1)
    assert bad_mass != SIM_CONFIG.read_text()
    (tmp_path / "bad_mass.toml").write_text(bad_mass)
    (tmp_path / "bad.json").write_text('{"B": 0.3')
    (tmp_path / "section.json").write_text(json.dumps(SECTION))
    (tmp_path / "sway.json").write_text(json.dumps({**SECTION, "fp": 1.0}))
    (tmp_path / "table.csv").write_text("K,H1,A2\n0.5,-12,-0.4\n1,-6,-0.2\n")
    (tmp_path / "bad_table.csv").write_text("K,H1,A2\n0.5,-12,-0.4\n1,-6,x\n")
    (tmp_path / "bad_section.json").write_text(json.dumps({**SECTION, "m": -1.0}))
    (tmp_path / "list.json").write_text("[1, 2]")
    (tmp_path / "model_bad.json").write_text(json.dumps({"A": [[[0, 0], [0, 0]]], "d": []}))
    (tmp_path / "model.json").write_text(json.dumps(flat_plate.jones_model().to_dict()))
    section = SectionModel(**SECTION)
    U_F = fl.analyze(section, flat_plate.jones_model()).speed
    one_speed = [Release.from_simulation(simulate_release(
        section, flat_plate.jones_model(), 0.6 * U_F, 0.004, 0.02, duration=6.0, fs=250.0))
        for _ in range(2)]
    write_release_run(tmp_path / "one_speed.h5", load_rig_config(SIM_CONFIG), one_speed)
    data = (tmp_path / "one_speed.h5").read_bytes()
    (tmp_path / "truncated.h5").write_bytes(data[:len(data) // 3])
    return tmp_path


CASES = [
    # (arguments, exit status, what the error line must say)
    (["identify", "{d}/nothing.h5"], 2, "nothing.h5: no such file"),
    (["check", "--config", str(SIM_CONFIG), "--simulate", "--json", "{d}/no/such/c.json"], 2,
     "folder"),
    (["identify", "{d}/text.txt"], 2, "text.txt: not an HDF5 file"),
    (["identify", "{d}/empty.h5"], 2, "empty.h5: has no /entry/config: not a windrig run file"),
    (["identify", "{d}"], 2, "a directory, not a run file"),
    (["identify", "{d}/one_speed.h5"], 1, "releases at one wind speed"),
    (["diagnose", "{d}/nothing.h5", "--out", "{d}/o"], 2, "nothing.h5: no such file"),
    (["diagnose", "{d}/text.txt", "--out", "{d}/o"], 2, "text.txt: not an HDF5 file"),
    (["acquire", "--config", "{d}/broken.toml", "--duration", "5", "--out", "{d}/r.h5"], 2,
     "broken.toml: not valid TOML"),
    (["acquire", "--config", "{d}/missing_keys.toml", "--duration", "5", "--out", "{d}/r.h5"], 2,
     "missing_keys.toml: missing required key(s)"),
    (["acquire", "--config", "{d}/bad_mass.toml", "--duration", "5", "--out", "{d}/r.h5"], 2,
     "[section]: m must be > 0"),
    (["acquire", "--config", "{d}/nothing.toml", "--duration", "5", "--out", "{d}/r.h5"], 2,
     "nothing.toml"),
    (["acquire", "--config", str(SIM_CONFIG), "--simulate", "--duration", "-5", "--out",
      "{d}/r.h5"], 2, "--duration -5: must be > 0 s"),
    (["simulate", "--config", "{d}/broken.toml"], 2, "broken.toml: not valid TOML"),
    (["simulate", "--config", str(SIM_CONFIG), "--duration", "0"], 2,
     "--duration 0: must be > 0 s"),
    (["flutter", "--section", "{d}/bad.json", "--model", "{d}/model.json"], 2,
     "bad.json: not valid JSON"),
    (["flutter", "--section", "{d}/nothing.json", "--model", "{d}/model.json"], 2,
     "nothing.json: cannot read the section file"),
    (["flutter", "--section", "{d}/list.json", "--model", "{d}/model.json"], 2,
     "list.json: expected a JSON object of SectionModel fields"),
    (["flutter", "--section", "{d}/bad_section.json", "--model", "{d}/model.json"], 2,
     "bad_section.json: m must be > 0"),
    (["flutter", "--section", "{d}/section.json", "--model", "{d}/model_bad.json"], 2,
     "model_bad.json: not a rational-function model"),
    (["flutter", "--section", "{d}/sway.json", "--model", "{d}/model.json"], 2,
     "is a model of heave and pitch only"),
    (["flutter", "--section", "{d}/sway.json", "--table", "{d}/table.csv"], 2,
     "has the derivatives of heave and pitch only"),
    (["flutter", "--section", "{d}/section.json", "--table", "{d}/bad_table.csv"], 2,
     "bad_table.csv, line 3: 'x' is not a number"),
    (["flutter", "--section", "{d}/section.json", "--table", "{d}/nothing.csv"], 2,
     "nothing.csv: no such file"),
    (["flutter", "--section", "{d}/section.json", "--model", "{d}/model.json", "--u-max", "-3"],
     2, "--u-max -3: must be > 0 m/s"),
    (["reprocess", "{d}/nothing*", "--out", "{d}/r"], 2, "nothing*: no such run file"),
    (["gui", "--replay", "{d}/nothing.h5"], 2, "nothing.h5: no such file"),
    (["gui", "--replay", "{d}/text.txt"], 2, "text.txt"),
    (["recover", "{d}/nothing.h5"], 2, "nothing.h5: No such file or directory"),
    (["acquire", "--config", "sim_nothing", "--simulate", "--duration", "1", "--out",
      "{d}/r.h5"], 2,
     "shipped configs, by name: example_real_rig, sim_bluff_deck_3dof, sim_flat_plate, "
     "sim_flat_plate_nidaq, sim_streamlined_deck"),
    (["recover", "{d}/text.txt"], 2, "text.txt: not an HDF5 file"),
    (["recover", "{d}/empty.h5"], 2, "empty.h5: has no /entry/sync: not a windrig run file"),
    (["recover", "{d}"], 2, "a directory, not a run file"),
    (["recover", "{d}/one_speed.h5", "{d}/text.txt"], 2, "text.txt: not an HDF5 file"),
    (["info", "{d}/nothing.h5"], 2, "nothing.h5: No such file or directory"),
    (["info", "{d}/text.txt"], 2, "text.txt: not an HDF5 file"),
    (["info", "{d}/empty.h5"], 2,
     "error: {d}/empty.h5: has no /entry/sync: not a windrig run file"),
    (["info", "{d}", "--json"], 2, "a directory, not a run file"),
    (["info", "{d}/truncated.h5"], 2, "truncated.h5: HDF5 cannot open it (truncated?)"),
    (["identify", "{d}/truncated.h5"], 2, "truncated.h5: cannot be opened as HDF5"),
    (["recover", "{d}/truncated.h5"], 1, "truncated.h5: HDF5 cannot read it even read-only"),
    # --json read as a flag (as windrig info's): the run file after it is not overwritten.
    (["identify", "--json", "{d}/one_speed.h5", "{d}/one_speed.h5"], 2,
     "--json {d}/one_speed.h5: an HDF5 file (a run file?) that the output would overwrite"),
    (["diagnose", "--json", "{d}/empty.h5", "{d}/one_speed.h5", "--out", "{d}/o"], 2,
     "--json {d}/empty.h5: an HDF5 file"),
]


@pytest.mark.parametrize(("argv", "status", "message"), CASES,
                         ids=[" ".join(c[0][:2]) + f" [{i}]" for i, c in enumerate(CASES)])
def test_bad_input_is_one_error_line(files, capsys, argv, status, message):
    code = main([a.replace("{d}", str(files)) for a in argv])
    message = message.replace("{d}", str(files))
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == status, err
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert message in lines[0], lines[0]
    assert "Traceback" not in err
    assert h5py.is_hdf5(files / "one_speed.h5") and h5py.is_hdf5(files / "empty.h5")


def test_debug_shows_the_traceback(files):
    """--debug lets the exception through (the traceback is the point)."""
    with pytest.raises(ValueError, match="not valid JSON"):
        main(["--debug", "flutter", "--section", str(files / "bad.json"), "--model",
              str(files / "model.json")])


def test_version_and_usage_errors(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0 and capsys.readouterr().out.startswith("windrig ")
    with pytest.raises(SystemExit) as stop:
        main(["identify"])  # a missing argument: argparse's usage error
    assert stop.value.code == 2 and "the following arguments are required" in \
        capsys.readouterr().err


def test_flutter_reads_what_identify_writes_and_says_which_density_it_assumed(tmp_path, capsys):
    """Round trip: identify --json -> flutter --model; a section without rho gets a note."""
    section = SectionModel(**SECTION)
    U_F = fl.analyze(section, flat_plate.jones_model()).speed
    releases = [Release.from_simulation(simulate_release(
        section, flat_plate.jones_model(), f * U_F, 0.004, 0.02, duration=8.0, fs=250.0,
        noise=0.01, rng=i)) for i, f in enumerate((0.5, 0.8))]
    run = tmp_path / "run.h5"
    write_release_run(run, load_rig_config(SIM_CONFIG), releases)
    assert main(["identify", str(run), "--json", str(tmp_path / "id.json")]) == 0
    identified = json.loads((tmp_path / "id.json").read_text())
    (tmp_path / "section.json").write_text(json.dumps(SECTION))
    capsys.readouterr()
    assert main(["flutter", "--section", str(tmp_path / "section.json"), "--model",
                 str(tmp_path / "id.json"), "--json", str(tmp_path / "flutter.json")]) == 0
    out = capsys.readouterr().out
    assert "section.json: no air density rho: taken as 1.225 kg/m^3" in out
    result = json.loads((tmp_path / "flutter.json").read_text())
    assert result["defaults"][0].endswith("no air density rho: taken as 1.225 kg/m^3 (ISA sea "
                                          "level)")
    # The run files' air (1.2 kg/m^3) against the note's 1.225: the speeds differ by the
    # square root of the density ratio, about 1 %; the model is the one identify wrote.
    assert result["model"] == identified["model"]
    assert result["flutter_speed"] == pytest.approx(identified["flutter_speed"], rel=0.02)
    assert result["flutter_speed_frequency_domain"] == pytest.approx(
        result["flutter_speed"], rel=0.01)
    assert set(result) >= {"flutter_speed", "flutter_frequency",
                           "flutter_speed_frequency_domain", "section", "model"}
