"""The releases table of a run, filled as the synchronised view is written: one row per decay.

Responsibility: :class:`ReleaseRows` turns the engine's ``"release"`` and ``"arm"`` events into
rows of ``/entry/releases``: the release instant, the sync rows of the free decay (from the
first row after the release to the row before the model is armed again, or to the next
release, or to the end of the run), the median wind speed over it, and the position held
before it (``h0``, ``alpha0``, a 3-DOF rig's ``p0``: the median over :data:`HOLD_WINDOW_S`
before the release). A row
is written once its decay has ended, so a live reader never sees one change.

Manual releases (a rig without a PLC, or a PLC not used): the operator lets the model go by
hand and says so with a key or a button (a ``"manual_release"`` event, some time after the
release). Once the sync rows up to :data:`MANUAL_AFTER_S` after the key are in, the release
instant is found in ``h`` and ``alpha`` before it
(:func:`ident.records.release_onset.locate_release`, within :data:`MANUAL_LOOKBACK_S`), the
release row starts there, and a ``"release_detected"`` event records it with its std and the
key's lag (or ``"release_not_detected"`` says why not: no row then). The operator's
``"manual_hold"`` (model caught and held again) ends the decay, like an arm, at the start of
the still hold before that key (:func:`ident.records.release_onset.still_start_before`), less
:data:`ident.records.release_onset.CATCH_GUARD_S` (the catch, a step, kept out of the decay).

Not responsible for: the sync rows themselves (:class:`daq.recording.writer.RunWriter`) or the
file (:mod:`daq.recording.recorder`). A run without sync rows (no lasers, no scanner) still gets
its rows, with NaN where the view would be needed.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from daq.recording.layout import event_row
from daq.recording.recorder_protocol import Recorder
from ident.errors import ReleaseNotFoundError
from ident.records.release_onset import (
    CATCH_GUARD_S,
    STILL_WINDOW_S,
    locate_release,
    still_start_before,
)

__all__ = ["HOLD_WINDOW_S", "MANUAL_AFTER_S", "MANUAL_LOOKBACK_S", "ReleaseRows"]

log = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]

#: Window of the held position before a release (h0, alpha0): [t - 0.3 s, t - 0.05 s].
HOLD_WINDOW_S = (0.3, 0.05)
#: How long sync rows are kept for the events that arrive after them, s. A release event
#: exists once the PLC confirmed it (its RELEASED input, polled), an arm event once the command
#: returned; on a loaded host that came after the rows of the release instant were written,
#: and the release started at the next block (10 ms late) with no rows left to give h0.
RECENT_S = 5.0
#: A manual release is looked for in the rows this far before the operator's key, s: the key
#: must come within it of the release (and the model have been held still before it).
MANUAL_LOOKBACK_S = 4.0
#: Rows after the operator's key waited for before looking, s (the sync view lags the host).
MANUAL_AFTER_S = 0.2

Hook = Callable[[str, float], None]


@dataclass
class _Release:
    time: float
    end_time: float | None = None  # the next arm event: the model is caught, the decay ends
    start_index: int | None = None
    stop_index: int | None = None
    h0: float = math.nan
    alpha0: float = math.nan
    p0: float = math.nan
    U: list[FloatArray] = field(default_factory=list)


class ReleaseRows:
    """The releases of one run, written to ``/entry/releases`` as their decays end.

    Attributes
    ----------
    written : int
        Rows written so far.
    """

    def __init__(self, f_max: float = math.inf) -> None:
        #: The section's faster structural frequency, Hz (the manual onset fit's length).
        self.f_max = float(f_max)
        # The operator's manual_release / manual_hold keys not yet looked at: (kind, t, hook)
        self._operator: list[tuple[str, float, Hook | None]] = []
        # (t, h, alpha) of the recent sync rows, and p on a 3-DOF rig
        self._recent: deque[tuple[FloatArray, ...]] = deque()
        self._sway = False
        self._releases: list[_Release] = []
        self._sync_rows = 0
        self._end = 0  # the index after the newest sync row taken
        self.written = 0

    def released(self, t: float) -> float:
        """Start a release at ``t`` (s from the run start); return ``t``."""
        self._releases.append(_Release(time=t))
        return t

    def caught(self, t_end: float) -> float | None:
        """End the last decay at ``t_end`` (its last row's time, s); None if none is running."""
        if not self._releases or self._releases[-1].end_time is not None:
            return None
        self._releases[-1].end_time = t_end
        return t_end

    def operator(self, kind: str, t: float, hook: Hook | None = None) -> None:
        """Take an operator's ``"manual_release"`` or ``"manual_hold"`` key at ``t`` (s).

        Looked at once the rows :data:`MANUAL_AFTER_S` after it are in (module docstring);
        ``hook`` is then told ``("release", t)`` or ``("caught", t)`` as the writer's is.
        """
        if kind not in ("manual_release", "manual_hold"):
            raise ValueError(f"not an operator's release key: {kind!r}")
        self._operator.append((kind, float(t), hook))

    def track(self, rec: Recorder, base: int, t: FloatArray, h: FloatArray, alpha: FloatArray,
              U: FloatArray, p: FloatArray | None = None) -> None:
        """Take sync rows ``base, base + 1, ...`` (times ``t``, s); write the decays ended.

        ``p``: the sway (m) of a 3-DOF rig, whose rows then get ``p0``.
        """
        self._sway = p is not None
        self._end = base + t.size
        self._recent.append((t, h, alpha) if p is None else (t, h, alpha, p))
        while len(self._recent) > 1 and self._recent[1][0][0] < t[-1] - RECENT_S:
            self._recent.popleft()
        while self._operator and t[-1] >= self._operator[0][1] + MANUAL_AFTER_S:
            self._manual(rec, *self._operator.pop(0))
        for rel in self._releases[self.written:]:
            if rel.start_index is None and t[-1] >= rel.time:
                rel.start_index = self._row_at(base + t.size, rel.time)
                rel.h0, rel.alpha0, rel.p0 = self._held(rel.time)
            if (rel.stop_index is None and rel.end_time is not None
                    and t[-1] >= rel.end_time):
                rel.stop_index = self._row_at(base + t.size, rel.end_time)
            if rel.start_index is not None:
                lo = max(rel.start_index - base, 0)
                hi = t.size if rel.stop_index is None else max(rel.stop_index - base, lo)
                if lo < min(hi, t.size):
                    rel.U.append(U[lo:hi])
        self._write_finished(rec, final=False)

    def _manual(self, rec: Recorder, kind: str, t_key: float, hook: Hook | None) -> None:
        """Find the instant an operator's key speaks of in the recent rows; act on it."""
        t = self._recent_column(0) if self._recent else np.zeros(0)
        rows = t >= t_key - MANUAL_LOOKBACK_S
        t, h, alpha = (t[rows], self._recent_column(1)[rows],
                       self._recent_column(2)[rows]) if t.size else (t, t, t)
        last = self._releases[-1].time if self._releases else -math.inf
        if kind == "manual_hold":
            # A key pressed with the catch: its hold is still from half a window after it.
            start = None if t.size < 30 else still_start_before(
                t, h, alpha, before=t_key + STILL_WINDOW_S, after=last)
            t_end = t_key if start is None else min(start - CATCH_GUARD_S, t_key)
            if self.caught(t_end) is not None and hook is not None:
                hook("caught", t_end)
            return
        try:
            if t.size == 0:
                raise ReleaseNotFoundError("no sync rows (no lasers' h and alpha) to find it in")
            onset = locate_release(t, h, alpha, before=t_key, f_max=self.f_max)
            if onset.time <= last:
                raise ReleaseNotFoundError(f"the last release found before it ({onset.time:.3f}"
                                           " s) is already a release of this run")
        except (ReleaseNotFoundError, ValueError) as exc:  # recorded, and the run goes on
            log.warning("operator's release at %.3f s: not found in the lasers: %s", t_key, exc)
            rec.add_event(t_key, *event_row("release_not_detected", f"operator's release key "
                                            f"at {t_key:.3f} s: {exc}", None, {}))
            return
        self.released(onset.time)
        # Its rows are among the recent ones already (a PLC release's come later).
        found = self._releases[-1]
        found.start_index = self._row_at(self._end, onset.time)
        found.h0, found.alpha0, found.p0 = self._held(onset.time)
        text = "release found in the lasers' signals" + (
            "" if onset.reliable else " (a weak onset: the instant may be off by several std)")
        rec.add_event(onset.time, *event_row(
            "release_detected", text, None,
            {"release_time": round(onset.time, 6), "std_s": float(f"{onset.std:.3g}"),
             "snr": round(onset.snr), "key_lag_s": round(t_key - onset.time, 4)}))
        if hook is not None:
            hook("release", onset.time)

    def _row_at(self, end: int, t_event: float) -> int:
        """Index of the first sync row at or after ``t_event`` among the recent rows.

        ``end``: the index after the newest row. The rows kept are contiguous up to it, so an
        event older than the newest block (it arrived late) still finds its row; one older
        than every row kept starts at the oldest.
        """
        t = self._recent_column(0)
        return end - t.size + int(np.searchsorted(t, t_event, side="left"))

    def _recent_column(self, col: int) -> FloatArray:
        """One column of the recent rows (0: t, 1: h, 2: alpha, 3: p), oldest first."""
        return np.concatenate([b[col] for b in self._recent])

    def _held(self, t_release: float) -> tuple[float, float, float]:
        """Return h0, alpha0 and p0 (NaN on a 2-DOF rig) held before a release."""
        if not self._recent:  # a rig without lasers or scanner has no sync rows
            return math.nan, math.nan, math.nan
        t = self._recent_column(0)
        sel = (t >= t_release - HOLD_WINDOW_S[0]) & (t < t_release - HOLD_WINDOW_S[1])
        out = []
        for col in range(1, len(self._recent[-1])):
            v = self._recent_column(col)[sel]
            v = v[np.isfinite(v)]
            out.append(float(np.median(v)) if v.size else math.nan)
        return out[0], out[1], out[2] if len(out) > 2 else math.nan

    def finish(self, rec: Recorder, sync_rows: int) -> None:
        """Write every release not written yet (the run ends after ``sync_rows`` rows)."""
        self._sync_rows = sync_rows
        while self._operator:  # keys just before the end: looked at with the rows there are
            self._manual(rec, *self._operator.pop(0))
        self._write_finished(rec, final=True)

    def _write_finished(self, rec: Recorder, *, final: bool) -> None:
        pending = self._releases[self.written:]
        for i, rel in enumerate(pending):
            following = pending[i + 1] if i + 1 < len(pending) else None
            if rel.stop_index is not None:
                stop = rel.stop_index
            elif following is not None and following.start_index is not None:
                stop = following.start_index
            elif final:
                stop = self._sync_rows
            else:
                return
            start = rel.start_index if rel.start_index is not None else stop
            if rel.start_index is None:
                rel.h0, rel.alpha0, rel.p0 = self._held(rel.time)
            u = np.concatenate(rel.U) if rel.U else np.zeros(0)
            u = u[: max(stop - start, 0)]
            u = u[np.isfinite(u)]
            rec.add_release(release_time=rel.time, start_index=start, stop_index=max(stop, start),
                            U=float(np.median(u)) if u.size else math.nan, h0=rel.h0,
                            alpha0=rel.alpha0, **({"p0": rel.p0} if self._sway else {}))
            self.written += 1
