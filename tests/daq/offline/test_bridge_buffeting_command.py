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
