"""Pneumatic tubing between the pressure taps and the scanner: its response, distortion, correction.

A tap's pressure reaches the scanner's transducer through a tube (length ``L``, inner diameter
``D``) that ends in the transducer's internal volume ``V``. The pressure at the transducer is the
tap's filtered by the tube: amplified near the tube's acoustic resonance, attenuated and
delayed above it. This module gives the complex ratio ``H(f) = p_transducer / p_tap``:

* :class:`Tube`, the theory of Bergh and Tijdeman (1965) for one tube ending in a volume
  (viscous and thermal losses in the tube, wave propagation, a polytropic volume)::

      H = 1 / [cosh(phi L) + (V / V_t) (sigma + 1/k) n phi L sinh(phi L)]
      phi = (omega / c) sqrt(J0(a) / J2(a)) sqrt(gamma / n)
      n = 1 / [1 + ((gamma - 1) / gamma) J2(a sqrt(Pr)) / J0(a sqrt(Pr))]
      a = i^(3/2) (D / 2) sqrt(rho omega / mu)        (the shear wave number)

  with ``V_t = pi D^2 L / 4`` the tube's volume, ``sigma`` the volume's relative increase by
  diaphragm deflection (0 for a stiff transducer), ``k`` the volume's polytropic constant
  (``gamma`` adiabatic, 1 isothermal) and the air's density ``rho``, viscosity ``mu``, speed of
  sound ``c``, ratio of specific heats ``gamma`` and Prandtl number ``Pr`` (:class:`Air`, from the
  air's pressure and temperature). Limits: ``H -> 1`` as ``f -> 0``; without losses and volume
  ``H = 1 / cos(omega L / c)`` (the organ pipe closed at the transducer, resonant at
  ``c / (4 L)``), and a small volume lengthens the pipe to ``L_eff = L + V / (pi D^2 / 4)``.
* :class:`TableResponse`, a measured response (frequency, gain, phase), interpolated.

A :class:`TubingSet` assigns a response to each tap group. :func:`distort` applies the tubing to
tap pressures (what a scanner behind the tubes records); :func:`correct` undoes it. Both work on a
whole record by FFT. The record is extended past its end by a half-cosine back to its first
value, so that the periodic extension the FFT assumes is continuous (no jump to ring through
the filter), and padded to at least twice its length, so that the tube's impulse response (tens
of ms) does not wrap around. The pressure before the record is taken to be steady at its first
value (a release starts from a held, steady state). The correction divides the spectrum by ``H``
only up to a cut-off ``f_c``: above the lowest frequency where ``|H|`` falls below
``gain_floor`` (default 0.5), the tube has let little through and dividing would amplify the
scanner's noise by ``1 / |H|`` without bound; there the corrected spectrum is set to zero, with
a raised-cosine roll-off from ``0.8 f_c`` (a real window, so zero-phase; a brick wall would
ring). The section model's frequencies (a few Hz) lie far below any practical tube's cut-off
(tens of Hz), so the band limit removes only noise.

Units: m, m^3, Pa, K, Hz, rad. Phases are of ``H`` (negative: the transducer lags the tap).
Pure numerics; the rig config's ``[[taps.tubing]]`` tables are parsed in
:mod:`daq.tubing_config`.
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt
from scipy.special import jve

from ident.numerics import validate as v
from ident.physics.air import R_DRY_AIR

__all__ = [
    "Air",
    "FrequencyResponse",
    "TableResponse",
    "Tube",
    "TubingGroup",
    "TubingSet",
    "correct",
    "cutoff",
    "distort",
    "force_correction",
    "from_description",
    "tubing_set",
]

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]

#: Default fraction of the tube's gain below which the correction stops (module docstring).
GAIN_FLOOR = 0.5
#: Fraction of the cut-off where the correction's roll-off begins (below it: exactly 1 / H).
TAPER_START = 0.8


@dataclass(frozen=True)
class Air:
    """Air in the tubes: static pressure and temperature, and the properties they give.

    Parameters
    ----------
    pressure_pa : float
        Absolute static pressure, Pa (default 101325).
    temperature_k : float
        Temperature, K (default 293.15).
    gamma : float
        Ratio of specific heats (1.4 for air).
    prandtl : float
        Prandtl number (0.71 for air near room temperature).
    """

    pressure_pa: float = 101325.0
    temperature_k: float = 293.15
    gamma: float = 1.4
    prandtl: float = 0.71

    def __post_init__(self) -> None:
        v.positive("pressure_pa", self.pressure_pa)
        v.positive("temperature_k", self.temperature_k)
        if not v.finite("gamma", self.gamma) > 1.0:
            raise ValueError(f"gamma must be > 1, got {self.gamma!r}")
        v.positive("prandtl", self.prandtl)

    @property
    def density(self) -> float:
        """Density by the ideal-gas law, kg/m^3."""
        return self.pressure_pa / (R_DRY_AIR * self.temperature_k)

    @property
    def viscosity(self) -> float:
        """Dynamic viscosity by Sutherland's law (air: 1.716e-5 Pa s at 273.15 K, S = 110.4 K)."""
        T = self.temperature_k
        return 1.716e-5 * (T / 273.15) ** 1.5 * (273.15 + 110.4) / (T + 110.4)

    @property
    def speed_of_sound(self) -> float:
        """Adiabatic speed of sound, m/s."""
        return math.sqrt(self.gamma * R_DRY_AIR * self.temperature_k)


