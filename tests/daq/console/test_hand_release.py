"""Releases by hand from the console: the "released" and "held" buttons on a rig without a PLC.

The simulated flat plate without its ``[plc]``, acquired in the test's process
(:class:`~daq.console.live_source.LiveSource`, its instruments in a process of their own). The
test clicks "released" and, 4 s later, "held"; on a simulated rig each click first moves the
simulated operator's hand through the virtual tunnel (``LiveSource.simulated_hand``). The run
writer finds the release in the lasers' signals and the releases table shows it with its
modes, as a PLC release.
"""

from __future__ import annotations

import re
import time

import numpy as np
import pytest

from daq.config import parse_rig_config
from daq.console.live_source import LiveSource
from daq.console.window import ConsoleWindow
from ident.model import flat_plate, flutter

from support.configs import FAST_FAN, SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

DECAY_S = 4.0


def test_released_and_held_by_hand_from_the_console(qtbot):
    text, n = re.subn(r"\n\[plc\]\n(?:[^\[\n].*\n|\n)*", "\n",
                      SIM_FLAT_PLATE.read_text())
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
        # The simulated rig's hand lets the model go as the button is clicked (a person's
        # click comes after their hand; the writer looks for the release before the click).
        b["hand_release"].click()
        qtbot.waitUntil(lambda: panel.busy is None, timeout=5_000)
        qtbot.waitUntil(lambda: len(source.decays()) == 1, timeout=5_000)  # found
        qtbot.wait(int(DECAY_S * 1000))
        b["hand_hold"].click()  # the hand catches it, then the click is recorded
        qtbot.waitUntil(lambda: panel.busy is None, timeout=5_000)
        qtbot.waitUntil(lambda: source.decays()[0][1] is not None, timeout=5_000)
        release, caught = source.decays()[0]
        keys = [source.events(kind) for kind in ("manual_release", "manual_hold")]
        assert [len(k) for k in keys] == [1, 1]
        # The decay runs from the hand's release to its catch (the clicks a few ms after
        # each), to a sync window or two.
        clicks_s = (keys[1][0].host_time_ns - keys[0][0].host_time_ns) * 1e-9
        assert caught - release == pytest.approx(clicks_s, abs=0.15)
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
