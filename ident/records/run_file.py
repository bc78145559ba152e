"""The one thin module through which :mod:`ident` reads run files (the file format of docs/).

It reads the synchronised view ``/entry/sync``, the releases table ``/entry/releases`` and the
section model from the rig config stored verbatim in ``/entry/config``, and returns
:class:`~ident.records.release.Release` objects and a :class:`~ident.model.section.SectionModel`.
Nothing else in :mod:`ident` touches files. Files are opened read-only, as SWMR readers when a
writer has them open, so a run still being written, or one left by a crash, can be read as well as a
finished one.

Errors are specific: a missing file or dataset, a truncated file, or a release whose rows hold
gaps (NaN) raises :class:`FileFormatError` (a ``ValueError``) naming the file and what is wrong;
a part another program wrote in another layout (a column of text, a release table of plain
numbers, a release listed twice, a release time that is not at its first row) is named by
:mod:`ident.records.run_layout`. What the reader takes in place of a missing part (an
air density never measured) or leaves out (a release row without rows, sway a 2-DOF section
does not read) is said in :attr:`RunFile.reading_notes`.

Longer than 600 lines: one read of one open file feeds the releases, their holds and the
tubing correction of both from the same arrays (the hold's rows depend on the release rows and
the arm events, the correction on both); the checks of the parts against the layout are
already apart, in :mod:`ident.records.run_layout`.

Pneumatic tubing: ``/entry/sync/lift`` and ``moment`` are the forces of the pressures as
measured at the scanner. When the file records its taps' tubing (``/entry/metadata/tubing``),
each release's forces are corrected for it by default (:func:`ident.physics.tubing.force_correction`
on the release's pressures plus up to :data:`TUBING_LEAD_S` of the held model before it, the
tubes' air at the run's measured density and its barometer's median temperature, 20 C without
one); ``tubing_correction=False`` reads them as measured. Dead taps
(``/entry/calibration/taps/dead``) are left out of the correction as they are out of the forces.
The drag of a 3-DOF file is read as measured (the correction covers lift and moment).

Releases without a PLC (since issue 35): a file whose releases were made by hand and said with
the operator's keys has them in ``/entry/releases`` like any other (found in the lasers' signals
as it was recorded); a file without any release rows can have them found now
(``read_run(detect_releases=True)``, :func:`ident.records.release_onset.find_releases`). A
rig without taps records no forces: ``read_run(displacements_only=True)`` reads its releases
for the displacement-only route, and :func:`forces_recorded` tells such a file.

Three degrees of freedom: a file of a rig with a sway spring (``[section] fp``) has ``p`` and
``drag`` in ``/entry/sync``; its section is 3-DOF (``fp``, ``zeta_p``, ``m_p``) and each release
carries them (``Release(p=, drag=)``). A 2-DOF file reads exactly as before.

The hold before each release (:class:`~ident.records.release.ReleaseHold`, since issue 16): the rows
of
``/entry/sync`` while the model was held in the wind just before the release, read from the
same columns (the file format is unchanged). They start :data:`HOLD_SETTLE_S` after the last
``arm`` event of ``/entry/events`` since the previous release (without one: at the previous
release's ``stop_index``, or the first row), end :data:`HOLD_GUARD_S` before ``release_time``,
and are cut to the last stretch without gaps and with the wind on (``U``, as a running median
over :data:`HOLD_U_WINDOW_S`, within :data:`HOLD_U_RTOL` of the release's). Fewer than 2 such
rows: no hold. With a tubing correction the hold's forces are corrected too (a window of their
own, so the release's corrected forces are exactly as before).
"""

from __future__ import annotations

import os
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import h5py
import numpy as np
from scipy.ndimage import median_filter

