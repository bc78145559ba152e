"""Flutter-derivative tables with each derivative's standard deviation (``H1_std`` columns)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from ident.model import flat_plate
from ident.model.conventions import FLUTTER_DERIVATIVE_NAMES
from ident.tables.fd_table import FlutterDerivativeTable

K = np.geomspace(0.2, 2.0, 7)


def _table(**extra):
    values = flat_plate.flutter_derivatives(K)
    std = {name: 0.01 * np.abs(values[name]) + 1e-3 for name in FLUTTER_DERIVATIVE_NAMES}
    return FlutterDerivativeTable(K, values, std=std, **extra)


def test_std_columns_round_trip_exactly_and_read_by_a_plain_csv_reader(tmp_path: Path):
    table = _table()
    path = tmp_path / "t.csv"
    table.to_csv(path)
    with open(path, newline="", encoding="utf-8") as handle:  # an independent reader
        rows = list(csv.reader(handle))
    assert rows[0] == ["K", *FLUTTER_DERIVATIVE_NAMES,
                       *(f"{n}_std" for n in FLUTTER_DERIVATIVE_NAMES)]
    column = rows[0].index("H1_std")
    np.testing.assert_array_equal([float(r[column]) for r in rows[1:]], table.std["H1"])
    back = FlutterDerivativeTable.from_csv(path)
    assert set(back.std) == set(FLUTTER_DERIVATIVE_NAMES)
    for name in FLUTTER_DERIVATIVE_NAMES:  # repr(): 17 digits, exact
        np.testing.assert_array_equal(back.std[name], table.std[name])
        np.testing.assert_array_equal(back.values[name], table.values[name])


def test_std_of_some_derivatives_with_stars_and_in_z_up_keeps_its_sign(tmp_path: Path):
    """A std is a magnitude: converting signs (z up) flips H3 but not H3's std."""
    path = tmp_path / "t.csv"
    path.write_text("Ur, H1*, H3*, H3*_std, A2*\n10, -3.0, -4.0, 0.2, -0.5\n5, -1.5, -1.0, 0.1, "
                    "-0.2\n")
    table = FlutterDerivativeTable.from_csv(path, convention="z_up")
    assert set(table.std) == {"H3"}
    # K increasing: Ur 10 (K = 0.63) first; H3 flipped, its std not.
    np.testing.assert_array_equal(table.values["H3"], [4.0, 1.0])
    np.testing.assert_array_equal(table.std["H3"], [0.2, 0.1])


def test_a_table_without_std_writes_no_std_columns(tmp_path: Path):
    values = flat_plate.flutter_derivatives(K)
    FlutterDerivativeTable(K, values).to_csv(tmp_path / "t.csv")
    header = (tmp_path / "t.csv").read_text().splitlines()[0]
    assert "_std" not in header and FlutterDerivativeTable.from_csv(tmp_path / "t.csv").std == {}


@pytest.mark.parametrize("text, message", [
    ("K, H1, A2_std\n1, -1, 0.1\n", r"std column\(s\) \['A2_std'\] without"),
    ("K, H1, H1_std\n1, -1, -0.1\n", "H1_std is not a finite value >= 0 at K = 1"),
    ("K, H1, H1_std\n1, -1, nan\n", "H1_std is not a finite value >= 0"),
    ("K, H1, H9_std\n1, -1, 0.1\n", r"unknown column\(s\) \['H9_std'\]"),
])
def test_bad_std_columns_get_one_clear_error(tmp_path: Path, text: str, message: str):
    path = tmp_path / "t.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        FlutterDerivativeTable.from_csv(path)


def test_std_of_an_unknown_derivative_or_wrong_length_is_refused():
    values = flat_plate.flutter_derivatives(K)
    with pytest.raises(ValueError, match=r"std of unknown flutter derivative\(s\) \['P1'\]"):
        FlutterDerivativeTable(K, values, std={"P1": np.ones(K.size)})
    with pytest.raises(ValueError, match="H1_std has 2 values for 7 K"):
        FlutterDerivativeTable(K, values, std={"H1": np.ones(2)})
