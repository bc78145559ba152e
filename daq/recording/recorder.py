"""HDF5 writer of one run: raw device streams, the synchronised view, releases and events.

Responsible for: writing one run file in the layout of :mod:`daq.recording.layout` (a contract that
tests, ``ident`` and outside readers such as silx rely on); appending blocks in place to chunked,
resizable datasets; switching the file to SWMR mode so that a live reader (the GUI, h5py in another
process, silx) can follow the run; flushing every ``flush_interval_s`` so that a crash of the
process loses at most that much (a power cut too, with ``fsync=True``); and failing *at once*, with
a specific error, when the file cannot be created or the disk is (nearly) full.

Not responsible for: acquisition, clock fitting, resampling or integrating pressures (the
acquisition engine computes every number written here), nor for threads: a :class:`RunRecorder`
is a subscriber fed through its methods, from one thread (the engine's writer thread). It never
touches acquisition threads' state and acquisition threads never touch h5py.

Call order
----------
Once a file is in SWMR mode its writer may only append to (or overwrite) existing datasets: new
groups, datasets and attributes are not supported (HDF5 SWMR User's Guide). So a run is
recorded in three phases::

    rec = RunRecorder(path, config_text=cfg.text, rig_name=cfg.name)   # no I/O
    rec.open()                               # create the file (fails at once if it cannot)
    rec.add_stream("laser_h", ["distance"], "m", 2000.0, "float64")    # declare ...
    rec.add_sync(tap_names)                  # ... every stream and the synchronised view
    rec.add_metadata("calz", {...})          # optional, written now
    rec.start()                              # file switches to SWMR mode: declarations end
    rec.append_raw(...); rec.append_sync(...); rec.add_event(...)      # append, many times
    rec.close()                              # idempotent; a normal HDF5 file afterwards

:meth:`set_sync_attrs` and :meth:`add_metadata` may also be called after :meth:`start`; their
attributes and datasets cannot be created in SWMR mode, so they are held in memory and written
by :meth:`close` (which reopens the file without SWMR). A crash loses them (not the data: clock
fits can be redone from the raw streams, which keep every host and device time stamp).

The file's layout (groups, datasets, their types and fill values) is
:mod:`daq.recording.layout`'s, described for readers in ``docs/file_format.md``.

A live reader opens with ``h5py.File(path, "r", libver="latest", swmr=True)`` and calls
``dataset.refresh()`` before reading a shape. The datasets of one group are resized one after the
other, so a live reader should read the shortest length over the datasets it combines
(:func:`daq.recording.layout.read_sync` does). A file left behind by a crash keeps HDF5's "open for
SWMR write" flag: it opens read-only with ``swmr=True`` (as :func:`daq.recording.layout.read_sync`
does); a plain ``h5py.File(path)`` refuses it until ``h5clear -s`` clears the flag.

Longer than 600 lines: :class:`RunRecorder` is one object, the life cycle of one HDF5 file
under SWMR (open, declare, start, append, flush, close) together with its failure paths (a full
disk, a failed write, an abandoned file), which all hold the same open file and dataset handles;
most of its length is the numpydoc of its public methods, which state the SWMR rules where they
apply. What does not need that state is elsewhere: the layout in :mod:`daq.recording.layout`,
the errors in :mod:`daq.errors`, the writer that feeds it in :mod:`daq.recording.writer`.
"""

from __future__ import annotations

import errno
import math
import os
import re
import shutil
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import AbstractContextManager, contextmanager
from pathlib import Path
from typing import Any, Protocol

import h5py
import numpy as np
import numpy.typing as npt

from daq.errors import InsufficientSpaceError, RecorderStateError, StorageError
from daq.recording.layout import (
    EVENT_DTYPE,
    EVENT_KIND_BYTES,
    EVENT_TEXT_BYTES,
    EXTRA_DTYPES,
    GAP_DTYPE,
    RELEASE_DTYPE,
    RELEASE_DTYPE_SWAY,
    VALUE_DTYPES,
    append_rows,
    check_name,
    create_column,
    create_stream,
    create_sync,
    now_iso,
    per_device_attr,
    validate_metadata,
    write_metadata,
    write_skeleton,
)

__all__ = [
    "Recorder",
    "RunRecorder",
    "failed_writes",
    "refuse_existing_run_file",
]


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


class _Stream:
    """Open datasets and row count of one device's raw stream."""

    def __init__(self, datasets: dict[str, h5py.Dataset], n_channels: int, dtype: np.dtype[Any],
                 extra: dict[str, np.dtype[Any]]) -> None:
        # Held open on purpose: closing a dataset flushes and drops its chunk cache, so opening
        # it again per block (group["value"]) re-reads and re-compresses its partial chunk each
        # time and leaves the old copy as dead space (measured: a 3x larger file, 5x slower).
        self.datasets = datasets
        self.n_channels = n_channels
        self.dtype = dtype
        self.extra = extra
        self.rows = 0
        self.gaps = 0


