"""Helper process for tests/daq/recording/test_recover.py (not a test module: no ``test_`` prefix).

``python _crash_child.py crash PATH``
    Write a small run file in SWMR mode with the layout's own functions, flush it, then leave a
    last append half-done as a crash can (sizes written before their rows: fill values; columns
    of one group of unequal length), flush that too and kill itself with SIGKILL.

``python _crash_child.py hold PATH``
    Write and flush the same file, print ``ready`` and wait (the parent kills it): a writer
    still recording.
"""

from __future__ import annotations

import functools
import os
import signal
import sys
import time

import h5py
import numpy as np

from daq.recording.layout import (
    append_rows,
    create_column,
    create_stream,
    create_sync,
    write_skeleton,
)

CONFIG_TEXT = '[rig]\nname = "crash test"\n[section]\nB = 0.3\nm = 3.0\nI = 0.03\nfh = 2.0\n' \
              'fa = 4.0\nzeta_h = 0.005\nzeta_a = 0.005\n'
SYNC_ROWS = 300
RAW_ROWS = 600
#: Rows of the half-done last append: sync, raw.
PARTIAL = (7, 3)


def expected_sync() -> dict[str, np.ndarray]:
    """Return the sync rows written whole (the parent checks them after recovery)."""
    t = np.arange(SYNC_ROWS) / 500.0
    return {"time": t, "h": 1e-3 * np.sin(t), "alpha": 1e-2 * np.cos(t), "lift": t,
            "moment": -t, "U": np.full(SYNC_ROWS, 5.0), "rho": np.full(SYNC_ROWS, 1.2),
            "pressure": np.tile(np.float32([1.0, 2.0]), (SYNC_ROWS, 1))}


def write(path: str) -> h5py.File:
    """Write the whole rows in SWMR mode, flushed; return the open file."""
    f = h5py.File(path, "w", libver=("v110", "latest"))
    make = functools.partial(create_column, chunk_rows=64, compression="gzip")
    releases, events = write_skeleton(f, rig_name="crash test", operator_notes="",
                                      config_text=CONFIG_TEXT, make_column=make)
    raw = create_stream(f["entry/instrument"], "laser", ["distance"], ["m"], 1000.0,
                        np.dtype("float64"), {"error_code": np.dtype("int32")},
                        make_column=make)
    sync, columns = create_sync(f["entry"], ["p0", "p1"], np.dtype("float32"),
                                make_column=make)
    sync.attrs["t0_host_ns"] = 10**9
    f.swmr_mode = True
    for name, values in expected_sync().items():
        append_rows(columns[name], 0, values)
    k = np.arange(RAW_ROWS)
    for name, values in {"host_time_ns": 10**9 + k * 10**6, "device_time": k / 1000.0,
                         "counter": k, "value": (k * 1e-6)[:, None],
                         "error_code": np.zeros(RAW_ROWS, np.int32)}.items():
        append_rows(raw[name], 0, values)
    append_rows(raw["gaps"], 0, np.array([(100, 5)], dtype=raw["gaps"].dtype))
    rows = np.zeros(2, dtype=releases.dtype)
    rows["release_time"], rows["start_index"], rows["stop_index"] = (0.02, 0.5), (10, 250), \
        (200, SYNC_ROWS + 5)  # the second decay ends in the half-written rows
    rows["U"] = 5.0
    append_rows(releases, 0, rows)
    ev = np.zeros(2, dtype=events.dtype)
    ev["time"], ev["kind"], ev["text"] = (0.1, 0.3), ("arm", "release"), ("plc: arm", "plc: go")
    append_rows(events, 0, ev)
    f.flush()
    return f


def crash(path: str) -> None:
    """Write, then leave a last append half-done and die by SIGKILL."""
    f = write(path)
    sync, raw = f["entry/sync"], f["entry/instrument/laser"]
    n, m = SYNC_ROWS + PARTIAL[0], RAW_ROWS + PARTIAL[1]
    for name in ("h", "alpha", "lift", "moment", "U", "rho", "pressure"):
        sync[name].resize(n, axis=0)
        sync[name][SYNC_ROWS:] = 1.0  # written; time's rows are not (its chunk never came)
    sync["time"].resize(n, axis=0)
    raw["host_time_ns"].resize(m, axis=0)  # a size without rows: fill values
    raw["value"].resize(m, axis=0)
    raw["gaps"].resize(2, axis=0)
    f["entry/events"].resize(3, axis=0)
    f.flush()
    os.kill(os.getpid(), signal.SIGKILL)


def hold(path: str) -> None:
    """Write and keep the file open until killed."""
    f = write(path)
    print("ready", flush=True)
    time.sleep(60.0)
    f.close()


if __name__ == "__main__":
    {"crash": crash, "hold": hold}[sys.argv[1]](sys.argv[2])
