"""What a run file holds for other programs, read once for ``windrig export``.

Responsibility: read, once, what a run file holds for other programs into
:class:`RunContents`: the synchronised view (``/entry/sync``: every column with its units and
long name, ``pressure`` with its tap names), the releases (``/entry/releases``, with units),
the events (``/entry/events``), the calibrations the run applied (``/entry/calibration``, each
with its ``source``, ``date`` and ``configured``), the rig config's text and the run's own
attributes (:func:`read_contents`).

A file needs only ``/entry/sync`` (with ``time``) to be exported: the releases, events,
calibrations and config it lacks are left out, each with a warning that says so (the smallest
run file of ``docs/reference/file_format.md`` has no events and no calibrations). A file being
written (SWMR) or left by a crash is read as far as every column of the sync view goes.

Not responsible for: the formats (:mod:`daq.exchange.export_writers`), the command
(:mod:`daq.exchange.export_run`), the run file's layout (:mod:`daq.recording.layout`,
``docs/reference/file_format.md``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import numpy.typing as npt

from daq.errors import NotARunFileError
from daq.recording.layout import RELEASE_UNITS, SWAY_COLUMNS, SYNC_COLUMNS, open_run_file

__all__ = ["RELEASE_MEANINGS", "Column", "RunContents", "read_contents"]

#: Units of the releases' fields when a file does not state them (its ``units`` attribute).
_RELEASE_UNITS = dict(zip(("release_time", "start_index", "stop_index", "U", "h0", "alpha0"),
                          RELEASE_UNITS, strict=True)) | {"p0": "m"}
#: What each field of a release row means (index fields: 0-based rows of the sync view).
RELEASE_MEANINGS = {
    "release_time": "release instant, s from the run start",
    "start_index": "first row of the sync view in the free decay (0-based)",
    "stop_index": "one past the decay's last row of the sync view (0-based)",
    "U": "median wind speed over the decay", "h0": "heave held before the release",
    "alpha0": "pitch held before the release", "p0": "sway held before the release"}
#: Attributes of ``/`` and ``/entry`` carried into every export (text).
_RUN_ATTRS = ("windrig_version", "created", "creator", "rig_name", "operator_notes",
              "start_time", "recovered")


@dataclass(frozen=True)
class Column:
    """One dataset of the sync view.

    Attributes
    ----------
    name : str
        Its name in ``/entry/sync`` (``h``, ``pressure``, ...).
    values : ndarray
        (n,) or, for ``pressure``, (n, taps); the file's own dtype (float64, or float32).
    units : str
        As the file states them (``""``: the file gives none).
    long_name : str
        As the file states it (``""``: none).
    """

    name: str
    values: npt.NDArray[Any]
    units: str
    long_name: str


@dataclass
class RunContents:
    """What a run file holds for other programs (:func:`read_contents`).

    Attributes
    ----------
    source : Path
        The run file.
    columns : list of Column
        The sync view, ``time`` first, then the file's order; 2-D ones (``pressure``) too.
    taps : list of str
        The names of ``pressure``'s columns (``tap000``, ...; empty without taps).
    releases : ndarray
        Structured, one row per release (the file's fields; empty without releases).
    release_units : dict of str to str
        Units per release field (``""`` for the indices).
    events : dict of str to ndarray
        ``time`` (float64, s), ``kind`` and ``text`` (str objects).
    calibrations : dict of str to dict
        Per calibration: ``values`` (name -> ndarray or str, SI units in the names) and
        ``attrs`` (``source``, ``date``, ``configured``).
    config_text : str
        The rig config's TOML, verbatim (``""``: the file has none).
    attrs : dict of str to str
        The run's attributes (``rig_name``, ``created``, ``windrig_version``, ...).
    warnings : list of str
        What the file lacks (left out of the export), one sentence each.
    """

    source: Path
    columns: list[Column]
    taps: list[str]
    releases: npt.NDArray[Any]
    release_units: dict[str, str]
    events: dict[str, npt.NDArray[Any]]
    calibrations: dict[str, dict[str, dict[str, Any]]]
    config_text: str
    attrs: dict[str, str]
    warnings: list[str] = field(default_factory=list)

    @property
    def n_rows(self) -> int:
        """Count the rows of the sync view."""
        return int(self.columns[0].values.shape[0])


def _text(value: Any) -> str:
    if isinstance(value, bytes):
        return value.decode("utf-8", errors="replace")
    if isinstance(value, np.ndarray) and value.shape == ():
        return _text(value[()])
    return str(value)


def _value(ds: h5py.Dataset) -> Any:
    """Return a calibration's dataset: a str (text) or an ndarray (numbers, bools, strings)."""
    data = ds[()]
    if isinstance(data, bytes | str):
        return _text(data)
    array = np.asarray(data)
    if array.dtype.kind in "OS":
        return np.array([_text(v) for v in array.ravel()], dtype=object).reshape(array.shape)
    return array


def read_contents(path: str | os.PathLike[str]) -> RunContents:
    """Read what a run file holds for export.

    Parameters
    ----------
    path : path-like
        A windrig run file (closed, being written, or left by a crash).

    Returns
    -------
    RunContents

    Raises
    ------
    NotARunFileError
        Missing, a directory, not HDF5, or no ``/entry/sync/time``: nothing to export.
    """
    path = Path(path)
    if not path.exists():
        raise NotARunFileError(f"{path}: no such file")
    if path.is_dir():
        raise NotARunFileError(f"{path}: a directory, not a run file")
    try:
        handle = open_run_file(path)
    except OSError as exc:
        raise NotARunFileError(f"{path}: not an HDF5 run file (or a damaged one): {exc}") \
            from exc
    with handle as f:
        if "entry/sync/time" not in f:
            raise NotARunFileError(f"{path}: has no /entry/sync/time: not a windrig run file, "
                                   "nothing to export (docs/reference/file_format.md: the "
                                   "smallest run file)")
        warnings: list[str] = []
        columns, taps = _sync_columns(f["entry/sync"], path, warnings)
        releases, units = _releases(f, path, warnings)
        events = _events(f, path, warnings)
        calibrations = _calibrations(f)
        config_text = _text(f["entry/config"][()]) if "entry/config" in f else ""
        if not config_text:
            warnings.append(f"{path} has no /entry/config: exported without the rig config")
        attrs = {k: _text(v) for k, v in f.attrs.items() if k in _RUN_ATTRS}
        if "entry" in f:
            attrs.update({k: _text(v) for k, v in f["entry"].attrs.items() if k in _RUN_ATTRS})
    return RunContents(source=path, columns=columns, taps=taps, releases=releases,
                       release_units=units, events=events, calibrations=calibrations,
                       config_text=config_text, attrs=attrs, warnings=warnings)


def _sync_columns(sync: h5py.Group, path: Path,
                  warnings: list[str]) -> tuple[list[Column], list[str]]:
    """Return the sync view's datasets on ``time``, cut to the rows all of them hold."""
    datasets = {name: ds for name, ds in sync.items() if isinstance(ds, h5py.Dataset)
                and name != "tap" and ds.ndim in (1, 2) and ds.dtype.kind in "fiub"}
    for ds in datasets.values():
        if ds.id.get_create_plist().get_layout() == h5py.h5d.CHUNKED:
            ds.refresh()  # a file being written grows; rows not in every column are left out
    n = min(ds.shape[0] for ds in datasets.values())
    # Rows sized but never written (a crash: docs/reference/file_format.md, fill values) read as NaN
    # times at the end; they are no data, and windrig info does not count them either.
    finite = np.flatnonzero(np.isfinite(datasets["time"][:n]))
    written = int(finite[-1]) + 1 if finite.size else 0
    if written < n:
        warnings.append(f"{path}: the last {n - written} row(s) of /entry/sync were sized but "
                        "never written (a crash?): not exported")
        n = written
    others = sorted(set(sync) - set(datasets) - {"tap"})
    if others:
        warnings.append(f"{path}: /entry/sync/{', '.join(others)} not exported (not a column "
                        "of numbers on time)")
    known = [name for name in (*SYNC_COLUMNS, *SWAY_COLUMNS) if name in datasets]
    order = [*known, *sorted(set(datasets) - set(known))]  # the file format's order first
    columns = [Column(name, np.asarray(datasets[name][:n]),
                      _text(datasets[name].attrs.get("units", "")),
                      _text(datasets[name].attrs.get("long_name", ""))) for name in order]
    taps: list[str] = []
    if "tap" in sync:
        taps = [_text(v) for v in sync["tap"][()]]
    elif "tap_names" in sync.attrs:
        taps = [_text(v) for v in np.atleast_1d(sync.attrs["tap_names"])]
    for c in columns:
        if c.values.ndim == 2 and c.values.shape[1] != len(taps):
            taps = [f"{c.name}{i:03d}" for i in range(c.values.shape[1])]
            warnings.append(f"{path}: /entry/sync/{c.name} has {c.values.shape[1]} columns "
                            f"and no names for them: named {taps[0]}...")
    return columns, taps


def _releases(f: h5py.File, path: Path,
              warnings: list[str]) -> tuple[npt.NDArray[Any], dict[str, str]]:
    if "entry/releases" not in f:
        warnings.append(f"{path} has no /entry/releases: exported without releases")
        return np.zeros(0, dtype=[("release_time", "<f8")]), {"release_time": "s"}
    ds = f["entry/releases"]
    if ds.id.get_create_plist().get_layout() == h5py.h5d.CHUNKED:
        ds.refresh()
    table = np.asarray(ds[()])
    names = [_text(v) for v in np.atleast_1d(ds.attrs.get("field_names", []))]
    stated = [_text(v) for v in np.atleast_1d(ds.attrs.get("units", []))]
    units = dict(zip(names, stated, strict=False)) if len(names) == len(stated) else {}
    fields = table.dtype.names or ()
    return table, {name: units.get(name, _RELEASE_UNITS.get(name, "")) for name in fields}


def _events(f: h5py.File, path: Path, warnings: list[str]) -> dict[str, npt.NDArray[Any]]:
    if "entry/events" not in f:
        warnings.append(f"{path} has no /entry/events: exported without events")
        rows = np.zeros(0, dtype=[("time", "<f8"), ("kind", "S1"), ("text", "S1")])
    else:
        ds = f["entry/events"]
        if ds.id.get_create_plist().get_layout() == h5py.h5d.CHUNKED:
            ds.refresh()
        rows = np.asarray(ds[()])
    return {"time": np.asarray(rows["time"], dtype=np.float64),
            "kind": np.array([_text(k) for k in rows["kind"]], dtype=object),
            "text": np.array([_text(t) for t in rows["text"]], dtype=object)}


def _calibrations(f: h5py.File) -> dict[str, dict[str, dict[str, Any]]]:
    """Each calibration group (NXparameters, or NXcollection before issue 37): values, attrs."""
    if "entry/calibration" not in f:
        return {}  # older files: the defaults (docs/reference/file_format.md); not a mistake
    out = {}
    for name, group in f["entry/calibration"].items():
        if not isinstance(group, h5py.Group):
            continue
        out[name] = {"values": {k: _value(ds) for k, ds in group.items()
                                if isinstance(ds, h5py.Dataset)},
                     "attrs": {k: _text(v) for k, v in group.attrs.items() if k != "NX_class"}}
    return out