from ident.errors import IdentError
from ident.model.section import SectionModel
from ident.physics.air import R_DRY_AIR
from ident.physics.taps import TapLayout
from ident.physics.tubing import Air, TubingSet, force_correction, from_description
from ident.records.release import Release, ReleaseHold
from ident.records.release_onset import ReleaseOnset, find_releases
from ident.records.run_layout import (
    column_problem,
    empty_release,
    release_rows_problem,
    release_table_problem,
    release_time_problem,
    shared_rows_problem,
)

__all__ = ["FileFormatError", "HOLD_GUARD_S", "HOLD_SETTLE_S", "HOLD_U_RTOL", "RunFile",
           "TUBING_LEAD_S", "forces_recorded", "read_run"]

_SECTION_FIELDS = ("B", "m", "I", "fh", "fa", "zeta_h", "zeta_a", "S", "fp", "zeta_p", "m_p")
#: Columns of ``/entry/sync`` a 3-DOF file has (docs/reference/file_format.md).
_SWAY_COLUMNS = ("p", "drag")
#: Keys of a ``[taps]`` table that describe the layout (others: tubing, channels, ...).
_LAYOUT_KEYS = {"shape", "B", "D", "taps_per_face", "n_taps", "vertices",
                "x", "z", "nx", "nz", "length"}
#: Seconds of the held, steady model before a release included in its tubing correction, so
#: that the tubes' response to the release itself lies inside the corrected record.
TUBING_LEAD_S = 1.0
#: Temperature of the air in the tubes when correcting a file without a barometer's
#: temperature, K (10 K off changes the 1 m, 1 mm tube's lag at 4 Hz by about 1 %).
TUBING_TEMPERATURE_K = 293.15
#: Seconds after arming before the hold is taken: arming catches a moving model, and the catch
#: shakes it for a moment.
HOLD_SETTLE_S = 0.25
#: Seconds before ``release_time`` left out of the hold: the PLC acknowledges the release after
#: the magnet lets go (the same 0.05 s as ``h0``'s median, docs/reference/file_format.md).
HOLD_GUARD_S = 0.05
#: A hold row has the wind on when its ``U``, as a running median over :data:`HOLD_U_WINDOW_S`,
#: is within this fraction of the release's.
HOLD_U_RTOL = 0.1
#: Window of that running median, s: a Pitot's single rows scatter by more than 10 % at low
#: wind (5 m/s on the simulated plate rig: 7 rows of an 11 s hold), the fan's ramp does not.
HOLD_U_WINDOW_S = 0.5
#: Plausible tunnel air temperatures, K: a barometer reading outside is not used for the tubes.
_TEMPERATURE_RANGE_K = (233.15, 333.15)


class FileFormatError(IdentError, ValueError):
    """A run file is missing, truncated, or does not follow the windrig layout."""


@dataclass(frozen=True)
class RunFile:
    """What identification needs from one run file.

    Attributes
    ----------
    path : str
    section : SectionModel
        From the stored rig config (air density from the run's mean measured density).
    releases : tuple of Release
        One per row of ``/entry/releases``, time from the release instant.
    rig_name : str
    depth : float or None
        Section depth D from the stored ``[section]``, m (None when the config has none).
    tubing : TubingSet or None
        The taps' tubing the file records (None: none recorded).
    tubing_corrected : bool
        Whether the releases' lift and moment were corrected for it.
    cuts : tuple of str
        With ``read_run(cut_at_gaps=True)``: one sentence per release cut short before a gap
        or left out for one (empty otherwise).
    has_forces : bool
        Whether ``/entry/sync`` holds any lift and moment (a rig without taps has none).
    detected : tuple of ReleaseOnset
        With ``read_run(detect_releases=True)``: the onset of each release found, in order.
    recording_warnings : tuple of str
        What the file's writer warned of when it closed the file
        (``/entry/metadata/acquisition_summary/warnings``: a device whose clock no trigger
        pulse anchored, its samples then late by its transport latency); empty for a file
        without (an older or imported one).
    reading_notes : tuple of str
        What the reader found missing or left unread, and took instead, one sentence each
        (an air density never measured, sway columns a 2-DOF section does not read, a
        release row without rows left out); empty for a complete file.
    """

    path: str
    section: SectionModel
    releases: tuple[Release, ...]
    rig_name: str
    depth: float | None = None
    tubing: TubingSet | None = None
    tubing_corrected: bool = False
    cuts: tuple[str, ...] = ()
    has_forces: bool = True
    detected: tuple[ReleaseOnset, ...] = ()
    recording_warnings: tuple[str, ...] = ()
    reading_notes: tuple[str, ...] = ()


