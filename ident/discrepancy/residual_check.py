"""Is a systematic residual left after the named effects, and where is it (the honest answer).

:func:`locate_residual` splits, per channel, what is left of measured minus simulated into the
white measurement noise and a systematic part. The noise's variance is estimated from the
first differences of the residual (``var(diff e) / 2``: differencing leaves white noise's
variance doubled and removes most of a smooth error, whose frequencies are far below the
sampling rate), the systematic part is the rest. A channel whose systematic RMS is more than
``SYSTEMATIC_LIMIT`` of the channel's RMS *and* more than ``NOISE_RATIO`` times the noise's is
reported: what is left counts as explained only when it is white at the noise level. (The
floor of ``SYSTEMATIC_LIMIT`` keeps the identified linear model's own error, a fraction of a
per cent of a channel on clean decays, from being reported when the noise is far below 2 %.)
Correctly named effects meet this: the aerodynamic model is identified again beside them
(:mod:`ident.discrepancy.effect_selection`), and what they leave is 0.1-0.4 of the noise at
2 % noise (without the refit, friction at twice its realistic strength leaves 1.3-1.7 times
the noise, and is reported).
Each finding says where the residual is:

- a **spectral line**: the averaged periodogram of the residual has a peak holding at least
  ``LINE_SHARE`` of the systematic power; its frequency per wind speed says whether it moves
  with the wind (shedding-like) or stays put (a machine, the floor); in the lowest bin it is
  called a slow drift or offset;
- the **amplitude range**: the systematic power in four bands of the channel's own envelope
  (quartiles); where it is largest, or "at all amplitudes" when within a factor of two;
- the **wind speeds** at which the systematic part exceeds the limit.

Not responsible for: choosing effects (:mod:`ident.discrepancy.effect_selection`) or the report
(:mod:`ident.discrepancy.workflow`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ident.records.release import Release
from ident.simulation.decay import CHANNELS

__all__ = ["LINE_SHARE", "NOISE_RATIO", "SYSTEMATIC_LIMIT", "ResidualFinding",
           "locate_residual", "systematic_left", "systematic_levels"]

FloatArray = npt.NDArray[np.float64]

#: A channel's systematic residual must exceed this fraction of the channel's RMS (module doc) ...
SYSTEMATIC_LIMIT = 0.02
#: ... and this multiple of the white noise's RMS to count as unexplained.
NOISE_RATIO = 1.0
#: A periodogram peak (+-1 bin) holding at least this share of the systematic power is a line.
LINE_SHARE = 0.3
#: Segment length of the averaged periodogram, s (resolution 1/SEGMENT_S Hz).
SEGMENT_S = 2.0
_UNITS = {"h": (1e3, "mm"), "alpha": (180 / math.pi, "deg"), "lift": (1.0, "N/m"),
          "moment": (1.0, "N m/m")}


@dataclass(frozen=True)
class ResidualFinding:
    """A systematic residual left in one channel.

    Attributes
    ----------
    channel : str
        ``h``, ``alpha``, ``lift`` or ``moment``.
    systematic : float
        RMS of the systematic part over the channel's RMS.
    baseline : float
        The same of the baseline (without effects).
    noise : float
        RMS of the white part over the channel's RMS.
    line_hz : float or None
        Frequency of a spectral line holding the residual, Hz (None: no line).
    line_share : float
        Share of the systematic power in that line.
    line_per_speed : dict of float to float
        The line's frequency at each wind speed (m/s -> Hz).
    amplitudes : tuple of float or None
        The band of the channel's envelope (SI units) where the residual is largest; None when
        it is about the same at all amplitudes.
    wind_speeds : tuple of float
        Wind speeds (m/s) at which the systematic part exceeds the limit.
    """

    channel: str
    systematic: float
    baseline: float
    noise: float
    line_hz: float | None
    line_share: float
    line_per_speed: dict[float, float]
    amplitudes: tuple[float, float] | None
    wind_speeds: tuple[float, ...]

    def text(self) -> str:
        """Return the finding in plain words, one line."""
        parts = [f"{self.channel}: a systematic residual of {self.systematic:.1%} of the "
                 f"channel's RMS (baseline {self.baseline:.1%}, white noise {self.noise:.1%})"]
        if self.line_hz is not None and self.line_hz <= 1.0 / SEGMENT_S + 1e-9:
            parts.append(f"mostly ({self.line_share:.0%}) a slow drift or offset (below "
                         f"{1.0 / SEGMENT_S:.2g} Hz)")
        elif self.line_hz is not None:
            freqs = list(self.line_per_speed.values())
            speeds = list(self.line_per_speed)
            if len(freqs) > 1 and max(freqs) - min(freqs) <= 2.0 / SEGMENT_S:
                where = "the same at every wind speed"
            elif len(freqs) > 1:
                where = ("moving with the wind: " + ", ".join(
                    f"{f:.2f} Hz at {u:.1f} m/s" for u, f in zip(speeds, freqs, strict=True)))
            else:
                where = "at one wind speed"
            parts.append(f"mostly ({self.line_share:.0%}) a spectral line at {self.line_hz:.2f} "
                         f"Hz, {where}")
        else:
            parts.append("spread over frequencies (no single line)")
        scale, unit = _UNITS[self.channel]
        if self.amplitudes is None:
            parts.append("about the same at all amplitudes")
        else:
            lo, hi = self.amplitudes
            parts.append(f"largest where the amplitude is {lo * scale:.3g}-{hi * scale:.3g} "
                         f"{unit}")
        parts.append("at " + ", ".join(f"{u:.1f}" for u in self.wind_speeds) + " m/s"
                     if self.wind_speeds else "spread over the wind speeds")
        return "; ".join(parts)


def systematic_levels(releases: Sequence[Release],
                      simulated: Sequence[dict[str, FloatArray]]) -> dict[str, tuple[float, float]]:
    """Return per channel (systematic RMS, noise RMS), each over the channel's RMS."""
    out = {}
    for name in CHANNELS:
        total = noise = signal = 0.0
        n = 0
        for r, s in zip(releases, simulated, strict=True):
            m = np.asarray(getattr(r, name), dtype=float)
            e = m - s[name]
            e = e - e.mean()
            total += float(e @ e)
            noise += 0.5 * float(np.sum(np.diff(e) ** 2)) * e.size / max(e.size - 1, 1)
            signal += float(m @ m)
            n += e.size
        if signal <= 0:
            continue
        out[name] = (math.sqrt(max(total - noise, 0.0) / signal), math.sqrt(noise / signal))
    return out


