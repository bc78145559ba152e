"""The bridge model file and the mode tables: validation, strip-theory integrals, round trips."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from ident.bridge.mode_tables import bridge_from_mode_tables, read_mode_table
from ident.bridge.model import BridgeModel

from support.configs import BRIDGES

MODE_ORDER = ("L1S", "V1A", "V1S", "V2S", "T1S", "T1A")

GOOD = {"name": "t", "B": 20.0, "rho": 1.2, "nodes_x": [0.0, 10.0, 30.0],
        "modes": [{"frequency": 0.2, "damping": 0.01, "generalised_mass": 5.0,
                   "h": [0.0, 1.0, 0.0]},
                  {"frequency": 0.5, "damping": 0.01, "alpha": [0.0, 0.5, 1.0],
                   "p": [0.0, 0.2, 0.0]}],
        "static": {"C_D": 0.1, "C_L": 0.0, "C_M": 0.0, "dC_D": 0.0, "dC_L": -5.0, "dC_M": 1.0}}


def _changed(path: str, value: object) -> dict:
    """Return GOOD with one key (``a.b[1].c``-like, dots and indices) set, or deleted (None)."""
    data = copy.deepcopy(GOOD)
    parts = path.replace("[", ".").replace("]", "").split(".")
    target = data
    for part in parts[:-1]:
        target = target[int(part)] if part.isdigit() else target[part]
    key = int(parts[-1]) if parts[-1].isdigit() else parts[-1]
    if value is None:
        del target[key]
    else:
        target[key] = value
    return data


@pytest.mark.parametrize(("path", "value", "message"), [
    ("B", None, "missing key(s) ['B']"),
    ("modes", None, "missing key(s) ['modes']"),
    ("nodes_x", None, "missing key(s) ['nodes_x']"),
    ("span", 3.0, "unknown key(s) ['span']; allowed: B, modes, name, nodes_x, rho, static"),
    ("B", -31.0, "B = -31: the deck width in m must be > 0 and at most 200"),
    ("B", 31000.0, "B = 31000: the deck width in m"),
    ("B", "31", "B must be a number, got '31'"),
    ("rho", 1220.0, "rho = 1220: the air density in kg/m^3 must be in 0.5 to 2"),
    ("nodes_x", [0.0, 30.0, 10.0], "nodes_x must be strictly increasing (m along the span), "
                                   "but nodes_x[2] = 10 follows 30"),
    ("nodes_x", [0.0], "nodes_x needs at least 2 deck nodes, got 1"),
    ("modes", [], "modes must be a non-empty list"),
    ("modes[0].h", [0.0, 1.0], "modes[0].h has 2 values for 3 nodes_x (m at each deck node)"),
    ("modes[1].alpha", [0, "x", 1], "modes[1].alpha[1] must be a number, got 'x'"),
    ("modes[0].frequency", None, "modes[0]: missing key(s) ['frequency']"),
    ("modes[0].frequency", -0.2, "modes[0].frequency = -0.2: must be > 0 Hz"),
    ("modes[0].damping", 0.5 * 2, "modes[0].damping = 1: the damping ratio must be in [0, 1) "
                                  "(a percentage? 1 % is 0.01)"),
    ("modes[0].damping", -0.01, "modes[0].damping = -0.01: the damping ratio must be in"),
    ("modes[0].generalised_mass", 0.0, "modes[0].generalised_mass = 0: must be > 0 kg"),
    ("modes[0].shape", [1, 2, 3], "modes[0]: unknown key(s) ['shape']"),
    ("modes[0].h", None, "modes[0]: no shape: give at least one of h (m), alpha (rad), p (m)"),
    ("static.C_D", -0.1, "static.C_D = -0.1: drag is positive downwind"),
    ("static.dC_M", None, "static: missing key(s) ['dC_M']"),
])
def test_every_input_problem_has_its_own_clear_error(path, value, message):
    with pytest.raises(ValueError) as info:
        BridgeModel.from_dict(_changed(path, value))
    assert message in str(info.value)


def test_a_file_error_names_the_file(tmp_path: Path):
    bad = tmp_path / "bridge.json"
    bad.write_text('{"B": 3')
    with pytest.raises(ValueError, match=r"bridge.json: not valid JSON \("):
        BridgeModel.from_json(bad)
    with pytest.raises(ValueError, match="nothing.json: no such file"):
        BridgeModel.from_json(tmp_path / "nothing.json")
    bad.write_text(json.dumps(_changed("rho", 0.0)))
    with pytest.raises(ValueError, match=r"bridge.json: rho = 0: the air density"):
        BridgeModel.from_json(bad)


def test_notes_are_remarks_not_errors():
    """Non-orthogonal deck shapes, lift in the other sign, a default density: notes only."""
    data = _changed("static.dC_L", 5.0)
    del data["rho"]
    # The second mode moves the deck much like the first (its pitch moves the edges little).
    data["modes"][1].update(h=[0.0, 0.8, 0.0], alpha=[0.0, 0.005, 0.01])
    bridge = BridgeModel.from_dict(data)
    notes = " | ".join(bridge.notes())
    assert "rho" not in notes  # a default, recorded as such (below)
    assert bridge.defaults[0] == "no air density rho: taken as 1.225 kg/m^3 (ISA sea level)"
    assert "deck-only shapes of modes 1 and 2 are not orthogonal" in notes
    assert "dC_L = 5 > 0" in notes
    assert BridgeModel.from_dict(GOOD).notes() == []


def test_integrals_of_mode_shape_products_by_the_trapezoid_rule():
    """G[i, j] = int Phi_i^T Phi_j dx on uneven nodes (hand-computed trapezoid sums)."""
    bridge = BridgeModel.from_dict(GOOD)
    B = 20.0
    w = np.array([5.0, 15.0, 10.0])  # trapezoid weights of nodes 0, 10, 30
    np.testing.assert_allclose(bridge.quadrature_weights(), w)
    G = bridge.shape_integrals()
    h1, a2, p2 = np.array([0, 1, 0]) / B, np.array([0, 0.5, 1.0]), np.array([0, 0.2, 0]) / B
    assert G[0, 0, 0, 0] == pytest.approx(w @ (h1 * h1), rel=1e-14)
    assert G[0, 1, 0, 1] == pytest.approx(w @ (h1 * a2), rel=1e-14)
    assert G[1, 1, 1, 1] == pytest.approx(w @ (a2 * a2), rel=1e-14)
    assert G[2, 1, 1, 1] == pytest.approx(w @ (p2 * a2), rel=1e-14)
    assert G[1, 0, 0, 0] == 0.0
    # A section matrix with a single entry projects onto that entry's integral.
    A = np.zeros((3, 3))
    A[0, 1] = 2.0
    np.testing.assert_allclose(bridge.modal_coefficients(A), 2.0 * G[0, 1], rtol=1e-14)
    # Two degrees of freedom use the heave-pitch block only.
    np.testing.assert_allclose(bridge.modal_coefficients(A[:2, :2]), 2.0 * G[0, 1])
    with pytest.raises(ValueError, match="section matrices must be"):
        bridge.modal_coefficients(np.zeros((4, 4)))
    # The load matrix is the same quadrature: F_r = int (L h_r + M alpha_r + D p_r) dx.
    loads = np.array([[100.0, 10.0, 1.0]] * 3)
    F = np.einsum("rnc,nc->r", bridge.load_matrix(), loads)
    assert F[1] == pytest.approx(w @ (10.0 * np.array([0, 0.5, 1.0]) + np.array([0, 0.2, 0])))


def test_to_dict_round_trip_and_labels():
    bridge = BridgeModel.from_json(BRIDGES / "example_bridge.json")
    again = BridgeModel.from_dict(json.loads(json.dumps(bridge.to_dict())))
    assert again.to_dict() == bridge.to_dict()
    assert bridge.mode_kinds() == ["lateral", "vertical", "vertical", "vertical", "torsional",
                                   "torsional"]
    assert bridge.mode_labels()[4] == "T1S (0.28 Hz, torsional)"


def test_mode_tables_give_the_example_bridge():
    """The shipped mode tables (one CSV per mode) plus the deck data are the example bridge."""
    template = json.loads((BRIDGES / "example_deck.json").read_text())
    paths = [BRIDGES / "example_modes" / f"{name}.csv" for name in MODE_ORDER]
    built = bridge_from_mode_tables(template, paths)
    assert built.to_dict() == BridgeModel.from_json(BRIDGES / "example_bridge.json").to_dict()


def test_a_pitch_in_degrees_is_named_so_and_converted(tmp_path: Path):
    path = tmp_path / "t1.csv"
    path.write_text("# frequency = 0.3\n# damping = 0.005\nx,alpha_deg\n0,0\n"
                    "10,57.29577951308232\n")
    x, entry = read_mode_table(path)
    assert x.tolist() == [0.0, 10.0]
    assert entry["alpha"] == pytest.approx([0.0, 1.0], rel=1e-15)
    assert entry["frequency"] == 0.3 and "h" not in entry


@pytest.mark.parametrize(("text", "message"), [
    ("x,h\n0,0\n", "no '# frequency = ...' line above the header"),
    ("# frequency = 0.1\n# damping = 0.01\n# mass = 3\nx,h\n0,0\n",
     "line 3: unknown key 'mass'; allowed: frequency, damping, generalised_mass, name"),
    ("# frequency = 0.1\n# damping = 0.01\nh,x\n0,0\n", "line 3: the first column must be x"),
    ("# frequency = 0.1\n# damping = 0.01\nx,z\n0,0\n", "line 3: unknown column(s) ['z']"),
    ("# frequency = 0.1\n# damping = 0.01\nx,h\n0,0\n1,a\n", "line 5: 'a' is not a number"),
    ("# frequency = 0.1\n# damping = 0.01\nx,h\n0,0\n1\n", "line 5: 1 values for 2 columns"),
    ("# frequency = fast\n# damping = 0.01\nx,h\n0,0\n", "frequency: 'fast' is not a number"),
    ("# frequency = 0.1\n# damping = 0.01\nx,alpha,alpha_deg\n0,0,0\n", "a column appears twice"),
    ("# frequency = 0.1\n# damping = 0.01\n", "no table"),
])
def test_bad_mode_tables_get_one_clear_error(tmp_path: Path, text: str, message: str):
    path = tmp_path / "mode.csv"
    path.write_text(text)
    with pytest.raises(ValueError) as info:
        read_mode_table(path)
    assert message in str(info.value) and "mode.csv" in str(info.value)


def test_mode_tables_must_share_their_nodes(tmp_path: Path):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    a.write_text("# frequency = 0.1\n# damping = 0.01\nx,h\n0,0\n10,1\n")
    b.write_text("# frequency = 0.2\n# damping = 0.01\nx,alpha\n0,0\n12,1\n")
    with pytest.raises(ValueError, match="b.csv: its deck nodes x differ from those of .*a.csv"):
        bridge_from_mode_tables({"B": 10.0}, [a, b])
    with pytest.raises(ValueError, match="the template already has"):
        bridge_from_mode_tables({"B": 10.0, "modes": []}, [a])
    bridge = bridge_from_mode_tables({"B": 10.0}, [a, a])
    assert bridge.n_modes == 2 and bridge.nodes_x.tolist() == [0.0, 10.0]
