"""Export, import back, identify: the same flutter speed through every lossless format.

A campaign of three MATLAB records (:mod:`support.lab_data`, the flat plate released twice at
each of three speeds) is imported once; each of its run files is exported to CSV, MATLAB v5 and
TDMS (``windrig export``) and imported back (``windrig import``, one map per format naming the
export's own columns), and the three campaigns are identified. The exports keep every float64
exactly (CSV by Python's shortest round-trip text), and the maps give each decay's release and
end (``[releases] times`` and ``ends``), so the identified flutter speeds must agree to 1e-9
relative: the same samples, cut at the same rows, fitted by the same code.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import pytest

from daq.cli import main

from support.lab_data import MAP_V5, SPEEDS, write_mat_v5

#: Each format's map of the export's own layout; RELEASES is filled from the run file.
MAPS = {
    "csv": """\
config = "sim_flat_plate"
[time]
column = "time [s]"
unit = "s"
[channels]
h = { column = "h [m]", unit = "m", sign = "down" }
alpha = { column = "alpha [rad]", unit = "rad", sign = "nose_up" }
lift = { column = "lift [N/m]", unit = "N/m", sign = "down" }
moment = { column = "moment [N m/m]", unit = "N m/m", sign = "nose_up" }
[wind]
U = { column = "U [m/s]", unit = "m/s" }
rho = { column = "rho [kg/m^3]", unit = "kg/m^3" }
[releases]
RELEASES
""",
    "mat": """\
config = "sim_flat_plate"
[time]
column = "sync.time"
unit = "s"
[channels]
h = { column = "sync.h", unit = "m", sign = "down" }
alpha = { column = "sync.alpha", unit = "rad", sign = "nose_up" }
lift = { column = "sync.lift", unit = "N/m", sign = "down" }
moment = { column = "sync.moment", unit = "N m/m", sign = "nose_up" }
[wind]
U = { column = "sync.U", unit = "m/s" }
rho = { column = "sync.rho", unit = "kg/m^3" }
[releases]
RELEASES
""",
    "tdms": """\
config = "sim_flat_plate"
groups = ["sync"]
[time]
column = "time"
unit = "s"
[channels]
h = { column = "h", unit = "m", sign = "down" }
alpha = { column = "alpha", unit = "rad", sign = "nose_up" }
lift = { column = "lift", unit = "N/m", sign = "down" }
moment = { column = "moment", unit = "N m/m", sign = "nose_up" }
[wind]
U = { column = "U", unit = "m/s" }
rho = { column = "rho", unit = "kg/m^3" }
[releases]
RELEASES
""",
}


def _identify(files: list[Path], out: Path) -> float:
    assert main(["identify", *map(str, files), "--json", str(out)]) == 0
    speed = json.loads(out.read_text())["flutter_speed"]
    assert speed is not None
    return float(speed)


def _releases(run: Path) -> str:
    """Return the run file's release instants and decay ends as the map's [releases] (s)."""
    with h5py.File(run, "r") as f:
        rows = f["entry/releases"][:]
        time = f["entry/sync/time"][:]
    step = float(time[1] - time[0])
    times = ", ".join(repr(float(time[r["start_index"]])) for r in rows)
    ends = ", ".join(repr(float(time[r["stop_index"]]) if r["stop_index"] < time.size
                          else float(time[-1]) + step) for r in rows)
    return f"times = [{times}]\nends = [{ends}]\nhold = 1.0"


@pytest.mark.parametrize("fmt", ["csv", "mat", "tdms"])
def test_export_then_import_identifies_to_the_same_flutter_speed(tmp_path, fmt):
    sources = []
    for k in range(len(SPEEDS)):
        sources.append(tmp_path / f"lab_{k}.mat")
        write_mat_v5(sources[-1], k)
    (tmp_path / "map.toml").write_text(MAP_V5)
    assert main(["import", *map(str, sources), "--map", str(tmp_path / "map.toml"), "--out",
                 str(tmp_path / "first")]) == 0
    runs = sorted((tmp_path / "first").glob("*.h5"))
    assert len(runs) == len(SPEEDS)
    original = _identify(runs, tmp_path / "first.json")

    again = []
    for run in runs:
        exported = tmp_path / "exports" / (run.stem if fmt == "csv" else f"{run.stem}.{fmt}")
        exported.parent.mkdir(exist_ok=True)
        assert main(["export", str(run), "--to", fmt, "--out", str(exported)]) == 0
        source = exported / "sync.csv" if fmt == "csv" else exported
        if fmt == "csv":  # one folder per run: give each sync table the run's name
            source = source.rename(tmp_path / "exports" / f"{run.stem}.csv")
        the_map = tmp_path / f"{run.stem}_{fmt}.toml"
        the_map.write_text(MAPS[fmt].replace("RELEASES", _releases(run)))
        out = tmp_path / "again" / run.stem
        assert main(["import", str(source), "--map", str(the_map), "--out", str(out)]) == 0
        again += sorted(out.glob("*.h5"))
    assert len(again) == len(runs)
    assert _identify(again, tmp_path / "again.json") == pytest.approx(original, rel=1e-9)
