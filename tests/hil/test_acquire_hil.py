"""record_run on the whole simulated flat-plate rig: the run file against the tunnel's truth.

Real drivers over real (loopback) transports, the acquisition engine, the RunWriter, an HDF5 file
in SWMR mode; a scripted sequence sets the fan, pulses the trigger, arms and releases once.

Measured (this machine, 3 runs of 4 s, 0.5 s clock windows): max |h - truth| over the sync
view 0.023-0.083 mm (largest at the release kink: a sub-millisecond timing error of the clock
maps), rms 0.006-0.021 mm; max |alpha - truth| 0.2-0.8 mrad; U 5.993-5.995 m/s against the
tunnel's 6.0 (0.1 %). Tolerances below are ~5x the worst measured.
"""

from __future__ import annotations

import time
from typing import Any

import h5py
import numpy as np
import pytest

from daq.config import parse_rig_config
from daq.sim.recording import record_simulated_run

from support.configs import FAST_FAN, SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

FAN_RPM = 600.0  # 6 m/s on this rig


def test_record_run_writes_a_release_matching_the_tunnel_truth(tmp_path):
    # A fast fan ramp (a simulator option) keeps the test short.
    text = SIM_FLAT_PLATE.read_text() + \
        FAST_FAN
    config = parse_rig_config(text, "sim_flat_plate.toml")
    seen: dict[str, Any] = {}

    def actions(acq: Any, rig: Any) -> None:
        seen["rig"] = rig
        # Host monotonic time minus the tunnel's true time: the truth at a sync time.
        seen["true_offset_s"] = time.monotonic() - rig.tunnel.clock.now()
        fan = acq.drivers["fan"]
        fan.set_speed(FAN_RPM)
        fan.start()
        time.sleep(0.8)
        acq.trigger()
        time.sleep(0.3)
        acq.arm()
        time.sleep(0.4)
        seen["release"] = acq.release()
        time.sleep(0.5)
        acq.trigger()

    path = tmp_path / "run.h5"
    started = time.monotonic()
    summary = record_simulated_run(config, path, duration_s=4.0, actions=actions,
                                   progress=False, operator_notes="HIL")
    assert time.monotonic() - started < 10.0
    assert summary["errors"] == [] and summary["subscriber_errors"] == {}
    assert summary["overflows"] == 0 and summary["releases"] == 1
    assert all(n > 0 for n in summary["samples"].values())
    assert set(summary["clock_fits"]) == {"scanner", "laser_front", "laser_rear", "laser_check"}

    rig = seen["rig"]
    with h5py.File(path, "r") as f:
        sync = f["entry/sync"]
        t, h, alpha, U = (sync[k][:] for k in ("time", "h", "alpha", "U"))
        t0_s = int(sync.attrs["t0_host_ns"]) * 1e-9
        releases = f["entry/releases"][:]
        kinds = [k.decode() for k in f["entry/events"]["kind"]]
        assert f["entry/instrument/laser_front/value"].shape[0] == \
            summary["samples"]["laser_front"]
        assert f.attrs["default"] == "entry" and f["entry"].attrs["default"] == "sync"
        # The scanner was zeroed (wind off) before the run, and the file says so; the
        # simulator's CALZ takes 0.2 s, polled every 0.1 s by the driver.
        calz = f["entry/metadata/calz_scanner_start"]
        assert 0.2 <= float(calz["calz_s"][()]) < 0.6 and float(calz["wind_speed_now"][()]) == 0
    # The writer's view of the streams goes into the failure message: a heave lost without any
    # error, overflow or missing clock fit has been seen on a loaded host.
    writer_view = {key: summary[key] for key in ("gaps", "late_samples", "overlapping_samples",
                                                 "clock_restarts", "timelines", "clock_fits")}
    assert t.size > 1500 and np.isfinite(h).mean() > 0.98, (
        f"heave finite on {np.isfinite(h).mean():.3f} of {t.size} rows, NaN from "
        f"{t[~np.isfinite(h)][:1]} s; {writer_view}")
    # Two pulses from the actions, and the sync pulses record_run sends: each 0.5 s after the
    # previous one ended (the first after 0.5 s, the last possibly cut by the stop). A pulse
    # takes its 10 ms width and two Modbus round trips, longer while an arm or a release holds
    # the PLC's bus, so the 4 s run holds 5 to 8 (5 in 2 of 30 runs on a loaded host). A fixed
    # 0.5 s grid was tried and left: its pulses met the scripted releases of the HIL tests.
    assert kinds.count("release") == 1
    assert 2 + 5 <= kinds.count("trigger") <= 2 + 8

    (row,) = releases
    release_s = (seen["release"].data["command_ns"] * 1e-9) - t0_s
    assert abs(row["release_time"] - release_s) < 1e-9
    assert row["start_index"] == np.searchsorted(t, release_s)
    assert row["stop_index"] == t.size
    wind = rig.tunnel.wind_speed()
    assert abs(row["U"] - wind) < 0.02 * wind
    # The held position is the simulated rig's hold (tolerances as measured since issue 5).
    held = config.simulation
    assert held is not None
    assert abs(row["h0"] - held.hold_h) < 5e-5 and abs(row["alpha0"] - held.hold_alpha) < 5e-4

    # The model is held before the release and moves after it.
    before = h[(t < release_s - 0.05) & (t > 0.2)]
    after = h[t > release_s + 0.05]
    assert np.nanmax(before) - np.nanmin(before) < 1e-4
    assert np.nanmax(after) - np.nanmin(after) > 3e-3

    # h(t) in the file against the truth at the same (host-mapped) times.
    ok = np.isfinite(h)
    true = rig.tunnel.sample(t[ok] + t0_s - seen["true_offset_s"])
    err_h = h[ok] - true["h"]
    err_a = alpha[ok] - true["alpha"]
    assert np.sqrt(np.mean(err_h**2)) < 1e-4          # 0.1 mm rms (measured ~0.02 mm)
    assert np.max(np.abs(err_h)) < 5e-4               # 0.5 mm (measured <= 0.083 mm)
    assert np.sqrt(np.mean(err_a**2)) < 1e-3          # 1 mrad rms
    decay = t[ok] > release_s
    assert np.corrcoef(h[ok][decay], true["h"][decay])[0, 1] > 0.99
    # U comes from the scanner's Pitot tap: its rows are NaN until the scanner's first frame
    # (its SCAN is sent as the run starts; that frame came 0.26 s in once on the loaded CI
    # host, 0.05 s typically), and finite from there on.
    has_U = np.isfinite(U)
    first_U = int(np.argmax(has_U))
    assert has_U.any() and t[first_U] < 1.0, t[first_U] if has_U.any() else "no U"
    # Rows without a scanner frame stay NaN (a marked gap, never filled). On a loaded two-core
    # host the scanner's frames have stalled once for 6 % of the run's rows (CI of cd91519,
    # 94 % finite; 100 % on other runs): 0.9 allows that stall, not a scanner that stops.
    assert has_U[first_U:].mean() > 0.9, (
        f"U finite on {has_U[first_U:].mean():.3f} of the rows after the first frame; "
        f"{writer_view}")


def test_cli_acquire_simulated_prints_the_summary(tmp_path, capsys):
    from daq.cli import main

    out = tmp_path / "cli.h5"
    code = main(["acquire", "--config", str(SIM_FLAT_PLATE), "--simulate",
                 "--duration", "1.5", "--out", str(out), "--notes", "cli test"])
    text = capsys.readouterr().out
    assert code == 0, text
    assert f"wrote {out}" in text and "laser_front" in text and "drift" in text
    with h5py.File(out, "r") as f:
        assert f["entry/sync/h"].shape[0] > 500
        assert f["entry"].attrs["operator_notes"] == "cli test"
