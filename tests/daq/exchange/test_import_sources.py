"""``windrig import`` of the files other labs' tools really write: their quirks and damage.

Each test writes a real file as a spreadsheet, LabVIEW or MATLAB leaves it (Excel's rows of
empty cells, a header that names a column twice, a TDMS file cut short by a crash, a
pre-trigger's ``wf_start_offset``, a v7.3 file copied half-way) and checks that the import
either reads every sample where it belongs, says what it lost in a warning, or answers with
one ``error:`` line naming the file and the column or key (exit 2), nothing written.
"""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

from daq.cli import main

from support.lab_data import FS, MAP, lab_record

N = 4250  # the first release of the 5.88 m/s record: 1 s held, 7.5 s of decay
CHANNELS = ("h", "alpha", "lift", "moment")

RATE_MAP = MAP.replace('[time]\ncolumn = "t"\nunit = "s"', "[time]\nrate = 500.0")
TDMS_MAP = (MAP.replace('[time]\ncolumn = "t"\nunit = "s"', "[time]\nwaveform = true")
            .replace('U = { column = "U", unit = "m/s" }', "U = 5.88"))


def columns() -> dict[str, np.ndarray]:
    r = lab_record(0)
    return {"t": r.t[:N], **{c: getattr(r, c)[:N] for c in CHANNELS},
            "U": np.full(N, r.U), "magnet": r.magnet[:N]}


def csv_text(cols: dict[str, np.ndarray], header: str | None = None) -> str:
    rows = np.column_stack(list(cols.values()))
    return ((header or ",".join(cols)) + "\n"
            + "\n".join(",".join(repr(float(x)) for x in row) for row in rows) + "\n")


def run_import(tmp_path, map_text: str, *sources, capsys):
    """Run the command; return its exit code, the lines of stdout and those of stderr."""
    (tmp_path / "map.toml").write_text(map_text)
    code = main(["import", *map(str, sources), "--map", str(tmp_path / "map.toml"),
                 "--out", str(tmp_path / "runs"), "--json", str(tmp_path / "import.json")])
    out = capsys.readouterr()
    return code, out.out.strip().splitlines(), out.err.strip().splitlines()


def one_error(code: int, err: list[str], *names: str) -> None:
    assert code == 2 and len(err) == 1 and err[0].startswith("error: "), err
    for name in names:
        assert name in err[0], (name, err[0])


def sync(path) -> dict[str, np.ndarray]:
    with h5py.File(path, "r") as f:
        return {c: f["entry/sync"][c][:] for c in ("time", *CHANNELS)}


# -- CSV -----------------------------------------------------------------------------------------

def test_a_header_naming_a_mapped_column_twice_is_refused_not_read_as_the_last(tmp_path,
                                                                              capsys):
    # Two lasers both logged as "h" (the second a check laser reading zero here): read as a
    # mapping, the last "h" silently became the heave.
    cols = columns()
    text = csv_text({**cols, "h2": np.zeros(N)}, header=",".join(cols) + ",h")
    (tmp_path / "lab.csv").write_text(text)
    code, _, err = run_import(tmp_path, MAP, tmp_path / "lab.csv", capsys=capsys)
    one_error(code, err, "lab.csv", "more than one column 'h'", "[channels] h")
    assert not (tmp_path / "runs").exists()


def test_a_column_named_twice_that_the_map_does_not_read_is_no_obstacle(tmp_path, capsys):
    cols = columns()
    text = csv_text({**cols, "spare": np.zeros(N)}, header=",".join(cols) + ",magnet")
    (tmp_path / "lab.csv").write_text(text)
    code, _, err = run_import(tmp_path, MAP, tmp_path / "lab.csv", capsys=capsys)
    assert code == 0, err
    assert np.array_equal(sync(tmp_path / "runs" / "lab.h5")["h"], cols["h"][:N])


