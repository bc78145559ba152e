"""The operator console on a replayed run file (pytest-qt, offscreen).

The run file is written by the real recorder (:class:`daq.recording.recorder.RunRecorder`, the
layout of docs/reference/file_format.md) with synthetic rows whose values are known: h a 2 Hz
sinusoid, alpha 3.3 Hz, a slowly rising wind, tap pressures of a fixed Cp distribution scaled by qd.
"""

from __future__ import annotations

import os
import struct
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.cli import main
from daq.config import parse_rig_config
from daq.console import replay
from daq.console.display import amplitude_spectrum, pressure_coefficients
from daq.console.replay import ReplaySource
from daq.console.ring_buffer import RingBuffer
from daq.console.source import sync_columns
from daq.console.window import ConsoleWindow, peak_decimate
from daq.errors import ReplayError
from daq.recording.recorder import RunRecorder

from support.clocks import ManualClock
from support.configs import SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

RATE_HZ = 100.0
DURATION_S = 30.0
F_H = 2.0      # heave frequency, Hz
F_A = 3.3      # pitch frequency, Hz
RHO = 1.18     # kg/m^3


def wind(t: np.ndarray) -> np.ndarray:
    return 8.0 + 0.05 * t


@pytest.fixture(scope="module")
def run_file(tmp_path_factory) -> Path:
    config = parse_rig_config(SIM_FLAT_PLATE.read_text(),
                              "sim_flat_plate.toml")
    n_taps = config.taps.n_taps
    path = tmp_path_factory.mktemp("console") / "run.h5"
    rec = RunRecorder(path, config_text=config.text, rig_name=config.name, min_free_bytes=0,
                      reserve_bytes=0)
    rec.open()
    rec.add_sync([f"tap{i:03d}" for i in range(n_taps)])
    rec.start()
    t = np.arange(int(DURATION_S * RATE_HZ)) / RATE_HZ
    cp_true = np.linspace(-1.5, 0.8, n_taps)
    for block in np.array_split(np.arange(t.size), 12):
        tb = t[block]
        U = wind(tb)
        qd = 0.5 * RHO * U**2
        rec.append_sync(tb, h=0.004 * np.sin(2 * np.pi * F_H * tb),
                        alpha=0.01 * np.sin(2 * np.pi * F_A * tb),
                        lift=5.0 * np.cos(2 * np.pi * F_H * tb),
                        moment=0.2 * np.cos(2 * np.pi * F_A * tb),
                        pressure=qd[:, None] * cp_true[None, :] * (1 + 0.1 * np.sin(tb))[:, None],
                        U=U, rho=np.full(tb.size, RHO))
    rec.add_event(1.0, "operator", "synthetic run")
    rec.close()
    return path


def read_file(path: Path) -> dict[str, np.ndarray]:
    with h5py.File(path, "r") as f:
        return {name: f[f"entry/sync/{name}"][()] for name in
                ("time", "h", "alpha", "pressure", "U", "rho")}


@pytest.fixture
def make_window(qtbot):
    """Build console windows that pytest-qt closes after the test."""

    def make(source, **kwargs):
        window = ConsoleWindow(source, **kwargs)
        qtbot.addWidget(window)
        return window

    return make


@pytest.fixture
def played(qtbot, run_file, make_window):
    """Return a window over a replay on a fake clock: 25 s of the run played, one redraw."""
    clock = ManualClock()
    source = ReplaySource(run_file, speed=1.0, window_s=20.0, clock=clock)
    source.open()
    window = make_window(source, window_s=20.0, frame_ms=10_000_000)  # redraw by hand only
    window.tick()  # starts the playback clock
    clock.now += 25.0
    window.tick()
    return window


# -- the data source ---------------------------------------------------------------------------

