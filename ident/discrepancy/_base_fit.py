"""The base-vibration candidate of the discrepancy workflow (private to it).

A floor vibrating at a fixed frequency ``f_b`` shakes the supports; in their frame the model
feels ``-a(t) [m B, S]`` (generalised, N m/m; :class:`ident.physics.effects.BaseVibration`), which
the pressures do not measure. So it stays in the structural equation's residual
(:mod:`ident.discrepancy._equation_error`) as a line at ``f_b``, the same at every wind speed, in
the heave equation (and the pitch one by ``S``). Its regressors, per release (a phase of its own:
the floor does not wait for the release), are ``-[m B, S] sin(2 pi f_b t)`` and the cosine,
each in its own release's block; the parameters are the base acceleration's sine and cosine
amplitudes, m/s^2.

``f_b`` is found once, on the baseline's residual: the heave equation's periodograms summed
over the releases, with a band of ``MODE_GUARD`` around each release's own heave and pitch
frequencies left out (there the residual of every structural effect lives, and a constant
line would soak part of it up), between ``BASE_HZ_MIN`` and ``BASE_HZ_MAX_FRACTION`` of the
low-pass band; then refined by least squares.

Not responsible for: scoring or choosing (:mod:`ident.discrepancy.effect_selection`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ident.model.section import SectionModel

FloatArray = npt.NDArray[np.float64]

#: Lowest frequency scanned, Hz (a slower line is a drift, not a machine).
BASE_HZ_MIN = 0.5
#: Highest, as a fraction of the low-pass cut-off of the equation error.
BASE_HZ_MAX_FRACTION = 0.9
#: Left out around each release's modal frequencies, as a fraction of them.
MODE_GUARD = 0.15
#: The candidate is offered only if its line stands out this much (peak over median of the
#: scanned periodogram): a floor at 6 Hz and 10 milli-g gave about 5000, residuals without a
#: line 4 to 23 (clean, friction, drag with crosstalk, ...; at 13 a spurious "floor" was named
#: beside drag and crosstalk before this test).
MIN_PROMINENCE = 100.0


@dataclass(frozen=True)
class BaseLine:
    """The line found in the heave equation's residual.

    Attributes
    ----------
    frequency_hz : float
        Its frequency, Hz.
    prominence : float
        The summed periodogram's peak over its median on the scanned grid (a line stands out
        by orders of magnitude; a broadband residual's highest point by a few times).
    """

    frequency_hz: float
    prominence: float = math.inf


def modal_peaks(t: FloatArray, q: FloatArray) -> tuple[float, float]:
    """Return the spectral peaks (Hz) of ``q[:, 0]`` (heave) and ``q[:, 1]`` (pitch)."""
    fs = 1.0 / float(np.median(np.diff(t)))
    n_fft = 1 << int(math.ceil(math.log2(4 * t.size)))
    f = np.fft.rfftfreq(n_fft, d=1.0 / fs)
    peaks = []
    for k in range(2):
        spectrum = np.abs(np.fft.rfft(q[:, k] - q[:, k].mean(), n=n_fft))
        spectrum[f < BASE_HZ_MIN] = 0.0
        peaks.append(float(f[int(np.argmax(spectrum))]))
    return peaks[0], peaks[1]


def find_line(ts: Sequence[FloatArray], heave: Sequence[FloatArray],
              modes: Sequence[tuple[float, float]], f_max: float) -> BaseLine:
    """Find the strongest line in the heave residuals away from the modes (module docstring).

    Parameters
    ----------
    ts : sequence of ndarray
        Time of each release's rows, s.
    heave : sequence of ndarray
        The heave equation's residual of each release (same rows).
    modes : sequence of (float, float)
        Each release's heave and pitch frequencies, Hz.
    f_max : float
        The low-pass cut-off, Hz.
    """
    fs = 1.0 / float(np.median(np.diff(ts[0])))
    duration = min(float(t[-1] - t[0]) for t in ts)
    grid = np.arange(BASE_HZ_MIN, BASE_HZ_MAX_FRACTION * f_max, 0.25 / duration)
    power = np.zeros(grid.size)
    for t, e, (fh, fa) in zip(ts, heave, modes, strict=True):
        n_fft = 1 << int(math.ceil(math.log2(8 * t.size)))
        spectrum = np.abs(np.fft.rfft(e - e.mean(), n=n_fft)) ** 2 / t.size
        here = np.interp(grid, np.fft.rfftfreq(n_fft, d=1.0 / fs), spectrum)
        for f0 in (fh, fa):
            here[np.abs(grid - f0) <= MODE_GUARD * f0] = 0.0
        power += here
    f0 = float(grid[int(np.argmax(power))])
    step = float(grid[1] - grid[0]) if grid.size > 1 else 0.1

    def rss(f: float) -> float:
        total = 0.0
        for t, e in zip(ts, heave, strict=True):
            w = 2 * math.pi * f * t
            X = np.column_stack([np.sin(w), np.cos(w), np.ones(t.size)])
            theta, *_ = np.linalg.lstsq(X, e, rcond=None)
            total += float(np.sum((e - X @ theta) ** 2))
        return total

    from scipy.optimize import minimize_scalar

    res = minimize_scalar(rss, bounds=(f0 - 2 * step, f0 + 2 * step), method="bounded",
                          options={"xatol": step * 1e-3})
    prominence = float(power.max() / max(float(np.median(power)), np.finfo(float).tiny))
    return BaseLine(frequency_hz=float(res.x), prominence=prominence)


def base_columns(ts: Sequence[FloatArray], line: BaseLine, section: SectionModel,
                 scale: FloatArray, index: int, passband: float = 1.0) -> FloatArray:
    """Release ``index``'s whitened regressors in a block-diagonal design, shape (2 n, 2 N).

    ``passband`` is the equation error's low-pass gain at the line (the residual holds the
    floor's force filtered: a line at 0.9 of the cut-off, unscaled, came out 28 % low).
    """
    t = ts[index]
    w = 2 * math.pi * line.frequency_hz * t
    gain = -passband * np.array([section.m * section.B, section.S]) / scale
    block = np.zeros((2 * t.size, 2 * len(ts)))
    block[:, 2 * index] = np.outer(np.sin(w), gain).ravel()
    block[:, 2 * index + 1] = np.outer(np.cos(w), gain).ravel()
    return block


def accelerations(theta: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Per release, the base acceleration's amplitude (m/s^2) and phase (rad) from ``theta``.

    ``theta`` holds the sine and cosine amplitudes of each release: ``a(t) = a_s sin(w t) +
    a_c cos(w t) = accel sin(w t + phase)``.
    """
    pairs = np.asarray(theta, dtype=float).reshape(-1, 2)
    return np.hypot(pairs[:, 0], pairs[:, 1]), np.arctan2(pairs[:, 1], pairs[:, 0])