def systematic_left(releases: Sequence[Release],
                    simulated: Sequence[dict[str, FloatArray]]) -> bool:
    """Return True when a channel has a systematic residual (as :func:`locate_residual` reports).

    Parameters
    ----------
    releases : sequence of Release
        The measured decays.
    simulated : sequence of dict
        Per release, the four channels of a model (as measured).
    """
    return any(_significant(systematic, noise)
               for systematic, noise in systematic_levels(releases, simulated).values())


def locate_residual(releases: Sequence[Release], simulated: Sequence[dict[str, FloatArray]],
                    baseline: Sequence[dict[str, FloatArray]]) -> tuple[ResidualFinding, ...]:
    """Return a finding for every channel with a systematic residual (module docstring).

    Parameters
    ----------
    releases : sequence of Release
        The measured decays.
    simulated : sequence of dict
        Per release, the four channels of the model with the named effects.
    baseline : sequence of dict
        The same of the baseline model (no effects).
    """
    releases = list(releases)
    before = systematic_levels(releases, baseline)
    findings = []
    for name, (systematic, noise) in systematic_levels(releases, simulated).items():
        if not _significant(systematic, noise):
            continue
        residuals = [np.asarray(getattr(r, name), dtype=float) - s[name]
                     for r, s in zip(releases, simulated, strict=True)]
        line_hz, share, per_speed = _line(releases, residuals)
        findings.append(ResidualFinding(
            channel=name, systematic=systematic, baseline=before[name][0], noise=noise,
            line_hz=line_hz, line_share=share, line_per_speed=per_speed,
            amplitudes=_amplitude_band(releases, residuals, name),
            wind_speeds=_speeds(releases, simulated, name)))
    return tuple(findings)


