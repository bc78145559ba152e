"""The operator control panel of the live console (pytest-qt, offscreen).

One live simulated rig, acquired in its own process as ``windrig gui`` runs it
(:class:`~daq.console.process_source.ProcessLiveSource`: every action crosses to the acquisition
process and back), runs the state checks and actions end to end:
forbidden actions disabled with a reason, arm then release (confirmation injected) recorded by the
engine with the model moving afterwards, a refused confirmation, the fan limit, CALZ refused while
the fan runs and done (the scan paused by the engine) once it is stopped. A fake source checks the
panel of a rig without a fan or PLC, without any device.
"""

from __future__ import annotations

import math
import time
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from daq.config import parse_rig_config
from daq.console.controls import ControlPanel
from daq.console.process_source import ProcessLiveSource
from daq.console.window import ConsoleWindow

from support.configs import live_config_text

pytestmark = pytest.mark.realtime


def _events(source: ProcessLiveSource, kind: str) -> list[Any]:
    """Return the engine's events of a kind, as the source's subscriber saw them."""
    return source.events(kind)


def test_controls_on_a_live_simulated_rig(qtbot):
    config = parse_rig_config(live_config_text(), "sim_flat_plate.toml + fast fan")
    source = ProcessLiveSource(config, simulate=True, window_s=10.0, fan_rpm=500.0)
    source.open()
    answers: list[bool] = []
    questions: list[str] = []

    def confirm(title: str, question: str) -> bool:
        questions.append(question)
        return answers.pop(0)

    try:
        window = ConsoleWindow(source, window_s=10.0, frame_ms=50, confirm=confirm)
        qtbot.addWidget(window)
        window.show()
        panel = window.controls
        assert panel is not None
        b = panel.buttons

        # The simulated PLC starts armed (the magnet holds the model): withdraw the permission
        # behind the panel's back (its next PLC reading shows it), for the state before arming.
        qtbot.waitUntil(lambda: panel.armed() is not None, timeout=5_000)  # the PLC was read
        source.acq.drivers["plc"].disarm()
        # Before arming: release disabled, and why (tooltip and status line).
        qtbot.waitUntil(lambda: panel.armed() is False, timeout=5_000)
        window.tick()  # the timer's re-evaluation, now
        assert not b["release"].isEnabled()
        assert b["release"].toolTip() == "release: arm first"
        assert "release: arm first" in panel.status_text
        # The fan runs (500 rpm at the start): CALZ is disabled.
        qtbot.waitUntil(lambda: source.fan_speed_rpm > 10.0, timeout=5_000)
        window.tick()
        assert not b["calz"].isEnabled()
        assert b["calz"].toolTip() == "CALZ: stop the fan first"
        assert "CALZ: stop the fan first" in panel.status_text
        # The fan box shows the actual speed read back from the drive; the engine recorded
        # when it settled at the set-point (fan_reached, 1 % of 500 rpm).
        qtbot.waitUntil(lambda: window.tick() or panel.fan_actual.text() == "actual 500 rpm",
                        timeout=5_000)
        qtbot.waitUntil(lambda: len(_events(source, "fan_reached")) == 1, timeout=5_000)
        assert abs(_events(source, "fan_reached")[0].data["rpm"] - 500.0) <= 5.0

        # The fan setpoint cannot exceed the limit; a direct call above it is refused.
        assert panel.fan_spin.maximum() == config.limits.max_fan_rpm
        panel.fan_spin.setValue(config.limits.max_fan_rpm + 500.0)
        assert panel.fan_spin.value() == config.limits.max_fan_rpm
        panel.apply_fan(config.limits.max_fan_rpm + 100.0)
        qtbot.waitUntil(lambda: panel.busy is None, timeout=5_000)
        assert "fan failed: SafetyError" in panel.status_text
        assert "max_fan_rpm" in panel.status_text

        # An event marker.
        panel.note_edit.setText("steady at 500 rpm")
        b["mark"].click()
        qtbot.waitUntil(lambda: any(e.text == "steady at 500 rpm" for e in _events(source, "note")),
                        timeout=5_000)

        # Arm, then release with the confirmation refused: nothing happens.
        assert b["arm"].isEnabled()
        b["arm"].click()
        qtbot.waitUntil(lambda: panel.busy is None and b["release"].isEnabled(), timeout=5_000)
        # the engine's event reaches the source through the dispatcher thread: soon, not now
        # (each check asks the acquisition process; 5 s, as the panel's waits, for a loaded host)
        qtbot.waitUntil(lambda: len(_events(source, "arm")) == 1, timeout=5_000)
        assert not b["arm"].isEnabled()
        answers.append(False)
        b["release"].click()
        assert questions and panel.busy is None
        assert "release: cancelled" in panel.status_text
        time.sleep(0.2)
        assert _events(source, "release") == [] and panel.armed() is True

        # Release, confirmed: the engine records it and h starts moving.
        before = source.snapshot()
        h_before = float(np.ptp(before["h"][-250:]))
        answers.append(True)
        b["release"].click()
        qtbot.waitUntil(lambda: panel.busy is None, timeout=5_000)
        assert "release: done" in panel.status_text, panel.status_text
        # The event comes from the acquisition process through the dispatcher, as the arm's:
        # soon after the panel's "done", not with it (a fresh-clone CI run found none yet).
        qtbot.waitUntil(lambda: len(_events(source, "release")) >= 1, timeout=5_000)
        assert len(_events(source, "release")) == 1
        t_end = float(before["time"][-1])
        # The model moved before the PLC confirmed (RELEASED follows the magnet), so rows 1.5 s
        # past the confirmation hold the decay: waiting for t_end + 1 s instead missed it when
        # the release itself took about a second under load (the sync view lags real time).
        t_done = float(source.snapshot(1)["time"][-1])
        qtbot.waitUntil(lambda: float(source.snapshot(1)["time"][-1]) > t_done + 1.5,
                        timeout=5_000)
        after = source.snapshot()
        h_after = float(np.ptp(after["h"][after["time"] > t_end]))
        assert h_after > 3.0 * h_before and h_after > 1e-3, (h_before, h_after)
        qtbot.waitUntil(lambda: panel.armed() is False and not b["release"].isEnabled(),
                        timeout=5_000)

        # CALZ during the run: allowed once the fan is stopped and the wind is off; the engine
        # pauses the scan for it and marks the pause.
        b["fan_stop"].click()
        deadline = time.monotonic() + 15.0
        while not b["calz"].isEnabled():
            assert time.monotonic() < deadline, panel.reasons
            qtbot.wait(100)
            window.tick()
        b["calz"].click()
        qtbot.waitUntil(lambda: panel.busy is None, timeout=15_000)
        assert "calz: done (scanner zeroed; scan paused" in panel.status_text, panel.status_text
        qtbot.waitUntil(lambda: len(_events(source, "calz")) >= 1, timeout=5_000)  # as above
        assert len(_events(source, "calz")) == 1
        rows = source.snapshot(1)["time"]
        qtbot.waitUntil(lambda: float(source.snapshot(1)["time"][-1]) > float(rows[-1]) + 0.5,
                        timeout=5_000)  # the sync view goes on after the pause
        assert np.isfinite(source.snapshot(50)["h"]).all()

        window.close()  # waits for the worker, stops engine and rig: the leak fixture checks
        assert not source.running
    finally:
        source.close()


