"""Calibrations on the whole simulated rig: wired taps, dead taps, Pitot, lasers, humid air.

One short recording (real drivers over loopback, the engine, the run writer, an HDF5 file) of
the flat-plate rig with every calibration of the rig config in use. The simulators read the same
config and build the errors the calibrations undo (daq.sim.rig): each tap's pressure on its
wired channel of two scanner modules, in no particular order; a Pitot that reads the dynamic
pressure / 1.05; a check laser tilted by 8 degrees with a gain and offset error; a barometer
that reports 45 %RH (a PTU300-class line), which gives the humid air density.

Measured (this machine, 3 runs of 3.5 s at 9 m/s, scanner noise 0.1 Pa per tap): lift and
moment of the 60 live taps against all 62 taps integrated from the same recorded pressures
differ by 0.42-0.49 % and 0.21-0.24 % of the decay's rms lift and moment, sample by sample
(tolerance 1 %; the difference is the dead taps' noise: without noise the redistribution
is exact to 0.06 % for this pressure field, tests/ident/physics/test_taps_without.py); lift and
moment against the tunnel's truth: correlation 0.9997-0.9998; U 9.017-9.020 m/s against 9.000
(tolerance 1 %: the humid density is 0.4 % below the simulated dry air, so U is 0.2 % high;
without the Pitot calibration U would be 2.4 % low).
"""

from __future__ import annotations

import time
from typing import Any

import h5py
import numpy as np
import pytest

from daq.config import parse_rig_config
from daq.recording.info import format_info, run_info
from daq.sim.recording import record_simulated_run
from ident.physics.air import moist_air_density

from support.configs import SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

FAN_RPM = 900.0  # 9 m/s on this rig: lift and moment well above the scanner's noise
DEAD = [10, 45]  # an interior tap of the upper face and one of the lower face
MAX_LAG_S = 0.05  # the wiring check's lag search, s (in-process simulators, see below)


def calibrated_config_text() -> str:
    """Return the flat-plate rig: two scanner modules, taps wired out of order, calibrations."""
    text = SIM_FLAT_PLATE.read_text()
    text = text.replace("modules = 1\n", "modules = 2\n")
    # Tap i on module i % 2, channel 40 - i // 2: alternating modules, descending channels.
    wiring = ", ".join(f"[{i % 2}, {40 - i // 2}]" for i in range(62))
    old = "taps_per_face = 28          # 2 x 28 on the faces + 2 x 3 on the edges = 62 taps\n"
    assert old in text
    text = text.replace(old, f"taps_per_face = 28\nchannels = [{wiring}]\ndead = {DEAD}\n"
                             'source = "tap wiring survey"\ndate = 2026-11-20\n')
    text = text.replace("[section]\n", "[section]\nspan = 0.6\n")
    text = text.replace("wind_per_rpm = 0.01         # (m/s)/rpm, tunnel calibration\n",
                        "wind_per_rpm = 0.01\n\n[tunnel.pitot]\nfactor = 1.05\n"
                        'source = "Pitot vs reference probe"\ndate = "2026-11-18"\n')
    old = 'name = "laser_check"'
    i = text.index(old)
    j = text.index("[fan]", i)
    text = (text[:j] + "[lasers.calibration]\ngain = 1.02\noffset_mm = 0.5\nangle_deg = 8.0\n"
            'source = "gauge blocks"\ndate = 2026-11-19\n\n' + text[j:])
    # The humidity the barometer reports: a PTU300-class line's RH= field (simulated at 45 %RH).
    text += ('\n[air]\nrelative_humidity = "barometer"\nsource = "PTU300 humidity probe"\n'
             "date = 2026-11-20\n\n[simulation.devices.fan]\nramp_rpm_per_s = 4000.0\n"
             "\n[simulation.devices.barometer]\nrelative_humidity = 0.45\n"
             # 0.1 Pa per tap (1 Pa by default): the forces of 60 and 62 taps differ by
             # their noise, 0.02 N/m rms at 1 Pa, 8 % of this decay's lift.
             "\n[simulation.devices.scanner]\nnoise_pa = 0.1\n")
    return text


