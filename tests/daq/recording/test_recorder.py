"""Tests of daq.recording.recorder: one run's HDF5 file, as docs/reference/file_format.md has it.

Measurements (2026-11, h5py 3.16.0 / HDF5 2.0.0, shared 2-core VM, local disk, page cache warm;
a throwaway script, to be kept in benchmarks/ later): a 512-channel float32 stream at 500 Hz in
blocks of 50 rows (host_time_ns with arrival jitter, device_time, counter, value: 103.6 kB a
block), 400 blocks; pressures = tap mean + 2 Hz swing + 2 Pa noise. MB/s of payload, best and
median of 5, close included; ratio = payload / file size.

    plain h5py resize + write of the 4 arrays, no filter    321 / 238 MB/s   ratio 0.99
    plain h5py, same, gzip level 1 + shuffle                  57 /  49 MB/s   ratio 1.28
    RunRecorder.append_raw (SWMR), compression=None          302 / 216 MB/s   ratio 0.99
    RunRecorder.append_raw (SWMR), "lzf" + shuffle           124 / 121 MB/s   ratio 1.21
    RunRecorder.append_raw (SWMR), "gzip" 1 + shuffle         59 /  46 MB/s   ratio 1.28  default
    same, with fsync and a 0.1 s flush interval               47 /  37 MB/s   ratio 1.27
    gzip level 4 / level 6 (earlier run)                      53 /  47 MB/s   ratio 1.31 / 1.32

Per dataset (gzip 1 + shuffle): value 1.3x, host_time_ns 2.5x, device_time 12.7x, counter 59x:
noisy float32 samples compress little (their low mantissa bits are noise). The recorder's own
cost is small (302 vs 321 MB/s unfiltered); the filter is what costs. The stream itself is
1.0 MB/s, so gzip takes ~2 % of a core: gzip (level 1: within 2 % of level 4's ratio, faster) is
the default because every HDF5 reader (MATLAB, HDFView, h5dump, silx without hdf5plugin) can
read it, which lzf cannot. Before the recorder kept its datasets open, reopening them per block
cost 5x in rate and tripled the file (a chunk's cache dies with its dataset handle).
"""

from __future__ import annotations

import errno
import importlib.util
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from datetime import UTC, datetime
from importlib.metadata import version
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from daq.errors import DaqError, InsufficientSpaceError, RecorderStateError, StorageError
from daq.recording.layout import CLOCK_MODEL, EVENT_DTYPE, GAP_DTYPE, RELEASE_DTYPE, read_sync
from daq.recording.recorder import RunRecorder

from support.configs import SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

CHILD = Path(__file__).with_name("_recorder_child.py")
CONFIG_TEXT = SIM_FLAT_PLATE.read_text(encoding="utf-8") + \
    "\n# verbatim check: ünïcode, trailing spaces   \n"
TAPS = ["t00", "t01", "t02", "t03"]


def recorder(path: Path, **kwargs: Any) -> RunRecorder:
    kwargs.setdefault("min_free_bytes", 0)
    return RunRecorder(path, config_text=CONFIG_TEXT, rig_name="flat_plate",
                       operator_notes="run 7, gusty", **kwargs)


def declared(path: Path, **kwargs: Any) -> RunRecorder:
    """Open a recorder with a scanner (float32), a laser stream (float64) and the sync view."""
    rec = recorder(path, **kwargs)
    rec.open()
    rec.add_stream("scanner", ["p0", "p1", "p2"], "Pa", 500.0, "float32",
                   extra={"trigger_time": "float64"})
    rec.add_stream("lasers", ["h", "alpha"], ["m", "rad"], 2000.0, "float64")
    rec.add_sync(TAPS)
    return rec


def raw_block(k0: int, n: int, channels: int) -> dict[str, np.ndarray]:
    k = np.arange(k0, k0 + n)
    return {"host_time_ns": 10**12 + 2_000_000 * k, "device_time": k / 500.0,
            "counter": k.astype(np.int64),
            "values": np.stack([k * 0.5 + j for j in range(channels)], axis=1)}


def sync_block(k0: int, n: int) -> dict[str, np.ndarray]:
    k = np.arange(k0, k0 + n, dtype=float)
    return {"time": k / 100.0, "h": 1e-3 * np.sin(k), "alpha": 1e-2 * np.cos(k),
            "lift": 2.0 * k, "moment": -0.5 * k, "pressure": np.outer(k, [1.0, 2.0, 3.0, 4.0]),
            "U": np.full(n, 12.5), "rho": np.full(n, 1.2)}


