"""The operator console on a live simulated rig (pytest-qt, offscreen).

The rig is ``sim_flat_plate.toml`` with a fast fan ramp, its simulators in a child process
(:func:`daq.sim.rig_process.start_rig_process`), acquired by the real drivers and engine and
synchronised by the recording pipeline's own :class:`~daq.recording.writer.RunWriter` into the
window's ring buffer (:class:`daq.console.live_source.LiveSource`).
"""

from __future__ import annotations

import math
import os
import struct
import subprocess
import sys
import time

import pytest

from daq.config import parse_rig_config
from daq.console.live_source import LiveSource
from daq.console.source import DeviceHealth, HealthSource
from daq.console.window import HEALTH_COLUMNS, ConsoleWindow

from support.configs import SIM_FLAT_PLATE, live_config_text

pytestmark = pytest.mark.realtime


def test_live_window_traces_move_and_every_device_reports_health(qtbot):
    config = parse_rig_config(live_config_text(), "sim_flat_plate.toml + fast fan")
    source = LiveSource(config, simulate=True, window_s=10.0, fan_rpm=500.0)
    source.open()
    try:
        assert isinstance(source, HealthSource)
        window = ConsoleWindow(source, window_s=10.0, frame_ms=50)
        qtbot.addWidget(window)
        window.show()
        curve = window.curves["h"]
        qtbot.waitUntil(lambda: curve.xData is not None and curve.xData.size > 0, timeout=10_000)
        size, end = curve.xData.size, float(curve.xData[-1])
        qtbot.waitUntil(lambda: curve.xData.size > size and float(curve.xData[-1]) > end,
                        timeout=5_000)  # the trace grows: the live data moves
        assert math.isfinite(float(curve.yData[-1]))  # h from the lasers, in mm
        qtbot.waitUntil(lambda: window.cp_curve.xData is not None
                        and window.cp_curve.xData.size == config.taps.n_taps, timeout=5_000)

        names = [inst.name for inst in config.instruments]
        table = window.health_table
        assert table is not None and window.alarm_label is not None
        assert [table.horizontalHeaderItem(c).text() for c in range(table.columnCount())] == \
            list(HEALTH_COLUMNS)

        def rates() -> dict[str, float]:
            return {table.item(r, 0).text(): float(table.item(r, 1).text())
                    for r in range(table.rowCount()) if table.item(r, 1) is not None}

        # Every device, the 1 Hz barometer included, with a nonzero rate and no alarm. The
        # rates are averaged over the last 2 s of wall-clock time, the start included at first
        # (devices that came up late on a loaded host): waited for, as the nonzero ones.
        qtbot.waitUntil(lambda: sorted(rates()) == sorted(names)
                        and min(rates().values()) > 0 and rates()["laser_front"] > 1000.0
                        and rates()["scanner"] > 100.0, timeout=10_000)
        assert rates()["laser_front"] > 1000.0 and rates()["scanner"] > 100.0
        assert window.alarm_label.text() == "all devices OK"
        qtbot.waitUntil(lambda: source.fan_speed_rpm > 0, timeout=5_000)  # the fan stream

        # A stall (every device silent for 10 s, by the clock seam) and a fault raise the alarm.
        stalled = source.health(now_ns=time.monotonic_ns() + 10_000_000_000)
        assert {h.device for h in stalled} == set(names)
        assert all(h.alarm is not None and "stalled" in h.alarm for h in stalled)
        fault = DeviceHealth(device="fan", kind="fan", rate_hz=0.0, gaps=0, overflow_samples=0,
                             faults=1, last_fault="TransportError: timeout", clock_fit=None,
                             alarm="fault: TransportError: timeout")
        window.show_health([fault], 0.0)
        assert window.alarm_label.text().startswith("ALARM") and "fan" in \
            window.alarm_label.text()

        window.close()  # stops the engine and the rig: the thread-leak fixture checks
        assert not source.running
    finally:
        source.close()


def test_cli_screenshot_of_a_live_simulated_run(tmp_path):
    config = tmp_path / "sim_fast_fan.toml"
    config.write_text(live_config_text())
    out = tmp_path / "live.png"
    env = {k: v for k, v in os.environ.items()
           if k not in ("QT_QPA_PLATFORM", "DISPLAY", "WAYLAND_DISPLAY")}  # it must set it
    proc = subprocess.run(
        [sys.executable, "-m", "daq.cli", "gui", "--config", str(config), "--simulate",
         "--fan-rpm", "500", "--screenshot", str(out), "--after", "2", "--size", "800", "600"],
        capture_output=True, text=True, env=env, timeout=90)
    assert proc.returncode == 0, proc.stderr
    assert "wrote" in proc.stdout and "running" in proc.stdout and "sync rows" in proc.stdout
    png = out.read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert struct.unpack(">II", png[16:24]) == (800, 600)  # the IHDR chunk
    assert len(png) > 10_000  # drawn, not blank


@pytest.mark.parametrize("args, message", [
    (["--config", str(SIM_FLAT_PLATE)], "url = 'auto'"),
    (["--config", str(SIM_FLAT_PLATE), "--simulate", "--replay", "x.h5"],
     "exclude each other"),
    (["--config", str(SIM_FLAT_PLATE), "--simulate", "--fan-rpm", "5000"],
     "max_fan_rpm"),
    (["--config", "missing.toml", "--simulate"], "cannot read rig config"),
], ids=["auto-urls-without-simulate", "replay-and-live", "fan-above-limit", "missing-config"])
def test_bad_live_options_give_one_line_and_exit_code_2(args, message, capsys):
    from daq.cli import main

    assert main(["gui", *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err
