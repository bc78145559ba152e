"""``windrig flutter --table`` with published-style tables: the number, and the slips named.

The truth is Theodorsen's typical section solved here on its own (the classical flutter
determinant in Theodorsen's notation, half-chord b, lift positive up; Bisplinghoff, Ashley and
Halfman, "Aeroelasticity", 1955), independent of windrig's conventions, tables and routes.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import fsolve
from scipy.special import hankel2

from daq.cli import main
from ident.tables.fd_table import FlutterDerivativeTable
from simulators.decks import bluff_deck_3dof_model

#: The test rig's flat plate (chord 0.3 m, 3 kg/m, 0.03 kg m^2/m, 2 and 4 Hz, 0.5 %).
SECTION = {"B": 0.3, "m": 3.0, "I": 0.03, "fh": 2.0, "fa": 4.0, "zeta_h": 0.005,
           "zeta_a": 0.005, "rho": 1.225, "S": 0.0}


def _theodorsen(k: np.ndarray) -> np.ndarray:
    return hankel2(1, k) / (hankel2(1, k) + 1j * hankel2(0, k))


def _classical_flutter() -> tuple[float, float]:
    """Return Theodorsen's flutter speed (m/s) and frequency (Hz) of SECTION, mid-chord axis.

    ``det [[m s^2 + c_h s + k_h + L_h, L_a], [-M_h, I s^2 + c_a s + k_a - M_a]] = 0`` at
    ``s = i omega`` with Theodorsen's lift (up) and moment (nose-up) on a plate with its
    elastic axis at mid-chord (a = 0) and h down, solved for real (U, omega).
    """
    B, m, I, rho = SECTION["B"], SECTION["m"], SECTION["I"], SECTION["rho"]
    b = B / 2
    wh, wa = 2 * math.pi * SECTION["fh"], 2 * math.pi * SECTION["fa"]

    def det(x: np.ndarray) -> list[float]:
        U, w = x
        s, C = 1j * w, _theodorsen(np.array(w * b / U))
        L_h = math.pi * rho * b**2 * s**2 + 2 * math.pi * rho * U * b * C * s
        L_a = math.pi * rho * b**2 * U * s + 2 * math.pi * rho * U * b * C * (U + b * s / 2)
        M_h = math.pi * rho * U * b**2 * C * s
        M_a = (math.pi * rho * b**2 * (-U * b * s / 2 - b**2 * s**2 / 8)
               + math.pi * rho * U * b**2 * C * (U + b * s / 2))
        d = ((m * s**2 + 2 * SECTION["zeta_h"] * m * wh * s + m * wh**2 + L_h)
             * (I * s**2 + 2 * SECTION["zeta_a"] * I * wa * s + I * wa**2 - M_a)
             + L_a * M_h) / (m * wh**2 * I * wa**2)
        return [float(np.real(d)), float(np.imag(d))]

    U, w = fsolve(det, [12.0, 2 * math.pi * 3.0], xtol=1e-13)
    return float(U), float(w / (2 * math.pi))


def _write_plate(path: Path, K_column_factor: float = 1.0) -> None:
    """Write Theodorsen's derivatives (Scanlan's forms, K = B omega / U) at K 0.2 to 3."""
    K = np.geomspace(0.2, 3.0, 40)
    C = _theodorsen(K / 2)
    F, G, pi = C.real, C.imag, math.pi
    values = {"H1": -2 * pi * F / K, "H2": -(pi / (2 * K)) * (1 + F + 4 * G / K),
              "H3": -(2 * pi / K**2) * (F - K * G / 4), "H4": (pi / 2) * (1 + 4 * G / K),
              "A1": pi * F / (2 * K), "A2": -(pi / (8 * K)) * (1 - F - 4 * G / K),
              "A3": (pi / (2 * K**2)) * (K**2 / 32 + F - K * G / 4), "A4": -pi * G / (2 * K)}
    FlutterDerivativeTable(K * K_column_factor, values).to_csv(path)


def _flutter(tmp_path: Path, table: Path) -> dict:
    section = tmp_path / "section.json"
    section.write_text(json.dumps(SECTION))
    out = tmp_path / "out.json"
    assert main(["flutter", "--section", str(section), "--table", str(table),
                 "--json", str(out)]) == 0
    return json.loads(out.read_text())


def test_theodorsen_s_table_flutters_at_the_classical_speed(tmp_path: Path):
    """Both routes within 0.1 % of the classical determinant (11.85 m/s, 2.951 Hz)."""
    U_F, f_F = _classical_flutter()
    table = tmp_path / "plate.csv"
    _write_plate(table)
    result = _flutter(tmp_path, table)
    assert result["result"]["flutter_speed"] == pytest.approx(U_F, rel=1e-3)
    assert result["flutter_speed_frequency_domain"] == pytest.approx(U_F, rel=1e-3)
    assert result["result"]["flutter_frequency"] == pytest.approx(f_F, rel=1e-3)
    assert not any("|H1*|" in w for w in result["warnings"])


def test_a_k_column_on_the_half_chord_is_warned_of_in_the_json(tmp_path: Path):
    """K = b omega / U in the column: 23.7 m/s, twice the truth, now with the slip named."""
    U_F, _ = _classical_flutter()
    table = tmp_path / "plate_kb.csv"
    _write_plate(table, K_column_factor=0.5)
    result = _flutter(tmp_path, table)
    assert result["result"]["flutter_speed"] == pytest.approx(2 * U_F, rel=2e-3)
    assert any("reduced frequency on the half-width" in w for w in result["warnings"])


def test_a_three_dof_table_on_a_section_without_sway_says_what_it_leaves_out(tmp_path: Path):
    """The 18 derivatives, a section without fp: heave and pitch alone, said in the JSON."""
    table = tmp_path / "deck3.csv"
    FlutterDerivativeTable.from_model(bluff_deck_3dof_model(), np.geomspace(0.2, 3.0, 30)
                                      ).to_csv(table)
    result = _flutter(tmp_path, table)
    (found,) = [w for w in result["warnings"] if "sway and drag" in w]
    assert found.startswith(f"{table} gives the sway and drag derivatives H5, H6, A5, A6, P1")
    assert "no lateral spring (fp)" in found