def test_wired_and_dead_taps_and_calibrations_end_to_end(tmp_path):
    config = parse_rig_config(calibrated_config_text(), "calibrated.toml")
    seen: dict[str, Any] = {}

    def actions(acq: Any, rig: Any) -> None:
        seen["rig"] = rig
        seen["true_offset_s"] = time.monotonic() - rig.tunnel.clock.now()
        fan = acq.drivers["fan"]
        fan.set_speed(FAN_RPM)
        fan.start()
        time.sleep(0.8)
        acq.arm()
        time.sleep(0.3)
        seen["release"] = acq.release()

    path = tmp_path / "run.h5"
    summary = record_simulated_run(config, path, duration_s=3.5, actions=actions,
                                   progress=False)
    assert summary["errors"] == [] and summary["releases"] == 1
    rig = seen["rig"]
    with h5py.File(path, "r") as f:
        sync = f["entry/sync"]
        t, h, lift, moment, U, rho, pressure = (
            sync[k][:] for k in ("time", "h", "lift", "moment", "U", "rho", "pressure"))
        t0_s = int(sync.attrs["t0_host_ns"]) * 1e-9
        raw = f["entry/instrument/scanner/value"]
        assert raw.shape[1] == 63  # the 62 taps (dead ones too: nothing lost) and the Pitot
        cal = f["entry/calibration"]
        taps = cal["taps"]
        assert list(taps["dead"][:]) == DEAD and not taps["live"][10] and taps["live"][11]
        assert list(taps["scanner_module"][:4]) == [0, 1, 0, 1]
        assert list(taps["scanner_channel"][:4]) == [40, 40, 39, 39]
        assert (taps.attrs["source"], taps.attrs["date"]) == ("tap wiring survey", "2026-11-20")
        assert float(cal["pitot/factor"][()]) == 1.05 and cal["pitot"].attrs["date"] == \
            "2026-11-18"
        laser = cal["laser_laser_check"]
        assert float(laser["gain"][()]) == 1.02
        assert abs(float(laser["offset_m"][()]) - 5e-4) < 1e-12
        assert abs(float(laser["angle_rad"][()]) - np.radians(8.0)) < 1e-12
        assert laser.attrs["source"] == "gauge blocks"
        assert cal["air/humidity_from"][()].decode() == "barometer"
        assert cal["air"].attrs["configured"] == "yes"
        baro = f["entry/instrument/barometer"]
        names = [n.decode() if isinstance(n, bytes) else n for n in baro.attrs["channel_names"]]
        humidity = baro["value"][:, names.index("relative_humidity")]
        assert humidity.size > 0 and np.all(np.abs(humidity - 0.45) < 1e-9)
        assert float(cal["section/span_m"][()]) == 0.6
    info = run_info(path)  # windrig info lists them
    assert info["calibrations"]["pitot"]["source"] == "Pitot vs reference probe"
    assert info["calibrations"]["taps"]["values"]["dead"] == DEAD
    assert "  laser_laser_check: source gauge blocks, date 2026-11-19" in format_info(info)

    release_s = seen["release"].data["command_ns"] * 1e-9 - t0_s
    decay = (t > release_s + 0.05) & np.all(np.isfinite(pressure), axis=1)
    assert decay.sum() > 500  # > 1 s of 500 Hz rows
    # The full set: all 62 taps (the simulated dead taps still read true pressures).
    full_lift, full_moment = config.taps.integrate(pressure[decay].astype(np.float64))
    rel_lift = np.sqrt(np.mean((lift[decay] - full_lift) ** 2) / np.mean(full_lift**2))
    rel_moment = np.sqrt(np.mean((moment[decay] - full_moment) ** 2) / np.mean(full_moment**2))
    print(f"live vs full taps: lift {rel_lift:.2%}, moment {rel_moment:.2%} rms")
    assert rel_lift < 0.01 and rel_moment < 0.01
    assert abs(np.std(lift[decay]) / np.std(full_lift) - 1.0) < 0.01  # the decay's amplitude
    assert abs(np.std(moment[decay]) / np.std(full_moment) - 1.0) < 0.01

    # The wiring is right end to end: the forces follow the tunnel's truth (a wrong channel map
    # would scramble the pressures and the correlation with them, at any lag). The correlation
    # is taken at its best lag within +-MAX_LAG_S: the simulators run in this process, and
    # their share of the interpreter lock delays the scanner's frames by 5-30 ms on a slow
    # host (a latency floor the clock map cannot see; no real instrument has it), while the
    # lasers stay within 1 ms. The sync view's timing is tested against the truth with the
    # rig in a process of its own (test_sync_alignment_hil).
    lags = np.arange(-MAX_LAG_S, MAX_LAG_S + 1e-9, 5e-4)
    best = {"lift": (-1.0, 0.0), "moment": (-1.0, 0.0)}
    for lag in lags:
        true = rig.tunnel.sample(t[decay] + t0_s - seen["true_offset_s"] - lag)
        for name, measured in (("lift", lift[decay]), ("moment", moment[decay])):
            best[name] = max(best[name], (float(np.corrcoef(measured, true[name])[0, 1]),
                                          float(lag)))
    (r_lift, lag_lift), (r_moment, lag_moment) = best["lift"], best["moment"]
    print(f"correlation with the truth: lift {r_lift:.4f} at {lag_lift * 1e3:+.1f} ms, "
          f"moment {r_moment:.4f} at {lag_moment * 1e3:+.1f} ms")
    assert r_lift > 0.99 and r_moment > 0.99
    # The optimum inside the window, and one lag for both forces (the same scanner frames;
    # 1 ms: two grid steps).
    assert max(abs(lag_lift), abs(lag_moment)) < MAX_LAG_S - 1e-3
    assert abs(lag_lift - lag_moment) <= 1e-3

    # Heave through the calibrated, tilted check laser against the truth (0.1 mm rms; the
    # uncalibrated reading would be off by ~0.7 mm).
    ok = np.isfinite(h)
    true_all = rig.tunnel.sample(t[ok] + t0_s - seen["true_offset_s"])
    assert np.sqrt(np.mean((h[ok] - true_all["h"]) ** 2)) < 1e-4

    # Humid air: the density from the barometer's p, T and RH (45 %RH, CIPM-2007); the
    # simulated barometer adds ~2 Pa of noise and drift to the tunnel's air: 0.1 %.
    air = rig.tunnel.air
    expected = float(moist_air_density(air.pressure_pa, air.temperature_k, 0.45))
    assert abs(np.nanmedian(rho) / expected - 1.0) < 1e-3
    # The Pitot read qd / 1.05; calibrated, U matches the tunnel (humid rho is 0.4 % below the
    # tunnel's dry truth: U 0.2 % high).
    wind = rig.tunnel.wind_speed()
    u_held = np.nanmedian(U[(t > release_s - 0.25) & (t < release_s)])
    print(f"U {u_held:.4f} m/s against {wind:.4f}")
    assert abs(u_held / wind - 1.0) < 0.01
