"""A campaign on a simulated rig without a PLC and without taps: prompted releases by hand.

The flat-plate rig with its ``[plc]`` and ``[scanner]`` taken out, so nothing on the wire
releases the model and nothing measures forces. The plan names the displacement-only route.
The operator's prompts are answered by the test (``ask``), and the simulated operator's hand
lets the model go through the virtual tunnel (:mod:`daq.campaign.releasing`); the run writer
finds each release in the lasers' signals. Before issue 35 the first release failed after 16 s
(``name the PLC``), and a rig without taps dropped every release after its campaign ("a gap
0.00 s after its release"). Afterwards ``windrig identify`` on the files chooses the
displacement-only route by itself and states its caveats.
"""

from __future__ import annotations

import json
import re

import h5py
import pytest

from daq.campaign.plan import parse_plan
from daq.campaign.runner import run_plan
from daq.cli import main
from daq.config import parse_rig_config
from daq.offline.displacement_route import CAVEATS

from support.configs import SIM_FLAT_PLATE

pytestmark = [pytest.mark.slow, pytest.mark.realtime]

FAST_FAN = "\n[simulation.devices.fan]\nramp_rpm_per_s = 1000.0\n"


def _without(text: str, table: str) -> str:
    out, n = re.subn(rf"\n\[{table}\]\n(?:[^\[\n].*\n|\n)*", "\n", text)
    assert n == 1
    return out


def test_a_campaign_without_plc_or_taps_releases_by_hand_and_keeps_every_release(tmp_path,
                                                                                   capsys):
    rig = _without(_without(SIM_FLAT_PLATE.read_text(),
                            "plc"), "scanner") + FAST_FAN
    config = parse_rig_config(rig, "rig.toml")
    plan = parse_plan("""
[campaign]
mode = "fixed"
releases_per_speed = 1
decay_s = 4.0
settle_s = 0.5
calz_start = false
calz_end = false
identification = "displacement"

[speeds]
wind_speeds = [4.0, 6.0, 8.0]
""", "plan.toml")
    prompts: list[str] = []
    lines: list[str] = []
    outcome = run_plan(plan, config, tmp_path, simulate=True, say=lines.append,
                       ask=prompts.append)
    assert outcome.stopped_because == "plan done: 3 speeds", lines
    assert "releases by hand: the operator is prompted before each hold and release" in lines
    # Per speed: hold, release, then hold again after the decay.
    assert len(prompts) == 9 and sum("let the model go" in p for p in prompts) == 3
    paths = [s.path for s in outcome.steps]
    for step, path in zip(outcome.steps, paths, strict=True):
        assert step.releases == 1, lines  # kept: no forces is no gap on this route
        with h5py.File(path, "r") as f:
            kinds = [k.decode() for k in f["entry/events"]["kind"]]
            assert f["entry/releases"].shape[0] == 1
        assert kinds.count("release_detected") == 1 and "release" not in kinds
    assert not any("gap" in line for line in lines), lines
    # No PLC: no trigger pulse anchors the lasers' clocks, which every file warns of.
    unanchored = [w for w in outcome.recording_warnings if "no PLC trigger pulse" in w]
    assert [w.split(":")[0] for w in unanchored] == [p.name for p in paths], lines
    assert sum("warning: no PLC trigger pulse" in line for line in lines) == len(paths)
    assert any("displacement-only route: identify after the campaign" in line
               for line in lines)

    out = tmp_path / "fd.json"
    capsys.readouterr()
    assert main(["identify", *map(str, paths), "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "route: displacement only (3 of 3 file(s) hold no forces" in printed
    data = json.loads(out.read_text())
    # Each file's unanchored clocks lead, by file, then the route's caveats.
    assert data["warnings"][-len(CAVEATS):] == list(CAVEATS)
    leading = data["warnings"][:-len(CAVEATS)]
    assert [w.split(": recorded with a warning: ")[0] for w in leading] == list(map(str, paths))
    assert all("no PLC trigger pulse reached this file" in w for w in leading)
    assert data["route"] == "displacement_only"
    assert data["flutter_derivatives"]["U"] == pytest.approx([4.0, 6.0, 8.0], rel=0.03)
