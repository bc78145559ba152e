"""``windrig reprocess`` on a folder of run files with 2 local Dask workers.

The folder: three run files of a simulated campaign (the flat-plate rig, one wind speed each, two
5 s releases, 2 % noise; written by the acquisition's recorder), a truncated copy of one of them
and a file that is not HDF5. The numbers must equal ``windrig identify`` on the three good
files, the two bad files must be reported with their reasons, and a second run must take the
files from the cache.
"""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from daq.cli import main
from daq.config import parse_rig_config
from daq.offline.reprocess import ReprocessSettings, expand_paths, process_file, reprocess
from daq.recording.layout import storable_metadata
from daq.recording.synthetic import write_release_run
from simulators.campaigns import FRACTIONS, simulated_campaign

from support.configs import SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime


#: A recording warning one file carries, as the run writer stores it when no pulse anchored.
UNANCHORED = ("no PLC trigger pulse reached this file (no PLC, or its pulses off or failing): "
              "the clock map of scanner has no anchor")


def write_run(path: Path, releases: list, warnings: tuple[str, ...] = ()) -> None:
    """Write releases into a run file of the flat-plate rig, with the writer's warnings."""
    config = parse_rig_config(SIM_FLAT_PLATE.read_text(),
                              "sim_flat_plate.toml")
    write_release_run(path, config, releases, metadata={"acquisition_summary": storable_metadata(
        {"warnings": list(warnings)})})


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("campaign")
    releases = simulated_campaign(None, seed=11, duration=5.0)
    per_speed = len(releases) // len(FRACTIONS)
    for i in range(len(FRACTIONS)):
        write_run(root / f"run_{i}.h5", releases[i * per_speed:(i + 1) * per_speed],
                  (UNANCHORED,) if i == 1 else ())
    good = root / "run_0.h5"
    truncated = root / "run_9_truncated.h5"
    shutil.copy(good, truncated)
    with truncated.open("r+b") as f:
        f.truncate(good.stat().st_size // 2)
    (root / "notes.h5").write_text("operator's notes, not a run file\n")
    return root


def test_reprocess_matches_identify_and_reports_the_bad_files(folder, tmp_path, capsys):
    good = sorted(str(p) for p in folder.glob("run_[0-2].h5"))
    assert main(["identify", *good, "--json", str(tmp_path / "identify.json")]) == 0
    expected = json.loads((tmp_path / "identify.json").read_text())

    out = tmp_path / "out"
    summary = reprocess([str(folder)], out, workers=2, progress=False)
    assert len(summary.files) == 5
    assert set(summary.failed) == {str(folder / "run_9_truncated.h5"), str(folder / "notes.h5")}
    assert "truncated" in summary.failed[str(folder / "run_9_truncated.h5")]
    assert "not an HDF5 file" in summary.failed[str(folder / "notes.h5")]
    assert len(summary.campaigns) == 1
    campaign = summary.campaigns[0]
    assert campaign["files"] == good and campaign["n_releases"] == 6
    # Same files, same order, same section: the same numbers as `windrig identify` (the
    # workers run the same code; 1e-9 leaves room only for float summation order).
    assert campaign["flutter_speed"] == pytest.approx(expected["flutter_speed"], rel=1e-9)
    assert campaign["flutter_std"] == pytest.approx(expected["flutter_speed_std"], rel=1e-6)
    assert np.allclose(campaign["model"]["d"], expected["model"]["d"], rtol=1e-9)
    # The structures within one SE of the best, as identify reports them, and their range.
    structures = expected["flutter_speed_structures"]
    assert list(campaign["flutter_structures"]) == list(structures)
    assert np.allclose(list(campaign["flutter_structures"].values()), list(structures.values()),
                       rtol=1e-9)
    assert campaign["flutter_speed_low"] == pytest.approx(min(structures.values()), rel=1e-9)
    assert campaign["flutter_speed_high"] == pytest.approx(max(structures.values()), rel=1e-9)
    assert (campaign["flutter_speed_low"] <= campaign["flutter_speed"]
            <= campaign["flutter_speed_high"])
    assert campaign["effect"] is None  # a clean campaign: no discrepancy
    # The file recorded with a warning says so, first, in both, and by the same words.
    assert expected["warnings"][0] == f"{good[1]}: recorded with a warning: {UNANCHORED}"
    assert campaign["warnings"] == expected["warnings"]

    with (out / "releases.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 6 and {r["campaign"] for r in rows} == {"campaign_1"}
    assert all(1.8 < float(r["f_h"]) < 2.2 and 3.0 < float(r["f_a"]) < 4.1 for r in rows)
    data = json.loads((out / "summary.json").read_text())
    assert data["campaigns"][0]["flutter_speed"] == pytest.approx(campaign["flutter_speed"])
    with (out / "campaigns.csv").open() as f:
        (row,) = list(csv.DictReader(f))
    assert float(row["flutter_speed_low"]) == pytest.approx(campaign["flutter_speed_low"])
    assert float(row["flutter_speed_high"]) == pytest.approx(campaign["flutter_speed_high"])
    report = (out / "index.html").read_text()
    assert "campaign_1_flutter_derivatives.png" in report and "notes.h5" in report
    assert "campaign_1_modes.png" in report
    for plot in ("campaign_1_flutter_derivatives.png", "campaign_1_modes.png"):
        assert (out / plot).read_bytes()[:4] == b"\x89PNG"
        assert summary.outputs[f"plot_{plot[:-4]}"] == out / plot
    # The modes plot's model curves: the campaign's flutter analysis, damping crossing zero
    # at its flutter speed.
    curves = campaign["curves"]
    assert curves["mode_names"] == ["heave", "pitch"]
    U, damping = curves["U"], curves["damping"]
    j = int(np.argmin(damping[-1]))  # the mode that goes unstable
    i = int(np.flatnonzero(damping[:, j] < 0)[0])
    crossing = np.interp(0.0, [damping[i, j], damping[i - 1, j]], [U[i], U[i - 1]])
    assert crossing == pytest.approx(campaign["flutter_speed"], rel=0.01)

    # Resumable: nothing changed, so every file comes from the cache.
    again = reprocess([str(folder / "*.h5")], out, workers=1, progress=False)
    assert sorted(again.reused) == sorted(summary.files)
    assert again.campaigns[0]["flutter_speed"] == campaign["flutter_speed"]


def test_settings_and_paths_are_checked(folder, tmp_path, capsys):
    assert ReprocessSettings.parse(["n_lags=2", "diagnose=false"]) == \
        ReprocessSettings(n_lags=2, diagnose=False)
    with pytest.raises(ValueError, match="n_lags, with_A3, diagnose, depth|name one of"):
        ReprocessSettings.parse(["lags=2"])
    with pytest.raises(ValueError, match="expected true or false"):
        ReprocessSettings.parse(["diagnose=maybe"])
    with pytest.raises(FileNotFoundError, match="nothing matches"):
        expand_paths([str(folder / "missing_*.h5")])
    assert main(["reprocess", str(folder / "none.h5"), "--out", str(tmp_path)]) == 2
    assert "no such run file" in capsys.readouterr().err


def test_a_config_names_the_campaigns_and_sets_the_settings(folder, tmp_path, capsys):
    config = tmp_path / "reprocess.toml"
    config.write_text(f"""
[reprocess]
n_lags = 2
diagnose = false

[campaigns]
low = ["{folder}/run_0.h5", "{folder}/run_1.h5"]
all_three = ["{folder}/run_[0-2].h5"]
""")
    with pytest.raises(ValueError, match="in two campaigns"):
        from daq.offline.reprocess import load_reprocess_config

        settings, campaigns = load_reprocess_config(config)
        reprocess([], tmp_path / "o", workers=1, settings=settings, campaigns=campaigns,
                  progress=False)
    config.write_text(config.read_text().replace(
        'all_three = ["' + f"{folder}/run_[0-2].h5" + '"]', ""))
    code = main(["reprocess", "--config", str(config), "--out", str(tmp_path / "out"),
                 "--workers", "1", "--no-progress", "--set", "with_A3=true"])
    printed = capsys.readouterr().out
    assert code == 0, printed
    assert "low: 2 file(s), 4 releases" in printed and "effect: None" in printed
    data = json.loads((tmp_path / "out" / "summary.json").read_text())
    (campaign,) = data["campaigns"]
    assert campaign["campaign"] == "low" and campaign["effect"] is None  # diagnose = false
    assert campaign["structure"] == "given by the caller"  # n_lags and with_A3 were set
    bad = tmp_path / "bad.toml"
    bad.write_text("[reprocess]\nn_lags = 'two'\n")
    assert main(["reprocess", "--config", str(bad), "--out", str(tmp_path / "o2")]) == 2
    assert "n_lags = 'two' has the wrong type" in capsys.readouterr().err


def test_a_file_task_returns_plain_numbers_and_the_stored_section_depth(folder):
    result = process_file(str(folder / "run_1.h5"))
    # The depth the discrepancy check turns a shedding line into a Strouhal number with, as
    # `windrig diagnose` takes it: the run's stored [section] depth (0.01 m in the rig config).
    assert result["depth"] == 0.01
    assert result["rig"] == "Simulated flat-plate rig" and len(result["releases"]) == 2
    for release in result["releases"]:
        assert isinstance(release["U"], float) and isinstance(release["h"], np.ndarray)
    bad = process_file(str(folder / "notes.h5"))
    assert set(bad) == {"path", "error"}
