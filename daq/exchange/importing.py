"""A lab's test through its import map into a normal windrig run file.

Responsibility: :func:`import_sources` reads each source (:mod:`daq.exchange.sources`), and
for each test in it (a file, or a TDMS group) :func:`table_releases` applies the map
(:mod:`daq.exchange.import_map`): the time base, every channel converted to SI and to windrig's
signs (h and lift downward, alpha and moment nose-up), the wind speed (a value, a channel's
mean over each decay, or a Pitot's ``sqrt(2 q / rho)``), the release instants (listed, a
trigger channel's edge interpolated between samples, or found in h and alpha by
:func:`ident.records.release_onset.find_releases`) and the stretch kept around each: ``hold``
before it, and after it the decay up to the catch (the model still again, found by
:func:`ident.records.release_onset.still_start_before`, less its ``CATCH_GUARD_S``), the next
release's hold, or ``length``, whichever comes first. A catch is a step (the model pulled back
to its hold) that E2RFC would read as aerodynamics: measured on the test campaign, one sample
of it left in a decay moved the flutter speed by -0.5 % and raised its std fivefold, 0.5 s of it
by -10 %. A kept hold that reaches back into the catch is named in a warning.

The releases are written by the acquisition's own recorder
(:func:`daq.recording.synthetic.write_release_run`), so that ``windrig identify``,
``diagnose``, ``reprocess`` and ``info`` read the result as any run file;
``/entry/metadata/import`` records where it came from: the source file's name and SHA-256,
the test (TDMS group), the format and the map's text, verbatim.

A release row starts at the sample nearest the release instant (the recorder's rows are
samples): at most half a sampling interval off (1 ms at 500 Hz; a release instant 30 ms late
moves the flutter speed by about 1 %). A trigger's edge interpolated halfway between two
samples goes to the later, the first free one. Measured: a decay cut one sample (2 ms) after
its instant made E2RFC's modal fit overflow on one of six releases, hence the nearest.

Not responsible for: reading files (:mod:`daq.exchange.sources`), checking the map
(:mod:`daq.exchange.import_map`), or the command line (:mod:`daq.exchange.import_command`).
"""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from daq.config import RigConfig, load_rig_config
from daq.errors import UsageError
from daq.exchange.import_map import (
    QUANTITIES,
    UNITS,
    ChannelSpec,
    ImportMap,
    TapsSpec,
    Value,
    WindSpec,
    parse_import_map,
    parse_number,
)
from daq.exchange.sources import SourceTable, read_source, source_format
from daq.recording.synthetic import write_release_run
from daq.sync.conversions import wind_speed
from ident.errors import PlausibilityError
from ident.records.plausibility import check_units
from ident.records.release_onset import CATCH_GUARD_S, find_releases, still_start_before

__all__ = ["ImportedRelease", "ImportedRun", "import_sources", "table_releases"]

FloatArray = npt.NDArray[np.float64]

#: A time column's steps may deviate from their mean by this fraction and still be taken as
#: one sampling rate: text files round times (0.002 written as 0.002000 or 2.0E-3 and summed
#: LabVIEW timestamps drift by far less than 0.1 % of a step); anything more is a real change
#: of rate or a gap, which the run file's one time base cannot hold.
TIME_STEP_RTOL = 1e-3
#: Shortest decay kept after a release, in periods of the slower structural mode: below three
#: periods a modal fit has too little to go on (as ``find_releases``'s own ``min_periods``).
MIN_PERIODS = 3.0
#: A wind-speed channel that varies by more than this fraction over a decay is named in a
#: warning: E2RFC takes one U per release.
U_VARIATION = 0.05


@dataclass(frozen=True, eq=False)
class ImportedRelease:
    """One release of an imported test, in SI and windrig's signs (what the writer takes).

    ``t`` is s from the release instant (negative over the hold); ``lift``/``moment`` are NaN
    when the map gives no forces (the displacement-only route).
    """

    t: FloatArray
    h: FloatArray
    alpha: FloatArray
    lift: FloatArray
    moment: FloatArray
    U: float
    rho: float
    p: FloatArray | None = None
    drag: FloatArray | None = None
    instant: float = 0.0  # the release instant, s on the source's own time base
    pressure: FloatArray | None = None  # Pa, (n, n_taps), when the map gives [taps]


@dataclass(frozen=True)
class ImportedRun:
    """One run file written: its source test, releases (instant s, U m/s) and warnings."""

    source: str
    path: Path
    release_times: tuple[float, ...]
    speeds: tuple[float, ...]
    warnings: tuple[str, ...] = field(default_factory=tuple)