#: With ``cut_at_gaps``, a release cut before a gap is kept when at least this many periods of
#: the section's slower mode remain (E2RFC identifies releases of 3-5 periods).
MIN_CUT_PERIODS = 3.0


def read_run(path: str | os.PathLike[str], *, tubing_correction: bool = True,
             cut_at_gaps: bool = False, detect_releases: bool = False,
             displacements_only: bool = False) -> RunFile:
    """Read the section and the releases of a run file.

    Parameters
    ----------
    path : path-like
        A windrig HDF5 run file.
    tubing_correction : bool
        Correct the releases' lift and moment for the recorded tubing (default; no effect on a
        file without tubing). False: the forces as measured.
    cut_at_gaps : bool
        False (default): a gap (NaN) in a release's rows is an error. True: such a release
        ends before its first gap, or is left out when less than :data:`MIN_CUT_PERIODS`
        periods of the slower mode remain; :attr:`RunFile.cuts` says which and why (a
        campaign goes on with what its files hold). Nothing is filled either way.
    detect_releases : bool
        The file has no release rows (releases by hand without the operator's keys, a file
        imported from elsewhere): find them in ``h`` and ``alpha``
        (:func:`ident.records.release_onset.find_releases`; :attr:`RunFile.detected` holds
        each onset with its std). A file with release rows is refused: its rows say where
        its releases are.
    displacements_only : bool
        Read ``h`` and ``alpha`` alone, for the displacement-only route
        (:mod:`ident.identification.fd_method`, which never reads forces): each release's
        lift and moment are zeros, marked ``meta["forces"] = False``, and their gaps (a rig
        without taps has no forces at all) do not count.

    Returns
    -------
    RunFile

    Raises
    ------
    FileFormatError
        If the file cannot be opened as HDF5 or lacks a part of the layout, or if a release's rows
        contain gaps (NaN) and ``cut_at_gaps`` is False: identification never silently fills a
        gap.
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileFormatError(f"{path}: no such file")
    if os.path.isdir(path):
        raise FileFormatError(f"{path}: a directory, not a run file")
    try:
        handle = _open(path)
    except OSError as exc:
        reason = ("not an HDF5 file (or its first bytes are lost)"
                  if "signature" in str(exc) else f"cannot be opened as HDF5: {exc}")
        raise FileFormatError(f"{path}: {reason}") from exc
    with handle as f:
        part = "/entry/config"
        try:
            config_text = _text(f["entry/config"][()])
            sync = {}
            for name in ("time", "h", "alpha", "lift", "moment", "U", "rho"):
                part = f"/entry/sync/{name}"
                sync[name] = _column(f[part], part, path)
            for name in _SWAY_COLUMNS:  # a 3-DOF rig's file has both
                if f"entry/sync/{name}" in f:
                    part = f"/entry/sync/{name}"
                    sync[name] = _column(f[part], part, path)
            part = "/entry/releases"
            table = f["entry/releases"][()]
            _refuse(path, release_table_problem(table))
            rig_name = _text(f["entry"].attrs.get("rig_name", ""))
            part = "/entry/metadata/tubing"
            tubing_meta = (_group_dict(f[part]) if part in f else None)
            tube_temperature = _barometer_temperature(f) if tubing_meta is not None else None
            if tubing_meta is not None and tubing_correction:
                part = "/entry/sync/pressure"
                sync["pressure"] = np.asarray(f[part][()], dtype=float)
            # Dead taps (since issue 18): the forces leave them out, so must their correction.
            dead_part = "/entry/calibration/taps/dead"
            dead = (np.asarray(f[dead_part][()], dtype=np.int64) if dead_part in f
                    else np.zeros(0, dtype=np.int64))
            part = "/entry/metadata/acquisition_summary/warnings"
            recording_warnings = (tuple(_text(w) for w in np.atleast_1d(f[part][()]))
                                  if part in f else ())
            # Arm events mark where each hold starts (issue 16); a file without events has
            # none, and its holds start at the previous release's end.
            arms = np.zeros(0)
            if "entry/events" in f:
                part = "/entry/events"
                events = f["entry/events"][()]
                if events.size:
                    kinds = np.array([_text(k) for k in events["kind"]])
                    arms = np.sort(np.asarray(events["time"], dtype=float)[
                        np.isin(kinds, ("arm", "manual_hold"))])  # a catch by hand too
        except KeyError as exc:
            raise FileFormatError(f"{path}: has no {part}: not a windrig run file (or an "
                                  "incomplete one)") from exc
        except FileFormatError:
            raise  # already says what is wrong with which part
        except (OSError, RuntimeError, ValueError) as exc:
            # h5py's errors on a truncated or damaged file (OSError on reading data,
            # RuntimeError on following a link, ValueError on a bad type)
            raise FileFormatError(f"{path}: unreadable (truncated or damaged?): {exc}") from exc
    section, depth = _section(config_text, path, sync["rho"])
    if section.n_dof == 3 and not all(name in sync for name in _SWAY_COLUMNS):
        raise FileFormatError(f"{path}: its [section] has fp (3 DOF) but /entry/sync has no "
                              "p and drag: a 2-DOF recording of a 3-DOF section")
    notes = []
    if not np.isfinite(sync["rho"]).any():
        notes.append(f"/entry/sync/rho holds no air density (all NaN): the default "
                     f"{section.rho} kg/m^3 is used (the flutter speed does not depend on it; "
                     "the flutter derivatives scale with its inverse)")
    if section.n_dof == 2:  # releases of a 2-DOF section have no sway, whatever the file holds
        if all(name in sync for name in _SWAY_COLUMNS) and np.isfinite(sync["p"]).any():
            # A 3-DOF rig's file whose [section] lost fp: its sway is not read, so say so.
            notes.append("/entry/sync has sway p and drag, but its [section] has no fp: read "
                         "as 2-DOF, the sway left out (a 3-DOF section needs fp, zeta_p)")
        for name in _SWAY_COLUMNS:
            sync.pop(name, None)
    has_forces = bool(np.isfinite(sync["lift"]).any() and np.isfinite(sync["moment"]).any())
    if displacements_only:
        for name in ("lift", "moment") + (_SWAY_COLUMNS[1:] if "drag" in sync else ()):
            sync[name] = np.zeros_like(sync["time"])  # never read by the route that asked
    detected: tuple[ReleaseOnset, ...] = ()
    if detect_releases:
        if table.size:
            raise FileFormatError(f"{path}: has {table.size} release row(s) in /entry/releases;"
                                  " releases are detected only in a file without any")
        table, detected = _detected_table(sync, section, table.dtype)
        # Each detected hold starts where the model was first still (as an arm would).
        arms = np.array([onset.hold_start - HOLD_SETTLE_S for onset in detected])
    _refuse(path, shared_rows_problem(table))
    holds = _hold_rows(sync, table, arms)
    tubing = None
    if tubing_meta is not None:
        tubing, integration = _tubing(tubing_meta, config_text, path, section.rho, dead,
                                      tube_temperature or TUBING_TEMPERATURE_K)
        if tubing_correction:
            if dead.size and "pressure" in sync:  # weight 0, but a dead tap's NaN would spread
                sync["pressure"][:, dead[(dead >= 0) & (dead < sync["pressure"].shape[1])]] = 0.0
            _correct_forces(sync, table, tubing, integration, holds)
    cuts: list[str] = []
    min_s = MIN_CUT_PERIODS / min(section.fh, section.fa)
    releases = []
    for i, row in enumerate(table):
        if int(row["start_index"]) == int(row["stop_index"]):
            # The recorder writes a release commanded as the recording ended with no rows
            # (daq.recording.releases): nothing to identify, and nothing that invalidates the
            # file's other releases; left out, and said.
            notes.append(f"{empty_release(i)}: left out")
            continue
        stop = _gap_free_stop(sync, row) if cut_at_gaps else int(row["stop_index"])
        start = int(row["start_index"])
        if stop < int(row["stop_index"]):
            gap_s = float(sync["time"][stop] - row["release_time"])
            kept_s = float(sync["time"][stop - 1] - row["release_time"]) if stop > start else 0.0
            if kept_s < min_s:
                cuts.append(f"release {i} left out: a gap {gap_s:.2f} s after its release "
                            f"(less than {MIN_CUT_PERIODS:g} periods, {min_s:.2f} s)")
                continue
            cuts.append(f"release {i} cut before a gap {gap_s:.2f} s after its release")
            row = row.copy()
            row["stop_index"] = stop
        release = _release(sync, row, path, i, holds[i])
        if displacements_only:
            release.meta["forces"] = False
        releases.append(release)
    return RunFile(path=path, section=section, releases=tuple(releases), rig_name=rig_name,
                   depth=depth, tubing=tubing,
                   tubing_corrected=tubing is not None and tubing_correction, cuts=tuple(cuts),
                   has_forces=has_forces, detected=detected,
                   recording_warnings=recording_warnings, reading_notes=tuple(notes))


def _detected_table(sync: dict[str, np.ndarray], section: SectionModel,
                    dtype: np.dtype[Any]) -> tuple[np.ndarray, tuple[ReleaseOnset, ...]]:
    """Return ``/entry/releases`` rows of the releases found in h and alpha, and their onsets.

    A row as the recorder writes it: the onset, the first sync row at or after it, the row
    after the decay's end, the median wind speed over the decay, the held ``h0``, ``alpha0``
    (``p0`` NaN: not detected).
    """
    time = sync["time"]
    found = find_releases(time, sync["h"], sync["alpha"], f_min=min(section.fh, section.fa),
                          f_max=max(section.fh, section.fa))
    rows = np.zeros(len(found), dtype=dtype)
    for k, release in enumerate(found):
        start = int(np.searchsorted(time, release.onset.time, side="left"))
        stop = int(np.searchsorted(time, release.end, side="right"))
        U = sync["U"][start:stop]
        U = U[np.isfinite(U)]
        values = {"release_time": release.onset.time, "start_index": start,
                  "stop_index": stop, "U": float(np.median(U)) if U.size else np.nan,
                  "h0": release.onset.held[0], "alpha0": release.onset.held[1], "p0": np.nan}
        for name in dtype.names or ():
            rows[name][k] = values[name]
    return rows, tuple(release.onset for release in found)


def _release_channels(sync: dict[str, np.ndarray]) -> tuple[str, ...]:
    """Return the sync columns a release is made of (sway ones only kept for a 3-DOF section)."""
    return ("h", "alpha", "lift", "moment") + (_SWAY_COLUMNS if "p" in sync else ())


def _gap_free_stop(sync: dict[str, np.ndarray], row: Any) -> int:
    """Return the end row of a release's gap-free start: its first NaN row, or its stop."""
    start, stop = int(row["start_index"]), int(row["stop_index"])
    n = sync["time"].size
    if not 0 <= start < stop <= n:
        return stop  # _release says what is wrong
    bad = np.zeros(stop - start, dtype=bool)
    for name in _release_channels(sync):
        bad |= ~np.isfinite(sync[name][start:stop])
    return start + int(np.argmax(bad)) if bad.any() else stop


