"""Helper process for tests/daq/recording/test_recorder.py (not a test module: no ``test_`` prefix).

``python _recorder_child.py write PATH``
    Record a run with :class:`daq.recording.recorder.RunRecorder` (flush interval 0.1 s), appending
    a block of ``BLOCK`` rows every 0.02 s to a raw stream and to the sync view, and print ``flushed
    <raw rows> <sync rows>`` (rows written when it flushed) after each flush, until killed (or
    ``MAX_S`` passed). Row ``k`` holds the values of :func:`expected`, so the parent can check what
    survives a SIGKILL.

``python _recorder_child.py fill PATH``
    Record with a 1 MB limit on file size (``RLIMIT_FSIZE``: writes past it fail with EFBIG, as
    they would with ENOSPC on a full disk, without needing root to make one), flushing every
    block, until an append or flush raises; print ``error <class> <errno> <state> <rows>``
    (``rows`` appended and flushed before the failing call), then leave with ``os._exit``:
    h5py 3.16 / HDF5 2.0 crash (SIGSEGV) when a file whose write failed is closed or collected.

``python _recorder_child.py follow PATH ROWS``
    Open PATH as an SWMR reader, print ``ready``, then print ``rows <n>`` each time the raw
    stream's row count changes (``dataset.refresh()``), until it reaches ROWS (or ``MAX_S``).
"""

from __future__ import annotations

import os
import resource
import signal
import sys
import time

import h5py
import numpy as np

from daq.errors import StorageError
from daq.recording.recorder import RunRecorder

BLOCK = 20
MAX_S = 20.0
TAPS = ["p0", "p1", "p2"]


def expected(k: np.ndarray) -> dict[str, np.ndarray]:
    """Column values of rows ``k`` (int64 array), as the writer writes them."""
    k = np.asarray(k, dtype=np.int64)
    return {
        "counter": k,
        "host_time_ns": 1_000_000 * k,
        "device_time": k / 1000.0,
        "value": np.stack([1e-3 * k, -2e-3 * k], axis=1),
        "time": k / 1000.0,
        "h": 1e-4 * k,
        "pressure": np.stack([k + 0.5 * j for j in range(len(TAPS))], axis=1).astype(np.float32),
    }


def report(rec: RunRecorder, flushes: int, raw: int, sync: int) -> int:
    """Print ``flushed <raw rows> <sync rows>`` if the last append flushed; return the count."""
    if rec.flushes != flushes:
        print(f"flushed {raw} {sync}", flush=True)
    return rec.flushes


def write(path: str) -> int:
    rec = RunRecorder(path, config_text="[rig]\nname = 'child'\n", rig_name="child",
                      flush_interval_s=0.1, min_free_bytes=0)
    rec.open()
    rec.add_stream("lasers", ["h", "alpha"], ["m", "rad"], 1000.0, "float64")
    rec.add_sync(TAPS)
    rec.start(t0_host_ns=0)
    rows = 0
    flushes = rec.flushes
    raw = sync = 0  # rows appended to each part
    deadline = time.monotonic() + MAX_S
    while time.monotonic() < deadline:
        k = np.arange(rows, rows + BLOCK)
        e = expected(k)
        rec.append_raw("lasers", e["host_time_ns"], e["device_time"], e["counter"], e["value"])
        raw += BLOCK
        flushes = report(rec, flushes, raw, sync)
        nan = np.full(BLOCK, np.nan)
        rec.append_sync(e["time"], h=e["h"], alpha=nan, lift=nan, moment=nan,
                        pressure=e["pressure"], U=nan, rho=nan)
        sync += BLOCK
        flushes = report(rec, flushes, raw, sync)
        rows += BLOCK
        time.sleep(0.02)
    rec.close()
    return 0


def fill(path: str) -> None:
    rec = RunRecorder(path, config_text="", rig_name="child", min_free_bytes=0,
                      compression=None)
    rec.open()
    rec.add_stream("lasers", ["h", "alpha"], ["m", "rad"], 1000.0, "float64")
    rec.add_sync(TAPS)
    rec.start()
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # else the kernel kills us at the limit
    resource.setrlimit(resource.RLIMIT_FSIZE, (1_000_000, 1_000_000))
    rows = 0
    try:
        while rows < 10**6:
            e = expected(np.arange(rows, rows + 500))
            rec.append_raw("lasers", e["host_time_ns"], e["device_time"], e["counter"],
                           e["value"])
            rec.flush()
            rows += 500
    except StorageError as exc:
        print(f"error {type(exc).__name__} {exc.errno} {rec.state} {rows}", flush=True)
        print(exc, flush=True)
    os._exit(0)


def follow(path: str, target: int) -> int:
    with h5py.File(path, "r", libver="latest", swmr=True) as f:
        counter = f["entry/instrument/lasers/counter"]
        print("ready", flush=True)
        seen = -1
        deadline = time.monotonic() + MAX_S
        while time.monotonic() < deadline:
            counter.refresh()
            n = counter.shape[0]
            if n != seen:
                seen = n
                print(f"rows {n}", flush=True)
                if n >= target:
                    return 0
            time.sleep(0.005)
    return 1


if __name__ == "__main__":
    if sys.argv[1] == "write":
        sys.exit(write(sys.argv[2]))
    if sys.argv[1] == "fill":
        fill(sys.argv[2])
    sys.exit(follow(sys.argv[2], int(sys.argv[3])))