def _number(value: Value, table: SourceTable, of: str | None = None) -> float:
    """Return a map's number: given, given for this source, or read from a property.

    A property is looked up on the column the map names (``of``), else on ``of`` given here
    (a channel's own scale), then on the table (TDMS: group, then file).
    """
    if value.number is not None:
        return value.number
    if value.per_source is not None:
        for key in (table.name, table.path.name, table.path.stem):
            if key in value.per_source:
                return value.per_source[key]
        raise UsageError(f"{value.where}: no value for source {table.name!r}; given for "
                         f"{sorted(value.per_source)}")
    assert value.prop is not None
    raw = table.property(value.prop, value.of or of, value.where)
    return parse_number(raw, f"{table.name}: property {value.prop!r} ({value.where})")


def _convert(spec: ChannelSpec, table: SourceTable, span: float | None) -> FloatArray:
    """Return a channel in SI and windrig's signs: ``sign * factor * (scale * raw + offset)``."""
    raw = table.column(spec.column, spec.where)
    if spec.unit == "V":
        assert spec.scale is not None
        raw = _number(spec.scale, table, spec.column) * raw + (
            _number(spec.offset, table, spec.column) if spec.offset is not None else 0.0)
    factor = UNITS[QUANTITIES[spec.quantity][0]][spec.si_unit]
    if spec.total:
        if span is None:
            raise UsageError(f"{spec.where} is a total ({spec.si_unit}): give span (m, the "
                             "model's length) in the map or [section] span in the rig config, "
                             "to make it per unit span")
        factor /= span
    return np.asarray(spec.sign * factor * raw, dtype=np.float64)


def _tap_pressures(spec: TapsSpec, table: SourceTable, config: RigConfig) -> FloatArray:
    """Return the taps' pressures, Pa, shape (n, n_taps), in the rig config's tap order."""
    if spec.columns is not None:
        names = list(spec.columns)
    else:
        pattern = re.compile(re.escape(spec.prefix or "") + r"(\d+)$")
        numbered = sorted((int(m.group(1)), c) for c in table.columns
                          if (m := pattern.match(c)) is not None)
        names = [c for _, c in numbered]
    n_taps = config.taps.n_taps
    if len(names) != n_taps:
        raise UsageError(f"{table.name}: {len(names)} tap column(s) ({spec.where}) but the rig "
                         f"config has {n_taps} taps")
    factor = UNITS["pressure"][spec.unit]
    return np.column_stack([table.column(c, spec.where) for c in names]) * factor


def _speed(U: FloatArray | None, q: FloatArray | None, rho: FloatArray, rows: slice,
           wind: WindSpec, table: SourceTable) -> float:
    """Return the wind speed over some rows, m/s: the channel's mean, or from the Pitot's.

    A Pitot's speed is taken from its mean dynamic pressure, where the noise averages out
    (:func:`daq.sync.conversions.wind_speed`, whose zero tolerance refuses a mean far below
    zero: swapped lines, or a zero taken with the wind on).
    """
    if U is not None:
        return float(np.nanmean(U[rows]))
    assert q is not None and wind.pitot is not None
    w = wind_speed(float(np.nanmean(q[rows])), float(np.nanmean(rho[rows])))
    if bool(w.rejected):
        raise UsageError(f"{table.name}: the Pitot column {wind.pitot.column!r} reads "
                         f"{np.nanmean(q[rows]):.3g} Pa on average: below zero, not noise "
                         "(swapped lines, or its zero taken with the wind on?)")
    return float(w.speed)


