"""The virtual tunnel's physics: free-vibration releases of a section model in the wind.

A release starts from rest at ``(h0, alpha0)`` with all aerodynamic lag states at zero (DESIGN.md)
and runs freely. The linear physics (structure plus Roger self-excited forces, plus static
unbalance and harmonic vortex forcing, which stay linear) is advanced by its exact discretisation
``z[k+1] = expm(A dt) z[k]``. Structural nonlinearities (friction, quadratic damping, cubic springs)
are added by a second-order exponential integrator (ETD2RK of Cox and Matthews) on a fixed step
that is a multiple of the output rate: exact for the linear part, second order for the nonlinear
part. Measurement effects (channel delay, crosstalk) and noise are applied to the recorded channels
last. The forces returned are the self-excited forces (plus vortex forcing): what the surface
pressures integrate to, not the spring or friction forces.

This module knows physics only; the simulated instruments (later) sample it through their own
wire protocols.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.interpolate import CubicSpline
from scipy.linalg import expm

from ident import _validate as v
from ident.rfc import RationalFunctionModel
from ident.section import SectionModel
from ident.statespace import AeroelasticSystem
from ident.taps import TapLayout
from simulators.effects import (
    ChannelDelay,
    Effect,
    SensorCrosstalk,
    StaticUnbalance,
    VortexShedding,
)

__all__ = ["CHANNELS", "SimulatedRelease", "simulate_release"]

#: Recorded channels of a release, in order.
CHANNELS: tuple[str, ...] = ("h", "alpha", "lift", "moment")

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
        Self-excited (plus vortex) lift, N/m, and moment, N m/m, with measurement effects and noise.
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

    def pressures(self, taps: TapLayout, mean: Any = None) -> FloatArray:
        """Tap pressures (Pa), shape (n, n_taps), that integrate exactly to ``lift`` and ``moment``.

        See :meth:`ident.taps.TapLayout.pressures_for`; ``mean`` is a steady distribution, Pa.
        """
        return taps.pressures_for(self.lift, self.moment, mean=mean)


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
        Gaussian measurement noise as a fraction of each channel's RMS (one number for all four
        channels, or a dict by channel name ``h, alpha, lift, moment``).
    rng : numpy.random.Generator or int, optional
        Random source (or seed) of the noise; required when ``noise`` is not zero, so that every
        noisy simulation is reproducible.
    effects : iterable of Effect, optional
        Extra physics (:mod:`simulators.effects`); at most one of each kind.
    oversample : int, optional
        Integrator steps per output sample for nonlinear effects (>= 1); raised automatically when
        a stiff effect (smoothed friction) needs a smaller step.
    pre_s : float, optional
        Seconds of the held, static model recorded before the release (t < 0), >= 0.

    Returns
    -------
    SimulatedRelease

    Examples
    --------
    >>> from ident import SectionModel, flat_plate
    >>> s = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)
    >>> r = simulate_release(s, flat_plate.jones_model(), 5.0, 0.0, 0.02, duration=10.0, fs=200.0)
    >>> r.t.shape, float(r.alpha[0])
    ((2000,), 0.02)
    """
    U = v.finite("U", U)
    if U < 0.0:
        raise ValueError(f"U must be >= 0, got {U!r}")
    duration = v.positive("duration", duration)
    fs = v.positive("fs", fs)
    pre_s = v.finite("pre_s", pre_s)
    if pre_s < 0.0:
        raise ValueError(f"pre_s must be >= 0, got {pre_s!r}")
    if not isinstance(oversample, int) or oversample < 1:
        raise ValueError(f"oversample must be an integer >= 1, got {oversample!r}")
    effects = _check_effects(effects)
    noise_frac = _noise_fractions(noise)
    if any(noise_frac.values()) and rng is None:
        raise ValueError("noise needs rng (a numpy Generator or a seed) so that it is reproducible")
    generator = np.random.default_rng(rng) if rng is not None else None

    for effect in effects:
        if isinstance(effect, StaticUnbalance):
            section = section.replace(S=section.S + effect.S)
    system = AeroelasticSystem(section, model, U)
    z0 = system.initial_state(h0, alpha0)  # validates h0, alpha0
    n = int(round(duration * fs))
    if n < 2:
        raise ValueError(f"duration * fs must give at least 2 samples, got {n}")
    dt = 1.0 / fs

    plant = _Plant(system, effects)
    if plant.nonlinear:
        z, qdd = plant.integrate_nonlinear(z0, n, dt, oversample)
    else:
        z, qdd = plant.integrate_linear(z0, n, dt)
    t = np.asarray(np.arange(n) * dt, dtype=np.float64)
    forces = plant.forces(z, qdd, t)
    clean = {
        "h": z[:, 0] * section.B,
        "alpha": z[:, 1].copy(),
        "lift": forces[:, 0] / section.B,
        "moment": forces[:, 1],
    }
    static_force = plant.static_force(z0)
    if pre_s > 0.0:
        n_pre = int(round(pre_s * fs))
        t_pre = np.asarray(-np.arange(n_pre, 0, -1) * dt, dtype=np.float64)
        held = plant.vortex_force(t_pre) + static_force
        t = np.concatenate([t_pre, t])
        clean = {
            "h": np.concatenate([np.full(n_pre, h0), clean["h"]]),
            "alpha": np.concatenate([np.full(n_pre, alpha0), clean["alpha"]]),
            "lift": np.concatenate([held[:, 0] / section.B, clean["lift"]]),
            "moment": np.concatenate([held[:, 1], clean["moment"]]),
        }
    measured = _measure(clean, t, effects, plant, static_force, section.B)
    if generator is not None:
        for name, frac in noise_frac.items():
            if frac:
                rms = math.sqrt(float(np.mean(clean[name] ** 2)))
                measured[name] = measured[name] + generator.normal(0.0, frac * rms, t.size)
    return SimulatedRelease(
        t=t,
        **measured,
        U=U,
        rho=section.rho,
        fs=fs,
        h0=float(h0),
        alpha0=float(alpha0),
        clean=clean,
        section=section,
        model=model,
        effects=effects,
    )


