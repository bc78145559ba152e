"""Named physical effects that the linear aeroelastic model leaves out.

These are the named physical terms used both by the virtual tunnel (:mod:`simulators.tunnel`,
through :func:`ident.simulation.decay.simulate_decay`), which adds them to the simulated physics,
and by the discrepancy workflow (:mod:`ident.discrepancy.workflow`), which tries them as candidate
explanations of a gap between an identified model and the measured releases. Each effect is a small
validated dataclass with its own parameters, in SI units per unit span. The names are fixed
(``docs/reference/conventions.md``, "Named effects").

Four kinds: structural nonlinearities (``coulomb_friction``, ``quadratic_damping``,
``cubic_stiffness``), an aerodynamic nonlinearity that the pressure taps measure
(``aerodynamic_nonlinearity``), changes to the linear physics (``static_unbalance``,
``vortex_shedding``, ``base_vibration``), and measurement effects applied to the recorded
channels (``channel_delay``, ``sensor_crosstalk``, ``tubing_distortion``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from ident.numerics import validate as v

__all__ = [
    "EFFECT_NAMES",
    "AerodynamicNonlinearity",
    "BaseVibration",
    "ChannelDelay",
    "CoulombFriction",
    "CubicStiffness",
    "Effect",
    "QuadraticDamping",
    "SensorCrosstalk",
    "StaticUnbalance",
    "TubingDistortion",
    "VortexShedding",
]


class Effect:
    """Base class of the named effects: ``name`` is the effect's fixed name."""

    name: ClassVar[str]
    #: True for effects that need a nonlinear (fixed-step) integration.
    nonlinear: ClassVar[bool] = False
    #: True for a force that acts through the air (the pressure taps measure it).
    aerodynamic: ClassVar[bool] = False

    def structural_force(
        self, q: npt.NDArray[np.float64], qd: npt.NDArray[np.float64], B: float
    ) -> npt.NDArray[np.float64]:
        """Return the extra generalised force ``[F_h B, M]``, N m/m, at ``q``, ``q'`` (here 0)."""
        return np.zeros(2)

    def stiffness_rate(self, effective_mass: npt.NDArray[np.float64], B: float) -> float:
        """Return the largest rate (1/s) at which the force changes with velocity (step sizing)."""
        return 0.0

    def aerodynamic_force(self, q: npt.NDArray[np.float64], qd: npt.NDArray[np.float64],
                          B: float, U: float, rho: float) -> npt.NDArray[np.float64]:
        """Return the extra aerodynamic force ``[L B, M]``, N m/m (here 0; see ``aerodynamic``)."""
        return np.zeros(np.shape(q))


@dataclass(frozen=True)
class CoulombFriction(Effect):
    """Dry friction in the suspension: a force of constant size opposing the velocity.

    Signature: the free-decay envelope falls linearly in time instead of exponentially.

    Parameters
    ----------
    force_h : float
        Friction force on heave, N/m (per unit span), >= 0.
    moment_a : float
        Friction moment on pitch, N m/m, >= 0.
    v_smooth_h, v_smooth_a : float
        Velocity band over which the sign function is smoothed (``tanh(v / v_smooth)``), m/s and
        rad/s: an integrable stand-in for stick-slip, much smaller than the release velocities.
    """

    name: ClassVar[str] = "coulomb_friction"
    nonlinear: ClassVar[bool] = True
    force_h: float = 0.0
    moment_a: float = 0.0
    v_smooth_h: float = 1e-4
    v_smooth_a: float = 1e-3

    def __post_init__(self) -> None:
        for name in ("force_h", "moment_a"):
            if v.finite(name, getattr(self, name)) < 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        v.positive("v_smooth_h", self.v_smooth_h)
        v.positive("v_smooth_a", self.v_smooth_a)

    def stiffness_rate(self, effective_mass: npt.NDArray[np.float64], B: float) -> float:
        """Slope of the smoothed friction force over mass: the explicit step must resolve it."""
        m_h = effective_mass[0, 0] / B**2
        return max(self.force_h / (self.v_smooth_h * m_h),
                   self.moment_a / (self.v_smooth_a * effective_mass[1, 1]))

    def structural_force(
        self, q: npt.NDArray[np.float64], qd: npt.NDArray[np.float64], B: float
    ) -> npt.NDArray[np.float64]:
        """Return the extra generalised force ``[F_h B, M]``, N m/m (see :class:`Effect`)."""
        h_dot, a_dot = qd[0] * B, qd[1]
        return np.array([  # math.tanh: scalars, at every substep of the integrator
            -self.force_h * math.tanh(h_dot / self.v_smooth_h) * B,
            -self.moment_a * math.tanh(a_dot / self.v_smooth_a),
        ])


