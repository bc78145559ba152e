"""One HDF5 file written under SWMR: created, switched to SWMR mode, flushed, closed, and failed.

Responsibility: the life cycle of the file behind a :class:`~daq.recording.recorder.RunRecorder`
and its failure paths. :class:`SwmrFile` creates the file only where it may (the directory
exists, no recorded run is overwritten: :func:`refuse_existing_run_file`, enough free space),
switches it to SWMR mode so that a live reader (the GUI, h5py in another process, silx) can
follow the run, flushes it every ``flush_interval_s`` so that a crash of the process loses at
most that much (a power cut too, with ``fsync``), stops before the disk is full (a reserve
checked at each flush), writes at :meth:`SwmrFile.close` the attributes and metadata that SWMR
mode forbids creating, and turns every HDF5 failure into one :class:`~daq.errors.StorageError`
(:meth:`SwmrFile.io`), counted by :func:`failed_writes`.

Not responsible for: what the file holds (:mod:`daq.recording.layout` lays it out, the recorder
declares and appends), nor for threads: like the recorder that owns it, it is used from one
thread.

The phases of the file, as :attr:`SwmrFile.state`: ``"new"`` (no I/O yet) -> ``"declaring"``
(created, not yet SWMR: groups, datasets and attributes may be created) -> ``"recording"``
(SWMR mode: only appends) -> ``"closed"``; ``"failed"`` after a failed write, where only
:meth:`SwmrFile.close` remains.

A live reader opens with ``h5py.File(path, "r", libver="latest", swmr=True)`` and calls
``dataset.refresh()`` before reading a shape. The datasets of one group are resized one after the
other, so a live reader should read the shortest length over the datasets it combines
(:func:`daq.recording.layout.read_sync` does). A file left behind by a crash keeps HDF5's "open for
SWMR write" flag: it opens read-only with ``swmr=True`` (as :func:`daq.recording.layout.read_sync`
does); a plain ``h5py.File(path)`` refuses it until ``h5clear -s`` clears the flag.
"""

from __future__ import annotations

import errno
import os
import re
import shutil
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import h5py

from daq.errors import InsufficientSpaceError, RecorderStateError, StorageError
from daq.recording.layout import write_metadata

__all__ = ["SwmrFile", "failed_writes", "refuse_existing_run_file"]


def refuse_existing_run_file(path: Path, hint: str = "") -> None:
    """Raise :class:`StorageError` (``EEXIST``) if ``path`` exists: a recorded run is kept.

    Parameters
    ----------
    path : Path
        The run file about to be created.
    hint : str
        Appended to the message (how the caller would replace it, if it can).
    """
    if path.exists():
        raise StorageError(errno.EEXIST, f"run file {path} already exists; refusing to "
                           f"overwrite a recorded run{hint}", str(path))


def _disk_free(directory: Path) -> int:
    return shutil.disk_usage(directory).free


_failed_writes = 0
#: HDF5 objects of the files whose write failed, never freed (:meth:`SwmrFile.close`).
_abandoned: list[list[Any]] = []


def failed_writes() -> int:
    """Count the run-file writes that failed in this process (each raised a StorageError).

    After one, h5py 3.16 / HDF5 2.0 crash the process (SIGSEGV) when it exits, whatever is
    closed first (h5py issue 914, a bug of the HDF5 library): a command line that has reported
    the error should then leave with ``os._exit`` (after flushing its output). The failed file's
    HDF5 objects are never freed for the same reason (:meth:`SwmrFile.close`).
    """
    return _failed_writes


