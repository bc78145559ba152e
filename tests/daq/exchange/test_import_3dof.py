"""``windrig import`` with three degrees of freedom: sway and drag from a lab's CSV.

The bluff deck of ``rig_configs/sim_bluff_deck_3dof.toml`` (its 3x3 aerodynamics,
:func:`simulators.decks.bluff_deck_3dof_model`) released at 7, 9 and 11 m/s with 2 % noise
(as ``tests/daq/offline/test_identify_3dof.py``), each release one CSV: sway in mm positive
upwind, drag as a total over a 0.9 m span positive upwind, the rest SI. Imported, read back as
3-DOF releases and identified.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from daq.cli import main
from ident.model import flutter
from ident.records.run_file import read_run
from simulators.decks import BLUFF_DECK_3DOF, bluff_deck_3dof_model
from simulators.tunnel import simulate_release

SPAN = 0.9  # m
SPEEDS = (7.0, 9.0, 11.0)  # m/s
MAP = """\
config = "sim_bluff_deck_3dof"
span = 0.9
[time]
rate = 200.0
[channels]
h = { column = "h", unit = "m", sign = "down" }
alpha = { column = "alpha", unit = "rad", sign = "nose_up" }
lift = { column = "lift", unit = "N/m", sign = "down" }
moment = { column = "moment", unit = "N m/m", sign = "nose_up" }
p = { column = "sway_mm", unit = "mm", sign = "upwind" }
drag = { column = "drag_N", unit = "N", sign = "upwind" }
[wind]
U = { "deck_0.csv" = 7.0, "deck_1.csv" = 9.0, "deck_2.csv" = 11.0 }
rho = 1.2
[releases]
times = [1.0]
hold = 1.0
"""


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    where = tmp_path_factory.mktemp("sway")
    (where / "map.toml").write_text(MAP)
    section = BLUFF_DECK_3DOF.replace(rho=1.2)
    sources = []
    for k, U in enumerate(SPEEDS):
        r = simulate_release(section, bluff_deck_3dof_model(), U, 0.006, 0.015, p0=0.004,
                             duration=12.0, fs=200.0, noise=0.02, rng=10 * k, pre_s=1.0)
        cols = {"h": r.h, "alpha": r.alpha, "lift": r.lift, "moment": r.moment,
                "sway_mm": -r.p * 1e3, "drag_N": -r.drag * SPAN}
        sources.append(where / f"deck_{k}.csv")
        sources[-1].write_text(",".join(cols) + "\n" + "\n".join(
            ",".join(repr(float(x)) for x in row) for row in np.column_stack(list(cols.values()))))
    assert main(["import", *map(str, sources), "--map", str(where / "map.toml"),
                 "--out", str(where / "runs")]) == 0
    return where


def test_sway_and_drag_arrive_in_windrig_signs(imported):
    record = read_run(imported / "runs" / "deck_0.h5")
    assert record.section.n_dof == 3 and len(record.releases) == 1
    release = record.releases[0]
    # The released sway, 4 mm downwind, plus 2 % noise of its RMS.
    assert release.p[0] == pytest.approx(0.004, abs=4e-4)
    assert release.U == 7.0


def test_the_imported_3dof_campaign_identifies(imported, capsys):
    out = imported / "model.json"
    assert main(["identify", *map(str, sorted((imported / "runs").glob("*.h5"))),
                 "--json", str(out)]) == 0
    capsys.readouterr()
    speed = json.loads(out.read_text())["flutter_speed"]
    truth = flutter.analyze(BLUFF_DECK_3DOF.replace(rho=1.2), bluff_deck_3dof_model()).speed
    print(f"3dof: {speed:.3f} m/s, truth {truth:.3f} m/s, error {speed / truth - 1:+.2%}")
    # One release per speed (the identify test has two): 2 % allowed, twice that test's 1 %.
    assert speed == pytest.approx(truth, rel=0.02)
