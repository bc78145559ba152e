"""``windrig reprocess``: whole campaigns of run files, again, on Dask (a laptop or a cluster).

Responsibility: :func:`reprocess` expands paths and globs into run files and hands each to a
``dask.distributed`` worker (:func:`process_file`: opens it read-only, reads its releases, fits
each release's modes; returns plain numbers and arrays, never h5py objects). Files are grouped
into campaigns by the rig and section model stored in them; each campaign is a second task
(:func:`process_campaign`: E2RFC on all its releases, the flutter speed, the discrepancy check).
Only the client writes: the summary tables (CSV and JSON, per release and per campaign), plots
per campaign and a static HTML report linking them, into the output directory. A file that
cannot be read (truncated, not HDF5, no releases) is reported with its reason and the others go
on. Finished files are cached in ``OUT/cache`` under a key of their path, size and
modification time (the per-file work does not depend on the settings), so a second run reads
again only files that changed; the campaigns, which the settings do change, are always redone.

The cluster (:func:`daq.offline.cluster.dask_client`, shared with ``windrig bridge
--uncertainty``): a ``LocalCluster`` of ``workers`` single-threaded processes by default; with
``scheduler`` an existing one (``tcp://host:8786``) is used instead, and nothing else changes.

Not responsible for: the numerics (:mod:`ident`), reading files (:mod:`ident.records.run_file`).
"""

from __future__ import annotations

import dataclasses
import glob
import hashlib
import json
import math
import os
import pickle
import time
import tomllib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from daq.offline.cluster import dask_client
from daq.offline.report import ReprocessSummary, write_outputs
from ident.discrepancy.workflow import diagnose
from ident.errors import IdentError
from ident.identification.campaign import analyze_campaign
from ident.identification.modal import fit_release_modes
from ident.model.section import SectionModel
from ident.records.release import Release
from ident.records.run_file import read_run
from ident.records.run_set import differing_parameters, recording_notes, section_difference

__all__ = ["ReprocessSettings", "expand_paths", "load_reprocess_config",
           "process_campaign", "process_file", "reprocess"]

#: A campaign whose section differs from another's in at most this many stored parameters is
#: warned of: more likely one model with a slip in one file's config than another model.
NEAR_SECTION_PARAMETERS = 2

#: Bumped when the per-file results change meaning: old cache entries are then not reused.
CACHE_VERSION = 4  # 2: a file result has the section depth; 3: its recording warnings;
# 4: its reading notes (a default air density, sway not read) among them


