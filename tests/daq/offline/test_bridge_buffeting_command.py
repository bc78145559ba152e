"""``windrig bridge --buffeting``: the example bridge's buffeting through the command line."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from daq.cli import main
from ident.model import flat_plate

from support.configs import BRIDGES

BRIDGE = BRIDGES / "example_bridge.json"
WIND = BRIDGES / "example_wind.toml"


@pytest.fixture
def model(tmp_path: Path) -> Path:
    path = tmp_path / "model.json"
    path.write_text(json.dumps(flat_plate.jones_model().to_dict()), encoding="utf-8")
    return path


def test_example_bridge_buffeting_json_and_plots(tmp_path: Path, model: Path, capsys) -> None:
    """DESIGN's keys at every speed; the seeded 1800 s record within 4 stated std of the FD RMS.

    The tolerance is 4 standard deviations (0.5 sqrt(T_c/T), printed and in the JSON) at the
    node of largest RMS heave, on one fixed seed.
    """
    out = tmp_path / "result.json"
    assert main(["bridge", str(BRIDGE), "--aero", str(model), "--buffeting", "30,45",
                 "--wind", str(WIND), "--time-domain", "1800", "--json", str(out),
                 "--out", str(tmp_path / "plots")]) == 0
    text = capsys.readouterr().out
    assert "buffeting at U = 45 m/s (frequency domain): largest RMS h" in text
    result = json.loads(out.read_text())
    assert [b["U"] for b in result["buffeting"]] == [30.0, 45.0]
    for entry in (*result["buffeting"], *result["time_domain"]):
        assert set(entry) >= {"U", "x", "rms_h", "rms_alpha", "rms_p"}
        assert len(entry["x"]) == len(entry["rms_h"]) == len(entry["rms_alpha"]) == 41
        assert entry["rms_h"][0] == 0.0 and entry["rms_h"][20] > 0.0  # supported ends
    for freq, time in zip(result["buffeting"], result["time_domain"], strict=True):
        std = time["rms_relative_std"]
        k = max(range(len(std["x"])), key=lambda i: freq["rms_h"][freq["x"].index(std["x"][i])])
        node = freq["x"].index(std["x"][k])
        for name in ("h", "alpha", "p"):
            ratio = time[f"rms_{name}"][node] / freq[f"rms_{name}"][node]
            assert abs(ratio - 1.0) < 4.0 * std[name][k], (freq["U"], name)
        assert time["duration"] == pytest.approx(1800.0, rel=0.01)
    # The response grows with the wind.
    assert result["buffeting"][1]["rms_h"][20] > result["buffeting"][0]["rms_h"][20]
    for name in ("buffeting_rms.png", "buffeting_spectra.png"):
        assert (tmp_path / "plots" / name).stat().st_size > 10_000
    rows = (tmp_path / "plots" / "buffeting_rms.csv").read_text().splitlines()
    assert rows[0] == "U_m_s,x_m,method,rms_h_m,rms_alpha_rad,rms_p_m"
    assert len(rows) == 1 + 4 * 41
    assert not any(isinstance(v, float) and math.isnan(v)
                   for t in result["time_domain"] for v in t["rms_relative_std"]["p"])


@pytest.mark.parametrize(("wind_text", "args", "message"), [
    ("Iu = 0.1\n", ["--buffeting", "30"], "wind.toml: missing key(s) Cuy, Cwy, Iw, Lux, Lwx"),
    (None, ["--buffeting", "95"], "--buffeting 95: U = 95 m/s is at or above the flutter"),
])
def test_buffeting_errors_are_one_line(tmp_path: Path, model: Path, capsys,
                                       wind_text: str | None, args: list[str],
                                       message: str) -> None:
    wind = WIND
    if wind_text is not None:
        wind = tmp_path / "wind.toml"
        wind.write_text(wind_text, encoding="utf-8")
    code = main(["bridge", str(BRIDGE), "--aero", str(model), "--wind", str(wind), *args])
    err = capsys.readouterr().err
    assert code in (1, 2)
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(lines) == 1 and message in lines[0], err
    assert "Traceback" not in err


def test_an_intensity_in_per_cent_is_one_error_line(tmp_path: Path, model: Path,
                                                    capsys) -> None:
    """``Iu = 15`` (15 %) had been taken as sigma_u = 15 U: a sway RMS of 35 m, exit 0."""
    wind = tmp_path / "wind.toml"
    wind.write_text(WIND.read_text(encoding="utf-8").replace("Iu = 0.10", "Iu = 15"),
                    encoding="utf-8")
    code = main(["bridge", str(BRIDGE), "--aero", str(model), "--wind", str(wind),
                 "--buffeting", "30"])
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert code == 2 and "Traceback" not in err
    assert lines == [f"error: {wind}: key Iu = 15 is sigma / U, a fraction < 1 (a percentage? "
                     "15 % is 0.15)"]


def test_slips_and_extrapolation_are_warnings_in_the_json(tmp_path: Path, capsys) -> None:
    """A length scale in km, a lift slope of the source's sign and a table left behind.

    The bridge's ``dC_L = +5`` (lift up) and ``Lux = 0.15`` (km) are warnings; with the table
    (K 0.314 to 3.14), at 45 m/s the lateral mode L1S (0.052 Hz) resonates at K = 2 pi f B / U
    = 0.225: its entry names it in ``extrapolated_modes``, with a warning; at 30 m/s every mode
    is inside (K of L1S 0.337, of T1A 2.37).
    """
    data = json.loads(BRIDGE.read_text(encoding="utf-8"))
    data["static"]["dC_L"] = 5.0
    bridge = tmp_path / "bridge.json"
    bridge.write_text(json.dumps(data), encoding="utf-8")
    wind = tmp_path / "wind.toml"
    wind.write_text(WIND.read_text(encoding="utf-8").replace("Lux = 150.0", "Lux = 0.15"),
                    encoding="utf-8")
    out = tmp_path / "result.json"
    assert main(["bridge", str(bridge), "--aero", str(BRIDGES / "example_deck_table.csv"),
                 "--buffeting", "30,45", "--wind", str(wind), "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    result = json.loads(out.read_text())
    warnings = result["warnings"]
    assert f"{wind}: Lux = 0.15 m is no atmospheric length scale (tens to hundreds of m at a " \
           "deck): given in km? 0.15 km is 150 m" in warnings
    assert any(line.startswith("static dC_L = 5 > 0 drives the buffeting lift") for line in
               warnings)
    at30, at45 = result["buffeting"]
    assert at30["extrapolated_modes"] == []
    [row] = at45["extrapolated_modes"]
    assert row["mode"].startswith("L1S") and row["K"] == pytest.approx(
        2 * math.pi * row["frequency"] * 31.0 / 45.0, rel=1e-12)
    assert row["K"] == pytest.approx(0.225, abs=0.001)
    line = next(w for w in warnings if w.startswith("buffeting at U = 45 m/s: L1S"))
    assert "outside the table's K 0.314 to 3.14" in line and f"warning: {line}" in printed
