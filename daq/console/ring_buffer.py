"""A thread-safe, fixed-size ring of the most recent rows of a few named columns.

Responsibility: keep the last ``capacity_rows`` rows appended, per column, in preallocated numpy
arrays (memory is fixed at construction: O(capacity), whatever is appended), and hand out
time-ordered copies. The live view (:mod:`daq.console.window`) polls :meth:`RingBuffer.snapshot`
from its GUI timer; an acquisition subscriber calls :meth:`RingBuffer.append` from the dispatcher
thread. One lock makes every append and snapshot atomic: a snapshot never mixes rows of two appends,
and all its columns have the same rows.

Not responsible for: choosing what to buffer (the subscriber that feeds it), downsampling or
plotting (the GUI), or persistence (the recorder).
"""

from __future__ import annotations

import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["Column", "RingBuffer"]


@dataclass(frozen=True)
class Column:
    """One column of a :class:`RingBuffer`.

    Attributes
    ----------
    name : str
        Column name (the key of appended blocks and snapshots).
    dtype : numpy dtype-like
        Element type, default float64.
    shape : tuple of int
        Shape of one row's value: ``()`` for a scalar per row, ``(64,)`` for 64 pressures.
    """

    name: str
    dtype: Any = np.float64
    shape: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"a column name is a non-empty string, got {self.name!r}")
        if not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0
                   for s in self.shape):
            raise ValueError(f"column {self.name!r}: shape must be a tuple of ints >= 0, "
                             f"got {self.shape!r}")
        np.dtype(self.dtype)  # raises TypeError for an unknown dtype


