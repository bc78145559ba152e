"""``windrig import``'s answers to bad input, and its warnings.

A mistake is one ``error:`` line naming the file, channel or key (exit 2), and nothing is
written; a doubtful input is a warning that names the likely mistake.

The sources are small CSV and TDMS files made here (a held model released into a decay of the
flat plate's record, :mod:`support.lab_data`), the map the CSV guide's.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

from daq.cli import main
from daq.errors import UsageError
from daq.exchange.import_map import parse_number

from support.lab_data import FS, MAGNET_ON, MAP, lab_record


def write_csv(path, *, rows: slice = slice(0, 4250), U_ramp: float = 0.0,
              t_jitter: bool = False) -> None:
    """Write the first release of the 5.9 m/s record as an SI CSV (optionally a ramping U)."""
    r = lab_record(0)
    t = r.t[rows].copy()
    if t_jitter:
        t[100] += 0.5 / FS  # a logger that missed its clock: half a step late
    U = r.U * (1.0 + U_ramp * (t - t[0]) / (t[-1] - t[0]))
    cols = {"t": t, "h": r.h[rows], "alpha": r.alpha[rows], "lift": r.lift[rows],
            "moment": r.moment[rows], "U": U, "magnet": r.magnet[rows],
            "line": MAGNET_ON - r.magnet[rows]}
    path.write_text(",".join(cols) + "\n" + "\n".join(
        ",".join(repr(float(x)) for x in row) for row in np.column_stack(list(cols.values()))))


def run_import(tmp_path, map_text: str, *sources, capsys):
    """Run the command; return its exit code and the lines of stderr."""
    (tmp_path / "map.toml").write_text(map_text)
    code = main(["import", *map(str, sources), "--map", str(tmp_path / "map.toml"),
                 "--out", str(tmp_path / "runs"), "--json", str(tmp_path / "import.json")])
    return code, capsys.readouterr().err.strip().splitlines()


@pytest.mark.parametrize(("edit", "names"), [
    (('h = { column = "h", unit = "m", sign = "down" }', 'h = { column = "h", unit = "m" }'),
     ["[channels] h", "missing", "'sign'"]),
    (('unit = "m", sign', 'unit = "inch", sign'), ["[channels] h", "'inch'", "'mm'"]),
    (('column = "h",', 'column = "heave",'), ["data.csv", "'heave'", "[channels] h", "alpha"]),
    (('unit = "N/m", sign = "down"', 'unit = "N", sign = "down"'),
     ["[channels] lift", "total", "span"]),
    (('sign = "nose_up" }\nlift', 'sign = "up" }\nlift'),
     ["[channels] alpha", "sign = 'up'", "nose_down"]),
    (('h = { column = "h", unit = "m"', 'h = { column = "h", unit = "V"'),
     ["[channels] h", "volts", "scale"]),
    (("times = [1.0]", "times = [1.0, 30.0]"), ["data.csv", "[30.0]", "outside the record"]),
    (("hold = 1.0", "hold = 1.5"), ["data.csv", "hold = 1.5", "before it"]),
    (("rho = 1.225", 'rho = "1.000,5"'), ["[wind] rho", "'1.000,5'", "decimal comma"]),
    (('[releases]\ntimes = [1.0]', '[releases]\ntimes = [1.0]\ndetect = true'),
     ["[releases]", "exactly one of"]),
    (('config = "sim_flat_plate"', 'config = "no_such_rig"'), ["no_such_rig"]),
    (("[time]", "[tyme]"), ["unknown key(s) ['tyme']"]),
    (('config = "sim_flat_plate"', 'config = "sim_flat_plate"\ngroups = ["Test_*"]'),
     ["data.csv", "TDMS groups", "csv"]),
    (("[wind]", "wind = ["), ["not valid TOML"]),
    (("times = [1.0]", "times = [1.0]\nends = [2.0, 3.0]"),
     ["[releases] ends", "list of 1 seconds"]),
    (("times = [1.0]", "times = [1.0]\nends = [0.5]"), ["[releases] ends[0] = 0.5", "not after"]),
])
def test_a_mistake_in_the_map_is_one_error_line_naming_it(tmp_path, capsys, edit, names):
    write_csv(tmp_path / "data.csv")
    assert edit[0] in MAP
    code, err = run_import(tmp_path, MAP.replace(*edit), tmp_path / "data.csv", capsys=capsys)
    assert code == 2, err
    assert len(err) == 1 and err[0].startswith("error: "), err
    for name in names:
        assert name in err[0], (name, err[0])
    assert not (tmp_path / "runs").exists()  # nothing written


def test_a_time_column_that_is_not_uniform_is_refused_naming_its_row(tmp_path, capsys):
    write_csv(tmp_path / "data.csv", t_jitter=True)
    code, err = run_import(tmp_path, MAP, tmp_path / "data.csv", capsys=capsys)
    assert code == 2 and len(err) == 1
    assert "data.csv: time column 't' is not uniformly sampled" in err[0]
    assert "row 100" in err[0] or "row 101" in err[0]


def test_an_existing_run_file_is_never_overwritten(tmp_path, capsys):
    write_csv(tmp_path / "data.csv")
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / "data.h5").write_bytes(b"a run file from before")
    code, err = run_import(tmp_path, MAP, tmp_path / "data.csv", capsys=capsys)
    assert code == 2 and len(err) == 1 and "data.h5: exists" in err[0]
    assert (tmp_path / "runs" / "data.h5").read_bytes() == b"a run file from before"


def test_an_unknown_extension_and_a_missing_source_are_named(tmp_path, capsys):
    (tmp_path / "data.xlsx").write_bytes(b"PK")
    code, err = run_import(tmp_path, MAP, tmp_path / "data.xlsx", capsys=capsys)
    assert code == 2 and len(err) == 1 and "data.xlsx" in err[0] and "'.xlsx'" in err[0]
    code, err = run_import(tmp_path, MAP, tmp_path / "gone.csv", capsys=capsys)
    assert code == 2 and len(err) == 1 and "gone.csv: no such source file" in err[0]


def test_a_wind_speed_that_drifts_over_a_decay_is_a_warning(tmp_path, capsys):
    write_csv(tmp_path / "data.csv", U_ramp=0.2)
    code, err = run_import(tmp_path, MAP, tmp_path / "data.csv", capsys=capsys)
    assert code == 0, err
    warnings = json.loads((tmp_path / "import.json").read_text())["warnings"]
    # U ramps by 20 % over the 8.5 s record from 5.88 m/s: the means of the 7.5 s decay's
    # halves 6.28 and 6.80 m/s, 8 % apart.
    assert len(warnings) == 1 and "the wind speed drifts from 6.28 to 6.8 m/s" in warnings[0]
    assert "more than 5%" in warnings[0]


@pytest.mark.parametrize("trigger", ['column = "magnet"', 'column = "line"\nedge = "rising"',
                                     'column = "magnet"\nthreshold = "4,5"'])
def test_a_trigger_channel_marks_the_release_on_its_edge(tmp_path, capsys, trigger):
    write_csv(tmp_path / "data.csv")
    code, err = run_import(tmp_path, MAP.replace("times = [1.0]", trigger),
                           tmp_path / "data.csv", capsys=capsys)
    assert code == 0, err
    found = json.loads((tmp_path / "import.json").read_text())["files"][0]["release_times_s"]
    # The magnet drops from 5 V at its last held sample to 0 V at the first free one (1.0 s):
    # the edge, interpolated, lies between them, where the threshold puts it (2.5 V by
    # default: halfway; 4.5 V: a tenth of the step after the held sample).
    fraction = 0.1 if "4,5" in trigger else 0.5
    assert found == pytest.approx([1.0 - (1.0 - fraction) / FS], abs=1e-9)


def test_a_trigger_that_never_crosses_its_threshold_is_named(tmp_path, capsys):
    write_csv(tmp_path / "data.csv")
    code, err = run_import(tmp_path, MAP.replace("times = [1.0]",
                                                 'column = "magnet"\nthreshold = 7.5'),
                           tmp_path / "data.csv", capsys=capsys)
    assert code == 2 and len(err) == 1
    assert "data.csv: trigger channel 'magnet' never crosses 7.5 (falling)" in err[0]


def _tdms(path, props: dict) -> None:
    r = lab_record(0)
    wf = {"wf_increment": 1.0 / FS}
    with TdmsWriter(path) as writer:
        writer.write_segment([
            RootObject(), GroupObject("Test_1", properties=props),
            *(ChannelObject("Test_1", name, getattr(r, name)[:4250], properties=wf)
              for name in ("h", "alpha", "lift", "moment"))])


TDMS_MAP = (MAP.replace('[time]\ncolumn = "t"\nunit = "s"', "[time]\nwaveform = true")
            .replace('U = { column = "U", unit = "m/s" }', 'U = { property = "WindSpeed" }'))


def test_a_tdms_property_missing_or_not_a_number_is_named(tmp_path, capsys):
    _tdms(tmp_path / "a.tdms", {"Wind": "5,9"})
    code, err = run_import(tmp_path, TDMS_MAP, tmp_path / "a.tdms", capsys=capsys)
    assert code == 2 and len(err) == 1
    assert "a.tdms:Test_1: no property 'WindSpeed'" in err[0] and "Wind" in err[0]
    _tdms(tmp_path / "b.tdms", {"WindSpeed": "fast"})
    code, err = run_import(tmp_path, TDMS_MAP, tmp_path / "b.tdms", capsys=capsys)
    assert code == 2 and len(err) == 1
    assert "b.tdms:Test_1: property 'WindSpeed'" in err[0] and "'fast'" in err[0]
    _tdms(tmp_path / "c.tdms", {"WindSpeed": "5,88"})
    code, err = run_import(tmp_path, TDMS_MAP, tmp_path / "c.tdms", capsys=capsys)
    assert code == 0, err
    assert json.loads((tmp_path / "import.json").read_text())["files"][0]["U_m_per_s"] == [5.88]


@pytest.mark.parametrize(("text", "value"), [
    ("0,9", 0.9), ("0.9", 0.9), ("-1,25e-3", -1.25e-3), (" 12 ", 12.0), (",5", 0.5), (3, 3.0)])
def test_numbers_as_labview_writes_them(text, value):
    assert parse_number(text, "here") == value


@pytest.mark.parametrize("text", ["1.000,5", "1,000.5", "", "nan", "inf", "5 m/s", True])
def test_numbers_that_would_be_guessed_are_refused(text):
    with pytest.raises(UsageError, match="here"):
        parse_number(text, "here")