class SwmrFile:
    """The HDF5 file of one run under SWMR, with its flushes and its failures.

    Parameters
    ----------
    path : Path
        The file to create.
    flush_interval_s, min_free_bytes, reserve_bytes, overwrite, fsync
        As :class:`~daq.recording.recorder.RunRecorder`'s (validated there).
    disk_free : callable, optional
        ``disk_free(directory) -> bytes`` free for the file; ``shutil.disk_usage(dir).free`` by
        default.
    clock : callable, optional
        Monotonic clock in s for the flush interval; ``time.monotonic`` by default.
    release_handles : callable
        Returns the open HDF5 objects (groups, datasets) its owner holds in the file and forgets
        them; called once, when the file is closed or abandoned.

    Notes
    -----
    Not thread-safe: call every method from one thread. The constructor does no I/O.
    """

    def __init__(self, path: Path, *, flush_interval_s: float, min_free_bytes: int,
                 reserve_bytes: int, overwrite: bool, fsync: bool,
                 disk_free: Callable[[Path], int] | None, clock: Callable[[], float] | None,
                 release_handles: Callable[[], list[Any]]) -> None:
        self.path = path
        self.flush_interval_s = flush_interval_s
        self.min_free_bytes = min_free_bytes
        self.reserve_bytes = reserve_bytes
        self.overwrite = overwrite
        self.fsync = fsync
        self._disk_free = disk_free if disk_free is not None else _disk_free
        self._clock = clock if clock is not None else time.monotonic
        self._release_handles = release_handles
        #: The phase (module docstring): new -> declaring -> recording -> closed; failed after
        #: an I/O error.
        self.state = "new"
        #: The open file (``"declaring"``, ``"recording"``), else None.
        self.h5: h5py.File | None = None
        self._deferred_attrs: dict[str, dict[str, Any]] = {}
        self._deferred_metadata: dict[str, Any] = {}
        self._last_flush = 0.0
        self._batch_depth = 0  # > 0 inside batch(): the appends leave the flush to its end
        #: Flushes done so far (periodic and explicit).
        self.flushes = 0

    def require(self, what: str, *states: str) -> None:
        """Raise :class:`RecorderStateError` unless the file is in one of ``states``."""
        if self.state not in states:
            order = "open() -> add_stream()/add_sync() -> start() -> append -> close()"
            raise RecorderStateError(f"{what}() is not allowed while the recorder is "
                                     f"{self.state!r} (allowed: {', '.join(states)}); "
                                     f"call order: {order}")

    def create(self, write_skeleton: Callable[[h5py.File], None]) -> None:
        """Create the file and write its fixed groups (``write_skeleton(file)``).

        Raises
        ------
        InsufficientSpaceError
            The file system has less than ``min_free_bytes`` free (``errno`` ENOSPC).
        StorageError
            The directory is missing or not writable, the file exists (without ``overwrite``),
            or creating it failed (e.g. ENOSPC from the disk); ``errno`` says which.
        """
        directory = self.path.parent
        if not directory.is_dir():
            code, why = ((errno.ENOTDIR, "is not a directory") if directory.exists()
                         else (errno.ENOENT, "does not exist"))
            raise StorageError(code, f"cannot create run file {self.path}: {directory} {why}",
                               str(self.path))
        if not self.overwrite:
            refuse_existing_run_file(self.path, " (pass overwrite=True to replace it)")
        free = self._free_bytes(directory)
        if free < self.min_free_bytes:
            raise InsufficientSpaceError(
                errno.ENOSPC, f"cannot record to {self.path}: only {free / 2**20:.1f} MiB free on "
                f"its file system, the minimum is {self.min_free_bytes / 2**20:.1f} MiB "
                "(free space or choose another disk)", str(self.path))
        try:
            # v110 is the oldest format with SWMR: readable by HDF5 >= 1.10 (MATLAB, silx, ...).
            self.h5 = h5py.File(self.path, "w" if self.overwrite else "w-",
                                libver=("v110", "latest"))
            write_skeleton(self.h5)
            self.h5.flush()  # write the superblock now: a full disk fails here, not later
        except OSError as exc:
            self._abandon()
            code = exc.errno if exc.errno is not None else errno.EIO
            raise StorageError(code, f"cannot create run file {self.path}: {os.strerror(code)}",
                               str(self.path)) from exc
        self.state = "declaring"

    def start_swmr(self) -> None:
        """Switch the file to SWMR mode: from now on, only appends."""
        assert self.h5 is not None
        with self.io("start SWMR mode"):
            self.h5.swmr_mode = True
            self.h5.flush()
        self._last_flush = self._clock()
        self.state = "recording"

    def defer_attrs(self, group: str, attrs: dict[str, Any]) -> None:
        """Write ``attrs`` on ``group`` (a path in the file) at :meth:`close`; later ones win."""
        self._deferred_attrs.setdefault(group, {}).update(attrs)

    def defer_metadata(self, name: str, value: Any) -> None:
        """Write ``/entry/metadata/<name>`` at :meth:`close` (validated by the caller)."""
        self._deferred_metadata[name] = value

    def flush(self) -> None:
        """Write everything appended so far to the file (and ``fsync`` it if configured).

        Raises
        ------
        InsufficientSpaceError
            Free space fell below ``reserve_bytes``: the file was flushed and closed (it is
            complete up to now) and the file is closed.
        StorageError
            The write failed (e.g. ENOSPC): the file is failed; only :meth:`close` remains.
        """
        if self.state not in ("declaring", "recording"):
            return
        assert self.h5 is not None
        with self.io("flush"):
            self.h5.flush()
            if self.fsync:
                os.fsync(self.h5.id.get_vfd_handle())
        self._last_flush = self._clock()
        self.flushes += 1
        if self.state == "recording" and self.reserve_bytes > 0:
            free = self._free_bytes(self.path.parent)
            if free < self.reserve_bytes:
                self.close()
                raise InsufficientSpaceError(
                    errno.ENOSPC, f"stopped recording to {self.path}: only {free / 2**20:.1f} "
                    f"MiB left on its file system, below the reserve of "
                    f"{self.reserve_bytes / 2**20:.1f} MiB; the file is closed and complete up "
                    "to now", str(self.path))

    def flush_if_due(self) -> bool:
        """Flush if the last flush is ``flush_interval_s`` old; return whether it flushed."""
        if self.state == "recording" and self._batch_depth == 0 and \
                self._clock() - self._last_flush >= self.flush_interval_s:
            self.flush()
            return True
        return False

    @contextmanager
    def batch(self) -> Iterator[None]:
        """Append several things as one: a flush due inside waits for the end (not on error)."""
        self._batch_depth += 1
        try:
            yield
        finally:
            self._batch_depth -= 1
        if self._batch_depth == 0:
            self.flush_if_due()

    def close(self) -> None:
        """Flush and close the file, then write what was deferred; idempotent.

        After this the file is a normal HDF5 file (the SWMR flag is cleared), unless a write had
        failed: then the file is left as it is (readable with SWMR up to its last flush) and its
        HDF5 objects are kept, never freed (see :func:`failed_writes`).
        """
        if self.state in ("new", "closed"):
            self.state = "closed"
            return
        assert self.h5 is not None
        file, self.h5 = self.h5, None
        failed = self.state == "failed"
        self.state = "closed"
        handles = self._release_handles()
        if failed:
            # A write failed (the StorageError raised then said why). Closing, or merely freeing,
            # the HDF5 objects of such a file fails again in their finalisers, which print
            # tracebacks ("Exception ignored in ... __dealloc__"), and HDF5 crashes the process
            # at exit whatever is done here: keep them, for the life of the process.
            _abandoned.append([file, *handles])
            return
        del handles
        with self.io("close"):
            try:
                file.flush()
            finally:
                file.close()
            if self._deferred_attrs or self._deferred_metadata:
                # SWMR forbids new attributes and objects: write them now, without SWMR.
                with h5py.File(self.path, "r+", libver=("v110", "latest")) as again:
                    for group, attrs in self._deferred_attrs.items():
                        for name, value in attrs.items():
                            again[group].attrs[name] = value
                    for name, value in self._deferred_metadata.items():
                        write_metadata(again["entry/metadata"], name, value)
        self._deferred_attrs.clear()
        self._deferred_metadata.clear()

    @contextmanager
    def io(self, what: str) -> Iterator[None]:
        """Turn an HDF5 failure into a :class:`StorageError` and mark the file failed.

        h5py reports a failed write (ENOSPC, EIO) as ``RuntimeError`` from a flush and as
        ``OSError`` elsewhere; the errno is only in HDF5's message ("errno = 28").
        """
        try:
            yield
        except StorageError:
            raise
        except (OSError, RuntimeError) as exc:
            global _failed_writes
            _failed_writes += 1
            if self.state != "closed":
                self.state = "failed"
            code = getattr(exc, "errno", None)
            if code is None:
                found = re.search(r"errno = (\d+)", str(exc))
                code = int(found.group(1)) if found else errno.EIO
            raise StorageError(code, f"run file {self.path}: cannot {what}: "
                               f"{os.strerror(code)}; the recording stopped, the file holds the "
                               "data up to the last flush", str(self.path)) from exc

    def _free_bytes(self, directory: Path) -> int:
        try:
            return int(self._disk_free(directory))
        except OSError as exc:
            code = exc.errno if exc.errno is not None else errno.EIO
            raise StorageError(code, f"cannot check free space for {self.path}: {exc}",
                               str(self.path)) from exc

    def _abandon(self) -> None:
        """Close and delete a half-created file (its creation failed)."""
        self._release_handles()
        if self.h5 is not None:
            try:
                self.h5.close()
            except OSError:  # closing a half-created file: the create error is what matters
                pass
            self.h5 = None
        if self.path.is_file():  # never unlink a device such as /dev/full
            self.path.unlink(missing_ok=True)
