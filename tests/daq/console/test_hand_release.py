"""Releases by hand from the console: the "released" and "held" buttons on a rig without a PLC.

The simulated flat plate without its ``[plc]``, acquired in the test's process
(:class:`~daq.console.live_source.LiveSource`, its instruments in a process of their own). The
test is the operator: it lets the model go through the virtual tunnel
(``RigProcess.hand_release``), clicks "released" 0.4 s later, catches the model and clicks
"held". The run writer finds the release in the lasers' signals and the releases table shows
it with its modes, as a PLC release.
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np
import pytest

from daq.config import parse_rig_config
from daq.console.live_source import LiveSource
from daq.console.window import ConsoleWindow
from ident.model import flat_plate, flutter

CONFIGS = Path(__file__).resolve().parents[3] / "rig_configs"
FAST_FAN = "\n[simulation.devices.fan]\nramp_rpm_per_s = 4000.0\n"
DECAY_S = 4.0


def test_released_and_held_by_hand_from_the_console(qtbot):
    text, n = re.subn(r"\n\[plc\]\n(?:[^\[\n].*\n|\n)*", "\n",
                      (CONFIGS / "sim_flat_plate.toml").read_text())
    assert n == 1
    config = parse_rig_config(text + FAST_FAN, "no_plc.toml")
    source = LiveSource(config, simulate=True, window_s=10.0, fan_rpm=600.0)
    source.open()
    try:
        window = ConsoleWindow(source, window_s=10.0, frame_ms=50, confirm=lambda *_: True)
        qtbot.addWidget(window)
        window.show()
        panel, table = window.controls, window.releases_panel
        assert panel is not None
        b = panel.buttons
        assert b["release"].toolTip() == "release: no PLC in this rig"
        qtbot.waitUntil(lambda: abs(source.fan_speed_rpm - 600.0) < 5.0, timeout=10_000)
        window.tick()
        assert b["hand_release"].isEnabled() and b["hand_hold"].isEnabled()
        time.sleep(1.0)  # held still in the wind
        rig = source.simulated_rig
        truth = rig.hand_release()  # the operator's hand: host monotonic time, s
        time.sleep(0.4)
        b["hand_release"].click()
        qtbot.waitUntil(lambda: panel.busy is None, timeout=5_000)
        keys = source.events("manual_release")
        assert len(keys) == 1 and keys[0].host_time_ns * 1e-9 > truth
        qtbot.waitUntil(lambda: len(source.decays()) == 1, timeout=5_000)  # found
        qtbot.wait(int((DECAY_S - 0.4) * 1000))
        held_at = time.monotonic()
        rig.hand_hold()
        time.sleep(0.3)
        b["hand_hold"].click()
        qtbot.waitUntil(lambda: source.decays()[0][1] is not None, timeout=5_000)
        release, caught = source.decays()[0]
        # Ends at the catch (the still hold before the click, less 0.05 s), not at the click
        # 0.3 s later: the decay as long as the hand let it run, to a sync window or two.
        assert caught - release == pytest.approx(held_at - truth, abs=0.15)
        qtbot.waitUntil(lambda: table.table.rowCount() == 1 and table.cell(0, "status") == "ok",
                        timeout=20_000)
        U = float(table.cell(0, "U (m/s)"))
        res = flutter.analyze(config.section, flat_plate.jones_model(), U_max=10.0)
        names = list(res.mode_names)
        f_a = float(np.interp(U, res.U, res.frequencies[:, names.index("pitch")]))
        # 4 s of decay: the pitch frequency to 1 % (as a PLC release in test_releases.py).
        assert float(table.cell(0, "f_a (Hz)")) == pytest.approx(f_a, rel=0.01)
        window.close()
    finally:
        source.close()