@pytest.mark.parametrize("map_text", [MAP, RATE_MAP], ids=["time column", "rate"])
def test_a_spreadsheets_trailing_rows_of_empty_cells_are_no_samples(tmp_path, capsys,
                                                                    map_text):
    # Excel pads a saved sheet with rows of separators. Before: with a time column, "does not
    # increase"; with a rate, one NaN sample invented after the record's end.
    cols = columns()
    (tmp_path / "lab.csv").write_text(csv_text(cols) + ",,,,,,\n,,,,,,\n\n")
    code, _, err = run_import(tmp_path, map_text, tmp_path / "lab.csv", capsys=capsys)
    assert code == 0, err
    got = sync(tmp_path / "runs" / "lab.h5")
    assert got["h"].size == N and np.isfinite(got["h"]).all()
    assert np.array_equal(got["h"], cols["h"])


@pytest.mark.parametrize(("column", "factor", "named"), [
    ("h", 1e3, "h looks like millimetres"),
    ("alpha", 180.0 / np.pi, "alpha looks like degrees"),
    ("t", 1e3, "t looks like milliseconds"),
], ids=["heave in mm", "pitch in degrees", "time in ms"])
def test_a_unit_the_map_gets_wrong_is_refused_at_the_import(tmp_path, capsys, column, factor,
                                                            named):
    # The file in mm, degrees or ms, the map saying m, rad or s: converted without a word
    # before, a run file of impossible motion that only `windrig identify` refused.
    cols = columns()
    cols[column] = cols[column] * factor
    (tmp_path / "lab.csv").write_text(csv_text(cols))
    map_text = MAP.replace("times = [1.0]", "times = [1000.0]") if column == "t" else MAP
    code, _, err = run_import(tmp_path, map_text, tmp_path / "lab.csv", capsys=capsys)
    one_error(code, err, "lab.csv", named, "map.toml")
    assert not (tmp_path / "runs").exists()


def test_an_empty_time_cell_is_named_by_its_row(tmp_path, capsys):
    cols = columns()
    cols["t"] = cols["t"].copy()
    cols["t"][2000] = np.nan
    (tmp_path / "lab.csv").write_text(csv_text(cols).replace("nan,", ",", 1))
    code, _, err = run_import(tmp_path, MAP, tmp_path / "lab.csv", capsys=capsys)
    # Before: "time column 't' does not increase", which sends the lab to its logger's clock.
    one_error(code, err, "lab.csv", "time column 't' has no time in 1 row(s)", "row 2001",
              "empty cell")


def test_a_bad_row_is_named_by_its_line_in_the_file(tmp_path, capsys):
    # Comment lines count as lines: an editor's "go to line" must land on the bad row.
    text = "# tunnel B\n# flat plate\n" + csv_text(columns())
    lines = text.splitlines()
    lines[1000] += ",0.5"  # the file's line 1001 has a cell too many
    (tmp_path / "lab.csv").write_text("\n".join(lines) + "\n")
    code, _, err = run_import(tmp_path, MAP, tmp_path / "lab.csv", capsys=capsys)
    one_error(code, err, "lab.csv: line 1001 has 8 cells, the header 7")


def test_a_units_row_under_the_header_is_named_as_such(tmp_path, capsys):
    text = csv_text(columns()).replace("\n", "\ns,m,rad,N/m,N m/m,m/s,V\n", 1)
    (tmp_path / "lab.csv").write_text(text)
    code, _, err = run_import(tmp_path, MAP, tmp_path / "lab.csv", capsys=capsys)
    one_error(code, err, "lab.csv: line 2 is not all numbers", "a row of units")


# -- TDMS ----------------------------------------------------------------------------------------

