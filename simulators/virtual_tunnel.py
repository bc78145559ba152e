"""The virtual tunnel: one physical truth that every simulated instrument samples.

It owns the wind (from the fan speed the simulated drive reports), the air (pressure and
temperature, hence density), the electromagnet that holds the section model and the release, and
the motion and aerodynamic forces of the model, which come from
:func:`simulators.tunnel.simulate_release` (the physics the identification is tested against).
Instruments ask it for values at true times (:mod:`simulators.clock`); it never pushes data to
them.

Motion: while the magnet holds, the model sits at the hold position ``(h0, alpha0)`` (with
sway, ``(h0, alpha0, p0)``); a release
at wind speed U computes the free decay once (on a fine grid, then interpolated with cubic splines)
and the model follows it; re-arming pulls it back to the hold position. Forces are the
self-excited forces plus any vortex forcing and wind load; tap pressures integrate exactly to
them, plus a mean pressure distribution that integrates to zero. The Pitot channel reads the
mean dynamic pressure.

Three degrees of freedom (a section with a sway spring, ``fp``, and a 3x3 model): the tunnel
serves the sway ``p`` (m, downwind) and the drag (N/m, downwind) too (:meth:`VirtualTunnel.sample`,
:meth:`VirtualTunnel.decay_truth`), and the tap pressures integrate to the drag as well when the
taps' outline carries it (:attr:`ident.physics.taps.TapLayout.carries_drag`: faces across the wind;
a plate's taps cannot, and then the drag is in no pressure, as on a real rig).

Turbulent flow (optional: static coefficients, a :class:`~ident.physics.turbulence.TurbulenceSpec`,
the model's span and a seed): one periodic field of effective gusts along the distance the air
travels, ``x`` (:class:`~ident.physics.turbulence.GustField`, ``2**20`` points every 1 cm, so ~10.5
km, 17 min at 10 m/s before it repeats), is generated from the seed at construction. The tunnel
tracks ``x(t)``, advancing at the wind speed of the moment (continuous when the fan changes), and
the buffeting forces follow it whenever the wind blows: on the held model (which does not move;
the taps see the fluctuating pressures) and during a decay, which is driven by the same field
from the release on. After the computed decay (``decay_duration_s``) the model does not freeze:
the response is continued on demand from the full final state under the same field, in chunks
of the same length (:meth:`ident.simulation.decay.SimulatedDecay.continued`), the latest
``CONTINUATION_CHUNKS_KEPT`` of which are kept (instruments sample the recent past; an older
time takes the value at the start of the oldest chunk kept). :meth:`VirtualTunnel.decay_truth`
covers the computed decay only. Smooth flow keeps the previous behaviour (the model rests at its
final state after the computed decay). Everything is deterministic for a seed: the field
depends on the seed only, and the motion on the field, the wind and the release times.

Thread safety: state changes (fan, magnet) come from Modbus server threads, reads from instrument
threads; one lock guards the state, and the sampled release is an immutable object.
"""

from __future__ import annotations

import dataclasses
import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from scipy.interpolate import CubicSpline

from ident.model.quasi_steady import StaticCoefficients
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.physics.air import R_DRY_AIR
from ident.physics.taps import TapLayout
from ident.physics.tubing import TubingSet
from ident.physics.turbulence import GustField, TurbulenceSpec, WindLoad
from ident.simulation.decay import SimulatedDecay, simulate_decay
from simulators.clock import Clock, MonotonicClock
from simulators.effects import Effect
from simulators.tubing import TubingFilter
from simulators.tunnel import SimulatedRelease, simulate_release

__all__ = ["AirState", "VirtualTunnel"]

FloatArray = npt.NDArray[np.float64]

#: Points and spacing (m) of the tunnel's gust field (see the module docstring).
GUST_FIELD_POINTS = 2**20
GUST_FIELD_DX_M = 0.01

#: Continuation chunks of the random response after a decay kept for sampling.
CONTINUATION_CHUNKS_KEPT = 2


@dataclass(frozen=True)
class AirState:
    """Ambient air: static pressure (Pa) and temperature (K); density by the ideal-gas law."""

    pressure_pa: float = 101325.0
    temperature_k: float = 293.15

    @property
    def density(self) -> float:
        """Air density, kg/m^3."""
        return self.pressure_pa / (R_DRY_AIR * self.temperature_k)


