"""Recording a run file from the live operator console (pytest-qt, offscreen).

A live simulated rig (``sim_flat_plate.toml`` with a fast fan ramp, as ``test_console_live.py``)
is recorded from the control panel's recording row while the operator arms and releases the model;
the file is then read back with h5py (the docs/reference/file_format.md layout) and with
:func:`ident.records.run_file.read_run`.
A second rig checks the refusals (each shown by the panel), a disk that fills up during a
recording (the recording stops with its error, the live view goes on) and closing the console
while recording (the file is complete).
"""

from __future__ import annotations

import re
import threading
from typing import Any

import h5py
import numpy as np
import pytest

from daq.config import RigConfig, parse_rig_config
from daq.console.controls import ControlPanel
from daq.console.live_source import LiveSource
from daq.console.window import ConsoleWindow
from daq.errors import RecordingError
from ident.records.run_file import read_run

from support.configs import SIM_FLAT_PLATE, live_config_text
from support.run_files import sync_rows

pytestmark = pytest.mark.realtime

#: Sync rows are placed at exactly t_k = k / rate (computed from k, never accumulated): the
#: grid holds to float64 rounding of values of a few seconds.
GRID_TOL_S = 1e-9


def live_config() -> RigConfig:
    return parse_rig_config(live_config_text(), "sim_flat_plate.toml + fast fan")


def sync_rate_hz(config: RigConfig) -> float:
    return float(config.by_role("scanner")[0].settings["rate_hz"])


