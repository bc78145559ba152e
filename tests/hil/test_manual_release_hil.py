"""Manual releases on the simulated rig without a PLC: found in the lasers, identified as by PLC.

The simulated flat-plate rig with its ``[plc]`` taken out: no magnet on the wire, no trigger
pulses. The test is the operator: it lets the model go through the virtual tunnel directly
(``VirtualTunnel.release``, which knows the true instant), presses the release key 0.3-0.6 s
later (``Acquisition.manual_release``), catches the model (``VirtualTunnel.arm``) and says so
(``manual_hold``). The run writer finds each release instant in the lasers' signals.

The same script on the rig with its PLC (arm, release, arm through the engine) gives the PLC
path's releases; both files are identified by E2RFC (two releases at each of 6 and 8 m/s).

Measured (this host, 2 runs): the detected instants were 0.2-0.65 ms from the tunnel's truth,
against the 5 ms required (the PLC path's release time, the host's time of the PLC's
acknowledgement, is 3-20 ms after the magnet let go); flutter speeds 12.44 +- 0.57 m/s by hand
against 12.29 +- 0.62 m/s by PLC, 0.15 m/s apart (two speeds of short decays: both above the
truth, 11.85 m/s, within 1 std).
"""

from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from daq.config import parse_rig_config
from daq.sim.recording import record_simulated_run
from ident.identification.campaign import analyze_campaign
from ident.records.run_file import campaign_section, read_run

pytestmark = pytest.mark.slow

CONFIGS = Path(__file__).resolve().parents[2] / "rig_configs"
FAST_FAN = "\n[simulation.devices.fan]\nramp_rpm_per_s = 4000.0\n"
SPEEDS_RPM = (600.0, 800.0)  # 6 and 8 m/s on this rig
DECAY_S = 4.5
KEY_LAGS_S = (0.3, 0.6, 0.45, 0.35)  # the operator's key after each release
#: Required by the issue: a manual release found within 5 ms of the simulator's truth.
TOLERANCE_S = 5e-3


def _rig(with_plc: bool) -> Any:
    text = (CONFIGS / "sim_flat_plate.toml").read_text() + FAST_FAN
    if not with_plc:
        text, n = re.subn(r"\n\[plc\]\n(?:[^\[\n].*\n|\n)*", "\n", text)
        assert n == 1
    config = parse_rig_config(text, "rig.toml")
    assert bool(config.by_role("plc")) == with_plc
    return config


def _record(path: Path, *, manual: bool) -> tuple[list[float], float]:
    """Record the script; return the true release times on the host clock and the run's t0."""
    truths: list[float] = []

    def actions(acq: Any, rig: Any) -> None:
        origin = rig.tunnel.clock.origin_s
        time.sleep(2.0)  # the clock maps settle before the first release
        k = 0
        for rpm in SPEEDS_RPM:
            acq.set_fan_speed(rpm)
            acq.start_fan()
            time.sleep(1.5)
            for _ in range(2):
                if manual:
                    truths.append(origin + rig.tunnel.release())  # the operator's hand
                    time.sleep(KEY_LAGS_S[k])
                    acq.manual_release()
                    time.sleep(DECAY_S - KEY_LAGS_S[k])
                    rig.tunnel.arm()  # caught by hand ...
                    time.sleep(0.3)
                    acq.manual_hold()  # ... and said so
                    time.sleep(0.7)
                else:
                    acq.arm()
                    time.sleep(1.0)
                    acq.release()
                    time.sleep(DECAY_S)
                k += 1
        if not manual:
            acq.arm()

    summary = record_simulated_run(_rig(not manual), path, duration_s=35.0, actions=actions,
                                   progress=False)
    assert summary["errors"] == [] and summary["releases"] == 4
    with h5py.File(path, "r") as f:
        t0 = int(f["entry/sync"].attrs["t0_host_ns"]) * 1e-9
    return truths, t0


def _identify(path: Path) -> tuple[float, float]:
    run = read_run(path)
    assert len(run.releases) == 4
    analysis = analyze_campaign(list(run.releases), campaign_section([run]), table=False)
    assert analysis.flutter.speed is not None
    return float(analysis.flutter.speed), float(analysis.flutter_std)


def test_manual_releases_found_within_5_ms_and_identified_as_the_plcs(tmp_path):
    manual = tmp_path / "manual.h5"
    truths, t0 = _record(manual, manual=True)
    with h5py.File(manual, "r") as f:
        releases = f["entry/releases"][:]
        events = f["entry/events"][:]
    kinds = [k.decode() for k in events["kind"]]
    assert kinds.count("manual_release") == 4 and kinds.count("release_detected") == 4
    assert "release_not_detected" not in kinds and "release" not in kinds
    truth_sync = np.array(truths) - t0
    errors = releases["release_time"] - truth_sync
    assert np.all(np.abs(errors) < TOLERANCE_S), errors
    # Each decay ends at the catch (the manual_hold's still hold), not at the next release.
    stops = releases["stop_index"]
    assert np.all(stops[:-1] < releases["start_index"][1:])
    assert np.all(np.isfinite(releases["h0"])) and np.allclose(releases["alpha0"], 0.04, atol=1e-3)

    plc = tmp_path / "plc.h5"
    _record(plc, manual=False)
    U_manual, std_manual = _identify(manual)
    U_plc, std_plc = _identify(plc)
    assert abs(U_manual - U_plc) <= std_plc, (U_manual, std_manual, U_plc, std_plc)