@dataclass(frozen=True, eq=False)
class _Decay:
    """A computed free decay after a release at true time ``t0``."""

    t0: float
    U: float
    duration: float
    splines: dict[str, CubicSpline] = field(repr=False)
    final: dict[str, float] = field(repr=False)
    continuation: _Continuation | None = field(default=None, repr=False)


_NAMES = ("h", "alpha", "lift", "moment")
#: The channels of a section with sway (three degrees of freedom).
_NAMES_3DOF = _NAMES + ("p", "drag")

#: Samples of the previous chunk that a continuation chunk's splines run through.
_SPLINE_LEAD = 16


class _Continuation:
    """The random response after a computed decay in turbulence, extended on demand in chunks."""

    def __init__(self, sim: SimulatedDecay, n_chunk: int) -> None:
        self._names = _NAMES if sim.n_dof == 2 else _NAMES_3DOF
        self._lock = threading.Lock()
        self._last = sim
        self._n_chunk = n_chunk
        self._end = float(sim.t[-1])
        self._chunks: list[tuple[float, dict[str, CubicSpline]]] = []

    def fill(
        self, tau: FloatArray, out: dict[str, FloatArray], mask: npt.NDArray[np.bool_]
    ) -> None:
        """Write the channels at times ``tau[mask]`` (after the computed decay) into ``out``."""
        if not np.any(mask):
            return
        with self._lock:  # one sampler extends; the others wait for it
            while self._end < float(tau[mask].max()):
                self._extend()
            chunks = list(self._chunks)
        for i, (start, splines) in enumerate(chunks):
            inside = mask & (tau > start) if i else mask  # older times: the oldest chunk kept
            for name in self._names:
                out[name][inside] = splines[name](np.maximum(tau[inside], start))

    def _extend(self) -> None:
        last = self._last
        nxt = last.continued(self._n_chunk)
        # The spline runs through the last samples of the previous chunk too, so that its end
        # condition (fading by 0.27 per knot) does not show at the seam.
        lead = slice(-_SPLINE_LEAD, None)
        t = np.concatenate([last.t[lead], nxt.t])
        splines = {name: CubicSpline(t, np.concatenate([getattr(last, name)[lead],
                                                        getattr(nxt, name)]))
                   for name in self._names}
        seam = float(last.t[-1])
        self._chunks = [*self._chunks, (seam, splines)][-CONTINUATION_CHUNKS_KEPT:]
        self._last = nxt
        self._end = float(nxt.t[-1])


