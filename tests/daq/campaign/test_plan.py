"""PLAN.toml validation: every mistake is a ConfigError naming the key and what is allowed."""

from __future__ import annotations

import pytest

from daq.campaign import plan as plan_module
from daq.campaign.plan import load_plan, parse_plan
from daq.cli import main
from daq.config import load_rig_config
from daq.errors import ConfigError
from ident.identification import e2rfc

from support.configs import REPO, SIM_FLAT_PLATE

RIG = SIM_FLAT_PLATE

FIXED = """
[campaign]
mode = "fixed"
releases_per_speed = 2
decay_s = 5.0

[speeds]
wind_speeds = [5.0, 7.0]
"""

ADAPTIVE = """
[campaign]
mode = "adaptive"

[speeds]
wind_speeds = [5.0, 7.0]

[adaptive]
target_std = 0.01
candidate_min = 5.0
candidate_max = 11.0
candidate_step = 0.5
"""


def test_example_plans_load_and_fit_the_default_rig():
    config = load_rig_config(RIG)
    for name in ("fixed", "adaptive"):
        plan = load_plan(REPO / "rig_configs" / "plans" / f"{name}.toml")
        plan.check_against(config)
        assert plan.mode == name
    adaptive = load_plan(REPO / "rig_configs" / "plans" / "adaptive.toml").adaptive
    assert adaptive is not None
    assert adaptive.candidates()[0] == 5.0 and adaptive.candidates()[-1] == 11.0


def test_defaults_and_candidates():
    plan = parse_plan(ADAPTIVE, "p.toml")
    assert plan.releases_per_speed == 2 and plan.decay_s is None
    assert plan.settle_s == 1.0 and plan.calz_start and plan.calz_end
    assert plan.files == "per_speed"
    assert parse_plan(FIXED.replace("decay_s = 5.0", 'decay_s = 5.0\nfiles = "per_release"')
                      ).files == "per_release"
    assert plan.decay_end == "fixed" and plan.turbulent_estimator == "ml"
    # The plan's names and default (kept in daq: parsing a plan imports no numerics) are
    # E2RFC's.
    assert plan_module.TURBULENT_ESTIMATORS == e2rfc.TURBULENT_ESTIMATORS
    assert plan.turbulent_estimator == e2rfc.TURBULENT_ESTIMATOR
    assert plan_module.CLOSED_LOOP_BUFFETINGS == e2rfc.CLOSED_LOOP_BUFFETING_CHOICES
    assert plan.closed_loop_buffeting == e2rfc.CLOSED_LOOP_BUFFETING
    assert parse_plan(FIXED.replace("decay_s = 5.0", 'decay_s = 5.0\nclosed_loop_buffeting = '
                                    '"fourth-order"')).closed_loop_buffeting == "fourth-order"
    assert parse_plan(FIXED.replace("decay_s = 5.0", 'decay_s = 5.0\nturbulent_estimator = "iv"')
                      ).turbulent_estimator == "iv"
    assert plan.hold_s == 0.5  # daq.procedure.HOLD_S, the console's
    assert parse_plan(FIXED.replace("decay_s = 5.0", "decay_s = 5.0\nhold_s = 11")).hold_s == 11.0
    assert parse_plan(FIXED.replace("decay_s = 5.0", 'decay_s = 5.0\ndecay_end = "settled"')
                      ).decay_end == "settled"
    assert plan.adaptive is not None
    assert plan.adaptive.safety_fraction == 0.9
    assert len(plan.adaptive.candidates()) == 13
    assert plan.adaptive.release_options() == []  # the plan's releases_per_speed everywhere
    chosen = parse_plan(ADAPTIVE + "max_releases_per_speed = 3\n").adaptive
    assert chosen is not None and chosen.release_options() == [1, 2, 3]


def test_fan_set_points_become_wind_speeds():
    plan = parse_plan(FIXED.replace("wind_speeds = [5.0, 7.0]", "fan_rpm = [500, 700]"))
    assert plan.listed_speeds(0.01) == pytest.approx([5.0, 7.0])