def _group_dict(group: Any) -> dict[str, Any]:
    """Return an HDF5 metadata group as nested dicts (strings decoded, arrays as arrays)."""
    out: dict[str, Any] = {}
    for key, item in group.items():
        if isinstance(item, h5py.Group):
            out[key] = _group_dict(item)
        else:
            value = item[()]
            out[key] = _text(value) if isinstance(value, (bytes, str)) else np.asarray(value)
    return out


def _barometer_temperature(f: Any) -> float | None:
    """Return the median air temperature the run's barometer measured, K (None without one).

    The barometer's raw stream (``/entry/instrument/<device>``, channels ``pressure``,
    ``temperature``, ...) is the only record of the temperature; readings outside
    ``_TEMPERATURE_RANGE_K`` (a disconnected probe) are not used.
    """
    instruments = f.get("entry/instrument")
    if instruments is None:
        return None
    for group in instruments.values():
        names = [_text(c) for c in group.attrs.get("channel_names", [])]
        if "temperature" not in names or "pressure" not in names or "value" not in group:
            continue
        column = np.asarray(group["value"][:, names.index("temperature")], dtype=float)
        low, high = _TEMPERATURE_RANGE_K
        valid = column[np.isfinite(column) & (column > low) & (column < high)]
        if valid.size:
            return float(np.median(valid))
    return None


