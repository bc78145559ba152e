"""CALZ of the pressure scanner while the acquisition engine runs (Acquisition.calz).

Real drivers against the simulated flat-plate rig over real TCP on 127.0.0.1; the run file is
written by the real RunWriter (record_run). Nothing of ours is mocked. The simulated scanner's
truth (its zero error, frames sent) is the reference.

Tolerances, all from the simulator's settings (sim_flat_plate.toml, SimScanivalveMps4264
defaults): 500 Hz frames, noise 1 Pa RMS per frame, sensor zero offsets 10 Pa RMS, CALZ 0.2 s.
A mean over the 250 frames of 0.5 s has a noise of 1 / sqrt(250) = 0.063 Pa: 0.5 Pa is 8
sigma, and 20 times below the 10 Pa offsets it must tell apart.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from daq.acquisition.calz import CalzResult
from daq.acquisition.drivers import drivers_from_config
from daq.acquisition.engine import Acquisition
from daq.acquisition.records import Event
from daq.config import RigConfig, parse_rig_config
from daq.errors import CalzError, SafetyError
from daq.recording.run import record_run
from daq.sim.recording import record_simulated_run
from daq.sim.rig import SimulatedRig, start_simulated_rig
from daq.sim.rig_process import start_rig_process
from daq.sim.sync_check import ClockTruthTracker, check_run
from daq.sync.conversions import wind_speed

from support.configs import FAST_FAN, SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

RATE_HZ = 500.0  # the scanner's frame rate in sim_flat_plate.toml
PERIOD_S = 1.0 / RATE_HZ
#: Noise of a 0.5 s mean of one channel is 0.063 Pa (module docstring): 8 sigma.
ZERO_TOL_PA = 0.5


def config(extra: str = "") -> RigConfig:
    text = SIM_FLAT_PLATE.read_text() + extra
    return parse_rig_config(text, "sim_flat_plate.toml")


def test_calz_during_a_recorded_run_rezeroes_and_leaves_a_measured_gap(tmp_path: Path) -> None:
    path = tmp_path / "run.h5"
    seen: dict[str, Any] = {}
    # The simulators in their own process, as real instruments are (in this one, the scanner's
    # frames queue behind the recorder's interpreter lock, 5-30 ms on a loaded host, which the
    # clock check below is not about); their truth is asked of it.
    tracker = ClockTruthTracker()
    with start_rig_process(config()) as rig:

        def actions(acq: Acquisition) -> None:
            time.sleep(1.8)  # the clock maps are usable after ~1.5 s (pipeline.RunWriter)
            seen["zero_before"] = rig.attribute("scanner", "zero_error_pa")
            seen["scan_id_before"] = rig.attribute("scanner", "scan_id")
            # The fan never runs in this run: the wind is off, as the console checks first.
            seen["result"] = acq.calz(wind_speed_now=0.0)
            seen["zero_after"] = rig.attribute("scanner", "zero_error_pa")
            seen["scan_id_after"] = rig.attribute("scanner", "scan_id")

        # calz=False: the scanner starts with its raw sensor offsets (10 Pa RMS), which the
        # CALZ during the run must remove.
        record_run(rig.config, path, duration_s=4.0, actions=actions, progress=False,
                   calz=False, writer_options={"clock_truth": tracker})
        alignment = check_run(path, tracker, true_time_of=rig.true_time_of,
                              decay_truth=rig.decay_truth, origin_s=rig.origin_s)

    result: CalzResult = seen["result"]
    n_taps = 32  # sim_flat_plate.toml: 16 taps per face
    # The simulator's truth: before, the raw offsets; after, zeroed (wind off: exactly 0).
    assert np.sqrt(np.mean(seen["zero_before"][:n_taps] ** 2)) > 3.0  # something to remove
    np.testing.assert_allclose(seen["zero_after"], 0.0, atol=1e-9)
    assert seen["scan_id_after"] == seen["scan_id_before"] + 1  # one new scan, no more
    # The zero the engine measured before STOP is the simulator's zero error, within noise.
    assert result.frames_averaged == 250  # 0.5 s at 500 Hz
    np.testing.assert_allclose(result.offsets_before_pa[:n_taps], seen["zero_before"][:n_taps],
                               atol=ZERO_TOL_PA)
    # CALZ took the simulator's 0.2 s (polled every 0.1 s by the driver); the pause adds STOP,
    # the drain of the frames in flight (50 ms of silence) and SCAN.
    assert 0.2 <= result.calz_s < 0.5
    assert result.calz_s < result.pause_s < result.calz_s + 0.3

    with h5py.File(path, "r") as f:
        raw = f["entry/instrument/scanner"]
        counter = raw["counter"][:]
        t_dev = raw["device_time"][:]
        host_s = raw["host_time_ns"][:] * 1e-9
        value = raw["value"][:]
        gaps = raw["gaps"][:]
        t0_s = int(f["entry/sync"].attrs["t0_host_ns"]) * 1e-9
        sync_t = f["entry/sync/time"][:]
        sync_p = f["entry/sync/pressure"][:]
        sync_lift = f["entry/sync/lift"][:]
        events = f["entry/events"][:]
        calz = {k: v[()] for k, v in f["entry/metadata/calz_scanner_1"].items()}
        assert "calz_scanner_start" not in f["entry/metadata"]  # record_run(calz=False)

    # -- the CALZ's record: when, how long, and the zero it removed per channel ---------------
    assert set(calz) == {"time_s", "pause_s", "calz_s", "wind_speed_now", "frames_averaged",
                         "offsets_before_pa"}
    np.testing.assert_array_equal(calz["offsets_before_pa"], result.offsets_before_pa)
    assert calz["pause_s"] == result.pause_s and calz["frames_averaged"] == 250
    assert calz["time_s"] == pytest.approx((result.stop_ns * 1e-9 - t0_s), abs=1e-3)

    # -- the raw stream: one gap, marked, as long as the pause --------------------------------
    assert gaps.shape == (1,)
    after, length = int(gaps[0]["after_counter"]), int(gaps[0]["length"])
    i = int(np.flatnonzero(counter == after)[0])  # last frame before the pause
    assert np.all(np.diff(counter) >= 1)
    assert counter[i + 1] == after + length + 1  # the counter skips exactly the gap
    assert np.all(np.delete(np.diff(counter), i) == 1)  # and nothing else is missing
    gap_s = t_dev[i + 1] - t_dev[i]  # PTP frame times: the scanner's own clock
    assert length == round(gap_s * RATE_HZ) - 1
    # The scanner stopped while STOP was in flight ([stop_ns, stopped_ns]) and started again
    # while SCAN was ([restart_ns, restarted_ns]); its last frame precedes the stop by less
    # than a period, its first frame is the scan start. 0.5 ms for the rounding of clock reads.
    lo_s = (result.restart_ns - result.stopped_ns) * 1e-9
    hi_s = (result.restarted_ns - result.stop_ns) * 1e-9
    assert lo_s - 5e-4 <= gap_s <= hi_s + PERIOD_S + 5e-4
    assert lo_s <= result.pause_s <= hi_s
    stop_s, restart_s = result.stop_ns * 1e-9, result.restarted_ns * 1e-9
    # The frames in flight at STOP were read before the restart (the drain), none after it.
    assert host_s[i] < result.restart_ns * 1e-9 <= host_s[i + 1]

    # -- re-zeroed: before, the offsets; after, zero within noise ------------------------------
    taps = value[:, :n_taps].astype(np.float64)
    before = taps[max(i - 249, 0):i + 1].mean(axis=0)
    after_mean = taps[i + 1:i + 251].mean(axis=0)
    np.testing.assert_allclose(before, seen["zero_before"][:n_taps], atol=ZERO_TOL_PA)
    np.testing.assert_allclose(after_mean, 0.0, atol=ZERO_TOL_PA)
    assert abs(value[i + 1:, n_taps].mean()) < ZERO_TOL_PA  # the Pitot column (channel 63)

    # -- the sync view: NaN over the pause only, uniform time, finite again soon after --------
    assert np.allclose(np.diff(sync_t), PERIOD_S, rtol=0, atol=1e-9)  # no time step
    bad = ~np.all(np.isfinite(sync_p), axis=1)
    t_stop, t_restart = stop_s - t0_s, restart_s - t0_s
    # Before the pause and from 50 ms after the restart to the end: every row finite. (The
    # first rows after SCAN wait for the first frames and one interpolation interval.)
    late = sync_t > t_restart + 0.05
    assert late.sum() > 0.9 * RATE_HZ and not bad[late].any()
    early = (sync_t < t_stop - 0.02) & (sync_t > 0.5)  # after the start-up of the streams
    assert early.sum() > 0.5 * RATE_HZ and not bad[early].any()
    nan_t = sync_t[bad & (sync_t > 0.5)]
    assert nan_t.size > 0.8 * result.pause_s * RATE_HZ  # the pause is NaN, not bridged
    assert nan_t.min() > t_stop - 0.02 and nan_t.max() < t_restart + 0.05
    assert np.array_equal(np.isnan(sync_lift[sync_t > 0.5]), bad[sync_t > 0.5])

    # The scanner's mapped times agree with the simulator's truth after the pause too (its
    # alignment check counts from 2 s, i.e. mostly after the pause): a restart mapped a frame
    # period (2 ms) or more off would fail. Measured: 0.2 to 0.8 ms.
    assert alignment["clocks"]["clock_error_max_s"]["scanner"] < PERIOD_S, alignment

    # -- the event ---------------------------------------------------------------------------
    kinds = [k.decode() if isinstance(k, bytes) else k for k in events["kind"]]
    (row,) = [e for e, k in zip(events, kinds, strict=True) if k == "calz"]
    text = row["text"].decode() if isinstance(row["text"], bytes) else row["text"]
    data = json.loads(text[text.index("{"):])
    assert abs(row["time"] - t_stop) < 1e-3
    assert data["pause_s"] == pytest.approx(result.pause_s)
    assert data["offset_rms_pa"] == pytest.approx(result.summary()["offset_rms_pa"])
    assert "calz_failed" not in kinds and "fault" not in kinds


def test_without_ptp_the_restarted_clock_is_continued_and_the_sync_view_recovers(
        tmp_path: Path) -> None:
    # PTP absent: frame times restart at 0 with every scan (docs/reference/wire_formats.md,
    # scanner).
    path = tmp_path / "run.h5"
    seen: dict[str, CalzResult] = {}

    def actions(acq: Acquisition, rig: SimulatedRig) -> None:
        time.sleep(1.8)
        seen["result"] = acq.calz(wind_speed_now=0.0)

    record_simulated_run(config("\n[simulation.devices.scanner]\nptp = false\n"), path,
                         duration_s=3.5, actions=actions, progress=False)
    result = seen["result"]
    with h5py.File(path, "r") as f:
        raw = f["entry/instrument/scanner"]
        counter, t_dev, gaps = raw["counter"][:], raw["device_time"][:], raw["gaps"][:]
        t0_s = int(f["entry/sync"].attrs["t0_host_ns"]) * 1e-9
        sync_t, sync_p = f["entry/sync/time"][:], f["entry/sync/pressure"][:]
    # The length is unknown without the device clock: a restart gap (-1), counter continuous.
    assert [(int(g["after_counter"]), int(g["length"])) for g in gaps] == [(gaps[0][0], -1)]
    assert np.all(np.diff(counter) == 1)
    # The new scan's frame times continue the old base with the host-measured pause (from
    # the STOP and SCAN commands): exact but for the last frame's phase before STOP (< 1
    # period) and half the commands' durations (pause bounds), plus 0.5 ms of clock reads.
    i = int(np.flatnonzero(counter == gaps[0]["after_counter"])[0])
    assert np.all(np.diff(t_dev) > 0)
    lo_s = (result.restart_ns - result.stopped_ns) * 1e-9
    hi_s = (result.restarted_ns - result.stop_ns) * 1e-9
    half_width = 0.5 * (hi_s - lo_s)
    assert abs(t_dev[i + 1] - t_dev[i] - result.pause_s) <= half_width + PERIOD_S + 5e-4
    # So the sync view recovers: finite after the pause to the end.
    bad = ~np.all(np.isfinite(sync_p), axis=1)
    t_restart = result.restarted_ns * 1e-9 - t0_s
    late = sync_t > t_restart + 0.05
    assert late.sum() > 0.5 * RATE_HZ and not bad[late].any()
    # The pause is NaN, not bridged. (Where: only as well as the clock map of a relative
    # time base on a 3.5 s run places it, which is not what this test is about.)
    assert bad[sync_t > 0.5].sum() >= 0.8 * result.pause_s * RATE_HZ


# ------------------------------------------------------------------------------------------------
# Engine runs without a file: a subscriber collects what the engine delivers
# ------------------------------------------------------------------------------------------------
class Collector:
    def __init__(self) -> None:
        self.docs: list[tuple[str, Any]] = []
        self.lock = threading.Lock()

    def __call__(self, name: str, doc: Any) -> None:
        with self.lock:
            self.docs.append((name, doc))

    def scanner_blocks(self) -> list[Any]:
        with self.lock:
            return [d for n, d in self.docs if n == "block" and d.device == "scanner"]

    def events(self, kind: str) -> list[Event]:
        with self.lock:
            return [d for n, d in self.docs if n == "event" and d.kind == kind]


@pytest.fixture
def engine(request: pytest.FixtureRequest) -> Iterator[tuple[Acquisition, SimulatedRig,
                                                              Collector]]:
    """Scanner and fan of the simulated rig in a running engine (options via indirect)."""
    extra = getattr(request, "param", "")
    with start_simulated_rig(config(extra)) as rig:
        drivers = drivers_from_config(rig.config)
        sink = Collector()
        acq = Acquisition({name: drivers[name] for name in ("scanner", "fan")},
                          subscribers=[sink])
        with acq:
            yield acq, rig, sink


def frames_after(sink: Collector, t_ns: int) -> int:
    return sum(int(np.count_nonzero(b.host_time_ns > t_ns)) for b in sink.scanner_blocks())




@pytest.mark.parametrize("engine", [FAST_FAN], indirect=True)
def test_calz_with_the_wind_on_is_refused_and_the_scan_goes_on(
        engine: Any, wait_until: Any) -> None:
    acq, rig, sink = engine
    fan = acq.drivers["fan"]
    fan.set_speed(600.0)  # 6 m/s at wind_per_rpm 0.01 of sim_flat_plate.toml
    fan.start()
    wait_until(lambda: rig.tunnel.wind_speed() >= 5.0, "the tunnel at 5 m/s")

    def pitot_wind() -> float:
        """Return the wind speed the Pitot (channel 63) measured over the last 0.1 s of frames."""
        pitot = np.concatenate([b.values["pitot"] for b in sink.scanner_blocks()])[-50:]
        return float(np.mean(wind_speed(pitot, np.full(pitot.size, 1.2)).speed))

    # The frames of the new wind reach the sink through the dispatcher: soon, not at once.
    wait_until(lambda: pitot_wind() > 4.0, "the Pitot reading the wind")
    measured = pitot_wind()
    assert measured > 4.0
    zero_before = rig.simulators["scanner"].zero_error_pa
    scan_id = rig.simulators["scanner"].scan_id
    t_call = time.monotonic_ns()

    with pytest.raises(SafetyError, match="refusing CALZ with wind speed"):
        acq.calz(wind_speed_now=measured)

    # Frames keep coming (counted as they arrive: a loaded host may deliver 0.2 s of frames
    # later than 0.3 s after the call).
    time.sleep(0.3)
    wait_until(lambda: frames_after(sink, t_call) > 0.2 * RATE_HZ, "frames after the refusal")
    # Refused before anything was touched: same scan, same zero, no gap, frames keep coming.
    assert rig.simulators["scanner"].scan_id == scan_id
    assert rig.simulators["scanner"].truth.calz_wind_speeds == []
    np.testing.assert_array_equal(rig.simulators["scanner"].zero_error_pa, zero_before)
    assert frames_after(sink, t_call) > 0.2 * RATE_HZ
    blocks = sink.scanner_blocks()
    assert [b.gaps for b in blocks if b.gaps] == []
    assert np.all(np.diff(np.concatenate([b.counter for b in blocks])) == 1)
    (event,) = sink.events("calz_failed")
    assert event.device == "scanner" and event.data["stage"] == "refused"
    assert event.data["error"] == "SafetyError" and event.data["scan_interrupted"] is False
    assert sink.events("calz") == [] and sink.events("fault") == []


def test_calz_is_refused_when_not_running_and_for_a_device_that_is_no_scanner() -> None:
    with start_simulated_rig(config()) as rig:
        drivers = drivers_from_config(rig.config)
        acq = Acquisition({name: drivers[name] for name in ("scanner", "fan")})
        with pytest.raises(RuntimeError, match="not running"):
            acq.calz(wind_speed_now=0.0)  # before start
        with acq:
            with pytest.raises(ValueError, match="'fan' is not a device of kind 'scanner'"):
                acq.calz("fan", wind_speed_now=0.0)
            with pytest.raises(ValueError, match="'nope' is not a device of kind 'scanner'"):
                acq.calz("nope", wind_speed_now=0.0)
            with pytest.raises(ValueError, match="timeout_s"):
                acq.calz(wind_speed_now=0.0, timeout_s=0.0)
            assert rig.simulators["scanner"].scan_id == 1  # nothing was interrupted
        with pytest.raises(RuntimeError, match="stopped, not running"):
            acq.calz(wind_speed_now=0.0)  # after stop


SLOW_CALZ = "\n[simulation.devices.scanner]\ncalz_duration_s = 0.6\n"


@pytest.mark.parametrize("engine", [SLOW_CALZ], indirect=True)
def test_a_second_calz_while_one_runs_is_refused(engine: Any, wait_until: Any) -> None:
    acq, rig, sink = engine
    sim = rig.simulators["scanner"]
    results: list[CalzResult] = []
    first = threading.Thread(target=lambda: results.append(acq.calz(wind_speed_now=0.0)))
    first.start()
    try:
        # the simulator's side (after the engine's 0.5 s zero average and its STOP)
        wait_until(lambda: sim.state == "CALZ", "the simulator in CALZ")
        assert sim.state == "CALZ"
        with pytest.raises(RuntimeError, match="already in progress"):
            acq.calz(wind_speed_now=0.0)
    finally:
        first.join(15.0)
    assert not first.is_alive()
    assert len(results) == 1 and len(sim.truth.calz_wind_speeds) == 1  # one CALZ, not two
    # events reach subscribers on the dispatcher thread: soon, not with the call's return
    wait_until(lambda: sink.events("calz"), "the calz event")
    assert [e.data["pause_s"] for e in sink.events("calz")] == [results[0].pause_s]


@pytest.mark.parametrize("engine", [SLOW_CALZ], indirect=True)
def test_a_calz_that_times_out_still_restarts_the_scan_and_says_so(
        engine: Any, wait_until: Any) -> None:
    acq, rig, sink = engine
    sim = rig.simulators["scanner"]
    with pytest.raises(CalzError, match=r"failed at calz: .*not finished after 0.1 s; the scan "
                                        r"was restarted"):
        acq.calz(wind_speed_now=0.0, timeout_s=0.1)  # the simulator takes 0.6 s
    t_back = time.monotonic_ns()
    time.sleep(0.3)
    # Data flows again, and the failure's event arrives, through the dispatcher (a loaded host
    # may take longer than 0.3 s to deliver 0.2 s of frames).
    wait_until(lambda: frames_after(sink, t_back) > 0.2 * RATE_HZ and sink.events("calz_failed"),
               "frames and the calz_failed event after the timeout")
    assert sim.state == "SCAN" and sim.scan_id == 2  # restarted once the zero was done
    assert frames_after(sink, t_back) > 0.2 * RATE_HZ  # data flows again
    (event,) = sink.events("calz_failed")
    assert event.data["stage"] == "calz" and event.data["error"] == "DeviceError"
    assert event.data["scan_restarted"] is True and event.data["pause_s"] >= 0.6
    gaps = [g for b in sink.scanner_blocks() for g in b.gaps]
    assert len(gaps) == 1 and gaps[0].length >= 0.6 * RATE_HZ - 2  # the pause, measured
    assert gaps[0].kind == "restart"
    assert sink.events("calz") == []