def _check_effects(effects: Iterable[Effect]) -> tuple[Effect, ...]:
    out = tuple(effects)
    for effect in out:
        if not isinstance(effect, Effect):
            raise TypeError(f"effects must be simulators.effects.Effect instances, got {effect!r}")
    names = [effect.name for effect in out]
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise ValueError(f"each effect may appear once; repeated: {repeated}")
    return out


def _noise_fractions(noise: float | Mapping[str, float]) -> dict[str, float]:
    if isinstance(noise, Mapping):
        unknown = sorted(set(noise) - set(CHANNELS))
        if unknown:
            raise ValueError(f"noise has unknown channel(s) {unknown}; channels are {CHANNELS}")
        fractions = {name: float(noise.get(name, 0.0)) for name in CHANNELS}
    else:
        fractions = dict.fromkeys(CHANNELS, v.finite("noise", noise))
    for name, frac in fractions.items():
        if not (math.isfinite(frac) and frac >= 0.0):
            raise ValueError(f"noise for {name} must be a finite fraction >= 0, got {frac!r}")
    return fractions


class _Plant:
    """The linear system, optionally augmented with a vortex oscillator, plus nonlinear terms.

    The vortex forcing ``sin(w t)``, ``cos(w t)`` is generated by two extra states of a harmonic
    oscillator, so that a vortex-forced linear system is still advanced by an exact matrix
    exponential.
    """

    def __init__(self, system: AeroelasticSystem, effects: tuple[Effect, ...]) -> None:
        self.system = system
        self.B = system.section.B
        self.nonlinear_effects = [e for e in effects if e.nonlinear]
        self.nonlinear = bool(self.nonlinear_effects)
        self.M_inv = np.linalg.inv(system.effective_mass())
        vortex = [e for e in effects if isinstance(e, VortexShedding)]
        self.vortex = vortex[0] if vortex and system.U > 0.0 else None
        n = system.n_states
        A = system.matrix()
        if self.vortex is not None:
            w = 2.0 * math.pi * self.vortex.frequency(system.U)
            A_aug = np.zeros((n + 2, n + 2))
            A_aug[:n, :n] = A
            A_aug[n, n + 1] = w  # s' = w c
            A_aug[n + 1, n] = -w  # c' = -w s
            A_aug[2:4, n : n + 2] = self.M_inv @ self._vortex_gain()
            A = A_aug
        self.A = A
        self.n_struct = n

    def _vortex_gain(self) -> FloatArray:
        """Generalised vortex force per oscillator state ``[s, c]``: ``[L B, M] = G [s, c]``."""
        assert self.vortex is not None
        s = self.system.section
        qd_B2 = 0.5 * s.rho * self.system.U**2 * s.B**2
        vx = self.vortex
        return qd_B2 * np.array(
            [[vx.cl, 0.0], [vx.cm * math.cos(vx.phase), vx.cm * math.sin(vx.phase)]]
        )

    def initial(self, z0: FloatArray) -> FloatArray:
        if self.vortex is None:
            return z0
        return np.concatenate([z0, [0.0, 1.0]])  # sin(0) = 0, cos(0) = 1

    def vortex_force(self, t: FloatArray) -> FloatArray:
        """Generalised vortex force at times ``t`` (any sign), shape (len(t), 2)."""
        if self.vortex is None:
            return np.zeros((t.size, 2))
        w = 2.0 * math.pi * self.vortex.frequency(self.system.U)
        sc = np.column_stack([np.sin(w * t), np.cos(w * t)])
        return np.asarray(sc @ self._vortex_gain().T, dtype=float)

    def static_force(self, z0: FloatArray) -> FloatArray:
        """Self-excited generalised force on the held model (no motion, lag states at zero)."""
        return np.asarray(self.system.forces(z0, np.zeros(2)), dtype=float)

    def nonlinear_acceleration(self, z: FloatArray) -> FloatArray:
        """``q''`` contribution of the structural nonlinearities at state ``z``."""
        force = np.zeros(2)
        for effect in self.nonlinear_effects:
            force = force + effect.structural_force(z[0:2], z[2:4], self.B)
        return np.asarray(self.M_inv @ force, dtype=float)

    def integrate_linear(self, z0: FloatArray, n: int, dt: float) -> tuple[FloatArray, FloatArray]:
        phi = expm(self.A * dt)
        z = np.empty((n, self.A.shape[0]))
        z[0] = self.initial(z0)
        for k in range(1, n):
            z[k] = phi @ z[k - 1]
        qdd = z @ self.A[2:4, :].T
        return z, qdd

    def integrate_nonlinear(
        self, z0: FloatArray, n: int, dt: float, oversample: int
    ) -> tuple[FloatArray, FloatArray]:
        rate = max(e.stiffness_rate(self.system.effective_mass(), self.B)
                   for e in self.nonlinear_effects)
        # Keep the explicit treatment of the nonlinear term well inside its stability limit.
        substeps = max(oversample, math.ceil(2.0 * rate * dt))
        h = dt / substeps
        n_aug = self.A.shape[0]
        # Van Loan: expm([[A, I, 0], [0, 0, I], [0, 0, 0]] h) holds e^{Ah}, int e^{As} ds and
        # int e^{A(h-s)} s ds, the three matrices of the ETD2RK step (Cox and Matthews 2002).
        big = np.zeros((3 * n_aug, 3 * n_aug))
        big[:n_aug, :n_aug] = self.A
        big[:n_aug, n_aug : 2 * n_aug] = np.eye(n_aug)
        big[n_aug : 2 * n_aug, 2 * n_aug :] = np.eye(n_aug)
        blocks = expm(big * h)
        phi = blocks[:n_aug, :n_aug]
        gamma1 = blocks[:n_aug, n_aug : 2 * n_aug][:, 2:4]  # only q'' rows receive the force
        gamma2 = blocks[:n_aug, 2 * n_aug :][:, 2:4] / h
        z = np.empty((n, n_aug))
        u = self.initial(z0)
        z[0] = u
        for k in range(1, n):
            for _ in range(substeps):
                n_u = self.nonlinear_acceleration(u)
                a = phi @ u + gamma1 @ n_u
                u = a + gamma2 @ (self.nonlinear_acceleration(a) - n_u)
            z[k] = u
        qdd = z @ self.A[2:4, :].T + np.array([self.nonlinear_acceleration(zk) for zk in z])
        return z, qdd

    def forces(self, z: FloatArray, qdd: FloatArray, t: FloatArray) -> FloatArray:
        """Generalised aerodynamic forces ``[L B, M]`` recorded at the output samples."""
        aero = self.system.forces(z[:, : self.n_struct], qdd)
        return np.asarray(aero + self.vortex_force(t), dtype=float)


