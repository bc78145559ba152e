"""Synchronisation against the simulator's truth: device clocks 20 ms off and 50 ppm apart.

The issue's must-show: simulated devices with a 20 ms clock offset and 50 ppm drift, recorded
through the real drivers, clock maps and resampler, the misalignment left in the sync view
measured against the simulators' own clocks and reported in the file. The simulated rig runs in
its own process (:class:`daq.sim.rig_process.RigProcess`), as real instruments do: sharing the
recorder's interpreter lock would add milliseconds of simulated-device latency that no real
instrument has.
"""

from __future__ import annotations

import time

import h5py
import numpy as np
import pytest

from daq.config import parse_rig_config
from daq.recording.devices import CLOCK_SETTLE_S
from daq.recording.run import record_run
from daq.recording.trigger_anchors import MAX_ANCHOR_ROUND_TRIP_S
from daq.sim.rig_process import start_rig_process
from daq.sim.sync_check import ClockTruthTracker, check_run, release_rows
from daq.sync.conversions import heave_pitch_from_lasers

from support.configs import DRIFTING_CLOCKS, SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

#: Mean misalignment between devices over the run after the settling, s: the bound that matters
#: to E2RFC, force and motion within 0.5 ms (0.013 rad of phase at 4 Hz; a fault once left them
#: 2.5 ms apart and E2RFC in turbulence found a flutter speed of 0.05 m/s). Measured: under
#: 0.2 ms on a quiet host; 0.15-0.27 ms with the whole suite running beside on 2 cores, where the
#: anchors' midpoints are off by their round trips' asymmetry.
TARGET_S = 0.5e-3
#: Length of the recorded run, s. The online clock maps settle over a file's first
#: CLOCK_SETTLE_S = 6 s (the README's known limitation: 0.3-0.9 ms common error at 2-6 s on a
#: slow host, 0.1-0.3 ms after). Campaigns release no earlier, and so do this test's actions;
#: the figures are over the run after it (14 s; a real run is 30-120 s).
RUN_S = 20.0



def actions(acq, rig=None):
    fan = acq.drivers["fan"]
    fan.set_speed(700.0)
    fan.start()
    time.sleep(CLOCK_SETTLE_S - 0.5)  # the first release at CLOCK_SETTLE_S, as a campaign's
    for _ in range(2):
        acq.arm()
        time.sleep(0.5)
        acq.release()
        time.sleep(3.0)
    acq.arm()


# Grid turbulence (issue 16's vertical 1 %): the tunnel computes the buffeting for every block
# the simulated instruments sample. Each block once cost ~12 ms (the gust field interpolated
# over its whole period): the instruments starved each other in the rig's process and their
# clocks were mapped 1-2 ms off, opposite ways for scanner and lasers (force against motion
# 2.5 ms apart, E2RFC in turbulence then found a flutter speed of 0.05 m/s).
TURBULENCE = """
[simulation.static]
C_D = 0.02
C_L = 0.0
C_M = 0.0
dC_D = 0.0
dC_L = -6.283
dC_M = 1.571
[simulation.turbulence]
Iu = 0.0
Iw = 0.01
Lux = 1.0
Lwx = 0.3
span = 1.0
seed = 1
"""


