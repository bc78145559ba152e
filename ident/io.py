"""The one thin module through which :mod:`ident` reads run files (``docs/file_format.md``).

It reads the synchronised view ``/entry/sync``, the releases table ``/entry/releases`` and the
section model from the rig config stored verbatim in ``/entry/config``, and returns
:class:`~ident.release.Release` objects and a :class:`~ident.section.SectionModel`. Nothing else
in :mod:`ident` touches files. Files are opened read-only, as SWMR readers when a writer has them
open, so a run still being written, or one left by a crash, can be read as well as a finished one.

Errors are specific: a missing file or dataset, a truncated file, or a release whose rows hold
gaps (NaN) raises :class:`FileFormatError` (a ``ValueError``) naming the file and what is wrong.
"""

from __future__ import annotations

import os
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import h5py
import numpy as np

from ident.errors import IdentError
from ident.release import Release
from ident.section import SectionModel

__all__ = ["FileFormatError", "RunFile", "campaign_section", "read_run"]

_SECTION_FIELDS = ("B", "m", "I", "fh", "fa", "zeta_h", "zeta_a", "S")


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
    """

    path: str
    section: SectionModel
    releases: tuple[Release, ...]
    rig_name: str
    depth: float | None = None


def read_run(path: str | os.PathLike[str]) -> RunFile:
    """Read the section and the releases of a run file.

    Parameters
    ----------
    path : path-like
        A windrig HDF5 run file.

    Returns
    -------
    RunFile

    Raises
    ------
    FileFormatError
        If the file cannot be opened as HDF5 or lacks a part of the layout, or if a release's rows
        contain gaps (NaN): identification never silently fills a gap.
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
                sync[name] = np.asarray(f[part][()], dtype=float)
            part = "/entry/releases"
            table = f["entry/releases"][()]
            rig_name = _text(f["entry"].attrs.get("rig_name", ""))
        except KeyError as exc:
            raise FileFormatError(f"{path}: has no {part}: not a windrig run file (or an "
                                  "incomplete one)") from exc
        except (OSError, RuntimeError, ValueError) as exc:
            # h5py's errors on a truncated or damaged file (OSError on reading data,
            # RuntimeError on following a link, ValueError on a bad type)
            raise FileFormatError(f"{path}: unreadable (truncated or damaged?): {exc}") from exc
    section, depth = _section(config_text, path, sync["rho"])
    releases = tuple(_release(sync, row, path, i) for i, row in enumerate(table))
    return RunFile(path=path, section=section, releases=releases, rig_name=rig_name,
                   depth=depth)


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


def campaign_section(runs: Sequence[RunFile]) -> SectionModel:
    """Return the one section model of a campaign's run files, with the median air density.

    Parameters
    ----------
    runs : sequence of RunFile
        Files of one campaign (one section model, any wind speeds).

    Returns
    -------
    SectionModel
        The stored section with ``rho`` the median of the files' measured densities.

    Raises
    ------
    FileFormatError
        If there are no runs, or if the files' sections differ (other than in air density):
        releases of different models cannot be identified together.
    """
    if not runs:
        raise FileFormatError("no run files given")
    first = runs[0].section
    for run in runs[1:]:
        if run.section.replace(rho=first.rho) != first:
            raise FileFormatError(f"{run.path}: its section model differs from the one of "
                                  f"{runs[0].path}; identify one section model at a time")
    return first.replace(rho=float(np.median([run.section.rho for run in runs])))


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


def _release(sync: dict[str, np.ndarray], row: Any, path: str, index: int) -> Release:
    start, stop = int(row["start_index"]), int(row["stop_index"])
    n = sync["time"].size
    if not 0 <= start < stop <= n:
        raise FileFormatError(f"{path}: release {index} rows {start}..{stop} are outside the "
                              f"{n} rows of /entry/sync (truncated run?)")
    rows = slice(start, stop)
    channels = {name: sync[name][rows] for name in ("h", "alpha", "lift", "moment")}
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
        return Release(t=t, **channels, U=U, rho=rho_value,
                       meta={"file": path, "release": index})
    except ValueError as exc:
        raise FileFormatError(f"{path}: release {index}: {exc}") from exc
