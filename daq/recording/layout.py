"""The run file's layout: names, types, fill values and attributes every run file has.

Responsibility: the contract of a windrig run file in code (``docs/reference/file_format.md``
describes it for readers): the compound row types of ``/entry/releases``, ``/entry/events`` and a
stream's ``gaps`` (:data:`RELEASE_DTYPE`, :data:`EVENT_DTYPE`, :data:`GAP_DTYPE`) and their rows
(:func:`release_table_row`, :func:`event_table_row`), the columns of
``/entry/sync`` with their units (:data:`SYNC_COLUMNS`), the clock model stated in its
attributes (:data:`CLOCK_MODEL`), the fill value an unwritten row reads as (:func:`fill_value`),
how datasets are chunked and compressed (:func:`create_column`), the fixed groups of a new file
(:func:`write_skeleton`), metadata entries (:func:`validate_metadata`, :func:`write_metadata`),
and :func:`read_sync`, which reads the synchronised view back from a closed, live or crashed
file.

Not responsible for: the writer (:mod:`daq.recording.recorder`), or the file's life cycle, SWMR,
flushing and its failures (:mod:`daq.recording.swmr_file`).

File layout
-----------
::

    /                      attrs windrig_version, created (ISO 8601 UTC), default="entry", creator
    /entry                 NXentry; default="sync", rig_name, operator_notes, start_time
    /entry/config          scalar UTF-8 string: the rig config TOML, verbatim
    /entry/instrument      NXinstrument
    /entry/instrument/<d>  NXdata (signal value, axes host_time_ns, channel); attrs channel_names,
                           units (one per channel), rate (Hz)
        host_time_ns  (n,)          int64    host time.monotonic_ns() at arrival, ns
        device_time   (n,)          float64  device clock, s (NaN: the device has none)
        counter       (n,)          int64    unwrapped sample counter
        value         (n, ch)       float32 or float64, units as the group's attrs
        gaps          (g,) compound (after_counter int64, length int64); length -1 = unknown
        <extra>       (n,)          optional per-sample columns declared with the stream
        channel       (ch,)         the channel names (value's second axis)
    /entry/sync            NXdata; signal="h", axes="time", time_indices=0, tap_names, t0_host_ns,
                           clock_model, clock_offset_s__<d>, clock_drift_ppm__<d>,
                           residual_misalignment_s
        time (s from run start), h (m), alpha (rad), lift (N/m), moment (N m/m), U (m/s),
        rho (kg/m^3): (n,) float64;  pressure (n, taps) float32 by default (Pa);
        a 3-DOF rig only: p (m), drag (N/m): (n,) float64
    /entry/releases        (r,) compound: release_time f8 (s), start_index i8, stop_index i8,
                           U f8 (m/s), h0 f8 (m), alpha0 f8 (rad), a 3-DOF rig's p0 f8 (m);
                           attrs field_names, units
    /entry/events          (e,) compound: time f8 (s), kind S32, text S1024 (UTF-8 bytes)
    /entry/metadata        NXparameters: CALZ results, the run's summary (``add_metadata``)
    /entry/calibration     NXparameters: one NXparameters group per calibration applied

Rows that never reached the file read as fill values no real row has: NaN in float columns and
fields, -1 in signed integer ones (``host_time_ns``, ``counter``, indices, ``error_code``), and a
gap row ``(-1, 0)`` (a real gap has a length >= 1 or -1). This matters after a failed write (a
full disk): HDF5 may then have recorded a dataset's new size but not the chunk holding the new
rows, which would otherwise read as plausible zeros (time 0 s, h 0 m).

Releases and events are compound datasets, not groups of 1-D datasets: under SWMR a row is then
appended as one unit (a live reader never sees a release whose ``U`` is missing), ``ds[:]`` gives
a NumPy structured array (``pandas.DataFrame(ds[:])`` works), ``ds["U"]`` reads one column, and
silx shows them as one table. Gaps, which one might expect among the stream's attributes, are a
dataset for the same SWMR reason (attributes cannot grow in SWMR mode).
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Callable, Mapping, Sequence
from datetime import UTC, datetime
from importlib.metadata import PackageNotFoundError, version
from typing import Any

import h5py
import numpy as np
import numpy.typing as npt

__all__ = ["CLOCK_MODEL", "EVENT_DTYPE", "EVENT_KIND_BYTES", "EVENT_TEXT_BYTES", "EXTRA_DTYPES",
           "EXTRA_UNITS", "GAP_DTYPE", "GAP_FILL", "GZIP_LEVEL", "MAX_CHUNK_BYTES", "NAME_PATTERN",
           "PER_DEVICE_SEPARATOR", "RELEASE_DTYPE", "RELEASE_DTYPE_SWAY", "RELEASE_UNITS",
           "STREAM_TABLES", "SWAY_COLUMNS", "SYNC_COLUMNS", "VALUE_DTYPES", "append_rows",
           "attach_dimension_scales", "check_name", "column_of", "create_column", "create_stream",
           "create_sync", "event_row", "event_table_row", "fill_value", "integer_column",
           "metadata_name_part", "now_iso", "open_run_file", "per_device_attr", "per_device_attrs",
           "read_sync", "release_table_row", "storable_metadata", "str_array", "validate_metadata",
           "windrig_version", "write_metadata", "write_skeleton"]

#: Row of ``/entry/instrument/<device>/gaps``.
GAP_DTYPE = np.dtype([("after_counter", "<i8"), ("length", "<i8")])


#: What an unwritten row of a ``gaps`` dataset reads as: no real gap has length 0.
GAP_FILL = np.array((-1, 0), dtype=GAP_DTYPE)


#: Row of ``/entry/releases`` (times in s from run start, indices into ``/entry/sync``).
RELEASE_DTYPE = np.dtype([("release_time", "<f8"), ("start_index", "<i8"), ("stop_index", "<i8"),
                          ("U", "<f8"), ("h0", "<f8"), ("alpha0", "<f8")])


RELEASE_UNITS = ("s", "", "", "m/s", "m", "rad")


#: Row of ``/entry/releases`` of a 3-DOF rig: the sway held before the release, ``p0`` (m), added.
RELEASE_DTYPE_SWAY = np.dtype(RELEASE_DTYPE.descr + [("p0", "<f8")])


#: Longest event kind and text, in UTF-8 bytes (fixed-length fields: SWMR appends must not use
#: variable-length data, HDF5 SWMR User's Guide).
EVENT_KIND_BYTES = 32


EVENT_TEXT_BYTES = 1024


#: Row of ``/entry/events``.
EVENT_DTYPE = np.dtype([("time", "<f8"),
                        ("kind", h5py.string_dtype("utf-8", EVENT_KIND_BYTES)),
                        ("text", h5py.string_dtype("utf-8", EVENT_TEXT_BYTES))])


#: Clock mapping stored in ``/entry/sync``'s attributes (that of
#: :class:`daq.sync.clock_map.ClockMap`).
CLOCK_MODEL = ("device_time = clock_offset_s__<device> + (1 + 1e-6 clock_drift_ppm__<device>) t, "
               "t in s from run start")


#: Separates a quantity from the device (or channel) it is for in an attribute name:
#: ``clock_offset_s__scanner``. Files before issue 17 used ``.``, which NeXus does not allow in
#: names; :func:`per_device_attrs` reads both.
PER_DEVICE_SEPARATOR = "__"


def per_device_attr(quantity: str, device: str) -> str:
    """Return the attribute name of ``quantity`` for one device or channel.

    >>> per_device_attr("clock_offset_s", "laser_front")
    'clock_offset_s__laser_front'
    """
    return f"{quantity}{PER_DEVICE_SEPARATOR}{device}"


def per_device_attrs(attrs: Mapping[str, Any], quantity: str) -> dict[str, float]:
    """Return ``{device: value}`` of the attributes :func:`per_device_attr` names.

    Reads the names of files before issue 17 too (``clock_offset_s.scanner``).

    >>> per_device_attrs({"clock_offset_s__scanner": 0.5, "clock_offset_s.laser": 0.25,
    ...                   "clock_model": "..."}, "clock_offset_s")
    {'scanner': 0.5, 'laser': 0.25}
    """
    out = {}
    for key, value in attrs.items():
        for sep in (PER_DEVICE_SEPARATOR, "."):
            if key.startswith(quantity + sep) and len(key) > len(quantity) + len(sep):
                out[key[len(quantity) + len(sep):]] = float(value)
    return out


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


#: Columns of ``/entry/sync`` of a rig with three degrees of freedom only (absent otherwise).
SWAY_COLUMNS: dict[str, tuple[str, str]] = {
    "p": ("m", "sway p (positive downwind)"),
    "drag": ("N/m", "drag per unit span (positive downwind)"),
}


#: Chunks are capped to this many bytes: HDF5 keeps each dataset's chunks in a cache of 1 MiB by
#: default (HDF5 1.x; 8 MiB in 2.0); a chunk being appended must stay in it, or every block
#: re-reads and re-compresses it. 512 KiB is also inside the 10 KiB - 1 MiB HDF5 recommends.
MAX_CHUNK_BYTES = 512 * 1024


#: gzip level: 1 compresses these streams within 2 % of level 4 and is 10 % faster (measured: see
#: tests/daq/recording/test_recorder.py, "Measurements").
GZIP_LEVEL = 1


NAME_PATTERN = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


VALUE_DTYPES = (np.dtype("float32"), np.dtype("float64"))


#: Datasets of a raw stream that are not one row per sample (the gaps table, the channel names).
STREAM_TABLES = ("gaps", "channel")


#: Units of the extra per-sample columns a stream may declare (any other is a count or a flag,
#: units "1").
EXTRA_UNITS = {"trigger_time": "s"}


EXTRA_DTYPES = tuple(np.dtype(t) for t in ("bool", "int8", "int16", "int32", "int64", "uint8",
                                            "uint16", "uint32", "float32", "float64"))


def windrig_version() -> str:
    """Return the installed windrig's version (``"unknown"`` from a bare source tree)."""
    try:
        return version("windrig")
    except PackageNotFoundError:  # running from a source tree that was never installed
        return "unknown"


