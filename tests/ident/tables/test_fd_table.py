"""Flutter-derivative tables: CSV in and out, sign conventions, interpolation, flutter."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from ident.model import flat_plate
from ident.model import flutter as fl
from ident.model.conventions import FLUTTER_DERIVATIVE_NAMES_3DOF, Q_from_flutter_derivatives
from ident.model.quasi_steady import StaticCoefficients, quasi_steady_model
from ident.tables.fd_table import FlutterDerivativeTable
from ident.tables.roger_table import fit_table
from simulators.decks import BLUFF_DECK, bluff_deck_model

from support.sections import FLAT_PLATE

BLUFF = StaticCoefficients(C_D=0.9, C_L=-0.15, C_M=0.02, dC_D=-0.4, dC_L=-4.5, dC_M=1.1)
MODEL_3DOF = flat_plate.jones_model().with_sway(quasi_steady_model(BLUFF))


def test_csv_round_trip_of_18_derivatives(tmp_path: Path):
    K = np.geomspace(0.1, 3.0, 25)
    table = FlutterDerivativeTable.from_model(MODEL_3DOF, K)
    table.to_csv(tmp_path / "t.csv")
    back = FlutterDerivativeTable.from_csv(tmp_path / "t.csv")
    assert back.n_dof == 3 and back.filled == ()
    np.testing.assert_array_equal(back.K, table.K)  # repr(): exact
    for name in FLUTTER_DERIVATIVE_NAMES_3DOF:
        np.testing.assert_array_equal(back.values[name], table.values[name])


def test_reduced_velocity_column_missing_derivatives_and_comments(tmp_path: Path):
    """Ur = 2 pi / K; rows in any order; a missing derivative is zero and reported as filled."""
    path = tmp_path / "t.csv"
    path.write_text("# a published table\nUr, H1*, A2*\n10, -3.0, -0.5\n\n5, -1.5, -0.2\n")
    table = FlutterDerivativeTable.from_csv(path)
    np.testing.assert_allclose(table.K, [2 * math.pi / 10, 2 * math.pi / 5], rtol=1e-15)
    np.testing.assert_array_equal(table.values["H1"], [-3.0, -1.5])
    assert table.n_dof == 2
    assert set(table.filled) == {"H2", "H3", "H4", "A1", "A3", "A4"}
    np.testing.assert_array_equal(table.values["H4"], 0.0)
    # Asked for 3 DOF, the ten drag and sway derivatives are filled too.
    assert len(FlutterDerivativeTable.from_csv(path, n_dof=3).filled) == 16


def _forces(fd: dict[str, float], K: float, h: complex, alpha: complex, p: complex) -> np.ndarray:
    """Generalised forces [L B, M, D B] / (qd B^2) of harmonic motion, from Q (windrig's form)."""
    Q = Q_from_flutter_derivatives([K], {n: np.array([v]) for n, v in fd.items()})[0]
    return Q @ np.array([h, alpha, p])


def test_z_up_convention_is_the_same_physics_with_h_and_L_upward(tmp_path: Path):
    """A table written with h and L upward reads as the same physics.

    Its forces on an upward motion z are windrig's on h = -z with the lift negated (the same
    moment and drag).
    """
    rng = np.random.default_rng(3)
    ours = {n: float(rng.normal()) for n in FLUTTER_DERIVATIVE_NAMES_3DOF}
    path = tmp_path / "zup.csv"
    flips = {"H2", "H3", "H5", "H6", "A1", "A4", "P5", "P6"}
    z_up = {n: (-v if n in flips else v) for n, v in ours.items()}
    names = list(FLUTTER_DERIVATIVE_NAMES_3DOF)
    path.write_text("K," + ",".join(names) + "\n0.8," + ",".join(repr(z_up[n]) for n in names))
    table = FlutterDerivativeTable.from_csv(path, convention="z_up")
    read = {n: float(table.values[n][0]) for n in names}
    for n in names:
        assert read[n] == pytest.approx(ours[n], rel=1e-15)
    # The physics: with z up, lift up, the z-up derivatives in the same formulas give forces
    # [L_up B, M, D B] that must equal [-L B, M, D B] of windrig's on h = -z.
    z, alpha, p = 0.3 + 0.1j, 0.02j, -0.05
    up = _forces(z_up, 0.8, z, alpha, p)
    down = _forces(ours, 0.8, -z, alpha, p)
    np.testing.assert_allclose(up, down * np.array([-1, 1, 1]), rtol=1e-12)


@pytest.mark.parametrize(("text", "message"), [
    ("U,H1\n1,2\n", "first column must be K or Ur"),
    ("K,H1,X9\n1,2,3\n", "unknown column(s) ['X9']"),
    ("K,H1\n1,abc\n", "line 2: 'abc' is not a number"),
    ("K,H1\n1,2,3\n", "line 2: 3 values for 2 columns"),
    ("K,H1\n1,2\n1,3\n", "K = 1 appears twice"),
    ("K,H1\n1,nan\n", "H1 is not finite at K = 1"),
    ("K,H1\n-1,2\n", "every K must be finite and > 0"),
    ("K,H1\n", "no rows below the header"),
    ("K,H1,H1*\n1,2,3\n", "appear twice"),
    # Milan's notation, never read as Scanlan's capitals: a lower-case column is refused.
    ("Ur,h1*,h4*,a1*,a4*\n5,1,2,3,4\n", "['h1*', 'h4*', 'a1*', 'a4*'] are in lower case"),
    ("k,H1,a2\n1,2,3\n", "['a2'] are in lower case"),
])
def test_bad_tables_get_one_clear_error(tmp_path: Path, text: str, message: str):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ValueError) as info:
        FlutterDerivativeTable.from_csv(path)
    assert message in str(info.value) and str(path) in str(info.value)


