"""A lab's files read into tables of columns and properties: CSV, MATLAB v5 and v7.3, TDMS.

Responsibility: :func:`read_source` reads one file into one :class:`SourceTable` per test (a
TDMS file: one per group that holds channels; CSV and MATLAB: one per file), each with its
columns (1-D float arrays by name), the properties the map may read numbers from
(:meth:`SourceTable.property`) and, for TDMS waveforms, each channel's ``wf_increment``. The
readers are the well-kept libraries: the standard :mod:`csv` module, :func:`scipy.io.loadmat`
for MATLAB v5 files, h5py for v7.3 files (HDF5 underneath, arrays stored transposed, text as
uint16 with ``MATLAB_class = "char"``) and npTDMS, which applies the DAQmx scales LabVIEW
stores with a channel (``NI_Scale[n]_...``), so a scaled channel arrives in its scaled unit.

CSV: the first row that is not a comment (``#``) is the header; the delimiter is found by
:class:`csv.Sniffer` among ``, ; tab``; with ``;`` or tab a decimal comma is read as a point.
An empty cell is NaN (a gap). MATLAB: a numeric vector (1 x n or n x 1) is a column, a scalar
or a char array a property; a struct's fields are reached by dotted names (``test.h``).

Not responsible for: what the columns mean (:mod:`daq.exchange.importing` applies the map).
"""

from __future__ import annotations

import csv
import fnmatch
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import numpy.typing as npt
from scipy.io import loadmat
from scipy.io.matlab import MatReadError

from daq.errors import UsageError
from daq.exchange.import_map import FORMATS