class VirtualTunnel:
    """The physical truth shared by all simulated instruments.

    Parameters
    ----------
    section : SectionModel
        The spring-mounted section model (its ``rho`` is replaced by the air state's density).
    model : RationalFunctionModel
        Self-excited forces.
    taps : TapLayout
        Pressure taps of the section.
    wind_per_rpm : float
        Tunnel calibration: wind speed per fan speed, (m/s)/rpm.
    hold : (float, float) or (float, float, float)
        Hold position of the magnet, (h0 m, alpha0 rad), with sway (h0, alpha0, p0 m); p0 is 0
        when a 3-DOF section gets two numbers, and must be absent for a 2-DOF one.
    effects : sequence of Effect, optional
        Extra physics of the model in this tunnel.
    air : AirState, optional
    mean_cp_upper, mean_cp_lower : float
        Mean pressure coefficients on upper and lower faces (shape of the steady distribution).
    clock : Clock, optional
        True time (default: real monotonic time).
    decay_duration_s : float
        Length of each computed decay; afterwards the model rests at its final state.
    fs_internal : float
        Sampling rate of the computed decay before spline interpolation, Hz.
    static : StaticCoefficients, optional
        Static coefficients of the section: the mean wind load, and the buffeting forces with
        ``turbulence``. Default None: no wind load (smooth flow as before).
    turbulence : TurbulenceSpec, optional
        Oncoming turbulence (needs ``static``, ``span`` and ``seed``). Default None.
    span : float, optional
        Span of the section model, m (span-wise coherence of the gusts).
    seed : int, optional
        Seed of the gust field.
    tubing : TubingSet, optional
        Pneumatic tubing of the taps (:mod:`simulators.tubing`): :meth:`pressures` gives the
        pressures at the scanner's transducers, behind the tubes. Default None: perfect tubing.
    """

    def __init__(
        self,
        section: SectionModel,
        model: RationalFunctionModel,
        taps: TapLayout,
        *,
        wind_per_rpm: float,
        hold: tuple[float, ...] = (0.004, 0.02),
        effects: Sequence[Effect] = (),
        air: AirState | None = None,
        mean_cp_upper: float = -0.6,
        mean_cp_lower: float = -0.2,
        clock: Clock | None = None,
        decay_duration_s: float = 60.0,
        fs_internal: float = 1000.0,
        static: StaticCoefficients | None = None,
        turbulence: TurbulenceSpec | None = None,
        span: float | None = None,
        seed: int | None = None,
        tubing: TubingSet | None = None,
    ) -> None:
        if not wind_per_rpm > 0:
            raise ValueError(f"wind_per_rpm must be > 0, got {wind_per_rpm!r}")
        self.air = air or AirState()
        self.section = section.replace(rho=self.air.density)
        self.model = model
        self.taps = taps
        self.wind_per_rpm = float(wind_per_rpm)
        if len(hold) not in (2, self.section.n_dof):
            raise ValueError(f"hold must be (h0, alpha0) or, with sway, (h0, alpha0, p0); got "
                             f"{hold!r} for a {self.section.n_dof}-DOF section")
        self.hold = (float(hold[0]), float(hold[1]))
        #: Sway of the hold position, m (0 without sway).
        self.hold_p = float(hold[2]) if len(hold) == 3 else 0.0
        #: The channels :meth:`sample` and :meth:`decay_truth` give besides U and qd.
        self.channels = _NAMES if self.section.n_dof == 2 else _NAMES_3DOF
        self.effects = tuple(effects)
        self.clock: Clock = clock or MonotonicClock()
        self.decay_duration_s = float(decay_duration_s)
        self.fs_internal = float(fs_internal)
        self.static = static
        self._gusts: GustField | None = None
        if turbulence is not None:
            if static is None or span is None or seed is None:
                raise ValueError("turbulence needs static coefficients, the span and a seed")
            self._gusts = GustField.generate(turbulence, B=self.section.B, span=span,
                                             n=GUST_FIELD_POINTS, dx=GUST_FIELD_DX_M, rng=seed)
        elif span is not None or seed is not None:
            raise ValueError("span and seed are for turbulence; pass turbulence too")
        # Distance travelled by the air past the model: x(t) = x_ref + U (t - t_ref).
        self._t_ref = 0.0
        self._x_ref = 0.0
        self._cp_mean = np.where(taps.nz < 0, mean_cp_upper, mean_cp_lower)
        #: Whether the tap pressures carry the drag (a 3-DOF section whose outline can).
        self.pressures_carry_drag = self.section.n_dof == 3 and taps.carries_drag
        # The taps are fixed: their force matrix and its pseudo-inverse are computed once (an
        # SVD per production step cost ~10 % of a core with 511 taps).
        self._G = taps.integration_matrix(drag=self.pressures_carry_drag)
        self._G_pinv = np.linalg.pinv(self._G)
        self._tubing: TubingFilter | None = None
        if tubing is not None:
            # p = [lift, moment(, drag)] G+' + qd (cp - G+ G cp): the pressures as a linear map.
            mean_part = self._cp_mean - self._G_pinv @ (self._G @ self._cp_mean)
            self._tubing = TubingFilter(tubing, np.column_stack([self._G_pinv, mean_part]))
        self._lock = threading.Lock()
        self._fan_rpm = 0.0
        self._armed = True  # the magnet holds at start
        self._decay: _Decay | None = None
        self._triggers: list[float] = []
        self._releases: list[float] = []
        # Every decay with the true time it ended (caught by an arm; inf while running): the
        # truth that recorded runs are checked against (decay_truth).
        self._history: list[tuple[_Decay, float]] = []

    # -- state changes (from the simulated drive and PLC) ----------------------------------------
    def set_fan_speed(self, rpm: float) -> None:
        """Set the actual fan speed (the simulated drive ramps it), rpm."""
        with self._lock:
            now = self.clock.now()
            self._x_ref += self._fan_rpm * self.wind_per_rpm * (now - self._t_ref)
            self._t_ref = now
            self._fan_rpm = float(rpm)

    def arm(self) -> None:
        """Energise the magnet: the model is pulled back to the hold position."""
        with self._lock:
            self._armed = True
            if self._decay is not None and self._history:
                self._history[-1] = (self._history[-1][0], self.clock.now())
            self._decay = None

    def release(self) -> float:
        """De-energise the magnet: the model is released now; returns the true release time.

        The decay is computed first (~25 ms) and the release instant taken when it is installed,
        so an instrument sampling meanwhile sees the held model, consistently with later queries.
        """
        with self._lock:
            U = self._fan_rpm * self.wind_per_rpm
            x0 = self._x_ref + U * (self.clock.now() - self._t_ref)
        decay = self._compute_decay(U, x0)
        with self._lock:
            t0 = self.clock.now()
            # The decay starts at x0 in the gust field: re-anchor x(t) there, so the forces run
            # on continuously through the release (the held past moves by the ~25 ms the
            # computation took, invisible in the statistics).
            self._t_ref, self._x_ref = t0, x0
            self._decay = dataclasses.replace(decay, t0=t0)
            self._armed = False
            self._releases.append(t0)
            self._history.append((self._decay, math.inf))
        return t0

    def trigger(self) -> float:
        """Pulse the trigger line (from the PLC); return the pulse's true time."""
        with self._lock:
            t = self.clock.now()
            self._triggers.append(t)
        return t

    # -- state queries ------------------------------------------------------------------------
    @property
    def armed(self) -> bool:
        """Measure whether the magnet holds the model."""
        with self._lock:
            return self._armed

    @property
    def fan_rpm(self) -> float:
        """Measure the actual fan speed, rpm."""
        with self._lock:
            return self._fan_rpm

    def wind_speed(self) -> float:
        """Mean wind speed now, m/s."""
        with self._lock:
            return self._fan_rpm * self.wind_per_rpm

    def release_times(self) -> list[float]:
        """Return the true times of every release so far, s."""
        with self._lock:
            return list(self._releases)

    def trigger_times(self, since: float = -math.inf) -> list[float]:
        """Return the true times of trigger pulses after ``since``, s."""
        with self._lock:
            return [t for t in self._triggers if t > since]

    def sample(self, t: FloatArray) -> dict[str, FloatArray]:
        """Physical channels at true times ``t`` (s, increasing, not in the future).

        Returns
        -------
        dict
            ``h`` (m), ``alpha`` (rad), ``lift`` (N/m), ``moment`` (N m/m), ``U`` (m/s) and
            ``qd`` (dynamic pressure, Pa), each of shape ``t.shape``; with sway also ``p`` (m)
            and ``drag`` (N/m).
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if t.ndim != 1:
            raise ValueError(f"t must be 1-D, got shape {t.shape}")
        with self._lock:
            # Each decay from its release to the arm that caught it: an instrument's sample
            # times lie a little in the past (a laser averages, a scanner frame takes time),
            # and a sample taken before a catch must still show the free decay (it showed the
            # held position, a step a few ms before the arm command, in the decay's last rows).
            decays = [(decay, end) for decay, end in self._history if end > t[0]] \
                if t.size else []
            U_now = self._fan_rpm * self.wind_per_rpm
            x_origin = self._x_ref - U_now * self._t_ref
        # The wind follows the fan at all times (the Pitot and the mean pressures see it). A
        # decay's motion and self-excited forces are those computed at the wind of its release:
        # a change of wind during a free decay is not modelled (a campaign keeps it constant).
        U = np.full(t.shape, U_now)
        qd = 0.5 * self.air.density * U**2
        h0, a0 = self.hold
        B = self.section.B
        # Held: motionless, with the static aerodynamic force of the held position.
        k = self.section.n_dof
        q0 = np.array([h0 / B, a0, self.hold_p / B][:k])
        static = np.outer(qd * B**2, self.model.A[0] @ q0)
        if self.static is not None:
            gusts = None if self._gusts is None else self._gusts.shifted(x_origin)
            wind = WindLoad(self.static, U_now, B, self.air.density, gusts)
            static = static + wind.force(t)[:, :k]
        out = {"h": np.full(t.shape, h0), "alpha": np.full(t.shape, a0),
               "lift": static[:, 0] / B, "moment": static[:, 1], "U": U, "qd": qd}
        if k == 3:
            out.update(p=np.full(t.shape, self.hold_p), drag=static[:, 2] / B)
        for decay, end in decays:
            tau = t - decay.t0
            after = (tau >= 0) & (t < end)
            inside = after & (tau <= decay.duration)
            for name in self.channels:
                values = out[name].copy()
                values[inside] = decay.splines[name](tau[inside])
                values[after & ~inside] = decay.final[name]
                out[name] = values
            if decay.continuation is not None:
                decay.continuation.fill(tau, out, after & ~inside)
        return out

    def decay_truth(self, t: FloatArray) -> dict[str, FloatArray]:
        """Return the free-decay motion and forces at true times ``t`` (s), NaN outside decays.

        Unlike :meth:`sample` (the present state), this covers every release so far, each from
        its release to the arm that caught it: the truth a recorded run is checked against.

        Returns
        -------
        dict
            ``h`` (m), ``alpha`` (rad), ``lift`` (N/m), ``moment`` (N m/m), with sway ``p`` (m)
            and ``drag`` (N/m), shape ``t.shape``.
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        out = {name: np.full(t.shape, np.nan) for name in self.channels}
        with self._lock:
            history = list(self._history)
        for decay, end in history:
            tau = t - decay.t0
            inside = (tau >= 0) & (tau <= decay.duration) & (t < end)
            for name, values in out.items():
                values[inside] = decay.splines[name](tau[inside])
        return out

    def pressures(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Tap pressures (n, n_taps) and Pitot dynamic pressure (n,) at true times ``t``, Pa.

        With tubing, the tap pressures are those behind the tubes (the Pitot's is not). With
        sway they integrate to the drag too when :attr:`pressures_carry_drag`.
        """
        values = self.sample(t)
        names = ("lift", "moment", "drag") if self.pressures_carry_drag else ("lift", "moment")
        if self._tubing is not None:
            def channels(times: FloatArray) -> FloatArray:
                s = self.sample(times)
                return np.column_stack([*(s[name] for name in names), s["qd"]])

            return self._tubing.pressures(np.atleast_1d(np.asarray(t, dtype=float)),
                                          channels), values["qd"]
        mean = np.outer(values["qd"], self._cp_mean)
        G, G_pinv = self._G, self._G_pinv
        forces = np.column_stack([values[name] for name in names])
        # Remove the mean field's own lift and moment so that taps integrate to the forces.
        p = forces @ G_pinv.T + mean - (mean @ G.T) @ G_pinv.T
        return p, values["qd"]

    # -- physics ------------------------------------------------------------------------------
    def _compute_decay(self, U: float, x0: float) -> _Decay:
        """Compute the decay at wind ``U`` from position ``x0`` (m) of the gust field."""
        sim: SimulatedRelease | SimulatedDecay
        continuation = None
        if self.static is None:
            sim = simulate_release(
                self.section, self.model, U, *self.hold, duration=self.decay_duration_s,
                fs=self.fs_internal, effects=self.effects, p0=self.hold_p,
            )
        else:
            # Noise-free and without a held stretch, simulate_release is simulate_decay; the
            # latter's record can be continued.
            n = int(round(self.decay_duration_s * self.fs_internal))
            gusts = None if self._gusts is None else self._gusts.shifted(x0)
            sim = simulate_decay(self.section, self.model, U, *self.hold, n=n,
                                 fs=self.fs_internal, effects=self.effects, static=self.static,
                                 turbulence=gusts, p0=self.hold_p)
            if gusts is not None and U > 0.0:
                continuation = _Continuation(sim, n)
        splines = {name: CubicSpline(sim.t, getattr(sim, name)) for name in self.channels}
        final = {name: float(getattr(sim, name)[-1]) for name in splines}
        return _Decay(t0=math.nan, U=U, duration=float(sim.t[-1]), splines=splines, final=final,
                      continuation=continuation)
