"""A spawned child for ``test_acquisition_process.py``: appends to a shared ring.

A module of its own, imported by its file name, because the child process imports its target
by module name and the test modules' names are pytest's own.
"""

from __future__ import annotations

import numpy as np

from daq.console.shared_ring import SharedRingBuffer, SharedRingHandle

#: Rows appended, in blocks of BLOCK.
ROWS, BLOCK = 20_000, 50


def append_rows(handle: SharedRingHandle) -> None:
    """Append rows 0 .. ROWS-1 (``t = i``, ``p = [i, -i]``) in blocks of BLOCK."""
    ring = SharedRingBuffer.attach(handle)
    try:
        for start in range(0, ROWS, BLOCK):
            t = np.arange(start, start + BLOCK, dtype=np.float64)
            ring.append({"t": t, "p": np.stack([t, -t], axis=1).astype(np.float32)})
    finally:
        ring.close()