class Recorder(Protocol):
    """What :class:`~daq.recording.writer.RunWriter` writes a run into.

    :class:`RunRecorder` (a run file) and :class:`daq.console.ring_recorder.RingRecorder` (the live
    console's ring buffer, no file) implement it; the methods and their meaning are
    :class:`RunRecorder`'s.
    """

    @property
    def state(self) -> str:
        """Measure the phase: ``"new"``, ``"declaring"``, ``"recording"`` or ``"closed"``."""
        ...

    def open(self) -> None:
        """Start declaring streams."""
        ...

    def start(self, t0_host_ns: int | None = None) -> None:
        """Start taking rows (time 0 at ``t0_host_ns``)."""
        ...

    def close(self) -> None:
        """Finish."""
        ...

    def batch(self) -> AbstractContextManager[None]:
        """Group appends (raw rows and the sync rows made from them) for one flush."""
        ...

    def add_stream(self, device: str, channels: Sequence[str], units: Any, rate_hz: float,
                   value_dtype: Any = "float32", *,
                   extra: Mapping[str, Any] | None = None) -> None:
        """Declare a device's raw stream."""
        ...

    def add_sync(self, tap_names: Sequence[str]) -> None:
        """Declare the synchronised view."""
        ...

    def append_raw(self, device: str, host_time_ns: Any, device_time: Any, counter: Any,
                   values: Any, *, extra: Mapping[str, Any] | None = None) -> None:
        """Append a device's raw samples."""
        ...

    def append_sync(self, time: Any, *, h: Any, alpha: Any, lift: Any, moment: Any,
                    pressure: Any, U: Any, rho: Any, p: Any = None, drag: Any = None) -> None:
        """Append rows of the synchronised view (``p``, ``drag``: a 3-DOF rig's)."""
        ...

    def add_gap(self, device: str, after_counter: int, length: int) -> None:
        """Mark a gap in a device's stream."""
        ...

    def add_event(self, time: float, kind: str, text: str = "") -> None:
        """Add an operator or system event."""
        ...

    def add_release(self, *, release_time: float, start_index: int, stop_index: int, U: float,
                    h0: float, alpha0: float, p0: float | None = None) -> Any:
        """Add a free decay to the releases table (``p0``: a 3-DOF rig's)."""
        ...

    def set_sync_attrs(self, *, clock_offset_s: Mapping[str, float] | None = None,
                       clock_drift_ppm: Mapping[str, float] | None = None,
                       residual_misalignment_s: float | None = None) -> None:
        """Store the clock fits with the synchronised view."""
        ...

    def add_metadata(self, name: str, value: Any) -> None:
        """Store a metadata entry."""
        ...

    def add_calibrations(self, records: Mapping[str, tuple[Mapping[str, Any],
                                                           Mapping[str, str]]]) -> None:
        """Store the calibrations the run applies (before start)."""
        ...