def _tubing(meta: dict[str, Any], config_text: str, path: str, rho: float,
            dead: np.ndarray, temperature_k: float) -> tuple[TubingSet, np.ndarray]:
    """Return the recorded tubing and the taps' integration matrix.

    The tubes' air has the run's density ``rho`` (kg/m^3) at ``temperature_k`` (K): the
    barometer's temperature, or :data:`TUBING_TEMPERATURE_K` without one.

    The matrix is that of the forces the file holds: the live taps' (``dead`` left out, their
    lengths shared by their neighbours, :meth:`ident.physics.taps.TapLayout.without`), zero for the
    dead taps' columns.
    """
    try:
        table = tomllib.loads(config_text)["taps"]
        layout = TapLayout.from_table({k: v for k, v in table.items() if k in _LAYOUT_KEYS})
    except (tomllib.TOMLDecodeError, KeyError, TypeError, ValueError) as exc:
        raise FileFormatError(f"{path}: /entry/config has no usable [taps] for the tubing "
                              f"correction: {exc}") from exc
    groups = [meta[key] for key in sorted(meta, key=lambda k: int(k.rsplit("_", 1)[-1]))]
    for group in groups:
        if isinstance(group.get("taps"), np.ndarray):
            group["taps"] = group["taps"].tolist()
    air = Air(pressure_pa=rho * R_DRY_AIR * temperature_k, temperature_k=temperature_k)
    try:
        tubing = from_description(groups, layout.n_taps, air)
    except (TypeError, ValueError) as exc:
        raise FileFormatError(f"{path}: /entry/metadata/tubing: {exc}") from exc
    if dead.size == 0:
        return tubing, layout.integration_matrix()
    live = np.ones(layout.n_taps, dtype=bool)
    try:
        live[dead] = False
        integration = np.zeros((2, layout.n_taps))
        integration[:, live] = layout.without(dead).integration_matrix()
    except (IndexError, ValueError) as exc:
        raise FileFormatError(f"{path}: /entry/calibration/taps/dead: {exc}") from exc
    return tubing, integration