def _time_base(imap: ImportMap, table: SourceTable, n: int) -> FloatArray:
    spec = imap.time
    if spec.rate is not None:
        return np.arange(n, dtype=np.float64) / _number(spec.rate, table)
    if spec.waveform:
        column = imap.channels["h"].column
        if column not in table.increments:
            raise UsageError(f"{table.name}: channel {column!r} has no wf_increment property "
                             f"([time] waveform = true); give [time] rate or column instead")
        step = table.increments[column]
        # Channels of one length at other rates would be read as simultaneous: refused.
        others = {spec.column: table.increments[spec.column] for spec in imap.channels.values()
                  if spec.column in table.increments}
        odd = {c: inc for c, inc in others.items() if abs(inc - step) > TIME_STEP_RTOL * step}
        if odd:
            raise UsageError(f"{table.name}: the mapped channels' wf_increment differ ({column!r}"
                             f" {step:.6g} s, {odd}); a run file holds one sampling rate")
        # LabVIEW's waveform time is wf_start_offset + i * wf_increment (a pre-trigger makes the
        # offset negative): the instants a lab lists are on that axis, as npTDMS's time_track.
        start = parse_number(table.properties.get(column, {}).get("wf_start_offset", 0.0),
                             f"{table.name}: channel {column!r} property 'wf_start_offset'")
        return start + np.arange(n, dtype=np.float64) * step
    assert spec.column is not None
    t = table.column(spec.column, f"{imap.path} [time] column") * UNITS["time"][spec.unit]
    missing = np.flatnonzero(~np.isfinite(t))
    if missing.size:  # else named as "does not increase", which sends the lab to its clock
        raise UsageError(f"{table.name}: time column {spec.column!r} has no time in "
                         f"{missing.size} row(s), the first at row {missing[0] + 1} of "
                         f"{t.size} (an empty cell, or NaN)")
    steps = np.diff(t)
    dt = float(np.mean(steps)) if steps.size else 0.0
    if not dt > 0 or np.any(steps <= 0):
        raise UsageError(f"{table.name}: time column {spec.column!r} does not increase")
    worst = float(np.max(np.abs(steps - dt)))
    if worst > TIME_STEP_RTOL * dt:
        where = int(np.argmax(np.abs(steps - dt)))
        raise UsageError(f"{table.name}: time column {spec.column!r} is not uniformly sampled "
                         f"(step {steps[where]:.6g} s at row {where + 1} against a mean "
                         f"{dt:.6g} s); a run file holds one sampling rate")
    return float(t[0]) + np.arange(n, dtype=np.float64) * dt  # a text file's rounding removed


def _crossings(t: FloatArray, x: FloatArray, threshold: float, edge: str) -> list[float]:
    """Return when a trigger channel crosses ``threshold`` on ``edge``, interpolated linearly."""
    above = x > threshold
    rows = np.flatnonzero(above[:-1] & ~above[1:] if edge == "falling" else ~above[:-1] & above[1:])
    return [float(t[i] + (threshold - x[i]) / (x[i + 1] - x[i]) * (t[i + 1] - t[i]))
            for i in rows]


def _release_times(imap: ImportMap, table: SourceTable, t: FloatArray, h: FloatArray,
                   alpha: FloatArray, config: RigConfig,
                   warnings: list[str]) -> list[float]:
    spec = imap.releases
    if spec.times is not None:
        outside = [x for x in spec.times if not t[0] <= x <= t[-1]]
        if outside:
            raise UsageError(f"{table.name}: release time(s) {outside} s ([releases] times) "
                             f"outside the record, {t[0]:.6g} to {t[-1]:.6g} s")
        return list(spec.times)
    if spec.column is not None:
        x = table.column(spec.column, f"{imap.path} [releases] column")
        threshold = (_number(spec.threshold, table) if spec.threshold is not None
                     else 0.5 * (float(np.nanmin(x)) + float(np.nanmax(x))))
        times = _crossings(t, x, threshold, spec.edge)
        if not times:
            raise UsageError(f"{table.name}: trigger channel {spec.column!r} never crosses "
                             f"{threshold:.6g} ({spec.edge}); no release found")
        return times
    section = config.section
    found = find_releases(t, h, alpha, f_min=min(section.fh, section.fa),
                          f_max=max(section.fh, section.fa))
    if not found:
        raise UsageError(f"{table.name}: no release found in h and alpha ([releases] detect): "
                         "a release needs a still hold before it; list the times instead")
    for r in found:
        if not r.onset.reliable:
            warnings.append(f"{table.name}: the release at {r.onset.time:.4f} s is weakly "
                            f"marked (snr {r.onset.snr:.0f}): its instant may be off by "
                            "several ms; list it in [releases] times if known")
    return [r.onset.time for r in found]


