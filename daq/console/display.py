"""Numbers the operator console shows: pressure coefficients, tap perimeter, spectra.

Responsibility: small pure functions of numpy arrays, kept out of the Qt code so that they are
tested without a window. Not responsible for drawing (:mod:`daq.console.window`) or reading data.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from ident.physics.taps import TapLayout

__all__ = ["amplitude_spectrum", "perimeter_positions", "pressure_coefficients"]

FloatArray = npt.NDArray[np.float64]

#: Below this dynamic pressure (Pa) Cp is not shown: wind off, p / qd is noise over noise.
MIN_DYNAMIC_PRESSURE_PA = 1.0


def pressure_coefficients(pressure: npt.ArrayLike, U: float, rho: float,
                          *, min_qd: float = MIN_DYNAMIC_PRESSURE_PA) -> FloatArray:
    """Return the pressure coefficients of one row of tap pressures.

    Parameters
    ----------
    pressure : array_like, (taps,)
        Tap pressures relative to the free-stream static pressure, Pa.
    U : float
        Wind speed, m/s.
    rho : float
        Air density, kg/m^3.
    min_qd : float
        Dynamic pressures below this (Pa), or not finite, give NaN coefficients.

    Returns
    -------
    ndarray, (taps,)
        ``Cp = p / qd`` with ``qd = rho U^2 / 2`` (dimensionless).

    Examples
    --------
    >>> pressure_coefficients([-60.0, 30.0], U=10.0, rho=1.2).tolist()
    [-1.0, 0.5]
    """
    p = np.asarray(pressure, dtype=np.float64)
    qd = 0.5 * float(rho) * float(U) ** 2
    if not math.isfinite(qd) or qd < min_qd:
        return np.full(p.shape, np.nan)
    return p / qd


def perimeter_positions(taps: TapLayout) -> FloatArray:
    """Return each tap's position along the section outline, m.

    Taps are taken in their configured order around the outline; a tap sits at the middle of its
    tributary length, so the position is ``cumsum(length) - length / 2``.

    Parameters
    ----------
    taps : TapLayout
        The tap layout of the rig config.

    Returns
    -------
    ndarray, (taps,)
        Perimeter coordinate, m, increasing from the first tap.
    """
    length = np.asarray(taps.length, dtype=np.float64)
    return np.cumsum(length) - 0.5 * length


def amplitude_spectrum(t: npt.ArrayLike, y: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Return the one-sided amplitude spectrum of a uniformly sampled signal.

    The mean is removed and a Hann window applied; the amplitude is scaled so that a sinusoid of
    amplitude ``a`` falling on a frequency bin reads ``a``. Non-finite samples (gaps) are set to
    the mean before the transform.

    Parameters
    ----------
    t : array_like, (n,)
        Sample times, s (uniform; the median step is used).
    y : array_like, (n,)
        Samples, any unit.

    Returns
    -------
    freq : ndarray, (n // 2 + 1,)
        Frequencies, Hz (resolution ``1 / (n dt)``).
    amplitude : ndarray, (n // 2 + 1,)
        Amplitude, in the unit of ``y``. Both empty when fewer than 4 samples are given.

    Examples
    --------
    >>> t = np.arange(400) / 100.0
    >>> f, a = amplitude_spectrum(t, 0.5 * np.sin(2 * np.pi * 5.0 * t))
    >>> float(f[np.argmax(a)]), round(float(a.max()), 2)
    (5.0, 0.5)
    """
    t = np.asarray(t, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if t.size < 4 or y.shape != t.shape:
        return np.zeros(0), np.zeros(0)
    steps = np.diff(t)
    steps = steps[np.isfinite(steps) & (steps > 0)]
    if steps.size == 0:
        return np.zeros(0), np.zeros(0)
    dt = float(np.median(steps))
    finite = np.isfinite(y)
    mean = float(np.mean(y[finite])) if np.any(finite) else 0.0
    x = np.where(finite, y - mean, 0.0)
    window = np.hanning(x.size)
    spectrum = np.fft.rfft(x * window)
    amplitude = 2.0 * np.abs(spectrum) / np.sum(window)
    return np.fft.rfftfreq(x.size, dt).astype(np.float64), amplitude