def append_sync(rec: RunRecorder, block: dict[str, np.ndarray]) -> None:
    rest = {key: value for key, value in block.items() if key != "time"}
    rec.append_sync(block["time"], **rest)


def record_run(path: Path) -> dict[str, Any]:
    """Write a small complete run; return what was written."""
    rec = declared(path)
    rec.set_sync_attrs(clock_offset_s={"scanner": 0.25}, clock_drift_ppm={"scanner": 20.0})
    rec.add_metadata("calz_scanner", {"offsets_pa": np.array([0.1, -0.2, 0.05]), "ok": True})
    rec.add_event(0.0, "system", "declared")
    rec.start(t0_host_ns=10**12)
    scanner = [raw_block(0, 30, 3), raw_block(30, 20, 3), raw_block(50, 7, 3)]
    for block in scanner:
        rec.append_raw("scanner", block["host_time_ns"], block["device_time"], block["counter"],
                       block["values"], extra={"trigger_time": block["device_time"] + 0.5})
    lasers = raw_block(0, 11, 2)
    rec.append_raw("lasers", lasers["host_time_ns"], lasers["device_time"], lasers["counter"],
                   lasers["values"])
    rec.add_gap("scanner", after_counter=29, length=3)
    rec.add_gap("lasers", after_counter=10, length=-1)
    syncs = [sync_block(0, 40), sync_block(40, 25)]
    for block in syncs:
        append_sync(rec, block)
    first = rec.add_release(release_time=0.1, start_index=10, stop_index=40, U=12.5, h0=0.01,
                            alpha0=0.02)
    second = rec.add_release(release_time=0.45, start_index=45, stop_index=65, U=12.5, h0=-0.01,
                             alpha0=0.0)
    rec.add_event(0.1, "release", "magnet off")
    rec.add_event(0.3, "operator", "gust — noted")
    rec.set_sync_attrs(clock_offset_s={"lasers": -0.125}, clock_drift_ppm={"lasers": -3.0},
                       residual_misalignment_s=1.5e-4)
    rec.add_metadata("calz_late", [1.0, 2.0])
    rec.close()
    return {"scanner": scanner, "lasers": lasers, "sync": syncs, "release_rows": (first, second)}


def load_child() -> Any:
    spec = importlib.util.spec_from_file_location("_recorder_child", CHILD)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# --------------------------------------------------------------------------------------------------
