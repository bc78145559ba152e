"""A campaign checks before the fan turns that the rig can release and identify.

Rigs: the shipped simulated flat plate, without its ``[plc]`` (releases by hand), without its
``[scanner]`` (no taps' forces: the displacement-only route must be named), without lasers.
The command line refuses in one ``error:`` line, exit 2, with nothing started or written; the
simulated rig is never started (the check comes first), so these run in well under a second.
"""

from __future__ import annotations

import re
import time

import pytest

from daq.campaign.plan import parse_plan
from daq.campaign.releasing import ManualReleases, PlcReleases, releaser
from daq.cli import main
from daq.config import parse_rig_config
from daq.errors import ConfigError

from support.configs import SIM_FLAT_PLATE

RIG_TEXT = SIM_FLAT_PLATE.read_text()


def _without(table: str, text: str = RIG_TEXT) -> str:
    """Return the rig's text without one of its tables (``[plc]``, ``[scanner]``)."""
    out, n = re.subn(rf"\n\[{table}\]\n(?:[^\[\n].*\n|\n)*", "\n", text)
    assert n == 1
    return out


def _without_lasers(text: str = RIG_TEXT) -> str:
    out, n = re.subn(r"^\[\[lasers\]\]\n(?:[^\[\n].*\n|\n)*", "", text, flags=re.M)
    assert n == 3
    return out


def _plan(extra: str = "", speeds: str = "[5.0, 7.0]", mode: str = "fixed") -> str:
    adaptive = ("\n[adaptive]\ntarget_std = 0.01\ncandidate_min = 5.0\ncandidate_max = 10.0\n"
                if mode == "adaptive" else "")
    return (f'[campaign]\nmode = "{mode}"\ndecay_s = 4.0\n{extra}\n'
            f"[speeds]\nwind_speeds = {speeds}\n{adaptive}")


def _check(plan_text: str, rig_text: str) -> None:
    plan = parse_plan(plan_text, "plan.toml")
    config = parse_rig_config(rig_text, "rig.toml")
    plan.check_against(config)
    plan.check_rig(config)


def test_a_rig_without_a_plc_releases_by_hand():
    plan = parse_plan(_plan(), "plan.toml")
    config = parse_rig_config(_without("plc"), "rig.toml")
    plan.check_rig(config)  # no error: the operator's hand
    assert plan.release_method(config) == "manual"
    assert isinstance(releaser(plan.release_method(config)), ManualReleases)
    with_plc = parse_rig_config(RIG_TEXT, "rig.toml")
    assert plan.release_method(with_plc) == "plc"
    assert isinstance(releaser("plc"), PlcReleases)
    manual = parse_plan(_plan('release = "manual"'), "plan.toml")
    assert manual.release_method(with_plc) == "manual"


def test_a_plc_release_on_a_rig_without_a_plc_is_refused():
    with pytest.raises(ConfigError, match=r'release = "plc": rig.toml has no \[plc\]'):
        _check(_plan('release = "plc"'), _without("plc"))


def test_e2rfc_on_a_rig_without_taps_is_refused_naming_the_other_route():
    with pytest.raises(ConfigError, match='no pressure scanner.*identification = "displacement"'):
        _check(_plan(), _without("scanner"))
    # Named, with three speeds in a fixed plan: accepted.
    _check(_plan('identification = "displacement"', "[4.0, 5.0, 6.0]"), _without("scanner"))


def test_the_displacement_route_needs_three_speeds_and_a_fixed_plan():
    with pytest.raises(ConfigError, match="3 or more distinct speeds"):
        _check(_plan('identification = "displacement"'), _without("scanner"))
    with pytest.raises(ConfigError, match='needs mode = "fixed"'):
        _check(_plan('identification = "displacement"', "[4.0, 5.0, 6.0]", "adaptive"),
               _without("scanner"))


def test_a_rig_without_lasers_is_refused():
    with pytest.raises(ConfigError, match="has no lasers"):
        _check(_plan(), _without_lasers())


def test_unknown_release_and_identification_values_are_named():
    with pytest.raises(ConfigError, match=r"release = 'magnet'; allowed: auto, plc, manual"):
        parse_plan(_plan('release = "magnet"'), "plan.toml")
    with pytest.raises(ConfigError, match="identification = 'fd'; allowed: e2rfc, displacement"):
        parse_plan(_plan('identification = "fd"'), "plan.toml")


@pytest.mark.parametrize(("rig", "plan", "message"), [
    (_without("plc"), _plan('release = "plc"'), "has no [plc]"),
    (_without("scanner"), _plan(), "no pressure scanner"),
])
def test_the_command_refuses_in_one_line_before_anything_starts(tmp_path, capsys, rig, plan,
                                                                message):
    (tmp_path / "rig.toml").write_text(rig)
    (tmp_path / "plan.toml").write_text(plan)
    out = tmp_path / "out"
    started = time.monotonic()
    assert main(["campaign", str(tmp_path / "plan.toml"), "--config",
                 str(tmp_path / "rig.toml"), "--simulate", "--out", str(out)]) == 2
    # Before the simulated rig (a process of its own, ~2 s to start) or the fan: at once.
    assert time.monotonic() - started < 2.0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and message in err[0]
    assert not out.exists()


def test_a_prompt_without_an_operator_is_an_error_naming_it(monkeypatch, capsys):
    import io

    from daq.campaign.releasing import ask_on_terminal
    from daq.errors import OperatorError

    monkeypatch.setattr("sys.stdin", io.StringIO("\n"))
    ask_on_terminal("  >>> let the model go")  # Enter: returns
    assert capsys.readouterr().out == "  >>> let the model go\n"
    with pytest.raises(OperatorError, match="no operator: standard input ended at the prompt"):
        ask_on_terminal("  >>> let the model go")  # the input has ended
