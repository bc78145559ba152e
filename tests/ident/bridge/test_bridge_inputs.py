"""The bridge's inputs checked: every default taken is recorded, implausible modes are named.

Each awkward bridge is the shipped example bridge (six modes, 800 m span; equivalent deck masses
10 281 to 22 740 kg/m) or its mode tables with one thing changed.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import pytest

from daq.cli import main
from ident.bridge.mode_tables import bridge_from_mode_tables
from ident.bridge.model import BridgeModel
from ident.model import flat_plate

from support.configs import BRIDGES

BRIDGE = BRIDGES / "example_bridge.json"
MODE_ORDER = ("L1S", "V1A", "V1S", "V2S", "T1S", "T1A")


def _example_with(tmp_path: Path, change) -> Path:
    """Write the example bridge file with ``change(data)`` applied to tmp_path."""
    data = json.loads(BRIDGE.read_text())
    change(data)
    path = tmp_path / "bridge.json"
    path.write_text(json.dumps(data))
    return path


def test_the_example_bridge_takes_no_default_and_raises_no_warning():
    bridge = BridgeModel.from_json(BRIDGE)
    assert bridge.defaults == () and bridge.warnings == ()


def test_a_mode_without_generalised_mass_is_recorded_and_flagged(tmp_path: Path):
    """The issue's case: V1S's mass left out defaults to 1 kg beside masses of ~1e7 to 1e9."""
    path = _example_with(tmp_path, lambda d: d["modes"][2].pop("generalised_mass"))
    bridge = BridgeModel.from_json(path)
    assert bridge.modes[2].generalised_mass == 1.0
    assert bridge.defaults == (f"{path}: modes[2] (V1S): no generalised_mass: taken as 1 kg "
                               "(shapes normalised to a unit modal mass)",)
    assert len(bridge.warnings) == 1
    warning = bridge.warnings[0]
    # 1 kg over int h^2 dx = 400 m (a half sine of unit amplitude over 800 m).
    assert warning.startswith(f"{path}: modes[2] (V1S): generalised_mass = 1 kg (the default: "
                              "give the mode's generalised_mass) gives an equivalent deck mass "
                              "of 0.0025 kg/m, lighter than any deck")


def test_a_mode_table_without_generalised_mass_is_named_by_its_file(tmp_path: Path):
    folder = tmp_path / "modes"
    shutil.copytree(BRIDGES / "example_modes", folder)
    table = folder / "V1S.csv"
    table.write_text("".join(line for line in table.read_text().splitlines(keepends=True)
                             if not line.startswith("# generalised_mass")))
    template = BRIDGES / "example_deck.json"
    bridge = bridge_from_mode_tables(json.loads(template.read_text()),
                                     [folder / f"{n}.csv" for n in MODE_ORDER],
                                     source=str(template))
    assert bridge.defaults == (f"{table} (V1S): no generalised_mass: taken as 1 kg (shapes "
                               "normalised to a unit modal mass)",)
    assert len(bridge.warnings) == 1 and bridge.warnings[0].startswith(
        f"{table} (V1S): generalised_mass = 1 kg (the default")


def test_a_generalised_mass_a_thousand_times_too_large_is_named(tmp_path: Path):
    """T1A's mass x 1e3 (tonnes read as kg): only T1A flagged, 1e3 times the others' median."""
    def heavier(data):
        data["modes"][5]["generalised_mass"] *= 1e3

    path = _example_with(tmp_path, heavier)
    bridge = BridgeModel.from_json(path)
    assert bridge.defaults == ()
    assert bridge.warnings == (
        f"{path}: modes[5] (T1A): generalised_mass = 9.88e+11 kg gives an equivalent deck mass "
        "of 1.03e+07 kg/m, 452 times the median of the other modes' (2.27e+04 kg/m): a mass in "
        "other units or normalisation, or a mode with little deck motion (a tower's or a "
        "cable's)?",)


def test_a_mode_with_no_deck_motion_is_an_error_naming_file_and_mode(tmp_path: Path):
    def still(data):
        data["modes"][4]["alpha"] = [0.0] * len(data["nodes_x"])

    path = _example_with(tmp_path, still)
    with pytest.raises(ValueError, match=rf"^{path}: modes\[4\] \(T1S\): no deck motion: h, "
                                         r"alpha and p are zero at every deck node"):
        BridgeModel.from_json(path)
    folder = tmp_path / "modes"
    shutil.copytree(BRIDGES / "example_modes", folder)
    table = folder / "T1S.csv"
    lines = table.read_text().splitlines()
    header = lines.index("x,alpha")
    table.write_text("\n".join(lines[:header + 1] + [line.split(",")[0] + ",0.0"
                                                     for line in lines[header + 1:]]) + "\n")
    with pytest.raises(ValueError, match=rf"^{table} \(T1S\): no deck motion"):
        bridge_from_mode_tables({"B": 31.0, "rho": 1.22}, [folder / f"{n}.csv" for n in MODE_ORDER])


def test_missing_damping_and_rho_are_taken_and_recorded(tmp_path: Path):
    def bare(data):
        del data["rho"]
        del data["modes"][0]["damping"]

    path = _example_with(tmp_path, bare)
    bridge = BridgeModel.from_json(path)
    assert bridge.rho == 1.225 and bridge.modes[0].damping == 0.003
    assert bridge.defaults == (
        f"{path}: no air density rho: taken as 1.225 kg/m^3 (ISA sea level)",
        f"{path}: modes[0] (L1S): no damping: taken as 0.003 (ratio; a welded steel deck's)")
    assert bridge.warnings == ()


def test_windrig_bridge_prints_and_records_the_defaults_and_warnings(tmp_path: Path, capsys):
    """Through the command line: printed, and in the JSON under defaults and warnings."""
    def careless(data):
        del data["rho"]
        data["modes"][2].pop("generalised_mass")

    path = _example_with(tmp_path, careless)
    model = tmp_path / "plate.json"
    model.write_text(json.dumps(flat_plate.jones_model().to_dict()))
    out = tmp_path / "result.json"
    assert main(["bridge", str(path), "--aero", str(model), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"default: {path}: no air density rho: taken as 1.225 kg/m^3" in text
    assert f"default: {path}: modes[2] (V1S): no generalised_mass: taken as 1 kg" in text
    assert f"warning: {path}: modes[2] (V1S): generalised_mass = 1 kg (the default" in text
    result = json.loads(out.read_text())
    assert result["defaults"] == [
        f"{path}: no air density rho: taken as 1.225 kg/m^3 (ISA sea level)",
        f"{path}: modes[2] (V1S): no generalised_mass: taken as 1 kg (shapes normalised to a "
        "unit modal mass)"]
    # The bridge's own warnings join the others of the result (the aerodynamics' notes).
    mine = [w for w in result["warnings"] if w.startswith(f"{path}: ")]
    assert len(mine) == 1 and mine[0].startswith(f"{path}: modes[2] (V1S): generalised_mass = "
                                                 "1 kg")


def test_windrig_bridge_warns_of_a_shifted_table_column(tmp_path: Path, capsys):
    """The issue's A2* + 0.15 at every row of the example table: named in print and JSON."""
    lines = (BRIDGES / "example_deck_table.csv").read_text().splitlines()
    header = lines.index("K,H1,H2,H3,H4,A1,A2,A3,A4")
    shifted = lines[:header + 1]
    for line in lines[header + 1:]:
        cells = line.split(",")
        cells[6] = repr(float(cells[6]) + 0.15)
        shifted.append(",".join(cells))
    table = tmp_path / "shifted.csv"
    table.write_text("\n".join(shifted) + "\n")
    out = tmp_path / "result.json"
    assert main(["bridge", str(BRIDGE), "--aero", str(table), "--json", str(out),
                 "--u-max", "100"]) == 0
    assert f"warning: {table}: A2* tends to +0.194, not to zero" in capsys.readouterr().out
    result = json.loads(out.read_text())
    assert result["defaults"] == []
    # The table's warnings join the others of the result (the routes', the fit's).
    assert [w.split(", not")[0] for w in result["warnings"]
            if w.startswith(f"{table}: ")] == [f"{table}: A2* tends to +0.194"]