def _correct_forces(sync: dict[str, np.ndarray], table: Any, tubing: TubingSet,
                    integration: np.ndarray, holds: Sequence[slice | None]) -> None:
    """Replace each release's rows of lift and moment, and its hold's, by corrected forces."""
    time, pressure = sync["time"], sync["pressure"]
    if time.size < 2 or pressure.ndim != 2 or pressure.shape[1] != tubing.n_taps:
        return  # no pressures to correct with: _release reports the forces' own gaps
    fs = 1.0 / float(np.median(np.diff(time)))
    lift, moment = sync["lift"].copy(), sync["moment"].copy()
    spans = [(int(row["start_index"]), int(row["stop_index"])) for row in table]
    # Each hold in a window of its own: the releases' windows stay as they were.
    spans += [(hold.start, hold.stop) for hold in holds if hold is not None]
    for start, stop in spans:
        if not 0 <= start < stop <= time.size:
            continue  # _release names the bad rows
        first = max(0, start - int(round(TUBING_LEAD_S * fs)))
        # The lead must be gap-free: start after its last row with a missing force.
        holes = np.flatnonzero(~np.isfinite(sync["lift"][first:start]))
        if holes.size:
            first += int(holes[-1]) + 1
        if stop - first < 2:
            continue
        delta = force_correction(pressure[first:stop], fs, tubing, integration)
        lift[start:stop] += delta[start - first:, 0]
        moment[start:stop] += delta[start - first:, 1]
    sync["lift"], sync["moment"] = lift, moment


