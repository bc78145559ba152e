"""HDF5 writer of one run: raw device streams, the synchronised view, releases and events.

Responsible for: laying out one run file exactly as DESIGN.md, "HDF5 file" says (a contract that
tests, ``ident`` and outside readers such as silx rely on); appending blocks in place to chunked,
resizable datasets; switching the file to SWMR mode so that a live reader (the GUI, h5py in
another process, silx) can follow the run; flushing every ``flush_interval_s`` so that a crash
of the process loses at most that much (a power cut too, with ``fsync=True``); and failing
*at once*, with a specific error, when the file cannot be created or the disk is (nearly) full.

Not responsible for: acquisition, clock fitting, resampling or integrating pressures (the
acquisition engine computes every number written here), nor for threads: a :class:`RunRecorder`
is a subscriber fed through its methods, from one thread (the engine's writer thread). It never
touches acquisition threads' state and acquisition threads never touch h5py (STYLE.md, principle 4).

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

File layout (DESIGN.md, binding)
--------------------------------
::

    /                      attrs windrig_version, created (ISO 8601 UTC), default="entry", creator
    /entry                 NXentry; default="sync", rig_name, operator_notes, start_time
    /entry/config          scalar UTF-8 string: the rig config TOML, verbatim
    /entry/instrument      NXinstrument
    /entry/instrument/<d>  NXcollection; attrs channel_names, units (one per channel), rate (Hz)
        host_time_ns  (n,)          int64    host time.monotonic_ns() at arrival, ns
        device_time   (n,)          float64  device clock, s (NaN: the device has none)
        counter       (n,)          int64    unwrapped sample counter
        value         (n, ch)       float32 or float64, units as the group's attrs
        gaps          (g,) compound (after_counter int64, length int64); length -1 = unknown
        <extra>       (n,)          optional per-sample columns declared with the stream
    /entry/sync            NXdata; signal="h", axes="time", time_indices=0, tap_names, t0_host_ns,
                           clock_model, clock_offset_s.<d>, clock_drift_ppm.<d>,
                           residual_misalignment_s
        time (s from run start), h (m), alpha (rad), lift (N/m), moment (N m/m), U (m/s),
        rho (kg/m^3): (n,) float64;  pressure (n, taps) float32 by default (Pa)
    /entry/releases        (r,) compound: release_time f8 (s), start_index i8, stop_index i8,
                           U f8 (m/s), h0 f8 (m), alpha0 f8 (rad); attrs field_names, units
    /entry/events          (e,) compound: time f8 (s), kind S32, text S1024 (UTF-8 bytes)
    /entry/metadata        NXcollection: calibrations, CALZ results (:meth:`add_metadata`)

Rows that never reached the file read as fill values no real row has: NaN in float columns and
fields, -1 in signed integer ones (``host_time_ns``, ``counter``, indices, ``error_code``), and a
gap row ``(-1, 0)`` (a real gap has a length >= 1 or -1). This matters after a failed write (a
full disk): HDF5 may then have recorded a dataset's new size but not the chunk holding the new
rows, which would otherwise read as plausible zeros (time 0 s, h 0 m).

Releases and events are compound datasets, not groups of 1-D datasets: under SWMR a row is then
appended as one unit (a live reader never sees a release whose ``U`` is missing), ``ds[:]`` gives
a NumPy structured array (``pandas.DataFrame(ds[:])`` works), ``ds["U"]`` reads one column, and
silx shows them as one table. Gaps, which DESIGN.md lists among the stream's attributes, are a
dataset for the same SWMR reason (attributes cannot grow in SWMR mode).

A live reader opens with ``h5py.File(path, "r", libver="latest", swmr=True)`` and calls
``dataset.refresh()`` before reading a shape. The datasets of one group are resized one after the
other, so a live reader should read the shortest length over the datasets it combines
(:func:`read_sync` does). A file left behind by a crash keeps HDF5's "open for SWMR write" flag:
it opens read-only with ``swmr=True`` (as :func:`read_sync` does); a plain ``h5py.File(path)``
refuses it until ``h5clear -s`` clears the flag.
"""

from __future__ import annotations