@dataclass(frozen=True)
class QuadraticDamping(Effect):
    """Velocity-squared damping (e.g. air drag on the springs and arms): ``-c2 |v| v``.

    Signature: damping that grows with amplitude; the decay is fast at first, then exponential.

    Parameters
    ----------
    c2_h : float
        Heave coefficient, N s^2/m^3 (force per unit span per (m/s)^2), >= 0.
    c2_a : float
        Pitch coefficient, N m s^2/m (moment per unit span per (rad/s)^2), >= 0.
    """

    name: ClassVar[str] = "quadratic_damping"
    nonlinear: ClassVar[bool] = True
    c2_h: float = 0.0
    c2_a: float = 0.0

    def __post_init__(self) -> None:
        for name in ("c2_h", "c2_a"):
            if v.finite(name, getattr(self, name)) < 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")

    def structural_force(
        self, q: npt.NDArray[np.float64], qd: npt.NDArray[np.float64], B: float
    ) -> npt.NDArray[np.float64]:
        """Return the extra generalised force ``[F_h B, M]``, N m/m (see :class:`Effect`)."""
        h_dot, a_dot = qd[0] * B, qd[1]
        return np.array([-self.c2_h * abs(h_dot) * h_dot * B, -self.c2_a * abs(a_dot) * a_dot])


@dataclass(frozen=True)
class CubicStiffness(Effect):
    """Cubic spring term (hardening if > 0): restoring force ``k3 x^3`` added to the linear one.

    Signature: the oscillation frequency depends on amplitude (backbone curve).

    Parameters
    ----------
    k3_h : float
        Heave coefficient, N/m^4 (force per unit span per m^3).
    k3_a : float
        Pitch coefficient, N m/m per rad^3.
    """

    name: ClassVar[str] = "cubic_stiffness"
    nonlinear: ClassVar[bool] = True
    k3_h: float = 0.0
    k3_a: float = 0.0

    def __post_init__(self) -> None:
        v.finite("k3_h", self.k3_h)
        v.finite("k3_a", self.k3_a)

    def structural_force(
        self, q: npt.NDArray[np.float64], qd: npt.NDArray[np.float64], B: float
    ) -> npt.NDArray[np.float64]:
        """Return the extra generalised force ``[F_h B, M]``, N m/m (see :class:`Effect`)."""
        h, a = q[0] * B, q[1]
        return np.array([-self.k3_h * h**3 * B, -self.k3_a * a**3])


@dataclass(frozen=True)
class StaticUnbalance(Effect):
    """The centre of mass is off the elastic axis: static unbalance ``S = m x_cg``.

    Signature: inertial coupling of heave and pitch, visible even at zero wind.

    Parameters
    ----------
    S : float
        kg m/m (per unit span); positive when the centre of mass is downstream of the axis.
    """

    name: ClassVar[str] = "static_unbalance"
    S: float = 0.0

    def __post_init__(self) -> None:
        v.finite("S", self.S)


