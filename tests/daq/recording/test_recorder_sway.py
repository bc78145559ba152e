"""The run file of a 3-DOF rig: ``p`` and ``drag`` in ``/entry/sync``, ``p0`` in the releases.

``RunRecorder(sway=True)`` adds the two columns and the field; a 2-DOF recorder (the default)
writes exactly the layout it always did and refuses sway data, so a 2-DOF file cannot gain a
column by mistake. :func:`~daq.recording.layout.read_sync` and ``windrig recover``'s trimming
see the sway columns like any other.
"""

from __future__ import annotations

import math
from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.recording.layout import (
    RELEASE_DTYPE,
    RELEASE_DTYPE_SWAY,
    SWAY_COLUMNS,
    SYNC_COLUMNS,
    read_sync,
)
from daq.recording.recorder import RunRecorder

from support.configs import REPO

TEXT = (REPO / "rig_configs" / "sim_bluff_deck_3dof.toml").read_text(encoding="utf-8")
TAPS = ["t00", "t01"]


def _recorder(path: Path, *, sway: bool) -> RunRecorder:
    rec = RunRecorder(path, config_text=TEXT, rig_name="bluff 3dof", min_free_bytes=0, sway=sway)
    rec.open()
    rec.add_sync(TAPS)
    rec.start(t0_host_ns=10**12)
    return rec


def _rows(n: int) -> dict[str, np.ndarray]:
    k = np.arange(n, dtype=float)
    return {"h": 1e-3 * np.sin(k), "alpha": 1e-2 * np.cos(k), "lift": 2.0 * k,
            "moment": -0.5 * k, "pressure": np.outer(k, [1.0, 2.0]), "U": np.full(n, 9.0),
            "rho": np.full(n, 1.2)}


def test_a_2dof_recorder_writes_the_2dof_layout_and_refuses_sway_data(tmp_path):
    path = tmp_path / "two.h5"
    rec = _recorder(path, sway=False)
    with pytest.raises(ValueError, match=r"exactly into a 3-DOF run \(sway=False\)"):
        rec.append_sync(np.arange(3) / 100, p=np.zeros(3), drag=np.zeros(3), **_rows(3))
    with pytest.raises(ValueError, match="p0 goes into a 3-DOF run's releases only"):
        rec.add_release(release_time=0.0, start_index=0, stop_index=0, U=9.0, h0=0.0,
                        alpha0=0.0, p0=0.0)
    rec.append_sync(np.arange(3) / 100, **_rows(3))
    rec.add_release(release_time=0.0, start_index=0, stop_index=3, U=9.0, h0=0.0, alpha0=0.0)
    rec.close()
    with h5py.File(path, "r") as f:
        assert set(f["entry/sync"]) == set(SYNC_COLUMNS) | {"tap"}
        assert f["entry/releases"].dtype == RELEASE_DTYPE
    assert set(read_sync(path)) == set(SYNC_COLUMNS)


def test_a_3dof_recorder_writes_p_drag_and_p0(tmp_path):
    path = tmp_path / "three.h5"
    rec = _recorder(path, sway=True)
    with pytest.raises(ValueError, match="p and drag go together"):
        rec.append_sync(np.arange(3) / 100, **_rows(3))
    with pytest.raises(ValueError, match="p and drag go together"):
        rec.append_sync(np.arange(3) / 100, p=np.zeros(3), **_rows(3))
    p, drag = np.array([4e-3, 3e-3, 1e-3]), np.array([0.2, -0.1, 0.05])
    rec.append_sync(np.arange(3) / 100, p=p, drag=drag, **_rows(3))
    rec.add_release(release_time=0.0, start_index=0, stop_index=3, U=9.0, h0=6e-3,
                    alpha0=0.015, p0=4e-3)
    rec.add_release(release_time=0.02, start_index=2, stop_index=3, U=9.0, h0=6e-3,
                    alpha0=0.015)  # a release without a measured p0: NaN
    rec.close()
    with h5py.File(path, "r") as f:
        sync = f["entry/sync"]
        assert set(sync) == set(SYNC_COLUMNS) | set(SWAY_COLUMNS) | {"tap"}
        for name, (units, long_name) in SWAY_COLUMNS.items():
            assert sync[name].attrs["units"] == units
            assert sync[name].attrs["long_name"] == long_name
            # a dimension scale like every other column (xarray's time coordinate)
            assert sync[name].dims[0].label == "time"
        releases = f["entry/releases"]
        assert releases.dtype == RELEASE_DTYPE_SWAY
        assert list(releases.attrs["field_names"])[-1] == "p0"
        assert releases["p0"][0] == 4e-3 and math.isnan(releases["p0"][1])
    data = read_sync(path)
    assert np.array_equal(data["p"], p) and np.array_equal(data["drag"], drag)