def _text(value: Any) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def test_record_a_release_from_the_console_panel(qtbot, tmp_path):
    config = live_config()
    rate = sync_rate_hz(config)
    lasers = [inst.name for inst in config.by_role("lasers")]
    source = LiveSource(config, simulate=True, window_s=10.0, fan_rpm=500.0, record_dir=tmp_path)
    source.open()
    try:
        window = ConsoleWindow(source, window_s=10.0, frame_ms=50, confirm=lambda *_: True)
        qtbot.addWidget(window)
        window.show()
        panel = window.controls
        assert panel is not None
        b = panel.buttons
        assert panel.record_dir == tmp_path  # through the source: ConsoleWindow passes nothing
        assert re.fullmatch(r"run_\d{8}_\d{6}\.h5", panel.file_edit.text())
        assert b["stop_record"].toolTip() == "stop recording: not recording"

        # The simulated PLC starts armed: disarm it behind the panel's back, so that the panel
        # arms it itself (as test_console_controls does).
        qtbot.waitUntil(lambda: panel.armed() is not None, timeout=5_000)
        source.acq.drivers["plc"].disarm()
        qtbot.waitUntil(lambda: panel.armed() is False, timeout=5_000)
        qtbot.waitUntil(lambda: source.fan_speed_rpm > 400.0, timeout=5_000)  # wind on

        notes = "flat plate, 500 rpm: one release"
        panel.file_edit.setText("decay_run.h5")
        panel.run_notes_edit.setText(notes)
        b["record"].click()
        path = tmp_path / "decay_run.h5"
        rec = source.recording
        assert rec is not None and rec.path == path and rec.error is None, panel.status_text
        assert f"recording to {path}" in panel.status_text
        window.tick()
        assert panel.record_label.text().startswith("recording decay_run.h5 (0:00:0")
        assert not b["record"].isEnabled() and b["record"].toolTip() == "record: already recording"
        assert b["stop_record"].isEnabled()

        b["arm"].click()
        qtbot.waitUntil(lambda: panel.busy is None and b["release"].isEnabled(), timeout=5_000)
        b["release"].click()
        qtbot.waitUntil(lambda: panel.busy is None, timeout=5_000)
        assert "release: done" in panel.status_text, panel.status_text
        qtbot.waitUntil(lambda: len(source.decays()) == 1, timeout=5_000)
        t_release = source.decays()[0][0]  # live time (s from the engine's start)
        # Two seconds of free decay synchronised. The sync view trails the release event by the
        # writer's batching plus up to the resampler's 2 s hold, and by however far the simulated
        # instruments fall behind on a loaded host: a CI run once needed over 6 s, so 20 s (the
        # wait ends as soon as the rows are there; only a stalled view uses it all).
        qtbot.waitUntil(lambda: float(source.snapshot(1)["time"][-1]) > t_release + 2.0,
                        timeout=20_000)
        b["arm"].click()  # catch the model: the decay ends
        qtbot.waitUntil(lambda: panel.busy is None and source.decays()[0][1] is not None,
                        timeout=5_000)
        window.tick()
        assert panel.record_label.text() != "not recording"
        rows_before = source.total_rows
        b["stop_record"].click()
        assert source.recording is None
        assert f"recorded {path}" in panel.status_text and "1 release(s)" in panel.status_text
        assert panel.record_label.text() == "not recording"
        assert panel.file_edit.text() != "decay_run.h5"  # a fresh suggestion for the next run
        assert b["record"].isEnabled()
        qtbot.waitUntil(lambda: source.total_rows > rows_before, timeout=5_000)  # still live
        live_release = source.events("release")[0]
        window.close()
    finally:
        source.close()

    with h5py.File(path, "r") as f:
        assert _text(f.attrs["default"]) == "entry"
        entry = f["entry"]
        assert _text(entry.attrs["NX_class"]) == "NXentry" and _text(entry.attrs["default"]) == \
            "sync"
        assert _text(entry.attrs["operator_notes"]) == notes
        assert _text(entry.attrs["rig_name"]) == config.name
        assert _text(entry["config"][()]) == live_config_text()
        assert sorted(entry["instrument"]) == sorted(inst.name for inst in config.instruments)
        sync = entry["sync"]
        assert (_text(sync.attrs["NX_class"]), _text(sync.attrs["signal"]),
                _text(sync.attrs["axes"])) == ("NXdata", "h", "time")
        t = sync["time"][()]
        h, alpha = sync["h"][()], sync["alpha"][()]
        n = t.size
        for name in ("h", "alpha", "lift", "moment", "U", "rho"):
            assert sync[name].shape == (n,), name
        assert sync["pressure"].shape == (n, config.taps.n_taps)
        # Time 0 is the recording's start, on the 2 ms grid of the scanner's 500 Hz.
        assert t[0] == 0.0
        assert np.max(np.abs(np.diff(t) - 1.0 / rate)) < GRID_TOL_S
        # No NaN rows in h and alpha: every laser sample arrived (no gap marked) and the file's
        # writer was given a pre-roll, so the first rows are covered too.
        gaps = {name: int(entry[f"instrument/{name}/gaps"].shape[0]) for name in lasers}
        assert gaps == dict.fromkeys(lasers, 0)
        nan_rows = np.flatnonzero(np.isnan(h) | np.isnan(alpha))
        assert nan_rows.size == 0, f"NaN rows at t = {t[nan_rows[:10]]} of {t[-1]:.2f} s"
        t0_ns = int(sync.attrs["t0_host_ns"])
        assert t0_ns == rec.started_ns

        releases = entry["releases"][()]
        events = entry["events"][()]
        kinds = [_text(k) for k in events["kind"]]
        assert kinds.count("release") == 1 and kinds.count("arm") == 2
        # The recording's own bounds are events of it, and its text log beside it has them.
        # (A system event, a trigger pulse every 0.5 s, may fall just before or after them.)
        actions = [k for k in kinds if k != "trigger"]
        assert actions.count("recording_started") == actions.count("recording_stopped") == 1
        assert actions.index("recording_started") < actions.index("arm")
        assert actions.index("recording_stopped") > len(actions) - 1 - actions[::-1].index("arm")
        log_kinds = [line.split()[2] for line in
                     path.with_suffix(".events.log").read_text().splitlines()[1:]]
        assert log_kinds == actions
        assert releases.shape == (1,)
        row = releases[0]
        release_event_time = float(events["time"][kinds.index("release")])
        # Both are the PLC's acknowledgement of the RELEASE coil less t0, to float64 rounding.
        assert abs(float(row["release_time"]) - release_event_time) < 1e-9
        assert abs(float(row["release_time"]) - (live_release.host_time_ns - t0_ns) * 1e-9) < 1e-9
        start, stop = int(row["start_index"]), int(row["stop_index"])
        # The file reaches past 2 s of decay (the live view saw them before the catch). Arm and
        # release before it take however long the PLC needs: not a fixed 0.5 s.
        assert t[-1] > float(row["release_time"]) + 2.0
        assert t[start - 1] < row["release_time"] <= t[start]  # the first row after the release
        assert (stop - start) / rate > 2.0 - 2.0 / rate  # >= 2 s of decay, less the catch row
        assert np.ptp(h[start:stop]) > 1e-3  # the model moved (held ~4 mm off, then released)
        assert np.isfinite(row["U"]) and row["U"] > 1.0  # the fan runs at 500 rpm

    run = read_run(path)
    assert len(run.releases) == 1
    released = run.releases[0]
    assert 0.0 <= float(released.t[0]) < 1.0 / rate  # time from the release instant
    assert released.U == pytest.approx(float(row["U"]))