def str_array(values: Sequence[str]) -> npt.NDArray[Any]:
    """Return strings as an array HDF5 stores as variable-length UTF-8."""
    return np.array(list(values), dtype=h5py.string_dtype())


def check_name(name: str, what: str) -> str:
    """Return ``name`` if it can be an HDF5 path component here (letters, digits, ``_``)."""
    if not isinstance(name, str) or not NAME_PATTERN.match(name):
        raise ValueError(f"{what} {name!r} must be a name of letters, digits and '_' "
                         "(not starting with a digit): it becomes an HDF5 path component")
    return name


def now_iso() -> str:
    """Return the UTC time now, ISO 8601 with microseconds."""
    return datetime.now(UTC).isoformat(timespec="microseconds")


def fill_value(dtype: np.dtype[Any]) -> Any:
    """Return what an unwritten row of ``dtype`` reads as: NaN, -1, or (None) HDF5's zero."""
    if dtype.names:
        row = np.zeros((), dtype=dtype)
        fields = dtype.fields
        assert fields is not None  # a structured dtype (it has names)
        for name in dtype.names:
            value = fill_value(fields[name][0])
            if value is not None:
                row[name] = value
        return row
    if dtype.kind == "f":
        return np.nan
    if dtype.kind == "i":
        return -1
    return None  # bool, unsigned, strings: HDF5's default (False, 0, empty)