class FrequencyResponse(Protocol):
    """Anything that gives ``H(f) = p_transducer / p_tap`` at frequencies ``f`` (Hz)."""

    def response(self, f: npt.ArrayLike, air: Air) -> ComplexArray:
        """Complex ratio at ``f`` (NaN where unknown)."""
        ...

    def describe(self) -> dict[str, Any]:
        """Return the parameters, for the run file and reports."""
        ...


@dataclass(frozen=True)
class Tube:
    """One tube from a tap to a transducer volume (Bergh and Tijdeman, 1965).

    Parameters
    ----------
    length : float
        Tube length, m, > 0.
    diameter : float
        Inner diameter, m, > 0.
    volume : float
        Transducer (end) volume, m^3, >= 0.
    sigma : float
        Relative increase of the volume by diaphragm deflection, >= 0 (0: a stiff transducer).
    k : float or None
        Polytropic constant of the volume, in [1, gamma] (None: adiabatic, the air's gamma).
    """

    length: float
    diameter: float
    volume: float = 0.0
    sigma: float = 0.0
    k: float | None = None

    def __post_init__(self) -> None:
        v.positive("length", self.length)
        v.positive("diameter", self.diameter)
        if v.finite("volume", self.volume) < 0.0:
            raise ValueError(f"volume must be >= 0, got {self.volume!r}")
        if v.finite("sigma", self.sigma) < 0.0:
            raise ValueError(f"sigma must be >= 0, got {self.sigma!r}")
        if self.k is not None and not 1.0 <= v.finite("k", self.k) <= 1.67:
            raise ValueError(f"k must be in [1, 1.67] (isothermal to monatomic), got {self.k!r}")

    @property
    def tube_volume(self) -> float:
        """Inner volume of the tube, m^3."""
        return math.pi * self.diameter**2 / 4.0 * self.length

    def response(self, f: npt.ArrayLike, air: Air) -> ComplexArray:
        """``p_transducer / p_tap`` at frequencies ``f`` (Hz, >= 0); exactly 1 at f = 0."""
        f = np.asarray(f, dtype=float)
        if np.any(~np.isfinite(f)) or np.any(f < 0):
            raise ValueError("frequencies must be finite and >= 0")
        out = np.ones(f.shape, dtype=complex)
        pos = f > 0
        omega = 2.0 * np.pi * f[pos]
        gamma = air.gamma
        k = gamma if self.k is None else self.k
        R = self.diameter / 2.0
        a = (1j) ** 1.5 * R * np.sqrt(air.density * omega / air.viscosity)
        # Ratios of Bessel functions of a complex argument: jve scales both by exp(-|Im z|),
        # which cancels in the ratio and keeps it finite at wide bores and high frequencies.
        a_pr = a * math.sqrt(air.prandtl)
        n = 1.0 / (1.0 + (gamma - 1.0) / gamma * jve(2, a_pr) / jve(0, a_pr))
        phi = omega / air.speed_of_sound * np.sqrt(jve(0, a) / jve(2, a)) * np.sqrt(gamma / n)
        phiL = phi * self.length
        # The root's branch: Re(phi) >= 0 (waves decay along the tube); cosh and phi sinh are
        # even in phi, so the branch only matters for clarity.
        denom = np.cosh(phiL) + (self.volume / self.tube_volume) * (self.sigma + 1.0 / k) * n \
            * phiL * np.sinh(phiL)
        out[pos] = 1.0 / denom
        return out

    def describe(self) -> dict[str, Any]:
        """Parameters: kind ``"bergh_tijdeman"``, length, diameter, volume, sigma, k."""
        return {"kind": "bergh_tijdeman", "length": self.length, "diameter": self.diameter,
                "volume": self.volume, "sigma": self.sigma,
                "k": "adiabatic" if self.k is None else self.k}