def _hold_rows(sync: dict[str, np.ndarray], table: Any, arms: np.ndarray) -> list[slice | None]:
    """Return the rows of ``/entry/sync`` that are each release's hold (module docstring).

    None for a release without one (fewer than 2 rows; rows that are not a release's).
    """
    time = sync["time"]
    names = _release_channels(sync)
    holds: list[slice | None] = []
    previous_stop, previous_release = 0, -np.inf
    for row in table:
        start, release_time = int(row["start_index"]), float(row["release_time"])
        first = previous_stop
        armed = arms[(arms > previous_release) & (arms < release_time)]
        if armed.size:
            first = max(first, int(np.searchsorted(time, armed[-1] + HOLD_SETTLE_S)))
        last = min(start, int(np.searchsorted(time, release_time - HOLD_GUARD_S)))
        previous_stop = max(previous_stop, int(row["stop_index"]))
        previous_release = release_time
        if not 0 <= first < last <= time.size:
            holds.append(None)
            continue
        good = np.all([np.isfinite(sync[name][first:last]) for name in names], axis=0)
        good &= np.isfinite(time[first:last])
        # The wind on: a NaN speed (no pitot reading) does not count against a row.
        U_release = float(row["U"])
        U = np.where(np.isfinite(sync["U"][first:last]), sync["U"][first:last], U_release)
        if U.size > 2 and np.isfinite(U_release):
            rows = max(1, int(round(HOLD_U_WINDOW_S / float(np.median(np.diff(time[first:last]))))))
            U = median_filter(U, size=rows, mode="nearest")
        good &= ~(np.abs(U - U_release) > HOLD_U_RTOL * abs(U_release))
        bad = np.flatnonzero(~good)
        first += int(bad[-1]) + 1 if bad.size else 0
        holds.append(slice(first, last) if last - first >= 2 else None)
    return holds


def _column(dataset: Any, part: str, path: str) -> np.ndarray:
    """Return a column of ``/entry/sync`` as float64, once checked 1-D and numeric."""
    _refuse(path, column_problem(dataset.dtype, dataset.shape, part))
    return np.asarray(dataset[()], dtype=float)


def _refuse(path: str, problem: str | None) -> None:
    """Raise a problem :mod:`ident.records.run_layout` found (None: none) as the file's."""
    if problem is not None:
        raise FileFormatError(f"{path}: {problem}")