def test_replay_plays_at_its_speed_with_ring_buffer_snapshots(run_file, monkeypatch):
    # The ring keeps the window, or MIN_HISTORY_S (a whole decay) if that is longer.
    monkeypatch.setattr(replay, "MIN_HISTORY_S", 2.0)
    clock = ManualClock()
    with ReplaySource(run_file, speed=4.0, window_s=5.0, clock=clock) as source:
        assert source.info.rate_hz == pytest.approx(RATE_HZ)
        assert source.info.duration_s == pytest.approx(DURATION_S - 1 / RATE_HZ)
        assert source.poll() == 1  # the first row, at t = 0
        clock.now += 1.5  # 6 s of run at 4x
        source.poll()
        snap = source.snapshot()
        ring = RingBuffer(3, *sync_columns(source.info.config.taps.n_taps))
        expected = ring.snapshot()
        assert list(snap) == list(expected)  # same names and order as the live ring buffer
        assert {k: (v.dtype, v.shape[1:]) for k, v in snap.items()} == \
            {k: (v.dtype, v.shape[1:]) for k, v in expected.items()}
        assert snap["time"][-1] == pytest.approx(6.0)
        assert snap["time"][0] >= 6.0 - 5.0 - 0.03  # only the window is kept
        clock.now += 100.0
        source.poll()
        assert source.finished and "end of file" in source.status()


# -- the window --------------------------------------------------------------------------------

def test_window_opens_and_its_traces_move_as_the_replay_advances(qtbot, run_file,
                                                                  make_window):
    source = ReplaySource(run_file, speed=10.0, window_s=20.0)
    source.open()
    window = make_window(source, window_s=20.0, frame_ms=20)
    window.show()
    curve = window.curves["h"]
    qtbot.waitUntil(lambda: curve.xData is not None and curve.xData.size > 0, timeout=3000)
    first_end = float(curve.xData[-1])
    qtbot.waitUntil(lambda: float(curve.xData[-1]) > first_end, timeout=3000)
    assert "replay run.h5" in window.status_text


def test_the_traces_show_exactly_the_rows_h5py_reads_for_the_same_time_span(played, run_file):
    data = read_file(run_file)
    x, y = played.curves["h"].xData, played.curves["h"].yData
    assert x[-1] == pytest.approx(25.0, abs=1 / RATE_HZ)
    assert x[-1] - x[0] == pytest.approx(20.0, abs=1 / RATE_HZ)  # the scrolling window
    span = (data["time"] >= x[0]) & (data["time"] <= x[-1])
    # Times are the file's float64 values copied unchanged: equal bit for bit. h is shown in mm,
    # one multiplication by 1e3 in float64: equal to the file's h * 1e3 within 1 ulp.
    np.testing.assert_array_equal(x, data["time"][span])
    np.testing.assert_allclose(y, data["h"][span] * 1e3, rtol=1e-15, atol=0)
    alpha = played.curves["alpha"].yData
    np.testing.assert_allclose(alpha, np.degrees(data["alpha"][span]), rtol=1e-14, atol=0)


def test_cp_of_the_latest_row_is_its_pressure_over_qd(played, run_file):
    data = read_file(run_file)
    row = int(np.flatnonzero(data["time"] == played.cp_time)[0])
    qd = 0.5 * data["rho"][row] * data["U"][row] ** 2
    # Pressures are stored as float32 in the file and in the window's buffer; both sides divide
    # the same float32 values (as float64) by qd computed in float64: a few ulp apart at most.
    np.testing.assert_allclose(played.cp_curve.yData,
                               data["pressure"][row].astype(np.float64) / qd, rtol=1e-12)
    assert played.cp_curve.xData.size == data["pressure"].shape[1]


def test_spectrum_peak_of_a_2_hz_heave_is_at_2_hz_within_one_bin(played):
    freq, amp = played.spectrum_curves["h"].xData, played.spectrum_curves["h"].yData
    resolution = freq[1] - freq[0]  # 1 / (20 s) for the 20 s window
    assert resolution == pytest.approx(1 / 20.0, rel=0.01)
    assert abs(freq[np.argmax(amp)] - F_H) <= resolution
    assert amp.max() == pytest.approx(4.0, rel=0.1)  # 4 mm amplitude
    f_a, a_a = played.spectrum_curves["alpha"].xData, played.spectrum_curves["alpha"].yData
    assert abs(f_a[np.argmax(a_a)] - F_A) <= resolution