@dataclass(frozen=True, eq=False)
class TableResponse:
    """A measured tubing response: gain and phase at listed frequencies, interpolated.

    Between rows, gain and (unwrapped) phase are interpolated linearly in frequency; between 0
    and the first row, from ``H(0) = 1`` (gain 1, phase 0). Above the last row the response is
    unknown (NaN): :func:`correct` stops there and :func:`distort` refuses such a record.

    Parameters
    ----------
    frequency : array_like, shape (n,)
        Hz, > 0, strictly increasing.
    gain : array_like, shape (n,)
        ``|H|``, > 0.
    phase : array_like, shape (n,)
        ``arg H``, rad (negative: lag).
    source : str
        Where the table came from (a file name), for the record.
    """

    frequency: FloatArray
    gain: FloatArray
    phase: FloatArray
    source: str = ""

    def __post_init__(self) -> None:
        f = v.positive_array("frequency", self.frequency, ndim=1)
        g = v.positive_array("gain", self.gain, ndim=1)
        p = v.finite_array("phase", self.phase, ndim=1)
        if not f.size == g.size == p.size or f.size < 1:
            raise ValueError(f"frequency, gain and phase need equal lengths >= 1, got "
                             f"{f.size}, {g.size}, {p.size}")
        if np.any(np.diff(f) <= 0):
            raise ValueError("frequency must be strictly increasing")
        for name, arr in (("frequency", f), ("gain", g), ("phase", np.unwrap(p))):
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)

    @classmethod
    def from_csv(cls, path: str | os.PathLike[str]) -> TableResponse:
        """Read a CSV with a header ``frequency, gain, phase_deg`` (Hz, ratio, degrees).

        Raises
        ------
        ValueError
            Naming the file and the row when a column is missing or a value is not a number.
        OSError
            If the file cannot be read.
        """
        path = os.fspath(path)
        with open(path, encoding="utf-8", newline="") as handle:
            rows = list(csv.reader(line for line in handle if not line.lstrip().startswith("#")))
        if not rows:
            raise ValueError(f"{path}: empty; expected a header frequency,gain,phase_deg")
        header = [name.strip() for name in rows[0]]
        need = ["frequency", "gain", "phase_deg"]
        if header != need:
            raise ValueError(f"{path}: header must be {','.join(need)}, got {','.join(header)}")
        values = []
        for number, row in enumerate(rows[1:], start=2):
            if not row:
                continue
            try:
                if len(row) != 3:
                    raise ValueError(f"{len(row)} columns")
                values.append([float(x) for x in row])
            except ValueError as exc:
                raise ValueError(f"{path} line {number}: three numbers expected ({exc})") from exc
        data = np.asarray(values, dtype=float).reshape(-1, 3)
        try:
            return cls(frequency=data[:, 0], gain=data[:, 1], phase=np.radians(data[:, 2]),
                       source=path)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{path}: {exc}") from exc

    def response(self, f: npt.ArrayLike, air: Air | None = None) -> ComplexArray:
        """``H`` at ``f`` (Hz, >= 0); NaN above the last row. ``air`` is ignored (measured)."""
        f = np.asarray(f, dtype=float)
        fx = np.concatenate([[0.0], self.frequency])
        gain = np.interp(f, fx, np.concatenate([[1.0], self.gain]))
        phase = np.interp(f, fx, np.concatenate([[0.0], self.phase]))
        out = gain * np.exp(1j * phase)
        return np.where(f > self.frequency[-1], np.nan + 0j, out)

    def describe(self) -> dict[str, Any]:
        """Parameters: kind ``"table"``, the source and the table's rows."""
        return {"kind": "table", "source": self.source, "frequency": self.frequency.tolist(),
                "gain": self.gain.tolist(), "phase_deg": np.degrees(self.phase).tolist()}