def append_rows(ds: h5py.Dataset, start: int, rows: npt.NDArray[Any]) -> None:
    """Grow ``ds`` along its first axis and write ``rows`` from row ``start``."""
    ds.resize(start + rows.shape[0], axis=0)
    ds[start:start + rows.shape[0]] = rows


def integer_column(values: npt.ArrayLike, what: str) -> npt.NDArray[np.int64]:
    """Return ``values`` as a 1-D int64 column; raise unless 1-D integers (``what``: its name)."""
    array = np.asarray(values)
    if array.ndim != 1:
        raise ValueError(f"{what} must be 1-D, got shape {array.shape}")
    if array.size and not np.issubdtype(array.dtype, np.integer):
        raise TypeError(f"{what} must be integers, got dtype {array.dtype}")
    return array.astype(np.int64, copy=False)


def column_of(values: npt.ArrayLike, n: int | None, dtype: Any, what: str) -> npt.NDArray[Any]:
    """Return ``values`` as a 1-D column of ``dtype``; raise unless ``n`` rows (None: any)."""
    array = np.asarray(values, dtype=dtype)
    if array.ndim != 1 or (n is not None and array.shape[0] != n):
        expected = "(n,)" if n is None else f"({n},)"
        raise ValueError(f"{what} has shape {array.shape}, expected {expected}")
    return array