import errno
import math
import os
import re
import shutil
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from datetime import UTC, datetime
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any, Protocol

import h5py
import numpy as np
import numpy.typing as npt

from daq.errors import DaqError

__all__ = [
    "CLOCK_MODEL",
    "EVENT_DTYPE",
    "GAP_DTYPE",
    "RELEASE_DTYPE",
    "SYNC_COLUMNS",
    "InsufficientSpaceError",
    "Recorder",
    "RecorderError",
    "RecorderStateError",
    "RunRecorder",
    "StorageError",
    "failed_writes",
    "read_sync",
]


class RecorderError(DaqError):
    """Base class of the errors of the run recorder."""


class StorageError(RecorderError, OSError):
    """The run file cannot be created or written (permissions, no such directory, disk full).

    ``errno`` is set (``EACCES``, ``ENOENT``, ``ENOSPC``, ...) and ``filename`` is the file.
    """


class InsufficientSpaceError(StorageError):
    """The file system of the run file has less free space than the configured minimum."""


class RecorderStateError(RecorderError, RuntimeError):
    """A method was called out of the order open -> declare -> start -> append -> close."""


#: Row of ``/entry/instrument/<device>/gaps``.
GAP_DTYPE = np.dtype([("after_counter", "<i8"), ("length", "<i8")])
#: What an unwritten row of a ``gaps`` dataset reads as: no real gap has length 0.
_GAP_FILL = np.array((-1, 0), dtype=GAP_DTYPE)
#: Row of ``/entry/releases`` (times in s from run start, indices into ``/entry/sync``).
RELEASE_DTYPE = np.dtype([("release_time", "<f8"), ("start_index", "<i8"), ("stop_index", "<i8"),
                          ("U", "<f8"), ("h0", "<f8"), ("alpha0", "<f8")])
_RELEASE_UNITS = ("s", "", "", "m/s", "m", "rad")
#: Longest event kind and text, in UTF-8 bytes (fixed-length fields: SWMR appends must not use
#: variable-length data, HDF5 SWMR User's Guide).
EVENT_KIND_BYTES = 32
EVENT_TEXT_BYTES = 1024
#: Row of ``/entry/events``.
EVENT_DTYPE = np.dtype([("time", "<f8"),
                        ("kind", h5py.string_dtype("utf-8", EVENT_KIND_BYTES)),
                        ("text", h5py.string_dtype("utf-8", EVENT_TEXT_BYTES))])

#: Clock mapping stored in ``/entry/sync``'s attributes (that of :class:`daq.sync.ClockMap`).
CLOCK_MODEL = ("device_time = clock_offset_s.<device> + (1 + 1e-6 clock_drift_ppm.<device>) t, "
               "t in s from run start")
#: Columns of ``/entry/sync``: name -> (units, long_name). ``pressure`` is (n, taps).
SYNC_COLUMNS: dict[str, tuple[str, str]] = {
    "time": ("s", "time from run start"),
    "h": ("m", "heave h (positive downward)"),
    "alpha": ("rad", "pitch alpha (positive nose-up)"),
    "lift": ("N/m", "lift per unit span (positive along h)"),
    "moment": ("N m/m", "moment per unit span (positive along alpha)"),
    "pressure": ("Pa", "tap pressures"),
    "U": ("m/s", "wind speed"),
    "rho": ("kg/m^3", "air density"),
}

#: Chunks are capped to this many bytes: HDF5 keeps each dataset's chunks in a cache of 1 MiB by
#: default (HDF5 1.x; 8 MiB in 2.0); a chunk being appended must stay in it, or every block
#: re-reads and re-compresses it. 512 KiB is also inside the 10 KiB - 1 MiB HDF5 recommends.
_MAX_CHUNK_BYTES = 512 * 1024
#: gzip level: 1 compresses these streams within 2 % of level 4 and is 10 % faster (measured: see
#: tests/daq/test_recorder.py, "Measurements").
_GZIP_LEVEL = 1
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_VALUE_DTYPES = (np.dtype("float32"), np.dtype("float64"))
_EXTRA_DTYPES = tuple(np.dtype(t) for t in ("bool", "int8", "int16", "int32", "int64", "uint8",
                                            "uint16", "uint32", "float32", "float64"))


