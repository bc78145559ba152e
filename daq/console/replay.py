"""Play a recorded run file back, in time, as a console data source.

Responsibility: open a windrig run file read-only (as a SWMR reader when a writer has it open,
:func:`daq.recording.layout.open_run_file`, so a run still being written can be followed),
check that it has the synchronised view and a usable rig config, and on each
:meth:`ReplaySource.poll` move the playback position forward by ``speed`` times the wall-clock
time elapsed, appending the rows of ``/entry/sync`` now due to a :class:`~daq.console.ring_buffer.
RingBuffer` that holds the visible window. :meth:`ReplaySource.snapshot` is that buffer's
snapshot, so a live source wrapping the acquisition's ring buffer is a drop-in replacement.
Only the new rows are read from the file at each poll; h5py objects never leave this module.

Not responsible for: drawing (:mod:`daq.console.window`), or the file's layout
(:mod:`daq.recording.layout`, ``docs/reference/file_format.md``).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np

from daq.console.replay_config import replay_config
from daq.console.ring_buffer import RingBuffer
from daq.console.source import SWAY_SCALARS, SYNC_SCALARS, RingSource, SourceInfo, sync_columns
from daq.errors import ReplayError
from daq.recording.layout import open_run_file

__all__ = ["MIN_HISTORY_S", "ReplaySource"]

#: The ring holds at least this much of the run, s (a whole decay for the releases table).
MIN_HISTORY_S = 30.0


class ReplaySource(RingSource):
    """A recorded run played back at ``speed`` times real time (a :class:`DataSource`).

    Parameters
    ----------
    path : str or Path
        A windrig run file.
    speed : float
        Playback speed, > 0 (1: real time; 10: ten seconds of run per second).
    window_s : float
        Length of the history kept for the views, s of run time, > 0.
    clock : callable, optional
        Monotonic clock in s; ``time.monotonic`` by default (a seam for tests).

    Notes
    -----
    The constructor does no I/O; :meth:`open` (or ``with``) opens the file. The playback clock
    starts at the first :meth:`poll`, at the first row of the file.
    """

    def __init__(self, path: str | os.PathLike[str], *, speed: float = 1.0,
                 window_s: float = 20.0, clock: Callable[[], float] | None = None) -> None:
        if not (isinstance(speed, (int, float)) and 0 < speed < math.inf):
            raise ValueError(f"speed = {speed!r} must be a number > 0")
        if not (isinstance(window_s, (int, float)) and 0 < window_s < math.inf):
            raise ValueError(f"window_s = {window_s!r} must be a number of seconds > 0")
        self.path = Path(path)
        self.speed = float(speed)
        self.window_s = float(window_s)
        self._clock = clock if clock is not None else time.monotonic
        self._file: h5py.File | None = None
        self._ds: dict[str, h5py.Dataset] = {}
        self._time = np.zeros(0)  # the time column read so far, s
        self._next = 0  # first row not yet in the ring
        self._ring: RingBuffer | None = None
        self._info: SourceInfo | None = None
        self._started_at: float | None = None
        self._error: str | None = None
        self._decays: list[tuple[float, float | None]] = []  # the file's releases table
        self._note: str | None = None  # what the file lacks that replay does without
        self._n_taps = 0  # the width of the NaN pressures of a file without any

    # -- life cycle ------------------------------------------------------------------------------
    def open(self) -> None:
        """Open and check the file.

        Raises
        ------
        ReplayError
            The file is missing, is not HDF5, is truncated, lacks a scalar column of
            ``/entry/sync`` or ``/entry/config``, or its config is invalid (a file without
            pressures needs only its ``[section]``) or does not match the pressure width.
        """
        if self._file is not None:
            return
        where = str(self.path)
        if not self.path.is_file():
            raise ReplayError(f"{where}: no such file")
        try:
            f = open_run_file(self.path)
        except OSError as exc:
            raise ReplayError(f"{where}: cannot be opened as an HDF5 run file "
                              f"(not HDF5, or truncated): {exc}") from exc
        try:
            self._file = f
            self._check_layout(f, where)
        except BaseException:
            self.close()
            raise

    def _check_layout(self, f: h5py.File, where: str) -> None:
        # What replay needs (docs/reference/file_format.md, "What each command needs"): the sync
        # view's scalar columns and a [section]; the pressures and a whole rig config are optional.
        try:
            if "entry/sync" not in f:
                raise ReplayError(f"{where}: not a windrig run file: has no /entry/sync")
            sync = f["entry/sync"]
            missing = [name for name in SYNC_SCALARS if name not in sync]
            if missing:
                raise ReplayError(f"{where}: has no /entry/sync/{', '.join(missing)}: replay "
                                  f"needs {', '.join(SYNC_SCALARS)} "
                                  "(docs/reference/file_format.md)")
            if "entry/config" not in f:
                raise ReplayError(f"{where}: has no /entry/config: replay needs the stored "
                                  "rig config, or at least its [section] "
                                  "(docs/reference/file_format.md)")
            self._ds = {name: sync[name] for name in (*SYNC_SCALARS, "pressure") if name in sync}
            if all(name in sync for name in SWAY_SCALARS):  # a 3-DOF rig's run
                self._ds.update({name: sync[name] for name in SWAY_SCALARS})
            raw = f["entry/config"][()]
        except KeyError as exc:  # an object that vanished or a broken link: a damaged file
            raise ReplayError(f"{where}: not a windrig run file: missing "
                              f"{exc.args[0] if exc.args else exc}") from exc
        except OSError as exc:
            raise ReplayError(f"{where}: unreadable (truncated?): {exc}") from exc
        text = raw.decode("utf-8") if isinstance(raw, bytes) else str(raw)
        config, self._note = replay_config(text, f"{where}:/entry/config",
                                           has_pressure="pressure" in self._ds,
                                           name=self.path.stem)
        if "pressure" not in self._ds:
            self._n_taps = config.taps.n_taps  # drawn as NaN: the file has no pressures
        pressure = self._ds.get("pressure")
        width = (config.taps.n_taps if pressure is None
                 else pressure.shape[1] if pressure.ndim == 2 else -1)
        if width != config.taps.n_taps:
            raise ReplayError(f"{where}: /entry/sync/pressure has {width} columns, the stored "
                              f"config {config.taps.n_taps} taps")
        try:
            self._refresh()
            n = self._time.size
            for ds in self._ds.values():  # the first and last chunks: a truncated file fails here
                if n:
                    _ = (ds[0], ds[n - 1])
        except OSError as exc:
            raise ReplayError(f"{where}: unreadable HDF5 data (truncated?): {exc}") from exc
        t = self._time
        if t.size < 2:
            raise ReplayError(f"{where}: /entry/sync holds {t.size} row(s); nothing to replay")
        steps = np.diff(t[: min(t.size, 10_000)])
        steps = steps[np.isfinite(steps) & (steps > 0)]
        if steps.size == 0:
            raise ReplayError(f"{where}: /entry/sync/time does not increase")
        rate = 1.0 / float(np.median(steps))
        history_s = max(self.window_s, MIN_HISTORY_S)  # a whole decay, for the releases table
        self._ring = RingBuffer(int(math.ceil(history_s * rate)) + 2,
                                *sync_columns(config.taps.n_taps, sway="p" in self._ds))
        self._info = SourceInfo(label=self.path.name, config=config, rate_hz=rate,
                                duration_s=float(t[-1] - t[0]))

    def close(self) -> None:
        """Close the file (idempotent); the rows already in the window stay readable."""
        f, self._file = self._file, None
        self._ds = {}
        if f is not None:
            f.close()

    # -- the DataSource protocol -----------------------------------------------------------------
    @property
    def position_s(self) -> float:
        """Measure the playback position, s of run time (time of the first row until started)."""
        if self._time.size == 0:
            return math.nan
        if self._started_at is None:
            return float(self._time[0])
        return float(self._time[0]) + self.speed * (self._clock() - self._started_at)

    @property
    def finished(self) -> bool:
        """Tell whether every row of a closed file has been played."""
        return self._time.size > 0 and self._next >= self._time.size \
            and self.position_s > self._time[-1]

    def poll(self) -> int:
        """Append the rows due at the current playback position; return how many.

        Raises
        ------
        ReplayError
            The file became unreadable (truncated chunks); the source is closed then.
        """
        if self._ring is None or self._file is None:
            return 0
        if self._started_at is None:
            self._started_at = self._clock()
        target = self.position_s
        try:
            if self._time.size and target > self._time[-1]:
                self._refresh()  # a run still being written (SWMR) grows
            stop = int(np.searchsorted(self._time, target, side="right"))
            start = max(self._next, stop - self._ring.capacity_rows)  # skip what scrolled past
            if stop <= start:
                return 0
            block = {name: ds[start:stop] for name, ds in self._ds.items()}
            if "pressure" not in block:
                block["pressure"] = np.full((stop - start, self._n_taps), np.nan, np.float32)
        except OSError as exc:
            self._error = f"{self.path}: read failed (truncated?): {exc}"
            self.close()
            raise ReplayError(self._error) from exc
        self._ring.append(block)
        self._next = stop
        return stop - start

    def decays(self) -> list[tuple[float, float | None]]:
        """Return the file's free decays that the playback has reached, oldest first.

        Returns
        -------
        list of (float, float or None)
            ``(release, end)`` from ``/entry/releases``: the release instant and the time of the
            decay's last row, s (the sync view's ``time``), as
            :meth:`daq.console.live_source.LiveSource.decays` reports them live; ``end`` is None for
            a row whose end is past the rows read so far.
        """
        position = self.position_s
        return [d for d in self._decays if d[0] <= position]

    @property
    def error(self) -> str | None:
        """Describe the read error that stopped the replay, if any."""
        return self._error

    def status(self) -> str:
        """Return the status line: file, position / length, speed, end of file or error."""
        if self._error is not None:
            return f"error: {self._error}"
        if self._info is None:
            return f"replay {self.path.name}: not open"
        t0 = float(self._time[0])
        pos = min(self.position_s, float(self._time[-1])) - t0
        state = "end of file" if self.finished else "playing"
        return (f"replay {self._info.label}: {pos:.1f} / {self._info.duration_s or 0.0:.1f} s, "
                f"speed {self.speed:g}x, {self.total_rows} rows, {state}"
                + (f" ({self._note})" if self._note else ""))

    # -- internals -------------------------------------------------------------------------------
    def _refresh(self) -> None:
        """Read the rows of the time column written since the last refresh."""
        for ds in self._ds.values():
            ds.refresh()
        n = min(ds.shape[0] for ds in self._ds.values())  # rows complete in every column
        if n > self._time.size:
            self._time = np.concatenate([self._time, self._ds["time"][self._time.size:n]])
        self._read_releases()

    def _read_releases(self) -> None:
        """Read the releases table (absent in a run that has none yet: no releases)."""
        if self._file is None or "entry/releases" not in self._file:
            return
        ds = self._file["entry/releases"]
        ds.refresh()
        rows = ds[()]
        decays = []
        for row in rows:
            stop = int(row["stop_index"])
            end = float(self._time[stop - 1]) if 0 < stop <= self._time.size else None
            decays.append((float(row["release_time"]), end))
        self._decays = decays
