"""Headless campaigns on the simulated rig, end to end (HIL): real drivers, engine and files.

Every campaign here runs the simulated instruments in a process of their own on loopback
transports (``--simulate``), records one HDF5 file per wind speed, identifies E2RFC after each
speed and writes the report. The simulated fan ramps fast (a simulator option) and the decays
are short (one or two releases of 4-5 s) to keep the wall time modest; the simulated tunnel is
deterministic (smooth flow, noise keyed to the release and the sample), and the campaigns
wait on the drive's speed and on the decay monitor's event, never on fixed guesses of how
long the rig takes.
"""

from __future__ import annotations

import _thread
import json
import math
from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.campaign.adaptive import still_air_flutter_speed
from daq.campaign.plan import parse_plan
from daq.campaign.report import write_report
from daq.campaign.runner import run_plan
from daq.cli import main
from daq.config import parse_rig_config
from ident.model.flat_plate import jones_model

from support.configs import REPO, SIM_FLAT_PLATE

RIG_TEXT = SIM_FLAT_PLATE.read_text()
FAST_FAN = "\n[simulation.devices.fan]\nramp_rpm_per_s = 1000.0\n"
#: The flat plate with a softer pitch spring (fa = 3 Hz): it flutters at 7.84 m/s, and the
#: rig's limits allow 14 m/s, so a plan can ask for speeds beyond flutter.
SOFT_RIG_TEXT = (RIG_TEXT.replace("fa = 4.0         # Hz", "fa = 3.0         # Hz")
                 .replace("max_wind_speed = 11.0", "max_wind_speed = 14.0")
                 .replace("max_fan_rpm = 1300.0", "max_fan_rpm = 1450.0"))
SOFT_TRUTH = 7.838


def _stronger_forces(rig_text: str, factor: float) -> str:
    """Return the rig with its simulated flat plate's Roger matrices times ``factor``.

    Stronger self-excited forces than the flat plate's, as a bluff section has: the rig then
    flutters below its still-air prediction (``factor`` 1.6 on the soft rig: 6.37 m/s against
    the plate's 7.78 m/s).
    """
    model = jones_model().to_dict()
    A = (factor * np.asarray(model["A"])).tolist()
    return (rig_text.replace('aerodynamics = "flat_plate_jones"', 'aerodynamics = "rfc"')
            + f"\n[simulation.rfc]\nA = {A!r}\nd = {list(model['d'])!r}\n")

pytestmark = [pytest.mark.slow, pytest.mark.realtime]


def _fixed(speeds: list[float], releases: int = 1, decay_s: float = 4.0) -> str:
    return f"""
[campaign]
mode = "fixed"
releases_per_speed = {releases}
decay_s = {decay_s}
settle_s = 0.5
calz_end = false

[speeds]
wind_speeds = {speeds!r}
"""


def _fan_set_points(path: Path) -> list[float]:
    """Return the fan references (rpm) the campaign sent during one run file, from its events."""
    with h5py.File(path, "r") as f:
        events = f["/entry/events"][:]
        assert f["/entry/releases"].shape[0] >= 1
    return [json.loads(row["text"].decode().split(" rpm ", 1)[1])["rpm"]
            for row in events if row["kind"] == b"fan_speed"]