# Layout: the contract
# --------------------------------------------------------------------------------------------------
def test_layout_is_the_contract(tmp_path: Path) -> None:
    path = tmp_path / "run.h5"
    before = datetime.now(UTC)
    record_run(path)
    with h5py.File(path, "r") as f:
        assert f.attrs["windrig_version"] == version("windrig")
        created = datetime.fromisoformat(f.attrs["created"])
        offset = created.utcoffset()
        assert offset is not None and offset.total_seconds() == 0
        assert before.replace(microsecond=0) <= created <= datetime.now(UTC)
        assert f.attrs["default"] == "entry"

        entry = f["entry"]
        assert entry.attrs["NX_class"] == "NXentry"
        assert entry.attrs["default"] == "sync"
        assert entry.attrs["rig_name"] == "flat_plate"
        assert entry.attrs["operator_notes"] == "run 7, gusty"
        datetime.fromisoformat(entry.attrs["start_time"])
        assert sorted(entry) == ["config", "events", "instrument", "metadata", "releases", "sync"]

        assert entry["config"].shape == ()
        assert h5py.check_string_dtype(entry["config"].dtype).encoding == "utf-8"
        assert entry["config"].asstr()[()] == CONFIG_TEXT

        instrument = entry["instrument"]
        assert instrument.attrs["NX_class"] == "NXinstrument"
        assert sorted(instrument) == ["lasers", "scanner"]
        for device, channels, units, rate, dtype, rows in [
                ("scanner", ["p0", "p1", "p2"], ["Pa"] * 3, 500.0, "float32", 57),
                ("lasers", ["h", "alpha"], ["m", "rad"], 2000.0, "float64", 11)]:
            group = instrument[device]
            assert group.attrs["NX_class"] == "NXdata" and group.attrs["signal"] == "value"
            assert list(group.attrs["axes"]) == ["host_time_ns", "channel"]
            assert [c.decode() for c in group["channel"][:]] == channels
            assert list(group.attrs["channel_names"]) == channels
            assert list(group.attrs["units"]) == units
            assert group.attrs["rate"] == rate and group.attrs["rate_units"] == "Hz"
            expected: dict[str, tuple[Any, tuple[int, ...]]] = {
                "host_time_ns": (np.int64, (rows,)), "device_time": (np.float64, (rows,)),
                "counter": (np.int64, (rows,)), "value": (dtype, (rows, len(channels))),
                "gaps": (GAP_DTYPE, (1,))}
            if device == "scanner":
                expected["trigger_time"] = (np.float64, (rows,))
            assert sorted(group) == sorted([*expected, "channel"])
            for name, (kind, shape) in expected.items():
                ds = group[name]
                assert ds.dtype == np.dtype(kind), (device, name)
                assert ds.shape == shape, (device, name)
                assert ds.chunks is not None and ds.maxshape[0] is None, (device, name)
            assert group["host_time_ns"].attrs["units"] == "ns"
            assert group["device_time"].attrs["units"] == "s"
            assert group["counter"].attrs["units"] == "1"
            assert list(group["gaps"].dtype.names) == ["after_counter", "length"]
        assert instrument["scanner/value"].attrs["units"] == "Pa"
        assert "units" not in instrument["lasers/value"].attrs  # mixed: per channel on the group

        sync = entry["sync"]
        assert sync.attrs["NX_class"] == "NXdata"
        assert sync.attrs["signal"] == "h" and sync.attrs["axes"] == "time"
        assert sync.attrs["time_indices"] == 0
        assert list(sync.attrs["tap_names"]) == TAPS
        assert sync.attrs["t0_host_ns"] == 10**12
        sync_units = {"time": "s", "h": "m", "alpha": "rad", "lift": "N/m", "moment": "N m/m",
                      "pressure": "Pa", "U": "m/s", "rho": "kg/m^3"}
        assert sorted(sync) == sorted([*sync_units, "tap"])
        # Dimension scales: netCDF readers see time (and tap) as the coordinates.
        assert sync["time"].is_scale and sync["tap"].is_scale
        assert [t.decode() for t in sync["tap"][:]] == TAPS
        assert sync["pressure"].dims[1][0] == sync["tap"]
        for name, unit in sync_units.items():
            if name != "time":
                assert sync[name].dims[0][0] == sync["time"], name
                assert sync[name].dims[0].label == "time", name
            assert sync[name].attrs["units"] == unit
            assert sync[name].attrs["long_name"]
            shape = (65, len(TAPS)) if name == "pressure" else (65,)
            assert sync[name].shape == shape and sync[name].maxshape[0] is None
            assert sync[name].dtype == (np.float32 if name == "pressure" else np.float64)
        # clock fits: one before start (written at once), one after (written at close)
        assert sync.attrs["clock_model"] == CLOCK_MODEL
        assert sync.attrs["clock_offset_s__scanner"] == 0.25
        assert sync.attrs["clock_drift_ppm__scanner"] == 20.0
        assert sync.attrs["clock_offset_s__lasers"] == -0.125
        assert sync.attrs["clock_drift_ppm__lasers"] == -3.0
        assert sync.attrs["residual_misalignment_s"] == 1.5e-4

        assert entry["releases"].dtype == RELEASE_DTYPE
        assert list(entry["releases"].dtype.names) == ["release_time", "start_index",
                                                       "stop_index", "U", "h0", "alpha0"]
        assert list(entry["releases"].attrs["units"]) == ["s", "", "", "m/s", "m", "rad"]
        assert entry["events"].dtype == EVENT_DTYPE
        assert entry["metadata"].attrs["NX_class"] == "NXparameters"