@pytest.mark.parametrize("old, new, match", [
    ('mode = "fixed"', 'mode = "random"', r"mode = 'random'; allowed: fixed, adaptive"),
    ("releases_per_speed = 2", "releases_per_speed = 0",
     r"releases_per_speed = 0 must be an integer in \[1, 20\]"),
    ("decay_s = 5.0", "decay_s = 0.5", r"decay_s = 0.5 is outside the allowed range \[1.0"),
    ("decay_s = 5.0", "decay_s = 5.0\nsettle = 1", r"unknown key\(s\) \['settle'\]"),
    ("wind_speeds = [5.0, 7.0]", "wind_speeds = [5.0, -7.0]",
     r"wind_speeds\[1\] = -7.0 is outside the allowed range \(0, 200\] m/s"),
    ("wind_speeds = [5.0, 7.0]", "wind_speeds = [5.0]\nfan_rpm = [500]",
     r"exactly one of wind_speeds"),
    ("wind_speeds = [5.0, 7.0]", 'wind_speeds = ["5.0", 7.0]',
     r"wind_speeds\[0\] must be a number \(m/s\), got '5.0'"),
    ("wind_speeds = [5.0, 7.0]", "wind_speeds = {low = 5.0}",
     r"wind_speeds must be a non-empty list of numbers \(m/s\)"),
    ("decay_s = 5.0", "decay_s = 5.0\ncalz_end = 1", r"calz_end must be true or false"),
    ("decay_s = 5.0", 'decay_s = 5.0\nfiles = "per_run"',
     r"files = 'per_run'; allowed: per_speed, per_release"),
    ("decay_s = 5.0", 'decay_s = 5.0\ndecay_end = "noise"',
     r"\[campaign\] decay_end = 'noise'; allowed: fixed, settled"),
    ("decay_s = 5.0", "decay_s = 5.0\nhold_s = 0.0",
     r"\[campaign\] hold_s = 0.0 is outside the allowed range \[0.1, 600.0\]"),
    ("decay_s = 5.0", 'decay_s = 5.0\nturbulent_estimator = "kalman"',
     r"\[campaign\] turbulent_estimator = 'kalman'; allowed: iv, ml"),
    ("decay_s = 5.0", 'decay_s = 5.0\nclosed_loop_buffeting = "white"',
     r"\[campaign\] closed_loop_buffeting = 'white'; allowed: second-order, fourth-order"),
])
def test_fixed_plan_errors_name_the_key(old, new, match):
    assert old in FIXED
    with pytest.raises(ConfigError, match=match):
        parse_plan(FIXED.replace(old, new), "p.toml")


@pytest.mark.parametrize("old, new, match", [
    ("target_std = 0.01", "target_std = 0.0",
     r"\[adaptive\] target_std = 0.0 is outside the allowed range \(0.0, 0.5\]"),
    ("target_std = 0.01", "target_std = 0.01\nsafety_fraction = 1.5",
     r"safety_fraction = 1.5 is outside the allowed range \(0.0, 1.0\]"),
    ("candidate_max = 11.0", "candidate_max = 4.0",
     r"candidate_max = 4.0 is outside the allowed range \[5.0, 200.0\]"),
    ("wind_speeds = [5.0, 7.0]", "wind_speeds = [5.0]", r"two or more distinct first speeds"),
    ("target_std = 0.01", "target_std = 0.01\nmax_speeds = 1",
     r"max_speeds = 1 must be an integer in \[2, 50\]"),
    ("target_std = 0.01", "target_std = 0.01\nmax_releases_per_speed = 0",
     r"\[adaptive\] max_releases_per_speed = 0 must be an integer in \[1, 20\]"),
])
def test_adaptive_plan_errors_name_the_key(old, new, match):
    assert old in ADAPTIVE
    with pytest.raises(ConfigError, match=match):
        parse_plan(ADAPTIVE.replace(old, new), "p.toml")


def test_adaptive_table_needs_adaptive_mode_and_vice_versa():
    with pytest.raises(ConfigError, match=r"needs an \[adaptive\] table"):
        parse_plan(ADAPTIVE.split("[adaptive]")[0])
    with pytest.raises(ConfigError, match=r"only for mode = \"adaptive\""):
        parse_plan(ADAPTIVE.replace('mode = "adaptive"', 'mode = "fixed"'))


def test_a_speed_above_the_rig_limit_is_refused_before_anything_starts():
    config = load_rig_config(RIG)  # max_wind_speed 11 m/s
    plan = parse_plan(FIXED.replace("[5.0, 7.0]", "[5.0, 12.0]"), "p.toml")
    with pytest.raises(ConfigError, match=r"12 m/s is above the rig's limit 11 m/s"):
        plan.check_against(config)


