"""The live watch over each free decay: its amplitude, and whether it grows.

Responsibility: :class:`DecayMonitor` is an engine subscriber (``(name, doc)``, on the
dispatcher thread) that follows the laser distances from each ``"release"`` event to the next
``"arm"``. It cuts the decay into windows of one slow structural period and takes each window's
half peak-to-peak amplitude per laser. A decay *grows* (negative total damping: the wind speed is
at or beyond flutter) when two consecutive windows after the first of some laser exceed
:data:`GROWTH_RATIO` times the largest first-window amplitude of any laser (the release's own
amplitude: a laser that saw little of the release must not trip on turbulence's random response,
as one did at 0.8 U_F in 1 % turbulence, while a flutter mode barely excited at the release is
still caught before the motion exceeds the release's by half), or when a laser loses the
target (out of range) over most of a window; :attr:`DecayMonitor.growing` is then set at once,
so that the campaign's actions, which wait on it instead of sleeping, catch the model within a
window.

A decay has *settled* (:attr:`DecayMonitor.settled`; a plan with ``decay_end = "settled"``
then ends the release's recording) when, after :data:`MIN_SETTLED_WINDOWS` windows, the last
two windows of every laser are down to :data:`SETTLED_FRACTION` of its first (two: where the
two modes beat, one window can dip). Why that is enough: against white measurement noise a
decay's information on the forces goes with its amplitude squared, so what follows a window
at 20 % of the first holds about 4 % of the decay's information (and a decay that never gets
there, its amplitude lost in a higher noise, is recorded for the plan's ``decay_s``).

Why lasers and windows: they arrive every ~20 ms without any conversion, and a stable decay's
amplitude never rises by half over one period, even where the two modes beat, while a
flutter-unstable one does within a few periods.

Not responsible for: catching the model or stopping the fan (the campaign's actions do, through
the engine's commands), or the modal fit of a decay (done on the recorded file).
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["GROWTH_RATIO", "MIN_SETTLED_WINDOWS", "SETTLED_FRACTION", "DecayAmplitude",
           "DecayMonitor"]

#: A window this many times the first window's amplitude (twice in a row) is a growing decay.
GROWTH_RATIO = 1.5
#: Fraction of a window's samples without a value (target out of range) that counts as growth.
LOST_FRACTION = 0.5
#: Settled: the last two windows at most this fraction of the first (module docstring).
SETTLED_FRACTION = 0.2
#: Windows (slow periods) a decay is recorded for at least before it may count as settled. The
#: modal fit of E2RFC's regressors accepts records of 3 periods, but short decays identify
#: worse than their amplitude alone says: with 5 windows the flat plate's adaptive campaign
#: (benchmarks/campaign_efficiency.py, seed 6) ended at 6 speeds with std 1.6 %, where 8
#: windows reached 1 % at 4.
MIN_SETTLED_WINDOWS = 8


@dataclass(frozen=True)
class DecayAmplitude:
    """Amplitude of the latest decay, m (half peak-to-peak of the laser distance).

    Attributes
    ----------
    first, last : float
        Of the first and the latest complete window, the largest over the lasers, m.
    windows : int
        Complete windows seen.
    growing : bool
    """

    first: float
    last: float
    windows: int
    growing: bool


class _LaserTrack:
    """One laser's windows since the release."""

    def __init__(self) -> None:
        self.current: list[float] = []
        self.window_start: float | None = None
        self.amplitudes: list[float] = []
        self.lost: list[bool] = []