def _mass_ratio_of_the_example() -> float:
    """Return the example deck's mass ratio m / (rho B^2) (the guide's 22 740 kg/m)."""
    return 22740.0 / (1.22 * 31.0**2)


@pytest.mark.parametrize(("change", "cause"), [
    ("tonnes", "the generalised masses look given in tonnes"),
    ("mass-normalised", "the shapes look mass-normalised (generalised mass 1 kg) while "
                        "generalised_mass gives the finite-element program's modal mass"),
    ("mm", "h and p look given in mm (shapes in m, generalised masses in kg)"),
])
def test_a_slip_made_in_every_mode_is_named_by_the_deck_mass_ratio(tmp_path: Path, change,
                                                                   cause):
    """Every mode's mass in tonnes, or shapes mass-normalised with the FE's modal mass kept.

    The modes then agree with each other, so the spread between modes saw nothing, and the
    example bridge flutters at 77.13 m/s with the flat plate but gave "no flutter" without a
    word. The median equivalent deck mass over rho B^2 is the deck's mass ratio, 19.4 for
    the example (22 740 kg/m, B = 31 m, rho = 1.22); undoing the slip gives it back.
    """
    def slip(data):
        for mode in data["modes"]:
            scale = 1.0 / math.sqrt(mode["generalised_mass"])
            if change == "tonnes":
                mode["generalised_mass"] /= 1e3
            for key in ("h", "alpha", "p") if change == "mass-normalised" else ("h", "p"):
                if key in mode and change != "tonnes":
                    factor = scale if change == "mass-normalised" else 1e3
                    mode[key] = [factor * value for value in mode[key]]

    path = _example_with(tmp_path, slip)
    bridge = BridgeModel.from_json(path)
    (found,) = [w for w in bridge.warnings if "mass ratio" in w]
    assert found.startswith(f"{path}: the modes' equivalent deck mass per metre (median ")
    assert f"{cause}, which undone gives {_mass_ratio_of_the_example():.3g}" in found, found


