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
An empty cell is NaN (a gap); trailing rows of empty cells (a spreadsheet's padding) are
dropped, and a name the header repeats cannot be read by the map. MATLAB: a numeric vector
(1 x n or n x 1) is a column, a scalar or a char array a property; a struct's fields are
reached by dotted names (``test.h``). TDMS: a group of numeric channels is a test; a file cut
short inside its last write is read to the last sample all that write's channels hold, the loss
in the table's ``notes``.

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
from daq.exchange.import_map import FORMATS, parse_number

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
    repeated : frozenset of str
        CSV: names the header gives to more than one column; :meth:`column` refuses them.
    notes : tuple of str
        What reading lost or changed (TDMS: a file cut short), for the import's warnings.
    skipped : mapping of str to str
        MATLAB: variables that are neither a column nor a property, and what they are.
    """

    name: str
    path: Path
    columns: Mapping[str, FloatArray]
    properties: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    increments: Mapping[str, float] = field(default_factory=dict)
    repeated: frozenset[str] = frozenset()
    notes: tuple[str, ...] = ()
    skipped: Mapping[str, str] = field(default_factory=dict)

    def column(self, name: str, where: str) -> FloatArray:
        """Return a column, or raise UsageError naming the source, the key and the columns."""
        if name in self.repeated:
            raise UsageError(f"{self.name}: the header has more than one column {name!r} "
                             f"({where}); rename them so the map can tell them apart")
        if name not in self.columns:
            have = ", ".join(sorted(self.columns)[:20])
            raise UsageError(f"{self.name}: no column {name!r} ({where}); it has: {have}"
                             + (f"; not columns: {_skipped_text(self.skipped)}"
                                if self.skipped else ""))
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
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise UsageError(f"{path}: cannot read as a CSV text file: {exc}") from exc
    # Each row with its line in the file, so that a message points where an editor shows it
    # (comments and blank lines are not rows, but they are lines).
    numbered = [(i, line) for i, line in enumerate(text.splitlines(), start=1)
                if line.strip() and not line.lstrip().startswith("#")]
    if len(numbered) < 2:
        raise UsageError(f"{path}: a CSV needs a header row and at least one row of numbers")
    try:
        dialect = csv.Sniffer().sniff("\n".join(line for _, line in numbered[:20]),
                                      delimiters=",;\t")
    except csv.Error as exc:
        raise UsageError(f"{path}: cannot find the CSV delimiter (, ; or tab): {exc}") from exc
    rows = list(csv.reader((line for _, line in numbered), dialect))
    header = [h.strip() for h in rows[0]]
    # A name the header repeats cannot say which of its columns the map means (read as a
    # mapping, the last one won without a word): the map may not read it (SourceTable.column).
    repeated = frozenset(h for h in header if header.count(h) > 1)
    # A spreadsheet pads a sheet's end with rows of empty cells (",,,,"): they are no samples
    # (read as such, each added a NaN sample after the record). Only trailing ones are
    # dropped: an empty row within the data is a gap, whose place in the time base matters.
    while len(rows) > 1 and not any(cell.strip() for cell in rows[-1]):
        rows.pop()
    if len(rows) < 2:
        raise UsageError(f"{path}: a CSV needs a header row and at least one row of numbers")
    decimal_comma = dialect.delimiter != ","
    data = np.full((len(rows) - 1, len(header)), math.nan)
    for k, row in enumerate(rows[1:]):
        line = numbered[k + 1][0]
        if len(row) != len(header):
            raise UsageError(f"{path}: line {line} has {len(row)} cells, the header "
                             f"{len(header)}")
        try:
            data[k] = [_cell(c, decimal_comma) for c in row]
        except ValueError as exc:
            hint = (" (a row of units under the header? put the units in the map, and the row "
                    "in a # comment)" if k == 0 else "")
            raise UsageError(f"{path}: line {line} is not all numbers: {exc}{hint}") from exc
    return SourceTable(name=path.name, path=path,
                       columns={h: data[:, j] for j, h in enumerate(header)},
                       repeated=repeated)


def _flatten(prefix: str, value: Any, columns: dict[str, FloatArray], props: dict[str, Any],
             skipped: dict[str, str]) -> None:
    """Sort a MATLAB variable into columns and properties (a struct's fields: dotted names).

    What is neither (a matrix, a cell or struct array) goes into ``skipped`` with what it is,
    for the messages: a lab's ``data`` matrix was otherwise missing without a word.
    """
    if isinstance(value, Mapping):
        for key, item in value.items():
            _flatten(f"{prefix}.{key}" if prefix else str(key), item, columns, props, skipped)
    elif isinstance(value, str):
        props[prefix] = value
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        props[prefix] = float(value)
    elif isinstance(value, np.ndarray) and value.dtype.kind in "fiub":
        if value.size == 1:
            props[prefix] = float(value.ravel()[0])
        elif value.ndim == 1 or (value.ndim == 2 and min(value.shape) == 1):
            columns[prefix] = value.astype(np.float64).ravel()
        else:
            skipped[prefix] = f"a {' x '.join(map(str, value.shape))} matrix"
    elif isinstance(value, (list, np.ndarray)):  # simplify_cells: cell and struct arrays
        skipped[prefix] = f"a cell or struct array of {len(value)}"


def _read_mat(path: Path) -> SourceTable:
    columns: dict[str, FloatArray] = {}
    props: dict[str, Any] = {}
    skipped: dict[str, str] = {}
    if h5py.is_hdf5(path):  # a v7.3 file is HDF5
        try:
            with h5py.File(path, "r") as f:
                f.visititems(lambda name, obj: _mat73_item(name, obj, columns, props, skipped))
        except OSError as exc:  # HDF5's own words ("truncated file: eof = ...") lack the file
            raise UsageError(f"{path}: cannot read as a MATLAB v7.3 file (HDF5): "
                             f"{exc}") from exc
    else:
        try:
            data = loadmat(path, simplify_cells=True)
        except (MatReadError, ValueError, OSError) as exc:
            raise UsageError(f"{path}: cannot read as a MATLAB file (v5, or v7.3 HDF5): "
                             f"{exc}") from exc
        _flatten("", {k: v for k, v in data.items() if not k.startswith("__")}, columns, props,
                 skipped)
    if not columns:
        raise UsageError(f"{path}: holds no numeric vectors (the channels)"
                         + (f"; not vectors: {_skipped_text(skipped)}" if skipped else ""))
    return SourceTable(name=path.name, path=path, columns=columns, properties={"": props},
                       skipped=skipped)


def _skipped_text(skipped: Mapping[str, str]) -> str:
    """Name the variables that are no columns, and say what a column must be."""
    some = ", ".join(f"{k} ({v})" for k, v in sorted(skipped.items())[:10])
    return f"{some}; save each channel as a vector, or a struct's field"


def _mat73_item(name: str, obj: Any, columns: dict[str, FloatArray], props: dict[str, Any],
                skipped: dict[str, str]) -> None:
    """One dataset of a v7.3 file: MATLAB's own #refs# and #subsystem# are skipped."""
    if not isinstance(obj, h5py.Dataset) or name.startswith("#"):
        return
    key = name.replace("/", ".")
    kind = obj.attrs.get("MATLAB_class", b"")
    kind = kind.decode() if isinstance(kind, bytes) else str(kind)
    if obj.attrs.get("MATLAB_empty", 0):  # [] is stored as its dimensions: no values
        skipped[key] = "empty"
        return
    value = obj[()]
    if kind == "char":
        props[key] = "".join(chr(c) for c in np.asarray(value).ravel())
    elif isinstance(value, np.ndarray) and value.dtype.kind in "fiub":
        # HDF5 holds MATLAB's arrays transposed: .T gives MATLAB's shape for the messages.
        _flatten(key, value.T, columns, props, skipped)
    elif np.isscalar(value) and isinstance(value, (int, float, np.number)):
        props[key] = float(value)
    elif kind in ("cell", "struct"):
        skipped[key] = f"a {kind} array"


def _read_tdms(path: Path, patterns: tuple[str, ...]) -> list[SourceTable]:
    from nptdms import TdmsFile  # an optional extra (windrig[exchange]): TDMS sources only

    try:
        tdms = TdmsFile.read(path)
    except (ValueError, OSError, KeyError) as exc:
        raise UsageError(f"{path}: cannot read as a TDMS file: {exc}") from exc
    # A group of string or timestamp channels only (a LabVIEW file's notes) is no test.
    groups = [g for g in tdms.groups() if any(_numeric(c) for c in g.channels())]
    if patterns:
        chosen = [g for g in groups if any(fnmatch.fnmatchcase(g.name, p) for p in patterns)]
        if not chosen:
            raise UsageError(f"{path}: no group matches groups = {list(patterns)}; groups "
                             f"with numeric channels: {[g.name for g in groups]}")
        groups = chosen
    if not groups:
        raise UsageError(f"{path}: holds no group with numeric channels (string and timestamp "
                         "channels are not signals)" if tdms.groups() else
                         f"{path}: holds no groups: an empty TDMS file, or one cut short "
                         f"({path.stat().st_size} bytes)")
    file_props = dict(tdms.properties)
    status = tdms.file_status
    tables = []
    for group in groups:
        columns: dict[str, FloatArray] = {}
        props: dict[str, Mapping[str, Any]] = {"": {**file_props, **group.properties}}
        increments: dict[str, float] = {}
        for channel in group.channels():
            if not _numeric(channel):
                continue  # a string or timestamp channel: not a signal
            columns[channel.name] = np.asarray(channel[:]).astype(np.float64)
            props[channel.name] = dict(channel.properties)
            if "wf_increment" in channel.properties:
                increments[channel.name] = parse_number(
                    channel.properties["wf_increment"],
                    f"{path.name}:{group.name}: channel {channel.name!r} property 'wf_increment'")
        notes = _truncated(status, group, columns) if status.incomplete_final_segment else ()
        tables.append(SourceTable(name=f"{path.name}:{group.name}", path=path, columns=columns,
                                  properties=props, increments=increments, notes=notes))
    return tables


def _numeric(channel: Any) -> bool:
    """Whether a TDMS channel holds numbers (its dtype: the scaled one for a DAQmx scale)."""
    return channel.dtype is not None and np.dtype(channel.dtype).kind in "fiub"


def _truncated(status: Any, group: Any, columns: dict[str, FloatArray]) -> tuple[str, ...]:
    """Cut a group's channels of a TDMS file's unfinished last write to the samples they share.

    A file that ends inside its last segment (a logger stopped mid-write, a copy cut short):
    npTDMS reads what is there, and the channels of that write end at different samples (one
    after the other in the file). Unmarked, the channels differed in length, or, when the map's
    did not, the record simply lost its end. The channels of that write are cut to the samples
    they all hold, and the loss is returned as a note (a warning of the import).
    """
    if not status.channel_statuses:  # the segment's own header is cut: none of its data read
        return ("the file ends inside the header of its last write (a logger stopped "
                "mid-write, or a copy cut short): that write's samples are not read",)
    written = {c.name: status.channel_statuses[c.path] for c in group.channels()
               if c.name in columns and c.path in status.channel_statuses}
    if not written:
        return ()
    common = min(columns[name].size for name in written)
    missing = max(s.expected_length - s.read_length for s in written.values())
    if missing == 0 and all(columns[name].size == common for name in written):
        return ()  # marked unfinished, but every sample it announced is there
    for name in written:
        columns[name] = columns[name][:common]
    return (f"the file ends inside its last write (a logger stopped mid-write, or a copy cut "
            f"short): up to {missing} sample(s) per channel of that write are missing, and "
            f"channels {sorted(written)} are cut to the {common} samples they all hold",)