@dataclass(frozen=True)
class TubingGroup:
    """One response shared by a group of taps.

    Parameters
    ----------
    taps : tuple of int or None
        Tap indices (0-based, in the layout's order); None: every tap.
    model : Tube or TableResponse
    """

    taps: tuple[int, ...] | None
    model: Tube | TableResponse


@dataclass(frozen=True)
class TubingSet:
    """The tubing of every tap: groups of taps, each with its response; others have none.

    Parameters
    ----------
    groups : sequence of TubingGroup
        No tap may be in two groups.
    n_taps : int
        Number of taps of the layout.
    air : Air
        Air in the tubes (the run's ambient pressure and temperature).
    """

    groups: tuple[TubingGroup, ...]
    n_taps: int
    air: Air = field(default_factory=Air)

    def __post_init__(self) -> None:
        object.__setattr__(self, "groups", tuple(self.groups))
        seen: dict[int, int] = {}
        for index in range(len(self.groups)):
            for tap in self.members(index):
                if tap in seen:
                    raise ValueError(f"tap {tap} is in tubing groups {seen[tap]} and {index}")
                seen[tap] = index

    def members(self, index: int) -> npt.NDArray[np.intp]:
        """Tap indices of group ``index``."""
        taps = self.groups[index].taps
        if taps is None:
            return np.arange(self.n_taps)
        arr = np.asarray(taps, dtype=np.intp)
        if arr.size == 0 or np.any(arr < 0) or np.any(arr >= self.n_taps):
            raise ValueError(f"tubing group {index}: taps must be in 0..{self.n_taps - 1}, got "
                             f"{list(taps)}")
        if np.unique(arr).size != arr.size:
            raise ValueError(f"tubing group {index}: a tap is listed twice")
        return arr

    def response(self, f: npt.ArrayLike) -> ComplexArray:
        """``H`` per tap, shape (len(f), n_taps); 1 for taps without tubing."""
        f = np.atleast_1d(np.asarray(f, dtype=float))
        out = np.ones((f.size, self.n_taps), dtype=complex)
        for index, group in enumerate(self.groups):
            out[:, self.members(index)] = group.model.response(f, self.air)[:, None]
        return out

    def describe(self) -> list[dict[str, Any]]:
        """Each group's taps (``"all"`` or a list) and model parameters, for the run file."""
        return [{"taps": "all" if g.taps is None else list(g.taps), **g.model.describe()}
                for g in self.groups]


def _padded(x: FloatArray) -> tuple[FloatArray, int]:
    """Return the record minus its first row, extended to a continuous period, and its length."""
    n = x.shape[0]
    n_fft = 1 << int(math.ceil(math.log2(max(2 * n, 64))))
    base = x - x[:1]
    pad = n_fft - n
    # Half-cosine from the last value back to 0 (the first value, removed above).
    s = (np.arange(1, pad + 1) / (pad + 1))[:, None]
    taper = base[-1:] * 0.5 * (1.0 + np.cos(np.pi * s))
    return np.concatenate([base, taper]), n


