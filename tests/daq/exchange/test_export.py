"""``windrig export``: each format read back by its own independent reader (issue 37).

A run file is written by the production recorder (``RunRecorder``) with full-precision random
values (seeded), a gap (NaN), float32 tap pressures, two releases, events whose text has commas,
quotes, a newline and non-ASCII letters, and calibrations with numbers, arrays, bools and text.
Its expected contents are read with h5py directly (not through ``daq.exchange``). Each export is
then read by the format's own reader: numpy and the ``csv`` module, ``scipy.io.loadmat``,
``xarray.open_dataset`` (h5netcdf) and npTDMS; every value of the sync view must come back
exactly (``assert_array_equal``: no tolerance, the formats are lossless for float64, and
float32 pressures widen exactly), and so must the releases, the events and the calibrations.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.io
import xarray as xr
from nptdms import TdmsFile

from daq.cli import main
from daq.recording.recorder import RunRecorder

CONFIG = """[rig]
name = "export-test"
[section]
B = 0.3
m = 3.0
I = 0.03
fh = 2.0
fa = 4.0
zeta_h = 0.005
zeta_a = 0.005
"""
TAPS = ["tap000", "tap001", "tap002"]
EVENTS = [(0.5, "arm", "plc: armed {}"), (1.25, "release", "plc: model released {\"U\": 5.0}"),
          (2.0, "note", 'décollé, "vortex" at 3 Hz\nsecond line')]


def _write(path: Path, *, events: bool = True, calibrations: bool = True) -> None:
    rng = np.random.default_rng(37)
    n = 600
    rec = RunRecorder(path, config_text=CONFIG, rig_name="export-test", min_free_bytes=0,
                      reserve_bytes=0)
    rec.open()
    rec.add_sync(TAPS)
    if calibrations:
        rec.add_calibration("taps", {"scanner_module": np.zeros(3, dtype=np.int64),
                                     "scanner_channel": np.array([0, 2, 1], dtype=np.int64),
                                     "dead": np.array([1], dtype=np.int64),
                                     "live": np.array([True, False, True])},
                            {"source": "wiring sheet 7, \"rev B\"", "date": "2026-11-02",
                             "configured": "yes"})
        rec.add_calibration("air", {"relative_humidity": np.nan, "humidity_from": "none",
                                    "co2_mole_fraction": 0.0004},
                            {"source": "", "date": "", "configured": "no"})
    rec.start()
    columns = {name: rng.normal(scale, size=n) for name, scale in
               (("h", 0.004), ("alpha", 0.02), ("lift", 3.0), ("moment", 0.2), ("U", 5.0),
                ("rho", 1.2))}
    columns["lift"][100] = np.nan  # a gap: NaN must survive every format
    rec.append_sync(np.arange(n) / 200.0, **columns,
                    pressure=rng.normal(0, 40, size=(n, 3)).astype(np.float32))
    rec.add_release(release_time=0.5, start_index=100, stop_index=300, U=5.0, h0=0.004,
                    alpha0=0.02)
    rec.add_release(release_time=1.75, start_index=350, stop_index=600, U=5.123456789012345,
                    h0=-0.001, alpha0=0.0101)
    if events:
        for row in EVENTS:
            rec.add_event(*row)
    rec.close()


def _expected(path: Path) -> dict:
    """Read the run file with h5py alone: the truth every export is compared with."""
    with h5py.File(path, "r") as f:
        sync = f["entry/sync"]
        columns = {name: (ds[()], ds.attrs["units"]) for name, ds in sync.items()
                   if name != "tap"}
        calibration = {}
        if "entry/calibration" in f:
            for name, group in f["entry/calibration"].items():
                calibration[name] = ({k: ds[()] for k, ds in group.items()},
                                     {k: v for k, v in group.attrs.items() if k != "NX_class"})
        return {"columns": columns, "releases": f["entry/releases"][()],
                "calibration": calibration}


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> tuple[Path, dict]:
    path = tmp_path_factory.mktemp("export") / "run.h5"
    _write(path)
    return path, _expected(path)


def _export(path: Path, to: str, out: Path, capsys) -> str:
    assert main(["export", str(path), "--to", to, "--out", str(out)]) == 0
    captured = capsys.readouterr()
    assert captured.err == ""  # a complete file: nothing to warn about
    return captured.out


def test_csv_reads_back_exactly_with_numpy_and_csv(run, tmp_path, capsys):
    path, truth = run
    out = tmp_path / "run_csv"
    said = _export(path, "csv", out, capsys)
    assert "600 sync rows" in said and "2 release(s)" in said and "3 event(s)" in said
    with (out / "sync.csv").open(encoding="utf-8") as fh:
        header = next(csv.reader(fh))
    matrix = np.loadtxt(out / "sync.csv", delimiter=",", skiprows=1)
    assert header[:2] == ["time [s]", "h [m]"]
    for name, (values, units) in truth["columns"].items():
        if values.ndim == 2:
            cols = [header.index(f"{name} {tap} [{units}]") for tap in TAPS]
            np.testing.assert_array_equal(matrix[:, cols].astype(values.dtype), values)
            np.testing.assert_array_equal(matrix[:, cols], values.astype(np.float64))
        else:
            np.testing.assert_array_equal(matrix[:, header.index(f"{name} [{units}]")], values)
    assert np.isnan(matrix[100, header.index("lift [N/m]")])
    with (out / "releases.csv").open(encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert [float(r["U [m/s]"]) for r in rows] == list(truth["releases"]["U"])
    assert [int(r["start_index [1]"]) for r in rows] == [100, 350]
    with (out / "events.csv").open(encoding="utf-8", newline="") as fh:
        events = [(float(t), k, x) for t, k, x in list(csv.reader(fh))[1:]]
    assert events == EVENTS
    with (out / "calibration.csv").open(encoding="utf-8", newline="") as fh:
        cal = list(csv.DictReader(fh))
    channel = [int(r["value"]) for r in cal if r["name"] == "scanner_channel"]
    assert channel == [0, 2, 1]
    assert [r["value"] for r in cal if r["name"] == "@source"] == ["", 'wiring sheet 7, "rev B"']
    assert [r["value"] for r in cal if r["name"] == "live"] == ["1", "0", "1"]
    assert (out / "config.toml").read_text(encoding="utf-8") == CONFIG


def test_mat_reads_back_exactly_with_loadmat(run, tmp_path, capsys):
    path, truth = run
    out = tmp_path / "run.mat"
    _export(path, "mat", out, capsys)
    m = scipy.io.loadmat(out, squeeze_me=True, struct_as_record=False)
    for name, (values, units) in truth["columns"].items():
        got = getattr(m["sync"], name)
        assert got.dtype == values.dtype, name  # float32 pressures stay float32
        np.testing.assert_array_equal(got, values)
        assert getattr(m["sync_units"], name) == units
    assert list(m["taps"]) == TAPS
    for field in truth["releases"].dtype.names:
        np.testing.assert_array_equal(getattr(m["releases"], field), truth["releases"][field])
    assert m["releases_units"].U == "m/s"
    assert list(zip(m["events"].time, m["events"].kind, m["events"].text, strict=True)) \
        == EVENTS
    taps = m["calibration"].taps
    np.testing.assert_array_equal(taps.scanner_channel, [0, 2, 1])
    np.testing.assert_array_equal(taps.live.astype(bool), [True, False, True])
    assert np.isnan(m["calibration"].air.relative_humidity)
    assert m["calibration"].air.humidity_from == "none"
    assert m["calibration_attrs"].taps.source == 'wiring sheet 7, "rev B"'
    assert m["config"] == CONFIG and m["run"].rig_name == "export-test"


def test_netcdf_reads_back_exactly_with_xarray(run, tmp_path, capsys):
    path, truth = run
    out = tmp_path / "run.nc"
    _export(path, "netcdf", out, capsys)
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        assert ds["pressure"].dims == ("time", "tap") and list(ds["tap"].values) == TAPS
        for name, (values, units) in truth["columns"].items():
            np.testing.assert_array_equal(ds[name].values, values)
            assert ds[name].dtype == values.dtype and ds[name].attrs["units"] == units
        assert ds.attrs["rig_config"] == CONFIG
    with xr.open_dataset(out, engine="h5netcdf", group="releases") as ds:
        for field in truth["releases"].dtype.names:
            np.testing.assert_array_equal(ds[field].values, truth["releases"][field])
        assert ds["alpha0"].attrs["units"] == "rad"
    with xr.open_dataset(out, engine="h5netcdf", group="events") as ds:
        assert list(zip(ds["time"].values, ds["kind"].values, ds["text"].values,
                        strict=True)) == EVENTS
    with xr.open_dataset(out, engine="h5netcdf", group="calibration/taps") as ds:
        np.testing.assert_array_equal(ds["scanner_channel"].values, [0, 2, 1])
        np.testing.assert_array_equal(ds["live"].values, [True, False, True])
        assert ds.attrs["date"] == "2026-11-02"
    with xr.open_dataset(out, engine="h5netcdf", group="calibration/air") as ds:
        assert ds["humidity_from"].values[()] == "none"
        assert np.isnan(ds["relative_humidity"].values[()])


def test_tdms_reads_back_exactly_with_nptdms(run, tmp_path, capsys):
    path, truth = run
    out = tmp_path / "run.tdms"
    _export(path, "tdms", out, capsys)
    f = TdmsFile.read(out)
    sync = f["sync"]
    for name, (values, units) in truth["columns"].items():
        if values.ndim == 2:
            for i, tap in enumerate(TAPS):
                channel = sync[f"{name} {tap}"]
                assert channel.dtype == values.dtype
                np.testing.assert_array_equal(channel[:], values[:, i])
                assert channel.properties["unit_string"] == units
        else:
            np.testing.assert_array_equal(sync[name][:], values)
            assert sync[name].properties["unit_string"] == units
    # A waveform for LabVIEW: 200 Hz from 0 s (the rows are k / 200, exactly uniform).
    assert sync["h"].properties["wf_increment"] == pytest.approx(1 / 200, rel=1e-12)
    assert sync["h"].properties["wf_start_offset"] == 0.0
    np.testing.assert_allclose(sync["h"].time_track(), truth["columns"]["time"][0], rtol=0,
                               atol=1e-12)  # s: float64 rounding of k * increment
    for field in truth["releases"].dtype.names:
        np.testing.assert_array_equal(f["releases"][field][:], truth["releases"][field])
    events = f["events"]
    assert list(zip(events["time"][:], events["kind"][:], events["text"][:], strict=True)) \
        == EVENTS
    taps = f["calibration taps"]
    np.testing.assert_array_equal(taps["scanner_channel"][:], [0, 2, 1])
    assert taps.properties["source"] == 'wiring sheet 7, "rev B"'
    assert f["calibration air"].properties["humidity_from"] == "none"
    assert f.properties["rig_config"] == CONFIG


def test_a_file_without_events_or_calibrations_is_exported_with_a_warning(tmp_path, capsys):
    path = tmp_path / "bare.h5"
    _write(path, events=False, calibrations=False)
    assert main(["export", str(path), "--to", "mat"]) == 0  # default: beside the run
    err = capsys.readouterr().err
    assert err == ""  # an empty events table is not missing; no calibrations: the defaults
    m = scipy.io.loadmat(tmp_path / "bare.mat", squeeze_me=True, struct_as_record=False)
    assert np.size(m["events"].time) == 0
    with h5py.File(path, "a") as f:  # the smallest run file has no events at all
        del f["entry/events"]
    assert main(["export", str(path), "--to", "netcdf"]) == 0
    err = capsys.readouterr().err
    assert err.strip() == f"warning: {path} has no /entry/events: exported without events"
    with xr.open_dataset(tmp_path / "bare.nc", engine="h5netcdf", group="events") as ds:
        assert ds.sizes["event"] == 0


@pytest.mark.parametrize(("args", "expected"), [
    (["--to", "mat"], "exists already; an export never overwrites"),
    (["--to", "csv", "--out", "{tmp}/no/such/folder"], "does not exist"),
])
def test_bad_outputs_are_one_error_line(run, tmp_path, capsys, args, expected):
    path = tmp_path / "run.h5"
    path.write_bytes(run[0].read_bytes())
    (tmp_path / "run.mat").write_bytes(b"keep me")
    code = main(["export", str(path), *[a.format(tmp=tmp_path) for a in args]])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("error: ") and expected in err
    assert len(err.strip().splitlines()) == 1
    assert (tmp_path / "run.mat").read_bytes() == b"keep me"


def test_not_a_run_file_is_one_error_line(tmp_path, capsys):
    text = tmp_path / "run.csv"
    text.write_text("t,h\n0,0\n")
    assert main(["export", str(text), "--to", "tdms"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {text}: not an HDF5 run file") and len(err.splitlines()) == 1
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = 1
    assert main(["export", str(other), "--to", "tdms"]) == 2
    assert "has no /entry/sync/time" in capsys.readouterr().err
    assert not (tmp_path / "other.tdms").exists()


def test_an_output_name_that_does_not_fit_the_format_warns(run, tmp_path, capsys):
    out = tmp_path / "run.nc"
    assert main(["export", str(run[0]), "--to", "mat", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert err.startswith(f"warning: {out}: a mat file is usually named *.mat")
    assert scipy.io.loadmat(out)["run"] is not None  # written as asked: a MATLAB file


def test_a_missing_optional_library_names_the_extra(run, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "nptdms", None)  # as if the exchange extra were missing
    assert main(["export", str(run[0]), "--to", "tdms", "--out", str(tmp_path / "r.tdms")]) == 1
    assert capsys.readouterr().err == ("error: this command needs nptdms, which is not "
                                       "installed: pip install 'windrig[exchange]'\n")
    assert not (tmp_path / "r.tdms").exists()


def test_a_3dof_run_exports_its_sway_and_drag(tmp_path, capsys):
    path = tmp_path / "sway.h5"
    rng = np.random.default_rng(21)
    n = 50
    rec = RunRecorder(path, config_text=CONFIG + "fp = 1.5\n", rig_name="sway",
                      min_free_bytes=0, reserve_bytes=0, sway=True)
    rec.open()
    rec.add_sync(TAPS)
    rec.start()
    columns = {name: rng.normal(size=n) for name in
               ("h", "alpha", "lift", "moment", "U", "rho", "p", "drag")}
    rec.append_sync(np.arange(n) / 100.0, **columns, pressure=np.zeros((n, 3), np.float32))
    rec.add_release(release_time=0.1, start_index=10, stop_index=50, U=4.0, h0=0.0, alpha0=0.0,
                    p0=0.00123456789)
    rec.close()
    assert main(["export", str(path), "--to", "netcdf"]) == 0
    capsys.readouterr()
    with xr.open_dataset(tmp_path / "sway.nc", engine="h5netcdf") as ds:
        np.testing.assert_array_equal(ds["p"].values, columns["p"])
        np.testing.assert_array_equal(ds["drag"].values, columns["drag"])
        assert ds["p"].attrs["units"] == "m" and ds["drag"].attrs["units"] == "N/m"
    with xr.open_dataset(tmp_path / "sway.nc", engine="h5netcdf", group="releases") as ds:
        assert ds["p0"].values.tolist() == [0.00123456789] and ds["p0"].attrs["units"] == "m"


def test_rows_a_crash_sized_but_never_wrote_are_left_out_with_a_warning(run, tmp_path, capsys):
    path = tmp_path / "crashed.h5"
    path.write_bytes(run[0].read_bytes())
    with h5py.File(path, "a") as f:  # what a crash leaves: sizes ahead of the data (fill NaN)
        for ds in f["entry/sync"].values():
            if ds.maxshape[0] is None:
                ds.resize(ds.shape[0] + 7, axis=0)
                ds[-7:] = np.nan
    assert main(["export", str(path), "--to", "csv"]) == 0
    err = capsys.readouterr().err
    assert err == (f"warning: {path}: the last 7 row(s) of /entry/sync were sized but never "
                   "written (a crash?): not exported\n")
    matrix = np.loadtxt(tmp_path / "crashed_csv" / "sync.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(matrix[:, 0], run[1]["columns"]["time"][0])
