"""The virtual tunnel's releases: free-vibration decays of a section model in the wind, as recorded.

The physics (exact matrix-exponential stepping of the linear aeroelastic system, ETD2RK for the
structural nonlinearities, the measurement effects) lives in :mod:`ident.simulation.decay`, shared
with the discrepancy workflow; the effects in :mod:`ident.physics.effects` (re-exported by
:mod:`simulators.effects`).
This module adds what the instruments add: the held, static stretch before the release and
Gaussian measurement noise, and returns the record as a :class:`SimulatedRelease`. In turbulent
flow (``static`` and ``turbulence``, :mod:`ident.physics.turbulence`) the buffeting forces act on
the held model (which does not move; the forces fluctuate) and drive it after the release, which
then decays into a random response.

This module knows physics only; the simulated instruments sample it through their own wire
protocols.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ident.model.quasi_steady import StaticCoefficients
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.numerics import validate as v
from ident.physics.effects import Effect
from ident.physics.taps import TapLayout
from ident.physics.tubing import TubingSet, distort
from ident.physics.turbulence import GustField, TurbulenceSpec
from ident.simulation.decay import CHANNELS, CHANNELS_3DOF, channels, simulate_decay

__all__ = ["CHANNELS", "SimulatedRelease", "noise_scale", "simulate_release"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class SimulatedRelease:
    """One simulated free decay, as the instruments would record it.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Time from the release, s (negative during the optional hold before it).
    h, alpha : ndarray, shape (n,)
        Heave (m, positive down) and pitch (rad, positive nose-up), with measurement effects and
        noise.
    lift, moment : ndarray, shape (n,)
        Self-excited (plus vortex, plus mean and buffeting wind load) lift, N/m, and moment,
        N m/m, with measurement effects and noise.
    U, rho, fs : float
        Wind speed (m/s), air density (kg/m^3), sampling rate (Hz).
    h0, alpha0 : float
        Release position, m and rad.
    clean : dict
        The four channels before measurement effects and noise (the physical truth).
    section : SectionModel
        The structure as simulated (including any static unbalance effect).
    model : RationalFunctionModel
        The aerodynamic model simulated.
    effects : tuple of Effect
        Extra physics included.
    p, drag : ndarray, shape (n,), or None
        Sway (m, downwind) and drag (N/m, downwind), with measurement noise: a section with a
        lateral spring and a 3-DOF model only.
    p0 : float
        Sway of the release position, m.
    """

    t: FloatArray
    h: FloatArray
    alpha: FloatArray
    lift: FloatArray
    moment: FloatArray
    U: float
    rho: float
    fs: float
    h0: float
    alpha0: float
    clean: dict[str, FloatArray] = field(repr=False)
    section: SectionModel = field(repr=False)
    model: RationalFunctionModel = field(repr=False)
    effects: tuple[Effect, ...] = ()
    p: FloatArray | None = None
    drag: FloatArray | None = None
    p0: float = 0.0

    def pressures(self, taps: TapLayout, mean: Any = None,
                  tubing: TubingSet | None = None) -> FloatArray:
        """Tap pressures (Pa), shape (n, n_taps), that integrate exactly to ``lift`` and ``moment``.

        See :meth:`ident.physics.taps.TapLayout.pressures_for`; ``mean`` is a steady distribution,
        Pa. With sway, they integrate to the ``drag`` too when the outline has faces across the wind
        (:attr:`~ident.physics.taps.TapLayout.carries_drag`; a plate's taps cannot carry it).
        With ``tubing``, the pressures behind the tubes (:func:`ident.physics.tubing.distort`, the
        record taken as steady before its first sample: simulate with ``pre_s`` for a hold).
        """
        drag = self.drag if self.drag is not None and taps.carries_drag else None
        p = taps.pressures_for(self.lift, self.moment, mean=mean, drag=drag)
        return p if tubing is None else distort(p, self.fs, tubing)


def simulate_release(
    section: SectionModel,
    model: RationalFunctionModel,
    U: float,
    h0: float,
    alpha0: float,
    *,
    duration: float,
    fs: float,
    noise: float | Mapping[str, float] = 0.0,
    rng: np.random.Generator | int | None = None,
    effects: Iterable[Effect] = (),
    oversample: int = 8,
    pre_s: float = 0.0,
    static: StaticCoefficients | None = None,
    turbulence: TurbulenceSpec | GustField | None = None,
    span: float | None = None,
    p0: float = 0.0,
) -> SimulatedRelease:
    """Simulate a free-vibration release of a section model at wind speed ``U``.

    Parameters
    ----------
    section : SectionModel
        Structure and air density.
    model : RationalFunctionModel
        Self-excited forces.
    U : float
        Mean wind speed, m/s, >= 0.
    h0, alpha0 : float
        Position held before the release, m and rad.
    duration : float
        Length of the record after the release, s, > 0.
    fs : float
        Output sampling rate, Hz, > 0.
    noise : float or dict, optional
        Gaussian measurement noise as a fraction of each channel's RMS (one number for all
        channels, or a dict by channel name ``h, alpha, lift, moment``, with sway ``p, drag``).
    rng : numpy.random.Generator or int, optional
        Random source (or seed) of the noise and of the turbulence (drawn first); required when
        ``noise`` is not zero or ``turbulence`` is a spec, so that every simulation is
        reproducible.
    effects : iterable of Effect, optional
        Extra physics (:mod:`ident.physics.effects`); at most one of each kind.
    oversample : int, optional
        Integrator steps per output sample for nonlinear effects (>= 1); raised automatically when
        a stiff effect (smoothed friction) needs a smaller step.
    pre_s : float, optional
        Seconds of the held, static model recorded before the release (t < 0), >= 0.
    static, turbulence, span : optional
        Wind load: static coefficients (mean load), turbulence (spec or gust field) and the
        section model's span, m; see :func:`ident.simulation.decay.simulate_decay`.
    p0 : float, optional
        Sway held before the release, m (a section with sway: three degrees of freedom).

    Returns
    -------
    SimulatedRelease

    Examples
    --------
    >>> from ident import SectionModel
    >>> from ident.model import flat_plate
    >>> s = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)
    >>> r = simulate_release(s, flat_plate.jones_model(), 5.0, 0.0, 0.02, duration=10.0, fs=200.0)
    >>> r.t.shape, float(r.alpha[0])
    ((2000,), 0.02)
    """
    duration = v.positive("duration", duration)
    fs = v.positive("fs", fs)
    pre_s = v.finite("pre_s", pre_s)
    if pre_s < 0.0:
        raise ValueError(f"pre_s must be >= 0, got {pre_s!r}")
    noise_frac = _noise_fractions(noise)
    if any(noise_frac.values()) and rng is None:
        raise ValueError("noise needs rng (a numpy Generator or a seed) so that it is reproducible")
    if isinstance(turbulence, TurbulenceSpec) and rng is None:
        raise ValueError("turbulence needs rng (a numpy Generator or a seed) so that it is "
                         "reproducible")
    generator = np.random.default_rng(rng) if rng is not None else None
    n = int(round(duration * fs))
    if n < 2:
        raise ValueError(f"duration * fs must give at least 2 samples, got {n}")

    spec_rng = generator if isinstance(turbulence, TurbulenceSpec) else None
    decay = simulate_decay(section, model, U, h0, alpha0, n=n, fs=fs, effects=effects,
                           oversample=oversample, static=static, turbulence=turbulence,
                           span=span, rng=spec_rng, pre_s=pre_s, p0=p0)
    t, clean, measured = decay.t, decay.clean, decay.measured
    names = channels(decay.n_dof)
    if decay.n_dof == 2 and isinstance(noise, Mapping) and any(noise.get(n) for n in ("p", "drag")):
        raise ValueError("noise on p or drag needs a section with sway (fp)")
    if pre_s > 0.0:
        n_pre = int(round(pre_s * fs))
        t_pre = np.asarray(-np.arange(n_pre, 0, -1) * (1.0 / fs), dtype=np.float64)
        held_clean, held_measured = decay.held(t_pre)
        t = np.concatenate([t_pre, t])
        clean = {name: np.concatenate([held_clean[name], clean[name]]) for name in names}
        measured = {name: np.concatenate([held_measured[name], measured[name]])
                    for name in names}
    if generator is not None:
        for name in names:  # in CHANNELS_3DOF order: a 2-DOF record draws as before
            frac = noise_frac[name]
            if frac:
                measured[name] = measured[name] + generator.normal(
                    0.0, frac * noise_scale(clean[name]), t.size)
    return SimulatedRelease(
        t=t,
        **measured,
        U=decay.U,
        rho=decay.rho,
        fs=fs,
        h0=decay.h0,
        alpha0=decay.alpha0,
        clean=clean,
        section=decay.section,
        model=model,
        effects=decay.effects,
        p0=decay.p0,
    )


def noise_scale(clean: npt.ArrayLike) -> float:
    """Return what a channel's noise fraction multiplies: the RMS of its whole clean record.

    The whole record as recorded: the decay, the random response in turbulence, the mean wind
    load and the static deflection it causes, and the held part before the release. In
    turbulence that is several times the decay's own RMS.
    """
    return math.sqrt(float(np.mean(np.asarray(clean, dtype=float) ** 2)))


def _noise_fractions(noise: float | Mapping[str, float]) -> dict[str, float]:
    if isinstance(noise, Mapping):
        unknown = sorted(set(noise) - set(CHANNELS_3DOF))
        if unknown:
            raise ValueError(f"noise has unknown channel(s) {unknown}; channels are "
                             f"{CHANNELS_3DOF}")
        fractions = {name: float(noise.get(name, 0.0)) for name in CHANNELS_3DOF}
    else:
        fractions = dict.fromkeys(CHANNELS_3DOF, v.finite("noise", noise))
    for name, frac in fractions.items():
        if not (math.isfinite(frac) and frac >= 0.0):
            raise ValueError(f"noise for {name} must be a finite fraction >= 0, got {frac!r}")
    return fractions