def test_recording_refusals_a_full_disk_and_closing_while_recording(qtbot, tmp_path):
    source = LiveSource(live_config(), simulate=True, window_s=10.0, record_dir=tmp_path)
    with pytest.raises(RecordingError, match="acquisition not running"):
        source.start_recording(tmp_path / "early.h5")  # before open(): nothing runs yet
    assert not (tmp_path / "early.h5").exists()
    source.open()
    try:
        panel = ControlPanel(source, confirm=lambda *_: True)
        qtbot.addWidget(panel)
        b = panel.buttons
        # Stop when not recording.
        assert b["record"].isEnabled()
        assert b["stop_record"].toolTip() == "stop recording: not recording"
        panel.stop_record()
        assert "stop recording: not recording" in panel.status_text
        with pytest.raises(RecordingError, match="not recording"):
            source.stop_recording()

        # An existing file is never overwritten.
        existing = tmp_path / "exists.h5"
        existing.write_bytes(b"an earlier run")
        panel.file_edit.setText("exists.h5")
        b["record"].click()
        assert "record failed: StorageError" in panel.status_text
        assert "already exists" in panel.status_text
        assert existing.read_bytes() == b"an earlier run" and source.recording is None

        # A missing directory: refused before anything starts, nothing created.
        missing = tmp_path / "no_such_dir" / "run.h5"
        panel.file_edit.setText(str(missing))
        b["record"].click()
        assert "record failed: StorageError" in panel.status_text
        assert "does not exist" in panel.status_text
        assert not missing.parent.exists() and source.recording is None

        # Double start: the panel disables "record", the source refuses a second file.
        panel.file_edit.setText("first.h5")
        panel.run_notes_edit.setText("first")
        b["record"].click()
        assert source.recording is not None and source.recording.path == tmp_path / "first.h5"
        assert not b["record"].isEnabled()
        assert b["record"].toolTip() == "record: already recording"
        panel.record()
        assert "record: already recording" in panel.status_text
        with pytest.raises(RecordingError, match="already recording"):
            source.start_recording(tmp_path / "second.h5")
        assert not (tmp_path / "second.h5").exists()
        b["stop_record"].click()
        assert "recorded" in panel.status_text and source.recording is None

        # The disk fills up during a recording: that recording stops with its error, the file
        # is closed (complete up to its last flush), the live view goes on. The recorder's
        # free-space seam stands for the file system (a full disk needs root to make).
        full = threading.Event()
        options = {"disk_free": lambda _dir: 0 if full.is_set() else 8 << 30,
                   "flush_interval_s": 0.1, "reserve_bytes": 1 << 20}
        full_path = source.start_recording(tmp_path / "full.h5", "disk fills up",
                                           recorder_options=options)
        # Some rows reach the file first (read as a live SWMR reader would; a loaded host may
        # take longer than a fixed wait).
        qtbot.waitUntil(lambda: sync_rows(full_path) > 0, timeout=8_000)
        full.set()
        qtbot.waitUntil(lambda: source.recording is not None
                        and source.recording.error is not None, timeout=8_000)  # loaded host
        assert "InsufficientSpaceError" in source.recording.error
        rows = source.total_rows
        qtbot.waitUntil(lambda: source.total_rows > rows, timeout=5_000)  # still live
        assert source.running
        panel.refresh()
        assert "FAILED" in panel.record_label.text()
        assert "recording to" in panel.status_text and "failed" in panel.status_text
        assert b["record"].isEnabled()  # a new recording may start
        assert b["stop_record"].toolTip() == "stop recording: not recording"
        with pytest.raises(RecordingError, match="last one failed"):
            source.stop_recording()
        with h5py.File(full_path, "r") as f:
            assert f["entry/sync/time"].shape[0] > 0

        # Closing the console while recording finishes the file first.
        panel.file_edit.setText("closing.h5")
        panel.run_notes_edit.setText("closed while recording")
        b["record"].click()
        assert source.recording is not None and source.recording.error is None
        qtbot.wait(500)
        # At least a quarter second of rows in the file before closing: they reach it as the
        # sync view synchronises them, which lags real time on a loaded host.
        closing_rate = sync_rate_hz(live_config())
        qtbot.waitUntil(lambda: sync_rows(tmp_path / "closing.h5") > 0.25 * closing_rate,
                        timeout=10_000)
        panel.shutdown()
    finally:
        source.close()
    assert source.recording is None
    panel.refresh()
    assert not b["record"].isEnabled()
    assert b["record"].toolTip() == "record: acquisition not running"
    closing = tmp_path / "closing.h5"
    with h5py.File(closing, "r") as f:
        assert _text(f["entry"].attrs["operator_notes"]) == "closed while recording"
        assert _text(f["entry/metadata/acquisition_summary/reason"][()]) == "console closed"
        t = f["entry/sync/time"][()]
        # At least half of the 0.5 s recorded: the file ends where every stream has data.
        assert t.size > 0.25 * sync_rate_hz(live_config()), t.size
        assert not np.isnan(f["entry/sync/h"][()]).any()
    assert read_run(closing).releases == ()


@pytest.mark.parametrize("extra, message", [
    (["--replay", "x.h5", "--record-dir", "."], "not --replay"),
    (["--config", str(SIM_FLAT_PLATE), "--simulate", "--record-dir",
      "no_such_dir_here"], "no such directory"),
], ids=["with-replay", "missing-dir"])
def test_bad_record_dir_gives_one_line_and_exit_code_2(extra, message, capsys):
    from daq.cli import main

    assert main(["gui", *extra]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err
