"""Free-vibration decays of a section model in the wind, with the named physical effects.

A release starts from rest at ``(h0, alpha0)`` with all aerodynamic lag states at zero
(``docs/reference/conventions.md``, "In the time domain") and runs freely. The linear physics
(structure plus Roger self-excited forces, plus static unbalance and the harmonic forcing of vortex
shedding and of a base vibration, which stay linear) is
advanced by its exact discretisation ``z[k+1] = expm(A dt) z[k]``. Structural nonlinearities
(friction, quadratic damping, cubic springs) are added by a second-order exponential integrator
(ETD2RK of Cox and Matthews) on a fixed step that is a multiple of the output rate: exact for the
linear part, second order for the nonlinear part. Measurement effects (channel delay, crosstalk,
tubing) are applied to the recorded channels last. The forces returned are the self-excited forces
(plus vortex forcing, plus an aerodynamic nonlinearity, plus the wind load): what the surface
pressures integrate to, not the spring or friction forces, nor the inertial force of a base
vibration (the air does not move with the floor).

Wind load (optional, :mod:`ident.physics.turbulence`): with static coefficients the mean static load
``qd B^2 [C_L, C_M]`` acts in the wind (it shifts the equilibrium; ``h0, alpha0`` remain the
positions the magnet holds, measured from the still-air rest position, and the held model feels
the mean load plus the self-excited force of its displacement); with turbulence too, the
span-averaged buffeting forces act, before, during and after the release. The wind load is an
external force generated on the integrator's grid and entered through the first-order-hold
discretisation (Van Loan's matrix exponential gives ``int e^{As} ds`` and ``int e^{A(h-s)} s ds``),
so a piecewise-linear force is integrated exactly; the ETD2RK step treats it as part of its
explicit term, which is the same first-order hold. Linear interpolation between samples filters
the force by ``sinc^2(f / f_grid)`` (0.13 % in power at 4 Hz on a 200 Hz grid): keep the grid
rate well above the structural frequencies.

Three degrees of freedom: with a section that has a lateral spring (``fp``) and a 3-DOF model,
the release starts from ``(h0, alpha0, p0)`` and the record adds the sway ``p`` (m, downwind) and
the drag (N/m, downwind) to the four channels (:func:`channels`). The structural nonlinearities
and the sensor crosstalk act on heave and pitch only; a channel delay delays every force.

The plant that steps a decay (exact, ETD2RK and first-order-hold integrators sharing one
augmented state matrix) is :mod:`ident.simulation.plant`; the measurement chain (the channels
from the states, then delay, crosstalk and tubing) is :mod:`ident.simulation.measurement`. This
module holds the record (:class:`SimulatedDecay`, with its hold and its continuation) and the
entry point :func:`simulate_decay`.

This is the noise-free physics shared by the virtual tunnel
(:func:`simulators.tunnel.simulate_release` adds measurement noise and the held stretch before the
release) and by the discrepancy workflow, which simulates an identified model, with candidate
effects (:mod:`ident.physics.effects`), for every release. Units are SI throughout
(``docs/reference/conventions.md``, "Units").
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.interpolate import CubicSpline

from ident.model.quasi_steady import StaticCoefficients
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.model.statespace import AeroelasticSystem
from ident.numerics import validate as v
from ident.physics.effects import (
    Effect,
    StaticUnbalance,
)
from ident.physics.turbulence import GustField, TurbulenceSpec, WindLoad
from ident.simulation.measurement import clean_channels, generalised_forces, measure
from ident.simulation.plant import Plant, integrate

__all__ = ["CHANNELS", "CHANNELS_3DOF", "SimulatedDecay", "channels", "simulate_decay"]

#: Recorded channels of a release, in order.
CHANNELS: tuple[str, ...] = ("h", "alpha", "lift", "moment")
#: ... and of a release with sway.
CHANNELS_3DOF: tuple[str, ...] = CHANNELS + ("p", "drag")


def channels(n_dof: int) -> tuple[str, ...]:
    """Return the recorded channels of a release of ``n_dof`` (2 or 3) degrees of freedom."""
    return CHANNELS if n_dof == 2 else CHANNELS_3DOF

#: Samples of a record that the force spline of its continuation runs through.
_SPLINE_LEAD = 16

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
        Self-excited (plus vortex, plus wind-load) lift, N/m, and moment, N m/m, as measured: with
        the measurement effects (channel delay), no noise.
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
    static : StaticCoefficients or None
        Static coefficients of the mean and buffeting load (None: no wind load).
    gusts : GustField or None
        The effective gusts that drove the model (None: smooth flow).
    wind_load : ndarray, shape (n, n_dof), or None
        Mean plus buffeting generalised force ``[L B, M(, D B)]`` (N m/m) at ``t``, included in
        ``clean["lift"]`` (times B) and ``clean["moment"]`` (and ``clean["drag"]``).
    p, drag : ndarray, shape (n,), or None
        Sway (m, downwind) and drag (N/m, downwind) as measured: with sway only.
    p0 : float
        Sway of the release position, m (0 without sway).
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
    static: StaticCoefficients | None = field(default=None, repr=False)
    gusts: GustField | None = field(default=None, repr=False)
    wind_load: FloatArray | None = field(default=None, repr=False)
    _plant: Plant | None = field(default=None, repr=False)
    _static_force: FloatArray | None = field(default=None, repr=False)
    _delay_spline: Any = field(default=None, repr=False)
    _wind: WindLoad | None = field(default=None, repr=False)
    _held_from: float = field(default=-math.inf, repr=False)
    _z_end: FloatArray | None = field(default=None, repr=False)
    _substeps: int = field(default=1, repr=False)
    _before: Callable[[FloatArray], FloatArray] | None = field(default=None, repr=False)
    #: The tubes' state at the record's end and their last input (a continuation goes on).
    _tube_end: tuple[FloatArray, FloatArray] | None = field(default=None, repr=False)
    p: FloatArray | None = None
    drag: FloatArray | None = None
    p0: float = 0.0

    @property
    def n_dof(self) -> int:
        """Degrees of freedom simulated: 2 or 3."""
        return self.section.n_dof

    @property
    def rho(self) -> float:
        """Air density, kg/m^3 (that of :attr:`section`)."""
        return self.section.rho

    @property
    def measured(self) -> dict[str, FloatArray]:
        """The measured channels by name (``h, alpha, lift, moment``, then ``p, drag``)."""
        return {name: getattr(self, name) for name in channels(self.n_dof)}

    def held(self, t: npt.ArrayLike) -> tuple[dict[str, FloatArray], dict[str, FloatArray]]:
        """Channels of the model held still at ``(h0, alpha0)`` before the release.

        While held, the model does not move and its lag states stay at zero: the forces are the
        static self-excited force plus any vortex forcing and wind load (mean and buffeting),
        which run before the release too. The measurement effects apply as after the release (a
        delayed force channel shows the held force ``delay_s`` earlier).

        Parameters
        ----------
        t : array_like, shape (k,)
            Times before the release, s, all < 0 (and >= ``-pre_s`` with generated turbulence).

        Returns
        -------
        clean, measured : dict
            The four channels (``h`` m, ``alpha`` rad, ``lift`` N/m, ``moment`` N m/m) at ``t``,
            before and after the measurement effects.
        """
        t_arr = np.asarray(t, dtype=np.float64)
        if t_arr.ndim != 1 or not np.all(t_arr < 0.0):
            raise ValueError("held times must be a 1-D array of times before the release (t < 0)")
        if self._before is None:
            raise ValueError("held() is for a record from the release, not a continuation")
        if t_arr.size and float(t_arr.min()) < self._held_from - 1e-9 / self.fs:
            raise ValueError(f"the turbulence was generated from t = {self._held_from} s; "
                             f"pass pre_s to simulate_decay to cover t = {float(t_arr.min())} s")
        assert self._plant is not None and self._static_force is not None
        B = self.section.B
        force = self._before(t_arr)
        clean = {
            "h": np.full(t_arr.size, self.h0),
            "alpha": np.full(t_arr.size, self.alpha0),
            "lift": force[:, 0] / B,
            "moment": force[:, 1],
        }
        if self.n_dof == 3:
            clean.update(p=np.full(t_arr.size, self.p0), drag=force[:, 2] / B)
        measured, _ = measure(clean, t_arr, self.effects, self._before, self._delay_spline,
                               0.0, B)
        return clean, measured

    def continued(self, n: int) -> SimulatedDecay:
        """Continue the simulation for ``n`` more samples from the last state of this record.

        The model moves on from its full state (displacements, velocities, lag states, vortex
        phase) at ``t[-1]`` under the same forces; the wind load continues along the same gust
        field (a field generated by :func:`simulate_decay` is periodic, so its forcing repeats
        after its period: pass a long :class:`~ident.physics.turbulence.GustField` to continue far).
        A channel delay reaches back into this record (not further than its start).

        Parameters
        ----------
        n : int
            Number of further samples, >= 1.

        Returns
        -------
        SimulatedDecay
            With ``t = t[-1] + (1..n) / fs``; :meth:`held` does not apply to it.
        """
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n must be an integer >= 1, got {n!r}")
        assert self._plant is not None and self._z_end is not None
        t_start = float(self.t[-1])
        z, qdd, wind = integrate(self._plant, self._wind, self._z_end, t_start, int(n) + 1,
                                  1.0 / self.fs, self._substeps)
        t = t_start + np.arange(int(n) + 1) / self.fs
        clean, _ = clean_channels(self._plant, z, qdd, t, wind, (), self.section.B)
        B = self.section.B
        spline = None
        if self._delay_spline is not None:
            # The spline runs on through the last _SPLINE_LEAD samples of this record, so that
            # the seam is inside it (a cubic spline's end condition fades by 0.27 per knot).
            lead = slice(max(0, self.t.size - 1 - _SPLINE_LEAD), self.t.size - 1)
            t_spline = np.concatenate([self.t[lead], t])
            forces = generalised_forces(clean, B)
            lead_forces = generalised_forces({k: v[lead] for k, v in self.clean.items()}, B)
            spline = CubicSpline(t_spline, np.vstack([lead_forces, forces]), axis=0)
            t_start = float(t_spline[0])
        previous = self._delay_spline
        start = float(self.t[0])

        def before(ts: FloatArray) -> FloatArray:
            return np.asarray(previous(np.clip(ts, start, None)), dtype=float)

        keep = slice(1, None)
        clean = {name: values[keep] for name, values in clean.items()}
        measured, tube_end = measure(clean, t[keep], self.effects, before, spline, t_start, B,
                                      self._tube_end)
        return dataclasses.replace(
            self, t=t[keep], h=measured["h"], alpha=measured["alpha"], lift=measured["lift"],
            moment=measured["moment"], p=measured.get("p"), drag=measured.get("drag"),
            clean=clean,
            wind_load=None if wind is None else wind[keep], _z_end=z[-1].copy(),
            _delay_spline=spline, _before=None, _tube_end=tube_end,
        )


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
    static: StaticCoefficients | None = None,
    turbulence: TurbulenceSpec | GustField | None = None,
    span: float | None = None,
    rng: np.random.Generator | int | None = None,
    pre_s: float = 0.0,
    p0: float = 0.0,
) -> SimulatedDecay:
    """Simulate the free decay of a section model released from rest at wind speed ``U``.

    The record is ``n`` samples at ``fs`` from the release instant (``t = 0``), noise-free, with
    the measurement effects (channel delay, sensor crosstalk) applied to the measured channels.
    Without ``static`` and ``turbulence`` the result is exactly that of smooth flow without a
    mean load (the same arithmetic as before these options existed).

    Parameters
    ----------
    section : SectionModel
        Structure and air density.
    model : RationalFunctionModel
        Self-excited forces.
    U : float
        Mean wind speed, m/s, >= 0.
    h0, alpha0 : float
        Position held before the release, m and rad, measured from the still-air rest position
        (with a mean wind load the equilibrium in the wind is elsewhere).
    n : int
        Number of output samples, >= 2.
    fs : float
        Output sampling rate, Hz, > 0.
    effects : iterable of Effect, optional
        Extra physics (:mod:`ident.physics.effects`); at most one of each kind.
    oversample : int, optional
        Integrator steps per output sample for nonlinear effects (>= 1); raised automatically when
        a stiff effect (smoothed friction) needs a smaller step. Linear physics is stepped exactly
        at the output rate whatever this is.
    static : StaticCoefficients, optional
        Static coefficients: the mean load ``qd B^2 [C_L, C_M]`` acts, and they make the
        buffeting forces when ``turbulence`` is given.
    turbulence : TurbulenceSpec or GustField, optional
        Oncoming turbulence (needs ``static``). A spec is turned into gusts on the integrator's
        grid (the output grid, or its substeps with nonlinear effects) covering ``[-pre_s, t[-1]]``
        and needs ``span`` and ``rng``; a :class:`~ident.physics.turbulence.GustField` (made for
        this section's ``B``) is sampled at ``x = x0 + U t`` as it is.
    span : float, optional
        Span of the section model, m (span-wise coherence); with a turbulence spec only.
    rng : numpy.random.Generator or int, optional
        Random source or seed of the turbulence (required with a spec).
    pre_s : float, optional
        Seconds before the release that :meth:`SimulatedDecay.held` must cover with generated
        turbulence, >= 0.
    p0 : float, optional
        Sway held before the release, m (a section with sway only; default 0).

    Returns
    -------
    SimulatedDecay

    Examples
    --------
    >>> from ident import SectionModel
    >>> from ident.model import flat_plate
    >>> from ident.physics.effects import CubicStiffness
    >>> s = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)
    >>> d = simulate_decay(s, flat_plate.jones_model(), 5.0, 0.0, 0.02, n=1000, fs=200.0,
    ...                    effects=[CubicStiffness(k3_a=50.0)])
    >>> d.t.shape, float(d.alpha[0]), float(d.t[-1])
    ((1000,), 0.02, 4.995)

    In turbulence the same seed gives the same record:

    >>> from ident.model.quasi_steady import StaticCoefficients
    >>> from ident.physics.turbulence import TurbulenceSpec
    >>> spec = TurbulenceSpec(Iu=0.1, Iw=0.05, Lux=0.5, Lwx=0.2, Cuy=10.0, Cwy=8.0)
    >>> runs = [simulate_decay(s, flat_plate.jones_model(), 5.0, 0.0, 0.0, n=400, fs=200.0,
    ...                        static=StaticCoefficients.flat_plate(), turbulence=spec,
    ...                        span=1.0, rng=7) for _ in range(2)]
    >>> bool(np.array_equal(runs[0].alpha, runs[1].alpha)), bool(runs[0].alpha.std() > 0)
    (True, True)
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
    pre_s = v.finite("pre_s", pre_s)
    if pre_s < 0.0:
        raise ValueError(f"pre_s must be >= 0, got {pre_s!r}")

    for effect in effects:
        if isinstance(effect, StaticUnbalance):
            section = section.replace(S=section.S + effect.S)
    system = AeroelasticSystem(section, model, U)
    z0 = system.initial_state(h0, alpha0, p0)  # validates h0, alpha0, p0
    dt = 1.0 / fs

    plant = Plant(system, effects)
    substeps = plant.substeps(dt, oversample)
    wind, held_from = _wind_load(section, U, static, turbulence, span, rng,
                                 (n - 1) * substeps + 1, dt / substeps, pre_s)
    t = np.asarray(np.arange(n) * dt, dtype=np.float64)
    if wind is None:
        if plant.nonlinear:
            z, qdd = plant.integrate_nonlinear(z0, n, dt, oversample)
        else:
            z, qdd = plant.integrate_linear(z0, n, dt)
        wind_out = None
    else:
        z, qdd, wind_out = integrate(plant, wind, plant.initial(z0), 0.0, n, dt, substeps)
    clean, spline = clean_channels(plant, z, qdd, t, wind_out, effects, section.B)
    static_force = plant.static_force(z0)

    def before(ts: FloatArray) -> FloatArray:
        """Generalised force on the held model at times ``ts`` < 0."""
        force = plant.vortex_force(ts) + static_force
        if wind is not None:
            force = force + wind.force(ts)[:, : plant.k]
        return np.asarray(force, dtype=float)

    measured, tube_end = measure(clean, t, effects, before, spline, 0.0, section.B)
    return SimulatedDecay(
        t=t,
        **measured,
        p0=float(p0),
        U=U,
        fs=fs,
        h0=float(h0),
        alpha0=float(alpha0),
        clean=clean,
        section=section,
        model=model,
        effects=effects,
        static=static,
        gusts=None if wind is None else wind.gusts,
        wind_load=wind_out,
        _plant=plant,
        _static_force=static_force,
        _delay_spline=spline,
        _wind=wind,
        _held_from=held_from,
        _z_end=z[-1].copy(),
        _substeps=substeps,
        _before=before,
        _tube_end=tube_end,
    )