def table_releases(imap: ImportMap, table: SourceTable, config: RigConfig
                   ) -> tuple[list[ImportedRelease], list[str]]:
    """Apply the map to one test: its releases in SI, and the warnings.

    Raises
    ------
    UsageError
        A column, property or value is missing or wrong, or a release's hold or decay does not
        fit in the record (the message names the source and the map's key).
    """
    warnings: list[str] = []
    sway = config.section.n_dof == 3
    if sway != ("p" in imap.channels and "drag" in imap.channels):
        raise UsageError(f"{imap.path} [channels]: the rig config's section has "
                         f"{config.section.n_dof} degrees of freedom: "
                         + ("map p and drag too" if sway else "p and drag need [section] fp"))
    span = _number(imap.span, table) if imap.span is not None else config.calibration.span
    data = {name: _convert(spec, table, span) for name, spec in imap.channels.items()}
    lengths = {imap.channels[k].column: v.size for k, v in data.items()}
    if len(set(lengths.values())) != 1:
        raise UsageError(f"{table.name}: the mapped channels differ in length: {lengths}")
    n = next(iter(lengths.values()))
    if n < 2:  # no time base to speak of (an empty vector, a file cut short before its data)
        raise UsageError(f"{table.name}: the mapped channels hold {n} sample(s)"
                         + "".join(f"; {note}" for note in table.notes))
    warnings += [f"{table.name}: {note}" for note in table.notes]
    t = _time_base(imap, table, n)
    # A unit the map gets wrong (mm declared m, degrees declared rad, ms declared s) converts
    # without a word and is only refused when the run is identified: said here, at the map.
    try:
        check_units(table.name, (n - 1) / float(t[-1] - t[0]), data["h"], data["alpha"],
                    data.get("p"), config.section)
    except PlausibilityError as exc:
        raise UsageError(f"{exc}; or give the file's unit in {imap.path}") from exc
    pressures = None
    if imap.taps is not None:
        pressures = _tap_pressures(imap.taps, table, config)
        if pressures.shape[0] != n:
            raise UsageError(f"{table.name}: the taps' columns ({pressures.shape[0]} rows) and "
                             f"the channels ({n} rows) differ in length")
        if "lift" not in data:  # per unit span, windrig's signs (ident.physics.taps)
            data["lift"], data["moment"] = config.taps.integrate(pressures)
    wind = imap.wind
    rho = (np.full(n, _number(wind.rho, table)) if wind.rho is not None
           else _convert(wind.rho_channel, table, None))  # type: ignore[arg-type]
    q = U = None
    if wind.U is not None:
        U = np.full(n, _number(wind.U, table))
    elif wind.U_channel is not None:
        U = _convert(wind.U_channel, table, None)
    else:
        q = _convert(wind.pitot, table, None)  # type: ignore[arg-type]
    times = _release_times(imap, table, t, data["h"], data["alpha"], config, warnings)
    dt = float(t[1] - t[0])
    slow = 1.0 / min(config.section.fh, config.section.fa)
    hold = imap.releases.hold
    releases = []
    previous_hold: float | None = None
    for k, tr in enumerate(times):
        start = tr - hold
        if start < t[0] - dt:  # an instant between samples may put the hold half a step out
            raise UsageError(f"{table.name}: the release at {tr:.6g} s has less than hold = "
                             f"{hold:g} s before it in the record (it starts at {t[0]:.6g} s)")
        end = float(t[-1]) + 0.5 * dt
        if k + 1 < len(times):
            end = min(end, times[k + 1] - hold)
        ends = imap.releases.ends
        caught = None if ends is not None else still_start_before(
            t, data["h"], data["alpha"], after=tr,
            before=times[k + 1] if k + 1 < len(times) else float(t[-1]))
        if ends is not None:  # given: the decay is kept row for row, no catch searched
            end = min(end, ends[k])
        elif caught is not None:  # the model held still again: the catch ended the decay
            end = min(end, caught - CATCH_GUARD_S)
        # A still stretch is found up to half the stillness window late after a step (the
        # catch): CATCH_GUARD_S is that margin, as for the decay's end.
        if k > 0 and previous_hold is not None and previous_hold - CATCH_GUARD_S > start:
            warnings.append(f"{table.name}: the model is still only from {previous_hold:.4g} s "
                            f"before the release at {tr:.4g} s; hold = {hold:g} s keeps "
                            f"{previous_hold - start:.3g} s of the catch before it")
        if imap.releases.length is not None:
            end = min(end, tr + imap.releases.length)
        if end - tr < MIN_PERIODS * slow:
            raise UsageError(f"{table.name}: the release at {tr:.6g} s has {end - tr:.3g} s of "
                             f"decay, under {MIN_PERIODS:g} periods of the slower mode "
                             f"({MIN_PERIODS * slow:.3g} s)")
        # The first sample at or after each bound (1e-6 of a step for the float arithmetic of
        # the bounds): a decay ends where the next release's hold starts, no sample in both.
        rows = slice(int(np.searchsorted(t, start - 1e-6 * dt)),
                     int(np.searchsorted(t, end - 1e-6 * dt)))
        # The release row: the sample nearest the instant (a tie, as a trigger's edge halfway
        # between its samples, goes to the later, the first free sample).
        first = int(np.searchsorted(t, tr - 0.5 * dt + 1e-6 * dt))
        decay = slice(first, rows.stop)
        halves = (slice(first, (first + rows.stop) // 2), slice((first + rows.stop) // 2,
                                                                 rows.stop))
        speeds = [_speed(U, q, rho, part, wind, table) for part in (decay, *halves)]
        mean_u = speeds[0]
        if mean_u > 0 and abs(speeds[2] - speeds[1]) > U_VARIATION * mean_u:
            warnings.append(f"{table.name}: the wind speed drifts from {speeds[1]:.3g} to "
                            f"{speeds[2]:.3g} m/s (the decay's halves) over the release at "
                            f"{tr:.4g} s, more than {U_VARIATION:.0%}; their mean is used")
        previous_hold = caught
        nan = np.full(rows.stop - rows.start, math.nan)
        releases.append(ImportedRelease(
            t=t[rows] - t[first], h=data["h"][rows], alpha=data["alpha"][rows],
            lift=data["lift"][rows] if "lift" in data else nan,
            moment=data["moment"][rows] if "moment" in data else nan,
            U=mean_u, rho=float(np.nanmean(rho[decay])),
            p=data["p"][rows] if sway else None, drag=data["drag"][rows] if sway else None,
            instant=tr, pressure=pressures[rows] if pressures is not None else None))
    return releases, warnings


