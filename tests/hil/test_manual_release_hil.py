"""Releases by hand on the simulated rig without a PLC: found in the lasers, identified.

The flat plate with its ``[plc]`` taken out: no magnet on the wire, no trigger pulses. The test
is the operator: it lets the model go through the virtual tunnel directly
(``VirtualTunnel.release``, which knows the true instant), presses the release key 0.3-0.6 s
later (``Acquisition.manual_release``), catches the model (``VirtualTunnel.arm``) and says so
(``manual_hold``). The run writer finds each release instant in the lasers' signals. Two
releases at each of the demo's speeds (5.92, 7.70 and 9.48 m/s), 6 s decays, identified by
E2RFC and held against the simulator's true flutter speed. The PLC path at the same speeds is
``tests/hil/test_demo_hil.py``'s (the demo's campaign, held against the same truth).

Measured (this host, 2 runs): the found instants 0.25-0.45 ms from the tunnel's truth, against
the 5 ms required (a PLC release's time, the host's time of the PLC's acknowledgement, is 3-20
ms after the magnet let go); flutter speeds 11.896 +- 0.079 and 11.912 +- 0.081 m/s by hand
(CI once 11.962 +- 0.064) against 11.864 +- 0.201 and 11.844 +- 0.114 m/s by PLC; the truth is
11.849 m/s. Let go by hand on the rig whose PLC still pulses the trigger line: -0.93 to +0.04
ms, 11.822 +- 0.068 m/s. Before the decays by hand ended 70 ms before their catch
(``ident.records.release_onset.CATCH_GUARD_S``), their last row or two held the catch's step
and E2RFC gave 12.28-12.36 +- 0.55 m/s.
"""

from __future__ import annotations

import re
import threading
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from daq.config import parse_rig_config
from daq.sim.campaign import simulated_truth
from daq.sim.recording import record_simulated_run
from ident.identification.campaign import analyze_campaign
from ident.model import flutter
from ident.records.run_file import read_run
from ident.records.run_set import campaign_section

from support.configs import FAST_FAN, SIM_FLAT_PLATE

pytestmark = [pytest.mark.slow, pytest.mark.realtime]

#: The demo's speeds (0.5, 0.65 and 0.8 of the flutter speed, 5.92, 7.70 and 9.48 m/s): with
#: two speeds of short decays the flutter speed is an extrapolation whose structure, and std,
#: changed from run to run (PLC path 12.29 +- 0.62, then 11.85 +- 0.10 m/s).
SPEEDS_RPM = (592.0, 770.0, 948.0)
DECAY_S = 6.0
KEY_LAGS_S = (0.3, 0.6, 0.45, 0.35, 0.5, 0.4)  # the operator's key after each release
#: Required by the issue: a manual release found within 5 ms of the simulator's truth.
TOLERANCE_S = 5e-3


def _rig() -> Any:
    """Return the flat plate's simulated rig without its ``[plc]``."""
    text, n = re.subn(r"\n\[plc\]\n(?:[^\[\n].*\n|\n)*", "\n",
                      SIM_FLAT_PLATE.read_text() + FAST_FAN)
    assert n == 1
    config = parse_rig_config(text, "rig.toml")
    assert not config.by_role("plc")
    return config


def _record(path: Path) -> tuple[list[float], float]:
    """Record the script by hand; return the true release times (host clock) and the t0."""
    truths: list[float] = []
    done = threading.Event()

    def actions(acq: Any, rig: Any) -> None:
        origin = rig.tunnel.clock.origin_s
        time.sleep(2.0)  # the clock maps settle before the first release
        k = 0
        for rpm in SPEEDS_RPM:
            acq.set_fan_speed(rpm)
            acq.start_fan()
            time.sleep(1.5)
            for _ in range(2):
                truths.append(origin + rig.tunnel.release())  # the operator's hand
                time.sleep(KEY_LAGS_S[k])
                acq.manual_release()
                time.sleep(DECAY_S - KEY_LAGS_S[k])
                rig.tunnel.arm()  # caught by hand ...
                time.sleep(0.3)
                acq.manual_hold()  # ... and said so
                time.sleep(0.7)
                k += 1
        done.set()

    summary = record_simulated_run(_rig(), path, duration_s=90.0, actions=actions,
                                   progress=False, until=done)
    assert summary["errors"] == [] and summary["releases"] == 6
    with h5py.File(path, "r") as f:
        t0 = int(f["entry/sync"].attrs["t0_host_ns"]) * 1e-9
    return truths, t0


def _identify(path: Path) -> tuple[float, float]:
    # A host stall of a few seconds (CI runs the pure tests beside these) can leave a marked
    # gap in one release's scanner columns (seen once in about 20 CI runs: 4.6 s of lift in
    # a PLC file's fifth release). The reader then cuts that release, as a campaign does;
    # the comparison with the truth holds with five releases (its bound is their own std),
    # and more than one release cut is a failure, not the host.
    run = read_run(path, cut_at_gaps=True)
    assert len(run.cuts) <= 1, run.cuts
    if run.cuts:
        print(f"{path.name}: {run.cuts[0]}")
    assert len(run.releases) >= 5
    analysis = analyze_campaign(list(run.releases), campaign_section([run]), table=False)
    assert analysis.flutter.speed is not None
    return float(analysis.flutter.speed), float(analysis.flutter_std)


def _found(path: Path, truths: list[float], t0: float) -> np.ndarray:
    """Check the releases found in a file by hand; return their errors against the truth, s."""
    with h5py.File(path, "r") as f:
        releases = f["entry/releases"][:]
        events = f["entry/events"][:]
    kinds = [k.decode() for k in events["kind"]]
    assert kinds.count("manual_release") == 6 and kinds.count("release_detected") == 6
    assert "release_not_detected" not in kinds and "release" not in kinds
    # Each decay ends at the catch (the manual_hold's still hold), before the next release.
    assert np.all(releases["stop_index"][:-1] < releases["start_index"][1:])
    assert np.all(np.isfinite(releases["h0"])) and np.allclose(releases["alpha0"], 0.04, atol=1e-3)
    return np.asarray(releases["release_time"] - (np.array(truths) - t0))


def test_releases_by_hand_without_a_plc_are_found_within_5_ms_and_identified(tmp_path):
    manual = tmp_path / "manual.h5"
    truths, t0 = _record(manual)
    errors = _found(manual, truths, t0)
    assert np.all(np.abs(errors) < TOLERANCE_S), errors
    U_manual, std_manual = _identify(manual)
    truth = flutter.analyze(*simulated_truth(_rig())).speed
    assert truth == pytest.approx(11.849, abs=0.01)
    print(f"found {1e3 * errors} ms; U_F {U_manual:.3f} +- {std_manual:.3f} m/s by hand, "
          f"truth {truth:.3f} m/s")
    # The estimate against the truth within 3 of its own std: the five runs on record were
    # within 0.7-1.8 std (the CI one the farthest), and 3 std fail about one run in 400 by
    # chance while still catching a release by hand that biased the answer by a few tenths
    # of a m/s. The std itself stays small (0.064-0.081 m/s measured; 2 % of U_F allowed), so
    # the bound is no blanket.
    assert abs(U_manual - truth) <= 3.0 * std_manual, (U_manual, std_manual, truth)
    assert std_manual < 0.02 * truth