@dataclass(frozen=True)
class VortexShedding(Effect):
    """Harmonic lift and moment from vortex shedding at the Strouhal frequency ``St U / D``.

    Signature: a spectral line in the forces (and responses) that is not at a modal frequency and
    moves with U.

    Parameters
    ----------
    strouhal : float
        Strouhal number based on the depth, > 0 (about 0.1 to 0.2 for bridge decks).
    depth : float
        Section depth D, m, > 0.
    cl, cm : float
        Amplitudes of the lift and moment coefficients (``L = qd B cl sin(w t + lift_phase)``,
        ``M = qd B^2 cm sin(w t + lift_phase + phase)``, ``t`` from the start of the record),
        >= 0.
    phase : float
        Phase of the moment relative to the lift, rad.
    lift_phase : float
        Phase of the lift at the start of the record, rad (the shedding does not wait for a
        release: each release meets it at a phase of its own).
    """

    name: ClassVar[str] = "vortex_shedding"
    strouhal: float = 0.12
    depth: float = 0.03
    cl: float = 0.0
    cm: float = 0.0
    phase: float = 0.0
    lift_phase: float = 0.0

    def __post_init__(self) -> None:
        v.positive("strouhal", self.strouhal)
        v.positive("depth", self.depth)
        for name in ("cl", "cm"):
            if v.finite(name, getattr(self, name)) < 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        v.finite("phase", self.phase)
        v.finite("lift_phase", self.lift_phase)

    def frequency(self, U: float) -> float:
        """Shedding frequency at wind speed ``U``, Hz."""
        return self.strouhal * U / self.depth


@dataclass(frozen=True)
class ChannelDelay(Effect):
    """The force channels lag the displacement channels (pressure tubing, scanner buffering).

    Parameters
    ----------
    delay_s : float
        Delay of lift and moment relative to h and alpha, s, >= 0.
    """

    name: ClassVar[str] = "channel_delay"
    delay_s: float = 0.0

    def __post_init__(self) -> None:
        if v.finite("delay_s", self.delay_s) < 0.0:
            raise ValueError(f"delay_s must be >= 0, got {self.delay_s!r}")


@dataclass(frozen=True)
class SensorCrosstalk(Effect):
    """Each displacement reading picks up a fraction of the other degree of freedom.

    ``h_measured = h + h_from_alpha * alpha`` and ``alpha_measured = alpha + alpha_from_h * h``
    (laser misalignment, a wrong lever arm in the conversion).

    Parameters
    ----------
    h_from_alpha : float
        m/rad.
    alpha_from_h : float
        rad/m.
    """

    name: ClassVar[str] = "sensor_crosstalk"
    h_from_alpha: float = 0.0
    alpha_from_h: float = 0.0

    def __post_init__(self) -> None:
        v.finite("h_from_alpha", self.h_from_alpha)
        v.finite("alpha_from_h", self.alpha_from_h)


@dataclass(frozen=True)
class BaseVibration(Effect):
    """The floor, and with it the rig's base, vibrates vertically at a fixed frequency.

    A fan, a pump or traffic shakes the supports with the acceleration
    ``a(t) = accel sin(2 pi frequency_hz t + phase)``. In the supports' frame the model feels
    the inertial force ``-m a`` in heave and ``-S a`` in pitch (``S`` the static unbalance);
    the pressure taps do not see it (the air does not move with the floor), so the measured
    forces hold no trace of it, only the motion does.

    Signature: a spectral line in h (and alpha) at a frequency that does not move with U and is
    absent from the forces.

    Parameters
    ----------
    frequency_hz : float
        Frequency of the vibration, Hz, > 0.
    accel : float
        Amplitude of the base acceleration, m/s^2, >= 0.
    phase : float
        Phase at the release, rad.
    """

    name: ClassVar[str] = "base_vibration"
    frequency_hz: float = 5.0
    accel: float = 0.0
    phase: float = 0.0

    def __post_init__(self) -> None:
        v.positive("frequency_hz", self.frequency_hz)
        if v.finite("accel", self.accel) < 0.0:
            raise ValueError(f"accel must be >= 0, got {self.accel!r}")
        v.finite("phase", self.phase)

    def gain(self, section: Any) -> npt.NDArray[np.float64]:
        """Generalised force ``[F_h B, M]`` per unit ``[sin, cos]`` of ``2 pi f t``, N m/m.

        ``section`` is the :class:`~ident.model.section.SectionModel` (its ``m``, ``S`` and ``B``).
        """
        c, s = math.cos(self.phase), math.sin(self.phase)
        inertia = np.array([[section.m * section.B], [section.S]])
        return np.asarray(-self.accel * inertia @ np.array([[c, s]]), dtype=float)


