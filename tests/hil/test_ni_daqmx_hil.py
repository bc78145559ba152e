"""The simulated rig with its lasers (and a Pitot) read through NI-DAQmx, into a run file.

The DAQ is a simulated device behind the stand-in of the nidaqmx API (the NI runtime cannot be
installed here); everything else is the production path: the drivers, the engine, the run
writer, an HDF5 file read back with h5py. Also ``windrig check`` with and without the runtime.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from daq.cli import main
from daq.config import parse_rig_config
from daq.instruments.ni_daqmx import runtime
from daq.recording.devices import CLOCK_SETTLE_S
from daq.sim.recording import record_simulated_run
from simulators.nidaqmx_standin import standin_api

from support.configs import CONFIGS, FAST_FAN

pytestmark = pytest.mark.realtime

NIDAQ = (CONFIGS / "sim_flat_plate_nidaq.toml").read_text()
FAN_RPM = 600.0  # 6 m/s on this rig
RATE = 2000.0


def without(text: str, start: str, stop: str) -> str:
    """Cut a config's text from the line ``start`` up to (not including) ``stop``."""
    i, j = text.index(start), text.index(stop)
    return text[:i] + text[j:]


def scripted(seen: dict[str, Any], release_s: float = 1.5) -> Any:
    """Start the fan, pulse the trigger, arm; release ``release_s`` into the run, pulse again."""
    def actions(acq: Any, rig: Any) -> None:
        seen["rig"] = rig
        fan = acq.drivers["fan"]
        fan.set_speed(FAN_RPM)
        fan.start()
        time.sleep(0.8)
        acq.trigger()
        time.sleep(0.3)
        acq.arm()
        time.sleep(release_s - 1.1)
        seen["release"] = acq.release()
        time.sleep(0.5)
        acq.trigger()
        if hasattr(rig, "origin_s"):
            # A rig in its own process is gone when the run ends: take the decay's truth now,
            # on the tunnel's clock at 2 kHz from before the run to past its end (the decay is
            # computed whole at the release).
            now = time.monotonic() - rig.origin_s
            grid = np.arange(now - 6.0, now + 6.0, 5e-4)
            seen["truth_h"] = (grid, rig.decay_truth(grid)["h"])
    return actions


def test_nidaq_lasers_record_a_release_matching_the_tunnel(tmp_path):
    config = parse_rig_config(NIDAQ + FAST_FAN, "sim_flat_plate_nidaq.toml")
    seen: dict[str, Any] = {}
    path = tmp_path / "run.h5"
    # As a campaign: the release once the clock maps have settled (before, on a loaded host,
    # they were 1-30 ms off: 0.1-0.3 mm rms in h), and the simulators in a process of their
    # own, as `windrig acquire --simulate` (sharing this one's interpreter lock, the simulated
    # DAQ's blocks came 10-30 ms late).
    duration_s = CLOCK_SETTLE_S + 2.5
    summary = record_simulated_run(config, path, duration_s=duration_s,
                                   actions=scripted(seen, release_s=CLOCK_SETTLE_S),
                                   progress=False, own_process=True)
    assert summary["errors"] == [] and summary["subscriber_errors"] == {}
    assert summary["releases"] == 1 and summary["gaps"]["laser_front"] == 0
    # The trigger line reached the DAQ: the lasers' clocks are anchored on its pulses (every
    # 0.5 s, paired once a clock map is ready, after ~1.5 s).
    fits = summary["clock_fits"]
    assert all(fits[name]["anchors"] >= 1 for name in ("laser_front", "laser_rear"))
    with h5py.File(path, "r") as f:
        raw = f["entry/instrument/laser_front"]
        counter, device_time = raw["counter"][:], raw["device_time"][:]
        assert raw["value"].shape == (summary["samples"]["laser_front"], 1)
        assert np.all(raw["triggered"][:].astype(bool).sum() >= 3)
        sync = f["entry/sync"]
        t, h, U = sync["time"][:], sync["h"][:], sync["U"][:]
        t0_s = int(sync.attrs["t0_host_ns"]) * 1e-9
        rear_counter = f["entry/instrument/laser_rear/counter"][:]
    # The DAQ's sample clock is the device clock: counter = sample index, time = index / rate.
    assert np.array_equal(counter, np.arange(counter[0], counter[0] + counter.size))
    assert np.array_equal(device_time, counter / RATE)
    assert counter.size > (duration_s - 0.5) * RATE
    # Three lasers on one task: the same samples.
    assert np.intersect1d(counter, rear_counter).size > 0.95 * counter.size
    # h against the truth over the free decay (tolerance as the ILD1420 rig's HIL test: 0.1 mm
    # rms; measured 0.002-0.006 mm with both cores busy), and the lasers' clocks against the
    # simulated DAQ's.
    ok = np.isfinite(h)
    assert ok.mean() > 0.98
    # The truth at the view's times (linear between 2 kHz points: < 0.1 um on this decay).
    grid, h_grid = seen["truth_h"]
    true_h = np.interp(t + t0_s - seen["rig"].origin_s, grid, h_grid, left=np.nan, right=np.nan)
    decay = ok & np.isfinite(true_h)
    assert decay.sum() > 1.5 * 500  # the release 2.5 s before the end; the view at 500 Hz
    assert np.sqrt(np.mean((h[decay] - true_h[decay]) ** 2)) < 1e-4
    clocks = summary["alignment"]["clocks"]
    assert abs(clocks["clock_error_mean_s"]["laser_front"]) < 1e-3  # measured 0.003-0.16 ms
    assert np.isfinite(U).any()  # the scanner's Pitot, as on the serial-laser rig