def _windrig_version() -> str:
    try:
        return version("windrig")
    except PackageNotFoundError:  # running from a source tree that was never installed
        return "unknown"


def _disk_free(directory: Path) -> int:
    return shutil.disk_usage(directory).free


def _str_array(values: Sequence[str]) -> npt.NDArray[Any]:
    return np.array(list(values), dtype=h5py.string_dtype())


def _check_name(name: str, what: str) -> str:
    if not isinstance(name, str) or not _NAME.match(name):
        raise ValueError(f"{what} {name!r} must be a name of letters, digits and '_' "
                         "(not starting with a digit): it becomes an HDF5 path component")
    return name


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
    """What :class:`~daq.pipeline.RunWriter` writes a run into.

    :class:`RunRecorder` (a run file) and :class:`daq.live_source.RingRecorder` (the live
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
                    pressure: Any, U: Any, rho: Any) -> None:
        """Append rows of the synchronised view."""
        ...

    def add_gap(self, device: str, after_counter: int, length: int) -> None:
        """Mark a gap in a device's stream."""
        ...

    def add_event(self, time: float, kind: str, text: str = "") -> None:
        """Add an operator or system event."""
        ...

    def add_release(self, *, release_time: float, start_index: int, stop_index: int, U: float,
                    h0: float, alpha0: float) -> Any:
        """Add a free decay to the releases table."""
        ...

    def set_sync_attrs(self, *, clock_offset_s: Mapping[str, float] | None = None,
                       clock_drift_ppm: Mapping[str, float] | None = None,
                       residual_misalignment_s: float | None = None) -> None:
        """Store the clock fits with the synchronised view."""
        ...

    def add_metadata(self, name: str, value: Any) -> None:
        """Store a metadata entry."""
        ...


