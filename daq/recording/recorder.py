"""HDF5 writer of one run: raw device streams, the synchronised view, releases and events.

Responsibility: :class:`RunRecorder`, which writes one run file in the layout of
:mod:`daq.recording.layout` (a contract that tests, ``ident`` and outside readers such as silx
rely on), appending blocks in place to chunked, resizable datasets. Its parts: the file's life
cycle under SWMR, its flushes and failures (:class:`~daq.recording.swmr_file.SwmrFile`: a live
reader can follow the run, a crash of the process loses at most ``flush_interval_s``, a file
that cannot be created or a (nearly) full disk fails *at once*, with a specific error); each
device's raw stream (:class:`~daq.recording.raw_streams.RawStream`); the synchronised view
(:class:`~daq.recording.sync_rows.SyncRows`); the releases and events tables, the metadata and
the calibrations, here.

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
:mod:`daq.recording.layout`'s, described for readers in ``docs/reference/file_format.md``; how a
live reader follows the file, and opens one left by a crash: :mod:`daq.recording.swmr_file`.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import numpy.typing as npt

from daq.errors import RecorderStateError
from daq.recording.layout import (
    append_rows,
    check_name,
    create_column,
    event_table_row,
    now_iso,
    release_table_row,
    validate_metadata,
    write_metadata,
    write_skeleton,
)
from daq.recording.raw_streams import RawStream
from daq.recording.swmr_file import SwmrFile
from daq.recording.sync_rows import SyncRows, clock_attrs

__all__ = ["RunRecorder"]


class RunRecorder:
    """Write one run to an HDF5 file laid out as docs/reference/file_format.md (module docstring).

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
        self._file = SwmrFile(
            self.path, flush_interval_s=self.flush_interval_s, min_free_bytes=min_free_bytes,
            reserve_bytes=reserve_bytes, overwrite=self.overwrite, fsync=self.fsync,
            disk_free=disk_free, clock=clock, release_handles=self._release_handles)
        self._streams: dict[str, RawStream] = {}
        self._sync: SyncRows | None = None
        self._releases_ds: h5py.Dataset | None = None
        self._events_ds: h5py.Dataset | None = None
        self._releases = 0
        self._events = 0
        #: Told every event row appended, ``event_sink(time, kind, text)`` (the run's text log,
        #: :class:`~daq.recording.experiment_log.ExperimentLog`); None: no one.
        self.event_sink: Callable[[float, str, str], None] | None = None
        self._metadata_names: set[str] = set()

    # --------------------------------------------------------------------------------------------
    # Life cycle (the file's: daq.recording.swmr_file)
    # --------------------------------------------------------------------------------------------
    @property
    def state(self) -> str:
        """Measure the phase: ``"new"``, ``"declaring"``, ``"recording"`` or ``"closed"``."""
        return self._file.state

    @property
    def flushes(self) -> int:
        """Count the flushes done so far (periodic and explicit)."""
        return self._file.flushes

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
        self._file.require("open", "new")
        self._file.create(self._write_skeleton)

    def start(self, t0_host_ns: int | None = None) -> None:
        """End the declarations and switch the file to SWMR mode: appending may begin.

        Parameters
        ----------
        t0_host_ns : int, optional
            Host ``time.monotonic_ns()`` of the run start, ns: time 0 of ``/entry/sync/time``,
            releases and events. Default: now.
        """
        self._file.require("start", "declaring")
        if self._sync is None:
            raise RecorderStateError("declare the synchronised view (add_sync) before start(); "
                                     "no dataset can be created once the file is in SWMR mode")
        assert self._file.h5 is not None
        t0 = time.monotonic_ns() if t0_host_ns is None else int(t0_host_ns)
        self._sync.group.attrs["t0_host_ns"] = np.int64(t0)
        self._file.h5["entry"].attrs["start_time"] = now_iso()
        self._file.start_swmr()

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
        self._file.flush()

    def flush_if_due(self) -> bool:
        """Flush if the last flush is ``flush_interval_s`` old; return whether it flushed.

        The append methods call this; an idle writer thread (e.g. on a queue ``get`` timeout)
        calls it too, so that the last blocks reach the file within ``flush_interval_s``.
        """
        return self._file.flush_if_due()

    @contextmanager
    def batch(self) -> Iterator[None]:
        """Append several things as one: a flush due inside waits for the end (not on error).

        Else raw rows and the sync rows made from them could be split by a flush, and the sync
        rows would wait a whole interval more for the file (lost in a crash).
        """
        with self._file.batch():
            yield

    def close(self) -> None:
        """Flush and close the file, then write what was deferred; idempotent.

        After this the file is a normal HDF5 file (the SWMR flag is cleared), unless a write had
        failed: then the file is left as it is (readable with SWMR up to its last flush) and its
        HDF5 objects are kept, never freed (see :func:`daq.recording.swmr_file.failed_writes`).
        """
        self._file.close()

    def __enter__(self) -> RunRecorder:
        if self.state == "new":
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
        self._file.require("add_stream", "declaring")
        check_name(device, "device")
        if device in self._streams:
            raise ValueError(f"stream {device!r} is already declared")
        assert self._file.h5 is not None
        self._streams[device] = RawStream.declare(
            self._file.h5["entry/instrument"], device, channels, units, rate_hz, value_dtype,
            extra, make_column=self._column)

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
        self._file.require("add_sync", "declaring")
        if self._sync is not None:
            raise ValueError("the synchronised view is already declared")
        assert self._file.h5 is not None
        self._sync = SyncRows.declare(self._file.h5["entry"], tap_names, pressure_dtype,
                                      make_column=self._column, sway=self.sway)

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
        self._file.require("set_sync_attrs", "declaring", "recording")
        if self._sync is None:
            raise RecorderStateError("set_sync_attrs() needs the synchronised view: call "
                                     "add_sync() first")
        attrs = clock_attrs(self._streams, clock_offset_s=clock_offset_s,
                            clock_drift_ppm=clock_drift_ppm,
                            residual_misalignment_s=residual_misalignment_s)
        if self.state == "declaring":
            self._sync.group.attrs.update(attrs)
        else:
            self._file.defer_attrs("entry/sync", attrs)

    def add_metadata(self, name: str, value: Any) -> None:
        """Store a calibration or result under ``/entry/metadata/<name>``.

        Parameters
        ----------
        name : str
            Name (letters, digits, ``_``), e.g. ``"calz_scanner"``; each name once.
        value : scalar, str, array_like or mapping
            Numbers, strings and arrays become datasets; a mapping becomes a group (NXparameters)
            holding its items, recursively. After :meth:`start` it is written at :meth:`close`.
        """
        self._file.require("add_metadata", "declaring", "recording")
        check_name(name, "metadata name")
        if name in self._metadata_names:
            raise ValueError(f"metadata {name!r} was already added")
        validate_metadata(name, value)
        self._metadata_names.add(name)
        if self.state == "declaring":
            assert self._file.h5 is not None
            write_metadata(self._file.h5["entry/metadata"], name, value)
        else:
            self._file.defer_metadata(name, value)

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
            (docs/reference/file_format.md, "Calibrations").
        """
        self._file.require("add_calibration", "declaring")
        check_name(name, "calibration name")
        assert self._file.h5 is not None
        entry = self._file.h5["entry"]
        if "calibration" in entry and name in entry["calibration"]:
            raise ValueError(f"calibration {name!r} was already added")
        with self._file.io(f"writing calibration {name!r}"):
            parent = entry.require_group("calibration")
            # NXparameters, not NXcollection: punx validates no member of an NXcollection and
            # warns on each one (14 WARN on a simulated run); files of issue 18 to 37 have
            # NXcollection here and read the same (readers go by name, not by class).
            parent.attrs["NX_class"] = "NXparameters"
            write_metadata(parent, name, dict(values))  # the group: NXparameters too
            for key, text in attrs.items():
                parent[name].attrs[key] = str(text)

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
        self._file.require("append_raw", "recording")
        stream = self._stream(device)
        rows = stream.check_block(host_time_ns, device_time, counter, values, extra)
        if rows is None:
            return
        with self._file.io(f"append to {device}"):
            stream.append(rows)
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
        self._file.require("add_gap", "recording")
        stream = self._stream(device)
        row = stream.check_gap(after_counter, length)
        with self._file.io(f"add a gap to {device}"):
            stream.append_gap(row)
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
        self._file.require("append_sync", "recording")
        assert self._sync is not None  # start() requires it
        rows = self._sync.check_block(time, h=h, alpha=alpha, lift=lift, moment=moment,
                                      pressure=pressure, U=U, rho=rho, p=p, drag=drag)
        if rows is None:
            return
        with self._file.io("append to sync"):
            self._sync.append(rows)
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
        self._file.require("add_release", "recording")
        if not 0 <= int(start_index) <= int(stop_index):
            raise ValueError(f"release rows start_index = {start_index}, stop_index = "
                             f"{stop_index}: need 0 <= start_index <= stop_index")
        if p0 is not None and not self.sway:
            raise ValueError("p0 goes into a 3-DOF run's releases only (RunRecorder(sway=True))")
        row = release_table_row(release_time, start_index, stop_index, U, h0, alpha0, p0,
                                sway=self.sway)
        assert self._releases_ds is not None
        with self._file.io("add a release"):
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
        self._file.require("add_event", "declaring", "recording")
        row = event_table_row(time, kind, text)
        assert self._events_ds is not None
        with self._file.io("add an event"):
            append_rows(self._events_ds, self._events, row)
        self._events += 1
        if self.event_sink is not None:
            self.event_sink(float(time), kind, text)
        self.flush_if_due()

    # --------------------------------------------------------------------------------------------
    # Internals
    # --------------------------------------------------------------------------------------------
    def _stream(self, device: str) -> RawStream:
        try:
            return self._streams[device]
        except KeyError:
            raise ValueError(f"no stream {device!r} declared; have "
                             f"{sorted(self._streams)}") from None

    def _write_skeleton(self, f: h5py.File) -> None:
        self._releases_ds, self._events_ds = write_skeleton(
            f, rig_name=self.rig_name, operator_notes=self.operator_notes,
            config_text=self.config_text, make_column=self._column, sway=self.sway)

    def _column(self, group: h5py.Group, name: str, dtype: np.dtype[Any],
                **options: Any) -> h5py.Dataset:
        """Create an empty dataset of rows with this recorder's chunking and compression."""
        return create_column(group, name, dtype, chunk_rows=self.chunk_rows,
                             compression=self.compression, **options)

    def _release_handles(self) -> list[Any]:
        """Return the open HDF5 objects of the file (datasets and groups) and forget them."""
        sync = self._sync
        handles = [*(ds for stream in self._streams.values() for ds in stream.datasets.values()),
                   *(sync.datasets.values() if sync is not None else ()),
                   sync.group if sync is not None else None, self._releases_ds, self._events_ds]
        for stream in self._streams.values():
            stream.datasets.clear()
        if sync is not None:
            sync.datasets.clear()
        self._releases_ds = self._events_ds = None
        return handles