class RunRecorder:
    """Write one run to an HDF5 file laid out as docs/file_format.md (see module docstring).

    Parameters
    ----------
    path : str or Path
        The run file to create. Its directory must exist; an existing file is an error unless
        ``overwrite``.
    config_text : str
        The rig config TOML, verbatim (``RigConfig.text``); stored as ``/entry/config``.
    rig_name : str
        Name of the rig / section model (``RigConfig.name``); attribute of ``/entry``.
    operator_notes : str
        Free text of the operator; attribute of ``/entry``.
    flush_interval_s : float
        Longest time between flushes while appending, s (> 0). Each append method flushes when the
        last flush is older than this; an idle writer thread calls :meth:`flush_if_due`. The
        default, 0.5 s, keeps what a crash loses (this, the writer's 0.2 s batches and the sync
        view's lag behind the streams) under 1 s on two loaded cores (1 s lost up to 1.22 s:
        tests/hil/test_recover_hil.py). Shorter intervals cost file size: each flush writes the
        partly filled gzip chunks, which the next flush writes again elsewhere (0.25 s: a 60 s
        run's file 117 MB instead of 74 MB).
    compression : {"gzip", "lzf", None}
        Filter of the appended datasets, always with the shuffle filter. ``"gzip"`` (level 1, the
        default) is readable by every HDF5 build (MATLAB, HDFView, h5dump, silx); ``"lzf"`` is
        slightly faster but only h5py (or hdf5plugin) can read it. Measured in the tests'
        "Measurements" comment.
    chunk_rows : int
        Rows per chunk of the appended datasets, at most (>= 1); wide datasets get fewer rows so
        that a chunk stays <= 512 KiB (a 512-channel float32 stream: 256 rows). 4096 rows of a
        1-D float64 column are 32 KiB, 8 s at 500 Hz.
    min_free_bytes : int
        Free space the file system must have when :meth:`open` is called, bytes (>= 0). The
        default 1 GiB holds about 20 min of a 512-tap scanner at 500 Hz (0.8 MB/s compressed).
        Checked at :meth:`open`; while recording, ``reserve_bytes`` applies.
    reserve_bytes : int
        Free space to keep while recording, bytes (>= 0; 0: no check): each flush checks it and,
        below it, closes the file cleanly and raises :class:`InsufficientSpaceError`. Stopping
        before the disk is full matters: after a failed write, h5py 3.16 / HDF5 2.0 crash the
        process (SIGSEGV) when the file is closed or at exit (measured on a full tmpfs).
    overwrite : bool
        Replace an existing file instead of refusing it.
    fsync : bool
        Also ``fsync`` the file at each flush, so that a power cut (not only a crash of the
        process) loses at most ``flush_interval_s`` of data.
    disk_free : callable, optional
        ``disk_free(directory) -> bytes`` free for the file; ``shutil.disk_usage(dir).free`` by
        default. A seam for tests (a full disk cannot be made without root).
    clock : callable, optional
        Monotonic clock in s for the flush interval; ``time.monotonic`` by default.
    sway : bool
        A rig with three degrees of freedom: ``/entry/sync`` gets the ``p`` and ``drag``
        columns (``append_sync(p=, drag=)`` then required) and ``/entry/releases`` the ``p0``
        field. Default False: the 2-DOF layout, unchanged.

    Notes
    -----
    Not thread-safe: call every method from one thread. The constructor does no I/O.
    """

    def __init__(self, path: str | os.PathLike[str], *, config_text: str, rig_name: str,
                 operator_notes: str = "", flush_interval_s: float = 0.5,
                 compression: str | None = "gzip", chunk_rows: int = 4096,
                 min_free_bytes: int = 1 << 30, reserve_bytes: int = 64 << 20,
                 overwrite: bool = False, fsync: bool = False,
                 disk_free: Callable[[Path], int] | None = None,
                 clock: Callable[[], float] | None = None, sway: bool = False) -> None:
        if not isinstance(config_text, str):
            raise TypeError(f"config_text must be str (the TOML text), got "
                            f"{type(config_text).__name__}")
        if not isinstance(rig_name, str) or not rig_name:
            raise ValueError(f"rig_name must be a non-empty str, got {rig_name!r}")
        if not isinstance(operator_notes, str):
            raise TypeError(f"operator_notes must be str, got {type(operator_notes).__name__}")
        if not (isinstance(flush_interval_s, (int, float)) and 0 < flush_interval_s < math.inf):
            raise ValueError(f"flush_interval_s = {flush_interval_s!r} must be a number > 0 s")
        if compression not in ("gzip", "lzf", None):
            raise ValueError(f"compression = {compression!r}; allowed: 'gzip', 'lzf', None")
        if isinstance(chunk_rows, bool) or not isinstance(chunk_rows, int) or chunk_rows < 1:
            raise ValueError(f"chunk_rows = {chunk_rows!r} must be an int >= 1")
        for name, value in (("min_free_bytes", min_free_bytes), ("reserve_bytes", reserve_bytes)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{name} = {value!r} must be an int >= 0")
        self.path = Path(path)
        self.sway = bool(sway)
        self.config_text = config_text
        self.rig_name = rig_name
        self.operator_notes = operator_notes
        self.flush_interval_s = float(flush_interval_s)
        self.compression = compression
        self.chunk_rows = chunk_rows
        self.min_free_bytes = min_free_bytes
        self.reserve_bytes = reserve_bytes
        self.overwrite = bool(overwrite)
        self.fsync = bool(fsync)
        self._disk_free = disk_free if disk_free is not None else _disk_free
        self._clock = clock if clock is not None else time.monotonic
        self._state = "new"  # new -> declaring -> recording -> closed; failed after an I/O error
        self._file: h5py.File | None = None
        self._streams: dict[str, _Stream] = {}
        self._sync: h5py.Group | None = None
        self._sync_ds: dict[str, h5py.Dataset] = {}
        self._releases_ds: h5py.Dataset | None = None
        self._events_ds: h5py.Dataset | None = None
        self._sync_rows = 0
        self._n_taps = 0
        self._releases = 0
        self._events = 0
        #: Told every event row appended, ``event_sink(time, kind, text)`` (the run's text log,
        #: :class:`~daq.recording.experiment_log.ExperimentLog`); None: no one.
        self.event_sink: Callable[[float, str, str], None] | None = None
        self._metadata_names: set[str] = set()
        self._deferred_attrs: dict[str, Any] = {}
        self._deferred_metadata: dict[str, Any] = {}
        self._last_flush = 0.0
        self._batch_depth = 0  # > 0 inside batch(): the appends leave the flush to its end
        #: Flushes done so far (periodic and explicit).
        self.flushes = 0

    # --------------------------------------------------------------------------------------------
    # Life cycle
    # --------------------------------------------------------------------------------------------
    @property
    def state(self) -> str:
        """Measure the phase: ``"new"``, ``"declaring"``, ``"recording"`` or ``"closed"``."""
        return self._state

    def open(self) -> None:
        """Create the file and its fixed groups; streams may then be declared.

        Raises
        ------
        InsufficientSpaceError
            The file system has less than ``min_free_bytes`` free (``errno`` ENOSPC).
        StorageError
            The directory is missing or not writable, the file exists (without ``overwrite``),
            or creating it failed (e.g. ENOSPC from the disk); ``errno`` says which.
        RecorderStateError
            The recorder was already opened.
        """
        self._require("open", "new")
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
            self._file = h5py.File(self.path, "w" if self.overwrite else "w-",
                                   libver=("v110", "latest"))
            self._write_skeleton(self._file)
            self._file.flush()  # write the superblock now: a full disk fails here, not later
        except OSError as exc:
            self._abandon()
            code = exc.errno if exc.errno is not None else errno.EIO
            raise StorageError(code, f"cannot create run file {self.path}: {os.strerror(code)}",
                               str(self.path)) from exc
        self._state = "declaring"

    def start(self, t0_host_ns: int | None = None) -> None:
        """End the declarations and switch the file to SWMR mode: appending may begin.

        Parameters
        ----------
        t0_host_ns : int, optional
            Host ``time.monotonic_ns()`` of the run start, ns: time 0 of ``/entry/sync/time``,
            releases and events. Default: now.
        """
        self._require("start", "declaring")
        if self._sync is None:
            raise RecorderStateError("declare the synchronised view (add_sync) before start(); "
                                     "no dataset can be created once the file is in SWMR mode")
        assert self._file is not None
        t0 = time.monotonic_ns() if t0_host_ns is None else int(t0_host_ns)
        self._sync.attrs["t0_host_ns"] = np.int64(t0)
        self._file["entry"].attrs["start_time"] = now_iso()
        with self._io("start SWMR mode"):
            self._file.swmr_mode = True
            self._file.flush()
        self._last_flush = self._clock()
        self._state = "recording"

    def flush(self) -> None:
        """Write everything appended so far to the file (and ``fsync`` it if configured).

        Raises
        ------
        InsufficientSpaceError
            Free space fell below ``reserve_bytes``: the file was flushed and closed (it is
            complete up to now) and the recorder is closed.
        StorageError
            The write failed (e.g. ENOSPC): the recorder is failed; only :meth:`close` remains.
        """
        if self._state not in ("declaring", "recording"):
            return
        assert self._file is not None
        with self._io("flush"):
            self._file.flush()
            if self.fsync:
                os.fsync(self._file.id.get_vfd_handle())
        self._last_flush = self._clock()
        self.flushes += 1
        if self._state == "recording" and self.reserve_bytes > 0:
            free = self._free_bytes(self.path.parent)
            if free < self.reserve_bytes:
                self.close()
                raise InsufficientSpaceError(
                    errno.ENOSPC, f"stopped recording to {self.path}: only {free / 2**20:.1f} "
                    f"MiB left on its file system, below the reserve of "
                    f"{self.reserve_bytes / 2**20:.1f} MiB; the file is closed and complete up "
                    "to now", str(self.path))

    def flush_if_due(self) -> bool:
        """Flush if the last flush is ``flush_interval_s`` old; return whether it flushed.

        The append methods call this; an idle writer thread (e.g. on a queue ``get`` timeout)
        calls it too, so that the last blocks reach the file within ``flush_interval_s``.
        """
        if self._state == "recording" and self._batch_depth == 0 and \
                self._clock() - self._last_flush >= self.flush_interval_s:
            self.flush()
            return True
        return False

    @contextmanager
    def batch(self) -> Iterator[None]:
        """Append several things as one: a flush due inside waits for the end (not on error).

        Else raw rows and the sync rows made from them could be split by a flush, and the sync
        rows would wait a whole interval more for the file (lost in a crash).
        """
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
        if self._state in ("new", "closed"):
            self._state = "closed"
            return
        assert self._file is not None
        file, self._file = self._file, None
        failed = self._state == "failed"
        self._state = "closed"
        if failed:
            # A write failed (the StorageError raised then said why). Closing, or merely freeing,
            # the HDF5 objects of such a file fails again in their finalisers, which print
            # tracebacks ("Exception ignored in ... __dealloc__"), and HDF5 crashes the process
            # at exit whatever is done here: keep them, for the life of the process.
            _abandoned.append([file, *self._handles()])
            self._drop_handles()
            return
        self._drop_handles()
        with self._io("close"):
            try:
                file.flush()
            finally:
                file.close()
            if self._deferred_attrs or self._deferred_metadata:
                # SWMR forbids new attributes and objects: write them now, without SWMR.
                with h5py.File(self.path, "r+", libver=("v110", "latest")) as again:
                    for name, value in self._deferred_attrs.items():
                        again["entry/sync"].attrs[name] = value
                    for name, value in self._deferred_metadata.items():
                        write_metadata(again["entry/metadata"], name, value)
        self._deferred_attrs.clear()
        self._deferred_metadata.clear()

    def __enter__(self) -> RunRecorder:
        if self._state == "new":
            self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --------------------------------------------------------------------------------------------
    # Declarations (before start)
    # --------------------------------------------------------------------------------------------
    def add_stream(self, device: str, channels: Sequence[str], units: str | Sequence[str],
                   rate_hz: float, value_dtype: str | np.dtype[Any] = "float32", *,
                   extra: Mapping[str, str | np.dtype[Any]] | None = None) -> None:
        """Declare a device's raw stream: ``/entry/instrument/<device>``.

        Parameters
        ----------
        device : str
            Instrument name (letters, digits, ``_``), e.g. ``"scanner"``, ``"laser_h"``.
        channels : sequence of str
            Names of the columns of ``value``, unique, at least one.
        units : str or sequence of str
            Units of ``value``: one for all channels, or one per channel (e.g. ``"Pa"``, ``"m"``).
        rate_hz : float
            Nominal sample rate, Hz (> 0).
        value_dtype : {"float32", "float64"}
            Storage type of ``value``: float32 where 7 digits suffice (scanner pressures),
            float64 otherwise (laser distances in m at sub-micrometre resolution).
        extra : mapping of str to dtype, optional
            Further per-sample 1-D columns (e.g. ``{"trigger_time": "float64",
            "error_code": "int32"}``), stored next to ``value`` and given to :meth:`append_raw`.
        """
        self._require("add_stream", "declaring")
        check_name(device, "device")
        if device in self._streams:
            raise ValueError(f"stream {device!r} is already declared")
        channels = list(channels)
        if not channels or not all(isinstance(c, str) and c for c in channels):
            raise ValueError(f"{device}: channels must be a non-empty list of names, "
                             f"got {channels!r}")
        if len(set(channels)) != len(channels):
            raise ValueError(f"{device}: channel names repeat: {channels!r}")
        unit_list = [units] * len(channels) if isinstance(units, str) else list(units)
        if len(unit_list) != len(channels) or not all(isinstance(u, str) for u in unit_list):
            raise ValueError(f"{device}: units must be one str or one per channel "
                             f"({len(channels)}), got {units!r}")
        if isinstance(rate_hz, bool) or not isinstance(rate_hz, (int, float)) \
                or not 0 < rate_hz < math.inf:
            raise ValueError(f"{device}: rate_hz = {rate_hz!r} must be a number > 0 Hz")
        dtype = np.dtype(value_dtype)
        if dtype not in VALUE_DTYPES:
            raise ValueError(f"{device}: value_dtype = {value_dtype!r}; allowed: float32, float64")
        extra_types: dict[str, np.dtype[Any]] = {}
        for name, kind in (extra or {}).items():
            check_name(name, f"{device}: extra column")
            if name in ("host_time_ns", "device_time", "counter", "value", "gaps"):
                raise ValueError(f"{device}: extra column {name!r} clashes with a standard one")
            extra_types[name] = np.dtype(kind)
            if extra_types[name] not in EXTRA_DTYPES:
                raise ValueError(f"{device}: extra column {name!r} has dtype {kind!r}; allowed: "
                                 f"{[str(t) for t in EXTRA_DTYPES]}")
        assert self._file is not None
        ds = create_stream(self._file["entry/instrument"], device, channels, unit_list, rate_hz,
                           dtype, extra_types, make_column=self._column)
        self._streams[device] = _Stream(ds, len(channels), dtype, extra_types)

    def add_sync(self, tap_names: Sequence[str], *,
                 pressure_dtype: str | np.dtype[Any] = "float32") -> None:
        """Declare the synchronised view ``/entry/sync`` (NXdata, plotted as h(time)).

        Parameters
        ----------
        tap_names : sequence of str
            Names of the pressure taps: the columns of ``pressure`` (may be empty).
        pressure_dtype : {"float32", "float64"}
            Storage type of ``pressure`` (float32: 7 digits, far below the scanner's noise).
        """
        self._require("add_sync", "declaring")
        if self._sync is not None:
            raise ValueError("the synchronised view is already declared")
        taps = list(tap_names)
        if not all(isinstance(t, str) for t in taps) or len(set(taps)) != len(taps):
            raise ValueError(f"tap_names must be unique str, got {taps!r}")
        p_dtype = np.dtype(pressure_dtype)
        if p_dtype not in VALUE_DTYPES:
            raise ValueError(f"pressure_dtype = {pressure_dtype!r}; allowed: float32, float64")
        assert self._file is not None
        sync, self._sync_ds = create_sync(self._file["entry"], taps, p_dtype,
                                          make_column=self._column, sway=self.sway)
        self._sync = sync
        self._n_taps = len(taps)

    def set_sync_attrs(self, *, clock_offset_s: Mapping[str, float] | None = None,
                       clock_drift_ppm: Mapping[str, float] | None = None,
                       residual_misalignment_s: float | None = None) -> None:
        """Record how each device's clock maps onto the run's time base.

        The convention of :class:`daq.sync.clock_map.ClockMap` and
        :class:`simulators.clock.DeviceClock`: ``device_time = clock_offset_s + (1 + 1e-6
        clock_drift_ppm) t``, ``t`` in s from run start (host clock). Stored as attributes of
        ``/entry/sync``: ``clock_offset_s__<device>``, ``clock_drift_ppm__<device>`` (named by
        :func:`daq.recording.layout.per_device_attr`) and
        ``residual_misalignment_s``. After :meth:`start` they are written at :meth:`close` (SWMR
        forbids new attributes); a later call replaces earlier values.

        Parameters
        ----------
        clock_offset_s : mapping of str to float, optional
            Per declared device: its device time at the run start, s.
        clock_drift_ppm : mapping of str to float, optional
            Per declared device: its clock rate against the host's, ppm (positive: runs fast).
        residual_misalignment_s : float, optional
            Misalignment left between the streams after the fit, s.
        """
        self._require("set_sync_attrs", "declaring", "recording")
        if self._sync is None:
            raise RecorderStateError("set_sync_attrs() needs the synchronised view: call "
                                     "add_sync() first")
        attrs: dict[str, float] = {}
        for label, mapping in (("clock_offset_s", clock_offset_s),
                               ("clock_drift_ppm", clock_drift_ppm)):
            for device, value in (mapping or {}).items():
                if device not in self._streams:
                    raise ValueError(f"{label}: no stream {device!r} declared; have "
                                     f"{sorted(self._streams)}")
                attrs[per_device_attr(label, device)] = _finite(value, f"{label} of {device}")
        if residual_misalignment_s is not None:
            attrs["residual_misalignment_s"] = _finite(residual_misalignment_s,
                                                     "residual_misalignment_s")
        if self._state == "declaring":
            self._sync.attrs.update(attrs)
        else:
            self._deferred_attrs.update(attrs)

    def add_metadata(self, name: str, value: Any) -> None:
        """Store a calibration or result under ``/entry/metadata/<name>``.

        Parameters
        ----------
        name : str
            Name (letters, digits, ``_``), e.g. ``"calz_scanner"``; each name once.
        value : scalar, str, array_like or mapping
            Numbers, strings and arrays become datasets; a mapping becomes a group (NXcollection)
            holding its items, recursively. After :meth:`start` it is written at :meth:`close`.
        """
        self._require("add_metadata", "declaring", "recording")
        check_name(name, "metadata name")
        if name in self._metadata_names:
            raise ValueError(f"metadata {name!r} was already added")
        validate_metadata(name, value)
        self._metadata_names.add(name)
        if self._state == "declaring":
            assert self._file is not None
            write_metadata(self._file["entry/metadata"], name, value)
        else:
            self._deferred_metadata[name] = value

    def add_calibrations(self, records: Mapping[str, tuple[Mapping[str, Any],
                                                           Mapping[str, str]]]) -> None:
        """Store calibrations: ``name -> (values, attrs)`` (:meth:`add_calibration` each)."""
        for name, (values, attrs) in records.items():
            self.add_calibration(name, values, attrs)

    def add_calibration(self, name: str, values: Mapping[str, Any],
                        attrs: Mapping[str, str]) -> None:
        """Store a calibration the run applies: ``/entry/calibration/<name>`` (before start).

        Parameters
        ----------
        name : str
            Name (letters, digits, ``_``), e.g. ``"pitot"``, ``"laser_front"``; each name once.
        values : mapping
            Its values (numbers, arrays, text), one dataset each (units in their names).
        attrs : mapping of str to str
            Group attributes: ``source``, ``date`` (ISO 8601) and ``configured``
            (docs/file_format.md, "Calibrations").
        """
        self._require("add_calibration", "declaring")
        check_name(name, "calibration name")
        assert self._file is not None
        entry = self._file["entry"]
        if "calibration" in entry and name in entry["calibration"]:
            raise ValueError(f"calibration {name!r} was already added")
        with self._io(f"writing calibration {name!r}"):
            parent = entry.require_group("calibration")
            parent.attrs["NX_class"] = "NXcollection"
            write_metadata(parent, name, dict(values))
            group = parent[name]
            group.attrs["NX_class"] = "NXcollection"
            for key, text in attrs.items():
                group.attrs[key] = str(text)

    # --------------------------------------------------------------------------------------------
    # Appending (after start)
    # --------------------------------------------------------------------------------------------
    def append_raw(self, device: str, host_time_ns: npt.ArrayLike,
                   device_time: npt.ArrayLike | None, counter: npt.ArrayLike,
                   values: npt.ArrayLike, *,
                   extra: Mapping[str, npt.ArrayLike] | None = None) -> None:
        """Append a block of raw samples to a declared stream.

        Parameters
        ----------
        device : str
            A stream declared with :meth:`add_stream`.
        host_time_ns : array_like of int, (n,)
            Host ``time.monotonic_ns()`` at arrival, ns.
        device_time : array_like of float, (n,), or None
            Device clock, s; None for a device without a clock (polled), stored as NaN.
        counter : array_like of int, (n,)
            Unwrapped sample counter.
        values : array_like of float, (n, channels)
            Samples, in the stream's units; (n,) is accepted for a one-channel stream.
        extra : mapping of str to array_like (n,), optional
            Exactly the extra columns declared with the stream.
        """
        self._require("append_raw", "recording")
        stream = self._stream(device)
        t_host = _integers(host_time_ns, f"{device} host_time_ns")
        n = t_host.shape[0]
        t_dev = (np.full(n, np.nan) if device_time is None
                 else _column_of(device_time, n, np.float64, f"{device} device_time"))
        count = _integers(counter, f"{device} counter")
        if count.shape != (n,):
            raise ValueError(f"{device}: counter has {count.shape[0]} rows, host_time_ns {n}")
        block = np.asarray(values, dtype=stream.dtype)
        if block.ndim == 1 and stream.n_channels == 1:
            block = block[:, None]
        if block.shape != (n, stream.n_channels):
            raise ValueError(f"{device}: values have shape {block.shape}, expected "
                             f"({n}, {stream.n_channels}) (rows, channels)")
        given = dict(extra or {})
        if set(given) != set(stream.extra):
            raise ValueError(f"{device}: extra columns {sorted(given)} differ from the declared "
                             f"{sorted(stream.extra)}")
        columns = {name: _column_of(given[name], n, kind, f"{device} {name}")
                   for name, kind in stream.extra.items()}
        if n == 0:
            return
        start = stream.rows
        with self._io(f"append to {device}"):
            ds = stream.datasets
            append_rows(ds["value"], start, block)
            for name, array in columns.items():
                append_rows(ds[name], start, array)
            append_rows(ds["device_time"], start, t_dev)
            append_rows(ds["host_time_ns"], start, t_host)
            append_rows(ds["counter"], start, count)
        stream.rows = start + n
        self.flush_if_due()

    def add_gap(self, device: str, after_counter: int, length: int) -> None:
        """Mark samples missing from a stream.

        Parameters
        ----------
        device : str
            A declared stream.
        after_counter : int
            Unwrapped counter of the last sample before the gap.
        length : int
            Number of missing samples (>= 1), or -1 when unknown (a device restart).
        """
        self._require("add_gap", "recording")
        stream = self._stream(device)
        if not (length == -1 or length >= 1):
            raise ValueError(f"{device}: gap length = {length!r} must be >= 1, or -1 (unknown)")
        row = np.array([(int(after_counter), int(length))], dtype=GAP_DTYPE)
        with self._io(f"add a gap to {device}"):
            append_rows(stream.datasets["gaps"], stream.gaps, row)
        stream.gaps += 1
        self.flush_if_due()

    def append_sync(self, time: npt.ArrayLike, *, h: npt.ArrayLike, alpha: npt.ArrayLike,
                    lift: npt.ArrayLike, moment: npt.ArrayLike, pressure: npt.ArrayLike,
                    U: npt.ArrayLike, rho: npt.ArrayLike, p: npt.ArrayLike | None = None,
                    drag: npt.ArrayLike | None = None) -> None:
        """Append rows to the synchronised view ``/entry/sync``.

        Parameters
        ----------
        time : array_like, (n,)
            Time from run start, s.
        h, alpha : array_like, (n,)
            Heave (m, positive downward) and pitch (rad, positive nose-up).
        lift, moment : array_like, (n,)
            Lift (N/m) and moment (N m/m) per unit span (NaN if not computed).
        pressure : array_like, (n, taps)
            Tap pressures, Pa.
        U, rho : array_like, (n,)
            Wind speed (m/s) and air density (kg/m^3).
        p, drag : array_like, (n,)
            Sway (m, positive downwind) and drag (N/m, positive downwind): required by a
            ``sway`` recorder, refused by a 2-DOF one.
        """
        self._require("append_sync", "recording")
        if (p is not None or drag is not None) != self.sway or (p is None) != (drag is None):
            raise ValueError("p and drag go together, and exactly into a 3-DOF run (sway="
                             f"{self.sway}); got p {'given' if p is not None else 'None'}, "
                             f"drag {'given' if drag is not None else 'None'}")
        t = _column_of(time, None, np.float64, "sync time")
        n = t.shape[0]
        cols = {"h": h, "alpha": alpha, "lift": lift, "moment": moment, "U": U, "rho": rho}
        if p is not None and drag is not None:  # a sway recorder's (checked above)
            cols.update(p=p, drag=drag)
        arrays = {name: _column_of(v, n, np.float64, f"sync {name}") for name, v in cols.items()}
        p = np.asarray(pressure, dtype=self._sync_ds["pressure"].dtype)
        if p.shape != (n, self._n_taps):
            raise ValueError(f"sync pressure has shape {p.shape}, expected ({n}, {self._n_taps}) "
                             "(rows, taps)")
        if n == 0:
            return
        start = self._sync_rows
        with self._io("append to sync"):
            append_rows(self._sync_ds["pressure"], start, p)
            for name, array in arrays.items():
                append_rows(self._sync_ds[name], start, array)
            append_rows(self._sync_ds["time"], start, t)
        self._sync_rows = start + n
        self.flush_if_due()

    def add_release(self, *, release_time: float, start_index: int, stop_index: int, U: float,
                    h0: float, alpha0: float, p0: float | None = None) -> int:
        """Append a release to ``/entry/releases`` and return its row number.

        Parameters
        ----------
        release_time : float
            Release instant, s from run start.
        start_index, stop_index : int
            Rows of ``/entry/sync`` of the free decay: ``start_index <= i < stop_index``.
        U : float
            Wind speed during the decay, m/s.
        h0, alpha0 : float
            Displacement held before the release, m and rad.
        p0 : float, optional
            Sway held before the release, m: a ``sway`` recorder's (NaN when not given); refused
            by a 2-DOF one.
        """
        self._require("add_release", "recording")
        if not 0 <= int(start_index) <= int(stop_index):
            raise ValueError(f"release rows start_index = {start_index}, stop_index = "
                             f"{stop_index}: need 0 <= start_index <= stop_index")
        if p0 is not None and not self.sway:
            raise ValueError("p0 goes into a 3-DOF run's releases only (RunRecorder(sway=True))")
        fields = (float(release_time), int(start_index), int(stop_index), float(U), float(h0),
                  float(alpha0))
        if self.sway:
            row = np.array([(*fields, math.nan if p0 is None else float(p0))],
                           dtype=RELEASE_DTYPE_SWAY)
        else:
            row = np.array([fields], dtype=RELEASE_DTYPE)
        assert self._releases_ds is not None
        with self._io("add a release"):
            append_rows(self._releases_ds, self._releases, row)
        self._releases += 1
        self.flush_if_due()
        return self._releases - 1

    def add_event(self, time: float, kind: str, text: str = "") -> None:
        """Append an operator or system marker to ``/entry/events``.

        Parameters
        ----------
        time : float
            s from run start.
        kind : str
            Short category, at most 32 UTF-8 bytes (``"operator"``, ``"release"``, ``"gap"``...).
        text : str
            Free text, at most 1024 UTF-8 bytes.
        """
        self._require("add_event", "declaring", "recording")
        kind_b = kind.encode("utf-8")
        text_b = text.encode("utf-8")
        if not kind_b or len(kind_b) > EVENT_KIND_BYTES:
            raise ValueError(f"event kind {kind!r} must be 1..{EVENT_KIND_BYTES} UTF-8 bytes")
        if len(text_b) > EVENT_TEXT_BYTES:
            raise ValueError(f"event text is {len(text_b)} UTF-8 bytes, at most "
                             f"{EVENT_TEXT_BYTES} fit (starts {text[:40]!r})")
        row = np.array([(float(time), kind_b, text_b)], dtype=EVENT_DTYPE)
        assert self._events_ds is not None
        with self._io("add an event"):
            append_rows(self._events_ds, self._events, row)
        self._events += 1
        if self.event_sink is not None:
            self.event_sink(float(time), kind, text)
        self.flush_if_due()

    # --------------------------------------------------------------------------------------------
    # Internals
    # --------------------------------------------------------------------------------------------
    def _require(self, what: str, *states: str) -> None:
        if self._state not in states:
            order = "open() -> add_stream()/add_sync() -> start() -> append -> close()"
            raise RecorderStateError(f"{what}() is not allowed while the recorder is "
                                     f"{self._state!r} (allowed: {', '.join(states)}); "
                                     f"call order: {order}")

    def _stream(self, device: str) -> _Stream:
        try:
            return self._streams[device]
        except KeyError:
            raise ValueError(f"no stream {device!r} declared; have "
                             f"{sorted(self._streams)}") from None

    def _free_bytes(self, directory: Path) -> int:
        try:
            return int(self._disk_free(directory))
        except OSError as exc:
            code = exc.errno if exc.errno is not None else errno.EIO
            raise StorageError(code, f"cannot check free space for {self.path}: {exc}",
                               str(self.path)) from exc

    def _write_skeleton(self, f: h5py.File) -> None:
        self._releases_ds, self._events_ds = write_skeleton(
            f, rig_name=self.rig_name, operator_notes=self.operator_notes,
            config_text=self.config_text, make_column=self._column, sway=self.sway)

    def _column(self, group: h5py.Group, name: str, dtype: np.dtype[Any],
                **options: Any) -> h5py.Dataset:
        """Create an empty dataset of rows with this recorder's chunking and compression."""
        return create_column(group, name, dtype, chunk_rows=self.chunk_rows,
                             compression=self.compression, **options)

    @contextmanager
    def _io(self, what: str) -> Iterator[None]:
        """Turn an HDF5 failure into a :class:`StorageError` and mark the recorder failed.

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
            if self._state != "closed":
                self._state = "failed"
            code = getattr(exc, "errno", None)
            if code is None:
                found = re.search(r"errno = (\d+)", str(exc))
                code = int(found.group(1)) if found else errno.EIO
            raise StorageError(code, f"run file {self.path}: cannot {what}: "
                               f"{os.strerror(code)}; the recording stopped, the file holds the "
                               "data up to the last flush", str(self.path)) from exc

    def _handles(self) -> list[Any]:
        """Return the open HDF5 objects of the file (datasets and groups)."""
        return [*(ds for stream in self._streams.values() for ds in stream.datasets.values()),
                *self._sync_ds.values(), self._sync, self._releases_ds, self._events_ds]

    def _drop_handles(self) -> None:
        for stream in self._streams.values():
            stream.datasets.clear()
        self._sync_ds.clear()
        self._releases_ds = self._events_ds = None

    def _abandon(self) -> None:
        """Close and delete a half-created file (its creation failed)."""
        self._drop_handles()
        if self._file is not None:
            try:
                self._file.close()
            except OSError:  # closing a half-created file: the create error is what matters
                pass
            self._file = None
        if self.path.is_file():  # never unlink a device such as /dev/full
            self.path.unlink(missing_ok=True)


# ------------------------------------------------------------------------------------------------
# Helpers
# ------------------------------------------------------------------------------------------------


_failed_writes = 0
#: HDF5 objects of the files whose write failed, never freed (:meth:`RunRecorder.close`).
_abandoned: list[list[Any]] = []


def failed_writes() -> int:
    """Count the run-file writes that failed in this process (each raised a StorageError).

    After one, h5py 3.16 / HDF5 2.0 crash the process (SIGSEGV) when it exits, whatever is
    closed first (h5py issue 914, a bug of the HDF5 library): a command line that has reported
    the error should then leave with ``os._exit`` (after flushing its output). The failed file's
    HDF5 objects are never freed for the same reason (:meth:`RunRecorder.close`).
    """
    return _failed_writes


def _integers(values: npt.ArrayLike, what: str) -> npt.NDArray[np.int64]:
    array = np.asarray(values)
    if array.ndim != 1:
        raise ValueError(f"{what} must be 1-D, got shape {array.shape}")
    if array.size and not np.issubdtype(array.dtype, np.integer):
        raise TypeError(f"{what} must be integers, got dtype {array.dtype}")
    return array.astype(np.int64, copy=False)


def _column_of(values: npt.ArrayLike, n: int | None, dtype: Any, what: str) -> npt.NDArray[Any]:
    array = np.asarray(values, dtype=dtype)
    if array.ndim != 1 or (n is not None and array.shape[0] != n):
        expected = "(n,)" if n is None else f"({n},)"
        raise ValueError(f"{what} has shape {array.shape}, expected {expected}")
    return array


def _finite(value: Any, what: str) -> float:
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"{what} = {value!r} must be finite")
    return x


