"""The operator console shows the sway p of a rig with three degrees of freedom (offscreen).

A run file of the shipped 3-DOF rig (``sim_bluff_deck_3dof.toml``) is written by the real
recorder with known rows (p a 2.6 Hz sinusoid of 3 mm), replayed on a fake clock: the window has
a fifth trace, ``p`` in mm, holding exactly the file's rows; a 2-DOF file's window has the four
traces of before. Live, the simulated 3-DOF rig's sway laser reaches the p trace.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.config import SHIPPED_CONFIGS, load_rig_config, parse_rig_config
from daq.console.live_source import LiveSource
from daq.console.replay import ReplaySource
from daq.console.source import SWAY_SCALARS, sync_columns
from daq.console.window import ConsoleWindow
from daq.recording.recorder import RunRecorder

from support.clocks import ManualClock
from support.configs import FAST_FAN

pytestmark = pytest.mark.realtime

RATE_HZ = 100.0
DURATION_S = 30.0
F_P = 2.6  # sway frequency, Hz


def _write(path: Path, name: str) -> Path:
    config = load_rig_config(name)
    sway = config.section.n_dof == 3
    n_taps = config.taps.n_taps
    rec = RunRecorder(path, config_text=config.text, rig_name=config.name, min_free_bytes=0,
                      reserve_bytes=0, sway=sway)
    rec.open()
    rec.add_sync([f"tap{i:03d}" for i in range(n_taps)])
    rec.start()
    t = np.arange(int(DURATION_S * RATE_HZ)) / RATE_HZ
    for block in np.array_split(np.arange(t.size), 6):
        tb = t[block]
        extra = ({"p": 0.003 * np.sin(2 * np.pi * F_P * tb), "drag": 0.1 * np.cos(tb)}
                 if sway else {})
        rec.append_sync(tb, h=0.004 * np.sin(2 * np.pi * 1.2 * tb),
                        alpha=0.01 * np.sin(2 * np.pi * 3.6 * tb), lift=np.zeros(tb.size),
                        moment=np.zeros(tb.size), pressure=np.zeros((tb.size, n_taps)),
                        U=np.full(tb.size, 9.0), rho=np.full(tb.size, 1.2), **extra)
    rec.close()
    return path


def _played(qtbot, path: Path) -> ConsoleWindow:
    clock = ManualClock()
    source = ReplaySource(path, speed=1.0, window_s=20.0, clock=clock)
    source.open()
    window = ConsoleWindow(source, window_s=20.0, frame_ms=10_000_000)  # redraw by hand
    qtbot.addWidget(window)
    window.tick()
    clock.now += 25.0
    window.tick()
    return window


def test_the_console_draws_the_sway_of_a_3dof_run(qtbot, tmp_path):
    path = _write(tmp_path / "three.h5", "sim_bluff_deck_3dof")
    window = _played(qtbot, path)
    assert list(window.curves) == ["h", "alpha", "lift", "moment", "p"]
    x, y = window.curves["p"].xData, window.curves["p"].yData
    with h5py.File(path, "r") as f:
        t, p = f["entry/sync/time"][()], f["entry/sync/p"][()]
    span = (t >= x[0]) & (t <= x[-1])
    assert x[-1] == pytest.approx(25.0, abs=1 / RATE_HZ)
    np.testing.assert_array_equal(x, t[span])
    # p shown in mm: one multiplication by 1e3 in float64, within 1 ulp of the file's.
    np.testing.assert_allclose(y, p[span] * 1e3, rtol=1e-15, atol=0)
    assert np.max(y) == pytest.approx(3.0, abs=0.01)  # the 3 mm amplitude, sampled at 100 Hz


def test_a_2dof_run_has_the_four_traces_of_before(qtbot, tmp_path):
    window = _played(qtbot, _write(tmp_path / "two.h5", "sim_flat_plate"))
    assert list(window.curves) == ["h", "alpha", "lift", "moment"]


def test_the_ring_columns_of_a_3dof_view():
    names = [c.name for c in sync_columns(4, sway=True)]
    assert names[-3:] == [*SWAY_SCALARS, "pressure"]
    assert [c.name for c in sync_columns(4)] == [c.name for c in sync_columns(4, sway=False)]
    assert "p" not in [c.name for c in sync_columns(4)]


def test_the_live_console_of_the_simulated_3dof_rig_draws_p_from_the_sway_laser(qtbot):
    """Live: the simulated rig's sway laser, through the engine and the writer, into the trace.

    Held by the magnet, the model sits at the config's ``hold_p`` = 4 mm: the p trace reads
    that within the laser's noise (1.25 um) and its 16-bit words (0.8 um).
    """
    text = (SHIPPED_CONFIGS / "sim_bluff_deck_3dof.toml").read_text()
    config = parse_rig_config(text + FAST_FAN,
                              "sim_bluff_deck_3dof.toml + fast fan")
    source = LiveSource(config, simulate=True, window_s=10.0, fan_rpm=300.0)
    source.open()
    try:
        window = ConsoleWindow(source, window_s=10.0, frame_ms=50)
        qtbot.addWidget(window)
        window.show()
        curve = window.curves["p"]

        def held_p() -> bool:
            y = curve.yData
            return y is not None and y.size > 100 and bool(np.isfinite(y[-1]))

        qtbot.waitUntil(held_p, timeout=15_000)
        assert float(curve.yData[-1]) == pytest.approx(4.0, abs=0.01)  # mm
        window.close()
        assert not source.running
    finally:
        source.close()
