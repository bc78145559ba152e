"""The simulated rig with `[simulation] tubing = true`: the taps its scanner samples are tubed.

One pass of the whole recording path (scanner simulator with the tubes, real drivers, the
recorder, `windrig identify`) is in docs/guides/tubing.md, "What the tubing does to the flutter
speed"; it is not a test, because on a loaded host that path scatters the flutter speed by a few per
cent from run to run, more than the tubing correction's 0.5 %.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from daq.config import parse_rig_config
from daq.instruments.build import build_driver
from daq.sim.rig import start_simulated_rig
from ident.physics.tubing import Air, distort, tubing_set

from support.configs import FAST_FAN, SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

TUBES = '[[taps.tubing]]\ntaps = [0, 1, 2, 3]\nlength = 1.5\ndiameter = 1.0e-3\nvolume = 300e-9\n\n'


def test_the_simulated_rig_puts_the_configs_tubes_between_taps_and_scanner():
    """In the wind, through a release: taps 0..3 read behind their tubes, the others as before.

    The reference: the tunnel's own lift, moment and dynamic pressure (``sample``) made into
    tap pressures (the pressures that integrate to the forces, plus the mean field of the
    tunnel's default pressure coefficients), through ``ident.physics.tubing.distort``. Tolerance
    1e-3 of the pressures' range, past the release's step (tests/simulators/test_tubing.py).
    """
    text = SIM_FLAT_PLATE.read_text().replace("[limits]", TUBES + "[limits]")
    text = text.replace("temperature_c = 20.0", "temperature_c = 20.0\ntubing = true")
    config = parse_rig_config(text + FAST_FAN)
    taps = config.taps
    with start_simulated_rig(config) as rig:
        tunnel = rig.tunnel
        fan = build_driver(rig.config.instrument("fan"), rig.config.limits)
        fan.open()
        try:
            fan.set_speed(800.0)
            fan.start()
            deadline = time.monotonic() + 10.0
            while abs(tunnel.fan_rpm - 800.0) > 0.2 and time.monotonic() < deadline:
                time.sleep(0.02)
            t0 = tunnel.release()
            time.sleep(1.5)
            fs = 2000.0
            t = t0 - 0.3 + np.arange(int(1.5 * fs)) / fs
            seen, _ = tunnel.pressures(t)
            s = tunnel.sample(t)
            fan.stop()
        finally:
            fan.close()
    cp = np.where(taps.nz < 0, -0.6, -0.2)  # VirtualTunnel's default mean field
    G = taps.integration_matrix()
    mean_part = cp - np.linalg.pinv(G) @ (G @ cp)
    truth = taps.pressures_for(s["lift"], s["moment"]) + np.outer(s["qd"], mean_part)
    air = Air(pressure_pa=tunnel.air.pressure_pa, temperature_k=tunnel.air.temperature_k)
    expected = distort(truth, fs, tubing_set(config.tubing, taps.n_taps, air))
    scale = float(np.ptp(truth[:, :4]))
    after = t > t0 + 0.01
    np.testing.assert_allclose(seen[after], expected[after], atol=1e-3 * scale)
    assert np.max(np.abs(seen[:, :4] - truth[:, :4])) > 0.02 * scale  # the tubes matter
    np.testing.assert_allclose(seen[:, 4:], truth[:, 4:], rtol=1e-9, atol=1e-9 * scale)