def test_cli_reports_a_bad_plan_in_one_line(tmp_path, capsys):
    plan = tmp_path / "plan.toml"
    plan.write_text(FIXED.replace("releases_per_speed = 2", "releases_per_speed = 99"))
    code = main(["campaign", str(plan), "--config", str(RIG), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("error: ") and err.count("\n") == 1
    assert "releases_per_speed = 99" in err
    assert not (tmp_path / "out").exists()  # nothing started


def test_cli_refuses_auto_urls_without_simulate(tmp_path, capsys):
    plan = tmp_path / "plan.toml"
    plan.write_text(FIXED)
    code = main(["campaign", str(plan), "--config", str(RIG), "--out", str(tmp_path / "out")])
    assert code == 2
    assert "url = 'auto'" in capsys.readouterr().err


def test_candidates_above_the_rig_limit_are_refused_before_anything_starts():
    """Candidates in km/h (x 3.6) pass the parser's range but not the rig: refused up front.

    Before, only the listed speeds were checked: the campaign started, recorded its first
    speeds and then found every candidate above the bound.
    """
    config = load_rig_config(RIG)  # limit 11 m/s
    plan = parse_plan(ADAPTIVE.replace("candidate_min = 5.0", "candidate_min = 18.0")
                      .replace("candidate_max = 11.0", "candidate_max = 39.6"), "kmh.toml")
    with pytest.raises(ConfigError, match=r"kmh.toml \[adaptive\] candidate_max = 39.6 m/s is "
                                          r"above the rig's limit 11 m/s .*<= 11"):
        plan.check_against(config)
    parse_plan(ADAPTIVE, "p.toml").check_against(config)  # candidate_max = the limit: fine


@pytest.mark.parametrize("speeds, mode, refused", [
    ("[11.0, 13.0]", "adaptive", "11 m/s"),  # the first speed already beyond flutter
    ("[6.0, 10.8, 12.0]", "fixed", "10.8 m/s"),  # the second: still no estimate
    ("[6.0, 6.05, 10.8]", "fixed", "10.8 m/s"),  # 6.05 is 6.0 again for E2RFC: 10.8 is blind
])
def test_speeds_set_before_any_estimate_stay_below_the_still_air_prediction(
        tmp_path, speeds, mode, refused):
    """Blind speeds above 0.9 x the flat plate's flutter speed of the section are refused.

    The flat-plate rig flutters at 11.8 m/s; with its limits raised to 15 m/s, a plan's first
    speeds up there had no bound at all (no E2RFC estimate yet): only the decay monitor stood
    between the model and flutter.
    """
    rig = tmp_path / "wide.toml"
    rig.write_text(RIG.read_text().replace("max_wind_speed = 11.0", "max_wind_speed = 15.0")
                   .replace("max_fan_rpm = 1300.0", "max_fan_rpm = 1500.0"))
    config = load_rig_config(rig)
    text = (ADAPTIVE.replace("candidate_max = 11.0", "candidate_max = 14.0") if mode == "adaptive"
            else FIXED)
    plan = parse_plan(text.replace("[5.0, 7.0]", speeds), "p.toml")
    with pytest.raises(ConfigError, match=rf"p.toml \[speeds\]: {refused} is set before any "
                                          r"flutter estimate and is above 0.9 x 11.8 m/s"):
        plan.check_against(config)
    # Once E2RFC has its first estimate (after two distinct speeds) that bounds the rest.
    parse_plan(FIXED.replace("[5.0, 7.0]", "[6.0, 8.0, 12.0]")).check_against(config)


def test_a_config_limit_above_the_drives_full_scale_is_one_error_line(tmp_path, capsys):
    """``max_fan_rpm`` above the fan's ``max_rpm``: the config is refused, nothing starts.

    Before, the plan check passed 16 m/s (1600 rpm), the campaign zeroed the scanner, started
    recording, and the drive's SafetyError came as a traceback and two error lines.
    """
    rig = tmp_path / "rig.toml"
    rig.write_text(RIG.read_text().replace("max_wind_speed = 11.0", "max_wind_speed = 16.0")
                   .replace("max_fan_rpm = 1300.0", "max_fan_rpm = 2000.0"))
    plan = tmp_path / "plan.toml"
    plan.write_text(FIXED)
    out = tmp_path / "out"
    code = main(["campaign", str(plan), "--config", str(rig), "--simulate", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith(f"error: {rig} [limits] max_fan_rpm = 2000 is above [fan] max_rpm "
                          "= 1500")
    assert not out.exists()  # nothing started


def test_every_default_the_plan_takes_is_named_with_its_value():
    """No silent default: what the plan left out is listed, resolved on the rig.

    Before, a plan without decay_s recorded 7.5 s decays, and one without release = ... used
    the PLC, with nothing said.
    """
    config = load_rig_config(RIG)  # a PLC; its [fan] gives no ramp_rpm_per_s
    taken = parse_plan(ADAPTIVE, "p.toml").defaults_taken(config)
    assert "decay_s = 7.5 s (15 periods of the slower mode)" in taken
    assert "release = 'auto' (here: plc)" in taken and "safety_fraction = 0.9" in taken
    assert "releases_per_speed = 2" in taken and "hold_s = 0.5 s" in taken
    assert f"[fan] ramp_rpm_per_s = 100 rpm/s (not in {RIG})" in taken
    assert not any(line.startswith(("mode", "target_std", "candidate_max", "candidate_step"))
                   for line in taken)  # required, or given
    given = parse_plan(FIXED.replace("decay_s = 5.0", 'decay_s = 5.0\nrelease = "plc"'))
    assert not any(line.startswith(("decay_s", "release ", "releases_per_speed"))
                   for line in given.defaults_taken(config))