def test_display_numbers():
    assert np.isnan(pressure_coefficients([1.0, 2.0], U=0.0, rho=1.2)).all()  # wind off
    t = np.arange(1000) / 100.0
    f, a = amplitude_spectrum(t, np.sin(2 * np.pi * 2.0 * t))
    assert f[np.argmax(a)] == pytest.approx(2.0)
    assert amplitude_spectrum(t[:2], t[:2])[0].size == 0


# -- the command line --------------------------------------------------------------------------

def test_cli_screenshot_writes_a_png_of_the_window_size(run_file, tmp_path):
    out = tmp_path / "console.png"
    env = {k: v for k, v in os.environ.items()
           if k not in ("QT_QPA_PLATFORM", "DISPLAY", "WAYLAND_DISPLAY")}  # it must set it
    proc = subprocess.run(
        [sys.executable, "-m", "daq.cli", "gui", "--replay", str(run_file), "--speed", "20",
         "--screenshot", str(out), "--after", "0.5", "--size", "800", "600"],
        capture_output=True, text=True, env=env, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "wrote" in proc.stdout
    png = out.read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", png[16:24])  # the IHDR chunk
    assert (width, height) == (800, 600)
    assert len(png) > 10_000  # drawn, not blank


def _truncated(run_file: Path, tmp_path: Path) -> Path:
    path = tmp_path / "truncated.h5"
    data = run_file.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path


def _not_a_run(run_file: Path, tmp_path: Path) -> Path:
    path = tmp_path / "other.h5"
    with h5py.File(path, "w") as f:
        f["x"] = np.arange(3)
    return path


@pytest.mark.parametrize("make, message", [
    (lambda run, tmp: tmp / "missing.h5", "no such file"),
    (lambda run, tmp: (tmp / "notes.h5").write_text("not hdf5") and tmp / "notes.h5",
     "cannot be opened as an HDF5 run file"),
    (_truncated, "HDF5"),
    (_not_a_run, "not a windrig run file"),
], ids=["missing", "not-hdf5", "truncated", "not-a-run"])
def test_bad_replay_files_give_one_line_and_exit_code_2(make, message, run_file, tmp_path,
                                                        capsys):
    path = make(run_file, tmp_path)
    assert main(["gui", "--replay", str(path), "--screenshot", str(tmp_path / "x.png"),
                 "--after", "0"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err and "Traceback" not in err
    assert not (tmp_path / "x.png").exists()
    with pytest.raises(ReplayError):
        ReplaySource(path).open()


def test_gui_without_a_source_is_refused_clearly(capsys):
    assert main(["gui"]) == 2
    assert "give --replay FILE.h5, or --config CONFIG.toml" in capsys.readouterr().err


def test_the_refcount_guard_keeps_true_alive_through_many_signal_emissions(qapp):
    from PySide6 import QtCore

    from daq.console.qt_guard import guard_bool_refcounts

    class Emitter(QtCore.QObject):
        changed = QtCore.Signal(object)

    emitter = Emitter()
    emitter.changed.connect(lambda value: None)
    active = guard_bool_refcounts()
    for _ in range(5000):  # more than True's natural refcount: aborted the process unguarded
        emitter.changed.emit(1)
    if active:
        assert min(sys.getrefcount(True), sys.getrefcount(None)) > (1 << 39)


def test_peak_decimation_keeps_peaks_gaps_and_the_newest_samples():
    t = np.arange(10_000) / 500.0
    y = np.sin(2 * np.pi * 2.0 * t)
    y[4321] = 5.0  # one spike of one sample
    y[7000:7010] = np.nan  # a gap
    td, yd = peak_decimate(t, y, 1000)
    assert td.size == yd.size == 2000
    assert np.nanmax(yd) == 5.0 and np.nanmin(yd) == pytest.approx(-1.0, abs=1e-3)
    gap = (td >= t[7000] - 0.02) & (td <= t[7009] + 0.02)
    assert np.isnan(yd[gap]).any() and np.isfinite(yd[~gap]).all()
    assert td[-1] == t[-1] and np.all(np.diff(td) >= 0)  # newest kept, time order
    short_t, short_y = peak_decimate(t[:2000], y[:2000], 1000)
    assert np.array_equal(short_t, t[:2000]) and np.array_equal(short_y, y[:2000])  # as given