def _filtered(pressures: Any, fs: float, tubing: TubingSet, gains: Any) -> FloatArray:
    """Filter the columns of taps with tubing by ``gains(freqs)`` (shape (n_freqs, n_taps))."""
    p = v.finite_array("pressures", pressures, ndim=2)
    fs = v.positive("fs", fs)
    if p.shape[0] < 2:
        raise ValueError(f"pressures need at least 2 samples, got {p.shape[0]}")
    if p.shape[1] != tubing.n_taps:
        raise ValueError(f"pressures must have shape (n_samples, {tubing.n_taps}), got {p.shape}")
    out = p.copy()
    if not tubing.groups:
        return out
    tubed = np.concatenate([tubing.members(i) for i in range(len(tubing.groups))])
    ext, n = _padded(p[:, tubed])
    freqs = np.fft.rfftfreq(ext.shape[0], 1.0 / fs)
    spectrum = np.fft.rfft(ext, axis=0) * gains(freqs)[:, tubed]
    out[:, tubed] = np.fft.irfft(spectrum, ext.shape[0], axis=0)[:n] + p[:1, tubed]
    return out


def distort(pressures: Any, fs: float, tubing: TubingSet) -> FloatArray:
    """Pressures at the transducers for tap pressures ``pressures`` (the tubing applied).

    Parameters
    ----------
    pressures : array_like, shape (n_samples, n_taps)
        Tap pressures, Pa, sampled at ``fs``; steady at the first row before the record.
    fs : float
        Sampling rate, Hz.
    tubing : TubingSet

    Returns
    -------
    ndarray, shape (n_samples, n_taps)
        Pa.

    Raises
    ------
    ValueError
        If a table response does not reach the Nyquist frequency (the distortion there would be
        unknown).
    """
    def gains(freqs: FloatArray) -> ComplexArray:
        H = tubing.response(freqs)
        if np.any(np.isnan(H)):
            raise ValueError(f"a tubing table ends below the Nyquist frequency {fs / 2:g} Hz: "
                             "its distortion there is unknown")
        return H

    return _filtered(pressures, fs, tubing, gains)


def cutoff(model: Tube | TableResponse, air: Air, fs: float,
           gain_floor: float = GAIN_FLOOR) -> float:
    """Highest frequency (Hz) :func:`correct` divides by this response up to.

    The lowest frequency where ``|H|`` falls below ``gain_floor`` (or the table ends), else the
    Nyquist frequency ``fs / 2``; found on a 0.1 Hz grid.
    """
    freqs = np.arange(0.0, fs / 2.0 + 0.05, 0.1)
    gain = np.abs(model.response(freqs, air))
    bad = np.flatnonzero(~(gain >= gain_floor))  # NaN (beyond a table) counts as too small
    return float(freqs[bad[0]]) if bad.size else float(fs / 2.0)


def correct(pressures: Any, fs: float, tubing: TubingSet,
            gain_floor: float = GAIN_FLOOR) -> FloatArray:
    """Tap pressures recovered from transducer pressures (the tubing undone, band-limited).

    Zero-phase, on the whole record: the spectrum is divided by ``H`` of each tap's tubing up
    to its :func:`cutoff` and set to zero above (see the module docstring for why). Taps
    without tubing are returned unchanged.

    Parameters
    ----------
    pressures : array_like, shape (n_samples, n_taps)
        Transducer pressures, Pa, sampled at ``fs``; steady at the first row before the record.
    fs : float
        Sampling rate, Hz.
    tubing : TubingSet
    gain_floor : float
        In (0, 1]: the cut-off is where the tube's gain first falls below it.

    Returns
    -------
    ndarray, shape (n_samples, n_taps)
        Pa.
    """
    if not 0.0 < v.finite("gain_floor", gain_floor) <= 1.0:
        raise ValueError(f"gain_floor must be in (0, 1], got {gain_floor!r}")
    limits = np.full(tubing.n_taps, np.inf)
    for index, group in enumerate(tubing.groups):
        limits[tubing.members(index)] = cutoff(group.model, tubing.air, fs, gain_floor)

    def gains(freqs: FloatArray) -> ComplexArray:
        H = tubing.response(freqs)
        # A raised-cosine roll-off over the top fifth of the band instead of a brick wall,
        # whose 1/t ringing would spread an end effect over the whole record.
        start = TAPER_START * limits[None, :]
        with np.errstate(invalid="ignore", divide="ignore"):
            x = np.clip((freqs[:, None] - start) / (limits[None, :] - start), 0.0, 1.0)
            window = 0.5 * (1.0 + np.cos(np.pi * x))
            return np.where(freqs[:, None] < limits[None, :], window / H, 0.0)

    return _filtered(pressures, fs, tubing, gains)


