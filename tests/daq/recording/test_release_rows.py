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


def _manual_columns(k0: int, rng: np.random.Generator, t_catch: float) -> tuple[np.ndarray, ...]:
    """Held with noise, a decay from rest after T_RELEASE, caught (held again) at ``t_catch``."""
    t = (k0 + np.arange(BLOCK)) / RATE_HZ
    tau = t - T_RELEASE
    free = (tau >= 0) & (t < t_catch)
    w = 2 * np.pi * 2.0  # from rest: the sine term makes the velocity zero at the release
    decay = np.exp(-0.3 * tau) * (np.cos(w * tau) + 0.3 / w * np.sin(w * tau))
    h = np.where(free, H0 * decay, H0) + 2e-6 * rng.standard_normal(BLOCK)
    alpha = np.where(free, ALPHA0 * decay, ALPHA0) + 1e-5 * rng.standard_normal(BLOCK)
    return t, h, alpha, np.full(BLOCK, 9.0)


def test_an_operators_keys_make_a_release_row_at_the_instant_in_the_signals(tmp_path: Path):
    # The operator lets go at T_RELEASE, presses the key 0.6 s later (its event arrives with
    # the block after), catches the model at 3.5 s and says so 0.3 s later. A key at 0.1 s,
    # before any hold, finds nothing and says so.
    path = tmp_path / "run.h5"
    rec = RunRecorder(path, config_text="", rig_name="test", min_free_bytes=0)
    rec.open()
    rec.add_sync(["t0"])
    rec.start()
    rows = ReleaseRows(f_max=2.0)
    told: list[tuple[str, float]] = []
    keys = {1: ("manual_release", 0.1), 14: ("manual_release", T_RELEASE + 0.6),
            20: ("manual_hold", 3.8)}
    rng = np.random.default_rng(0)
    for b in range(25):
        if b in keys:
            rows.operator(*keys[b], hook=lambda what, t: told.append((what, t)))
        t, h, alpha, U = _manual_columns(b * BLOCK, rng, t_catch=3.5)
        rec.append_sync(t, h=h, alpha=alpha, lift=np.zeros(BLOCK), moment=np.zeros(BLOCK),
                        pressure=np.zeros((BLOCK, 1)), U=U, rho=np.full(BLOCK, 1.2))
        rows.track(rec, b * BLOCK, t, h, alpha, U)
    rows.finish(rec, 25 * BLOCK)
    rec.close()
    with h5py.File(path, "r") as f:
        table = f["entry/releases"][:]
        events = f["entry/events"][:]
    kinds = [k.decode() for k in events["kind"]]
    assert kinds == ["release_not_detected", "release_detected"]
    assert "no still hold" in events["text"][0].decode()
    assert table.shape == (1,)
    row = table[0]
    # The onset of a noise-weighted fit at 2 um / 1e-5 rad: well within 1 ms (the detector's
    # tests), and the row starts at the first sync row after it.
    assert row["release_time"] == pytest.approx(T_RELEASE, abs=1e-3)
    assert row["start_index"] == int(np.ceil(T_RELEASE * RATE_HZ))
    assert row["h0"] == pytest.approx(H0, abs=1e-5) and row["alpha0"] == pytest.approx(ALPHA0,
                                                                                    abs=1e-4)
    # Ends at the catch (3.5 s, the hold still from half a window later, less that half
    # window), not at the key 0.3 s after it.
    assert (row["stop_index"] - 1) / RATE_HZ == pytest.approx(3.5, abs=0.06)
    assert [w for w, _ in told] == ["release", "caught"]
    assert told[0][1] == pytest.approx(row["release_time"])
