"""``windrig bridge``: the example bridge through the command line, its JSON, and its errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from daq.cli import main
from ident.model import flat_plate
from ident.tables.fd_table import FlutterDerivativeTable

from support.configs import BRIDGES

BRIDGE = BRIDGES / "example_bridge.json"
MODES = [BRIDGES / "example_modes" / f"{n}.csv" for n in ("L1S", "V1A", "V1S", "V2S", "T1S",
                                                            "T1A")]


def test_the_example_bridge_with_the_identified_model_format(tmp_path: Path, capsys):
    """`windrig identify --json` output as --aero: DESIGN's keys, curves written, check agrees."""
    model = tmp_path / "identified.json"
    model.write_text(json.dumps({"model": flat_plate.jones_model().to_dict(),
                                 "flutter_speed": 1.0}))
    out = tmp_path / "result.json"
    assert main(["bridge", str(BRIDGE), "--aero", str(model), "--json", str(out),
                 "--out", str(tmp_path / "plots")]) == 0
    text = capsys.readouterr().out
    assert "flutter at U = 77.13 m/s" in text and "T1S (0.28 Hz, torsional):" in text
    result = json.loads(out.read_text())
    assert {"flutter_speed", "flutter_frequency", "flutter_speed_frequency_domain"} <= set(result)
    # Both routes use the same Q(p): they agree to the root solvers (0.5 % is the promise).
    assert result["flutter_speed_frequency_domain"] == pytest.approx(result["flutter_speed"],
                                                                     rel=1e-6)
    assert [p["mode"].split(" ")[0] for p in result["participation"]] == ["T1S", "V1S"]
    assert sum(p["share"] for p in result["participation"]) == pytest.approx(1.0, abs=0.02)
    assert len(result["modes"]["labels"]) == 6
    assert len(result["modes"]["U"]) == len(result["modes"]["damping"]) == 120
    # The 2-DOF model completed with quasi-steady sway terms: 3x3 matrices, the same lags.
    assert len(result["model"]["A"][0]) == 3 and result["model"]["d"] == [0.091, 0.6]
    assert (tmp_path / "plots" / "bridge_modes.png").stat().st_size > 10_000
    header = (tmp_path / "plots" / "bridge_modes.csv").read_text().splitlines()[0]
    assert header.startswith("U_m_s,f_L1S_Hz,") and header.endswith("zeta_T1A")


def test_the_example_bridge_with_a_bluff_table_reports_the_fit_at_every_row(tmp_path, capsys):
    out = tmp_path / "result.json"
    assert main(["bridge", str(BRIDGE), "--aero", str(BRIDGES / "example_deck_table.csv"),
                 "--json", str(out), "--u-max", "100"]) == 0
    printed = capsys.readouterr().out
    assert "largest error 0.13 % of its force (A3* at K = 1.571): within the 2 %" in printed
    result = json.loads(out.read_text())
    assert len(result["table_fit_relative_error"]) == len(result["table_K"]) == 19
    assert max(result["table_fit_relative_error"]) < 0.005
    assert max(max(e) for e in result["table_fit_derivative_error"].values()) < 0.02
    assert result["U_max"] == 100.0
    # The routes agree within their 0.5 %: the state space stands, nothing to warn about.
    assert result["flutter_speed_frequency_domain"] == pytest.approx(
        result["flutter_speed"], rel=0.005)
    assert result["result"]["basis"] == "state-space"
    assert result["result"]["flutter_speed"] == result["flutter_speed"]
    assert result["table_K_range"] == [result["table_K"][0], result["table_K"][-1]]
    assert result["units"]["flutter_speed"] == "m/s"
    assert "extrapolated" in result["divergence_basis"]


def test_mode_tables_make_the_bridge_file(tmp_path: Path):
    written = tmp_path / "bridge.json"
    assert main(["bridge", str(BRIDGES / "example_deck.json"), "--modes",
                 *map(str, MODES), "--write-bridge", str(written)]) == 0
    from ident.bridge.model import BridgeModel

    assert (BridgeModel.from_json(written).to_dict()
            == BridgeModel.from_json(BRIDGE).to_dict())


@pytest.fixture
def files(tmp_path: Path) -> Path:
    (tmp_path / "model.json").write_text(json.dumps(flat_plate.jones_model().to_dict()))
    (tmp_path / "bad.json").write_text('{"B": 3')
    bad_bridge = json.loads(BRIDGE.read_text())
    bad_bridge["modes"][2]["damping"] = 0.5 * 10
    (tmp_path / "percent.json").write_text(json.dumps(bad_bridge))
    (tmp_path / "model_bad.json").write_text(json.dumps({"A": [[[0, 0], [0, 0]]], "d": []}))
    (tmp_path / "table.csv").write_text("K,H1,A2\n0.5,-12,-0.4\n1,-6,-0.2\n")
    (tmp_path / "aero.txt").write_text("")
    (tmp_path / "mode.csv").write_text("x,h\n0,0\n")
    return tmp_path


