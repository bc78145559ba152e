"""The design report and JSON of `windrig flutter` (daq.offline.design_report, flutter_commands)."""

from __future__ import annotations

import hashlib
import json

from daq.cli import main

from support.configs import BRIDGES
from support.sections import FLAT_PLATE


def test_flutter_report_of_a_shifted_table(tmp_path, capsys):
    """A2* + 0.15 at every row of the shipped table, a section file without rho.

    The page holds the inputs' hashes, the default taken, both routes and the basis, the
    warnings, the two plots; the JSON the same numbers with units and warnings.
    """
    lines = (BRIDGES / "example_deck_table.csv").read_text().splitlines()
    header = lines[1].split(",")
    a2 = header.index("A2")
    rows = []
    for line in lines[2:]:
        cells = line.split(",")
        cells[a2] = repr(float(cells[a2]) + 0.15)
        rows.append(",".join(cells))
    table = tmp_path / "shifted.csv"
    table.write_text("\n".join([lines[1], *rows]) + "\n")
    section = tmp_path / "section.json"
    data = FLAT_PLATE.to_dict()
    data.pop("rho")
    section.write_text(json.dumps(data))
    out, result = tmp_path / "report", tmp_path / "result.json"
    assert main(["flutter", "--section", str(section), "--table", str(table), "--json",
                 str(result), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    default = f"{section}: no air density rho: taken as 1.225 kg/m^3 (ISA sea level)"
    assert f"note: {default}" in printed
    # The shifted column is named by the table's own checks, before any flutter analysis.
    assert f"warning: {table}: A2* tends to" in printed
    assert "warning: the two routes disagree" in printed
    summary = json.loads(result.read_text())
    result = summary["result"]
    assert result["basis"] == "frequency-domain"
    assert result["flutter_speed"] == summary["flutter_speed_frequency_domain"] > 5.0
    # flutter_speed is the state space's (the command's contract), the result the table's.
    assert summary["flutter_speed"] != result["flutter_speed"]
    assert summary["defaults"][0] == default
    assert summary["units"]["flutter_frequency"] == "Hz"
    assert any("below the table's range" in w for w in summary["warnings"])
    page = (out / "report.md").read_text()
    assert hashlib.sha256(table.read_bytes()).hexdigest() in page
    assert "| rests on | frequency-domain" in page
    assert default in page
    for warning in summary["warnings"]:
        assert warning in page
    for png in ("derivatives.png", "modes.png"):
        assert (out / png).stat().st_size > 10_000
        assert f"]({png})" in page
