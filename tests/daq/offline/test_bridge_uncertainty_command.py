"""``windrig bridge --uncertainty``: the example bridge through the command line, serially.

The identify JSON is the seeded flat-plate identification of :mod:`support.identified`; the
table is the example deck's with std columns added. The Dask paths (a scheduler address, a
local cluster) are in ``test_bridge_uncertainty_dask.py``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from daq.cli import main
from daq.offline.bridge_uncertainty import PLOT_NAME, SERIAL_BELOW_S, executor_rule
from ident.tables.fd_table import FlutterDerivativeTable

from support.configs import BRIDGES
from support.identified import identified_flat_plate

BRIDGE = BRIDGES / "example_bridge.json"


@pytest.fixture(scope="module")
def identify_json(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("identified") / "identified.json"
    path.write_text(json.dumps(identified_flat_plate()))
    return path


def test_an_identified_model_gives_both_stds_the_histogram_and_the_json(identify_json,
                                                                          tmp_path, capsys):
    out, plots = tmp_path / "bridge.json", tmp_path / "plots"
    assert main(["bridge", str(BRIDGE), "--aero", str(identify_json), "--uncertainty",
                 "--samples", "40", "--seed", "3", "--json", str(out), "--out",
                 str(plots)]) == 0
    printed = capsys.readouterr().out
    assert "uncertainty (model covariance): 40 samples, serial (about" in printed
    result = json.loads(out.read_text())
    u = result["uncertainty"]
    assert u["source"] == "model covariance" and u["executor"] == "serial"
    assert u["flutter_speed"] == pytest.approx(result["flutter_speed"], rel=1e-4)
    mc = u["monte_carlo"]
    assert (mc["n"], mc["fluttering"], mc["failed"], mc["seed"]) == (40, 40, 0, 3)
    assert list(mc["quantiles"]) == ["0.025", "0.16", "0.5", "0.84", "0.975"]
    assert mc["quantiles"]["0.025"] < mc["mean"] < mc["quantiles"]["0.975"]
    # 40 samples: a std within 3 of its sampling errors (1 / sqrt(78), 11 %) of the delta one.
    assert mc["std"] == pytest.approx(u["delta_std"], rel=3 / np.sqrt(2 * 39))
    assert u["std_ratio"] == pytest.approx(u["delta_std"] / mc["std"])
    assert u["units"]["delta_std"] == "m/s" and "warnings" in u
    # Fewer than 100 samples: said, in the entry and among the command's warnings.
    assert any("only 40 samples" in w for w in u["warnings"])
    assert any("only 40 samples" in w for w in result["warnings"])
    # The section's other parts, scaled by the ratio of the flutter speeds, into the total.
    section = identified_flat_plate()
    scale = u["flutter_speed"] / section["flutter_speed"]
    assert u["section_other_parts"]["extrapolation"] == pytest.approx(
        scale * section["flutter_speed_std_parts"]["extrapolation"])
    others = sum(v**2 for v in u["section_other_parts"].values())
    assert u["total_std"] == pytest.approx(np.sqrt(mc["std"] ** 2 + others))
    # The histogram, read back by Pillow: a real PNG of the figure's size (7 x 4.5 in at 100).
    with Image.open(plots / PLOT_NAME) as image:
        assert image.format == "PNG" and image.size == (700, 450)
    assert u["plot"] == str(plots / PLOT_NAME)
    report = (plots / "report.md").read_text()
    assert "## Uncertainty (the section's, carried to the bridge)" in report
    assert f"![flutter speed of the samples]({PLOT_NAME})" in report
    assert f"+- {u['delta_std']:.3g} m/s" in report


def test_a_table_with_std_columns_gives_a_monte_carlo_without_delta(tmp_path, capsys):
    table = FlutterDerivativeTable.from_csv(BRIDGES / "example_deck_table.csv")
    std = {n: 0.03 * np.abs(v) + 0.01 for n, v in table.values.items()}
    path = tmp_path / "deck_std.csv"
    FlutterDerivativeTable(table.K, table.values, source="deck", std=std).to_csv(path)
    out = tmp_path / "bridge.json"
    assert main(["bridge", str(BRIDGE), "--aero", str(path), "--uncertainty", "--samples",
                 "12", "--json", str(out)]) == 0
    u = json.loads(out.read_text())["uncertainty"]
    assert u["source"] == "table std columns" and u["delta_std"] is None
    assert u["method"].startswith("Monte Carlo only") and "1 lag(s), A3 fitted" in u["method"]
    mc = u["monte_carlo"]
    assert mc["n"] == 12 and mc["fluttering"] + mc["failed"] + mc["no_flutter"] == 12
    assert mc["fluttering"] >= 10 and mc["std"] > 0.0
    assert "total_std" not in u  # a table carries no other parts


@pytest.mark.parametrize(("args", "message"), [
    (["--samples", "50"], "--samples: only with --uncertainty"),
    (["--uncertainty", "--samples", "1"], "--samples 1: must be >= 2"),
    (["--uncertainty", "--workers", "0"], "--workers 0: must be >= 1"),
])
def test_a_wrong_option_is_one_error_line(args, message, identify_json, capsys):
    code = main(["bridge", str(BRIDGE), "--aero", str(identify_json), *args])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err == [f"error: {message}" + err[0].split(message, 1)[1]]


def test_aero_without_an_uncertainty_is_one_error_line_naming_the_file(tmp_path, capsys):
    for aero, what in ((BRIDGES / "example_deck_model.json", "holds no model_covariance"),
                       (BRIDGES / "example_deck_table.csv", "has no std column")):
        code = main(["bridge", str(BRIDGE), "--aero", str(aero), "--uncertainty"])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1
        assert err[0].startswith(f"error: --uncertainty: {aero}") and what in err[0]


def test_a_covariance_that_does_not_fit_the_model_is_one_error_line(identify_json, tmp_path,
                                                                     capsys):
    data = json.loads(identify_json.read_text())
    data["model_covariance"]["n_lags"] = 1
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    code = main(["bridge", str(BRIDGE), "--aero", str(path), "--uncertainty"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert err[0].startswith(f"error: {path}: model_covariance: ")


def test_the_executor_rule_runs_few_samples_serially_and_many_on_a_cluster():
    assert executor_rule(100, 0.05, None, None)[0] is True  # 5 s
    serial, why = executor_rule(1000, 0.05, None, None)  # 50 s
    assert serial is False and f"above {SERIAL_BELOW_S:g} s" in why
    assert executor_rule(10, 0.05, 2, None) == (False, "asked for")
    assert executor_rule(10, 0.05, None, "tcp://127.0.0.1:8786") == (False, "asked for")