class RingBuffer:
    """The most recent ``capacity_rows`` rows of named columns (thread-safe, fixed memory).

    Parameters
    ----------
    capacity_rows : int
        Rows kept, >= 1.
    *columns : str or Column
        The columns; a bare name is a float64 scalar column. Names must be distinct.

    Examples
    --------
    >>> ring = RingBuffer(3, "t", Column("p", shape=(2,)))
    >>> ring.append({"t": [0.0, 1.0], "p": [[1, 2], [3, 4]]})
    >>> ring.append({"t": [2.0, 3.0], "p": [[5, 6], [7, 8]]})
    >>> snap = ring.snapshot()
    >>> snap["t"].tolist(), snap["p"][:, 0].tolist(), ring.total_rows
    ([1.0, 2.0, 3.0], [3.0, 5.0, 7.0], 4)
    """

    def __init__(self, capacity_rows: int, *columns: str | Column) -> None:
        if isinstance(capacity_rows, bool) or not isinstance(capacity_rows, int) \
                or capacity_rows < 1:
            raise ValueError(f"capacity_rows must be an integer >= 1, got {capacity_rows!r}")
        if not columns:
            raise ValueError("a RingBuffer needs at least one column")
        specs = tuple(c if isinstance(c, Column) else Column(c) for c in columns)
        names = [c.name for c in specs]
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            raise ValueError(f"column names must be distinct; repeated: {repeated}")
        self._capacity = capacity_rows
        self._columns: dict[str, Column] = {c.name: c for c in specs}
        self._data: dict[str, npt.NDArray[Any]] = self._allocate(capacity_rows, specs)
        self._head = 0  # index the next row is written to
        self._total = 0  # rows appended since construction (or the last clear)
        self._lock: Any = threading.Lock()

    def _allocate(self, capacity_rows: int,
                  specs: tuple[Column, ...]) -> dict[str, npt.NDArray[Any]]:
        """Return the zeroed column arrays (a subclass may place them in shared memory)."""
        return {c.name: np.zeros((capacity_rows, *c.shape), dtype=c.dtype) for c in specs}

    # -- description -----------------------------------------------------------------------------
    @property
    def capacity_rows(self) -> int:
        """Measure the number of rows kept."""
        return self._capacity

    @property
    def columns(self) -> tuple[Column, ...]:
        """Measure the column specifications, in construction order."""
        return tuple(self._columns.values())

    @property
    def total_rows(self) -> int:
        """Measure the rows appended so far (a poller sees new data when it changes)."""
        with self._lock:
            return self._total

    def __len__(self) -> int:
        """Return the rows held: ``min(total_rows, capacity_rows)``."""
        with self._lock:
            return min(self._total, self._capacity)

    # -- writing ---------------------------------------------------------------------------------
    def append(self, block: Mapping[str, npt.ArrayLike]) -> None:
        """Append ``n`` rows (``n`` may be 0 or exceed the capacity: the last rows are kept).

        Parameters
        ----------
        block : mapping of str to array-like
            One array per column, exactly the buffer's columns, each of shape
            ``(n, *column.shape)`` with the same ``n``; values are cast to the column's dtype
            with ``same_kind`` casting (float into an int column is refused).

        Raises
        ------
        KeyError
            A column is missing, or the block has a column the buffer does not.
        ValueError
            Row counts differ between columns, or a row has the wrong shape.
        TypeError
            A value cannot be cast to its column's dtype safely.

        Nothing is written unless every column is valid.
        """
        missing = sorted(set(self._columns) - set(block))
        unknown = sorted(set(block) - set(self._columns))
        if missing or unknown:
            raise KeyError(f"block columns must be {sorted(self._columns)}; missing {missing}, "
                           f"unknown {unknown}")
        arrays: dict[str, npt.NDArray[Any]] = {}
        rows: int | None = None
        for name, spec in self._columns.items():
            arr = np.asarray(block[name])
            if arr.ndim != 1 + len(spec.shape) or arr.shape[1:] != spec.shape:
                raise ValueError(f"column {name!r}: expected shape (n, *{spec.shape}), "
                                 f"got {arr.shape}")
            if not np.can_cast(arr.dtype, spec.dtype, casting="same_kind"):
                raise TypeError(f"column {name!r}: cannot cast {arr.dtype} to {spec.dtype} "
                                "safely")
            if rows is None:
                rows = arr.shape[0]
            elif arr.shape[0] != rows:
                raise ValueError(f"columns have different row counts: {name!r} has "
                                 f"{arr.shape[0]}, others {rows}")
            arrays[name] = arr
        assert rows is not None  # at least one column
        if rows == 0:
            return
        cap = self._capacity
        keep = min(rows, cap)
        with self._lock:
            start = (self._head + rows - keep) % cap  # where the first kept row goes
            first = min(keep, cap - start)  # rows up to the end of the array
            for name, arr in arrays.items():
                src = arr[rows - keep:]
                dst = self._data[name]
                np.copyto(dst[start:start + first], src[:first], casting="same_kind")
                if keep > first:
                    np.copyto(dst[:keep - first], src[first:], casting="same_kind")
            self._head = (self._head + rows) % cap
            self._total += rows

    def clear(self) -> None:
        """Forget every row (the arrays are kept; ``total_rows`` restarts at 0)."""
        with self._lock:
            self._head = 0
            self._total = 0

    # -- reading ---------------------------------------------------------------------------------
    def snapshot(self, last: int | None = None,
                 columns: Sequence[str] | None = None) -> dict[str, npt.NDArray[Any]]:
        """Return copies of the rows held, oldest first (all columns the same rows).

        Parameters
        ----------
        last : int, optional
            Return only the most recent ``last`` rows (>= 0); default all rows held.
        columns : sequence of str, optional
            Copy only these columns (a viewer that draws the scalars of a whole window needs
            only the latest row of a wide column); default all.

        Returns
        -------
        dict of str to ndarray
            One array per requested column, shape ``(rows, *column.shape)``; the caller owns
            them.

        Raises
        ------
        ValueError
            ``last`` is not an integer >= 0.
        KeyError
            A requested column does not exist.
        """
        if last is not None and (isinstance(last, bool) or not isinstance(last, int)
                                 or last < 0):
            raise ValueError(f"last must be an integer >= 0 or None, got {last!r}")
        names = list(self._data) if columns is None else list(columns)
        unknown = [name for name in names if name not in self._data]
        if unknown:
            raise KeyError(f"no column(s) {unknown} in the buffer; it has {list(self._data)}")
        with self._lock:
            held = min(self._total, self._capacity)
            n = held if last is None else min(last, held)
            start = (self._head - n) % self._capacity
            idx_end = start + n
            out: dict[str, npt.NDArray[Any]] = {}
            for name in names:
                arr = self._data[name]
                if idx_end <= self._capacity:
                    out[name] = arr[start:idx_end].copy()
                else:
                    out[name] = np.concatenate((arr[start:], arr[:idx_end - self._capacity]))
            return out