@dataclass(frozen=True)
class AerodynamicNonlinearity(Effect):
    """Aerodynamic damping that depends on the amplitude: amplitude-dependent flutter derivatives.

    The linear model's aerodynamic damping terms ``qd B^2 A2 (B/U) q'`` (``A2[0, 0] = K H1*``,
    ``A2[1, 1] = K A2*`` for harmonic motion) each gain a part that grows with the square of
    the displacement::

        [L B, M] += qd B^2 (B / U) [e_h (q_h / q_ref)^2 q_h', e_a (alpha / q_ref)^2 alpha']

    with ``q_h = h / B``. For harmonic motion of amplitude ``a`` the fundamental of that force
    is a change of ``K H1*`` by ``e_h (a / q_ref)^2 / 4`` (of ``K A2*`` alike): a flutter
    derivative that depends on the amplitude. The force is ``0.5 rho U B^3`` times the bracket,
    proportional to the wind speed and zero at zero wind (unlike ``quadratic_damping``, which
    acts in still air too), and it acts through the air, so the pressure taps measure it.

    Signature: the decays' aerodynamic damping changes with the amplitude at wind-on, and the
    measured forces are not a linear function of the motion; the structural equation holds.

    Parameters
    ----------
    e_h, e_a : float
        Changes of ``A2[0, 0]`` and ``A2[1, 1]`` (non-dimensional) at an instantaneous
        displacement of ``q_ref``; negative: more damping at larger amplitudes (Scanlan's
        signs: a negative ``A2`` diagonal damps).
    q_ref : float
        Reference displacement (``h / B`` and rad), > 0; a fixed shape parameter.
    """

    name: ClassVar[str] = "aerodynamic_nonlinearity"
    nonlinear: ClassVar[bool] = True
    aerodynamic: ClassVar[bool] = True
    e_h: float = 0.0
    e_a: float = 0.0
    q_ref: float = 0.01

    def __post_init__(self) -> None:
        v.finite("e_h", self.e_h)
        v.finite("e_a", self.e_a)
        v.positive("q_ref", self.q_ref)

    def aerodynamic_force(self, q: npt.NDArray[np.float64], qd: npt.NDArray[np.float64],
                          B: float, U: float, rho: float) -> npt.NDArray[np.float64]:
        """Return the extra generalised force ``[L B, M]``, N m/m, at ``q``, ``q'``.

        ``q`` and ``q'`` hold ``[h/B, alpha]`` (and their rates) in their last axis.
        """
        q = np.asarray(q, dtype=float)
        qd = np.asarray(qd, dtype=float)
        scale = 0.5 * rho * U * B**3  # qd B^2 (B / U)
        if q.ndim == 1:  # one state: the integrator's every substep, kept to scalar arithmetic
            return np.array([self.e_h * (q[0] / self.q_ref) ** 2 * qd[0],
                             self.e_a * (q[1] / self.q_ref) ** 2 * qd[1]]) * scale
        return np.asarray(scale * np.stack([
            self.e_h * (q[..., 0] / self.q_ref) ** 2 * qd[..., 0],
            self.e_a * (q[..., 1] / self.q_ref) ** 2 * qd[..., 1]], axis=-1), dtype=float)


