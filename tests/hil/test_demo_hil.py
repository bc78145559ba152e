"""`windrig demo` end to end: the issue's must-show, the simulator's truth identified.

The whole default campaign (0.5, 0.65 and 0.8 of the simulated flutter speed, two releases each,
7.5 s decays) through the real drivers over loopback transports, one HDF5 file per wind speed,
identified by E2RFC. Only the simulated fan ramps faster (a simulator option) to save ~20 s.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.cli import main
from daq.sim.demo import DEFAULT_CONFIG
from ident.records.run_file import read_run

from support.configs import FAST_FAN

pytestmark = pytest.mark.realtime


def test_demo_campaign_identifies_the_flutter_speed_within_3_percent(tmp_path, capsys):
    config = tmp_path / "sim_flat_plate_fast_fan.toml"
    config.write_text(DEFAULT_CONFIG.read_text()
                      + FAST_FAN)
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--config", str(config)]) == 0
    printed = capsys.readouterr().out

    summary = json.loads((out / "summary.json").read_text())
    truth, speed = summary["truth_flutter_speed"], summary["identified_flutter_speed"]
    assert truth == pytest.approx(11.849, abs=0.01)
    # The end-to-end target of the issue is 3 %. Released from 4 mm and 0.02 rad (the rig's
    # hold before 2026-11-28) the demo landed at -0.2..+0.3 % in most runs and at +3.2..+3.7 %
    # in about 4 of 10: one lag came within one standard error of the best held-out error
    # (the tap noise) and the one-standard-error rule took it. From today's 8 mm and 0.04 rad
    # it is 4-17 standard errors behind, and 12 runs gave -0.36..+0.12 % (std 0.45-1.3 %);
    # with one engine for the whole campaign (2026-11-29) 8 runs gave -0.42..+0.50 %, each
    # within one reported std (0.57-0.94 %).
    # The assertion keeps its fallback for such a tie: within 3 %, or else the truth among
    # the flutter speeds of the structures the data cannot tell apart; in both cases within 2
    # reported std, which is itself under 5 %.
    structures = [v for v in summary["identified_flutter_speed_structures"].values()
                  if v is not None]
    assert (abs(summary["relative_error"]) < 0.03
            or min(structures) - 0.01 <= truth <= max(structures) + 0.01), printed
    std = summary["identified_flutter_speed_std"]
    assert abs(speed - truth) < 2 * std and std < 0.05 * truth, printed
    low, high = summary["identified_flutter_speed_interval"]  # longer above than below
    assert low <= truth <= high and high - speed >= speed - low, printed
    # Three run files, two releases each, read back as `windrig identify` reads them.
    files = [Path(p) for p in summary["files"]]
    assert len(files) == 3
    # One engine for the whole campaign: the later files were switched under it, so each
    # starts with the session's pre-roll (6 s of samples and trigger pulses before its time
    # 0), where a file of its own engine starts at its recording_started event.
    for i, path in enumerate(files):
        with h5py.File(path, "r") as f:
            first_times = f["entry/events"]["time"][:1]
        assert (first_times[0] < -4.0) == (i > 0), (path, first_times)
    for path in files:
        run = read_run(path)
        assert len(run.releases) == 2
        with h5py.File(path, "r") as f:
            released = f["entry/releases"]["release_time"]
            events = f["entry/events"][()]
        arms = np.sort(events["time"][events["kind"] == b"arm"])
        for release, t0 in zip(run.releases, released, strict=True):
            # The decay is cut before the model is caught: its last row comes before the
            # next arm event (the catch). The plan sleeps 7.5 s between release and catch;
            # the catch is logged when the PLC command returns, which on a loaded 2-core host
            # has come up to ~0.1 s late (7.61 s once), so the length is bounded by the
            # file's own catch, not by a wall-clock guess.
            catch = arms[arms > t0][0]
            assert 7.0 < release.t[-1] <= catch - t0 + 1e-9
    assert sorted({round(u, 2) for u in summary["wind_speeds"]}) == pytest.approx(
        [0.5 * 11.849, 0.65 * 11.849, 0.8 * 11.849], abs=0.02)
    # One table row per release: measured damping next to the truth's, within 5 % of it
    # (a modal fit of a 7.5 s decay; the measured values agree to ~0.1 %).
    assert len(summary["releases"]) == 6
    for row in summary["releases"]:
        assert row["zeta_a"] == pytest.approx(row["truth_zeta_a"], rel=0.05)
        assert row["zeta_h"] == pytest.approx(row["truth_zeta_h"], rel=0.05)
    # The printed table has a row per release with its measured mean wind speed, which is
    # within 0.05 m/s of the setpoint's (the wind's noise and the fan's settling move the
    # second decimal from run to run).
    for row in summary["releases"]:
        match = re.search(re.escape(row["release"]) + r"\s+(\d+\.\d\d)\s", printed)
        assert match, printed
        assert float(match.group(1)) == pytest.approx(row["U"], abs=0.005)
    first = summary["releases"][0]
    assert first["release"] == "campaign_U05.92.h5 #0"
    assert first["U"] == pytest.approx(0.5 * 11.849, abs=0.05)
    for name in ("decays", "flutter_derivatives", "flutter"):
        assert Path(summary["plots"][name]).stat().st_size > 10_000
