"""Run files written from releases (:mod:`daq.recording.synthetic`), the readers' test data.

The run-file writer must put each release where its row says.
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from daq.config import load_rig_config
from daq.recording.synthetic import write_release_run
from ident.model import flat_plate
from simulators import simulate_release

from support.configs import SIM_FLAT_PLATE

CONFIG = SIM_FLAT_PLATE


def test_releases_with_and_without_a_held_start_land_where_their_rows_say(tmp_path):
    config = load_rig_config(CONFIG)
    section, model = config.section.replace(rho=1.2), flat_plate.jones_model()
    held = simulate_release(section, model, 6.0, 0.004, 0.02, duration=3.0, fs=200.0,
                            pre_s=0.5)  # 100 held samples, t from -0.5 s
    free = simulate_release(section, model, 8.0, -0.003, 0.01, duration=2.0, fs=200.0)
    path = tmp_path / "run.h5"
    write_release_run(path, config, [held, free])
    with h5py.File(path, "r") as f:
        t, h = f["entry/sync/time"][:], f["entry/sync/h"][:]
        rows = f["entry/releases"][:]
    assert t.size == held.t.size + free.t.size and np.allclose(np.diff(t), 1 / 200.0)
    first, second = rows
    # The held release: its row starts at the release instant, after the 100 held samples.
    assert first["start_index"] == 100 and first["stop_index"] == held.t.size
    assert first["release_time"] == pytest.approx(0.5) and t[100] == pytest.approx(0.5)
    assert (first["h0"], first["alpha0"]) == (0.004, 0.02)  # the release's own hold
    np.testing.assert_array_equal(h[:held.t.size], held.h)
    # The next release follows one sample later; it starts at its first sample.
    assert second["start_index"] == held.t.size and second["stop_index"] == t.size
    assert second["release_time"] == pytest.approx(held.t[-1] + 0.5 + 1 / 200.0)
    assert second["U"] == 8.0 and second["h0"] == -0.003
