"""The releases table from the sync rows: events that arrive after the rows of their instant.

A release event exists once the PLC confirmed the release (its RELEASED input, polled), an arm
event once the command returned. On a loaded host that is later than the sync view's own lag,
so the rows of the release instant are already written when the event comes. The release must
still start at its own row and get its held position (h0, alpha0) from the rows before it.
Real run file (``RunRecorder``), read back with h5py.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.recording.recorder import RunRecorder
from daq.recording.releases import ReleaseRows

RATE_HZ = 500.0
BLOCK = 100  # rows per write: 0.2 s, the writer's interval
H0, ALPHA0 = 0.004, 0.02
T_RELEASE = 2.0013  # between two rows: the release starts at the next one


def columns(k0: int) -> tuple[np.ndarray, ...]:
    """One block of sync rows: held at (H0, ALPHA0) before the release, a decay after."""
    t = (k0 + np.arange(BLOCK)) / RATE_HZ
    free = t >= T_RELEASE
    decay = np.exp(-0.5 * (t - T_RELEASE)) * np.cos(2 * np.pi * 2.0 * (t - T_RELEASE))
    h = np.where(free, H0 * decay, H0)
    alpha = np.where(free, ALPHA0 * decay, ALPHA0)
    return t, h, alpha, np.full(BLOCK, 9.0)


@pytest.mark.parametrize("late_blocks", [0, 1, 6])
def test_a_release_event_after_its_rows_starts_at_its_own_row(tmp_path: Path, late_blocks: int):
    path = tmp_path / "run.h5"
    rec = RunRecorder(path, config_text="", rig_name="test", min_free_bytes=0)
    rec.open()
    rec.add_sync(["t0"])
    rec.start()
    rows = ReleaseRows()
    first_after = int(np.ceil(T_RELEASE * RATE_HZ))
    event_block = int(T_RELEASE * RATE_HZ) // BLOCK + late_blocks  # when the event arrives
    caught_at, caught_block = 3.4991, 0  # the arm event: 2 blocks late, at its time
    for b in range(25):  # 5 s of rows
        if b == event_block:
            rows.released(T_RELEASE)
        t, h, alpha, U = columns(b * BLOCK)
        if b == int(caught_at * RATE_HZ) // BLOCK + 2:
            rows.caught(caught_at)
            caught_block = b
        rec.append_sync(t, h=h, alpha=alpha, lift=np.zeros(BLOCK), moment=np.zeros(BLOCK),
                        pressure=np.zeros((BLOCK, 1)), U=U, rho=np.full(BLOCK, 1.2))
        rows.track(rec, b * BLOCK, t, h, alpha, U)
    rows.finish(rec, 25 * BLOCK)
    rec.close()
    assert caught_block > 0
    with h5py.File(path, "r") as f:
        (row,) = f["entry/releases"][:]
        t_all = f["entry/sync/time"][:]
    assert row["start_index"] == first_after == np.searchsorted(t_all, T_RELEASE)
    assert row["stop_index"] == np.searchsorted(t_all, caught_at)
    assert row["h0"] == H0 and row["alpha0"] == ALPHA0
    assert row["U"] == 9.0