def tubing_set(groups: Iterable[TubingGroup], n_taps: int,
               air: Air | None = None) -> TubingSet:
    """Build a :class:`TubingSet` (a convenience: ``air`` defaults to standard air)."""
    return TubingSet(groups=tuple(groups), n_taps=int(n_taps), air=air or Air())


def from_description(groups: Sequence[Mapping[str, Any]], n_taps: int,
                     air: Air | None = None) -> TubingSet:
    """Rebuild a :class:`TubingSet` from :meth:`TubingSet.describe` (e.g. read from a run file).

    Raises
    ------
    ValueError
        If a group's ``kind`` is unknown or its parameters are invalid (naming the group).
    """
    out = []
    for index, item in enumerate(groups):
        taps = item.get("taps", "all")
        tap_tuple = None if taps == "all" else tuple(int(t) for t in taps)
        kind = item.get("kind")
        try:
            model: Tube | TableResponse
            if kind == "bergh_tijdeman":
                k = item.get("k", "adiabatic")
                model = Tube(length=float(item["length"]), diameter=float(item["diameter"]),
                             volume=float(item["volume"]), sigma=float(item.get("sigma", 0.0)),
                             k=None if k == "adiabatic" else float(k))
            elif kind == "table":
                model = TableResponse(frequency=np.asarray(item["frequency"], dtype=float),
                                      gain=np.asarray(item["gain"], dtype=float),
                                      phase=np.radians(np.asarray(item["phase_deg"], dtype=float)),
                                      source=str(item.get("source", "")))
            else:
                raise ValueError(f"kind must be 'bergh_tijdeman' or 'table', got {kind!r}")
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"tubing group {index}: {exc}") from exc
        out.append(TubingGroup(taps=tap_tuple, model=model))
    return tubing_set(out, n_taps, air)


def force_correction(pressures: Any, fs: float, tubing: TubingSet,
                     integration: Any, gain_floor: float = GAIN_FLOOR) -> FloatArray:
    """Change of lift and moment when the tubing is undone: ``G (correct(p) - p)``.

    Added to forces integrated from the recorded pressures it gives the forces of the
    corrected pressures, whatever else went into the recorded forces. A tap whose pressure is
    not finite somewhere in the record (a gap, a dead channel) is left uncorrected.

    Parameters
    ----------
    pressures : array_like, shape (n_samples, n_taps)
        Recorded (transducer) pressures, Pa, sampled at ``fs``.
    fs : float
        Hz.
    tubing : TubingSet
    integration : array_like, shape (2, n_taps)
        ``[L, M] = G p`` (:meth:`ident.physics.taps.TapLayout.integration_matrix`).
    gain_floor : float
        See :func:`correct`.

    Returns
    -------
    ndarray, shape (n_samples, 2)
        Lift (N/m) and moment (N m/m) to add.
    """
    p = np.array(pressures, dtype=float, ndmin=2)
    G = v.finite_array("integration", integration, ndim=2)
    if G.shape != (2, tubing.n_taps) or p.shape[1] != tubing.n_taps:
        raise ValueError(f"need {tubing.n_taps} taps: pressures {p.shape}, integration {G.shape}")
    usable = np.all(np.isfinite(p), axis=0)
    p[:, ~usable] = 0.0
    delta = correct(p, fs, tubing, gain_floor) - p
    delta[:, ~usable] = 0.0
    return np.asarray(delta @ G.T, dtype=float)