class _FakeSource:
    """A live source without a fan or PLC: enough for the panel's state logic."""

    def __init__(self, config: Any) -> None:
        self.info = SimpleNamespace(config=config)
        self.acq = SimpleNamespace(running=True, drivers={})
        self.fan_speed_rpm = math.nan
        self.plc_armed = None

    def snapshot(self, last: int | None = None) -> dict[str, Any]:
        return {"U": np.array([0.0])}


def test_controls_without_fan_or_plc_are_disabled_with_reasons(qtbot):
    config = parse_rig_config(live_config_text(), "sim")
    source = _FakeSource(SimpleNamespace(limits=config.limits, by_role=lambda role: []))
    panel = ControlPanel(source, confirm=lambda *_: True)
    qtbot.addWidget(panel)
    assert panel.buttons["fan_apply"].toolTip() == "fan: no fan in this rig"
    assert not panel.buttons["fan_stop"].isEnabled() and not panel.fan_spin.isEnabled()
    assert panel.buttons["release"].toolTip() == "release: no PLC in this rig"
    assert panel.buttons["calz"].toolTip() == "CALZ: no scanner in this rig"
    assert panel.buttons["mark"].isEnabled()
    assert "fan: no fan in this rig" in panel.status_text
    assert panel.fan_actual.text() == "actual - rpm"  # no reading
    source.acq.running = False
    panel.refresh()
    assert not panel.buttons["mark"].isEnabled()
    assert panel.buttons["mark"].toolTip() == "mark: acquisition not running"