def release_table_row(release_time: float, start_index: int, stop_index: int, U: float,
                      h0: float, alpha0: float, p0: float | None, *,
                      sway: bool) -> npt.NDArray[Any]:
    """Return a row of ``/entry/releases``: :data:`RELEASE_DTYPE`, or :data:`RELEASE_DTYPE_SWAY`.

    The arguments are :meth:`daq.recording.recorder.RunRecorder.add_release`'s (checked there);
    with ``sway``, a ``p0`` of None is stored as NaN.
    """
    fields = (float(release_time), int(start_index), int(stop_index), float(U), float(h0),
              float(alpha0))
    if sway:
        return np.array([(*fields, math.nan if p0 is None else float(p0))],
                        dtype=RELEASE_DTYPE_SWAY)
    return np.array([fields], dtype=RELEASE_DTYPE)


def event_table_row(time: float, kind: str, text: str) -> npt.NDArray[Any]:
    """Return a row of ``/entry/events`` (:data:`EVENT_DTYPE`): time (s), kind and text.

    Raises
    ------
    ValueError
        ``kind`` is empty or longer than :data:`EVENT_KIND_BYTES` UTF-8 bytes, or ``text``
        longer than :data:`EVENT_TEXT_BYTES` (fixed-length fields).
    """
    kind_b = kind.encode("utf-8")
    text_b = text.encode("utf-8")
    if not kind_b or len(kind_b) > EVENT_KIND_BYTES:
        raise ValueError(f"event kind {kind!r} must be 1..{EVENT_KIND_BYTES} UTF-8 bytes")
    if len(text_b) > EVENT_TEXT_BYTES:
        raise ValueError(f"event text is {len(text_b)} UTF-8 bytes, at most "
                         f"{EVENT_TEXT_BYTES} fit (starts {text[:40]!r})")
    return np.array([(float(time), kind_b, text_b)], dtype=EVENT_DTYPE)


def validate_metadata(name: str, value: Any) -> None:
    """Raise unless ``value`` can be stored as metadata ``name`` (names, numbers, strings)."""
    if isinstance(value, Mapping):
        for key, item in value.items():
            check_name(key, f"metadata {name}: key")
            validate_metadata(f"{name}/{key}", item)
        return
    if isinstance(value, (str, bytes, bool, int, float, np.generic)):
        return
    array = np.asarray(value)
    if array.dtype.kind not in "biufU":
        raise TypeError(f"metadata {name}: cannot store {type(value).__name__} "
                        f"(dtype {array.dtype}); use numbers, strings, arrays or mappings")


def write_metadata(group: h5py.Group, name: str, value: Any) -> None:
    """Store ``value`` under ``group/name``: a dataset, or a group for a mapping."""
    if isinstance(value, Mapping):
        sub = group.create_group(name)
        sub.attrs["NX_class"] = "NXparameters"
        for key, item in value.items():
            write_metadata(sub, key, item)
    elif isinstance(value, str):
        group.create_dataset(name, data=value, dtype=h5py.string_dtype("utf-8"))
    else:
        array = np.asarray(value)
        if array.dtype.kind == "U":
            group.create_dataset(name, data=array.astype(object), dtype=h5py.string_dtype())
        else:
            group.create_dataset(name, data=array)


