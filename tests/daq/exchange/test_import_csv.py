"""``windrig import`` of CSV files in a lab's units, identified to the simulated truth.

Each wind speed's record (:mod:`support.lab_data`, the flat plate at 0.5, 0.65 and 0.8 of its
flutter speed) is written as a lab writes it: time in ms, heave in mm and pitch in degrees,
lift and moment as totals over a 0.9 m span, heave and lift positive upward (z up), the wind
in km/h. The map converts all of it; the run files are read back by h5py and identified by
``windrig identify``.
"""

from __future__ import annotations

import hashlib
import json

import h5py
import numpy as np
import pytest

from daq.cli import main

from support.lab_data import SPEEDS, assert_identifies_to_truth, imported_deviation, lab_record

SPAN = 0.9  # m

MAP = """\
config = "sim_flat_plate"
span = 0.9
[time]
column = "time_ms"
unit = "ms"
[channels]
h = { column = "heave_mm", unit = "mm", sign = "up" }
alpha = { column = "pitch_deg", unit = "deg", sign = "nose_up" }
lift = { column = "lift_N", unit = "N", sign = "up" }
moment = { column = "moment_Nm", unit = "N m", sign = "nose_up" }
[wind]
U = { column = "U_kmh", unit = "km/h" }
rho = 1.225
[releases]
times = [1.0, 9.5]
hold = 1.0
"""


def write_lab_csv(path, k: int) -> None:
    """Write a lab's CSV of record k: other units, totals over the span, z up."""
    r = lab_record(k)
    columns = {"time_ms": r.t * 1e3, "heave_mm": -r.h * 1e3, "pitch_deg": np.degrees(r.alpha),
               "lift_N": -r.lift * SPAN, "moment_Nm": r.moment * SPAN,
               "U_kmh": np.full(r.t.size, r.U * 3.6)}
    rows = np.column_stack(list(columns.values()))
    header = "# wind tunnel B, flat plate section, exported by the lab's logger\n"
    path.write_text(header + ",".join(columns) + "\n" +
                    "\n".join(",".join(f"{x:.9g}" for x in row) for row in rows) + "\n")


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    where = tmp_path_factory.mktemp("csv")
    (where / "map.toml").write_text(MAP)
    sources = []
    for k in range(len(SPEEDS)):
        sources.append(where / f"lab_{k}.csv")
        write_lab_csv(sources[-1], k)
    assert main(["import", *map(str, sources), "--map", str(where / "map.toml"),
                 "--out", str(where / "runs"), "--json", str(where / "import.json")]) == 0
    return where, sources


def test_the_csv_arrives_in_si_and_windrig_signs(imported):
    where, sources = imported
    r = lab_record(0)
    with h5py.File(where / "runs" / "lab_0.h5", "r") as f:
        sync = f["entry/sync"]
        rows = f["entry/releases"][:]
        provenance = f["entry/metadata/import"]
        assert provenance["source"][()].decode() == "lab_0.csv"
        assert provenance["sha256"][()].decode() == hashlib.sha256(
            sources[0].read_bytes()).hexdigest()
        assert provenance["map"][()].decode() == MAP
        # Two releases, each starting at its instant (a sample: the record's own) with 1 s
        # of hold before it; the first decay ends before the catch (the model pulled back to
        # its hold at 8.5 s, found still from 8.55 s, less the 0.07 s guard: 8.48 s), so the
        # second release lies at 8.48 + 1 s in the file.
        assert rows["release_time"] == pytest.approx([1.0, 9.48], abs=1e-9)
        U = sync["U"][:]
    # The CSV holds 9 significant digits: relative 1e-8 of each channel's peak is the rounding.
    assert max(imported_deviation(where / "runs" / "lab_0.h5", r).values()) < 1e-8
    assert U == pytest.approx(SPEEDS[0], rel=1e-8)
    report = json.loads((where / "import.json").read_text())
    assert report["warnings"] == []
    assert [f["U_m_per_s"] for f in report["files"]] == [
        pytest.approx([u, u], rel=1e-8) for u in SPEEDS]


def test_the_imported_csv_identifies_to_the_truth(imported):
    where, _ = imported
    assert_identifies_to_truth(where / "runs", "csv")
