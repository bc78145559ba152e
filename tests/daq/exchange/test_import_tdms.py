"""``windrig import`` of a LabVIEW-like TDMS file (npTDMS), identified to the simulated truth.

One file, one group per test (a wind speed each, :mod:`support.lab_data`), written with
npTDMS as LabVIEW lays it out: waveform channels (``wf_increment``), the heave laser in volts
with a DAQmx linear scale to mm (``NI_Scale[0]_...``, applied by npTDMS on reading), the pitch
in raw volts with its sensitivity and offset as string properties with decimal commas, lift
and moment as totals over the span given as a file property (``"0,9"``), heave and lift z up,
the wind speed and air density as group properties (strings, decimal commas), the magnet's
voltage as the release trigger, and a group of metadata without channels.
"""

from __future__ import annotations

import hashlib
import json

import h5py
import numpy as np
import pytest
from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

from daq.cli import main

from support.lab_data import FS, SPEEDS, assert_identifies_to_truth, imported_deviation, lab_record

SPAN = 0.9  # m
LASER_MM_PER_V = 5.0  # the heave laser's DAQmx scale
PITCH_DEG_PER_V, PITCH_OFFSET_DEG = 0.5, -0.25  # the pitch sensor's, as string properties

MAP = """\
config = "sim_flat_plate"
span = { property = "Model_Span_m" }
groups = ["Test_*"]
[time]
waveform = true
[channels]
h = { column = "Laser_H", unit = "mm", sign = "up" }
lift = { column = "Lift", unit = "N", sign = "up" }
moment = { column = "Moment", unit = "N m", sign = "nose_up" }
[channels.alpha]
column = "Pitch"
unit = "V"
scale = { property = "Sensitivity" }
offset = { property = "Offset" }
scaled_unit = "deg"
sign = "nose_up"
[wind]
U = { property = "WindSpeed" }
rho = { property = "AirDensity" }
[releases]
column = "Magnet"
hold = 1.0
"""


def comma(x: float) -> str:
    """Write a number as LabVIEW does on a PC with a German locale."""
    return repr(float(x)).replace(".", ",")


def write_labview_tdms(path) -> None:
    """Write every wind speed's record as one group of a LabVIEW-like TDMS file."""
    waveform = {"wf_increment": 1.0 / FS, "wf_start_offset": 0.0, "wf_samples": 1}
    objects: list = [RootObject(properties={"Operator": "lab", "Model_Span_m": comma(SPAN)}),
                     GroupObject("Setup", properties={"Tunnel": "B", "Section": "flat plate"})]
    for k in range(len(SPEEDS)):
        r = lab_record(k)
        group = f"Test_{k + 1}"
        objects.append(GroupObject(group, properties={"WindSpeed": comma(r.U),
                                                      "AirDensity": comma(r.rho)}))
        laser = {"NI_Number_Of_Scales": 1, "NI_Scale[0]_Scale_Type": "Linear",
                 "NI_Scale[0]_Linear_Slope": LASER_MM_PER_V,
                 "NI_Scale[0]_Linear_Y_Intercept": 0.0, "unit_string": "mm"}
        pitch_v = (np.degrees(r.alpha) - PITCH_OFFSET_DEG) / PITCH_DEG_PER_V
        objects += [
            ChannelObject(group, "Laser_H", -r.h * 1e3 / LASER_MM_PER_V,
                          properties={**waveform, **laser}),
            ChannelObject(group, "Pitch", pitch_v, properties={
                **waveform, "unit_string": "V", "Sensitivity": comma(PITCH_DEG_PER_V),
                "Offset": comma(PITCH_OFFSET_DEG)}),
            ChannelObject(group, "Lift", -r.lift * SPAN,
                          properties={**waveform, "unit_string": "N"}),
            ChannelObject(group, "Moment", r.moment * SPAN,
                          properties={**waveform, "unit_string": "N m"}),
            ChannelObject(group, "Magnet", r.magnet, properties={**waveform, "unit_string": "V"}),
        ]
    with TdmsWriter(path) as writer:
        writer.write_segment(objects)


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    where = tmp_path_factory.mktemp("tdms")
    (where / "map.toml").write_text(MAP)
    source = where / "campaign.tdms"
    write_labview_tdms(source)
    assert main(["import", str(source), "--map", str(where / "map.toml"),
                 "--out", str(where / "runs"), "--json", str(where / "import.json")]) == 0
    return where, source


def test_one_run_file_per_group_in_si_and_windrig_signs(imported):
    where, source = imported
    names = sorted(p.name for p in (where / "runs").glob("*.h5"))
    assert names == ["campaign_Test_1.h5", "campaign_Test_2.h5", "campaign_Test_3.h5"]
    r = lab_record(1)
    with h5py.File(where / "runs" / "campaign_Test_2.h5", "r") as f:
        sync = f["entry/sync"]
        meta = f["entry/metadata/import"]
        assert meta["test"][()].decode() == "Test_2"
        assert meta["format"][()].decode() == "tdms"
        assert meta["sha256"][()].decode() == hashlib.sha256(source.read_bytes()).hexdigest()
        U, rho = sync["U"][:], sync["rho"][:]
    # The magnet's edge is interpolated halfway between its last held sample and the first
    # free one; the row starts at the first free sample, and imported_deviation matches it
    # to the record's instant: volts and scales in float64 and back, 1e-12 of each peak.
    assert max(imported_deviation(where / "runs" / "campaign_Test_2.h5", r).values()) < 1e-12
    assert U == pytest.approx(SPEEDS[1], rel=1e-12)
    assert rho == pytest.approx(r.rho, rel=1e-12)
    report = json.loads((where / "import.json").read_text())
    assert report["warnings"] == []


def test_the_imported_tdms_identifies_to_the_truth(imported):
    where, _ = imported
    assert_identifies_to_truth(where / "runs", "tdms")


def test_info_says_where_the_imported_file_came_from(imported, capsys):
    where, source = imported
    assert main(["info", str(where / "runs" / "campaign_Test_1.h5")]) == 0
    lines = capsys.readouterr().out.splitlines()
    sha = hashlib.sha256(source.read_bytes()).hexdigest()
    assert (f"imported   from campaign.tdms group Test_1 (SHA-256 {sha[:16]}...) by the map "
            "map.toml") in lines
    assert "releases   2" in lines
    assert main(["info", str(where / "runs" / "campaign_Test_1.h5"), "--json"]) == 0
    imported_from = json.loads(capsys.readouterr().out)["imported"]
    assert imported_from["sha256"] == sha and imported_from["map"] == MAP
