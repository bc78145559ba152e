"""Run files the tests write through the real recorder, and read as a live reader would.

``write_run`` writes a small run file (two simulated releases of the flat plate) with
``daq.recording.recorder.RunRecorder``: the reader's tests (``tests/ident/records/test_io.py``)
and ``windrig identify``'s (``tests/daq/test_cli.py``) read the same files.
``write_smallest_run`` writes the smallest run file of docs/reference/file_format.md with h5py
alone, as a program other than windrig would. ``sync_rows``
counts what a SWMR reader sees of a file still being written (the console's recording tests).
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from daq.recording.recorder import RunRecorder
from ident.model import flat_plate
from simulators import simulate_release

from support.sections import FLAT_PLATE

#: The stored config of ``write_run``'s files: the flat plate, 0.01 m deep.
CONFIG = """[rig]
name = "test"
[section]
B = 0.3
m = 3.0
I = 0.03
fh = 2.0
fa = 4.0
zeta_h = 0.005
zeta_a = 0.005
depth = 0.01
"""


def write_run(path, *, gap=False, gap_row=300):
    """Write a run file with two releases through the real recorder.

    ``gap``: the second release's h is NaN at ``gap_row`` of its rows (0.5 s of hold at 200 Hz
    first: row 300 is 1.0 s after the release).
    """
    recorder = RunRecorder(path, config_text=CONFIG, rig_name="test", min_free_bytes=0)
    recorder.open()
    recorder.add_sync(["p0", "p1"])
    recorder.start()
    sims, t0, row = [], 0.0, 0
    for U in (5.0, 8.0):
        sim = simulate_release(FLAT_PLATE, flat_plate.jones_model(), U, 0.004, 0.02, duration=4.0,
                               fs=200.0, pre_s=0.5)
        n = sim.t.size
        columns = {"h": sim.h.copy(), "alpha": sim.alpha, "lift": sim.lift, "moment": sim.moment,
                   "U": np.full(n, U), "rho": np.full(n, FLAT_PLATE.rho),
                   "pressure": np.zeros((n, 2), dtype=np.float32)}
        if gap and U == 8.0:
            columns["h"][gap_row] = np.nan
        recorder.append_sync(t0 + 0.5 + sim.t, **columns)
        after = int(np.flatnonzero(sim.t >= 0)[0])
        recorder.add_release(release_time=t0 + 0.5, start_index=row + after, stop_index=row + n,
                             U=U, h0=0.004, alpha0=0.02)
        sims.append(sim)
        t0 += 0.5 + 4.0
        row += n
    recorder.close()
    return sims


def sync_rows(path: Path) -> int:
    """Rows of /entry/sync a SWMR reader sees now (0 while the file is not readable yet)."""
    try:
        with h5py.File(path, "r", swmr=True) as f:
            return int(f["entry/sync/time"].shape[0])
    except (OSError, KeyError):  # not yet in SWMR mode, or the datasets not created yet
        return 0


#: The stored config of the smallest run file: a [section] and nothing else.
SMALLEST_CONFIG = CONFIG.replace('[rig]\nname = "test"\n', "")


def write_smallest_run(path: Path, *, omit: tuple[str, ...] = ()) -> list:
    """Write docs/reference/file_format.md's smallest run file with h5py alone; return the releases.

    Two simulated flat-plate releases (5 and 8 m/s, 4 s at 200 Hz after 0.5 s of hold each):
    ``/entry/config`` (a ``[section]`` only), the seven columns of ``/entry/sync`` and
    ``/entry/releases``; no attributes, no raw streams, no events. ``omit``: paths under
    ``/entry`` (``"sync/lift"``, ``"releases"``, ...) to leave out.
    """
    columns: dict[str, list[np.ndarray]] = {name: [] for name in
                                            ("time", "h", "alpha", "lift", "moment", "U", "rho")}
    rows, sims, t0, row = [], [], 0.0, 0
    for U in (5.0, 8.0):
        sim = simulate_release(FLAT_PLATE, flat_plate.jones_model(), U, 0.004, 0.02, duration=4.0,
                               fs=200.0, pre_s=0.5)
        n = sim.t.size
        for name, values in (("time", t0 + 0.5 + sim.t), ("h", sim.h), ("alpha", sim.alpha),
                             ("lift", sim.lift), ("moment", sim.moment), ("U", np.full(n, U)),
                             ("rho", np.full(n, FLAT_PLATE.rho))):
            columns[name].append(values)
        after = int(np.flatnonzero(sim.t >= 0)[0])
        rows.append((t0 + 0.5, row + after, row + n, U, 0.004, 0.02))
        sims.append(sim)
        t0, row = t0 + 4.5, row + n
    parts = {"config": SMALLEST_CONFIG,
             **{f"sync/{name}": np.concatenate(v) for name, v in columns.items()},
             "releases": np.array(rows, dtype=[("release_time", "<f8"), ("start_index", "<i8"),
                                               ("stop_index", "<i8"), ("U", "<f8"),
                                               ("h0", "<f8"), ("alpha0", "<f8")])}
    with h5py.File(path, "w") as f:
        for part, value in parts.items():
            if part not in omit:
                f[f"entry/{part}"] = value
    return sims