NO_SCANNER = without(NIDAQ, "[scanner]", "[[lasers]]").replace("ai0:2?", "ai0:3?") + '''
[[analog]]
name = "pitot_daq"
driver = "ni_daqmx_analog"
url = "nidaqmx://Dev1/ai0:3?trigger=port0/line0&min=-10&max=10&terminal=diff"
rate_hz = 2000.0
channels = [{ name = "pitot", channel = "ai3", gain = 10.0, offset = 0.0, units = "Pa" }]
'''


def test_an_analog_pitot_gives_the_wind_speed_of_a_rig_without_a_scanner(tmp_path, capsys):
    config = parse_rig_config(NO_SCANNER + FAST_FAN, "no_scanner.toml")
    seen: dict[str, Any] = {}
    path = tmp_path / "run.h5"
    summary = record_simulated_run(config, path, duration_s=3.0, actions=scripted(seen),
                                   progress=False, calz=False)
    assert summary["errors"] == [] and summary["gaps"]["pitot_daq"] == 0
    with h5py.File(path, "r") as f:
        raw = f["entry/instrument/pitot_daq"]
        names = [str(n) for n in raw.attrs["channel_names"]]
        units = [str(u) for u in raw.attrs["units"]]
        q = raw["value"][:, names.index("pitot")]
        t, U = f["entry/sync/time"][:], f["entry/sync/U"][:]
    assert units[names.index("pitot")] == "Pa"
    wind = seen["rig"].tunnel.wind_speed()
    late = t > 2.0  # the fan reached 600 rpm (4000 rpm/s ramp) long before
    # U from the transducer's dynamic pressure within 1 % (noise 3 mPa on ~22 Pa).
    assert np.nanmedian(U[late]) == pytest.approx(wind, rel=0.01)
    assert np.nanmax(q) == pytest.approx(0.5 * 1.204 * wind**2, rel=0.02)
    # windrig info names the analog device's driver from the stored config.
    capsys.readouterr()
    assert main(["info", str(path)]) == 0
    (row,) = [line for line in capsys.readouterr().out.splitlines()
              if line.startswith("pitot_daq")]
    assert row.split()[1] == "ni_daqmx_analog"


def test_check_passes_the_simulated_nidaq_rig(capsys):
    assert main(["check", "--config", str(CONFIGS / "sim_flat_plate_nidaq.toml"),
                 "--simulate"]) == 0
    out = capsys.readouterr().out
    assert "7 of 7 device(s) OK" in out and "2000.0 Hz (of 2000)" in out


