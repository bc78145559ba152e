"""``windrig identify --table``: the flutter-derivative table with each derivative's std, read back.

The run file is written by the acquisition's own recorder (:mod:`daq.recording.synthetic`)
from simulated releases of the flat-plate rig (``rig_configs/sim_flat_plate.toml``, Jones's
aerodynamics) at 6 and 8 m/s, two holds each, 1 s held before each release (0.2 % of each
displacement's RMS as noise, 1 % on the forces). The table written is read back by an
independent CSV reader, by ``windrig flutter --table`` and by ``windrig bridge --aero``.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from daq.cli import main
from daq.config import parse_rig_config
from daq.recording.synthetic import write_release_run
from ident.model import flat_plate
from ident.model.conventions import FLUTTER_DERIVATIVE_NAMES
from ident.model.rfc import RationalFunctionModel
from ident.tables.fd_table import FlutterDerivativeTable
from simulators.tunnel import simulate_release

from support.configs import BRIDGES, SIM_FLAT_PLATE

CONFIG = parse_rig_config(SIM_FLAT_PLATE.read_text(), "sim_flat_plate.toml")
TRUTH = flat_plate.jones_model()
NOISE = {"h": 0.002, "alpha": 0.002, "lift": 0.01, "moment": 0.01}


@pytest.fixture(scope="module")
def identified(tmp_path_factory):
    """One run identified with --table (default rows) and --json: the paths."""
    where = tmp_path_factory.mktemp("table")
    sims = [simulate_release(CONFIG.section, TRUTH, U, h0, alpha0, duration=6.0, fs=500.0,
                             pre_s=1.0, noise=NOISE, rng=10 * k + j)
            for k, U in enumerate((6.0, 8.0))
            for j, (h0, alpha0) in enumerate(((0.008, 0.04), (0.006, 0.03)))]
    run = where / "run.h5"
    write_release_run(run, CONFIG, sims)
    table, out = where / "table.csv", where / "identify.json"
    assert main(["identify", str(run), "--table", str(table), "--json", str(out)]) == 0
    return run, table, out


def _read(path: Path) -> dict[str, np.ndarray]:
    with open(path, newline="", encoding="utf-8") as handle:  # an independent reader
        rows = list(csv.reader(handle))
    return {name: np.array([float(r[i]) for r in rows[1:]]) for i, name in enumerate(rows[0])}


def test_the_table_holds_the_models_derivatives_and_a_std_that_covers_the_truth(identified):
    _, table, out = identified
    columns = _read(table)
    assert list(columns) == ["K", *FLUTTER_DERIVATIVE_NAMES,
                             *(f"{n}_std" for n in FLUTTER_DERIVATIVE_NAMES)]
    result = json.loads(out.read_text())
    assert result["table"] == str(table)
    K = columns["K"]
    assert K.size == 25
    model = RationalFunctionModel.from_dict(result["model"])
    expected = model.flutter_derivatives(K)
    truth = TRUTH.flutter_derivatives(K)
    errors = []
    for name in FLUTTER_DERIVATIVE_NAMES:
        # The JSON's model and the CSV are both written with every digit: equal to round-off.
        np.testing.assert_allclose(columns[name], expected[name], rtol=1e-12, atol=1e-12)
        std = columns[f"{name}_std"]
        assert np.all(std > 0.0) and np.all(np.isfinite(std))
        errors.append(np.abs(columns[name] - truth[name]) / std)
    # The std is an honest one: the truth lies within 3 std nearly everywhere (ident's own
    # tests measure 94-98 % within 2 std); 90 % within 3 is a margin for one seed.
    assert np.mean(np.concatenate(errors) < 3.0) >= 0.9


def test_reduced_velocities_of_the_users_choosing_and_their_extrapolation_warned(
        identified, tmp_path, capsys):
    run, _, _ = identified
    table, out = tmp_path / "t.csv", tmp_path / "o.json"
    assert main(["identify", str(run), "--table", str(table), "--reduced-velocities",
                 "2:20:0.5", "--json", str(out)]) == 0
    K = _read(table)["K"]
    np.testing.assert_allclose(np.sort(2 * math.pi / K), np.arange(2.0, 20.01, 0.5), rtol=1e-12)
    printed = capsys.readouterr().out
    assert f"wrote {table}" in printed
    warnings = json.loads(out.read_text())["warnings"]
    assert any("rows lie outside the reduced velocities the releases cover" in w
               for w in warnings)


@pytest.mark.parametrize("args, message", [
    (["--table", "{d}/t.csv", "--reduced-velocities", "20:2:0.5"],
     "need 0 < START < STOP and STEP > 0"),
    (["--table", "{d}/t.csv", "--reduced-velocities", "2:20"], "expected START:STOP:STEP"),
    (["--reduced-velocities", "2:20:1"], "--reduced-velocities sets the rows of --table"),
])
def test_bad_reduced_velocities_are_one_error_line(identified, tmp_path, capsys, args, message):
    run, _, _ = identified
    code = main(["identify", str(run), *(a.format(d=tmp_path) for a in args)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("error:") and message in err[0]


def test_windrig_flutter_reads_the_table_and_carries_its_std(identified, tmp_path, capsys):
    _, table, _ = identified
    section = tmp_path / "section.json"
    section.write_text(json.dumps(CONFIG.section.to_dict()))
    out = tmp_path / "flutter.json"
    assert main(["flutter", "--section", str(section), "--table", str(table), "--json",
                 str(out)]) == 0
    assert "gives the std of 8 derivative(s)" in capsys.readouterr().out
    result = json.loads(out.read_text())
    columns = _read(table)
    order = np.argsort(columns["K"])
    for name in FLUTTER_DERIVATIVE_NAMES:
        np.testing.assert_array_equal(result["table_std"][name], columns[f"{name}_std"][order])
    assert isinstance(result["warnings"], list)


def test_windrig_bridge_reads_a_table_with_std_and_flutters_as_without(tmp_path, capsys):
    """The example deck table with std columns added: the same flutter speed, the std carried."""
    plain = FlutterDerivativeTable.from_csv(BRIDGES / "example_deck_table.csv")
    std = {name: 0.05 * np.abs(column) for name, column in plain.values.items()}
    with_std = tmp_path / "deck.csv"
    FlutterDerivativeTable(plain.K, plain.values, std=std).to_csv(with_std)
    results = []
    for aero in (BRIDGES / "example_deck_table.csv", with_std):
        out = tmp_path / f"{aero.stem}.json"
        assert main(["bridge", str(BRIDGES / "example_bridge.json"), "--aero", str(aero),
                     "--json", str(out), "--u-max", "100"]) == 0
        results.append(json.loads(out.read_text()))
    assert "table_std" not in results[0]
    assert results[1]["flutter_speed"] == results[0]["flutter_speed"]
    for name, column in std.items():
        np.testing.assert_array_equal(results[1]["table_std"][name], column)
    assert "gives the std of" in capsys.readouterr().out