def _out_name(table: SourceTable) -> str:
    stem = table.path.stem
    if ":" in table.name:  # a TDMS group: one file per test
        group = re.sub(r"[^A-Za-z0-9_.-]+", "_", table.name.split(":", 1)[1]).strip("_")
        stem = f"{stem}_{group}"
    return f"{stem}.h5"


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _rig_config(imap: ImportMap) -> RigConfig:
    """Load the map's config: a path relative to the map, else as given, else a shipped name."""
    beside = imap.path.parent / imap.config
    return load_rig_config(beside if beside.is_file() else imap.config)


def import_sources(sources: Sequence[str | Path], map_path: str | Path, out_dir: str | Path
                   ) -> list[ImportedRun]:
    """Import lab files into run files, one per test.

    Parameters
    ----------
    sources : sequence of str or Path
        CSV, MATLAB (v5, v7.3) or TDMS files.
    map_path : str or Path
        The import map (``docs/guides/import_export.md``).
    out_dir : str or Path
        Where the run files go (created if missing); an existing file is never overwritten.

    Returns
    -------
    list of ImportedRun
        One per run file written, in the order of the sources.

    Raises
    ------
    UsageError
        A source, the map or the config is wrong (naming the file, channel or key), or a run
        file would overwrite one that exists. Nothing is written unless every source imports.
    """
    imap = parse_import_map(map_path)
    config = _rig_config(imap)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out}: not a directory")
    planned: list[tuple[SourceTable, Path, list[ImportedRelease], list[str], str]] = []
    for source in sources:
        path = Path(source)
        fmt = source_format(path, imap.format)
        for table in read_source(path, fmt, imap.groups):
            releases, warnings = table_releases(imap, table, config)
            target = out / _out_name(table)
            if target.exists() or any(p[1] == target for p in planned):
                raise UsageError(f"{target}: exists (or two sources make it); remove it or "
                                 "choose another --out")
            planned.append((table, target, releases, warnings, fmt))
    out.mkdir(parents=True, exist_ok=True)
    done = []
    for table, target, releases, warnings, fmt in planned:
        provenance: dict[str, Any] = {
            "source": table.path.name, "sha256": _sha256(table.path), "format": fmt,
            "test": table.name.split(":", 1)[1] if ":" in table.name else "",
            "map_file": imap.path.name, "map": imap.text,
        }
        pressures = ([r.pressure for r in releases]
                     if all(r.pressure is not None for r in releases) else None)
        write_release_run(target, config, releases, pressures, metadata={"import": provenance})
        done.append(ImportedRun(source=table.name, path=target,
                                release_times=tuple(r.instant for r in releases),
                                speeds=tuple(r.U for r in releases),
                                warnings=tuple(warnings)))
    return done
