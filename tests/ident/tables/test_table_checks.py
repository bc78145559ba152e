"""Checks of flutter-derivative tables: each awkward table flagged as it should be, clean ones not.

Every awkward table is made from a clean one: the shipped example deck's table (19 rows, Ur 2 to
20) or the exact flat plate (Theodorsen) at 30 to 150 reduced frequencies. Noise is seeded.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ident.model import flutter as fl
from ident.model.flat_plate import flutter_derivatives
from ident.model.section import SectionModel
from ident.tables.fd_table import FlutterDerivativeTable
from ident.tables.table_checks import (
    GOVERNS,
    SPARSE_ROWS,
    check_flutter_range,
    check_table,
)
from simulators.decks import bluff_deck_3dof_model

from support.configs import BRIDGES

EXAMPLE = BRIDGES / "example_deck_table.csv"


def _example() -> FlutterDerivativeTable:
    return FlutterDerivativeTable.from_csv(EXAMPLE)


def _plate(n: int = 30, K: tuple[float, float] = (0.3, 3.0)) -> FlutterDerivativeTable:
    grid = np.geomspace(*K, n)
    return FlutterDerivativeTable(grid, flutter_derivatives(grid))


def _with(table: FlutterDerivativeTable, **columns: np.ndarray) -> FlutterDerivativeTable:
    return FlutterDerivativeTable(table.K, {**table.values, **columns})


def _noisy(table: FlutterDerivativeTable, level: float, seed: int,
           relative: bool = True) -> FlutterDerivativeTable:
    """Every value with noise of ``level`` times itself, or times its column's RMS."""
    rng = np.random.default_rng(seed)
    values = {}
    for name, column in table.values.items():
        size = np.abs(column) if relative else np.sqrt(np.mean(column**2))
        values[name] = column + level * size * rng.standard_normal(column.size)
    return FlutterDerivativeTable(table.K, values)


@pytest.mark.parametrize("n", [30, 60, 150])
def test_clean_tables_are_not_flagged(n: int):
    assert check_table(_example(), EXAMPLE) == []
    assert check_table(_plate(n)) == []
    assert check_table(_plate(n, (0.1, 1.5))) == []
    assert check_table(_plate(n, (0.2, 6.0))) == []


@pytest.mark.parametrize("K", [(0.3, 3.14, 19), (0.1, 5.0, 60), (0.021, 1.26, 151)])
def test_a_clean_three_dof_bluff_deck_table_is_not_flagged(K):
    """The simulated bluff deck's 18 derivatives: nothing flagged.

    The last range is that of a published 3-DOF table (151 rows, K 0.021 to 1.26), where A2*
    still changes sign among the last rows.
    """
    table = FlutterDerivativeTable.from_model(bluff_deck_3dof_model(), np.geomspace(*K))
    assert table.n_dof == 3 and check_table(table) == []


@pytest.mark.parametrize("level", [0.01, 0.02])
def test_a_good_measured_table_s_noise_raises_nothing(level: float):
    """1-2 % noise, of each value or of its column's RMS: no row or column flagged, ten seeds.

    The scatter is measured against each value, so noise of 2 % of a column's RMS reads as
    more on its small values and may be reported (as a scatter, nothing else); 2 % of each
    value is not.
    """
    for seed in range(10):
        for table in (_example(), _plate(30 + 60 * (seed % 2))):
            assert check_table(_noisy(table, level, seed)) == []
            found = check_table(_noisy(table, level, seed, relative=False))
            assert all(w.startswith("the derivatives scatter") for w in found), found


def test_a_noisy_table_has_its_noise_reported_and_nothing_false():
    """5 % noise: no row and no column wrongly flagged; the scatter estimated at about 5 %."""
    for seed in range(10):
        for table in (_example(), _plate(60)):
            for relative in (True, False):
                found = check_table(_noisy(table, 0.05, seed, relative))
                assert all("scatter" in w for w in found), found
    found = check_table(_noisy(_example(), 0.05, 36))
    assert len(found) == 1 and "scatter about smooth curves by about 5 %" in found[0]


