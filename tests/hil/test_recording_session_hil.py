"""One engine, several run files (a campaign's speeds): later files start on settled clocks.

:class:`daq.recording.session.RecordingSession` records files on request under one running
engine; a later file's writer starts from the session's last CLOCK_SETTLE_S of blocks and
trigger pulses. The second file here releases 0.5 s into itself, and its sync view is measured
against the simulator's true clocks from the file's time 0 on: the bound is the one the
single-file alignment test (test_sync_alignment_hil.py) holds only after CLOCK_SETTLE_S.
"""

from __future__ import annotations

import threading
import time

import h5py
import pytest

from daq.config import parse_rig_config
from daq.errors import StorageError
from daq.recording.devices import CLOCK_SETTLE_S
from daq.recording.session import RecordingSession
from daq.sim.rig_process import start_rig_process
from daq.sim.sync_check import ClockTruthTracker, check_run

from support.configs import DRIFTING_CLOCKS, SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

#: Mean misalignment between devices over the second file, from its time 0: the single-file
#: test's bound (test_sync_alignment_hil.py, force and motion within 0.5 ms), which that test
#: holds only after CLOCK_SETTLE_S (unsettled maps are 0.3-0.9 ms off over a file's first
#: seconds). Measured: 0.22-0.33 ms in CI; 0.14-0.37 ms with the whole suite and a busy loop
#: beside on 2 cores. (A CI run once found 0.92 ms: every trigger pulse's round trip had been
#: over the 3 ms the writer requires of an anchor, and no map had an anchor; checked first.)
TARGET_S = 0.5e-3
#: Largest spread right after a refit, s, unless the two least certain maps say they know less
#: (the single-file test's bound). 0.34-0.75 ms measured on a loaded 2-core host.
MAX_SPREAD_S = 1e-3


def _release(acq, decay_s: float = 3.0) -> None:
    acq.arm()
    time.sleep(0.5)  # the hold
    acq.release()
    time.sleep(decay_s)
    acq.arm()


def test_a_later_file_is_aligned_from_its_start(tmp_path):
    config = parse_rig_config(SIM_FLAT_PLATE.read_text() + DRIFTING_CLOCKS,
                              "sim_flat_plate.toml")
    tracker = ClockTruthTracker(settle_s=0.0)  # counted from the second file's time 0
    first, second = tmp_path / "speed01.h5", tmp_path / "speed02.h5"
    with start_rig_process(config) as rig:
        with RecordingSession(rig.config, calz=True) as session:
            done = threading.Event()

            def wind_then_release(acq):
                acq.drivers["fan"].set_speed(700.0)
                acq.drivers["fan"].start()
                time.sleep(session.clock_wait_s())  # the session's one clock settle
                _release(acq)
                done.set()

            reason, _ = session.record(first, actions=wind_then_release, until=done,
                                       duration_s=30.0)
            assert reason == "done"
            assert session.clock_wait_s() == 0.0
            done = threading.Event()

            def release_at_once(acq):
                _release(acq, decay_s=4.0)
                done.set()

            reason, summary = session.record(second, actions=release_at_once, until=done,
                                             duration_s=30.0,
                                             writer_options={"clock_truth": tracker})
            assert reason == "done"
            # An existing file is refused before anything starts, and the session goes on.
            with pytest.raises(StorageError, match="already exists"):
                session.record(second, actions=release_at_once, until=threading.Event(),
                               duration_s=1.0)
        result = check_run(second, tracker, true_time_of=rig.true_time_of,
                           decay_truth=rig.decay_truth, origin_s=rig.origin_s)
    clocks = result["clocks"]
    report = f"clocks {clocks}\nfits {summary['clock_fits']}"
    for name in ("scanner", "laser_front", "laser_rear", "laser_check"):
        # Every device's map has anchors. How many of the pre-roll's pulses join the file's own
        # (9 in 4.5 s) depends on when each map first became ready during the pre-roll: a
        # device trigger seen before then is dropped if the young map places it more than the
        # pairing distance from its pulse (0 to 3 of them measured, CI and development): not
        # a bound to hold. The pre-roll's blocks and pulses themselves are checked below.
        assert summary["clock_fits"][name]["anchors"] >= 1, report
    assert clocks["misalignment_s"] < TARGET_S, report
    uncertain = sorted((fit["anchor_uncertainty_s"] for fit in summary["clock_fits"].values()),
                       reverse=True)
    assert clocks["misalignment_max_s"] < max(MAX_SPREAD_S, uncertain[0] + uncertain[1]), report
    with h5py.File(first, "r") as f:
        assert "calz_scanner_start" in f["entry/metadata"]  # the session's CALZ: first file
        assert f["entry/releases"].shape[0] == 1
    with h5py.File(second, "r") as f:
        assert "calz_scanner_start" not in f["entry/metadata"]
        assert f["entry/releases"].shape[0] == 1
        release_t = float(f["entry/releases"]["release_time"][0])
        assert 0.3 < release_t < 1.5  # released within a second of the file's start
        # The pre-roll's raw samples and pulses precede the file's time 0.
        t0_ns = int(f["entry/sync"].attrs["t0_host_ns"])
        raw_t = (f["entry/instrument/laser_front/host_time_ns"][:] - t0_ns) * 1e-9
        assert raw_t[0] < -0.8 * CLOCK_SETTLE_S
        events = f["entry/events"][:]
        pulses = [float(row["time"]) for row in events if row["kind"] == b"trigger"]
        assert min(pulses) < -0.8 * CLOCK_SETTLE_S
        assert f["entry/sync/time"][0] >= 0.0