def _measure(
    clean: dict[str, FloatArray],
    t: FloatArray,
    effects: tuple[Effect, ...],
    plant: _Plant,
    static_force: FloatArray,
    B: float,
) -> dict[str, FloatArray]:
    """Apply the measurement effects (delay, crosstalk) to the clean channels."""
    out = {name: clean[name].copy() for name in CHANNELS}
    for effect in effects:
        if isinstance(effect, ChannelDelay) and effect.delay_s > 0.0:
            after = t >= 0.0
            t_src = t - effect.delay_s
            generalised = np.column_stack([clean["lift"] * B, clean["moment"]])
            # Smooth after the release; the release itself is a kink (the added-mass force jumps),
            # so the spline only spans t >= 0 and earlier times take the held (static) value.
            spline = CubicSpline(t[after], generalised[after], axis=0)
            delayed = np.where(
                (t_src >= 0.0)[:, None],
                spline(np.clip(t_src, 0.0, None)),
                static_force + plant.vortex_force(t_src),
            )
            out["lift"], out["moment"] = delayed[:, 0] / B, delayed[:, 1]
        elif isinstance(effect, SensorCrosstalk):
            out["h"] = clean["h"] + effect.h_from_alpha * clean["alpha"]
            out["alpha"] = clean["alpha"] + effect.alpha_from_h * clean["h"]
    return out
