"""The campaign report from an outcome: campaign.json's required keys, the page, the plots."""

from __future__ import annotations

import json
from pathlib import Path

from daq.campaign.adaptive import Choice
from daq.campaign.report import read_previous, write_report
from daq.campaign.runner import CampaignOutcome, SpeedStep


def _outcome(tmp_path: Path) -> CampaignOutcome:
    steps = [SpeedStep(1, 5.0, tmp_path / "speed01_U05.00.h5", 2, "listed in the plan",
                       wind_on_s=12.0),
             SpeedStep(2, 7.0, tmp_path / "speed02_U07.00.h5", 2, "listed in the plan", 11.9,
                       0.4, 25.0),
             SpeedStep(3, 9.5, tmp_path / "speed03_U09.50.h5", 2, "chosen 9.50 m/s", 11.91,
                       0.08, 40.0, flutter_std_parts={
                           "noise": 0.01, "structure": 0.03, "release_scatter": 0.07,
                           "extrapolation": 0.0})]
    choice = Choice(9.5, "chosen 9.50 m/s", 0.4, ((9.0, 0.2), (9.5, 0.17)), 9.6)
    return CampaignOutcome(steps=steps, stopped_because="target met", wind_on_s=45.0,
                           wall_s=50.0, truth_flutter_speed=11.849, choices=[choice],
                           recording_warnings=[f"u7.h5: {NO_ANCHOR}"])


#: A run file's warning, as the runner keeps it (named by its file).
NO_ANCHOR = "no PLC trigger pulse reached this file: the clock map of scanner has no anchor"


def test_campaign_json_holds_what_the_issue_asks(tmp_path):
    outcome = _outcome(tmp_path)
    paths = write_report(outcome, tmp_path)
    data = json.loads(paths["json"].read_text())
    # No analysis object here: the estimate is None, the history keeps each speed's.
    for key in ("flutter_speed", "flutter_speed_std", "speeds", "wind_on_s", "stopped_because",
                "truth_flutter_speed"):
        assert key in data
    assert data["speeds"] == [5.0, 7.0, 9.5]
    assert data["wind_on_s"] == 45.0 and data["stopped_because"] == "target met"
    assert [h["flutter_speed_std"] for h in data["history"]] == [None, 0.4, 0.08]
    assert [h["wind_on_s"] for h in data["history"]] == [12.0, 25.0, 40.0]
    assert [h["flutter_speed_std_parts"] for h in data["history"][:2]] == [None, None]
    assert data["history"][2]["flutter_speed_std_parts"]["release_scatter"] == 0.07
    assert data["choices"][0]["predicted_std"] == [[9.0, 0.2], [9.5, 0.17]]
    assert data["warnings"] == [f"u7.h5: {NO_ANCHOR}"]  # no analysis: the recordings' only
    assert paths["std_history"].stat().st_size > 0
    page = paths["markdown"].read_text()
    assert "Stopped because: target met" in page
    assert f"Warnings:\n\n- u7.h5: {NO_ANCHOR}\n" in page
    assert "| 3 | 9.50 | 2 | 11.910 | 0.080 | release scatter 0.070 | 40.0 |" in page
    assert "| 2 | 7.00 | 2 | 11.900 | 0.400 |  | 25.0 |" in page  # no parts: nothing made up
    assert "bound 9.60 m/s; 9.00: 0.200, 9.50: 0.170" in page
    assert "![std_history](campaign_std_history.png)" in page
    assert read_previous(tmp_path)["wind_on_s"] == 45.0


def test_read_previous_is_none_without_a_readable_report(tmp_path):
    assert read_previous(tmp_path) is None
    (tmp_path / "campaign.json").write_text("{not json")
    assert read_previous(tmp_path) is None