def test_check_inspects_an_analog_pitot(tmp_path, capsys):
    path = tmp_path / "no_scanner.toml"
    path.write_text(NO_SCANNER)
    assert main(["check", "--config", str(path), "--simulate"]) == 0
    out = capsys.readouterr().out
    (row,) = [line for line in out.splitlines() if line.startswith("pitot_daq")]
    # Wind off: the transducer reads ~0 Pa (noise 3 mPa), at the task's rate.
    assert "2000.0 Hz (of 2000)" in row and "pitot " in row and row.rstrip().endswith("OK")


def nidaq_only(tmp_path: Path) -> Path:
    """Write a rig of NI lasers only (real URLs: no simulator is started without --simulate)."""
    text = NIDAQ[:NIDAQ.index("[scanner]")] + NIDAQ[NIDAQ.index("[[lasers]]"):NIDAQ.index("[fan]")]
    path = tmp_path / "nidaq_only.toml"
    path.write_text(text)
    return path


def test_check_without_the_package_names_it_in_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "nidaqmx", None)  # as if not installed
    assert main(["check", "--config", str(nidaq_only(tmp_path))]) == 1
    captured = capsys.readouterr()
    failures = [line for line in captured.out.splitlines() if line.startswith("FAIL")]
    assert len(failures) == 3 and "Traceback" not in captured.out + captured.err
    for line in failures:
        assert line.endswith("cannot build the driver: NI-DAQmx: the Python package 'nidaqmx' "
                             "is not installed; install it with: pip install 'windrig[nidaqmx]'")


def test_check_without_the_runtime_names_it_in_one_line(tmp_path, capsys):
    # The package present, its C library not: the stand-in raises what nidaqmx raises then.
    path = nidaq_only(tmp_path)
    path.write_text(path.read_text().replace("terminal=diff", "terminal=diff&standin=127.0.0.1:9"))
    runtime.register_standin(lambda host, port: standin_api(host, port, runtime_missing=True))
    try:
        assert main(["check", "--config", str(path)]) == 1
    finally:
        runtime.register_standin(standin_api)
    out = capsys.readouterr().out
    failures = [line for line in out.splitlines() if line.startswith("FAIL")]
    assert len(failures) == 3
    assert all("the NI-DAQmx runtime (its C library) is not" in line and
               "python -m nidaqmx installdriver" in line for line in failures)


def test_overflow_and_a_lost_device_are_gap_rows_in_the_run_file(tmp_path):
    # A 0.5 s host buffer (1000 samples at 2 kHz), so that a 1.2 s stall overflows it.
    text = NIDAQ.replace("terminal=diff", "terminal=diff&buffer_s=0.5")
    config = parse_rig_config(text, "sim_flat_plate_nidaq.toml")

    def actions(acq: Any, rig: Any) -> None:
        daq = rig.simulators["laser_front"]  # one simulated DAQ for the three lasers
        time.sleep(1.0)
        daq.inject("stall", duration_s=1.2)
        time.sleep(2.0)
        daq.inject("device_lost", downtime_s=0.3)

    path = tmp_path / "faults.h5"
    summary = record_simulated_run(config, path, duration_s=5.5, actions=actions,
                                   progress=False)
    assert summary["errors"] == []
    with h5py.File(path, "r") as f:
        raw = f["entry/instrument/laser_front"]
        gaps = raw["gaps"][:]
        counter = raw["counter"][:]
        epochs = np.unique(raw["device_time"][:] < 0.5)  # the new task's clock from 0
        kinds = [k.decode() for k in f["entry/events"]["kind"]]
        h = f["entry/sync/h"][:]
    # Two gap rows: the overwritten samples, counted (the counter's hole, >= 0.7 s of them),
    # then the lost device's restart (-1: unknown, the clock started again).
    assert [int(g["length"]) == -1 for g in gaps] == [False, True], gaps
    after, length = int(gaps[0]["after_counter"]), int(gaps[0]["length"])
    k = int(np.searchsorted(counter, after))
    assert counter[k] == after and counter[k + 1] == after + length + 1
    assert length >= 0.7 * RATE
    assert "clock_restart" in kinds and epochs.size == 2
    # The sync view goes on after both faults.
    assert np.isfinite(h[-200:]).all()
