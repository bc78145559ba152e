"""A campaign directory's file names, and grouping an earlier session's files by speed."""

from __future__ import annotations

from pathlib import Path

from daq.campaign.files import interrupted_name, read_back, run_file_name
from daq.config import parse_rig_config
from daq.recording.layout import storable_metadata
from daq.recording.synthetic import write_release_run
from ident import Release
from ident.model import flat_plate
from simulators import simulate_release

from support.configs import SIM_FLAT_PLATE
from support.sections import FLAT_PLATE


def test_names_of_speeds_releases_and_interrupted_files():
    assert run_file_name(1, 5.0) == "speed01_U05.00.h5"
    assert run_file_name(12, 11.849, 3) == "speed12_U11.85_r03.h5"
    assert interrupted_name(Path("d/speed01_U05.00_r02.h5")) == \
        Path("d/speed01_U05.00_r02.interrupted.h5")


def test_read_back_groups_by_speed_skips_interrupted_and_reports_unreadable(tmp_path):
    for name in ("speed02_U07.00_r02.h5", "speed01_U05.00.h5", "speed02_U07.00_r01.h5",
                 "speed03_U08.50_r01.interrupted.h5", "notes.txt", "speed1_U5.h5"):
        (tmp_path / name).write_bytes(b"not hdf5")
    said: list[str] = []
    speeds = read_back(tmp_path, said.append)

    assert [(s.index, s.U) for s in speeds] == [(1, 5.0), (2, 7.0)]
    assert [p.name for p in speeds[1].paths] == ["speed02_U07.00_r01.h5",
                                                "speed02_U07.00_r02.h5"]
    # None of them is a run file: each is named once, kept out of the fit, none invented.
    assert len(said) == 3 and all("is not usable" in line for line in said)
    assert all(s.runs == [] and s.releases == 0 for s in speeds)


def test_an_earlier_files_recording_warning_is_read_back_with_its_name(tmp_path):
    config = parse_rig_config(SIM_FLAT_PLATE.read_text(), "sim_flat_plate.toml")
    release = Release.from_simulation(simulate_release(
        FLAT_PLATE, flat_plate.jones_model(), 5.0, 0.004, 0.02, duration=4.0, fs=250.0))
    warning = "no PLC trigger pulse reached this file: the clock map of scanner has no anchor"
    for name, warnings in (("speed01_U05.00.h5", [warning]), ("speed02_U07.00.h5", [])):
        write_release_run(tmp_path / name, config, [release], metadata={
            "acquisition_summary": storable_metadata({"warnings": warnings})})
    speeds = read_back(tmp_path, [].append)
    assert [s.releases for s in speeds] == [1, 1]
    assert speeds[0].recording_warnings == [f"speed01_U05.00.h5: {warning}"]
    assert speeds[1].recording_warnings == []
