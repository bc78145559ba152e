"""What a run file holds, for ``windrig info``: a summary as plain data and as text.

Responsible for: reading a run file's description (rig, section, devices with their rates,
samples, gaps and clock fits, releases with their wind speed and amplitudes, events, CALZ
records, whether the file was closed, left by a crash or recovered) into JSON-ready data
(:func:`run_info`), and printing it for a person (:func:`format_info`).

Not responsible for: the numbers' analysis (:mod:`ident`), repairing a crashed file
(:mod:`daq.recording.recover`).

The file is opened read-only (:func:`daq.recording.layout.open_run_file`: as a SWMR reader if a
writer still has it or left it open), so a file being written or left by a crash is described as
it is; the datasets of one group are read to their shortest length, as
:func:`daq.recording.layout.read_sync` does.
"""

from __future__ import annotations

import os
import tomllib
from collections import Counter
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from daq.errors import NotARunFileError
from daq.recording.layout import (
    STREAM_TABLES,
    SWAY_COLUMNS,
    SYNC_COLUMNS,
    open_run_file,
    per_device_attrs,
)
from daq.recording.recover import holders, read_superblock
from ident.records.run_layout import (
    empty_release,
    release_rows_problem,
    release_table_problem,
    shared_rows_problem,
)

__all__ = ["format_info", "run_info"]

#: Event kinds too frequent to list one by one (a trigger pulse every 0.5 s): counted only.
_COUNTED_ONLY = frozenset({"trigger"})


def _text(value: Any) -> str:
    return value.decode("utf-8") if isinstance(value, bytes) else str(value)


def _plain(value: Any) -> Any:
    """Return an HDF5 value as JSON-ready data (numbers, strings, lists, dicts)."""
    if isinstance(value, h5py.Group):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, h5py.Dataset):
        value = value[()]
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray):
        return [_plain(v) for v in value.tolist()]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None  # JSON has no NaN
    return value


def _state(path: Path, entry: h5py.Group) -> dict[str, Any]:
    flags = read_superblock(path).flags
    recovered = entry.attrs.get("recovered")
    if flags:
        writers = holders(path)
        if writers:  # a recording in progress, not a crash
            return {"state": "writing", "status_flags": flags, "open_in_processes": writers}
        return {"state": "crashed", "status_flags": flags}
    if recovered is not None:
        return {"state": "recovered", "recovered": _text(recovered)}
    return {"state": "closed"}


def _device(name: str, group: h5py.Group, t0_ns: int | None,
            clock: dict[str, dict[str, float]], config: dict[str, Any]) -> dict[str, Any]:
    rows = [ds for key, ds in group.items()
            if isinstance(ds, h5py.Dataset) and key not in STREAM_TABLES]
    for ds in rows:
        ds.refresh()
    n = min((ds.shape[0] for ds in rows), default=0)
    host = group["host_time_ns"][:n] if "host_time_ns" in group else np.zeros(0, np.int64)
    host = host[host >= 0]  # not fill rows
    lengths: np.ndarray = group["gaps"]["length"] if "gaps" in group else np.zeros(0, np.int64)
    lengths = lengths[lengths != 0]  # (-1, 0): a fill row, not a gap
    span = None
    if host.size and t0_ns is not None:
        span = [round(float((t - t0_ns) * 1e-9), 9) for t in (host[0], host[-1])]
    info: dict[str, Any] = {
        "driver": config.get(name, {}).get("driver"),
        "rate_hz": float(group.attrs.get("rate", np.nan)),
        "channels": [_text(c) for c in group.attrs.get("channel_names", [])],
        "samples": int(n),
        "time_span_s": span,
        "gaps": int(lengths.size),
        "missing_samples": int(lengths[lengths > 0].sum()),
        "restarts": int(np.count_nonzero(lengths < 0)),
        "clock_fit": None,
    }
    if name in clock.get("offset_s", {}):
        info["clock_fit"] = {key: values[name] for key, values in clock.items() if name in values}
    return info