def test_a_sign_typo_is_named_with_its_file_column_row_and_value(tmp_path):
    """One A2* sign flipped (the file's row 14, K = 0.898): that row, and nothing else."""
    lines = EXAMPLE.read_text().splitlines()
    header = lines.index("K,H1,H2,H3,H4,A1,A2,A3,A4")
    cells = lines[header + 14].split(",")
    value = float(cells[6])
    cells[6] = repr(-value)
    lines[header + 14] = ",".join(cells)
    path = tmp_path / "typo.csv"
    path.write_text("\n".join(lines) + "\n")
    found = check_table(FlutterDerivativeTable.from_csv(path), path)
    assert len(found) == 1, found
    assert found[0].startswith(f"{path}: A2* at row 14 (K = 0.8976, Ur = 7): {-value:.4g} has "
                               "the opposite sign of its neighbours' trend")
    assert found[0].endswith("a sign typo?")


def test_rows_are_numbered_as_in_a_file_by_reduced_velocity(tmp_path):
    """A file in Ur (increasing, so K decreasing): the row named is the file's."""
    table = _example()
    A2 = table.values["A2"].copy()
    A2[13] = -A2[13]  # K = 0.898 is the file's row 19 - 13 = 6 when sorted by Ur
    path = tmp_path / "by_ur.csv"
    names = list(table.values)
    rows = [",".join(["Ur", *names])]
    for i in reversed(range(table.K.size)):
        values = [A2[i] if n == "A2" else table.values[n][i] for n in names]
        rows.append(",".join(repr(float(x)) for x in [2 * math.pi / table.K[i], *values]))
    path.write_text("\n".join(rows) + "\n")
    found = check_table(FlutterDerivativeTable.from_csv(path))
    assert len(found) == 1 and f"{path}: A2* at row 6 (K = 0.8976, Ur = 7)" in found[0]


def test_every_sign_typo_of_a_clear_value_is_found_at_its_row():
    """Each value above a fifth of its column's largest, flipped alone, is found at its row."""
    for table in (_example(), _plate(30)):
        for name, column in table.values.items():
            for i in np.flatnonzero(np.abs(column) > 0.2 * np.max(np.abs(column))):
                flipped = column.copy()
                flipped[i] = -flipped[i]
                found = check_table(_with(table, **{name: flipped}))
                assert any(w.startswith(f"{name}* at row {i + 1} (") and "sign typo" in w
                           for w in found), (name, i, found)


def test_an_isolated_outlier_is_flagged():
    table = _plate(40)
    A3 = table.values["A3"].copy()
    A3[20] *= 3.0  # a digit slipped
    found = check_table(_with(table, A3=A3))
    assert len(found) == 1 and found[0].startswith("A3* at row 21 (")
    assert "lies far off its neighbours' trend" in found[0]


@pytest.mark.parametrize("shift", [0.15, -0.15])
def test_a_shifted_damping_derivative_is_flagged_as_shifted(shift: float):
    """A2* + 0.15 (or - 0.15) at every row: A2* does not vanish towards still air."""
    for table in (_example(), _plate(30)):
        found = check_table(_with(table, A2=table.values["A2"] + shift))
        assert len(found) == 1, found
        assert found[0].startswith("A2* tends to ")
        assert "shifted by about" in found[0]
        # The fitted limit is the shift within a third (the fit's own limit on the clean
        # tables is within 0.05 of zero).
        limit = float(found[0].split("tends to ")[1].split(",")[0])
        assert limit == pytest.approx(shift, abs=0.05)


def test_a_shift_is_still_found_under_noise():
    table = _example()
    shifted = _noisy(_with(table, A2=table.values["A2"] + 0.15), 0.02, 7)
    assert ["A2* tends to" in w for w in check_table(shifted)] == [True]


def test_a_table_in_the_other_lift_sign_contradicts_the_inter_relations():
    """Lift and heave positive upward read as Scanlan's: H3* and A1* against H1*, A3*."""
    for table in (_example(), _plate(30)):
        z_up = {n: -v if n in ("H2", "H3", "A1", "A4") else v for n, v in table.values.items()}
        found = check_table(FlutterDerivativeTable(table.K, z_up))
        assert [w.split(" have")[0] for w in found] == ["H1* and H3*", "A1* and A3*"], found
        assert all("convention z_up" in w for w in found)


