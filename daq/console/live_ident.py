"""The console's releases table: each free decay's frequency and damping, then E2RFC, as they come.

Responsibility: :class:`LiveIdentifier`, polled from the GUI timer, watches the free decays of a
source (``source.decays()``: release instants and, once the model is armed again, the end of each
decay) and, as soon as a decay is complete, cuts its rows out of the source's buffer, checks them
(gaps, length, wind) and has a worker process fit its two modes
(:func:`ident.identification.modal.fit_release_modes`: frequency and damping ratio of the heave- and
pitch-dominated modes). Once usable releases exist at two or more wind speeds, the worker identifies
the rational-function model from all of them together (:func:`identify_releases`, which is
:func:`ident.identification.campaign.analyze_campaign`: E2RFC, the flutter speed with its standard
deviation and warnings, the model's flutter derivatives, and the indirect method's table of flutter
derivatives from the same decays to plot against), again whenever a release is added.

A section with sway (three degrees of freedom): the decays carry ``p`` and ``drag`` too (the
releases E2RFC identifies in 3x3); the table's modes are still the heave and pitch ones, fitted
from h and alpha as for 2 DOF (the section's heave-pitch part).

The fits run in one worker *process*: a campaign fit takes ~1 s of CPU, which in the console's
process would hold the interpreter lock against the acquisition threads and the redraws. The
GUI thread only submits jobs and collects finished ones; nothing here blocks it.

Not responsible for: drawing (:mod:`daq.console.releases_panel`), where the decays come from
(:meth:`daq.console.live_source.LiveSource.decays`, :meth:`daq.console.replay.ReplaySource.decays`),
or the numerics (:mod:`ident`).
"""

from __future__ import annotations

import logging
import math
import multiprocessing
from collections.abc import Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from daq.procedure import default_decay_s
from ident.errors import IdentError
from ident.identification import results
from ident.identification.campaign import CampaignAnalysis, analyze_campaign
from ident.identification.modal import ReleaseModes, fit_release_modes
from ident.model.section import SectionModel
from ident.records.release import Release

__all__ = ["DECAY_COLUMNS", "MIN_DECAY_S", "STILL_AIR_U", "SWAY_COLUMNS", "DecaySource",
           "LiveIdentifier", "ReleaseRow", "identify_releases"]

log = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]

#: The sync-view columns a decay is cut from (a 3-DOF rig's add :data:`SWAY_COLUMNS`).
DECAY_COLUMNS = ("time", "h", "alpha", "lift", "moment", "U", "rho")
#: The sway and drag of a 3-DOF rig's decays.
SWAY_COLUMNS = ("p", "drag")
#: Shortest decay worth a modal fit, s (a release caught sooner is listed, not fitted).
MIN_DECAY_S = 2.0
#: Below this mean wind speed a release is a still-air decay (fitted, not used by E2RFC), m/s.
STILL_AIR_U = 0.5


class DecaySource(Protocol):
    """What the identifier reads: the decays and the buffer of the sync view."""

    def decays(self) -> list[tuple[float, float | None]]:
        """Return the release instants and decay ends (None: still decaying), s from the start."""
        ...

    def snapshot(self, last: int | None = None,
                 columns: Sequence[str] | None = None) -> dict[str, npt.NDArray[Any]]:
        """Return copies of the most recent sync rows, oldest first."""
        ...


@dataclass(frozen=True)
class ReleaseRow:
    """One line of the releases table.

    Attributes
    ----------
    number : int
        1, 2, ... in the order of the releases.
    release_s : float
        Release instant, s from the run start.
    length_s : float
        Length of the decay cut, s (NaN while it goes on).
    U : float
        Median wind speed over the decay, m/s (NaN while it goes on).
    modal : ReleaseModes or None
        The fitted modes, once fitted.
    status : str
        ``"decaying"``, ``"fitting"``, ``"ok"`` (used by E2RFC), ``"still air"`` (fitted, not
        used by E2RFC), or why the release is not used (a gap, too short, a failed fit).
    release : Release or None
        The decay, when it can be used by E2RFC.
    """

    number: int
    release_s: float
    length_s: float = math.nan
    U: float = math.nan
    modal: ReleaseModes | None = None
    status: str = "decaying"
    release: Release | None = field(default=None, repr=False)

    @property
    def usable(self) -> bool:
        """Tell whether E2RFC uses this release (fitted, wind on, no gap)."""
        return self.status == "ok" and self.release is not None


def identify_releases(releases: Sequence[Release], section: SectionModel) -> CampaignAnalysis:
    """Analyse the session's usable releases (``analyze_campaign``).

    Raises
    ------
    IdentError
        E2RFC cannot identify a model from these releases (one wind speed, rank deficiency).
    """
    return analyze_campaign(releases, section)