def write_tdms(path, *, per_write: int = N, offset: float = 0.0, increments=None,
               notes: bool = False) -> None:
    """Write the release as LabVIEW logs it: one segment per write of ``per_write`` samples."""
    cols = columns()
    names = (*CHANNELS, "magnet")
    props = {c: {"wf_increment": (increments or {}).get(c, 1.0 / FS), "wf_start_offset": offset}
             for c in names}
    with TdmsWriter(path) as writer:
        head = [RootObject(), GroupObject("Test_1", properties={})]
        if notes:  # a group of text only: the operator's notes, no test
            head += [GroupObject("Notes", properties={}),
                     ChannelObject("Notes", "text", np.array(["calm day", "door shut"]))]
        writer.write_segment(head)
        for i in range(0, N, per_write):
            writer.write_segment([ChannelObject("Test_1", c, cols[c][i:i + per_write],
                                                properties=props[c]) for c in names])


def test_a_tdms_file_cut_short_is_read_to_its_last_whole_sample_with_a_warning(tmp_path,
                                                                               capsys):
    # A logger writing every 0.5 s, stopped mid-write: npTDMS reads the last write's channels
    # to different samples. Before: "the mapped channels differ in length", or, when they did
    # not, the record lost its end without a word.
    write_tdms(tmp_path / "full.tdms", per_write=250)
    data = (tmp_path / "full.tdms").read_bytes()
    (tmp_path / "cut.tdms").write_bytes(data[:int(0.97 * len(data))])
    code, _, err = run_import(tmp_path, TDMS_MAP.replace("times = [1.0]", 'column = "magnet"'),
                              tmp_path / "cut.tdms", capsys=capsys)
    assert code == 0, err
    warnings = json.loads((tmp_path / "import.json").read_text())["warnings"]
    assert len(warnings) == 1, warnings
    assert "cut.tdms:Test_1: the file ends inside its last write" in warnings[0]
    # 0.97 of the file: the 17th and last write (samples 4000-4249) is cut inside its data.
    assert "up to 250 sample(s) per channel of that write are missing" in warnings[0]
    assert "cut to the 4000 samples they all hold" in warnings[0]
    got = sync(tmp_path / "runs" / "cut_Test_1.h5")
    n = got["h"].size
    assert 3500 < n <= 4000  # the decay, up to the record's end (less any catch found there)
    cols = columns()
    for c in CHANNELS:  # every sample kept is the one logged there
        assert np.array_equal(got[c], cols[c][:n]), c