class DecayMonitor:
    """Subscriber following each decay's amplitude (module docstring).

    Parameters
    ----------
    window_s : float
        Window length, s: one period of the slower structural mode.
    """

    def __init__(self, window_s: float) -> None:
        if not (math.isfinite(window_s) and window_s > 0):
            raise ValueError(f"window_s must be > 0 s, got {window_s!r}")
        self.window_s = float(window_s)
        #: Set (dispatcher thread) when a decay grows; cleared at the next release.
        self.growing = threading.Event()
        #: Set (dispatcher thread) when a decay has settled (module docstring); cleared at
        #: the next release.
        self.settled = threading.Event()
        #: Releases seen so far (incremented after the events above are cleared): a caller
        #: that just commanded a release waits for this to grow before trusting ``settled``,
        #: which until the release event reaches the dispatcher still tells of the last decay.
        self.releases = 0
        self._lock = threading.Lock()
        self._release_ns: int | None = None
        self._tracks: dict[str, _LaserTrack] = {}

    def __call__(self, name: str, doc: Any) -> None:
        """Receive one engine doc (dispatcher thread)."""
        if name == "event":
            kind = getattr(doc, "kind", "")
            with self._lock:
                if kind in ("release", "manual_release"):  # a manual one: from the key on
                    self._release_ns = int(doc.host_time_ns)
                    self._tracks = {}
                    self.growing.clear()
                    self.settled.clear()
                    self.releases += 1
                elif kind in ("arm", "manual_hold"):
                    self._release_ns = None  # caught: what follows is no decay
        elif name == "block" and getattr(doc, "kind", "") == "laser":
            with self._lock:
                if self._release_ns is not None:
                    self._add(doc.device, doc.host_time_ns, doc.values.get("distance"))

    def _add(self, device: str, host_ns: Any, distance: Any) -> None:
        if distance is None:
            return
        assert self._release_ns is not None
        t = (np.asarray(host_ns, dtype=np.int64) - self._release_ns) * 1e-9
        x = np.asarray(distance, dtype=float)
        track = self._tracks.setdefault(device, _LaserTrack())
        for ti, xi in zip(t, x, strict=True):
            if ti < 0:
                continue
            if track.window_start is None:
                track.window_start = 0.0
            if ti >= track.window_start + self.window_s:
                self._close_window(track)
                track.window_start += self.window_s * math.floor(
                    (ti - track.window_start) / self.window_s)
            track.current.append(float(xi))

    def _close_window(self, track: _LaserTrack) -> None:
        values = np.asarray(track.current)
        track.current = []
        if values.size == 0:
            return
        valid = values[np.isfinite(values)]
        lost = valid.size < (1.0 - LOST_FRACTION) * values.size
        track.lost.append(lost)
        track.amplitudes.append(0.5 * float(np.ptp(valid)) if valid.size else math.nan)
        firsts = [t.amplitudes[0] for t in self._tracks.values()
                  if t.amplitudes and math.isfinite(t.amplitudes[0])]
        first = max(firsts) if firsts else math.nan
        if len(track.amplitudes) >= 3 and math.isfinite(first) and first > 0:
            recent = track.amplitudes[-2:]
            grown = all(math.isfinite(a) and a > GROWTH_RATIO * first for a in recent)
            if grown or all(track.lost[-2:]):
                self.growing.set()
        if not self.growing.is_set() and self._tracks \
                and all(_settled(t.amplitudes) for t in self._tracks.values()):
            self.settled.set()

    def settled_since(self, releases: int) -> bool:
        """Whether a decay after the first ``releases`` releases has settled.

        Parameters
        ----------
        releases : int
            :attr:`releases` read before the release was commanded.
        """
        return self.releases > releases and self.settled.is_set()

    def amplitude(self) -> DecayAmplitude | None:
        """Amplitude of the current (or last) decay, or None before any complete window."""
        with self._lock:
            tracks = [t for t in self._tracks.values() if t.amplitudes]
            if not tracks:
                return None
            first = max(t.amplitudes[0] for t in tracks)
            last = max(t.amplitudes[-1] for t in tracks)
            windows = min(len(t.amplitudes) for t in tracks)
        return DecayAmplitude(first, last, windows, self.growing.is_set())


def _settled(amplitudes: list[float]) -> bool:
    """Whether one laser's window amplitudes show a settled decay (module docstring)."""
    if len(amplitudes) < MIN_SETTLED_WINDOWS:
        return False
    first, last_two = amplitudes[0], amplitudes[-2:]
    return math.isfinite(first) and first > 0 and all(
        math.isfinite(a) and a <= SETTLED_FRACTION * first for a in last_two)