def test_the_deck_mass_ratio_spares_the_example_and_one_heavy_mode(tmp_path: Path):
    """One mode's slip is the spread check's (above), not the deck's: the median holds."""
    assert BridgeModel.from_json(BRIDGE).warnings == ()
    path = _example_with(tmp_path, lambda d: d["modes"][5].update(
        generalised_mass=d["modes"][5]["generalised_mass"] * 1e3))
    assert not any("mass ratio" in w for w in BridgeModel.from_json(path).warnings)


def test_a_damping_percentage_given_as_a_ratio_is_warned_of(tmp_path: Path):
    """0.5 meant as 0.5 %: 50 % of critical hid the example's flutter (no flutter below U_max)."""
    def percent(data):
        data["modes"][4]["damping"] = 0.5

    path = _example_with(tmp_path, percent)
    bridge = BridgeModel.from_json(path)
    assert bridge.modes[4].damping == 0.5
    assert bridge.warnings == (
        f"{path}: modes[4] (T1S): damping = 0.5 is 50 % of critical, far above a bridge mode's "
        "structural damping (0.2 % to 2 %): a percentage given as a ratio? 0.5 % is 0.005",)


def test_the_bridge_command_prints_and_records_a_deck_mass_slip(tmp_path: Path, capsys):
    """Tonnes in every mode: the warning printed and in the JSON's warnings."""
    def tonnes(data):
        for mode in data["modes"]:
            mode["generalised_mass"] /= 1e3

    path = _example_with(tmp_path, tonnes)
    model = tmp_path / "model.json"
    model.write_text(json.dumps(flat_plate.jones_model().to_dict()))
    out = tmp_path / "result.json"
    assert main(["bridge", str(path), "--aero", str(model), "--json", str(out)]) == 0
    assert "look given in tonnes" in capsys.readouterr().out
    assert any("look given in tonnes" in w for w in json.loads(out.read_text())["warnings"])