def test_a_tdms_file_cut_before_its_data_is_one_error_line(tmp_path, capsys):
    # One write, cut in its data: every channel reads empty. Before: an IndexError traceback.
    write_tdms(tmp_path / "full.tdms")
    data = (tmp_path / "full.tdms").read_bytes()
    (tmp_path / "cut.tdms").write_bytes(data[:len(data) // 2])
    code, _, err = run_import(tmp_path, TDMS_MAP, tmp_path / "cut.tdms", capsys=capsys)
    one_error(code, err, "cut.tdms:Test_1: the mapped channels hold 0 sample(s)",
              "ends inside its last write")
    (tmp_path / "stub.tdms").write_bytes(data[:40])
    code, _, err = run_import(tmp_path, TDMS_MAP, tmp_path / "stub.tdms", capsys=capsys)
    one_error(code, err, "stub.tdms: holds no groups", "cut short (40 bytes)")


def test_a_group_of_text_channels_is_no_test(tmp_path, capsys):
    # Before: the notes' group was imported as a test and failed on its missing channels.
    write_tdms(tmp_path / "lab.tdms", notes=True)
    code, out, err = run_import(tmp_path, TDMS_MAP, tmp_path / "lab.tdms", capsys=capsys)
    assert code == 0, err
    assert len(out) == 1 and out[0].startswith("lab.tdms:Test_1 -> ")


def test_a_waveforms_start_offset_puts_the_samples_on_labviews_time_axis(tmp_path, capsys):
    # A pre-trigger of 2 s: LabVIEW and DIAdem (and npTDMS's time_track) show the release at
    # 3 s. Before: the offset was dropped, the listed 3 s read as 1 s late.
    write_tdms(tmp_path / "lab.tdms", offset=2.0)
    code, _, err = run_import(tmp_path, TDMS_MAP.replace("times = [1.0]", "times = [3.0]"),
                              tmp_path / "lab.tdms", capsys=capsys)
    assert code == 0, err
    with h5py.File(tmp_path / "runs" / "lab_Test_1.h5", "r") as f:
        row = f["entry/releases"][0]
        h = f["entry/sync"]["h"][:]
    cols = columns()
    assert row["start_index"] == 500  # the 1 s hold, from the record's first sample
    assert np.array_equal(h, cols["h"])


def test_channels_of_one_length_at_other_rates_are_refused(tmp_path, capsys):
    write_tdms(tmp_path / "lab.tdms", increments={"moment": 0.5 / FS})
    code, _, err = run_import(tmp_path, TDMS_MAP, tmp_path / "lab.tdms", capsys=capsys)
    one_error(code, err, "lab.tdms:Test_1", "wf_increment differ", "'moment': 0.001",
              "one sampling rate")


# -- MATLAB v7.3 and the map -------------------------------------------------------------------

def test_a_v73_file_cut_short_is_named(tmp_path, capsys):
    cols = columns()
    with h5py.File(tmp_path / "full.mat", "w", userblock_size=512) as f:
        for name, values in cols.items():
            f.create_dataset(name, data=values[None, :]).attrs["MATLAB_class"] = b"double"
    data = (tmp_path / "full.mat").read_bytes()
    (tmp_path / "cut.mat").write_bytes(data[:len(data) // 2])
    code, _, err = run_import(tmp_path, MAP, tmp_path / "cut.mat", capsys=capsys)
    # Before: HDF5's own line, without the file: "error: Unable to synchronously open file".
    one_error(code, err, "cut.mat: cannot read as a MATLAB v7.3 file (HDF5)", "truncated")


@pytest.mark.parametrize(("edit", "names"), [
    (('sign = "down" }', 'sign = ["down"] }'), ["[channels] h sign = ['down']", "'up'"]),
    (('config = "sim_flat_plate"', 'config = "sim_flat_plate"\nformat = ["csv"]'),
     ["format = ['csv']", "'tdms'"]),
])
def test_a_list_where_the_map_wants_a_word_is_one_error_line(tmp_path, capsys, edit, names):
    # Before: TypeError: unhashable type: 'list' (a traceback).
    (tmp_path / "lab.csv").write_text(csv_text(columns()))
    assert edit[0] in MAP
    code, _, err = run_import(tmp_path, MAP.replace(*edit, 1), tmp_path / "lab.csv",
                              capsys=capsys)
    one_error(code, err, *names)


def test_a_matlab_matrix_is_named_where_the_map_looks_for_a_column(tmp_path, capsys):
    # A lab's data as one matrix (v5, samples x channels) and a v7.3 file's 2-column matrix:
    # before, "holds no numeric vectors" and "no column 'hm'" left the lab guessing why.
    from scipy.io import savemat

    cols = columns()
    savemat(tmp_path / "v5.mat", {"data": np.column_stack(list(cols.values()))})
    code, _, err = run_import(tmp_path, MAP, tmp_path / "v5.mat", capsys=capsys)
    one_error(code, err, "v5.mat: holds no numeric vectors", "data (a 4250 x 7 matrix)",
              "save each channel as a vector")
    with h5py.File(tmp_path / "v73.mat", "w", userblock_size=512) as f:
        for name, values in cols.items():
            f.create_dataset(name, data=values[None, :]).attrs["MATLAB_class"] = b"double"
        # MATLAB's 4250 x 2 [h, alpha], stored transposed as HDF5 does
        f.create_dataset("hm", data=np.vstack([cols["h"], cols["alpha"]])).attrs[
            "MATLAB_class"] = b"double"
    code, _, err = run_import(tmp_path, MAP.replace('column = "h"', 'column = "hm"'),
                              tmp_path / "v73.mat", capsys=capsys)
    one_error(code, err, "v73.mat: no column 'hm'", "hm (a 4250 x 2 matrix)")