def _significant(systematic: float, noise: float) -> bool:
    return systematic > SYSTEMATIC_LIMIT and systematic > NOISE_RATIO * noise


def _spectrum(e: FloatArray, fs: float) -> tuple[FloatArray, FloatArray]:
    from scipy.signal import welch

    nper = min(e.size, int(round(SEGMENT_S * fs)))
    f, p = welch(e - e.mean(), fs=fs, nperseg=nper, detrend="constant")
    return np.asarray(f, dtype=float), np.asarray(p, dtype=float)


def _line(releases: list[Release],
          residuals: list[FloatArray]) -> tuple[float | None, float, dict[float, float]]:
    """Return the line's frequency, its share of the systematic power, its frequency per U."""
    fs = releases[0].fs
    spectra = [_spectrum(e, r.fs) for e, r in zip(residuals, releases, strict=True)]
    f = spectra[0][0]
    power = np.mean([np.interp(f, fi, pi) for fi, pi in spectra], axis=0)
    floor = float(np.median(power))  # white noise: flat
    excess = np.maximum(power - floor, 0.0)
    k = int(np.argmax(excess))
    window = slice(max(k - 1, 0), k + 2)
    share = float(excess[window].sum() / max(excess.sum(), np.finfo(float).tiny))
    if share < LINE_SHARE or excess[k] <= 0 or f[k] <= 0 or f[k] >= 0.45 * fs:
        return None, share, {}
    per_speed: dict[float, float] = {}
    for U in sorted({round(r.U, 1) for r in releases}):
        p = np.mean([np.interp(f, fi, pi) for (fi, pi), r in zip(spectra, releases, strict=True)
                     if round(r.U, 1) == U], axis=0)
        per_speed[U] = float(f[int(np.argmax(p - np.median(p)))])
    return float(f[k]), share, per_speed


def _envelope(x: FloatArray) -> FloatArray:
    from scipy.signal import hilbert

    return np.asarray(np.abs(hilbert(x - x.mean())), dtype=float)


def _amplitude_band(releases: list[Release], residuals: list[FloatArray],
                    name: str) -> tuple[float, float] | None:
    """Return the envelope quartile where the systematic power is largest, or None."""
    env = np.concatenate([_envelope(np.asarray(getattr(r, name), dtype=float))
                          for r in releases])
    e = np.concatenate([x - x.mean() for x in residuals])
    d = np.concatenate([np.append(np.diff(x), 0.0) for x in residuals])
    edges = np.quantile(env, [0.0, 0.25, 0.5, 0.75, 1.0])
    power = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        band = (env >= lo) & (env <= hi)
        power.append(max(float(np.mean(e[band] ** 2) - 0.5 * np.mean(d[band] ** 2)), 0.0))
    best = int(np.argmax(power))
    if power[best] <= 2.0 * min(power):
        return None
    return float(edges[best]), float(edges[best + 1])


def _speeds(releases: list[Release], simulated: Sequence[dict[str, FloatArray]],
            name: str) -> tuple[float, ...]:
    out = []
    for U in sorted({round(r.U, 1) for r in releases}):
        idx = [i for i, r in enumerate(releases) if round(r.U, 1) == U]
        here = [releases[i] for i in idx]
        level = systematic_levels(here, [simulated[i] for i in idx])
        if name in level and _significant(*level[name]):
            out.append(U)
    return tuple(out)