@dataclass(frozen=True)
class TubingDistortion(Effect):
    """The pressure tubing filters the measured forces: gain and phase that change with frequency.

    Every tap's tube (:mod:`ident.physics.tubing`) filters its pressure, so the integrated lift and
    moment are the true ones through the tube's response. At the section's frequencies, far
    below the tube's first organ-pipe resonance, a tube acts as a second-order low-pass::

        H(s) = w^2 / (s^2 + 2 damping w s + w^2),   w = 2 pi frequency_hz

    (:meth:`from_tube` gives the one that matches a Bergh-Tijdeman tube at low frequencies).
    The displacements are not affected. A pure delay ``tau`` has the same first-order term,
    ``2 damping / w = tau``; what tells a tube from a delay is its gain, ``|H| != 1``, which
    differs from 1 by ``(2 damping^2 - 1) (f / frequency_hz)^2`` at low frequencies.

    Signature: the measured forces lag the motion by a delay and are too weak (damping above
    0.71) or too strong (below) by an amount that grows with the square of the frequency.

    Parameters
    ----------
    frequency_hz : float
        Natural frequency of the equivalent second-order tube, Hz, > 0.
    damping : float
        Its damping ratio, > 0.
    """

    name: ClassVar[str] = "tubing_distortion"
    frequency_hz: float = 20.0
    damping: float = 0.7

    def __post_init__(self) -> None:
        v.positive("frequency_hz", self.frequency_hz)
        v.positive("damping", self.damping)

    def response(self, f: npt.ArrayLike) -> npt.NDArray[np.complex128]:
        """``measured / true`` force at frequencies ``f`` (Hz)."""
        x = np.asarray(f, dtype=float) / self.frequency_hz
        return np.asarray(1.0 / (1.0 - x**2 + 2j * self.damping * x), dtype=complex)

    def state_space(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Return ``(A, b)`` of ``x' = A x + b u``, ``x = [y, y']`` (``y`` the measured force)."""
        w = 2.0 * math.pi * self.frequency_hz
        return (np.array([[0.0, 1.0], [-w * w, -2.0 * self.damping * w]]),
                np.array([0.0, w * w]))

    @classmethod
    def from_tube(cls, tube: Any, air: Any, band_hz: float = 10.0) -> TubingDistortion:
        """Return the second-order tube that matches ``tube`` below ``band_hz`` (Hz).

        ``tube`` is an :class:`ident.physics.tubing.Tube` (or anything with its ``response(f,
        air)``).
        ``1 / H = 1 + a1 s + a2 s^2`` is fitted (least squares, 50 frequencies up to
        ``band_hz``) to the tube's ``1 / H``; then ``w = 1 / sqrt(a2)``, ``damping = a1 w / 2``.

        Raises
        ------
        ValueError
            If the tube's gain does not fall at low frequencies like a second-order low-pass
            (``a2 <= 0``).
        """
        f = np.linspace(band_hz / 50.0, band_hz, 50)
        w = 2.0 * np.pi * f
        inverse = 1.0 / tube.response(f, air)
        a1 = float(np.dot(w, inverse.imag) / np.dot(w, w))
        a2 = float(np.dot(w**2, 1.0 - inverse.real) / np.dot(w**2, w**2))
        if not a2 > 0.0:
            raise ValueError(f"the tube's response is not a second-order low-pass below "
                             f"{band_hz:g} Hz (a2 = {a2:.3g} s^2)")
        wn = 1.0 / math.sqrt(a2)
        return cls(frequency_hz=wn / (2.0 * math.pi), damping=0.5 * a1 * wn)


#: The named effects (docs/reference/conventions.md, "Named effects"), mapped to their classes.
EFFECT_NAMES: dict[str, type[Effect]] = {
    cls.name: cls
    for cls in (
        CoulombFriction,
        QuadraticDamping,
        CubicStiffness,
        ChannelDelay,
        VortexShedding,
        StaticUnbalance,
        SensorCrosstalk,
        BaseVibration,
        AerodynamicNonlinearity,
        TubingDistortion,
    )
}