def test_nexus_default_chain_plots_h_over_time(tmp_path: Path) -> None:
    """Follow default -> default -> signal/axes as a generic NeXus viewer (silx) does."""
    path = tmp_path / "run.h5"
    record_run(path)
    with h5py.File(path, "r") as f:
        node: Any = f
        while "default" in node.attrs:
            node = node[node.attrs["default"]]
        assert node.name == "/entry/sync"
        assert node.attrs["NX_class"] == "NXdata"
        signal_ds = node[node.attrs["signal"]]
        axes = node.attrs["axes"]
        axes = [axes] if isinstance(axes, str) else list(axes)
        assert signal_ds.name == "/entry/sync/h" and signal_ds.ndim == len(axes) == 1
        axis = node[axes[0]]
        assert axis.name == "/entry/sync/time"
        assert axis.shape == signal_ds.shape and axis.attrs["units"] == "s"
        assert signal_ds.attrs["units"] == "m"
        assert np.all(np.diff(axis[:]) > 0)


def test_blocks_appended_in_several_calls_concatenate(tmp_path: Path) -> None:
    path = tmp_path / "run.h5"
    written = record_run(path)
    with h5py.File(path, "r") as f:
        scanner = f["entry/instrument/scanner"]
        for key in ("host_time_ns", "device_time", "counter"):
            expected = np.concatenate([block[key] for block in written["scanner"]])
            np.testing.assert_array_equal(scanner[key][:], expected)
        expected_values = np.concatenate([b["values"] for b in written["scanner"]])
        np.testing.assert_array_equal(scanner["value"][:], expected_values.astype(np.float32))
        np.testing.assert_array_equal(
            scanner["trigger_time"][:],
            np.concatenate([b["device_time"] for b in written["scanner"]]) + 0.5)
        np.testing.assert_array_equal(f["entry/instrument/lasers/value"][:],
                                      written["lasers"]["values"])  # float64 kept exactly
    data = read_sync(path)
    assert sorted(data) == sorted(["time", "h", "alpha", "lift", "moment", "pressure", "U", "rho"])
    for key, value in data.items():
        expected = np.concatenate([block[key] for block in written["sync"]])
        np.testing.assert_allclose(value, expected, rtol=1e-7 if key == "pressure" else 0)


def test_polled_device_without_clock_and_typed_extra_columns(tmp_path: Path) -> None:
    path = tmp_path / "run.h5"
    rec = recorder(path)
    rec.open()
    rec.add_stream("plc", ["coil_release"], "", 10.0, "float64",
                   extra={"triggered": "bool", "status": "uint16"})
    rec.add_sync([])
    rec.start()
    rec.append_raw("plc", [5, 6, 7], None, [0, 1, 2], [1.0, 1.0, 0.0],
                   extra={"triggered": [False, True, False], "status": [1, 2, 65535]})
    rec.close()
    with h5py.File(path, "r") as f:
        plc = f["entry/instrument/plc"]
        assert np.isnan(plc["device_time"][:]).all() and plc["device_time"].shape == (3,)
        assert plc["value"][:].tolist() == [[1.0], [1.0], [0.0]]
        assert plc["triggered"].dtype == np.bool_ and plc["triggered"][:].tolist() == [0, 1, 0]
        assert plc["status"].dtype == np.uint16 and plc["status"][2] == 65535


def test_gaps_releases_events_and_metadata_stored(tmp_path: Path) -> None:
    path = tmp_path / "run.h5"
    written = record_run(path)
    assert written["release_rows"] == (0, 1)
    with h5py.File(path, "r") as f:
        assert f["entry/instrument/scanner/gaps"][:].tolist() == [(29, 3)]
        assert f["entry/instrument/lasers/gaps"][:].tolist() == [(10, -1)]
        releases = f["entry/releases"][:]
        assert releases.tolist() == [(0.1, 10, 40, 12.5, 0.01, 0.02),
                                     (0.45, 45, 65, 12.5, -0.01, 0.0)]
        np.testing.assert_array_equal(f["entry/releases"]["U"], [12.5, 12.5])
        events = f["entry/events"][:]
        assert events["time"].tolist() == [0.0, 0.1, 0.3]
        assert [k.decode() for k in events["kind"]] == ["system", "release", "operator"]
        assert [t.decode("utf-8") for t in events["text"]] == ["declared", "magnet off",
                                                               "gust — noted"]
        calz = f["entry/metadata/calz_scanner"]
        assert calz.attrs["NX_class"] == "NXparameters"
        np.testing.assert_array_equal(calz["offsets_pa"][:], [0.1, -0.2, 0.05])
        assert bool(calz["ok"][()]) is True
        np.testing.assert_array_equal(f["entry/metadata/calz_late"][:], [1.0, 2.0])


