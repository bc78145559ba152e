"""A ring buffer in shared memory: rows appended in one process, read in another.

Responsibility: :class:`SharedRingBuffer` keeps the ring's column arrays and its two counters
(the next row's index and the rows appended so far) in one
:class:`multiprocessing.shared_memory.SharedMemory` block, guarded by a
:class:`multiprocessing.Lock` instead of a thread lock. The process that creates it owns the
block (:meth:`SharedRingBuffer.unlink` removes it); another process attaches with the
picklable :class:`SharedRingHandle` (:meth:`SharedRingBuffer.handle`, passed to a ``spawn``
child as an argument, which is how a multiprocessing lock may travel). Every append and every
snapshot holds the lock, so a snapshot never mixes two appends, as in one process.

Why: the live console's acquisition runs in its own process (:mod:`daq.console.process_source`), so
that its threads do not hold the interpreter lock against the GUI thread; the rows it
synchronises reach the GUI through this ring without being pickled.

Not responsible for: the ring's semantics (:class:`~daq.console.ring_buffer.RingBuffer`), or who
appends.
"""

from __future__ import annotations

import multiprocessing
from dataclasses import dataclass
from multiprocessing.shared_memory import SharedMemory
from typing import Any

import numpy as np
import numpy.typing as npt

from daq.console.ring_buffer import Column, RingBuffer
from daq.errors import RingStalledError

__all__ = ["SharedRingBuffer", "SharedRingHandle"]

#: Each column starts at a multiple of this many bytes of the block (a cache line).
_ALIGN = 64
#: The counters at the start of the block: next row index, rows appended (int64 each).
_COUNTERS = 2
#: Longest wait for the ring's lock, s: an append or a snapshot holds it for about a
#: millisecond; a writer killed while holding it (SIGKILL) would block every reader forever
#: (the console's GUI froze so, once, in a test that kills the acquisition process).
LOCK_TIMEOUT_S = 0.5


class _TimedLock:
    """A multiprocessing lock taken with a timeout (:data:`LOCK_TIMEOUT_S`), or not at all."""

    def __init__(self, lock: Any) -> None:
        self.lock = lock
        self.abandoned = False

    def __enter__(self) -> _TimedLock:
        if not self.abandoned and not self.lock.acquire(timeout=LOCK_TIMEOUT_S):
            raise RingStalledError(
                f"the shared ring's lock was not released within {LOCK_TIMEOUT_S:g} s (its "
                "writer died holding it, or is stuck)")
        return self

    def __exit__(self, *exc: object) -> None:
        if not self.abandoned:
            self.lock.release()


@dataclass(frozen=True)
class SharedRingHandle:
    """What another process needs to attach to a :class:`SharedRingBuffer`.

    Attributes
    ----------
    name : str
        The shared memory block's name.
    capacity_rows : int
        Rows kept.
    columns : tuple of Column
        The ring's columns, in order.
    lock : multiprocessing.synchronize.Lock
        The lock every append and snapshot holds (passed to a child process when it starts).
    """

    name: str
    capacity_rows: int
    columns: tuple[Column, ...]
    lock: Any


def _layout(capacity_rows: int, columns: tuple[Column, ...]) -> tuple[dict[str, int], int]:
    """Return each column's byte offset in the block and the block's size, bytes."""
    offset = _ALIGN  # the counters first (16 bytes, padded to a cache line)
    offsets = {}
    for c in columns:
        offsets[c.name] = offset
        size = capacity_rows * int(np.prod(c.shape, dtype=np.int64)) * np.dtype(c.dtype).itemsize
        offset += -(-size // _ALIGN) * _ALIGN
    return offsets, max(offset, _ALIGN)


class SharedRingBuffer(RingBuffer):
    """A ring buffer whose rows live in shared memory (see the module docstring).

    Parameters
    ----------
    capacity_rows : int
        Rows kept, >= 1.
    *columns : str or Column
        The columns, as for :class:`~daq.console.ring_buffer.RingBuffer`.

    Examples
    --------
    >>> ring = SharedRingBuffer(3, "t")
    >>> other = SharedRingBuffer.attach(ring.handle())  # as another process would
    >>> other.append({"t": [1.0, 2.0]})
    >>> ring.snapshot()["t"].tolist(), ring.total_rows
    ([1.0, 2.0], 2)
    >>> other.close(); ring.close(); ring.unlink()
    """

    _shm: SharedMemory
    _counters: npt.NDArray[np.int64]

    def __init__(self, capacity_rows: int, *columns: str | Column) -> None:
        self._owner = True
        super().__init__(capacity_rows, *columns)
        self._lock = _TimedLock(multiprocessing.get_context("spawn").Lock())

    def _allocate(self, capacity_rows: int,
                  specs: tuple[Column, ...]) -> dict[str, npt.NDArray[Any]]:
        """Create the shared block and return the column arrays laid out in it."""
        _, size = _layout(capacity_rows, specs)
        self._shm = SharedMemory(create=True, size=size)
        data = self._views(capacity_rows, specs)
        self._counters[:] = 0
        for arr in data.values():
            arr.fill(0)
        return data

    def _views(self, capacity_rows: int,
               specs: tuple[Column, ...]) -> dict[str, npt.NDArray[Any]]:
        """Set the counters' view and return the columns' views of the shared block."""
        offsets, _ = _layout(capacity_rows, specs)
        buf = self._shm.buf
        self._counters = np.ndarray((_COUNTERS,), dtype=np.int64, buffer=buf, offset=0)
        return {c.name: np.ndarray((capacity_rows, *c.shape), dtype=c.dtype, buffer=buf,
                                   offset=offsets[c.name]) for c in specs}

    @classmethod
    def attach(cls, handle: SharedRingHandle) -> SharedRingBuffer:
        """Return the ring that ``handle`` describes, attached in this process (not its owner).

        Raises
        ------
        FileNotFoundError
            The block does not exist (its owner unlinked it).
        """
        ring = cls.__new__(cls)
        ring._owner = False
        ring._capacity = int(handle.capacity_rows)
        ring._columns = {c.name: c for c in handle.columns}
        ring._shm = SharedMemory(name=handle.name)
        ring._data = ring._views(ring._capacity, tuple(handle.columns))
        ring._lock = _TimedLock(handle.lock)
        return ring

    def handle(self) -> SharedRingHandle:
        """Return what another process needs to attach (pass it to the child at its start)."""
        return SharedRingHandle(self._shm.name, self._capacity, self.columns, self._lock.lock)

    def abandon_lock(self) -> None:
        """Read without the lock from now on: every writer is gone (its process ended).

        A writer killed while holding the lock never releases it; with no writer left the
        rows no longer change, so reading them unlocked is safe.
        """
        self._lock.abandoned = True

    # The counters are in the block, so that every process sees the same ring.
    @property
    def _head(self) -> int:
        return int(self._counters[0])

    @_head.setter
    def _head(self, value: int) -> None:
        self._counters[0] = value

    @property
    def _total(self) -> int:
        return int(self._counters[1])

    @_total.setter
    def _total(self, value: int) -> None:
        self._counters[1] = value

    def close(self) -> None:
        """Detach this process's views (the arrays must not be used afterwards)."""
        self._data = {}
        self._counters = np.zeros(_COUNTERS, dtype=np.int64)
        self._shm.close()

    def unlink(self) -> None:
        """Remove the block (the owner, once no process appends any more)."""
        if not self._owner:
            raise RuntimeError("SharedRingBuffer.unlink: only the process that created the "
                               "ring removes it")
        self._shm.unlink()