def _spawn_executor() -> Executor:
    # spawn, not fork: the console's process runs Qt and the acquisition threads.
    return ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn"))


class LiveIdentifier:
    """Fits the session's releases as they complete (see the module docstring).

    Parameters
    ----------
    section : SectionModel
        The rig's section model (the air density is replaced by the decays' measured one).
    rate_hz : float
        Row rate of the sync view, Hz.
    decay_s : float, optional
        A decay not ended by arming again is cut after this long, s; default
        :func:`daq.procedure.default_decay_s` (15 periods of the slower mode).
    executor : Executor, optional
        Where the fits run; default one spawned worker process, created at the first fit.

    Attributes
    ----------
    rows : list of ReleaseRow
        The releases table, oldest first.
    campaign : CampaignAnalysis or None
        The latest model identified from all usable releases.
    campaign_status : str
        What the model part is doing or why there is none (shown under the table).
    """

    def __init__(self, section: SectionModel, rate_hz: float, *, decay_s: float | None = None,
                 executor: Executor | None = None) -> None:
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"rate_hz = {rate_hz!r} must be a number of Hz > 0")
        self.section = section
        sway = section.n_dof == 3
        self._columns = DECAY_COLUMNS + (SWAY_COLUMNS if sway else ())
        # The table's heave and pitch modes come from h and alpha: the heave-pitch section.
        self._modal_section = (section.replace(fp=None, zeta_p=None, m_p=None) if sway
                               else section)
        self.rate_hz = float(rate_hz)
        self.decay_s = float(default_decay_s(section) if decay_s is None else decay_s)
        if not (math.isfinite(self.decay_s) and self.decay_s >= MIN_DECAY_S):
            raise ValueError(f"decay_s = {decay_s!r} must be a number of seconds >= "
                             f"{MIN_DECAY_S:g}")
        self._executor = executor
        self._own_executor = executor is None
        self.rows: list[ReleaseRow] = []
        self.campaign: CampaignAnalysis | None = None
        self.campaign_status = "releases at two or more wind speeds give the E2RFC model"
        self._modal_jobs: dict[int, Future[ReleaseModes]] = {}
        self._campaign_job: Future[CampaignAnalysis] | None = None
        self._campaign_inputs: tuple[int, ...] = ()  # the row numbers of the running/last fit
        self._closed = False

    # -- polling (GUI thread) --------------------------------------------------------------------
    def update(self, source: DecaySource) -> bool:
        """Cut the decays that completed, collect finished fits, start the next ones.

        Parameters
        ----------
        source : DecaySource
            The console's source (``decays()`` and ``snapshot()``).

        Returns
        -------
        bool
            Whether the table or the model changed (the panel redraws then).
        """
        if self._closed:
            return False
        changed = self._cut_decays(source)
        changed |= self._collect_modal()
        changed |= self._collect_campaign()
        self._start_campaign()
        return changed

    @property
    def busy(self) -> bool:
        """Tell whether a fit is running."""
        return bool(self._modal_jobs) or self._campaign_job is not None

    def close(self) -> None:
        """Cancel pending fits and stop the worker (idempotent)."""
        self._closed = True
        executor, self._executor = self._executor, None
        if executor is not None and self._own_executor:
            executor.shutdown(wait=True, cancel_futures=True)

    # -- decays ----------------------------------------------------------------------------------
    def _cut_decays(self, source: DecaySource) -> bool:
        decays = source.decays()
        changed = False
        while len(self.rows) < len(decays):
            number = len(self.rows) + 1
            self.rows.append(ReleaseRow(number=number, release_s=decays[number - 1][0]))
            changed = True
        pending = [row for row in self.rows if row.status == "decaying"]
        if not pending:
            return changed
        latest = source.snapshot(1, columns=("time",))["time"]
        if latest.size == 0:
            return changed
        t_latest = float(latest[-1])
        snap: dict[str, npt.NDArray[Any]] | None = None
        for row in pending:
            i = row.number - 1
            release, caught = decays[i]
            end = release + self.decay_s
            if caught is not None:
                end = min(end, caught)
            if i + 1 < len(decays):  # released again without arming: this decay ends there
                end = min(end, decays[i + 1][0] - 1.0 / self.rate_hz)
            if t_latest < end:
                break  # later decays are not complete either
            if snap is None:
                snap = source.snapshot(columns=self._columns)
            self._cut(row, snap, release, end)
            changed = True
        return changed

    def _cut(self, row: ReleaseRow, snap: dict[str, npt.NDArray[Any]], release: float,
             end: float) -> None:
        t = snap["time"]
        i0 = int(np.searchsorted(t, release, side="left"))
        i1 = int(np.searchsorted(t, end, side="right"))
        index = row.number - 1
        if t.size == 0 or t[0] > release + 1.0 / self.rate_hz:
            oldest = float(t[0]) if t.size else math.nan
            self._set(index, status=f"not in the buffer any more (released at {release:.1f} s, "
                                    f"oldest row {oldest:.1f} s); not used")
            return
        cols = {name: np.asarray(snap[name][i0:i1], dtype=float) for name in self._columns}
        length = float(cols["time"][-1] - release) if i1 > i0 else 0.0
        u = cols["U"][np.isfinite(cols["U"])]
        U = float(np.median(u)) if u.size else math.nan
        self._set(index, length_s=length, U=U)
        for name in ("h", "alpha", "lift", "moment", *self._columns[len(DECAY_COLUMNS):]):
            bad = ~np.isfinite(cols[name])
            if bad.any():
                first = float(cols["time"][np.argmax(bad)] - release)
                self._set(index, status=f"gap: {int(bad.sum())} rows without {name} from "
                                        f"{first:.2f} s; not used")
                return
        if length < MIN_DECAY_S:
            self._set(index, status=f"too short ({length:.1f} s < {MIN_DECAY_S:g} s); not used")
            return
        still_air = not math.isfinite(U) or U < STILL_AIR_U
        release_obj: Release | None = None
        if not still_air:
            rho = cols["rho"][np.isfinite(cols["rho"])]
            try:
                release_obj = Release(t=cols["time"] - release, h=cols["h"], alpha=cols["alpha"],
                                      lift=cols["lift"], moment=cols["moment"], U=U,
                                      rho=float(np.median(rho)) if rho.size else None,
                                      meta={"release": row.number, "time_s": release},
                                      p=cols.get("p"), drag=cols.get("drag"))
            except (IdentError, ValueError) as exc:
                self._set(index, status=f"not used: {exc}")
                return
        self._set(index, status="fitting", release=release_obj)
        self._modal_jobs[index] = self._submit(
            fit_release_modes, cols["time"] - release, cols["h"], cols["alpha"],
            self._modal_section)

    # -- fits ------------------------------------------------------------------------------------
    def _collect_modal(self) -> bool:
        changed = False
        for index, job in list(self._modal_jobs.items()):
            if not job.done():
                continue
            del self._modal_jobs[index]
            changed = True
            row = self.rows[index]
            error = _job_error(job, f"release {row.number} modal fit")
            if error is not None:
                self._set(index, status=f"fit failed: {error}", release=None)
                continue
            still_air = row.release is None
            self._set(index, modal=job.result(), status="still air" if still_air else "ok")
        return changed

    def _start_campaign(self) -> None:
        if self._campaign_job is not None or self._modal_jobs:
            return  # one at a time, and only with every decay fitted
        usable = [row for row in self.rows if row.usable]
        speeds = results.distinct_wind_speeds([row.U for row in usable])
        if len(speeds) < 2:
            have = ", ".join(f"{u:.2f}" for u in speeds) or "none"
            self.campaign_status = (f"E2RFC needs releases at two or more wind speeds "
                                    f"(have: {have} m/s)")
            return
        inputs = tuple(row.number for row in usable)
        if inputs == self._campaign_inputs:
            return
        releases = [row.release for row in usable if row.release is not None]
        rho = [r.rho for r in releases if r.rho is not None]
        section = self.section.replace(rho=float(np.median(rho))) if rho else self.section
        self._campaign_inputs = inputs
        self._campaign_job = self._submit(identify_releases, releases, section)
        self.campaign_status = (f"identifying the E2RFC model from {len(releases)} releases at "
                                f"{len(speeds)} wind speeds ...")

    def _collect_campaign(self) -> bool:
        job = self._campaign_job
        if job is None or not job.done():
            return False
        self._campaign_job = None
        error = _job_error(job, "E2RFC identification")
        if error is not None:
            kept = " (the model shown is the previous one)" if self.campaign is not None else ""
            self.campaign_status = f"E2RFC failed: {error}{kept}"
            return True
        self.campaign = job.result()
        self.campaign_status = self.campaign.summary()
        return True

    def _submit(self, fn: Any, *args: Any) -> Future[Any]:
        if self._executor is None:
            self._executor = _spawn_executor()
        try:
            return self._executor.submit(fn, *args)
        except BrokenProcessPool:  # the worker died (killed, out of memory): start another
            log.error("the identification worker process died; starting a new one")
            self._executor = _spawn_executor()
            return self._executor.submit(fn, *args)

    def _set(self, index: int, **changes: Any) -> None:
        self.rows[index] = replace(self.rows[index], **changes)


def _job_error(job: Future[Any], what: str) -> str | None:
    """Return the job's error as one line (logged with its traceback unless expected)."""
    exc = job.exception()
    if exc is None:
        return None
    if not isinstance(exc, IdentError):  # not a data problem: keep the traceback in the log
        log.error("%s failed", what, exc_info=exc)
    return f"{type(exc).__name__}: {exc}"