def test_chunks_and_compression(tmp_path: Path) -> None:
    sizes = {}
    for compression in ("gzip", "lzf", None):
        path = tmp_path / f"{compression}.h5"
        rec = recorder(path, compression=compression)
        rec.open()
        rec.add_stream("scanner", [f"p{i}" for i in range(512)], "Pa", 500.0, "float32")
        rec.add_sync([])
        rec.start()
        for k0 in range(0, 2000, 50):
            block = raw_block(k0, 50, 512)
            rec.append_raw("scanner", block["host_time_ns"], block["device_time"],
                           block["counter"], block["values"])
        rec.close()
        sizes[compression] = path.stat().st_size
        with h5py.File(path, "r") as f:
            value = f["entry/instrument/scanner/value"]
            assert value.chunks == (256, 512)  # <= 512 KiB: stays in HDF5's chunk cache
            assert f["entry/instrument/scanner/counter"].chunks == (4096,)
            assert value.compression == compression
            assert value.shuffle is (compression is not None)
            assert f["entry/sync/pressure"].shape == (0, 0)
    assert sizes["gzip"] < sizes["lzf"] < sizes[None]


# --------------------------------------------------------------------------------------------------
# Life cycle, call order and bad input
# --------------------------------------------------------------------------------------------------
def test_constructor_does_no_io_and_validates(tmp_path: Path) -> None:
    recorder(tmp_path / "missing_dir" / "run.h5")  # no directory needed until open()
    assert not (tmp_path / "missing_dir").exists()
    with pytest.raises(ValueError, match="compression = 'zstd'"):
        recorder(tmp_path / "r.h5", compression="zstd")
    with pytest.raises(ValueError, match="flush_interval_s"):
        recorder(tmp_path / "r.h5", flush_interval_s=0)
    with pytest.raises(ValueError, match="chunk_rows"):
        recorder(tmp_path / "r.h5", chunk_rows=0)
    with pytest.raises(TypeError, match="unexpected keyword"):
        recorder(tmp_path / "r.h5", swmr=True)


def test_call_order_is_enforced(tmp_path: Path) -> None:
    rec = recorder(tmp_path / "run.h5")
    with pytest.raises(RecorderStateError, match="open"):
        rec.add_stream("scanner", ["p0"], "Pa", 500.0)
    rec.open()
    rec.add_stream("scanner", ["p0"], "Pa", 500.0)
    with pytest.raises(RecorderStateError, match="not allowed while the recorder is 'declaring'"):
        rec.append_raw("scanner", [1], [0.0], [0], [[1.0]])
    with pytest.raises(RecorderStateError, match="add_sync"):
        rec.start()
    rec.add_sync([])
    rec.start()
    with pytest.raises(RecorderStateError, match="call order"):
        rec.add_stream("lasers", ["h"], "m", 2000.0)
    rec.close()
    with pytest.raises(RecorderStateError):
        rec.add_event(1.0, "late", "after close")