def test_unknown_convention_is_refused_not_guessed(tmp_path: Path):
    path = tmp_path / "t.csv"
    path.write_text("K,H1\n1,2\n")
    with pytest.raises(ValueError, match="unknown convention 'z_down'; allowed: scanlan, z_up"):
        FlutterDerivativeTable.from_csv(path, convention="z_down")


def test_interpolation_stays_inside_the_table():
    K = np.geomspace(0.2, 2.0, 40)
    table = FlutterDerivativeTable.from_model(flat_plate.jones_model(), K)
    f = table.interpolator()
    np.testing.assert_allclose(f(K)["A2"], table.values["A2"], rtol=1e-14)
    with pytest.raises(ValueError, match="outside the table's range"):
        f(np.array([0.1]))


def test_flutter_from_a_tabulated_theodorsen_plate_matches_the_exact_function():
    """Theodorsen's plate tabulated at 60 K between 0.1 and 3 flutters where the exact one does.

    PCHIP between the rows moves the flutter speed by less than 1e-4 (its interpolation error
    at this density).
    """
    K = np.geomspace(0.1, 3.0, 60)
    table = FlutterDerivativeTable(K, flat_plate.flutter_derivatives(K))
    exact = fl.frequency_domain(FLAT_PLATE, flat_plate.flutter_derivatives, (0.1, 3.0))
    tabulated = fl.frequency_domain(FLAT_PLATE, table.interpolator(), (0.1, 3.0))
    assert exact.speed is not None and tabulated.speed is not None
    assert tabulated.speed == pytest.approx(exact.speed, rel=1e-4)


def test_a_3dof_roger_table_is_fitted_back_exactly():
    """The Jones plate with quasi-steady drag terms, tabulated: lags, A and U_F come back.

    Exact data: the variable-projection optimum is the truth to the solver's tolerance (lag
    roots to 1e-5; the flutter speed, less sensitive, to 1e-6).
    """
    K = np.geomspace(0.15, 3.0, 16)
    fit = fit_table(FlutterDerivativeTable.from_model(MODEL_3DOF, K), n_lags=2, with_A3=True)
    np.testing.assert_allclose(fit.model.d, flat_plate.JONES_LAGS, rtol=1e-5)
    assert fit.relative_error.max() < 1e-6
    section = FLAT_PLATE.replace(fp=1.5, zeta_p=0.005)
    truth = fl.analyze(section, MODEL_3DOF)
    assert fl.analyze(section, fit.model).speed == pytest.approx(truth.speed, rel=1e-6)


def test_a_bluff_deck_table_is_fitted_by_evidence_to_its_flutter_speed():
    """The bluff deck's table (reduced velocities 2 to 20) is fitted to its flutter speed.

    Its ten unshared lags are not of Roger's low-order form. The structure is chosen by
    held-out rows; the relative error stays under 0.5 % at every row and the flutter speed
    within 0.5 % of the truth (measured: 3 lags, 0.15 % worst row, -0.11 %).
    """
    K = 2 * np.pi / np.linspace(2.0, 20.0, 19)
    fit = fit_table(FlutterDerivativeTable.from_model(bluff_deck_model(), K))
    assert fit.relative_error.max() < 0.005, fit.summary()
    truth = fl.analyze(BLUFF_DECK, bluff_deck_model()).speed
    assert fl.analyze(BLUFF_DECK, fit.model).speed == pytest.approx(truth, rel=0.005)
    assert "lag" in fit.summary()


def test_table_fit_refuses_unknown_options():
    table = FlutterDerivativeTable.from_model(flat_plate.jones_model(), np.geomspace(0.2, 2, 8))
    with pytest.raises(ValueError, match="unknown weighting 'plain'; allowed: relative"):
        fit_table(table, weighting="plain")
    with pytest.raises(ValueError, match="n_lags must be an integer in 0..6"):
        fit_table(table, n_lags=7)
    with pytest.raises(ValueError, match="accuracy must be > 0"):
        fit_table(table, accuracy=0.0)