def _config_tables(text: str) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """Return the stored config's ``[section]`` and its instruments by name (empty if bad)."""
    try:
        config = tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        return {}, {}
    section = {k: v for k, v in config.get("section", {}).items()
               if isinstance(v, (int, float, str))}
    devices: dict[str, dict[str, Any]] = {}
    for role in ("scanner", "fan", "plc", "barometer"):
        if isinstance(config.get(role), dict):
            devices[str(config[role].get("name", role))] = config[role]
    for role in ("lasers", "analog"):  # the roles a rig may have several of
        for table in config.get(role, []):
            if isinstance(table, dict) and "name" in table:
                devices[str(table["name"])] = table
    return section, devices


def run_info(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Describe a run file as JSON-ready data.

    Parameters
    ----------
    path : path-like
        A windrig run file (closed, being written, left by a crash, or recovered).

    Returns
    -------
    dict
        ``file``, ``size_bytes``, ``state`` (``"closed"``, ``"writing"`` (another process has
        it open), ``"crashed"`` (left open by a writer that is gone) or ``"recovered"``),
        ``windrig_version``, ``created``, ``start_time``, ``rig``, ``operator_notes``,
        ``section`` (the stored ``[section]``: m, kg/m, kg m^2/m, Hz), ``sync`` (rows written
        whole, rows sized but never written (a crash), rate in Hz, duration in s, the fraction
        of rows with h finite), ``devices`` (per device: driver,
        rate in Hz, channels, samples, time span in s from the run start, gaps, missing samples,
        restarts, clock fit: offset s, drift ppm), ``residual_misalignment_s``, ``releases``
        (time s, U m/s, h0 m, alpha0 rad, a 3-DOF run's p0 m, decay length s), ``events``
        (counts per kind and every event but the trigger pulses: time s, kind, text), ``calz``
        (each CALZ record's scalars), ``calibrations`` (per ``/entry/calibration`` group:
        ``source``, ``date``, ``configured`` and its ``values``) and ``recovery`` (what
        ``windrig recover`` did, or None), ``missing`` (the optional parts the file lacks:
        ``/entry/config``, ``/entry/instrument``, ``/entry/releases``, ``/entry/events``) and
        ``imported`` (where ``windrig import`` read it from: ``source``, ``sha256``, ``test``,
        ``format``, ``map_file``, ``map``; or None) and ``warnings`` (the texts of the
        file's ``warning`` events: the device check's notes, a fan target not reached, clocks
        no trigger pulse anchored; then ``release_problems``). ``release_problems``: the
        release rows the readers refuse or leave out, one sentence each (listed twice,
        sharing rows, outside the sync view, without rows, a wind speed not > 0). NaN is None.

    Raises
    ------
    FileNotFoundError
        If there is no such file.
    NotARunFileError
        If it is a directory, not HDF5, has no ``/entry/sync/time`` (not a windrig run file),
        or is unreadable (truncated).
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(2, "No such file or directory", str(path))
    if path.is_dir():
        raise NotARunFileError(f"{path}: a directory, not a run file")
    read_superblock(path)  # not HDF5: a specific error before h5py's
    try:
        handle = open_run_file(path)
    except OSError as exc:
        raise NotARunFileError(f"{path}: HDF5 cannot open it (truncated?): {exc}") from exc
    with handle as f:
        try:
            # The smallest run file (docs/reference/file_format.md) has the sync view and no raw
            # streams: info describes whatever else a file has, and says what it lacks.
            for part in ("entry/sync", "entry/sync/time"):
                if part not in f:
                    raise NotARunFileError(f"{path}: has no /{part}: not a windrig run file "
                                           "(docs/reference/file_format.md, the smallest run file)")
            return _describe(path, f)
        except NotARunFileError:
            raise
        except (OSError, RuntimeError, KeyError, ValueError) as exc:
            # h5py's errors on a truncated or damaged file: OSError on reading data, KeyError on
            # opening an object, RuntimeError on following a link, ValueError on a bad type.
            raise NotARunFileError(f"{path}: unreadable HDF5 data (truncated or damaged?): "
                                   f"{exc}") from exc


def _describe(path: Path, f: h5py.File) -> dict[str, Any]:
    entry, sync = f["entry"], f["entry/sync"]
    section, device_config = _config_tables(_text(entry["config"][()]) if "config" in entry
                                            else "")
    columns = [sync[name] for name in (*SYNC_COLUMNS, *SWAY_COLUMNS) if name in sync]
    for ds in columns:
        ds.refresh()
        if ds.dtype.kind not in "biuf":  # text written by another program: said, not summed
            raise NotARunFileError(f"{path}: {ds.name} holds {ds.dtype} values, not numbers")
    shortest = min((ds.shape[0] for ds in columns), default=0)
    time = sync["time"][:shortest] if "time" in sync else np.zeros(0)
    # Rows whose size reached the file but whose data did not (a crash) read as NaN times.
    finite = np.flatnonzero(np.isfinite(time))
    n = int(finite[-1]) + 1 if finite.size else 0
    time = time[:n]
    rate = round(1.0 / float(np.median(np.diff(time))), 6) if time.size > 1 else None
    h = sync["h"][:n] if "h" in sync else np.zeros(0)
    t0 = sync.attrs.get("t0_host_ns")
    t0_ns = int(t0) if t0 is not None else None
    clock = {"offset_s": per_device_attrs(sync.attrs, "clock_offset_s"),
             "drift_ppm": per_device_attrs(sync.attrs, "clock_drift_ppm")}
    devices = {name: _device(name, group, t0_ns, clock, device_config)
               for name, group in (entry["instrument"].items() if "instrument" in entry else ())
               if isinstance(group, h5py.Group)}
    releases = []
    row_warnings: list[str] = []
    if "releases" in entry:
        entry["releases"].refresh()
        table = entry["releases"][:]
        problem = release_table_problem(table)
        if problem is not None:  # a table another program wrote in another layout
            raise NotARunFileError(f"{path}: {problem}")
        fields = table.dtype.names or ()
        for row in table:
            start, stop = int(row["start_index"]), int(row["stop_index"])
            # h0 and alpha0 are shown, not needed: a file without them shows NaN (None).
            releases.append({"time_s": float(row["release_time"]), "U": float(row["U"]),
                             **{name: float(row[name]) if name in fields else np.nan
                                for name in ("h0", "alpha0")},
                             **({"p0": float(row["p0"])} if "p0" in fields else {}),
                             "decay_s": (stop - start) / rate if rate else None})
        row_warnings = _release_warnings(path, table, n)
    events: list[dict[str, Any]] = []
    counts: Counter[str] = Counter()
    if "events" in entry:
        entry["events"].refresh()
        for row in entry["events"][:]:
            kind = _text(row["kind"])
            counts[kind] += 1
            if kind not in _COUNTED_ONLY and np.isfinite(row["time"]):  # NaN: never written
                events.append({"time_s": float(row["time"]), "kind": kind,
                               "text": _text(row["text"])})
    metadata = entry["metadata"] if "metadata" in entry else {}
    calz = {name: _plain(item) for name, item in metadata.items() if name.startswith("calz_")}
    recovery = next((_plain(metadata[name]) for name in sorted(metadata, reverse=True)
                     if name.startswith("recovery")), None)
    residual = sync.attrs.get("residual_misalignment_s")
    calibrations = {name: {**{k: _text(v) for k, v in group.attrs.items() if k != "NX_class"},
                           "values": _plain(group)}
                    for name, group in (entry["calibration"].items() if "calibration" in entry
                                        else ()) if isinstance(group, h5py.Group)}
    return _finite_or_none({
        "file": str(path),
        "size_bytes": path.stat().st_size,
        **_state(path, entry),
        "windrig_version": _text(f.attrs.get("windrig_version", "")),
        "created": _text(f.attrs.get("created", "")),
        "start_time": _text(entry.attrs.get("start_time", "")),
        "rig": _text(entry.attrs.get("rig_name", "")),
        "operator_notes": _text(entry.attrs.get("operator_notes", "")),
        "section": section,
        "sync": {"rows": int(n), "unwritten_rows": int(shortest - n), "rate_hz": rate,
                 "duration_s": float(time[-1] - time[0]) if time.size else 0.0,
                 "h_finite": float(np.isfinite(h).mean()) if h.size else None},
        "devices": devices,
        "residual_misalignment_s": None if residual is None else float(residual),
        "releases": releases,
        "events": {"counts": dict(sorted(counts.items())), "list": events},
        "calz": calz,
        "calibrations": calibrations,
        "recovery": recovery,
        "missing": [f"/entry/{part}" for part in ("config", "instrument", "releases", "events")
                    if part not in entry],
        # `windrig import`'s provenance (daq.exchange.importing): source, sha256, test, format,
        # map_file and the map's text; None for a recorded run.
        "imported": _plain(metadata["import"]) if "import" in metadata else None,
        "release_problems": row_warnings,
        "warnings": [e["text"] for e in events if e["kind"] == "warning"] + row_warnings,
    })


def _release_warnings(path: Path, table: np.ndarray, rows: int) -> list[str]:
    """Return what ``windrig identify`` would refuse or leave out of the release rows.

    ``info`` describes a file as it is; these say beforehand which rows the readers
    (:func:`ident.records.run_file.read_run`) refuse or leave out: a release listed twice or
    sharing rows with another (:func:`ident.records.run_layout.shared_rows_problem`), rows
    outside the ``rows`` of the sync view or none, a wind speed that is not > 0.
    """
    shared = shared_rows_problem(table)
    out = [] if shared is None else [f"{path}: {shared}"]
    for i, row in enumerate(table):
        start, stop, U = int(row["start_index"]), int(row["stop_index"]), float(row["U"])
        if start == stop:  # the recorder's U of such a row is NaN: no more to say
            out.append(f"{path}: {empty_release(i)}: identify leaves it out")
            continue
        problem = release_rows_problem(start, stop, rows, i)
        if problem is not None:
            out.append(f"{path}: {problem}")
        if not U > 0.0:  # NaN too
            out.append(f"{path}: release {i} has U = {U:g} m/s: a wind speed must be > 0 m/s")
    return out


def _finite_or_none(value: Any) -> Any:
    """Return ``value`` with every NaN or infinite float, at any depth, as None (JSON null)."""
    if isinstance(value, dict):
        return {k: _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite_or_none(v) for v in value]
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


def _fmt(value: float | None, spec: str, scale: float = 1.0) -> str:
    """Format a number of :func:`run_info` (None, a NaN in the file, as ``?``)."""
    return "?" if value is None else format(value * scale, spec)


def format_info(info: dict[str, Any]) -> str:
    """Return :func:`run_info`'s data as text for a person (one block per part)."""
    state = {"closed": "closed by its writer",
             "crashed": (f"left open by its writer (crash?, status flags "
                         f"0x{info.get('status_flags', 0):02x}): run `windrig recover "
                         f"{info['file']}` before opening it with other HDF5 tools"),
             "writing": (f"being written (open in process "
                         f"{', '.join(map(str, info.get('open_in_processes', [])))})"),
             "recovered": f"recovered by windrig recover ({info.get('recovered')})"}[info["state"]]
    sync = info["sync"]
    lines = [
        f"{info['file']}: {info['size_bytes'] / 1e6:.1f} MB, {state}",
        f"rig        {info['rig'] or '?'}" + (f"  ({info['operator_notes']})"
                                       if info["operator_notes"] else ""),
        f"recorded   {info['start_time'] or info['created'] or '?'} by windrig "
        f"{info['windrig_version'] or '?'}",
        *([f"imported   from {imp['source']}" + (f" group {imp['test']}" if imp["test"] else "")
           + f" (SHA-256 {imp['sha256'][:16]}...) by the map {imp['map_file']}"]
          if (imp := info.get("imported")) else []),
        "section    " + (", ".join(f"{k} = {v}" for k, v in info["section"].items()) or "none"),
        *([f"missing    {', '.join(info['missing'])} (not needed by every command: "
           "docs/reference/file_format.md, the smallest run file)"] if info.get("missing") else []),
        f"sync view  {sync['rows']} rows"
        + (f" at {sync['rate_hz']:.6g} Hz, {sync['duration_s']:.3f} s" if sync["rate_hz"] else "")
        + (f", h finite in {sync['h_finite']:.1%}" if sync["h_finite"] is not None else "")
        + (f"; {sync['unwritten_rows']} more rows sized but never written (trimmed by windrig "
           "recover)" if sync["unwritten_rows"] else ""),
        "",
        f"{'device':<14} {'driver':<22} {'rate Hz':>8} {'samples':>9} {'gaps':>5} "
        f"{'missing':>8} {'restarts':>8}  clock fit" if info["devices"]
        else "devices    none (no raw streams: a file written from the sync view alone)",
    ]
    for name, d in info["devices"].items():
        fit = d["clock_fit"]
        clock = ("-" if fit is None else f"offset {_fmt(fit['offset_s'], '+.6f')} s, drift "
                 f"{_fmt(fit.get('drift_ppm'), '+.2f')} ppm")
        lines.append(f"{name:<14} {d['driver'] or '?':<22} {_fmt(d['rate_hz'], '>8g')} "
                     f"{d['samples']:>9} {d['gaps']:>5} {d['missing_samples']:>8} "
                     f"{d['restarts']:>8}  {clock}")
    if info["residual_misalignment_s"] is not None:
        lines.append(f"residual misalignment of the clock fits "
                     f"{info['residual_misalignment_s'] * 1e3:.3f} ms")
    elif info["state"] != "closed" and info["devices"]:
        lines.append("no clock fits: they are written when the file is closed, and the crash "
                     "lost them (the raw streams keep every time stamp)")
    lines += ["", f"releases   {len(info['releases'])}"]
    for i, r in enumerate(info["releases"]):
        decay = f", decay {r['decay_s']:.2f} s" if r["decay_s"] is not None else ""
        sway = f"  p0 = {_fmt(r['p0'], '+7.3f', 1e3)} mm" if "p0" in r else ""  # 3 DOF
        lines.append(f"  #{i}  t = {_fmt(r['time_s'], '8.3f')} s  U = {_fmt(r['U'], '6.3f')} m/s"
                     f"  h0 = {_fmt(r['h0'], '+7.3f', 1e3)} mm  alpha0 = "
                     f"{_fmt(r['alpha0'], '+7.3f', 180 / np.pi)} deg{sway}{decay}")
    lines += [f"  warning: {text}" for text in info.get("release_problems", [])]
    counts = info["events"]["counts"]
    lines += ["", "events     " + (", ".join(f"{k} {v}" for k, v in counts.items()) or "none")]
    for e in info["events"]["list"]:
        lines.append(f"  {_fmt(e['time_s'], '8.3f')} s  {e['kind']:<16} {e['text']}")
    configured = {k: c for k, c in info.get("calibrations", {}).items()
                  if c.get("configured") == "yes"}
    lines += ["", "calibrated " + (", ".join(configured) or "none (the defaults)")]
    for name, c in configured.items():
        lines.append(f"  {name}: source {c.get('source') or '?'}, date {c.get('date') or '?'}")
    lines += ["", "CALZ       " + (", ".join(info["calz"]) or "none")]
    for name, record in info["calz"].items():
        scalars = {k: v for k, v in record.items() if not isinstance(v, (list, dict))} \
            if isinstance(record, dict) else {}
        lines.append(f"  {name}: " + ", ".join(f"{k} = {v:.6g}" if isinstance(v, float)
                                                else f"{k} = {v}" for k, v in scalars.items()))
    return "\n".join(lines)