def open_run_file(path: str | os.PathLike[str]) -> h5py.File:
    """Open a run file read-only: as a plain reader, or as a SWMR reader if a writer has it.

    A file that a writer still has open, or left open by a crash, carries HDF5's "open for
    write" status flags and opens only as a SWMR reader. Any other file is opened plainly: a
    SWMR reader retries every metadata block whose checksum fails (it may be mid-write), with
    pauses, so a damaged closed file would take minutes to fail instead of failing at once.

    Raises
    ------
    OSError
        As ``h5py.File`` does (not HDF5, truncated, ...).
    """
    try:
        return h5py.File(path, "r")
    except OSError as exc:
        if "already open for write" not in str(exc):
            raise
    return h5py.File(path, "r", libver="latest", swmr=True)


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
        (m/s), ``rho`` (kg/m^3), each (n,); ``pressure`` (n, taps), Pa; a 3-DOF rig's file
        also ``p`` (m) and ``drag`` (N/m).
    """
    with h5py.File(path, "r", libver="latest", swmr=True) as f:
        sync = f["entry/sync"]
        datasets = {name: sync[name] for name in (*SYNC_COLUMNS, *SWAY_COLUMNS)
                    if name in SYNC_COLUMNS or name in sync}
        for ds in datasets.values():
            ds.refresh()
        n = min(ds.shape[0] for ds in datasets.values())
        return {name: ds[:n] for name, ds in datasets.items()}


def create_column(group: h5py.Group, name: str, dtype: np.dtype[Any], *, chunk_rows: int,
                  compression: str | None, width: int | None = None, units: str | None = None,
                  long_name: str | None = None, chunk: int | None = None,
                  fill: Any = None) -> h5py.Dataset:
    """Create an empty resizable, chunked (and compressed) dataset of rows.

    Chunks hold ``chunk`` rows, else at most ``chunk_rows`` and at most
    :data:`MAX_CHUNK_BYTES`; ``compression`` (``"gzip"``, ``"lzf"`` or None) applies with the
    shuffle filter to chunks of 1 KiB or more. Its fill value is ``fill``, else that of
    :func:`fill_value` (see the module docstring).
    """
    row_bytes = dtype.itemsize * (width or 1)
    rows = chunk or max(1, min(chunk_rows, MAX_CHUNK_BYTES // max(row_bytes, 1)))
    shape = (0,) if width is None else (0, width)
    chunks = (rows,) if width is None else (rows, max(width, 1))
    # A chunk dimension cannot exceed a fixed one: zero taps need an unlimited 2nd axis.
    maxshape = (None,) if width is None else (None, width if width else None)
    filters: dict[str, Any] = {}
    if compression is not None and row_bytes * rows >= 1024:
        filters = {"compression": compression, "shuffle": True}
        if compression == "gzip":
            filters["compression_opts"] = GZIP_LEVEL
    # Appends touch the last chunk or two: a cache of two chunks per dataset is all it
    # needs. HDF5 2.x gives each dataset 8 MiB by default, which ~40 datasets fill over
    # minutes (the run's memory then grows by ~300 MiB; benchmarks/daq_throughput.py).
    ds = group.create_dataset(name, shape=shape, maxshape=maxshape, chunks=chunks,
                              dtype=dtype, fillvalue=fill_value(dtype) if fill is None
                              else fill, rdcc_nbytes=2 * row_bytes * rows, rdcc_w0=1.0,
                              **filters)
    if units is not None:
        ds.attrs["units"] = units
    if long_name is not None:
        ds.attrs["long_name"] = long_name
    return ds


def write_skeleton(f: h5py.File, *, rig_name: str, operator_notes: str, config_text: str,
                   make_column: Callable[..., h5py.Dataset],
                   sway: bool = False) -> tuple[h5py.Dataset, h5py.Dataset]:
    """Write a new run file's root attributes and fixed groups; return releases and events.

    ``make_column(group, name, dtype, **options)`` creates a dataset as :func:`create_column`;
    ``sway``: a 3-DOF rig's file (releases with ``p0``, :data:`RELEASE_DTYPE_SWAY`).
    """
    f.attrs["windrig_version"] = windrig_version()
    f.attrs["created"] = now_iso()
    f.attrs["default"] = "entry"
    f.attrs["creator"] = f"windrig {windrig_version()} (daq.recording.recorder)"
    entry = f.create_group("entry")
    entry.attrs["NX_class"] = "NXentry"
    entry.attrs["default"] = "sync"
    entry.attrs["rig_name"] = rig_name
    entry.attrs["operator_notes"] = operator_notes
    config = entry.create_dataset("config", data=config_text,
                                  dtype=h5py.string_dtype("utf-8"))
    config.attrs["media_type"] = "application/toml"
    entry.create_group("instrument").attrs["NX_class"] = "NXinstrument"
    # NXparameters: named values, checked by validators like any base class (NXcollection's
    # members would each be a warning).
    entry.create_group("metadata").attrs["NX_class"] = "NXparameters"
    dtype = RELEASE_DTYPE_SWAY if sway else RELEASE_DTYPE
    releases = make_column(entry, "releases", dtype, chunk=64)
    releases.attrs["field_names"] = str_array(dtype.names or ())
    releases.attrs["units"] = str_array(RELEASE_UNITS + (("m",) if sway else ()))
    releases.attrs["description"] = ("one row per release; times in s from run start, "
                                     "start_index <= row < stop_index of /entry/sync")
    events = make_column(entry, "events", EVENT_DTYPE, chunk=64)
    events.attrs["description"] = "operator and system markers; time in s from run start"
    return releases, events


def create_stream(instrument: h5py.Group, device: str, channels: list[str], units: list[str],
                  rate_hz: float, dtype: np.dtype[Any], extra: Mapping[str, np.dtype[Any]], *,
                  make_column: Callable[..., h5py.Dataset]) -> dict[str, h5py.Dataset]:
    """Create ``/entry/instrument/<device>``: its attributes and its datasets (returned).

    ``make_column(group, name, dtype, **options)`` creates a dataset as :func:`create_column`.
    """
    group = instrument.create_group(device)
    # NXdata, plotted as value(host_time_ns, channel): NeXus validators accept a NXdata's own
    # fields and attributes (punx warns about every member of an NXcollection, nxcheck about
    # every field an NXlog does not define).
    group.attrs["NX_class"] = "NXdata"
    group.attrs["signal"] = "value"
    group.attrs["axes"] = str_array(["host_time_ns", "channel"])
    group.attrs["host_time_ns_indices"] = np.int32(0)
    group.attrs["channel_indices"] = np.int32(1)
    group.attrs["channel_names"] = str_array(channels)
    group.attrs["units"] = str_array(units)
    group.attrs["rate"] = float(rate_hz)
    group.attrs["rate_units"] = "Hz"
    ds = {
        "host_time_ns": make_column(group, "host_time_ns", np.dtype("int64"), units="ns",
                                    long_name="host time.monotonic_ns() at arrival"),
        "device_time": make_column(group, "device_time", np.dtype("float64"), units="s",
                                   long_name="device clock"),
        "counter": make_column(group, "counter", np.dtype("int64"), units="1",
                               long_name="unwrapped sample counter"),
        "value": make_column(group, "value", dtype, width=len(channels),
                             long_name=f"{device} samples"),
        "gaps": make_column(group, "gaps", GAP_DTYPE, chunk=256, fill=GAP_FILL),
    }
    if len(set(units)) == 1:
        ds["value"].attrs["units"] = units[0]
    ds["value"].attrs["channel_names"] = str_array(channels)
    ds["gaps"].attrs["description"] = (
        "samples missing from the stream: 'length' samples after the sample whose counter is "
        "'after_counter' (-1: unknown, e.g. a device restart)")
    ds["gaps"].attrs["units"] = "1"  # both fields count samples
    for name, kind in extra.items():
        ds[name] = make_column(group, name, kind, units=EXTRA_UNITS.get(name, "1"))
    # The channel names as a dataset too: the axis of value's second dimension (not a row
    # column: it is not returned, and never appended to).
    channel = group.create_dataset("channel", data=str_array(channels))
    channel.attrs["long_name"] = "channel name"
    return ds


def create_sync(entry: h5py.Group, taps: list[str], pressure_dtype: np.dtype[Any], *,
                make_column: Callable[..., h5py.Dataset], sway: bool = False,
                ) -> tuple[h5py.Group, dict[str, h5py.Dataset]]:
    """Create ``/entry/sync`` (NXdata, plotted as h(time)): its attributes and its columns.

    ``make_column(group, name, dtype, **options)`` creates a dataset as :func:`create_column`;
    ``sway``: a 3-DOF rig's view, with the :data:`SWAY_COLUMNS` too.
    """
    ds: dict[str, h5py.Dataset] = {}
    sync = entry.create_group("sync")
    sync.attrs["NX_class"] = "NXdata"
    sync.attrs["signal"] = "h"
    sync.attrs["axes"] = "time"
    sync.attrs["time_indices"] = np.int32(0)
    sync.attrs["tap_names"] = str_array(taps)
    sync.attrs["clock_model"] = CLOCK_MODEL
    for name, (units, long_name) in SYNC_COLUMNS.items():
        if name == "pressure":
            ds[name] = make_column(sync, name, pressure_dtype, width=len(taps), units=units,
                                   long_name=long_name)
        else:
            ds[name] = make_column(sync, name, np.dtype("float64"), units=units,
                                   long_name=long_name)
    for name, (units, long_name) in (SWAY_COLUMNS.items() if sway else ()):
        ds[name] = make_column(sync, name, np.dtype("float64"), units=units, long_name=long_name)
    attach_dimension_scales(sync, taps)
    return sync, ds


def attach_dimension_scales(sync: h5py.Group, taps: Sequence[str]) -> None:
    """Make ``time`` (and ``tap``, the tap names) the dimension scales of ``/entry/sync``.

    With them netCDF-4 readers (xarray with the h5netcdf engine) see ``time`` as the coordinate
    of every column and ``tap`` as the second of ``pressure``, instead of ``phony_dim_*``.
    Attaching writes attributes, so it happens before the file switches to SWMR mode.
    """
    time = sync["time"]
    time.make_scale("time")
    for name in (*SYNC_COLUMNS, *(n for n in SWAY_COLUMNS if n in sync)):
        if name != "time":
            sync[name].dims[0].attach_scale(time)
            sync[name].dims[0].label = "time"
    if len(taps):
        tap = sync.create_dataset("tap", data=str_array(taps))
        tap.attrs["long_name"] = "tap name"
        tap.make_scale("tap")
        sync["pressure"].dims[1].attach_scale(tap)
        sync["pressure"].dims[1].label = "tap"


def metadata_name_part(device: str) -> str:
    """Return a device name as part of a metadata name (letters, digits and ``_`` only)."""
    return re.sub(r"\W", "_", device)


def storable_metadata(value: Any) -> Any:
    """Make a summary storable as HDF5 metadata (names of letters, digits, _; no None)."""
    if isinstance(value, Mapping):
        return {"".join(c if c.isalnum() or c == "_" else "_" for c in str(k)): storable_metadata(v)
                for k, v in value.items()}
    if value is None:
        return ""
    if isinstance(value, list) and all(isinstance(v, str) for v in value):
        return np.array(value, dtype=str)  # strings even when empty (an empty list is float)
    return value


def event_row(kind: str, text: str, device: str | None, data: Mapping[str, Any]) -> tuple[str, str]:
    """Return an engine event's ``kind`` and ``text`` as ``/entry/events`` stores them.

    The text is prefixed with the device and followed by the event's scalar data as JSON
    (arrays are left out: they go to ``/entry/metadata``); both are cut to their fields'
    lengths (:data:`EVENT_KIND_BYTES`, :data:`EVENT_TEXT_BYTES`) on a UTF-8 character boundary.
    """
    text = text if device is None else f"{device}: {text}"
    scalars = {k: v for k, v in data.items() if not isinstance(v, np.ndarray)}
    if scalars:
        text = f"{text} {json.dumps(scalars, default=str)}"
    kind = kind.encode("utf-8")[:EVENT_KIND_BYTES].decode("utf-8", "ignore") or "event"
    return kind, text.encode("utf-8")[:EVENT_TEXT_BYTES].decode("utf-8", "ignore")