CASES = [
    (["{b}", "--aero", "{d}/model.json", "--u-max", "-3"], "--u-max -3: must be > 0 m/s"),
    (["{d}/bad.json", "--aero", "{d}/model.json"], "bad.json: not valid JSON"),
    (["{d}/nothing.json", "--aero", "{d}/model.json"], "nothing.json: no such file"),
    (["{d}/percent.json", "--aero", "{d}/model.json"],
     "percent.json: modes[2].damping = 5: the damping ratio must be in [0, 1) (a percentage?"),
    (["{b}"], "--aero is required"),
    (["{b}", "--aero", "{d}/aero.txt"], "--aero {d}/aero.txt: expected an RFC model (.json) "
                                        "or a flutter-derivative table (.csv)"),
    (["{b}", "--aero", "{d}/model_bad.json"], "model_bad.json: not a rational-function model"),
    (["{b}", "--aero", "{d}/table.csv"], "table.csv: 2 row(s); a flutter analysis from a table "
                                         "needs at least 4"),
    (["{b}", "--aero", "{d}/nothing.csv"], "nothing.csv: no such file"),
    (["{b}", "--aero", "{d}/model.json", "--write-bridge", "{d}/x.json"],
     "--write-bridge needs --modes"),
    (["{b}", "--aero", "{d}/model.json", "--buffeting", "30"], "--buffeting needs --wind"),
    (["{b}", "--aero", "{d}/model.json", "--time-domain", "60"], "--time-domain 60: needs "
                                                                  "--buffeting"),
    (["{b}", "--modes", "{d}/mode.csv", "--write-bridge", "{d}/x.json"],
     "with --modes: the template already has ['modes', 'nodes_x']"),
    (["{e}/example_deck.json", "--modes", "{d}/mode.csv"],
     "mode.csv: no '# frequency = ...' line above the header"),
]


@pytest.mark.parametrize(("argv", "message"), CASES, ids=[c[1][:40] for c in CASES])
def test_bad_input_is_one_error_line(files, capsys, argv, message):
    def fill(text: str) -> str:
        return text.replace("{d}", str(files)).replace("{b}", str(BRIDGE)).replace(
            "{e}", str(BRIDGES))

    code = main(["bridge", *map(fill, argv)])
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert fill(message) in lines[0], lines[0]


def test_a_bad_speed_list_is_argparse_usage():
    with pytest.raises(SystemExit) as stop:
        main(["bridge", str(BRIDGE), "--buffeting", "30,fast"])
    assert stop.value.code == 2


def test_flutter_outside_a_tables_range_is_flagged_as_extrapolation(tmp_path, capsys):
    """The bluff table cut to K >= 0.75: flutter (K = 0.63) is beyond its rows: a warning.

    The frequency domain, which never leaves the table, finds no flutter within it.
    """
    lines = (BRIDGES / "example_deck_table.csv").read_text().splitlines()
    rows = [line for line in lines[2:] if float(line.split(",")[0]) > 0.75]
    narrow = tmp_path / "narrow.csv"
    narrow.write_text("\n".join(lines[1:2] + rows) + "\n")
    result = tmp_path / "result.json"
    assert main(["bridge", str(BRIDGE), "--aero", str(narrow), "--json", str(result)]) == 0
    out = capsys.readouterr().out
    assert ("warning: state space: flutter at 64.77 m/s with K = 0.63, outside the table's K "
            "0.785 to 3.14 (above the table's wind speeds)") in out, out
    assert "an extrapolation of the fit, not a result" in out
    assert "frequency domain (the table's flutter derivatives): no flutter below" in out
    assert "warning: the frequency domain finds no flutter within the table's K" in out
    summary = json.loads(result.read_text())
    assert summary["result"]["basis"] == "none" and summary["result"]["flutter_speed"] is None
    assert summary["flutter_speed"] == pytest.approx(64.77, abs=0.01)  # the state space's
    assert summary["flutter_speed_frequency_domain"] is None
    assert len(summary["warnings"]) >= 2


def test_the_fast_method_gives_the_dense_answer(tmp_path):
    """--method fast (followed branches) against --method dense on the example bridge and table.

    Tolerance 1e-9 relative: both solve the same equations to 1e-12 (Brent on the dense grid,
    Newton on the followed branch); the divergence the same search on a coarser grid (1e-6).
    """
    results = {}
    for method in ("dense", "fast"):
        out = tmp_path / f"{method}.json"
        assert main(["bridge", str(BRIDGE), "--aero", str(BRIDGES / "example_deck_table.csv"),
                     "--method", method, "--json", str(out)]) == 0
        results[method] = json.loads(out.read_text())
    dense, fast = results["dense"], results["fast"]
    for key in ("flutter_speed", "flutter_speed_frequency_domain"):
        assert fast[key] == pytest.approx(dense[key], rel=1e-9)
    assert fast["divergence_speed"] == pytest.approx(dense["divergence_speed"], rel=1e-6)
    assert fast["result"]["basis"] == dense["result"]["basis"] == "state-space"


def test_a_table_with_h_and_a_swapped_is_one_error_line_naming_it(tmp_path, capsys):
    """The plate's lift and moment columns swapped: the frequency domain loses a mode's root.

    It ended the command with "error: expected 6 oscillatory roots at K = 0.5013, found 5",
    without the file or a cause.
    """
    K = np.geomspace(0.2, 3.0, 40)
    values = flat_plate.flutter_derivatives(K)
    swapped = tmp_path / "swapped.csv"
    FlutterDerivativeTable(K, {("A" if n[0] == "H" else "H") + n[1]: v
                               for n, v in values.items()}).to_csv(swapped)
    assert main(["bridge", str(BRIDGE), "--aero", str(swapped)]) == 1
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"error: {swapped}: the frequency-domain route"), lines[0]
    assert "expected 6 oscillatory roots" in lines[0] and "H and A swapped?" in lines[0]
