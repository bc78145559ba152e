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