class RunRecorder:
    """Write one run to an HDF5 file laid out as DESIGN.md, "HDF5 file" (see module docstring).

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
        last flush is older than this; an idle writer thread calls :meth:`flush_if_due`.
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

    Notes
    -----
    Not thread-safe: call every method from one thread. The constructor does no I/O.
    """

    def __init__(self, path: str | os.PathLike[str], *, config_text: str, rig_name: str,
                 operator_notes: str = "", flush_interval_s: float = 1.0,
                 compression: str | None = "gzip", chunk_rows: int = 4096,
                 min_free_bytes: int = 1 << 30, reserve_bytes: int = 64 << 20,
                 overwrite: bool = False, fsync: bool = False,
                 disk_free: Callable[[Path], int] | None = None,
                 clock: Callable[[], float] | None = None) -> None:
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
        self._metadata_names: set[str] = set()
        self._deferred_attrs: dict[str, Any] = {}
        self._deferred_metadata: dict[str, Any] = {}
        self._last_flush = 0.0
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
        if self.path.exists() and not self.overwrite:
            raise StorageError(errno.EEXIST, f"run file {self.path} already exists; refusing to "
                               "overwrite a recorded run (pass overwrite=True to replace it)",
                               str(self.path))
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
        self._file["entry"].attrs["start_time"] = _now_iso()
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
        if self._state == "recording" and \
                self._clock() - self._last_flush >= self.flush_interval_s:
            self.flush()
            return True
        return False

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
                        _write_metadata(again["entry/metadata"], name, value)
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
        _check_name(device, "device")
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
        if dtype not in _VALUE_DTYPES:
            raise ValueError(f"{device}: value_dtype = {value_dtype!r}; allowed: float32, float64")
        extra_types: dict[str, np.dtype[Any]] = {}
        for name, kind in (extra or {}).items():
            _check_name(name, f"{device}: extra column")
            if name in ("host_time_ns", "device_time", "counter", "value", "gaps"):
                raise ValueError(f"{device}: extra column {name!r} clashes with a standard one")
            extra_types[name] = np.dtype(kind)
            if extra_types[name] not in _EXTRA_DTYPES:
                raise ValueError(f"{device}: extra column {name!r} has dtype {kind!r}; allowed: "
                                 f"{[str(t) for t in _EXTRA_DTYPES]}")
        assert self._file is not None
        group = self._file["entry/instrument"].create_group(device)
        group.attrs["NX_class"] = "NXcollection"
        group.attrs["channel_names"] = _str_array(channels)
        group.attrs["units"] = _str_array(unit_list)
        group.attrs["rate"] = float(rate_hz)
        group.attrs["rate_units"] = "Hz"
        ds = {
            "host_time_ns": self._column(group, "host_time_ns", np.dtype("int64"), units="ns",
                                         long_name="host time.monotonic_ns() at arrival"),
            "device_time": self._column(group, "device_time", np.dtype("float64"), units="s",
                                        long_name="device clock"),
            "counter": self._column(group, "counter", np.dtype("int64"),
                                    long_name="unwrapped sample counter"),
            "value": self._column(group, "value", dtype, width=len(channels),
                                  long_name=f"{device} samples"),
            "gaps": self._column(group, "gaps", GAP_DTYPE, chunk=256, fill=_GAP_FILL),
        }
        if len(set(unit_list)) == 1:
            ds["value"].attrs["units"] = unit_list[0]
        ds["value"].attrs["channel_names"] = _str_array(channels)
        ds["gaps"].attrs["description"] = (
            "samples missing from the stream: 'length' samples after the sample whose counter is "
            "'after_counter' (-1: unknown, e.g. a device restart)")
        for name, kind in extra_types.items():
            ds[name] = self._column(group, name, kind)
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
        if p_dtype not in _VALUE_DTYPES:
            raise ValueError(f"pressure_dtype = {pressure_dtype!r}; allowed: float32, float64")
        assert self._file is not None
        sync = self._file["entry"].create_group("sync")
        sync.attrs["NX_class"] = "NXdata"
        sync.attrs["signal"] = "h"
        sync.attrs["axes"] = "time"
        sync.attrs["time_indices"] = np.int32(0)
        sync.attrs["tap_names"] = _str_array(taps)
        sync.attrs["clock_model"] = CLOCK_MODEL
        for name, (units, long_name) in SYNC_COLUMNS.items():
            if name == "pressure":
                self._sync_ds[name] = self._column(sync, name, p_dtype, width=len(taps),
                                                   units=units, long_name=long_name)
            else:
                self._sync_ds[name] = self._column(sync, name, np.dtype("float64"), units=units,
                                                   long_name=long_name)
        self._sync = sync
        self._n_taps = len(taps)

    def set_sync_attrs(self, *, clock_offset_s: Mapping[str, float] | None = None,
                       clock_drift_ppm: Mapping[str, float] | None = None,
                       residual_misalignment_s: float | None = None) -> None:
        """Record how each device's clock maps onto the run's time base.

        The convention of :class:`daq.sync.ClockMap` and :class:`simulators.clock.DeviceClock`:
        ``device_time = clock_offset_s + (1 + 1e-6 clock_drift_ppm) t``, ``t`` in s from run
        start (host clock). Stored as attributes of ``/entry/sync``: ``clock_offset_s.<device>``,
        ``clock_drift_ppm.<device>`` and ``residual_misalignment_s``. After :meth:`start` they
        are written at :meth:`close` (SWMR forbids new attributes); a later call replaces
        earlier values.

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
                attrs[f"{label}.{device}"] = _finite(value, f"{label} of {device}")
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
        _check_name(name, "metadata name")
        if name in self._metadata_names:
            raise ValueError(f"metadata {name!r} was already added")
        _validate_metadata(name, value)
        self._metadata_names.add(name)
        if self._state == "declaring":
            assert self._file is not None
            _write_metadata(self._file["entry/metadata"], name, value)
        else:
            self._deferred_metadata[name] = value

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
            _append(ds["value"], start, block)
            for name, array in columns.items():
                _append(ds[name], start, array)
            _append(ds["device_time"], start, t_dev)
            _append(ds["host_time_ns"], start, t_host)
            _append(ds["counter"], start, count)
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
            _append(stream.datasets["gaps"], stream.gaps, row)
        stream.gaps += 1
        self.flush_if_due()

    def append_sync(self, time: npt.ArrayLike, *, h: npt.ArrayLike, alpha: npt.ArrayLike,
                    lift: npt.ArrayLike, moment: npt.ArrayLike, pressure: npt.ArrayLike,
                    U: npt.ArrayLike, rho: npt.ArrayLike) -> None:
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
        """
        self._require("append_sync", "recording")
        t = _column_of(time, None, np.float64, "sync time")
        n = t.shape[0]
        cols = {"h": h, "alpha": alpha, "lift": lift, "moment": moment, "U": U, "rho": rho}
        arrays = {name: _column_of(v, n, np.float64, f"sync {name}") for name, v in cols.items()}
        p = np.asarray(pressure, dtype=self._sync_ds["pressure"].dtype)
        if p.shape != (n, self._n_taps):
            raise ValueError(f"sync pressure has shape {p.shape}, expected ({n}, {self._n_taps}) "
                             "(rows, taps)")
        if n == 0:
            return
        start = self._sync_rows
        with self._io("append to sync"):
            _append(self._sync_ds["pressure"], start, p)
            for name, array in arrays.items():
                _append(self._sync_ds[name], start, array)
            _append(self._sync_ds["time"], start, t)
        self._sync_rows = start + n
        self.flush_if_due()

    def add_release(self, *, release_time: float, start_index: int, stop_index: int, U: float,
                    h0: float, alpha0: float) -> int:
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
        """
        self._require("add_release", "recording")
        if not 0 <= int(start_index) <= int(stop_index):
            raise ValueError(f"release rows start_index = {start_index}, stop_index = "
                             f"{stop_index}: need 0 <= start_index <= stop_index")
        row = np.array([(float(release_time), int(start_index), int(stop_index), float(U),
                         float(h0), float(alpha0))], dtype=RELEASE_DTYPE)
        assert self._releases_ds is not None
        with self._io("add a release"):
            _append(self._releases_ds, self._releases, row)
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
            _append(self._events_ds, self._events, row)
        self._events += 1
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
        f.attrs["windrig_version"] = _windrig_version()
        f.attrs["created"] = _now_iso()
        f.attrs["default"] = "entry"
        f.attrs["creator"] = f"windrig {_windrig_version()} (daq.recorder)"
        entry = f.create_group("entry")
        entry.attrs["NX_class"] = "NXentry"
        entry.attrs["default"] = "sync"
        entry.attrs["rig_name"] = self.rig_name
        entry.attrs["operator_notes"] = self.operator_notes
        config = entry.create_dataset("config", data=self.config_text,
                                      dtype=h5py.string_dtype("utf-8"))
        config.attrs["media_type"] = "application/toml"
        entry.create_group("instrument").attrs["NX_class"] = "NXinstrument"
        entry.create_group("metadata").attrs["NX_class"] = "NXcollection"
        self._releases_ds = releases = self._column(entry, "releases", RELEASE_DTYPE, chunk=64)
        releases.attrs["field_names"] = _str_array(RELEASE_DTYPE.names or ())
        releases.attrs["units"] = _str_array(_RELEASE_UNITS)
        releases.attrs["description"] = ("one row per release; times in s from run start, "
                                         "start_index <= row < stop_index of /entry/sync")
        self._events_ds = events = self._column(entry, "events", EVENT_DTYPE, chunk=64)
        events.attrs["description"] = "operator and system markers; time in s from run start"

    def _column(self, group: h5py.Group, name: str, dtype: np.dtype[Any], *,
                width: int | None = None, units: str | None = None,
                long_name: str | None = None, chunk: int | None = None,
                fill: Any = None) -> h5py.Dataset:
        """Create an empty resizable, chunked (and compressed) dataset of rows.

        Its fill value is ``fill``, else that of :func:`_fill_value` (see the module docstring).
        """
        row_bytes = dtype.itemsize * (width or 1)
        rows = chunk or max(1, min(self.chunk_rows, _MAX_CHUNK_BYTES // max(row_bytes, 1)))
        shape = (0,) if width is None else (0, width)
        chunks = (rows,) if width is None else (rows, max(width, 1))
        # A chunk dimension cannot exceed a fixed one: zero taps need an unlimited 2nd axis.
        maxshape = (None,) if width is None else (None, width if width else None)
        filters: dict[str, Any] = {}
        if self.compression is not None and row_bytes * rows >= 1024:
            filters = {"compression": self.compression, "shuffle": True}
            if self.compression == "gzip":
                filters["compression_opts"] = _GZIP_LEVEL
        # Appends touch the last chunk or two: a cache of two chunks per dataset is all it
        # needs. HDF5 2.x gives each dataset 8 MiB by default, which ~40 datasets fill over
        # minutes (the run's memory then grows by ~300 MiB; benchmarks/daq_throughput.py).
        ds = group.create_dataset(name, shape=shape, maxshape=maxshape, chunks=chunks,
                                  dtype=dtype, fillvalue=_fill_value(dtype) if fill is None
                                  else fill, rdcc_nbytes=2 * row_bytes * rows, rdcc_w0=1.0,
                                  **filters)
        if units is not None:
            ds.attrs["units"] = units
        if long_name is not None:
            ds.attrs["long_name"] = long_name
        return ds

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
def _now_iso() -> str:
    return datetime.now(UTC).isoformat(timespec="microseconds")


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


def _fill_value(dtype: np.dtype[Any]) -> Any:
    """Return what an unwritten row of ``dtype`` reads as: NaN, -1, or (None) HDF5's zero."""
    if dtype.names:
        row = np.zeros((), dtype=dtype)
        fields = dtype.fields
        assert fields is not None  # a structured dtype (it has names)
        for name in dtype.names:
            value = _fill_value(fields[name][0])
            if value is not None:
                row[name] = value
        return row
    if dtype.kind == "f":
        return np.nan
    if dtype.kind == "i":
        return -1
    return None  # bool, unsigned, strings: HDF5's default (False, 0, empty)