@dataclass(frozen=True)
class ReprocessSettings:
    """What a reprocessing run may change (``--set name=value``).

    Attributes
    ----------
    n_lags : int or None
        E2RFC's number of lags (None: chosen by held-out error, as ``windrig identify``).
    with_A3 : bool or None
        Fit the added-mass matrix (None: chosen).
    diagnose : bool
        Run the discrepancy check on each campaign.
    depth : float or None
        Section depth for a shedding line's Strouhal number, m (None: the ``depth`` stored in
        the campaign's first run file, as ``windrig diagnose``; per metre without one).
    """

    n_lags: int | None = None
    with_A3: bool | None = None
    diagnose: bool = True
    depth: float | None = None

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], where: str,
                     base: ReprocessSettings | None = None) -> ReprocessSettings:
        """Return ``base`` (default: the defaults) with the settings of a TOML table.

        Raises
        ------
        ValueError
            An unknown name or a value of the wrong type, naming ``where``.
        """
        names = {f.name: f for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - set(names))
        if unknown:
            raise ValueError(f"{where}: unknown setting(s) {unknown}; known: {sorted(names)}")
        checked: dict[str, Any] = {}
        for name, value in values.items():
            if value is None or (name in ("with_A3", "diagnose") and isinstance(value, bool)):
                checked[name] = value
            elif name == "n_lags" and isinstance(value, int) and not isinstance(value, bool):
                checked[name] = value
            elif (name == "depth" and isinstance(value, (int, float))
                  and not isinstance(value, bool)):
                checked[name] = float(value)
            else:
                raise ValueError(f"{where}: {name} = {value!r} has the wrong type "
                                 f"({names[name].type})")
        return dataclasses.replace(base or cls(), **checked)

    @classmethod
    def parse(cls, assignments: Iterable[str],
              base: ReprocessSettings | None = None) -> ReprocessSettings:
        """Build settings from ``name=value`` strings (``none``, ``true``/``false``, numbers).

        Raises
        ------
        ValueError
            An unknown name or a value of the wrong kind, with the name.
        """
        names = {f.name for f in dataclasses.fields(cls)}
        values: dict[str, Any] = {}
        for item in assignments:
            name, sep, text = item.partition("=")
            name = name.strip().replace("-", "_")
            if not sep or name not in names:
                raise ValueError(f"--set {item!r}: expected name=value with name one of "
                                 f"{sorted(names)}")
            values[name] = _parse_value(name, text.strip())
        return dataclasses.replace(base or cls(), **values)

    def key(self) -> str:
        """Return a short hash of the settings (part of the cache key)."""
        text = json.dumps(dataclasses.asdict(self), sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def _parse_value(name: str, text: str) -> Any:
    lowered = text.lower()
    if lowered == "none":
        return None
    if name in ("with_A3", "diagnose"):
        if lowered in ("true", "1", "yes"):
            return True
        if lowered in ("false", "0", "no"):
            return False
        raise ValueError(f"--set {name}={text}: expected true or false")
    try:
        return int(text) if name == "n_lags" else float(text)
    except ValueError:
        raise ValueError(f"--set {name}={text}: expected a number") from None


def load_reprocess_config(path: str | os.PathLike[str]) -> tuple[ReprocessSettings,
                                                                dict[str, list[str]]]:
    """Read a reprocessing config: settings and, optionally, the campaigns by name.

    The TOML file may hold ``[reprocess]`` (the :class:`ReprocessSettings` names) and
    ``[campaigns]`` (``name = ["run files, directories or globs", ...]``, relative to the
    file's directory). Named campaigns replace the grouping by stored section model.

    Raises
    ------
    ValueError
        The file is not TOML, or a table or value is malformed (the message names it).
    """
    where = os.fspath(path)
    try:
        data = tomllib.loads(Path(path).read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ValueError(f"{where}: cannot read the reprocessing config: {exc}") from exc
    unknown = sorted(set(data) - {"reprocess", "campaigns"})
    if unknown:
        raise ValueError(f"{where}: unknown table(s) {unknown}; known: reprocess, campaigns")
    settings = ReprocessSettings.from_mapping(data.get("reprocess", {}), f"{where} [reprocess]")
    base = Path(path).resolve().parent
    campaigns: dict[str, list[str]] = {}
    for name, items in data.get("campaigns", {}).items():
        if not (isinstance(items, list) and items and all(isinstance(i, str) for i in items)):
            raise ValueError(f"{where} [campaigns] {name}: expected a list of paths or globs")
        campaigns[name] = [i if os.path.isabs(i) else str(base / i) for i in items]
    return settings, campaigns


# -- tasks (run on the workers) -----------------------------------------------------------------

def process_file(path: str) -> dict[str, Any]:
    """Read one run file and fit its releases' modes (a worker task).

    Parameters
    ----------
    path : str
        The run file (opened read-only).

    Returns
    -------
    dict
        ``path``, and either ``error`` (the reason the file cannot be used) or ``rig``,
        ``section`` (dict), ``depth`` (m, or None), ``campaign`` (the grouping key) and
        ``releases``: per release its
        arrays (``t``, ``h``, ``alpha``, ``lift``, ``moment``), ``U``, ``rho``, ``index`` and
        its modes (``f_h``, ``zeta_h``, ``f_a``, ``zeta_a``; NaN with ``modal_error`` when the
        fit fails), and ``recording_warnings`` (its writer's, led by its path: they join its
        campaign's ``warnings``).
    """
    try:
        run = read_run(path)
    except IdentError as exc:
        return {"path": path, "error": str(exc)}
    if not run.releases:
        return {"path": path, "error": f"{path}: no releases in /entry/releases"}
    section = run.section
    releases = []
    for i, r in enumerate(run.releases):
        item: dict[str, Any] = {"index": i, "U": float(r.U), "rho": r.rho,
                                **{name: np.asarray(getattr(r, name)) for name in
                                   ("t", "h", "alpha", "lift", "moment")}}
        try:
            modal = fit_release_modes(r.t, r.h, r.alpha, section)
            item.update(dataclasses.asdict(modal))
        except IdentError as exc:
            item.update(f_h=math.nan, zeta_h=math.nan, f_a=math.nan, zeta_a=math.nan,
                        modal_error=str(exc))
        releases.append(item)
    shape = section.replace(rho=1.0).to_dict()  # the model; air density differs by run
    return {"path": path, "rig": run.rig_name, "section": section.to_dict(), "depth": run.depth,
            "campaign": f"{run.rig_name} {json.dumps(shape, sort_keys=True)}",
            "releases": releases, "recording_warnings": recording_notes([run])}


def process_campaign(name: str, files: list[dict[str, Any]],
                     settings: ReprocessSettings) -> dict[str, Any]:
    """Identify one campaign from its files' results (a worker task).

    The section is the files' stored one with the median of their air densities, and the
    releases are taken file by file in path order: exactly what ``windrig identify`` does with
    the same files, so the numbers agree.

    Returns
    -------
    dict
        ``files``, ``n_releases``, ``wind_speeds``, and ``model`` (dict), ``structure``,
        ``flutter_speed``, ``flutter_std`` (all parts:
        :class:`ident.identification.uncertainty.FlutterUncertainty`),
        ``flutter_std_parts``, ``warnings`` (the files' recording warnings and reading notes,
        also when E2RFC fails, then E2RFC's), ``flutter_frequency``, ``flutter_structures`` (the
        flutter speed of every structure within one standard error of the best, by label, None
        for no flutter), ``effect`` and the gaps (with ``diagnose``: ``effects``, the named
        effects in the order added with the gap after each, ``explained`` and ``unexplained``,
        the located residual in words), or
        ``error`` when E2RFC cannot identify a model (one wind speed).
    """
    files = sorted(files, key=lambda f: f["path"])
    sections = [SectionModel.from_dict(f["section"]) for f in files]
    # The files' own warnings are kept even when the campaign cannot be identified.
    out: dict[str, Any] = {"name": name, "files": [f["path"] for f in files],
                           "warnings": [w for f in files for w in f["recording_warnings"]]}
    for f, s in zip(files[1:], sections[1:], strict=True):
        if s.replace(rho=sections[0].rho) != sections[0]:
            out["error"] = (f"{f['path']}: its section model differs from that of "
                            f"{files[0]['path']}; one campaign is one section model")
            return out
    section = sections[0].replace(rho=float(np.median([s.rho for s in sections])))
    releases = [Release(t=r["t"], h=r["h"], alpha=r["alpha"], lift=r["lift"],
                        moment=r["moment"], U=r["U"], rho=r["rho"],
                        meta={"file": f["path"], "release": r["index"]})
                for f in files for r in f["releases"]]
    out.update(n_releases=len(releases), wind_speeds=sorted({round(r.U, 2) for r in releases}),
               section=section.to_dict())
    try:
        analysis = analyze_campaign(releases, section, n_lags=settings.n_lags,
                                    with_A3=settings.with_A3, table=False)
    except IdentError as exc:
        out["error"] = f"{type(exc).__name__}: {exc}"
        return out
    model, result = analysis.model, analysis.flutter
    summary = analysis.to_dict()
    out.update(model=summary["model"], structure=summary["reason"],
               flutter_speed=analysis.flutter_speed, flutter_std=analysis.flutter_std,
               flutter_frequency=analysis.flutter_frequency,
               flutter_structures=summary["flutter_structures"],
               flutter_speed_low=summary["flutter_speed_low"],
               flutter_speed_high=summary["flutter_speed_high"],
               flutter_std_parts=summary["flutter_std_parts"],
               warnings=[*out["warnings"], *summary["warnings"]],
               K=analysis.K, derivatives=analysis.derivatives,
               curves={"U": result.U, "frequencies": result.frequencies,
                       "damping": result.damping, "mode_names": list(result.mode_names)})
    if settings.diagnose:
        depth = settings.depth if settings.depth is not None else files[0].get("depth")
        report = diagnose(releases, section, baseline=model, depth=depth)
        out.update(effect=report.effect, effect_parameters=report.parameters,
                   gap_before=report.gap_before, gap_after=report.gap_after,
                   runner_up=report.runner_up,
                   effects=[{"effect": step.name, "parameters": step.parameters,
                             "uncertainty": step.uncertainty, "gap_after": step.gap_after}
                            for step in report.effects],
                   explained=report.explained,
                   unexplained=[f.text() for f in report.unexplained])
    return out


# -- the client -----------------------------------------------------------------------------------


def expand_paths(items: Sequence[str | os.PathLike[str]]) -> list[str]:
    """Return the run files named by paths, directories (their ``*.h5``) and globs, sorted.

    Raises
    ------
    FileNotFoundError
        An item matches nothing.
    """
    found: set[str] = set()
    for item in items:
        text = os.fspath(item)
        if os.path.isdir(text):
            matches = glob.glob(os.path.join(text, "*.h5"))
        elif glob.has_magic(text):
            matches = glob.glob(text)
        else:
            matches = [text] if os.path.exists(text) else []
        if not matches:
            raise FileNotFoundError(f"{text}: no such run file (or nothing matches)")
        found.update(os.path.abspath(m) for m in matches)
    return sorted(found)


def reprocess(paths: Sequence[str | os.PathLike[str]], out: str | os.PathLike[str], *,
              workers: int | None = None, scheduler: str | None = None,
              settings: ReprocessSettings | None = None,
              campaigns: Mapping[str, Sequence[str]] | None = None,
              progress: bool = True) -> ReprocessSummary:
    """Reprocess run files on Dask; write the tables, plots and report (module docstring).

    Parameters
    ----------
    paths : sequence of path-like
        Run files, directories and globs.
    out : path-like
        Output directory (created).
    workers : int, optional
        Local worker processes (default: the machine's cores); ignored with ``scheduler``.
    scheduler : str, optional
        Address of an existing Dask scheduler.
    settings : ReprocessSettings, optional
        Identification settings (default: those of ``windrig identify``).
    campaigns : mapping of str to sequence of str, optional
        Named campaigns (paths, directories, globs each): they replace the grouping by stored
        section model, and their files are added to ``paths``.
    progress : bool
        Show a progress bar.

    Returns
    -------
    ReprocessSummary
    """
    # dask is an optional dependency (the ``dask`` extra): only this command needs it.
    from dask.distributed import as_completed

    settings = settings or ReprocessSettings()
    out_dir = Path(out)
    cache_dir = out_dir / "cache"
    cache_dir.mkdir(parents=True, exist_ok=True)
    named: dict[str, str] = {}  # file -> campaign name
    for name, items in (campaigns or {}).items():
        for path in expand_paths(items):
            if named.setdefault(path, name) != name:
                raise ValueError(f"{path} is in two campaigns: {named[path]} and {name}")
    files = sorted(set(expand_paths(paths) if paths else []) | set(named))
    if not files:
        raise FileNotFoundError("no run files given")
    summary = ReprocessSummary(files=files)
    started = time.monotonic()
    results: dict[str, dict[str, Any]] = {}
    todo = []
    for path in files:
        cached = _cache_load(cache_dir, path)
        if cached is not None:
            results[path] = cached
            summary.reused.append(path)
        else:
            todo.append(path)

    t_cluster = time.monotonic()
    with dask_client(workers, scheduler) as client:
        summary.timings["cluster start"] = time.monotonic() - t_cluster
        futures = client.map(process_file, todo, pure=False)
        bar = tqdm(total=len(files), initial=len(files) - len(todo), unit="file",
                   disable=not progress, desc="files")
        for future in as_completed(futures):
            path = todo[futures.index(future)]
            try:
                result = future.result()
            except Exception as exc:  # a worker's unexpected failure: reported, not fatal
                result = {"path": path, "error": f"{type(exc).__name__}: {exc}"}
            results[path] = result
            _cache_store(cache_dir, path, result)
            bar.update(1)
        bar.close()
        summary.timings["files"] = time.monotonic() - t_cluster - summary.timings["cluster start"]

        t1 = time.monotonic()
        groups: dict[str, list[dict[str, Any]]] = {}
        for path in files:
            result = results[path]
            if "error" in result:
                summary.failed[path] = result["error"]
            elif named:
                if path in named:  # files outside the named campaigns are read, not grouped
                    groups.setdefault(named[path], []).append(result)
            else:
                groups.setdefault(result["campaign"], []).append(result)
        labels = {key: key if named else f"campaign_{i + 1}" for i, key in enumerate(groups)}
        campaign_futures = [client.submit(process_campaign, labels[key], group, settings,
                                          pure=False) for key, group in groups.items()]
        near = {} if named else _near_sections(groups, labels)
        for key, future in zip(groups, campaign_futures, strict=True):
            try:
                summary.campaigns.append(future.result())
            except Exception as exc:  # reported with the campaign's files
                summary.campaigns.append({"name": labels[key],
                                          "files": [f["path"] for f in groups[key]],
                                          "error": f"{type(exc).__name__}: {exc}"})
            campaign = summary.campaigns[-1]
            campaign["warnings"] = [*near.get(key, []), *campaign.get("warnings", [])]
        summary.timings["campaigns"] = time.monotonic() - t1

    t2 = time.monotonic()
    summary.outputs = write_outputs(out_dir, results, summary)
    summary.timings["outputs"] = time.monotonic() - t2
    summary.timings["total"] = time.monotonic() - started
    return summary


def _near_sections(groups: Mapping[str, list[dict[str, Any]]],
                   labels: Mapping[str, str]) -> dict[str, list[str]]:
    """Return warnings for campaigns whose sections differ from an earlier one's only slightly.

    Files are grouped by their stored section: two files of one campaign whose configs differ
    by a typo (``fh = 2.1`` for ``2.0``) become two campaigns, each with fewer wind speeds,
    and nothing else would say why. Sections that differ in at most
    :data:`NEAR_SECTION_PARAMETERS` parameters (air density aside) are named.
    """
    sections = {key: SectionModel.from_dict(group[0]["section"]) for key, group in groups.items()}
    out: dict[str, list[str]] = {}
    keys = list(groups)
    for j, key in enumerate(keys):
        for other in keys[:j]:
            differing = differing_parameters(sections[key], sections[other])
            if 0 < len(differing) <= NEAR_SECTION_PARAMETERS:
                out.setdefault(key, []).append(
                    f"its files' section differs from {labels[other]}'s only in "
                    f"{section_difference(sections[key], sections[other])}: one section model "
                    "with a slip in one file's config? (files are grouped by their stored "
                    "section; a reprocessing config's [campaigns] groups them by name)")
    return out


# -- cache ------------------------------------------------------------------------------------

def _cache_key(path: str) -> str | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    text = f"{CACHE_VERSION} {path} {st.st_size} {st.st_mtime_ns}"
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def _cache_file(cache_dir: Path, path: str) -> Path:
    return cache_dir / (hashlib.sha256(path.encode()).hexdigest()[:24] + ".pkl")


def _cache_load(cache_dir: Path, path: str) -> dict[str, Any] | None:
    key = _cache_key(path)
    entry = _cache_file(cache_dir, path)
    if key is None or not entry.exists():
        return None
    try:
        with entry.open("rb") as f:
            stored = pickle.load(f)  # noqa: S301 - our own cache, written by this function
    except (OSError, pickle.UnpicklingError, EOFError):
        return None  # a damaged cache entry is redone
    if not isinstance(stored, dict) or stored.get("key") != key:
        return None
    result = stored.get("result")
    return result if isinstance(result, dict) else None


def _cache_store(cache_dir: Path, path: str, result: dict[str, Any]) -> None:
    key = _cache_key(path)
    if key is None:
        return
    entry = _cache_file(cache_dir, path)
    tmp = entry.with_suffix(".tmp")
    with tmp.open("wb") as f:
        pickle.dump({"key": key, "result": result}, f)
    tmp.replace(entry)  # atomic: an interrupted run leaves no half entry


# -- outputs ----------------------------------------------------------------------------------

