"""``windrig identify`` on runs of three degrees of freedom: the 18 flutter derivatives.

The table printed is checked against the definition of the derivatives
(docs/reference/conventions.md, "Three degrees of freedom"): ``Q(iK) = K^2 [[H4* + i H1*, H3* + i
H2*, H6* + i H5*], [A4* + i A1*, ...], [P6* + i P5*, P3* + i P2*, P4* + i P1*]]``, read off the
model's ``Q`` directly. The run files are written by the acquisition's recorder from simulated 3-DOF
releases of the bluff deck (:mod:`simulators.decks`) and read back by :mod:`ident.records.run_file`
as 3-DOF releases.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from daq.cli import main
from daq.config import load_rig_config
from daq.offline.derivative_table import (
    TABLE_POINTS,
    check_model_dof,
    derivative_rows,
    format_derivative_table,
)
from daq.recording.synthetic import write_release_run
from ident.errors import IdentError
from ident.model import flutter
from ident.model.conventions import derivative_names
from ident.model.flat_plate import jones_model
from ident.model.rfc import RationalFunctionModel
from ident.records.run_file import read_run
from ident.tables.fd_table import FlutterDerivativeTable
from simulators.decks import BLUFF_DECK_3DOF, bluff_deck_3dof_model
from simulators.tunnel import simulate_release

#: Entry of Q (row, column) and (real, imaginary) part of each derivative, over K^2.
DEFINITION = {
    "H4": (0, 0, 0), "H1": (0, 0, 1), "H3": (0, 1, 0), "H2": (0, 1, 1), "H6": (0, 2, 0),
    "H5": (0, 2, 1), "A4": (1, 0, 0), "A1": (1, 0, 1), "A3": (1, 1, 0), "A2": (1, 1, 1),
    "A6": (1, 2, 0), "A5": (1, 2, 1), "P6": (2, 0, 0), "P5": (2, 0, 1), "P3": (2, 1, 0),
    "P2": (2, 1, 1), "P4": (2, 2, 0), "P1": (2, 2, 1),
}


def test_the_table_holds_the_18_derivatives_of_their_definition():
    model = bluff_deck_3dof_model()
    K, values = derivative_rows(model, [0.3, 0.9])
    assert list(values) == list(derivative_names(3)) and len(values) == 18
    assert K.size == TABLE_POINTS and K[0] == 0.3 and K[-1] == 0.9
    Q = model.Q(1j * K)  # (n, 3, 3)
    for name, (i, j, part) in DEFINITION.items():
        entry = Q[:, i, j] / K**2
        expected = entry.imag if part else entry.real
        np.testing.assert_allclose(values[name], expected, rtol=1e-12, atol=1e-14)
    lines = format_derivative_table(model, [0.3, 0.9])
    assert len(lines) == 2 + 18
    printed = {line.split()[0]: [float(v) for v in line.split()[1:]] for line in lines[2:]}
    assert list(printed) == [f"{n}*" for n in derivative_names(3)]
    # Four significant digits printed.
    np.testing.assert_allclose(printed["P1*"], values["P1"], rtol=5e-4)


def test_a_2dof_model_of_a_3dof_section_is_refused():
    check_model_dof(bluff_deck_3dof_model(), BLUFF_DECK_3DOF)  # 3 and 3: fine
    with pytest.raises(IdentError, match="the identified model has 2 degrees of freedom, the "
                                         "section 3"):
        check_model_dof(jones_model(), BLUFF_DECK_3DOF)


@pytest.fixture(scope="module")
def run_files(tmp_path_factory) -> list[Path]:
    """Two releases at each of three wind speeds, 2 % noise, one run file per speed."""
    config = load_rig_config("sim_bluff_deck_3dof")
    section = BLUFF_DECK_3DOF.replace(rho=1.2)
    out = tmp_path_factory.mktemp("identify3")
    files = []
    for k, U in enumerate((7.0, 9.0, 11.0)):
        releases = [simulate_release(section, bluff_deck_3dof_model(), U, 0.006, 0.015,
                                     p0=0.004, duration=12.0, fs=200.0, noise=0.02,
                                     rng=10 * k + i) for i in range(2)]
        path = out / f"run_U{U:.0f}.h5"
        write_release_run(path, config, releases)
        files.append(path)
    return files


def test_the_files_read_back_as_3dof_releases(run_files):
    record = read_run(run_files[0])
    assert record.section.n_dof == 3 and len(record.releases) == 2
    assert all(r.p is not None and r.drag is not None for r in record.releases)
    assert record.releases[0].p[0] == pytest.approx(0.004, abs=4e-4)  # p0 plus 2 % noise


def test_identify_prints_the_18_derivatives_and_the_flutter_speed(run_files, tmp_path, capsys):
    """E2RFC in 3x3 on the files: the table, and the flutter speed near the truth's.

    Truth: the state-space flutter speed of the simulated deck in air of 1.2 kg/m^3 (the
    files' density), 13.947 m/s. Measured: 13.947 +/- 0.064 m/s at 2 % noise (within 0.01 %);
    the test allows 1 %, the issue's target.
    """
    out = tmp_path / "model.json"
    code = main(["identify", *map(str, run_files), "--json", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    names = re.findall(r"^\s+([HAP][1-6])\*", captured.out, flags=re.M)
    assert names == list(derivative_names(3))
    speed = float(re.search(r"flutter speed ([0-9.]+) \+/-", captured.out).group(1))
    truth = flutter.analyze(BLUFF_DECK_3DOF.replace(rho=1.2), bluff_deck_3dof_model()).speed
    assert truth == pytest.approx(13.947, abs=0.001)
    assert speed == pytest.approx(truth, rel=0.01)
    data = json.loads(out.read_text())
    table = data["flutter_derivatives"]
    assert list(table) == ["K", *derivative_names(3)] and len(table["K"]) == TABLE_POINTS
    assert np.asarray(data["model"]["A"]).shape[1:] == (3, 3)


def test_identify_table_holds_the_18_derivatives_and_their_std(run_files, tmp_path):
    """``--table``: 18 derivatives then 18 std columns, the JSON model's values, read back 3-DOF."""
    table, out = tmp_path / "table.csv", tmp_path / "model.json"
    assert main(["identify", *map(str, run_files), "--table", str(table), "--json",
                 str(out)]) == 0
    names = list(derivative_names(3))
    header = table.read_text().splitlines()[0].split(",")
    assert header == ["K", *names, *(f"{n}_std" for n in names)]
    back = FlutterDerivativeTable.from_csv(table)
    assert back.n_dof == 3 and list(back.std) == names
    model = RationalFunctionModel.from_dict(json.loads(out.read_text())["model"])
    expected = model.flutter_derivatives(back.K)
    for name in names:
        # Both written with every digit: equal to round-off.
        np.testing.assert_allclose(back.values[name], expected[name], rtol=1e-12, atol=1e-12)
        assert np.all(back.std[name] > 0.0)
