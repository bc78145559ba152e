"""The run writer's trigger anchors: which PLC pulses measure a clock map's latency floor.

The writer alone, fed synthetic scanner blocks with exact clocks: every frame reaches the host
LATENCY_S late, the scanner latches each PLC trigger pulse on its own (PTP) clock, and the PLC's
trigger events carry their command's round trip with the pulse at its midpoint (legs alike).
A pulse is an anchor if its round trip is under ``MAX_ANCHOR_ROUND_TRIP_S``; the map's floor is
then the latency, and without any anchor the map is late by the whole latency (floor 0).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from daq.config import parse_rig_config
from daq.recording.writer import MAX_ANCHOR_ROUND_TRIP_S, RunWriter

from support.configs import SIM_FLAT_PLATE
from support.scanner_stream import LATENCY_S, PTP_EPOCH_S, PULSE_S, scanner_run_docs

RATE_HZ = 500.0  # the scanner's frame rate in sim_flat_plate.toml
DURATION_S = 6.0


def _docs(round_trip_s: float) -> list[tuple[str, Any]]:
    """One scan on PTP time whose scanner latches every pulse; the pulses' round trips given."""
    true = np.arange(int(DURATION_S * RATE_HZ)) / RATE_HZ
    pulses = np.arange(0.25, true[-1], PULSE_S)
    k = np.searchsorted(pulses, true, side="right") - 1  # the last pulse at each frame
    trigger_time = np.where(k >= 0, PTP_EPOCH_S + pulses[np.maximum(k, 0)], np.nan)
    return scanner_run_docs(true, PTP_EPOCH_S + true, np.arange(1, true.size + 1),
                            np.zeros((true.size, 64)), trigger_time, true + LATENCY_S, pulses,
                            round_trip_s=round_trip_s)


def _scanner_fit(tmp_path: Path, round_trip_s: float) -> dict[str, float]:
    config = parse_rig_config(SIM_FLAT_PLATE.read_text(), "sim_flat_plate.toml")
    writer = RunWriter(tmp_path / "run.h5", config, write_interval_s=0.0)
    for name, doc in _docs(round_trip_s):
        writer(name, doc)
    assert writer.error is None
    assert writer.summary is not None
    fit: dict[str, float] = writer.summary["clock_fits"]["scanner"]
    return fit


@pytest.mark.parametrize("round_trip_s", [0.4e-3, 2.5e-3])
def test_pulses_under_the_cut_anchor_the_map(tmp_path: Path, round_trip_s: float) -> None:
    fit = _scanner_fit(tmp_path, round_trip_s)
    assert fit["anchors"] >= 10  # 12 pulses; the first may come before the map is ready
    # Exact midpoints and clocks: the floor is the latency, to the envelope's resolution
    # (the frames arrive exactly LATENCY_S late: 1 us for float rounding).
    assert fit["latency_floor_s"] == pytest.approx(LATENCY_S, abs=1e-6)
    assert fit["anchor_uncertainty_s"] == pytest.approx(0.5 * round_trip_s)


def test_a_pulse_slower_than_the_cut_is_no_anchor(tmp_path: Path) -> None:
    fit = _scanner_fit(tmp_path, 1.5 * MAX_ANCHOR_ROUND_TRIP_S)
    assert fit["anchors"] == 0
    assert fit["latency_floor_s"] == 0.0  # the assumed floor: the map is late by the latency
    assert np.isnan(fit["anchor_uncertainty_s"])
