"""The live console's acquisition in its own process (``daq.console.process_source``).

Real processes throughout: a :class:`~daq.console.shared_ring.SharedRingBuffer` appended by a
spawned child and read here; a :class:`~daq.console.process_source.ProcessLiveSource` over the
simulated rig (the acquisition in a child process, the simulators in its child) drawn by the console
window, its commands crossing the pipe (allowed, refused, failing with the driver's own error), a
recording made through it, the child killed under it, and a rig that does not start.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import signal
import sys
import threading
import time
from multiprocessing.shared_memory import SharedMemory
from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.config import parse_rig_config
from daq.console.process_source import ProcessLiveSource, _portable
from daq.console.ring_buffer import Column
from daq.console.shared_ring import SharedRingBuffer
from daq.console.window import ConsoleWindow
from daq.errors import (
    AcquisitionProcessError,
    ConfigError,
    RemoteError,
    RingStalledError,
    SafetyError,
)

# The shared-ring test's child imports its target by module name: a top-level one.
sys.path.insert(0, str(Path(__file__).resolve().parent))
from _ring_child import BLOCK, ROWS, append_rows  # noqa: E402

from support.configs import FAST_FAN, SIM_FLAT_PLATE  # noqa: E402
from support.run_files import sync_rows  # noqa: E402

pytestmark = pytest.mark.realtime


def live_config():
    return parse_rig_config(SIM_FLAT_PLATE.read_text() + FAST_FAN,
                            "sim_flat_plate.toml + fast fan")


def test_a_shared_ring_appended_by_another_process_reads_whole_appends_here():
    ring = SharedRingBuffer(1000, "t", Column("p", np.float32, (2,)))
    name = ring.handle().name
    child = multiprocessing.get_context("spawn").Process(target=append_rows,
                                                         args=(ring.handle(),))
    child.start()
    try:
        seen = 0
        while child.is_alive() or seen < ROWS:
            snap = ring.snapshot()
            t, p = snap["t"], snap["p"]
            # Every snapshot is whole appends, oldest first, both columns the same rows.
            assert t.size == p.shape[0] and t.size % BLOCK == 0
            if t.size:
                assert np.array_equal(np.diff(t), np.ones(t.size - 1))
                assert np.array_equal(p[:, 0], t) and np.array_equal(p[:, 1], -t)
                assert int(t[-1]) + 1 <= ring.total_rows
            seen = ring.total_rows
            if not child.is_alive() and seen < ROWS:
                break
        child.join(30.0)
        assert child.exitcode == 0
        assert ring.total_rows == ROWS
        assert ring.snapshot()["t"].tolist() == list(range(ROWS - 1000, ROWS))
    finally:
        ring.close()
        ring.unlink()
    with pytest.raises(FileNotFoundError):
        SharedMemory(name=name)


def test_only_the_owner_removes_a_shared_ring():
    ring = SharedRingBuffer(4, "t")
    other = SharedRingBuffer.attach(ring.handle())
    try:
        with pytest.raises(RuntimeError, match="only the process that created"):
            other.unlink()
    finally:
        other.close()
        ring.close()
        ring.unlink()


class _Unpicklable(Exception):
    """An error that holds what no pickle can carry (a lock: think of an open socket).

    Not merely a constructor pickling cannot replay: once ``dask.distributed`` is imported
    (another test may do it), tblib makes such exceptions pickle by their ``__dict__``.
    """

    def __init__(self, code: int, where: str) -> None:
        super().__init__(f"code {code} at {where}")
        self.lock = threading.Lock()


def test_an_exception_that_cannot_cross_becomes_a_remote_error_naming_it():
    sent = _portable(_Unpicklable(3, "scanner"))
    assert isinstance(sent, RemoteError)
    assert str(sent) == "_Unpicklable: code 3 at scanner"
    refused = SafetyError("fan speed above the limit")
    assert _portable(refused) is refused


def test_the_console_over_an_acquisition_process_draws_acts_refuses_and_records(qtbot, tmp_path):
    config = live_config()
    source = ProcessLiveSource(config, simulate=True, window_s=10.0, fan_rpm=500.0)
    source.open()
    ring_name = source._ring.handle().name
    process = source._process
    try:
        window = ConsoleWindow(source, window_s=10.0, frame_ms=50)
        qtbot.addWidget(window)
        window.show()
        assert window.controls is not None and window.health_table is not None
        # The traces move: rows synchronised in the child reach this process's window.
        curve = window.curves["h"]
        qtbot.waitUntil(lambda: curve.xData is not None and curve.xData.size > 0, timeout=10_000)
        end = float(curve.xData[-1])
        qtbot.waitUntil(lambda: float(curve.xData[-1]) > end + 0.5, timeout=5_000)
        names = sorted(inst.name for inst in config.instruments)
        qtbot.waitUntil(lambda: sorted(h.device for h in source.health()) == names
                        and all(h.rate_hz > 0 for h in source.health()), timeout=8_000)
        # The alarm line is redrawn every few frames, from the state of that frame: it follows
        # the health above soon, not at once (a device slow to start on a loaded host may still
        # have shown "no data yet" in the last redraw).
        qtbot.waitUntil(lambda: window.alarm_label.text() == "all devices OK", timeout=5_000)
        qtbot.waitUntil(lambda: source.fan_speed_rpm > 100.0, timeout=5_000)
        assert source.status().startswith(f"live {config.name}: running")

        # Allowed commands cross and come back; the driver's own refusal keeps its type.
        acq = source.acq
        assert sorted(acq.drivers) == names
        with pytest.raises(SafetyError, match="max_fan_rpm"):
            acq.drivers["fan"].set_speed(config.limits.max_fan_rpm + 100.0)
        note = acq.mark("note", "through the pipe")
        assert note.kind == "note" and note.text == "through the pipe"
        # Only the listed commands exist: here, and in the child if asked directly.
        with pytest.raises(AttributeError, match="cannot be called from the console"):
            acq.drivers["fan"].write_register  # noqa: B018 - the refusal is the point
        with pytest.raises(AttributeError):
            acq.drivers["scanner"].calz  # noqa: B018
        with pytest.raises(PermissionError, match="not allowed"):
            source.call("driver", "fan", "write_register", 0, 1)
        with pytest.raises(PermissionError, match="not allowed"):
            source.call("engine", "stop", "from the console")
        with pytest.raises(KeyError, match="no device 'tower'"):
            source.call("driver", "tower", "stop")

        # A recording made through the child: the file is complete and has the marker.
        path = source.start_recording(tmp_path / "run.h5", "process test")
        assert source.recording is not None and source.recording.path == path
        acq.mark("note", "while recording")
        qtbot.wait(1500)
        # The rows reach the file as the child synchronises them, which lags real time on a
        # loaded host: wait until a reader of the file sees them, not a fixed 1.5 s only.
        qtbot.waitUntil(lambda: sync_rows(path) > 400, timeout=15_000)
        summary = source.stop_recording()
        assert summary["sync_rows"] > 400 and source.recording is None
        with h5py.File(path, "r") as f:
            assert f["/entry"].attrs["operator_notes"] == "process test"
            t = f["/entry/sync/time"][:]
            assert t.size == summary["sync_rows"] and np.all(np.diff(t) > 0)
            texts = [x.decode() if isinstance(x, bytes) else str(x)
                     for x in f["/entry/events"][()]["text"]]
            assert "while recording" in texts

        window.close()  # closes the source: the child stops everything and exits
        assert not source.running
        assert not process.is_alive() and process.exitcode == 0
    finally:
        source.close()
    with pytest.raises(FileNotFoundError):
        SharedMemory(name=ring_name)




def _children(pid: int) -> list[int]:
    try:
        return [int(p) for p in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def test_a_ring_lock_its_writer_never_releases_stalls_a_reader_only_briefly():
    """A writer killed holding the ring's lock must not block the GUI forever (it did once).

    The lock is taken here and never released, as by a writer killed mid-append: a read gives
    up after LOCK_TIMEOUT_S with RingStalledError; once the writer is known gone the ring is
    read unlocked, its rows as they were.
    """
    from daq.console.shared_ring import LOCK_TIMEOUT_S

    ring = SharedRingBuffer(16, "t")
    try:
        ring.append({"t": np.arange(5.0)})
        assert ring._lock.lock.acquire(timeout=1.0)  # the "dead writer" holds it from now on
        start = time.monotonic()
        with pytest.raises(RingStalledError, match="not released within 0.5 s"):
            _ = ring.total_rows
        # The semaphore's deadline is on the wall clock, which may run a little against the
        # monotonic one (a CI run measured 0.4978 s): 20 ms under the timeout is still it.
        assert LOCK_TIMEOUT_S - 0.02 <= time.monotonic() - start < LOCK_TIMEOUT_S + 2.0
        ring.abandon_lock()
        assert ring.total_rows == 5
        np.testing.assert_array_equal(ring.snapshot()["t"], np.arange(5.0))
    finally:
        ring.close()
        ring.unlink()


def test_an_acquisition_process_that_dies_is_shown_and_refused(qtbot):
    source = ProcessLiveSource(live_config(), simulate=True, window_s=10.0)
    source.open()
    try:
        window = ConsoleWindow(source, window_s=10.0, frame_ms=50)
        qtbot.addWidget(window)
        qtbot.waitUntil(lambda: source.total_rows > 0, timeout=10_000)
        rig = _children(source._process.pid)
        assert len(rig) == 1  # the simulated rig's process
        os.kill(source._process.pid, signal.SIGKILL)
        qtbot.waitUntil(lambda: source.error is not None, timeout=5_000)
        assert "acquisition process ended" in source.error and "exit code -9" in source.error
        assert not source.running
        qtbot.waitUntil(lambda: window.status_text.startswith("error: acquisition process "
                                                              "ended"), timeout=5_000)
        with pytest.raises(AcquisitionProcessError, match="not running"):
            source.acq.arm()
        window.controls.refresh()
        assert not window.controls.buttons["arm"].isEnabled()
        assert window.controls.buttons["arm"].toolTip() == "arm: acquisition not running"
        rows = source.total_rows
        qtbot.wait(300)
        assert source.total_rows == rows  # nothing appends any more; nothing invented
        # The rig's process sees its parent gone (its pipe closes) and stops too.
        deadline = time.monotonic() + 15.0
        while Path(f"/proc/{rig[0]}").exists() and time.monotonic() < deadline:
            try:
                os.waitpid(rig[0], os.WNOHANG)
            except ChildProcessError:
                pass  # not our child: init reaps it
            time.sleep(0.1)
        state = Path(f"/proc/{rig[0]}/stat")
        assert not state.exists() or state.read_text().split()[2] == "Z"
        window.close()
    finally:
        source.close()


def test_a_rig_that_does_not_start_raises_its_own_error_and_leaves_nothing():
    source = ProcessLiveSource(live_config(), simulate=False, window_s=10.0)
    with pytest.raises(ConfigError, match="url = 'auto'"):
        source.open()
    assert source._process is not None and not source._process.is_alive()
    assert source._ring is None  # removed
    assert source.acq is None and not source.running
    source.close()  # idempotent


def test_bad_options_are_refused_before_a_process_starts():
    with pytest.raises(ValueError, match="window_s"):
        ProcessLiveSource(live_config(), window_s=math.nan)
    with pytest.raises(ValueError, match="fan_rpm"):
        ProcessLiveSource(live_config(), fan_rpm=-5.0)