def _append(ds: h5py.Dataset, start: int, rows: npt.NDArray[Any]) -> None:
    ds.resize(start + rows.shape[0], axis=0)
    ds[start:start + rows.shape[0]] = rows


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


def _validate_metadata(name: str, value: Any) -> None:
    if isinstance(value, Mapping):
        for key, item in value.items():
            _check_name(key, f"metadata {name}: key")
            _validate_metadata(f"{name}/{key}", item)
        return
    if isinstance(value, (str, bytes, bool, int, float, np.generic)):
        return
    array = np.asarray(value)
    if array.dtype.kind not in "biufU":
        raise TypeError(f"metadata {name}: cannot store {type(value).__name__} "
                        f"(dtype {array.dtype}); use numbers, strings, arrays or mappings")


def _write_metadata(group: h5py.Group, name: str, value: Any) -> None:
    if isinstance(value, Mapping):
        sub = group.create_group(name)
        sub.attrs["NX_class"] = "NXcollection"
        for key, item in value.items():
            _write_metadata(sub, key, item)
    elif isinstance(value, str):
        group.create_dataset(name, data=value, dtype=h5py.string_dtype("utf-8"))
    else:
        array = np.asarray(value)
        if array.dtype.kind == "U":
            group.create_dataset(name, data=array.astype(object), dtype=h5py.string_dtype())
        else:
            group.create_dataset(name, data=array)


def read_sync(path: str | os.PathLike[str]) -> dict[str, npt.NDArray[Any]]:
    """Read ``/entry/sync`` of a run file into NumPy arrays.

    Works on a closed file, on one being written (SWMR) and on one left by a crash; rows not yet
    written to every column of a live file are left out.

    Parameters
    ----------
    path : str or Path
        A run file written by :class:`RunRecorder`.

    Returns
    -------
    dict of str to ndarray
        ``time`` (s), ``h`` (m), ``alpha`` (rad), ``lift`` (N/m), ``moment`` (N m/m), ``U``
        (m/s), ``rho`` (kg/m^3), each (n,); ``pressure`` (n, taps), Pa.
    """
    with h5py.File(path, "r", libver="latest", swmr=True) as f:
        sync = f["entry/sync"]
        datasets = {name: sync[name] for name in SYNC_COLUMNS}
        for ds in datasets.values():
            ds.refresh()
        n = min(ds.shape[0] for ds in datasets.values())
        return {name: ds[:n] for name, ds in datasets.items()}