@pytest.mark.parametrize("flow", ["smooth", "turbulent"])
def test_sync_view_is_aligned_to_the_truth(tmp_path, flow):
    text = SIM_FLAT_PLATE.read_text() + DRIFTING_CLOCKS
    config = parse_rig_config(text + (TURBULENCE if flow == "turbulent" else ""),
                              "sim_flat_plate.toml")
    path = tmp_path / "aligned.h5"
    tracker = ClockTruthTracker(settle_s=CLOCK_SETTLE_S)
    with start_rig_process(config) as rig:
        # record_run pulses the PLC's trigger line every 0.5 s: the clock maps' anchors.
        summary = record_run(rig.config, path, duration_s=RUN_S, calz=True,
                             actions=actions, progress=False,
                             writer_options={"clock_truth": tracker})
        result = check_run(path, tracker, true_time_of=rig.true_time_of,
                           decay_truth=rig.decay_truth, origin_s=rig.origin_s)
    clocks, signals = result["clocks"], result["signals"]
    report = (f"clocks {clocks}\nsignals {signals}\nfits {summary['clock_fits']}\n"
              f"timelines {summary['timelines']}")
    with h5py.File(path, "r") as f:
        attrs = dict(f["entry/sync"].attrs)
    # Reported in the file.
    assert attrs["truth_misalignment_s"] == clocks["misalignment_s"]
    assert attrs["truth_misalignment_max_s"] == clocks["misalignment_max_s"]
    for name in ("scanner", "laser_front", "laser_rear", "laser_check"):
        assert attrs[f"truth_clock_error_mean_s__{name}"] == clocks["clock_error_mean_s"][name]
        assert summary["clock_fits"][name]["anchors"] >= 2, report
    # The 40 ms and 100 ppm between devices are undone: the samples of one instant land in the
    # sync view within TARGET_S of each other on average over the run after the settling. In
    # turbulence each release's decay takes ~150 ms of the rig process's time to compute (~40 ms
    # in smooth flow), and the instruments' streams stall meanwhile (0.17-0.21 ms measured, 0.21
    # with a campaign running beside it).
    assert clocks["misalignment_s"] < TARGET_S, report
    # The largest spread: within 1 ms, or within what the two least certain maps say they know
    # (each device's clock error is bounded by its anchors' uncertainty, below, so two devices
    # can be that far apart): a slow CI host's round trips left the scanner's anchors uncertain
    # by 1.04 ms and the spread in turbulence at 1.17 ms once.
    uncertain = sorted((fit["anchor_uncertainty_s"] for fit in summary["clock_fits"].values()),
                       reverse=True)
    assert clocks["misalignment_max_s"] < max(1e-3, uncertain[0] + uncertain[1]), report
    # Against the host's true time, each device is off by the anchors' error: the PLC pulse's
    # host time is the midpoint of a Modbus round trip (up to MAX_ANCHOR_ROUND_TRIP_S), and the
    # floor comes from the anchors of the shortest round trips. Within 0.5 ms, or within what
    # the map says it knows when a loaded host slowed every round trip (anchor_uncertainty_s:
    # half the longest round trip of those anchors; on the slow CI host the shortest were
    # 0.6-2 ms and the errors -0.1 to -0.7 ms).
    for name, err in clocks["clock_error_mean_s"].items():
        known = summary["clock_fits"][name]["anchor_uncertainty_s"]
        assert 0.0 < known <= 0.5 * MAX_ANCHOR_ROUND_TRIP_S, report
        assert abs(err) < max(0.5e-3, known), report
    # End to end on the signals, against the tunnel's decays: h and alpha are weighted means of
    # the lasers, so each is late by at most the lasers' largest clock error (the tracker's
    # truth over the whole run, or what the map says it knows), plus what the lasers' differing
    # errors leak of the other motion into it (CI once: laser errors up to 0.79 ms and 0.23 ms
    # apart, pitch's delay -0.53 ms against heave's -0.39 ms). h and alpha are known to 1-30 us
    # (the fit's residual includes the clock error's slow wander, not only noise); lift and
    # moment (62 taps, 1 Pa noise) only to ~0.25 ms: checked at 4 sigma.
    known = {name: max(0.5e-3, fit["anchor_uncertainty_s"])
             for name, fit in summary["clock_fits"].items()}
    lasers = [laser.name for laser in config.heave_pitch_lasers]
    latest = max(max(known[name], clocks["clock_error_max_s"][name]) for name in lasers)
    leak = cross_motion_leak_s(config, clocks["misalignment_max_s"], path)
    for name in ("h", "alpha"):
        bound = latest + leak[name] + 4 * signals["delay_std_s"][name]
        assert abs(signals["delay_s"][name]) < bound, f"{report}\nleak {leak}"
        assert signals["delay_std_s"][name] < 50e-6, report
    for name in ("lift", "moment"):
        latest = max(known["scanner"], clocks["clock_error_max_s"]["scanner"])
        bound = latest + 4 * signals["delay_std_s"][name]
        assert abs(signals["delay_s"][name]) < bound, report
    assert np.isfinite(attrs["truth_delay_s__h"])


def cross_motion_leak_s(config, spread_s, path):
    """Largest apparent delay that the lasers' differing clock errors add to h and alpha, s.

    With lasers at chord positions ``x_i`` and least-squares weights ``W`` (``h = W[0] z``,
    ``alpha = W[1] z``), lasers late by ``e_i`` give ``h`` a term ``-(W[0] (x e)) alpha'`` and
    ``alpha`` a term ``-(W[1] e) h'``. Both weight rows sum to zero against what they leak,
    so the coefficient is at most ``sum |W| * spread / 2`` for errors within ``spread`` of each
    other; regressed on the channel's own rate, the term is at most its rms over the channel's
    rms (Cauchy-Schwarz), taken from the recorded motion over the releases.
    """
    x = np.array([float(laser.settings["x"]) for laser in config.heave_pitch_lasers])
    # The weights are what the recorder's own solution makes of each laser alone.
    unit = heave_pitch_from_lasers(np.eye(x.size), x, 0.0)
    weights = np.vstack([unit.h, unit.alpha])
    with h5py.File(path, "r") as f:
        sync = {k: f["entry/sync"][k][:] for k in ("time", "h", "alpha")}
        rows = release_rows(sync["time"], f["entry/releases"][:])
    rms = {k: float(np.sqrt(np.nanmean(np.gradient(sync[k][rows], sync["time"][rows])**2)))
           for k in ("h", "alpha")}
    half = 0.5 * float(spread_s)
    return {"h": float(np.abs(weights[0] * x).sum()) * half * rms["alpha"] / rms["h"],
            "alpha": float(np.abs(weights[1]).sum()) * half * rms["h"] / rms["alpha"]}


def test_rig_process_reports_errors_of_its_child():
    config = parse_rig_config(SIM_FLAT_PLATE.read_text() + DRIFTING_CLOCKS,
                              "sim_flat_plate.toml")
    with start_rig_process(config) as rig:
        assert sorted(rig.clocked_devices()) == ["laser_check", "laser_front", "laser_rear",
                                                 "scanner"]
        with pytest.raises(RuntimeError, match="KeyError"):
            rig.true_time_of("no_such_device", [0.0])
        # The tunnel holds no decay yet: NaN everywhere, not zeros.
        truth = rig.decay_truth(np.array([0.0, 1.0]))
        assert np.all(np.isnan(truth["h"]))