def test_bad_blocks_are_refused(tmp_path: Path) -> None:
    rec = declared(tmp_path / "run.h5")
    with pytest.raises(ValueError, match="already declared"):
        rec.add_stream("lasers", ["h"], "m", 1.0)
    with pytest.raises(ValueError, match="units must be one str or one per channel"):
        rec.add_stream("x", ["a", "b"], ["m"], 1.0)
    with pytest.raises(ValueError, match="value_dtype"):
        rec.add_stream("y", ["a"], "m", 1.0, "int16")
    with pytest.raises(ValueError, match="HDF5 path component"):
        rec.add_stream("a/b", ["a"], "m", 1.0)
    with pytest.raises(ValueError, match="no stream 'fan' declared"):
        rec.set_sync_attrs(clock_offset_s={"fan": 1.0})
    rec.start()
    block = raw_block(0, 5, 2)
    with pytest.raises(ValueError, match=r"values have shape \(5, 3\), expected \(5, 2\)"):
        rec.append_raw("lasers", block["host_time_ns"], block["device_time"], block["counter"],
                       np.zeros((5, 3)))
    with pytest.raises(TypeError, match="host_time_ns must be integers"):
        rec.append_raw("lasers", block["host_time_ns"] * 1.0, block["device_time"],
                       block["counter"], block["values"])
    with pytest.raises(ValueError, match="extra columns"):
        rec.append_raw("scanner", block["host_time_ns"], block["device_time"], block["counter"],
                       np.zeros((5, 3)))
    with pytest.raises(ValueError, match="no stream 'fan' declared"):
        rec.append_raw("fan", [1], [0.0], [0], [[1.0]])
    with pytest.raises(ValueError, match="expected \\(3, 4\\)"):
        append_sync(rec, {**sync_block(0, 3), "pressure": np.zeros((3, 2))})
    with pytest.raises(TypeError, match="unexpected keyword"):
        rec.append_sync([0.0], h=[0.0], alpha=[0.0], lift=[0.0], moment=[0.0],  # type: ignore
                        pressure=np.zeros((1, 4)), U=[1.0], rho=[1.2], beta=[0.0])
    with pytest.raises(ValueError, match="at most 1024 fit"):
        rec.add_event(1.0, "operator", "x" * 1025)
    with pytest.raises(ValueError, match="start_index <= stop_index"):
        rec.add_release(release_time=1.0, start_index=5, stop_index=2, U=1, h0=0, alpha0=0)
    with pytest.raises(ValueError, match="gap length"):
        rec.add_gap("lasers", 3, 0)
    rec.close()
    with h5py.File(tmp_path / "run.h5", "r") as f:  # nothing half-appended
        assert f["entry/instrument/lasers/counter"].shape == (0,)
        assert f["entry/sync/time"].shape == (0,)


def test_periodic_flush_follows_the_interval(tmp_path: Path) -> None:
    now = [100.0]
    rec = declared(tmp_path / "run.h5", flush_interval_s=1.0, clock=lambda: now[0])
    rec.start()
    block = raw_block(0, 5, 2)

    def append() -> None:
        rec.append_raw("lasers", block["host_time_ns"], block["device_time"], block["counter"],
                       block["values"])

    append()
    now[0] += 0.9
    append()
    assert rec.flushes == 0
    now[0] += 0.1
    append()
    assert rec.flushes == 1
    assert rec.flush_if_due() is False
    now[0] += 1.5
    assert rec.flush_if_due() is True and rec.flushes == 2
    rec.close()


def test_close_is_idempotent_and_leaves_a_normal_file(tmp_path: Path) -> None:
    path = tmp_path / "run.h5"
    recorder(tmp_path / "never.h5").close()  # never opened: nothing to do, no file
    assert not (tmp_path / "never.h5").exists()
    with declared(path) as rec:
        rec.start()
        append_sync(rec, sync_block(0, 3))
    assert rec.state == "closed"
    rec.close()
    rec.close()
    # a file still flagged for SWMR writing refuses a plain read-write open ("may use h5clear")
    with h5py.File(path, "r+") as f:
        assert f["entry/sync/h"].shape == (3,)


def test_existing_file_is_not_overwritten(tmp_path: Path) -> None:
    path = tmp_path / "run.h5"
    path.write_bytes(b"a previous run")
    rec = recorder(path)
    with pytest.raises(StorageError, match="already exists") as info:
        rec.open()
    assert info.value.errno == errno.EEXIST
    assert path.read_bytes() == b"a previous run"


# --------------------------------------------------------------------------------------------------
# Unwritable path, full disk: fail at once
# --------------------------------------------------------------------------------------------------
def chmod_blocks_writes(directory: Path) -> bool:
    """Return whether a directory's mode stops this process from creating a file in it.

    It does not for root (CAP_DAC_OVERRIDE); probing is surer than testing the uid.
    """
    probe = directory / "probe"
    try:
        probe.touch()
    except PermissionError:
        return True
    probe.unlink()
    return False


@pytest.fixture
def unwritable_directory(tmp_path: Path) -> Iterator[Path]:
    """Yield a directory where creating a file fails with a permission error, for this process.

    A chmod 0o500 directory if that stops us; else (root) /sys, where sysfs refuses new files
    even to root.
    """
    directory = tmp_path / "read_only"
    directory.mkdir()
    directory.chmod(0o500)
    try:
        if chmod_blocks_writes(directory):
            yield directory
        elif os.path.ismount("/sys"):
            yield Path("/sys")
        else:
            pytest.skip("chmod does not stop this user (root) and /sys is not mounted")
    finally:
        directory.chmod(0o700)  # let pytest remove tmp_path