__all__ = ["SourceTable", "read_source", "source_format"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class SourceTable:
    """One test of a source file: its columns and properties.

    Attributes
    ----------
    name : str
        ``file`` or ``file:group`` (TDMS), for messages and per-source values.
    path : Path
        The file.
    columns : mapping of str to ndarray
        Each column's samples, float64.
    properties : mapping of str to mapping
        ``""`` the table's own (TDMS: the group's, then the file's; MATLAB: the scalars and
        strings), and per column its own (TDMS channel properties).
    increments : mapping of str to float
        TDMS waveforms: each column's ``wf_increment``, s.
    """

    name: str
    path: Path
    columns: Mapping[str, FloatArray]
    properties: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    increments: Mapping[str, float] = field(default_factory=dict)

    def column(self, name: str, where: str) -> FloatArray:
        """Return a column, or raise UsageError naming the source, the key and the columns."""
        if name not in self.columns:
            have = ", ".join(sorted(self.columns)[:20])
            raise UsageError(f"{self.name}: no column {name!r} ({where}); it has: {have}")
        return self.columns[name]

    def property(self, name: str, of: str | None, where: str) -> Any:
        """Return a property: the column ``of``'s own, else the table's (group, then file)."""
        scopes = ([of] if of is not None else []) + [""]
        for scope in scopes:
            if scope and scope not in self.columns:
                raise UsageError(f"{self.name}: no column {scope!r} to read property {name!r} "
                                 f"of ({where})")
            props = self.properties.get(scope, {})
            if name in props:
                return props[name]
        have = sorted({k for s in scopes for k in self.properties.get(s, {})})[:20]
        raise UsageError(f"{self.name}: no property {name!r} ({where}); it has: "
                         f"{', '.join(have) or 'none'}")


def source_format(path: Path, declared: str | None) -> str:
    """Return the format of a source: the map's ``format``, else the file's extension."""
    if declared is not None:
        return declared
    ext = path.suffix.lower().lstrip(".")
    if ext not in FORMATS:
        raise UsageError(f"{path}: cannot tell the format from the extension {path.suffix!r}; "
                         f"known: {sorted(FORMATS)}, or set format in the map")
    return FORMATS[ext]


def read_source(path: Path, fmt: str, groups: tuple[str, ...] = ()) -> list[SourceTable]:
    """Read one source file into its tests.

    Parameters
    ----------
    path : Path
        The file.
    fmt : {"csv", "mat", "tdms"}
        Its format (:func:`source_format`).
    groups : tuple of str
        TDMS only: the groups to import (names or :mod:`fnmatch` patterns); empty: every
        group that holds channels.

    Raises
    ------
    UsageError
        The file cannot be read as that format, or holds no columns (naming the file).
    """
    if not path.is_file():
        raise UsageError(f"{path}: no such source file")
    if groups and fmt != "tdms":
        raise UsageError(f"{path}: the map's groups = {list(groups)} are TDMS groups; this "
                         f"source is {fmt}")
    if fmt == "csv":
        return [_read_csv(path)]
    if fmt == "mat":
        return [_read_mat(path)]
    return _read_tdms(path, groups)


def _cell(text: str, decimal_comma: bool) -> float:
    text = text.strip()
    if not text:
        return math.nan
    return float(text.replace(",", ".") if decimal_comma else text)


def _read_csv(path: Path) -> SourceTable:
    try:
        lines = [line for line in path.read_text(encoding="utf-8-sig").splitlines()
                 if line.strip() and not line.lstrip().startswith("#")]
    except (OSError, UnicodeDecodeError) as exc:
        raise UsageError(f"{path}: cannot read as a CSV text file: {exc}") from exc
    if len(lines) < 2:
        raise UsageError(f"{path}: a CSV needs a header row and at least one row of numbers")
    try:
        dialect = csv.Sniffer().sniff("\n".join(lines[:20]), delimiters=",;\t")
    except csv.Error as exc:
        raise UsageError(f"{path}: cannot find the CSV delimiter (, ; or tab): {exc}") from exc
    rows = list(csv.reader(lines, dialect))
    header = [h.strip() for h in rows[0]]
    decimal_comma = dialect.delimiter != ","
    data = np.full((len(rows) - 1, len(header)), math.nan)
    for i, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise UsageError(f"{path}: row {i} has {len(row)} cells, the header {len(header)}")
        try:
            data[i - 2] = [_cell(c, decimal_comma) for c in row]
        except ValueError as exc:
            raise UsageError(f"{path}: row {i} is not all numbers: {exc}") from exc
    return SourceTable(name=path.name, path=path,
                       columns={h: data[:, j] for j, h in enumerate(header)})


def _flatten(prefix: str, value: Any, columns: dict[str, FloatArray],
             props: dict[str, Any]) -> None:
    """Sort a MATLAB variable into columns and properties (a struct's fields: dotted names)."""
    if isinstance(value, Mapping):
        for key, item in value.items():
            _flatten(f"{prefix}.{key}" if prefix else str(key), item, columns, props)
    elif isinstance(value, str):
        props[prefix] = value
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        props[prefix] = float(value)
    elif isinstance(value, np.ndarray) and value.dtype.kind in "fiub":
        if value.size == 1:
            props[prefix] = float(value.ravel()[0])
        elif value.ndim == 1 or (value.ndim == 2 and min(value.shape) == 1):
            columns[prefix] = value.astype(np.float64).ravel()


def _read_mat(path: Path) -> SourceTable:
    columns: dict[str, FloatArray] = {}
    props: dict[str, Any] = {}
    if h5py.is_hdf5(path):  # a v7.3 file is HDF5
        with h5py.File(path, "r") as f:
            f.visititems(lambda name, obj: _mat73_item(name, obj, columns, props))
    else:
        try:
            data = loadmat(path, simplify_cells=True)
        except (MatReadError, ValueError, OSError) as exc:
            raise UsageError(f"{path}: cannot read as a MATLAB file (v5, or v7.3 HDF5): "
                             f"{exc}") from exc
        _flatten("", {k: v for k, v in data.items() if not k.startswith("__")}, columns, props)
    if not columns:
        raise UsageError(f"{path}: holds no numeric vectors (the channels)")
    return SourceTable(name=path.name, path=path, columns=columns, properties={"": props})


def _mat73_item(name: str, obj: Any, columns: dict[str, FloatArray],
                props: dict[str, Any]) -> None:
    """One dataset of a v7.3 file: MATLAB's own #refs# and #subsystem# are skipped."""
    if not isinstance(obj, h5py.Dataset) or name.startswith("#"):
        return
    key = name.replace("/", ".")
    kind = obj.attrs.get("MATLAB_class", b"")
    kind = kind.decode() if isinstance(kind, bytes) else str(kind)
    value = obj[()]
    if kind == "char":
        props[key] = "".join(chr(c) for c in np.asarray(value).ravel())
    elif isinstance(value, np.ndarray) and value.dtype.kind in "fiub":
        _flatten(key, value, columns, props)
    elif np.isscalar(value) and isinstance(value, (int, float, np.number)):
        props[key] = float(value)


def _read_tdms(path: Path, patterns: tuple[str, ...]) -> list[SourceTable]:
    from nptdms import TdmsFile  # an optional extra (windrig[exchange]): TDMS sources only

    try:
        tdms = TdmsFile.read(path)
    except (ValueError, OSError, KeyError) as exc:
        raise UsageError(f"{path}: cannot read as a TDMS file: {exc}") from exc
    groups = [g for g in tdms.groups() if g.channels()]
    if patterns:
        chosen = [g for g in groups if any(fnmatch.fnmatchcase(g.name, p) for p in patterns)]
        if not chosen:
            raise UsageError(f"{path}: no group matches groups = {list(patterns)}; groups "
                             f"with channels: {[g.name for g in groups]}")
        groups = chosen
    if not groups:
        raise UsageError(f"{path}: holds no group with channels")
    file_props = dict(tdms.properties)
    tables = []
    for group in groups:
        columns: dict[str, FloatArray] = {}
        props: dict[str, Mapping[str, Any]] = {"": {**file_props, **group.properties}}
        increments: dict[str, float] = {}
        for channel in group.channels():
            data = np.asarray(channel[:])
            if data.dtype.kind not in "fiub":
                continue  # a string or timestamp channel: not a signal
            columns[channel.name] = data.astype(np.float64)
            props[channel.name] = dict(channel.properties)
            if "wf_increment" in channel.properties:
                increments[channel.name] = float(channel.properties["wf_increment"])
        tables.append(SourceTable(name=f"{path.name}:{group.name}", path=path, columns=columns,
                                  properties=props, increments=increments))
    return tables