@pytest.mark.parametrize("which", ["plate", "example deck", "3-DOF bluff deck"])
def test_a_reduced_velocity_headed_k_is_named(which):
    """The rows' Ur = 2 pi / K written in the K column: each power of K turns its sign.

    The clean tables above (the same sections over K 0.02-6, and noisy ones) are not
    reported: their quasi-steady derivatives fall as K^-1.1 to K^-2.2.
    """
    table = {"plate": _plate(30), "example deck": _example(),
             "3-DOF bluff deck": FlutterDerivativeTable.from_model(
                 bluff_deck_3dof_model(), np.geomspace(0.3, 3.14, 19))}[which]
    assert check_table(table) == []
    Ur = 2 * math.pi / table.K
    order = np.argsort(Ur)
    headed_k = FlutterDerivativeTable(Ur[order], {n: v[order] for n, v in table.values.items()})
    # One cause, not its echoes: the damping derivatives then tend to a constant at large
    # "K", which the shifted-column check would report too.
    (found,) = check_table(headed_k)
    assert "looks like the reduced velocity Ur" in found and "head it Ur" in found
    assert f"K {table.K[0]:.4g} to {table.K[-1]:.4g}" in found


def test_a_sparse_table_is_said_to_be_sparse_and_its_sign_typo_found():
    table = _plate(30)
    rows = np.round(np.linspace(0, table.K.size - 1, 8)).astype(int)
    sparse = FlutterDerivativeTable(table.K[rows], {n: v[rows] for n, v in table.values.items()})
    found = check_table(sparse)
    assert len(found) == 1 and found[0].startswith("sparse: 8 rows (K 0.3 to 3): the fit "
                                                   "between rows is an interpolation")
    A2 = sparse.values["A2"].copy()
    A2[3] = -A2[3]
    found = check_table(_with(sparse, A2=A2))
    assert found[1].startswith("A2* at row 4 (K = 0.7779, Ur = 8.077): 0.62 has the opposite "
                               "sign of both neighbours (-1.116, -0.3065)")
    assert len(found) == 2 and SPARSE_ROWS == 10


def test_missing_columns_are_named_with_what_they_govern(tmp_path):
    """4 of the 8 columns (the direct ones): the four left out, each with its role."""
    table = _example()
    path = tmp_path / "four.csv"
    names = ["H1", "H4", "A2", "A3"]
    lines = [",".join(["K", *names])]
    lines += [",".join(repr(float(x)) for x in [K, *(table.values[n][i] for n in names)])
              for i, K in enumerate(table.K)]
    path.write_text("\n".join(lines) + "\n")
    found = check_table(FlutterDerivativeTable.from_csv(path))
    assert found == [f"{path}: column(s) H2*, H3*, A1*, A4* not in the table: taken as zero "
                     f"(H2* governs {GOVERNS['H2']}; H3* governs {GOVERNS['H3']}; A1* governs "
                     f"{GOVERNS['A1']}; A4* governs {GOVERNS['A4']})"]
    assert "torsional divergence" in GOVERNS["A3"] and "damping" in GOVERNS["A2"]


def test_a_table_that_stops_short_of_the_flutter_K():
    """The example deck on the 1.1a bridge's section: flutter at Ur 9.8; a table up to Ur 8."""
    table = _example()
    section = SectionModel(B=31.0, m=22740.0, I=2.47e6, fh=0.10, fa=0.278, zeta_h=0.003,
                           zeta_a=0.003, rho=1.22)
    full = fl.frequency_domain(section, table.interpolator(), (table.K[0], table.K[-1]))
    assert full.reduced_frequency is not None and full.reduced_frequency < 2 * math.pi / 8
    keep = table.K >= 2 * math.pi / 8 - 1e-12
    short = FlutterDerivativeTable(table.K[keep], {n: v[keep] for n, v in table.values.items()},
                                   source="short.csv")
    assert check_flutter_range(table, full.reduced_frequency) == []
    found = check_flutter_range(short, full.reduced_frequency)
    assert found == [f"short.csv: flutter at K = {full.reduced_frequency:.4g} (Ur = "
                     f"{2 * math.pi / full.reduced_frequency:.4g}) lies outside the table (K "
                     "0.7854 to 3.142, Ur 2 to 8): the table stops short of it, the result "
                     "rests on an extrapolation"]
    assert check_flutter_range(short, None) == []
    # Seven rows: the table is also sparse.
    assert check_table(short)[0].startswith("short.csv: sparse: 7 rows")