def _wind_load(
    section: SectionModel,
    U: float,
    static: StaticCoefficients | None,
    turbulence: TurbulenceSpec | GustField | None,
    span: float | None,
    rng: np.random.Generator | int | None,
    n_grid: int,
    h: float,
    pre_s: float,
) -> tuple[WindLoad | None, float]:
    """Validate the wind-load options; return the load and the earliest time it covers."""
    if static is not None and not isinstance(static, StaticCoefficients):
        raise TypeError(f"static must be a StaticCoefficients, got {type(static).__name__}")
    if turbulence is None:
        if span is not None or rng is not None:
            raise ValueError("span and rng are for turbulence; pass turbulence too")
        return (None if static is None else WindLoad(static, U, section.B, section.rho)), -math.inf
    if static is None:
        raise ValueError("turbulence needs static coefficients (static=...) for its forces")
    if isinstance(turbulence, GustField):
        if span is not None or rng is not None:
            raise ValueError("a GustField carries its span and randomness; pass no span or rng")
        if not math.isclose(turbulence.B, section.B, rel_tol=1e-12):
            raise ValueError(f"the gust field was made for B = {turbulence.B} m, the section has "
                             f"B = {section.B} m")
        return WindLoad(static, U, section.B, section.rho, turbulence), -math.inf
    if not isinstance(turbulence, TurbulenceSpec):
        raise TypeError("turbulence must be a TurbulenceSpec or a GustField, got "
                        f"{type(turbulence).__name__}")
    if span is None:
        raise ValueError("turbulence needs the section model's span (span=..., m)")
    if rng is None:
        raise ValueError("turbulence needs rng (a numpy Generator or an int seed) so that it is "
                         "reproducible")
    span = v.positive("span", span)
    if U == 0.0:  # no wind, no gusts
        return WindLoad(static, U, section.B, section.rho), -math.inf
    # One period of the field covers the integrator's grid after the release and pre_s before it
    # (which wraps to the field's end): no part of the forcing repeats within [-pre_s, t[-1]].
    n_pre = math.ceil(pre_s / h - 1e-9)
    gusts = GustField.generate(turbulence, B=section.B, span=span, n=max(n_grid + n_pre, 2),
                               dx=U * h, rng=rng)
    return WindLoad(static, U, section.B, section.rho, gusts), -n_pre * h


def _check_effects(effects: Iterable[Effect]) -> tuple[Effect, ...]:
    out = tuple(effects)
    for effect in out:
        if not isinstance(effect, Effect):
            raise TypeError(f"effects must be ident.physics.effects.Effect instances, got "
                            f"{effect!r}")
    names = [effect.name for effect in out]
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise ValueError(f"each effect may appear once; repeated: {repeated}")
    return out
