"""One writer per export format: CSV, MATLAB v5, netCDF-4 (xarray), TDMS (npTDMS).

Responsibility: write a :class:`~daq.exchange.export_run.RunContents` so that the format's own
reader gets back every value of the sync view exactly (float64 stays float64; ``pressure``,
float32 in the run file, stays float32 where the format has it and is written exactly as a
float64 where it has not), the releases, the events, the calibrations and the units:

- ``csv``: a folder of ``sync.csv``, ``releases.csv``, ``events.csv``, ``calibration.csv``,
  ``run.csv`` (the run's attributes) and ``config.toml``. Each table's header names the units
  (``h [m]``); numbers are written as Python's ``repr`` (the shortest text that reads back as
  the same float64, exactly); NaN is ``nan``.
- ``mat``: MATLAB 5 (``scipy.io.savemat``, compressed), which MATLAB's ``load`` reads: the
  structs ``sync``, ``releases``, ``events``, ``calibration`` (one struct per calibration) and
  ``calibration_attrs``, the units in ``sync_units`` and ``releases_units``, the tap names in
  ``taps`` (a cell array), the rig config in ``config``, the run's attributes in ``run``.
  Columns are column vectors. Release indices stay 0-based (as in the run file).
- ``netcdf``: netCDF-4 through xarray and h5netcdf: the sync view at the root (dimensions
  ``time`` and ``tap``), then the groups ``releases`` (dimension ``release``), ``events``
  (dimension ``event``) and ``calibration/<name>``; every variable has ``units``.
- ``tdms``: one segment through npTDMS: the groups ``sync`` (a channel per column, one per tap
  for ``pressure``: ``pressure tap000``), ``releases``, ``events`` and ``calibration <name>``
  (numbers as channels, text as group properties); each channel's ``unit_string`` (the
  property LabVIEW shows as the unit) holds its units, and the sync view's channels of a
  uniform time base carry LabVIEW's waveform properties (``wf_start_offset``,
  ``wf_increment``, s).

MATLAB 5 files hold at most 2 GiB per variable: a larger sync view is refused with a pointer
to netCDF. Not responsible for: reading the run file (:mod:`daq.exchange.export_contents`).
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from daq.errors import UsageError
from daq.exchange.export_contents import RELEASE_MEANINGS, RunContents

__all__ = ["MAT_V5_LIMIT_BYTES", "WRITERS", "write_csv", "write_mat", "write_netcdf",
           "write_tdms"]

#: Largest variable a MATLAB 5 file can hold, bytes (its 32-bit sizes).
MAT_V5_LIMIT_BYTES = 2**31 - 1
#: Units of the events' time.
_EVENT_UNITS = {"time": "s", "kind": "", "text": ""}


def _float_text(value: Any) -> str:
    """Return a number as CSV text that reads back as the same float64 or integer."""
    if isinstance(value, (int, np.integer, bool, np.bool_)):
        return str(int(value))
    return repr(float(value))  # the shortest text that reads back as the same float64


def _head(name: str, units: str) -> str:
    return f"{name} [{units or '1'}]"


def _sync_matrix(contents: RunContents) -> tuple[list[str], npt.NDArray[np.float64]]:
    """Return the sync view as one float64 matrix (float32 widens exactly) and its header."""
    header, blocks = [], []
    for c in contents.columns:
        if c.values.ndim == 2:
            header += [_head(f"{c.name} {tap}", c.units) for tap in contents.taps]
            blocks.append(np.asarray(c.values, dtype=np.float64))
        else:
            header.append(_head(c.name, c.units))
            blocks.append(np.asarray(c.values, dtype=np.float64)[:, None])
    return header, np.hstack(blocks)


def write_csv(contents: RunContents, out: Path) -> list[Path]:
    """Write the CSV folder ``out``; return its files."""
    out.mkdir()
    files = []
    header, matrix = _sync_matrix(contents)
    path = out / "sync.csv"
    with path.open("w", encoding="utf-8") as fh:
        fh.write(",".join(header) + "\n")
        for row in matrix.tolist():  # repr: the shortest text that reads back as the same float
            fh.write(",".join(map(repr, row)) + "\n")
    files.append(path)
    table = contents.releases
    fields = list(table.dtype.names or ())
    files.append(_table(out / "releases.csv",
                        [_head(n, contents.release_units.get(n, "")) for n in fields],
                        [[_float_text(row[n]) for n in fields] for row in table]))
    events = contents.events
    files.append(_table(out / "events.csv", ["time [s]", "kind", "text"],
                        [[_float_text(t), k, x] for t, k, x in
                         zip(events["time"], events["kind"], events["text"], strict=True)]))
    rows = []
    for name, cal in contents.calibrations.items():
        rows += [[name, f"@{key}", "", text] for key, text in cal["attrs"].items()]
        for key, value in cal["values"].items():
            if isinstance(value, str):
                rows.append([name, key, "", value])
                continue
            flat = np.atleast_1d(value).ravel()
            rows += [[name, key, "" if np.ndim(value) == 0 else str(i), _value_text(v)]
                     for i, v in enumerate(flat)]
    files.append(_table(out / "calibration.csv", ["calibration", "name", "index", "value"], rows))
    files.append(_table(out / "run.csv", ["key", "value"],
                        [["source", str(contents.source)], *map(list, contents.attrs.items())]))
    if contents.config_text:
        path = out / "config.toml"
        path.write_text(contents.config_text, encoding="utf-8")
        files.append(path)
    return files


def _value_text(value: Any) -> str:
    if isinstance(value, (str, bytes)):
        return value.decode("utf-8") if isinstance(value, bytes) else value
    return _float_text(value)


def _table(path: Path, header: list[str], rows: list[list[Any]]) -> Path:
    with path.open("w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(header)
        writer.writerows(rows)
    return path


def _cell(values: Any) -> npt.NDArray[Any]:
    """Return a MATLAB cell array (a column) of strings."""
    array = np.empty((len(values), 1), dtype=object)
    for i, v in enumerate(values):
        array[i, 0] = str(v)
    return array


def _mat_value(value: Any) -> Any:
    if isinstance(value, str):
        return value
    array = np.asarray(value)
    return _cell(array.ravel()) if array.dtype.kind in "OUS" else array


def write_mat(contents: RunContents, out: Path) -> list[Path]:
    """Write a MATLAB 5 file (``load`` reads it); return ``[out]``."""
    from scipy.io import savemat  # here: only this format needs scipy.io (a faster start)

    size = sum(c.values.nbytes for c in contents.columns)
    if size > MAT_V5_LIMIT_BYTES:
        raise UsageError(f"{contents.source}: the sync view is {size / 2**30:.1f} GiB, more "
                         "than a MATLAB 5 file holds (2 GiB); export --to netcdf, which "
                         "MATLAB reads with ncread")
    table = contents.releases
    mdict: dict[str, Any] = {
        "sync": {c.name: c.values for c in contents.columns},
        "sync_units": {c.name: c.units for c in contents.columns},
        "sync_long_names": {c.name: c.long_name for c in contents.columns},
        "taps": _cell(contents.taps),
        "releases": {n: np.asarray(table[n]) for n in table.dtype.names or ()},
        "releases_units": dict(contents.release_units),
        "events": {"time": contents.events["time"], "kind": _cell(contents.events["kind"]),
                   "text": _cell(contents.events["text"])},
        "calibration": {name: {k: _mat_value(v) for k, v in cal["values"].items()}
                        for name, cal in contents.calibrations.items()},
        "calibration_attrs": {name: dict(cal["attrs"])
                              for name, cal in contents.calibrations.items()},
        "config": contents.config_text,
        "run": {"source": str(contents.source), **contents.attrs},
    }
    savemat(out, mdict, format="5", do_compression=True, oned_as="column",
            long_field_names=True)
    return [out]


def write_netcdf(contents: RunContents, out: Path) -> list[Path]:
    """Write a netCDF-4 file (xarray, h5netcdf); return ``[out]``."""
    import xarray as xr  # the optional extra `exchange`, imported only when it is used

    data: dict[str, Any] = {}
    for c in contents.columns[1:]:
        dims = ("time", "tap") if c.values.ndim == 2 else ("time",)
        data[c.name] = (dims, c.values, {"units": c.units, "long_name": c.long_name})
    time = contents.columns[0]
    coords: dict[str, Any] = {"time": ("time", time.values, {"units": time.units,
                                                             "long_name": time.long_name})}
    if contents.taps:
        coords["tap"] = ("tap", np.array(contents.taps, dtype=object))
    attrs = {"source": str(contents.source), **contents.attrs,
             "rig_config": contents.config_text}
    xr.Dataset(data, coords=coords, attrs=attrs).to_netcdf(out, engine="h5netcdf", mode="w")
    table = contents.releases
    xr.Dataset({n: ("release", np.asarray(table[n]),
                    {"units": contents.release_units.get(n, ""),
                     "long_name": _meaning(n)}) for n in table.dtype.names or ()}).to_netcdf(
        out, engine="h5netcdf", mode="a", group="releases")
    events = contents.events
    xr.Dataset({k: ("event", v if k == "time" else v.astype(str), {"units": _EVENT_UNITS[k]})
                for k, v in events.items()}).to_netcdf(out, engine="h5netcdf", mode="a",
                                                        group="events")
    for name, cal in contents.calibrations.items():
        variables = {k: _netcdf_variable(k, v) for k, v in cal["values"].items()}
        xr.Dataset(variables, attrs=dict(cal["attrs"])).to_netcdf(
            out, engine="h5netcdf", mode="a", group=f"calibration/{name}")
    return [out]


def _meaning(field: str) -> str:
    return RELEASE_MEANINGS.get(field, "")


def _netcdf_variable(name: str, value: Any) -> tuple[Any, ...]:
    if isinstance(value, str):
        return ((), value)
    array = np.asarray(value)
    if array.dtype.kind == "O":
        array = array.astype(str)
    return ((), array) if array.ndim == 0 else ((f"{name}_index",), array)


def write_tdms(contents: RunContents, out: Path) -> list[Path]:
    """Write a TDMS file (npTDMS; LabVIEW reads it); return ``[out]``."""
    # The optional extra `exchange`, imported only when it is used.
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    objects: list[Any] = [RootObject({"source": str(contents.source), **contents.attrs,
                                      "rig_config": contents.config_text}),
                          GroupObject("sync", {"taps": ",".join(contents.taps)})]
    waveform = _waveform(contents.columns[0].values)
    for c in contents.columns:
        unit = {"unit_string": c.units, "long_name": c.long_name,
                **(waveform if c.name != "time" else {})}
        if c.values.ndim == 2:
            objects += [ChannelObject("sync", f"{c.name} {tap}", c.values[:, i], unit)
                        for i, tap in enumerate(contents.taps)]
        else:
            objects.append(ChannelObject("sync", c.name, c.values, unit))
    table = contents.releases
    objects.append(GroupObject("releases", {}))
    objects += [ChannelObject("releases", n, np.asarray(table[n]),
                              {"unit_string": contents.release_units.get(n, ""),
                               "description": _meaning(n)}) for n in table.dtype.names or ()]
    objects.append(GroupObject("events", {}))
    objects += [ChannelObject("events", k, v, {"unit_string": _EVENT_UNITS[k]})
                for k, v in contents.events.items()]
    for name, cal in contents.calibrations.items():
        group = f"calibration {name}"
        texts = {k: v for k, v in cal["values"].items() if isinstance(v, str)}
        objects.append(GroupObject(group, {**cal["attrs"], **texts}))
        objects += [ChannelObject(group, k, np.atleast_1d(v)) for k, v in cal["values"].items()
                    if not isinstance(v, str)]
    with TdmsWriter(out) as writer:
        writer.write_segment(objects)
    return [out]


def _waveform(time: npt.NDArray[Any]) -> dict[str, Any]:
    """Return LabVIEW's waveform properties of a uniform time base (none for another).

    With ``wf_start_offset`` (s) and ``wf_increment`` (s) LabVIEW and DIAdem read a channel as
    a waveform against time; the ``time`` channel stays, for every other reader.
    """
    steps = np.diff(time)
    if time.size < 2 or not np.isfinite(steps).all():
        return {}
    step = float(np.median(steps))
    # Uniform to 1 ppm of a step: the sync view's rows are k / rate, rounded to float64.
    if step <= 0 or np.max(np.abs(steps - step)) > 1e-6 * step:
        return {}
    return {"wf_start_offset": float(time[0]), "wf_increment": step,
            "wf_samples": int(time.size)}


#: The writer of each format (the formats of ``windrig export``).
WRITERS: Mapping[str, Callable[[RunContents, Path], list[Path]]] = {
    "csv": write_csv, "mat": write_mat, "netcdf": write_netcdf, "tdms": write_tdms}
