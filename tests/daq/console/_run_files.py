"""Run files as a live reader sees them, for the console tests (not a test module)."""

from __future__ import annotations

from pathlib import Path

import h5py


def sync_rows(path: Path) -> int:
    """Rows of /entry/sync a SWMR reader sees now (0 while the file is not readable yet)."""
    try:
        with h5py.File(path, "r", swmr=True) as f:
            return int(f["entry/sync/time"].shape[0])
    except (OSError, KeyError):  # not yet in SWMR mode, or the datasets not created yet
        return 0