def test_unwritable_directory_fails_at_once(unwritable_directory: Path) -> None:
    path = unwritable_directory / "windrig_run.h5"
    rec = recorder(path)
    t = time.monotonic()
    with pytest.raises(StorageError, match="cannot create run file .*windrig_run.h5") as info:
        rec.open()
    assert time.monotonic() - t < 1.0
    assert info.value.errno in (errno.EACCES, errno.EPERM, errno.EROFS)
    assert isinstance(info.value, OSError) and isinstance(info.value, DaqError)
    assert info.value.filename == str(path)
    assert not path.exists()
    assert rec.state == "new"


def test_path_under_a_regular_file_fails_at_once(tmp_path: Path) -> None:
    """Works for every user, root included: a file cannot hold a directory entry."""
    (tmp_path / "plain_file").write_text("x")
    with pytest.raises(StorageError, match="plain_file is not a directory") as info:
        recorder(tmp_path / "plain_file" / "run.h5").open()
    assert info.value.errno == errno.ENOTDIR
    with pytest.raises(StorageError, match="does not exist") as info:
        recorder(tmp_path / "no_such_dir" / "run.h5").open()
    assert info.value.errno == errno.ENOENT


def test_free_space_below_minimum_fails_before_creating(tmp_path: Path) -> None:
    """The free-space check, with free space injected (a full disk needs root to make)."""
    asked = []

    def five_mib(directory: Path) -> int:
        asked.append(directory)
        return 5 * 2**20

    rec = recorder(tmp_path / "run.h5", min_free_bytes=2**30, disk_free=five_mib)
    with pytest.raises(InsufficientSpaceError,
                       match=r"only 5.0 MiB free .* the minimum is 1024.0 MiB") as info:
        rec.open()
    assert asked == [tmp_path]
    assert info.value.errno == errno.ENOSPC and isinstance(info.value, StorageError)
    assert not (tmp_path / "run.h5").exists()


def test_file_system_reporting_no_space_fails_at_once() -> None:
    """The real statvfs path: /proc reports 0 bytes free (and the default minimum is 1 GiB)."""
    if not os.path.isdir("/proc") or os.statvfs("/proc").f_bavail != 0:
        pytest.skip("needs a /proc that reports no free space")
    rec = RunRecorder("/proc/windrig_run.h5", config_text="", rig_name="r")
    with pytest.raises(InsufficientSpaceError, match="only 0.0 MiB free"):
        rec.open()


def test_disk_full_during_create_fails_at_once() -> None:
    """A real ENOSPC from the kernel: /dev/full accepts the open and fails every write.

    This exercises the "try the create" half (the superblock is written and flushed in open());
    ENOSPC in the middle of a run (flush after the disk filled up) is not reproduced here.
    """
    if not os.access("/dev/full", os.W_OK):
        pytest.skip("needs a writable /dev/full")
    rec = RunRecorder("/dev/full", config_text="", rig_name="r", overwrite=True,
                      min_free_bytes=0)
    with pytest.raises(StorageError, match="No space left on device") as info:
        rec.open()
    assert info.value.errno == errno.ENOSPC
    assert Path("/dev/full").is_char_device()  # the half-created "file" was not unlinked
    assert rec.state == "new"


def test_reserve_stops_the_recording_cleanly_before_the_disk_is_full(tmp_path: Path) -> None:
    path = tmp_path / "run.h5"
    free = [10 * 2**30]
    rec = declared(path, reserve_bytes=64 * 2**20, disk_free=lambda directory: free[0])
    rec.start()
    block = raw_block(0, 5, 2)
    rec.append_raw("lasers", block["host_time_ns"], block["device_time"], block["counter"],
                   block["values"])
    rec.flush()
    free[0] = 63 * 2**20
    block = raw_block(5, 5, 2)
    rec.append_raw("lasers", block["host_time_ns"], block["device_time"], block["counter"],
                   block["values"])
    with pytest.raises(InsufficientSpaceError,
                       match=r"only 63.0 MiB left .* below the reserve of 64.0 MiB") as info:
        rec.flush()
    assert info.value.errno == errno.ENOSPC
    assert rec.state == "closed"
    rec.close()
    with h5py.File(path, "r+") as f:  # closed cleanly: a normal file with every row
        np.testing.assert_array_equal(f["entry/instrument/lasers/counter"][:], np.arange(10))


