"""Free-vibration decays of a section model in the wind, with the named physical effects.

A release starts from rest at ``(h0, alpha0)`` with all aerodynamic lag states at zero (DESIGN.md)
and runs freely. The linear physics (structure plus Roger self-excited forces, plus static
unbalance and harmonic vortex forcing, which stay linear) is advanced by its exact discretisation
``z[k+1] = expm(A dt) z[k]``. Structural nonlinearities (friction, quadratic damping, cubic springs)
are added by a second-order exponential integrator (ETD2RK of Cox and Matthews) on a fixed step
that is a multiple of the output rate: exact for the linear part, second order for the nonlinear
part. Measurement effects (channel delay, crosstalk) are applied to the recorded channels last.
The forces returned are the self-excited forces (plus vortex forcing): what the surface pressures
integrate to, not the spring or friction forces.

This is the noise-free physics shared by the virtual tunnel
(:func:`simulators.tunnel.simulate_release` adds measurement noise and the held stretch before the
release) and by the discrepancy workflow, which simulates an identified model, with candidate
effects (:mod:`ident.effects`), for every release. Units are SI throughout (DESIGN.md,
"Conventions").
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.interpolate import CubicSpline
from scipy.linalg import expm

from ident import _validate as v
from ident.effects import (
    ChannelDelay,
    Effect,
    SensorCrosstalk,
    StaticUnbalance,
    VortexShedding,
)
from ident.rfc import RationalFunctionModel
from ident.section import SectionModel
from ident.statespace import AeroelasticSystem

__all__ = ["CHANNELS", "SimulatedDecay", "simulate_decay"]

#: Recorded channels of a release, in order.
CHANNELS: tuple[str, ...] = ("h", "alpha", "lift", "moment")

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class SimulatedDecay:
    """One simulated free decay from the release on (``t >= 0``), without noise.

    Made by :func:`simulate_decay`; not meant to be built by hand.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Time from the release, s: ``arange(n) / fs``.
    h, alpha : ndarray, shape (n,)
        Heave (m, positive down) and pitch (rad, positive nose-up) as measured: with the
        measurement effects (sensor crosstalk), no noise.
    lift, moment : ndarray, shape (n,)
        Self-excited (plus vortex) lift, N/m, and moment, N m/m, as measured: with the measurement
        effects (channel delay), no noise.
    U, fs : float
        Wind speed (m/s) and sampling rate (Hz).
    h0, alpha0 : float
        Release position, m and rad.
    clean : dict
        The four channels before the measurement effects (the physical truth).
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
    fs: float
    h0: float
    alpha0: float
    clean: dict[str, FloatArray] = field(repr=False)
    section: SectionModel = field(repr=False)
    model: RationalFunctionModel = field(repr=False)
    effects: tuple[Effect, ...] = ()
    _plant: _Plant | None = field(default=None, repr=False)
    _static_force: FloatArray | None = field(default=None, repr=False)
    _delay_spline: Any = field(default=None, repr=False)

    @property
    def rho(self) -> float:
        """Air density, kg/m^3 (that of :attr:`section`)."""
        return self.section.rho

    @property
    def measured(self) -> dict[str, FloatArray]:
        """The four measured channels by name (``h, alpha, lift, moment``)."""
        return {name: getattr(self, name) for name in CHANNELS}

    def held(self, t: npt.ArrayLike) -> tuple[dict[str, FloatArray], dict[str, FloatArray]]:
        """Channels of the model held still at ``(h0, alpha0)`` before the release.

        While held, the model does not move and its lag states stay at zero: the forces are the
        static self-excited force plus any vortex forcing, which runs before the release too. The
        measurement effects apply as after the release (a delayed force channel shows the held
        force ``delay_s`` earlier).

        Parameters
        ----------
        t : array_like, shape (k,)
            Times before the release, s, all < 0.

        Returns
        -------
        clean, measured : dict
            The four channels (``h`` m, ``alpha`` rad, ``lift`` N/m, ``moment`` N m/m) at ``t``,
            before and after the measurement effects.
        """
        t_arr = np.asarray(t, dtype=np.float64)
        if t_arr.ndim != 1 or not np.all(t_arr < 0.0):
            raise ValueError("held times must be a 1-D array of times before the release (t < 0)")
        assert self._plant is not None and self._static_force is not None
        B = self.section.B
        force = self._plant.vortex_force(t_arr) + self._static_force
        clean = {
            "h": np.full(t_arr.size, self.h0),
            "alpha": np.full(t_arr.size, self.alpha0),
            "lift": force[:, 0] / B,
            "moment": force[:, 1],
        }
        measured = _measure(
            clean, t_arr, self.effects, self._plant, self._static_force, self._delay_spline, B
        )
        return clean, measured