def _open(path: str) -> h5py.File:
    """Open read-only: plainly, or as a SWMR reader when a writer has the file (or had: a crash).

    Not SWMR otherwise: a SWMR reader retries each metadata block whose checksum fails, with
    pauses, so a damaged file would take minutes to fail instead of failing at once.
    """
    try:
        return h5py.File(path, "r")
    except OSError as exc:
        if "already open for write" not in str(exc):
            raise
    return h5py.File(path, "r", libver="latest", swmr=True)


def forces_recorded(path: str | os.PathLike[str]) -> bool:
    """Tell whether a run file's ``/entry/sync`` holds any lift and moment (taps recorded).

    A rig without taps (or without a scanner) records its forces as NaN throughout. A file
    that cannot be read answers True: :func:`read_run` then says what is wrong with it.
    """
    path = os.fspath(path)
    try:
        with _open(path) as f:
            return all(bool(np.isfinite(np.asarray(f[f"entry/sync/{name}"][()],
                                                   dtype=float)).any())
                       for name in ("lift", "moment"))
    except (OSError, KeyError, RuntimeError, ValueError):  # read_run names the problem
        return True


def _text(value: Any) -> str:
    return value.decode("utf-8") if isinstance(value, bytes) else str(value)


def _section(config_text: str, path: str,
             rho: np.ndarray) -> tuple[SectionModel, float | None]:
    """Return the stored section model (with the run's air density) and its depth, m."""
    try:
        table = tomllib.loads(config_text)["section"]
        fields = {name: float(table[name]) for name in _SECTION_FIELDS if name in table}
        depth = float(table["depth"]) if "depth" in table else None
    except (tomllib.TOMLDecodeError, KeyError, TypeError, ValueError) as exc:
        raise FileFormatError(f"{path}: /entry/config has no usable [section]: {exc}") from exc
    if depth is not None and not (np.isfinite(depth) and depth > 0):
        raise FileFormatError(f"{path}: /entry/config [section] depth = {depth!r} must be > 0")
    finite = rho[np.isfinite(rho)]
    if finite.size:
        fields["rho"] = float(np.median(finite))
    try:
        return SectionModel(**fields), depth
    except (TypeError, ValueError) as exc:
        raise FileFormatError(f"{path}: [section] of the stored config: {exc}") from exc


def _release(sync: dict[str, np.ndarray], row: Any, path: str, index: int,
             hold_rows: slice | None = None) -> Release:
    start, stop = int(row["start_index"]), int(row["stop_index"])
    n = sync["time"].size
    _refuse(path, release_rows_problem(start, stop, n, index))
    names = _release_channels(sync)
    # A crash can leave one column a flush shorter than the others: only the rows a release
    # reads must exist in every column it reads.
    short = [name for name in names if sync[name].size < stop]
    if short:
        raise FileFormatError(
            f"{path}: release {index} rows {start}..{stop} run past the end of /entry/sync/"
            f"{short[0]} ({sync[short[0]].size} rows; /entry/sync/time has {n}): the columns "
            "of /entry/sync must be equally long")
    _refuse(path, release_time_problem(sync["time"], row, index))
    rows = slice(start, stop)
    channels = {name: sync[name][rows] for name in names}
    for name, values in channels.items():
        bad = int(np.count_nonzero(~np.isfinite(values)))
        if bad:
            raise FileFormatError(f"{path}: release {index} has {bad} gap sample(s) in {name}; "
                                  "cut the release before the gap")
    t = sync["time"][rows] - float(row["release_time"])
    U = float(row["U"])
    rho = sync["rho"][rows]
    rho_value = float(np.median(rho)) if np.any(np.isfinite(rho)) else None
    try:
        hold = None
        if hold_rows is not None:
            hold = ReleaseHold(t=sync["time"][hold_rows] - float(row["release_time"]),
                               **{name: sync[name][hold_rows] for name in channels})
        return Release(t=t, **channels, U=U, rho=rho_value,
                       meta={"file": path, "release": index}, hold=hold)
    except ValueError as exc:
        raise FileFormatError(f"{path}: release {index}: {exc}") from exc
