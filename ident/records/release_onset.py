"""Where a held model was let go: the release instant found in its displacements alone.

A release without a PLC (the operator lets the model go by hand and presses a key some time
later), or a run file with no release events, has no recorded release instant. This module
finds it in ``h`` and ``alpha``: the model sits still at its held position (the measurement
noise only), and from the instant it is let go it moves off as a free decay *from rest*: the
displacement leaves the held level with zero velocity, as ``a2 tau^2 + a3 tau^3 + ...`` in the
time ``tau`` since the release (``a2 = -omega^2 (x0 - x_eq) / 2``). The release instant is the
change point of that model:

1. **Noise and stillness.** Each channel's noise is the 10th percentile, over 0.1 s blocks, of
   the standard deviation of its second differences over ``sqrt(6)`` (white noise; motion
   barely adds to it while held, and a record that is moving all the time only overestimates
   it). A row is *still* when every channel's standard deviation over a centred
   :data:`STILL_WINDOW_S` window is below :data:`STILL_FACTOR` times its noise. A hold is a
   still stretch of at least ``min_hold_s``.
2. **Coarse onset.** After a hold, the first row where a channel leaves the hold's median by
   more than :data:`EXCEEDANCE_SIGMAS` of its noise (``t_x``): after the release, almost
   surely.
3. **Fine onset.** For each candidate ``t0`` in ``[t_x - T, t_x]`` (``T`` =
   :data:`ONSET_PERIOD_FRACTION` of the fastest mode's period), both channels over ``[t_x - T
   - hold, t_x + T]`` are fitted by linear least squares with a held level ``c`` and, after
   ``t0``, ``a2 tau^2 + a3 tau^3 + a4 tau^4`` (no ``tau`` term: released from rest); each
   channel weighted by its noise. ``t0`` minimises the summed chi-square, first on a grid of a
   tenth of a sample, then by a bounded scalar search. Its standard deviation comes from the
   chi-square's curvature (``Delta chi^2 = 1``), scaled up by the reduced chi-square where the
   fit is worse than the noise.

Accuracy (``tests/ident/records/test_release_onset.py``; measured on synthetic decays of the
flat-plate rig, fh = 2 Hz, fa = 4 Hz, 30 seeds per case, white noise added): held at 8 mm and
0.04 rad, sampled at 500 Hz, the error is 0.04 ms rms (0.08 ms at most) with 1 um and 5e-6 rad of
noise (about the simulated lasers' in the sync view), 0.1 ms rms (0.4 ms at most) with 5 um
and 2.5e-5 rad, 0.4-0.7 ms rms (1.5 ms at most) with 30 um and 1.5e-4 rad, at 0, 6 and
9 m/s; at 200 Hz 1.0 ms rms (1.8 ms at most) at the highest noise. The stated std covers it
(every error within 4 std, mostly within 2). It worsens as ``sqrt(noise / (omega^2 x0))``: a
small hold, a hold in the slow mode only, or much noise. :attr:`ReleaseOnset.snr` measures
that: at or above :data:`MIN_SNR` the errors above hold; below it (2 mm and 0.01 rad, or a heave
hold alone, with 30 um and 1.5e-4 rad of noise: snr 0-112) the fit can take an onset up to
25 ms early and its std is no longer to be trusted. The model assumes a release from rest: a
hand that pushes as it lets go starts the decay with a velocity, which the ``tau``-free model
reads as an onset a little early; a hand that trembles makes the hold noisier, which the noise
estimate and the stated std take in.

Not responsible for: cutting releases out of a run file (:mod:`ident.records.run_file`, which
calls :func:`find_releases` for a file without release rows), or the live detection after an
operator's key (:mod:`daq.recording.releases`, which calls :func:`locate_release`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.optimize import minimize_scalar

from ident.errors import ReleaseNotFoundError

__all__ = ["CATCH_GUARD_S", "DetectedRelease", "ReleaseOnset",
           "find_releases", "locate_release", "noise_levels", "still_rows", "still_start_before"]

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

#: Window of the stillness test, s (centred): short against a decay's period (a 4 Hz mode
#: moves by 1.3 rad of phase in it), long against the sampling (50 rows at 500 Hz).
STILL_WINDOW_S = 0.1
#: A row is still when every channel's std over the window is below this many noise stds.
STILL_FACTOR = 4.0
#: The coarse onset: a channel this many noise stds away from its held median.
EXCEEDANCE_SIGMAS = 8.0
#: Fraction of the fastest mode's period searched before the coarse onset and fitted after
#: it: 0.1 period keeps ``omega tau`` under 1.3 rad over the fit, where a quartic in ``tau``
#: follows ``1 - cos`` to 0.5 % of the motion.
ONSET_PERIOD_FRACTION = 0.2
#: Powers of the time since the release in the onset's model (none below 2: from rest).
ONSET_POWERS = (2, 3, 4)
#: Below this :attr:`ReleaseOnset.snr` an onset can be off by several of its std.
MIN_SNR = 150.0
#: Held stretch fitted before the search window, s.
HOLD_FIT_S = 0.25
#: A decay caught (held again) ends this long before its hold's first still row: half the
#: stillness window (the window is still only once the catch is out of it), and 20 ms more,
#: since the catch is a step that a sync row averaging the lasers over its period, and the
#: window's edge moving by a row or two with the noise, would otherwise keep in the decay's
#: last rows (seen on the simulated rig: the last one or two rows of each decay halfway to
#: the hold, a 5-8 mm jump that E2RFC read as aerodynamics).
CATCH_GUARD_S = 0.5 * STILL_WINDOW_S + 0.02
#: Fewest rows of a hold: a shorter still stretch gives no held level.
MIN_HOLD_ROWS = 10


@dataclass(frozen=True)
class ReleaseOnset:
    """A release instant found in the displacements.

    Attributes
    ----------
    time : float
        The release instant, s, on the time base given.
    std : float
        Its standard deviation, s (from the fit's chi-square curvature).
    held : tuple of float
        The held level of each channel (h m, alpha rad).
    noise : tuple of float
        The noise std of each channel (m, rad).
    hold_start : float
        Start of the still stretch (the hold) before it, s.
    snr : float
        The onset's signal to noise: the fitted ``tau^2`` motion after a fit's length
        (:data:`ONSET_PERIOD_FRACTION` of the fastest period), in noise stds, the larger of
        the channels. Below :data:`MIN_SNR` the onset may be off by several std (module
        docstring).
    """

    time: float
    std: float
    held: tuple[float, ...]
    noise: tuple[float, ...]
    hold_start: float
    snr: float

    @property
    def reliable(self) -> bool:
        """Whether :attr:`snr` is at least :data:`MIN_SNR` (the std can be trusted)."""
        return self.snr >= MIN_SNR


@dataclass(frozen=True)
class DetectedRelease:
    """A release found in a whole record: its onset and where its free decay ends.

    Attributes
    ----------
    onset : ReleaseOnset
    end : float
        Last time of the free decay, s: before the next hold (the model caught) or the
        record's end.
    """

    onset: ReleaseOnset
    end: float


def _channels(t: object, channels: tuple[object, ...]) -> tuple[FloatArray, FloatArray]:
    tt = np.asarray(t, dtype=float)
    X = np.column_stack([np.asarray(c, dtype=float) for c in channels])
    if tt.ndim != 1 or X.shape[0] != tt.size:
        raise ValueError(f"t and the channels must be 1-D and equally long, got {tt.shape} "
                         f"and {[np.asarray(c).shape for c in channels]}")
    if tt.size < 3 * MIN_HOLD_ROWS:
        raise ReleaseNotFoundError(f"{tt.size} rows are too few to find a release in")
    return tt, X


def _dt(t: FloatArray) -> float:
    steps = np.diff(t)
    steps = steps[np.isfinite(steps)]
    if steps.size == 0 or not np.median(steps) > 0:
        raise ValueError("t must be increasing")
    return float(np.median(steps))


def noise_levels(t: object, *channels: object) -> FloatArray:
    """Return each channel's measurement-noise std (step 1 of the module docstring).

    Parameters
    ----------
    t : array_like, shape (n,)
        Times, s (uniform; NaN rows of the channels are gaps).
    *channels : array_like, shape (n,)
        Displacements (any units).

    Returns
    -------
    ndarray, shape (n_channels,)
        Noise std per channel, in its units (NaN where a channel has too few finite rows).
    """
    tt, X = _channels(t, channels)
    block = max(5, int(round(STILL_WINDOW_S / _dt(tt))))
    d2 = X[2:] - 2.0 * X[1:-1] + X[:-2]
    out = np.full(X.shape[1], math.nan)
    n_blocks = d2.shape[0] // block
    if n_blocks == 0:
        return out
    blocks = d2[: n_blocks * block].reshape(n_blocks, block, X.shape[1])
    # The std of each block's finite values (a block inside a gap has none: NaN, left out
    # below); by counts rather than np.nanstd, which warns of every such block.
    finite = np.isfinite(blocks)
    count = finite.sum(axis=1)
    mean = np.where(finite, blocks, 0.0).sum(axis=1) / np.maximum(count, 1)
    square = np.where(finite, blocks - mean[:, None, :], 0.0) ** 2
    spread = np.sqrt(square.sum(axis=1) / np.maximum(count, 1))
    stds = np.where(count > 0, spread, math.nan) / math.sqrt(6.0)  # var(d2) = 6 var(noise)
    for c in range(X.shape[1]):
        good = stds[:, c][np.isfinite(stds[:, c])]
        if good.size:
            out[c] = float(np.percentile(good, 10.0))
    return out


def still_rows(t: object, *channels: object, noise: FloatArray | None = None) -> BoolArray:
    """Return which rows are still (step 1 of the module docstring): True where held.

    ``noise`` (per channel) defaults to :func:`noise_levels`. A row with a gap is not still.
    """
    tt, X = _channels(t, channels)
    sigma = noise_levels(tt, *channels) if noise is None else np.asarray(noise, dtype=float)
    half = max(2, int(round(0.5 * STILL_WINDOW_S / _dt(tt))))
    still = np.ones(tt.size, dtype=bool)
    for c in range(X.shape[1]):
        x = X[:, c]
        finite = np.isfinite(x)
        if not np.isfinite(sigma[c]) or sigma[c] <= 0:
            still &= False
            continue
        # Rolling std by cumulative sums of the centred signal (gaps count as not still).
        y = np.where(finite, x - np.nanmedian(x), 0.0)
        s1 = np.concatenate([[0.0], np.cumsum(y)])
        s2 = np.concatenate([[0.0], np.cumsum(y * y)])
        bad = np.concatenate([[0], np.cumsum(~finite)])
        lo = np.clip(np.arange(tt.size) - half, 0, tt.size)
        hi = np.clip(np.arange(tt.size) + half + 1, 0, tt.size)
        n = hi - lo
        mean = (s1[hi] - s1[lo]) / n
        var = np.maximum((s2[hi] - s2[lo]) / n - mean * mean, 0.0)
        still &= (np.sqrt(var) < STILL_FACTOR * sigma[c]) & (bad[hi] - bad[lo] == 0)
    return still


def _runs(mask: BoolArray) -> list[tuple[int, int]]:
    """Return the (start, stop) row ranges where ``mask`` is True."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _holds(t: FloatArray, still: BoolArray, min_hold_s: float) -> list[tuple[int, int]]:
    dt = _dt(t)
    need = max(MIN_HOLD_ROWS, int(math.ceil(min_hold_s / dt)))
    return [(a, b) for a, b in _runs(still) if b - a >= need]


def locate_release(t: object, h: object, alpha: object, *, before: float, f_max: float,
                   min_hold_s: float = 0.3) -> ReleaseOnset:
    """Find the last release before ``before`` (an operator's key press after it).

    Parameters
    ----------
    t : array_like, shape (n,)
        Times, s, uniform (a few seconds around the release: the hold before it, and at least
        a tenth of a period of the fastest mode after it).
    h, alpha : array_like, shape (n,)
        Heave (m) and pitch (rad); NaN marks a gap.
    before : float
        The release happened before this time, s (the key press).
    f_max : float
        The fastest structural mode's frequency, Hz (sets the fit's length).
    min_hold_s : float
        Shortest still stretch taken for a hold, s.

    Returns
    -------
    ReleaseOnset

    Raises
    ------
    ReleaseNotFoundError
        No hold ends before ``before`` with a departure from it after (the model was not held
        still, or let go after ``before``, or the rows end too soon).
    """
    tt, X = _channels(t, (h, alpha))
    noise = noise_levels(tt, h, alpha)
    still = still_rows(tt, h, alpha, noise=noise)
    holds = [(a, b) for a, b in _holds(tt, still, min_hold_s) if tt[b - 1] < before and b < tt.size]
    if not holds:
        raise ReleaseNotFoundError(
            f"no still hold of at least {min_hold_s:g} s ends before t = {before:.3f} s: was "
            "the model held still before it was let go?")
    for a, b in reversed(holds):
        try:
            return _fine_onset(tt, X, noise, a, b, f_max)
        except ReleaseNotFoundError:
            continue
    raise ReleaseNotFoundError(
        f"no departure from a hold before t = {before:.3f} s looks like a release from rest")


def still_start_before(t: object, h: object, alpha: object, *, before: float,
                       after: float, min_hold_s: float = 0.3) -> float | None:
    """Return the start of the last hold that begins in ``(after, before]``, s (None if none).

    The end of a free decay that the operator caught by hand: the model held still again.
    """
    tt, _ = _channels(t, (h, alpha))
    still = still_rows(tt, h, alpha)
    dt = _dt(tt)
    need = max(MIN_HOLD_ROWS, int(math.ceil(min_hold_s / dt)))
    starts = [tt[a] for a, b in _runs(still)
              if after < tt[a] <= before and (b - a >= need or b == tt.size or tt[b - 1] >= before)]
    return float(starts[-1]) if starts else None


def find_releases(t: object, h: object, alpha: object, *, f_min: float, f_max: float,
                  min_hold_s: float = 0.3, min_periods: float = 3.0) -> list[DetectedRelease]:
    """Find every release in a whole record (a run file without release events).

    A release is a hold (a still stretch of at least ``min_hold_s``) followed by motion that
    lasts at least ``min_periods`` periods of the slower mode (``f_min``) and moves away from
    the held level: a model pulled into its hold moves for less than that, a model that
    settled after a decay is not displaced. Its decay ends :data:`CATCH_GUARD_S` before the
    next hold (the catch) or at the record's end.

    Parameters
    ----------
    t, h, alpha : array_like, shape (n,)
        Times (s, uniform), heave (m), pitch (rad); NaN marks a gap.
    f_min, f_max : float
        The slower and the faster structural frequency, Hz.
    min_hold_s : float
        Shortest hold, s.
    min_periods : float
        Fewest periods of the slower mode a decay must last.

    Returns
    -------
    list of DetectedRelease
        In time order (empty when the record holds none).
    """
    if not (0 < f_min <= f_max and math.isfinite(f_max)):
        raise ValueError(f"need 0 < f_min <= f_max, got f_min={f_min!r}, f_max={f_max!r}")
    tt, X = _channels(t, (h, alpha))
    noise = noise_levels(tt, h, alpha)
    still = still_rows(tt, h, alpha, noise=noise)
    holds = _holds(tt, still, min_hold_s)
    found: list[DetectedRelease] = []
    for k, (a, b) in enumerate(holds):
        if b >= tt.size:
            break
        end_row = holds[k + 1][0] if k + 1 < len(holds) else tt.size
        end = float(tt[end_row]) - CATCH_GUARD_S if end_row < tt.size else float(tt[-1])
        if end - tt[b] < min_periods / f_min:
            continue  # a short move: the model pulled into a hold, not a decay
        held = np.nanmedian(X[a:b], axis=0)
        moving = np.nanmedian(np.abs(X[b:end_row] - held), axis=0)
        if not np.any(moving > EXCEEDANCE_SIGMAS * noise):
            continue
        try:
            onset = _fine_onset(tt, X, noise, a, b, f_max)
        except ReleaseNotFoundError:
            continue
        found.append(DetectedRelease(onset=onset, end=end))
    return found


def _fine_onset(t: FloatArray, X: FloatArray, noise: FloatArray, a: int, b: int,
                f_max: float) -> ReleaseOnset:
    """Fit the onset after the hold ``rows a..b`` (steps 2 and 3 of the module docstring)."""
    if not (f_max > 0 and math.isfinite(f_max)):
        raise ValueError(f"f_max must be a frequency > 0 Hz, got {f_max!r}")
    dt = _dt(t)
    good = np.isfinite(noise) & (noise > 0)
    held = np.nanmedian(X[a:b], axis=0)
    with np.errstate(invalid="ignore"):
        away = np.abs(X[b:] - held) > EXCEEDANCE_SIGMAS * noise
    away[:, ~good] = False
    hit = np.flatnonzero(away.any(axis=1))
    if hit.size == 0:
        raise ReleaseNotFoundError("the displacements never leave the hold")
    i_x = b + int(hit[0])
    span = ONSET_PERIOD_FRACTION / f_max
    lo_t = max(float(t[i_x]) - span, float(t[a]) + MIN_HOLD_ROWS * dt)
    hi_t = float(t[i_x])
    first = max(a, int(np.searchsorted(t, lo_t - HOLD_FIT_S)))
    last = min(t.size, int(np.searchsorted(t, hi_t + span, side="right")))
    tw, Xw = t[first:last], X[first:last][:, good]
    rows = np.all(np.isfinite(Xw), axis=1)
    tw, Xw = tw[rows], Xw[rows] / noise[good]
    if tw.size < 2 * MIN_HOLD_ROWS or int(np.count_nonzero(tw > hi_t)) < 3:
        raise ReleaseNotFoundError("too few rows after the departure from the hold")

    def fit(t0: float) -> tuple[float, FloatArray]:
        tau = np.clip(tw - t0, 0.0, None)
        A = np.column_stack([np.ones_like(tw)] + [tau**k for k in ONSET_POWERS])
        coef = np.asarray(np.linalg.lstsq(A, Xw, rcond=None)[0], dtype=np.float64)
        return float(np.sum((Xw - A @ coef) ** 2)), coef

    def chi2(t0: float) -> float:
        return fit(t0)[0]

    grid = np.arange(lo_t, hi_t + 0.05 * dt, 0.1 * dt)
    if grid.size < 3:
        raise ReleaseNotFoundError("the departure comes too soon after the hold's start")
    values = np.array([chi2(t0) for t0 in grid])
    k = int(np.argmin(values))
    bounds = (grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)])
    best = minimize_scalar(chi2, bounds=bounds, method="bounded",
                           options={"xatol": 1e-3 * dt})
    t0 = float(best.x) if best.fun <= values[k] else float(grid[k])
    c_min = min(float(best.fun), float(values[k]))
    # Curvature of chi2 near the minimum: a parabola through the grid within +-1 sample.
    near = np.abs(grid - t0) <= 1.0 * dt
    if np.count_nonzero(near) >= 3:
        curv = 2.0 * float(np.polyfit(grid[near] - t0, values[near], 2)[0])
    else:
        curv = math.nan
    dof = max(Xw.size - (1 + len(ONSET_POWERS)) * Xw.shape[1] - 1, 1)
    scale = max(1.0, c_min / dof)
    std = math.sqrt(2.0 * scale / curv) if curv > 0 else span
    # The onset's signal: the tau^2 term's motion after a fit's length, in noise stds.
    snr = float(np.max(np.abs(fit(t0)[1][1]))) * span**2
    return ReleaseOnset(time=t0, std=min(std, span), held=tuple(float(v) for v in held),
                        noise=tuple(float(v) for v in noise), hold_start=float(t[a]), snr=snr)
