"""The run writer's trigger anchors: which PLC pulses measure a clock map's latency floor.

The writer alone, fed synthetic scanner blocks with exact clocks: every frame reaches the host
LATENCY_S late, the scanner latches each PLC trigger pulse on its own (PTP) clock, and the PLC's
trigger events carry their command's round trip with the pulse at its midpoint (legs alike).
A pulse is an anchor if its round trip is under ``MAX_ANCHOR_ROUND_TRIP_S``; the map's floor is
then the latency, and without any anchor the map is late by the whole latency (floor 0), which
the summary, the file and the log then warn of, naming the cause.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from daq.config import parse_rig_config
from daq.recording.devices import DeviceState, new_clock_map
from daq.recording.info import run_info
from daq.recording.trigger_anchors import MAX_ANCHOR_ROUND_TRIP_S, TriggerPulses
from daq.recording.writer import RunWriter
from ident.records.run_file import read_run
from ident.records.run_set import recording_notes

from support.configs import SIM_FLAT_PLATE
from support.scanner_stream import LATENCY_S, PTP_EPOCH_S, PULSE_S, scanner_run_docs

RATE_HZ = 500.0  # the scanner's frame rate in sim_flat_plate.toml
DURATION_S = 6.0
#: The run's trigger pulses, host s (the scanner latches each: as many trigger times).
PULSES = np.arange(0.25, DURATION_S - 1.0 / RATE_HZ, PULSE_S)


def _docs(round_trip_s: float, *, latch_shift_s: float = 0.0,
          pulses_sent: bool = True) -> list[tuple[str, Any]]:
    """One scan on PTP time whose scanner latches every pulse; the pulses' round trips given.

    ``latch_shift_s`` moves the latched times off the pulses (a latch from another line);
    ``pulses_sent=False`` drops the PLC's trigger events (the scanner latches the same).
    """
    true = np.arange(int(DURATION_S * RATE_HZ)) / RATE_HZ
    pulses = PULSES
    k = np.searchsorted(pulses, true, side="right") - 1  # the last pulse at each frame
    trigger_time = np.where(k >= 0, PTP_EPOCH_S + latch_shift_s + pulses[np.maximum(k, 0)],
                            np.nan)
    docs = scanner_run_docs(true, PTP_EPOCH_S + true, np.arange(1, true.size + 1),
                            np.zeros((true.size, 64)), trigger_time, true + LATENCY_S, pulses,
                            round_trip_s=round_trip_s)
    if not pulses_sent:
        docs = [(name, doc) for name, doc in docs
                if not (name == "event" and doc.kind == "trigger")]
    return docs


def _summary(tmp_path: Path, docs: list[tuple[str, Any]]) -> dict[str, Any]:
    config = parse_rig_config(SIM_FLAT_PLATE.read_text(), "sim_flat_plate.toml")
    writer = RunWriter(tmp_path / "run.h5", config, write_interval_s=0.0)
    for name, doc in docs:
        writer(name, doc)
    assert writer.error is None
    assert writer.summary is not None
    return writer.summary


def _scanner_fit(tmp_path: Path, round_trip_s: float) -> dict[str, float]:
    fit: dict[str, float] = _summary(tmp_path, _docs(round_trip_s))["clock_fits"]["scanner"]
    return fit


def _file_warnings(path: Path) -> tuple[list[str], list[str]]:
    """Return the file's stored summary warnings and its ``warning`` events' texts (h5py)."""
    with h5py.File(path, "r") as f:
        stored = [w.decode() if isinstance(w, bytes) else str(w) for w in
                  f["entry/metadata/acquisition_summary/warnings"][()]]
        events = f["entry/events"][()]
        texts = [row["text"].decode() for row in events if row["kind"].decode() == "warning"]
    return stored, texts


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


def test_a_file_with_anchors_warns_of_nothing(tmp_path: Path) -> None:
    summary = _summary(tmp_path, _docs(0.4e-3))
    assert summary["warnings"] == []
    assert _file_warnings(tmp_path / "run.h5") == ([], [])
    assert read_run(tmp_path / "run.h5").recording_warnings == ()


def _no_trigger_channel(docs: list[tuple[str, Any]]) -> list[tuple[str, Any]]:
    """Return the same stream as a driver that reports no trigger times would give it."""
    for name, doc in docs:
        if name == "block":
            doc.values.pop("trigger_time")
    return docs


#: Each cause of a map without anchors: the stream, and words its warning must hold.
N = PULSES.size
CAUSES: dict[str, tuple[Callable[[], list[tuple[str, Any]]], tuple[str, ...]]] = {
    "every pulse slow": (lambda: _docs(1.5 * MAX_ANCHOR_ROUND_TRIP_S),
                         (f"every one of the {N} PLC trigger pulses took over 3 ms",)),
    "no pulse": (lambda: _docs(0.4e-3, pulses_sent=False),
                 ("no PLC trigger pulse reached this file",)),
    "latch off the pulses": (lambda: _docs(0.4e-3, latch_shift_s=0.2),
                             (f"scanner: reported {N} trigger time(s), none within 50 ms of one "
                              f"of the {N} usable PLC pulses",)),
    "no trigger input": (lambda: _no_trigger_channel(_docs(0.4e-3)),
                         ("scanner: reports no trigger times",)),
}


@pytest.mark.parametrize("cause", list(CAUSES))
def test_a_map_without_anchors_is_warned_of_with_its_cause(tmp_path: Path, cause: str) -> None:
    make_docs, words = CAUSES[cause]
    summary = _summary(tmp_path, make_docs())
    assert summary["clock_fits"]["scanner"]["anchors"] == 0
    assert len(summary["warnings"]) == 1, summary["warnings"]
    warning = summary["warnings"][0]
    for word in (*words, "the clock map of scanner has no anchor",
                 "late by its transport latency"):
        assert word in warning, warning
    # The file keeps it: in the stored summary and as an event, which `windrig info` shows.
    assert _file_warnings(tmp_path / "run.h5") == ([warning], [warning])
    assert run_info(tmp_path / "run.h5")["warnings"] == [warning]
    # Identification reads it back and passes it on, led by the file.
    run = read_run(tmp_path / "run.h5")
    assert run.recording_warnings == (warning,)
    assert recording_notes([run]) == [f"{run.path}: recorded with a warning: {warning}"]


def test_a_latched_trigger_without_its_pulse_is_no_anchor_but_counted() -> None:
    pulses = TriggerPulses()
    assert pulses.take(1.0, 0.4e-3) and not pulses.take(1.5, 4e-3)
    assert not pulses.take(2.0, float("nan"))  # no round trip known: no midpoint either
    assert (pulses.received, pulses.slow) == (3, 2)
    assert list(pulses.events) == [(1.0, 0.2e-3)]


def test_one_cause_names_every_device_it_left_without_anchors() -> None:
    devices = {name: DeviceState(name, kind, ["x"], rate, clock=new_clock_map())
               for name, kind, rate in (("scanner", "scanner", 500.0),
                                        ("laser_h", "laser", 4000.0),
                                        ("laser_a", "laser", 4000.0))}
    devices["barometer"] = DeviceState("barometer", "barometer", ["p"], 1.0)  # polled: no clock
    for dev in devices.values():
        if dev.clock is not None:
            dev.clock.update(1.0, 1.001)  # ready: one (device, host) pair
    devices["laser_a"].clock.add_anchor(1.0, 1.0005, 2e-4)  # type: ignore[union-attr]
    warnings = TriggerPulses().anchor_warnings(devices)  # no pulse in the file
    assert len(warnings) == 1
    assert ("the clock maps of scanner and laser_h have no anchor, so their samples are placed "
            "late by their transport latency") in warnings[0], warnings
    assert TriggerPulses().anchor_warnings({"laser_a": devices["laser_a"]}) == []
    assert "trigger anchors are switched off" in TriggerPulses().anchor_warnings(
        devices, anchors_used=False)[0]