def test_write_failure_mid_run_raises_storage_error(tmp_path: Path) -> None:
    """A real failed write (EFBIG past RLIMIT_FSIZE, in a child process) becomes StorageError.

    The file keeps what was flushed before the failure (read back with SWMR).
    """
    path = tmp_path / "run.h5"
    done = subprocess.run([sys.executable, str(CHILD), "fill", str(path)], capture_output=True,
                          text=True, timeout=30)
    lines = done.stdout.splitlines()
    assert lines and lines[0].startswith("error "), done.stdout + done.stderr
    _, kind, code, state, rows = lines[0].split()
    assert kind == "StorageError" and int(code) == errno.EFBIG and state == "failed"
    assert "File too large; the recording stopped" in lines[1]
    with h5py.File(path, "r", libver="latest", swmr=True) as f:
        counter = f["entry/instrument/lasers/counter"]
        assert counter.shape[0] >= int(rows) > 0
        np.testing.assert_array_equal(counter[: int(rows)], np.arange(int(rows)))


# --------------------------------------------------------------------------------------------------
# Crash and live readers (other processes)
# --------------------------------------------------------------------------------------------------
def test_sigkill_keeps_everything_up_to_the_last_flush(tmp_path: Path) -> None:
    path = tmp_path / "run.h5"
    child = load_child()
    proc = subprocess.Popen([sys.executable, str(CHILD), "write", str(path)],
                            stdout=subprocess.PIPE, text=True)
    reported: list[tuple[int, ...]] = []
    try:
        assert proc.stdout is not None
        while len(reported) < 3:
            line = proc.stdout.readline()
            assert line, f"writer exited early with code {proc.poll()}"
            reported.append(tuple(int(x) for x in line.split()[1:]))
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        assert proc.stdout is not None
        proc.stdout.close()
    assert proc.returncode == -signal.SIGKILL
    raw_rows, sync_rows = reported[-1]
    with h5py.File(path, "r", libver="latest", swmr=True) as f:  # SWMR flag still set
        lasers = f["entry/instrument/lasers"]
        n = min(lasers[name].shape[0] for name in ("host_time_ns", "device_time", "counter",
                                                   "value"))
        assert n >= raw_rows
        expected = child.expected(np.arange(n))
        for name in ("host_time_ns", "device_time", "counter", "value"):
            np.testing.assert_array_equal(lasers[name][:n], expected[name])
    data = read_sync(path)
    assert data["time"].shape[0] >= sync_rows
    expected = child.expected(np.arange(data["time"].shape[0]))
    for name in ("time", "h", "pressure"):
        np.testing.assert_array_equal(data[name], expected[name])


def test_swmr_reader_in_another_process_sees_rows_grow(tmp_path: Path) -> None:
    path = tmp_path / "run.h5"
    rec = declared(path, flush_interval_s=1000.0)  # flushed by hand below
    rec.start()
    blocks, rows = 8, 25
    reader = subprocess.Popen([sys.executable, str(CHILD), "follow", str(path),
                               str(blocks * rows)], stdout=subprocess.PIPE, text=True)
    lines: list[str] = []
    try:
        assert reader.stdout is not None
        assert reader.stdout.readline().strip() == "ready"
        for i in range(blocks):
            block = raw_block(i * rows, rows, 2)
            rec.append_raw("lasers", block["host_time_ns"], block["device_time"],
                           block["counter"], block["values"])
            rec.flush()
            # The next block only once the reader has seen this one: a fixed pause let a reader
            # descheduled on a loaded host skip steps (it prints every size it sees).
            while not (lines and int(lines[-1].split()[1]) >= (i + 1) * rows):
                line = reader.stdout.readline()
                assert line, f"the reader ended early: {lines}"
                lines.append(line)
        out, _ = reader.communicate(timeout=10)
        out = "".join(lines) + out
    finally:
        if reader.poll() is None:
            reader.kill()
            reader.wait()
        rec.close()
    seen = [int(line.split()[1]) for line in out.splitlines()]
    assert reader.returncode == 0, out
    assert seen == sorted(seen) and seen[-1] == blocks * rows
    assert len({n for n in seen if n > 0}) >= 3, f"the reader saw too few steps: {seen}"