def test_adaptive_campaign_reaches_its_target_near_the_truth(tmp_path, capsys):
    config = tmp_path / "rig.toml"
    config.write_text(RIG_TEXT + FAST_FAN)
    # The example plan with a 2 % target, on the shipped rig with its instruments' default
    # seeds. The simulated instruments key their noise to the release and the sample after it
    # (simulators.noise), so every campaign of this seed sees the same noise on its decays;
    # what still moves from run to run is each decay's time origin (the release time the DAQ
    # records is the host's time of the PLC's acknowledgement, 3-20 ms after the magnet let
    # go on a loaded host), and with it the fit a little. Measured (campaign_efficiency.py
    # --hil-check): five campaigns of this seed gave U_F = 11.819-11.858 m/s, std 0.127-0.151
    # (1.07-1.28 %), |U_F - truth| / std 0.001-0.20, all with 3-4 speeds: far inside 2 std.
    # The seed is not a lucky one: seeds 1-8 run the same way all met the target, within
    # 0.09-0.75 std of the truth (8 of 8; about 95 % is what an exact std would give).
    plan = tmp_path / "plan.toml"
    text = (REPO / "rig_configs" / "plans" / "adaptive.toml").read_text()
    assert "target_std = 0.01 " in text and 'decay_end = "settled"' in text
    plan.write_text(text.replace("target_std = 0.01 ", "target_std = 0.02 "))
    out = tmp_path / "campaign"
    assert main(["campaign", str(plan), "--config", str(config), "--simulate",
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    report = json.loads((out / "campaign.json").read_text())

    truth = report["truth_flutter_speed"]
    assert truth == pytest.approx(11.849, abs=0.01)
    assert report["stopped_because"].startswith("target met"), printed
    U_F, std = report["flutter_speed"], report["flutter_speed_std"]
    assert std <= 0.02 * U_F
    assert abs(U_F - truth) <= 2 * std, printed
    speeds = report["speeds"]
    low, high = report["flutter_speed_interval"]  # drawn beyond the top speed: longer above
    assert max(speeds) < low <= truth <= high and high - U_F > U_F - low
    # The first two speeds are the plan's; the later ones chosen below the safety bound: a new
    # speed while fewer than three are covered (the best predicted of those), then the best.
    assert speeds[:2] == [6.0, 8.0] and 3 <= len(speeds) <= 6
    for k, (choice, U) in enumerate(zip(report["choices"], speeds[2:], strict=False), start=2):
        assert choice["speed"] == U and U <= choice["bound"] < truth
        held = speeds[:k]
        pool = [row for row in choice["predicted_std"]
                if len(set(held)) >= 3 or all(abs(row[0] - u) > 0.02 * u for u in held)]
        best = min(row[1] for row in pool)
        assert dict(pool)[U] == best, printed  # (totals: equal ones may tie)
    # The std history: one value from the second speed on, the last the final one. (It need
    # not fall: the third speed adds the extrapolation part, which two speeds cannot measure;
    # seen: 0.129 then 0.137 m/s.)
    stds = [h["flutter_speed_std"] for h in report["history"] if h["flutter_speed_std"]]
    assert len(stds) == len(speeds) - 1 and stds[-1] == pytest.approx(std)
    for h in report["history"]:  # each std is its parts combined (FlutterUncertainty.total)
        if h["flutter_speed_std"]:
            parts = h["flutter_speed_std_parts"]
            statistical = parts["release_scatter"] or parts["noise"]
            systematic = [v for k, v in parts.items() if k not in ("noise", "release_scatter")]
            assert math.hypot(statistical, *systematic) == pytest.approx(
                h["flutter_speed_std"], rel=1e-9)
    assert 0 < report["wind_on_s"] < report["wall_s"]
    for name in ("campaign_std_history.png", "campaign_flutter.png",
                 "campaign_flutter_derivatives.png", "campaign.md"):
        assert (out / name).stat().st_size > 0
    for i, U in enumerate(speeds, start=1):
        assert max(_fan_set_points(out / f"speed{i:02d}_U{U:05.2f}.h5")) == pytest.approx(
            100 * U)


def test_fixed_plan_beyond_flutter_stops_at_the_safety_bound(tmp_path):
    config = parse_rig_config(SOFT_RIG_TEXT + FAST_FAN, "soft.toml")
    plan = parse_plan(_fixed([3.5, 5.0, 12.0]), "plan.toml")
    lines: list[str] = []
    outcome = run_plan(plan, config, tmp_path, simulate=True, say=lines.append)
    write_report(outcome, tmp_path, plots=False)

    assert outcome.truth_flutter_speed == pytest.approx(SOFT_TRUTH, abs=0.01)
    assert outcome.stopped_because.startswith("safety stop: the next speed 12.00 m/s"), lines
    assert [s.U for s in outcome.steps] == [3.5, 5.0]
    assert outcome.flutter_speed is not None and outcome.flutter_std is not None
    bound = 0.9 * (outcome.flutter_speed - 3 * outcome.flutter_std)
    assert bound < 12.0
    # The fan was never sent the refused speed (nor anything near the truth), and stopped.
    # (Not "below the bound": the first two speeds are set before there is an estimate, and
    # from two 4 s decays at low speeds the std can be a third of U_F, the bound then < 0.)
    assert outcome.max_fan_rpm_commanded * config.wind_per_rpm == pytest.approx(5.0)
    assert outcome.max_fan_rpm_commanded * config.wind_per_rpm < SOFT_TRUTH
    set_points = [rpm for s in outcome.steps for rpm in _fan_set_points(s.path)]
    assert set_points == pytest.approx([350.0, 500.0])
    assert any(line.startswith("fan stopped") for line in lines)
    report = json.loads((tmp_path / "campaign.json").read_text())
    assert report["speeds"] == [3.5, 5.0] and report["stopped_because"].startswith("safety")


def test_a_growing_decay_is_caught_and_the_campaign_stops(tmp_path):
    # The first speed (no estimate yet) is beyond this rig's flutter speed, yet below the
    # bound of its still-air prediction: the section flutters earlier than a flat plate of its
    # structure, as a bluff deck does, which only the decay monitor can see.
    config = parse_rig_config(_stronger_forces(SOFT_RIG_TEXT, 1.6) + FAST_FAN, "soft.toml")
    assert 6.9 < 0.9 * still_air_flutter_speed(config.section)  # the plan check lets it by
    plan = parse_plan(_fixed([6.9, 5.0], releases=2, decay_s=6.0), "plan.toml")
    lines: list[str] = []
    outcome = run_plan(plan, config, tmp_path, simulate=True, say=lines.append)

    assert "a decay grew at 6.90 m/s" in outcome.stopped_because, lines
    # The defaults the plan took are said, and the bound before the first estimate.
    assert any(line.startswith("plan defaults: ") and "hold_s = 0.5 s" in line
               and "release = 'auto' (here: plc)" in line for line in lines), lines
    assert any(line.startswith("safety: until E2RFC has an estimate, no speed above 7.00 m/s")
               for line in lines), lines
    assert len(outcome.steps) == 1  # the second speed was never set
    assert any("GROWS" in line and "model caught, fan stopped" in line for line in lines)
    path = outcome.steps[0].path
    with h5py.File(path, "r") as f:  # the file is finished and readable
        kinds = [row["kind"].decode() for row in f["/entry/events"][:]]
        assert f["/entry/releases"].shape[0] == 1  # the second release never happened
    # After the release: the model caught (arm) before the fan was stopped.
    after = kinds[kinds.index("release"):]
    assert after.index("arm") < after.index("fan_stop")
    assert any(line.startswith("fan stopped") for line in lines)


def test_the_plans_hold_is_recorded_and_read_back_as_each_releases_hold(tmp_path):
    """``hold_s``: the model held that long in the wind before each release, in the file.

    ``ident.records.run_file`` reads a release's hold from 0.25 s after its arm event to 0.05 s
    before the release (the refined-IV turbulence branch takes its noise model from it and needs
    10 s; the closed-loop one uses it as extra data): a plan's 11 s hold gives about 10.7 s
    (the default 0.5 s about 0.2 s). A single noisy Pitot row (at 5 m/s they scatter by more
    than 10 %) must not cut the hold short.
    """
    from ident.records.run_file import read_run

    config = parse_rig_config(RIG_TEXT + FAST_FAN, "rig.toml")
    plan = _fixed([5.0, 7.0], decay_s=3.0).replace("settle_s = 0.5", "settle_s = 0.5\nhold_s = 11")
    outcome = run_plan(parse_plan(plan, "plan.toml"), config, tmp_path, simulate=True,
                       say=lambda line: None)
    assert outcome.stopped_because == "plan done: 2 speeds"
    paths = sorted(tmp_path.glob("speed*.h5"))
    releases = [r for path in paths for r in read_run(path).releases]
    assert len(releases) == 2
    for path, release in zip(paths, releases, strict=True):
        assert release.hold is not None
        with h5py.File(path, "r") as f:
            events = f["/entry/events"][:]
            sync_time = f["/entry/sync/time"][:]
            # A release's columns (those the reader reads a hold of), NaN where a late
            # instrument's block left a row without its data.
            late = ~np.all([np.isfinite(f[f"/entry/sync/{name}"][:])
                            for name in ("h", "alpha", "lift", "moment")], axis=0)
        release_time = next(float(row["time"]) for row in events if row["kind"] == b"release")
        arm = min(float(row["time"]) for row in events if row["kind"] == b"arm")
        # The plan's hold, as the file records it: armed 11 s before the release, plus the
        # arm and release commands' own time (tens of ms; 0.24 s and once 1.45 s seen on a
        # host running the whole suite). The upper bound catches a hold waited twice, not a
        # slow host.
        assert 11.0 <= release_time - arm < 2 * 11.0
        # Read back from 0.25 s after the arm to 0.05 s before the release (10.7 s), less a
        # sync row or two at each end: 10.74 s measured. Rows that a busy host's late scanner
        # or laser blocks left without data (NaN in /entry/sync, 0.42 s once) are not a hold's:
        # the hold starts after the last of them (a CI run once read 6.96 s where the forces
        # alone would have left 7.86: a laser's late rows came after the scanner's).
        window = (sync_time >= arm + 0.25) & (sync_time < release_time - 0.05)
        lost = float(np.sum(late & window)) * float(np.median(np.diff(sync_time)))
        start = max(arm + 0.25, float(sync_time[late & window].max(initial=-np.inf)))
        assert release.hold.duration == pytest.approx(release_time - 0.05 - start, abs=0.02)
        # Not the default 0.5 s hold (0.2 s read back) nor 2 x 11 s; late rows 3 s into the
        # hold were seen on a loaded host, hence 5 s and not 10.
        assert 5.0 <= release.hold.duration < 2 * 11.0 - 0.3
        assert lost < 1.0  # late rows are a moment's, not the hold's
    # The wind-on time counts the holds: two speeds of at least 11 s + 3 s.
    assert outcome.wind_on_s is not None and outcome.wind_on_s > 2 * 14.0


def test_a_campaign_resumes_from_the_files_in_its_directory(tmp_path):
    config = parse_rig_config(RIG_TEXT + FAST_FAN, "rig.toml")
    first = run_plan(parse_plan(_fixed([5.0, 7.0]), "plan.toml"), config, tmp_path,
                     simulate=True, say=lambda line: None)
    write_report(first, tmp_path, plots=False)
    recorded = {p.name: p.stat().st_mtime_ns for p in tmp_path.glob("speed*.h5")}
    assert sorted(recorded) == ["speed01_U05.00.h5", "speed02_U07.00.h5"]
    assert first.flutter_speed is not None

    lines: list[str] = []
    previous = json.loads((tmp_path / "campaign.json").read_text())
    # The new speed lies below the highest one held (7 m/s), which the safety bound always
    # allows: above it, 0.9 (U_F - 3 std) from two 4 s releases fell below 8.5 m/s in a CI
    # run (a std above 7 % of U_F), and the plan rightly stopped there.
    second = run_plan(parse_plan(_fixed([5.0, 7.0, 6.0]), "plan.toml"), config, tmp_path,
                      simulate=True, say=lines.append, previous=previous)
    assert second.resumed == 2
    assert [s.U for s in second.steps] == [5.0, 7.0, 6.0], lines
    assert any(line.startswith("resume: 2 speed(s) read back") for line in lines)
    # The earlier files were read, not recorded again; only the third speed is new.
    assert {p.name: p.stat().st_mtime_ns for p in tmp_path.glob("speed0[12]*.h5")} == recorded
    assert (tmp_path / "speed03_U06.00.h5").exists()
    assert not any(line.startswith("[speed 1]") or line.startswith("[speed 2]")
                   for line in lines)
    assert second.stopped_because == "plan done: 3 speeds"
    assert second.wind_on_s > first.wind_on_s  # carried on, plus this session's
    assert second.analysis is not None and second.analysis.n_releases == 3


def test_ctrl_c_catches_the_model_stops_the_fan_and_finishes_the_file(tmp_path):
    config = parse_rig_config(RIG_TEXT + FAST_FAN, "rig.toml")
    plan = parse_plan(_fixed([5.0, 7.0], releases=2), "plan.toml")
    lines: list[str] = []

    def say(line: str) -> None:
        lines.append(line)
        if line.startswith("  release 1/2"):  # the operator presses Ctrl-C after a release
            _thread.interrupt_main()

    outcome = run_plan(plan, config, tmp_path, simulate=True, say=say)

    assert outcome.stopped_because == "interrupted by the operator (Ctrl-C)", lines
    assert outcome.steps == []  # the interrupted speed does not count: a resume repeats it
    assert not list(tmp_path.glob("speed01_U05.00.h5"))
    path = tmp_path / "speed01_U05.00.interrupted.h5"
    with h5py.File(path, "r") as f:  # finished and readable
        kinds = [row["kind"].decode() for row in f["/entry/events"][:]]
        assert f["/entry/releases"].shape[0] == 1
    assert kinds.count("release") == 1
    last = len(kinds) - 1 - kinds[::-1].index("release")
    assert "arm" in kinds[last:] and "fan_stop" in kinds[last:]
    assert any(line.startswith("fan stopped") for line in lines)
    assert not any(line.startswith("[speed 2]") for line in lines)


def test_one_file_per_release_each_fitted_when_closed_and_resumed_by_speed(tmp_path):
    config = parse_rig_config(RIG_TEXT + FAST_FAN, "rig.toml")
    text = _fixed([5.0, 7.0], releases=2).replace("calz_end = false",
                                                  'calz_end = false\nfiles = "per_release"')
    lines: list[str] = []
    outcome = run_plan(parse_plan(text, "plan.toml"), config, tmp_path, simulate=True,
                       say=lines.append)

    names = sorted(p.name for p in tmp_path.glob("speed*.h5"))
    assert names == ["speed01_U05.00_r01.h5", "speed01_U05.00_r02.h5",
                     "speed02_U07.00_r01.h5", "speed02_U07.00_r02.h5"]
    for name in names:  # one release per file, each with its own fan set-point event
        with h5py.File(tmp_path / name, "r") as f:
            assert f["/entry/releases"].shape[0] == 1
        assert _fan_set_points(tmp_path / name)[-1] == pytest.approx(100 * float(name[9:14]))
    # A host stall can leave a marked gap just after a release, which is then left out of the
    # fits (seen once in CI with the pure tests running beside: a 1.3 s gap); one, not more.
    left_out = sum("left out: a gap" in line for line in lines)
    assert left_out <= 1, lines
    # Live: a speed's first release's modal fit is reported before its second is taken.
    fits = [i for i, line in enumerate(lines) if line.startswith("  release 1: f_h")]
    takes = [i for i, line in enumerate(lines) if line.startswith("  release 2/2")]
    assert any(f < t for f in fits for t in takes), lines
    assert [len(s.paths) for s in outcome.steps] == [2, 2]
    assert [s.releases for s in outcome.steps] == [2, 2]
    assert outcome.analysis is not None and outcome.analysis.n_releases == 4 - left_out
    assert outcome.stopped_because == "plan done: 2 speeds"

    # A resume reads the four files back as two speeds and records only the new one.
    # (The new speed below the highest held one: the safety bound always allows it.)
    more = text.replace("[5.0, 7.0]", "[5.0, 7.0, 6.0]")
    again: list[str] = []
    second = run_plan(parse_plan(more, "plan.toml"), config, tmp_path, simulate=True,
                      say=again.append)
    assert second.resumed == 2 and [s.U for s in second.steps] == [5.0, 7.0, 6.0], again
    assert [s.releases for s in second.steps] == [2, 2, 2]
    assert (tmp_path / "speed03_U06.00_r02.h5").exists()
    # (the new speed can lose one release to a stall too)
    assert second.analysis is not None and second.analysis.n_releases >= 6 - left_out - 1