def simulate_decay(
    section: SectionModel,
    model: RationalFunctionModel,
    U: float,
    h0: float,
    alpha0: float,
    *,
    n: int,
    fs: float,
    effects: Iterable[Effect] = (),
    oversample: int = 8,
) -> SimulatedDecay:
    """Simulate the free decay of a section model released from rest at wind speed ``U``.

    The record is ``n`` samples at ``fs`` from the release instant (``t = 0``), noise-free, with
    the measurement effects (channel delay, sensor crosstalk) applied to the measured channels.

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
    n : int
        Number of output samples, >= 2.
    fs : float
        Output sampling rate, Hz, > 0.
    effects : iterable of Effect, optional
        Extra physics (:mod:`ident.effects`); at most one of each kind.
    oversample : int, optional
        Integrator steps per output sample for nonlinear effects (>= 1); raised automatically when
        a stiff effect (smoothed friction) needs a smaller step. Linear physics is stepped exactly
        at the output rate whatever this is.

    Returns
    -------
    SimulatedDecay

    Examples
    --------
    >>> from ident import SectionModel, flat_plate
    >>> from ident.effects import CubicStiffness
    >>> s = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)
    >>> d = simulate_decay(s, flat_plate.jones_model(), 5.0, 0.0, 0.02, n=1000, fs=200.0,
    ...                    effects=[CubicStiffness(k3_a=50.0)])
    >>> d.t.shape, float(d.alpha[0]), float(d.t[-1])
    ((1000,), 0.02, 4.995)
    """
    U = v.finite("U", U)
    if U < 0.0:
        raise ValueError(f"U must be >= 0, got {U!r}")
    fs = v.positive("fs", fs)
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
        raise ValueError(f"n must be an integer >= 2, got {n!r}")
    n = int(n)
    if not isinstance(oversample, int) or oversample < 1:
        raise ValueError(f"oversample must be an integer >= 1, got {oversample!r}")
    effects = _check_effects(effects)

    for effect in effects:
        if isinstance(effect, StaticUnbalance):
            section = section.replace(S=section.S + effect.S)
    system = AeroelasticSystem(section, model, U)
    z0 = system.initial_state(h0, alpha0)  # validates h0, alpha0
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
    spline = None
    if any(isinstance(e, ChannelDelay) and e.delay_s > 0.0 for e in effects):
        # Smooth after the release; the release itself is a kink (the added-mass force jumps),
        # so the spline only spans t >= 0 and earlier times take the held (static) value.
        generalised = np.column_stack([clean["lift"] * section.B, clean["moment"]])
        spline = CubicSpline(t, generalised, axis=0)
    measured = _measure(clean, t, effects, plant, static_force, spline, section.B)
    return SimulatedDecay(
        t=t,
        **measured,
        U=U,
        fs=fs,
        h0=float(h0),
        alpha0=float(alpha0),
        clean=clean,
        section=section,
        model=model,
        effects=effects,
        _plant=plant,
        _static_force=static_force,
        _delay_spline=spline,
    )


def _check_effects(effects: Iterable[Effect]) -> tuple[Effect, ...]:
    out = tuple(effects)
    for effect in out:
        if not isinstance(effect, Effect):
            raise TypeError(f"effects must be ident.effects.Effect instances, got {effect!r}")
    names = [effect.name for effect in out]
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise ValueError(f"each effect may appear once; repeated: {repeated}")
    return out


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
    spline: Any,
    B: float,
) -> dict[str, FloatArray]:
    """Apply the measurement effects (delay, crosstalk) to the clean channels at times ``t``.

    ``spline`` interpolates the clean generalised forces ``[L B, M]`` after the release (t >= 0);
    a delayed sample whose source time is before the release takes the held force instead.
    """
    out = {name: clean[name].copy() for name in CHANNELS}
    for effect in effects:
        if isinstance(effect, ChannelDelay) and effect.delay_s > 0.0:
            t_src = t - effect.delay_s
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