def _theodorsen_table(K: np.ndarray) -> dict[str, np.ndarray]:
    """Return the flat plate's eight derivatives by Theodorsen's closed form, written here.

    Independent of :mod:`ident.model.flat_plate`: C(k) = H1(k) / (H1(k) + i H0(k)) with Hankel
    functions of the second kind, k = K / 2, and Scanlan's forms (DESIGN, conventions).
    """
    from scipy.special import hankel2

    k = K / 2.0
    C = hankel2(1, k) / (hankel2(1, k) + 1j * hankel2(0, k))
    F, G, pi = C.real, C.imag, math.pi
    return {"H1": -2 * pi * F / K, "H2": -(pi / (2 * K)) * (1 + F + 4 * G / K),
            "H3": -(2 * pi / K**2) * (F - K * G / 4), "H4": (pi / 2) * (1 + 4 * G / K),
            "A1": pi * F / (2 * K), "A2": -(pi / (8 * K)) * (1 - F - 4 * G / K),
            "A3": (pi / (2 * K**2)) * (K**2 / 32 + F - K * G / 4), "A4": -pi * G / (2 * K)}


def _ratio(found: str) -> float:
    """Return the median |H1*| / |K H3*| a scale warning states."""
    return float(found.split("|H1*| is ")[1].split(" times")[0])


@pytest.mark.parametrize(("factor", "pitch", "cause"), [
    (0.5, 1.0, "reduced frequency on the half-width, b omega / U"),
    (2.0, 1.0, "looks like twice K = B omega / U"),
    (1 / (2 * math.pi), 1.0, "f B / U with f in Hz"),
    (1.0, math.pi / 180, "pitch derivatives (H2*, H3*, A2*, A3*) look given per degree"),
])
def test_a_k_column_or_pitch_unit_off_by_a_factor_is_named(factor, pitch, cause):
    """The flat plate with its K column scaled, or its pitch derivatives per degree.

    Each gave a flutter speed with no warning (Theodorsen's plate on the test rig, 11.85 m/s:
    23.70 with K on the half-width, 5.93 with K doubled, 27.5 per degree). The clean
    plate's median |H1*| / |K H3*| is 0.9 to 1 (Theodorsen, written out above); the slip moves
    it by the factor, which the warning states.
    """
    K = np.geomspace(0.2, 3.0, 40)
    exact = _theodorsen_table(K)
    clean_ratio = float(np.median(np.abs(exact["H1"] / (K * exact["H3"]))))
    assert 0.9 < clean_ratio < 1.0
    assert check_table(FlutterDerivativeTable(K, exact)) == []
    values = {n: v * pitch if n in ("H2", "H3", "A2", "A3") else v for n, v in exact.items()}
    (found,) = check_table(FlutterDerivativeTable(K * factor, values, source="deck.csv"))
    assert found.startswith("deck.csv: |H1*| is ") and cause in found, found
    expected = clean_ratio / factor / pitch
    assert _ratio(found) == pytest.approx(expected, rel=0.03)


def test_the_scale_check_spares_clean_and_noisy_tables_and_the_bluff_decks():
    """No scale warning on the bluff decks (0.90-0.99) or under 5 % noise (ten seeds)."""
    tables = [_example(), _plate(60, (0.1, 4.0)),
              FlutterDerivativeTable.from_model(bluff_deck_3dof_model(), np.geomspace(0.05, 3, 60))]
    for table in tables:
        assert check_table(table) == []
        for seed in range(10):
            assert not any("|H1*|" in w for w in check_table(_noisy(table, 0.05, seed)))
