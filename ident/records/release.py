"""One free-vibration release as a validated container (the input of every identification).

The checks here are the boundary where recorded or simulated data enters :mod:`ident`: after
them, arrays are 1-D, equally long, finite and uniformly sampled, and U is positive. Each failure
is a specific exception (a ``ValueError`` subclass) whose message names the problem.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ident.errors import InsufficientDataError, NonUniformSamplingError
from ident.numerics import validate as v
from ident.numerics.stats import white_noise_std

__all__ = ["Release", "ReleaseHold", "SAMPLING_RTOL", "MIN_PERIODS"]

#: Largest deviation of any time step from the mean step, relative to it. Host-resampled and
#: simulated time bases are uniform to round-off; 1e-6 also admits float32 device clocks.
SAMPLING_RTOL = 1e-6
#: Fewest oscillation periods (counted on the displacements) a release must hold.
MIN_PERIODS = 3
#: Fewest samples per release, whatever the rate.
MIN_SAMPLES = 64
#: Latest first sample of a release, s after the release instant. A record cut at the first
#: sample after the instant starts within a step of it, and the instants the plausibility checks
#: find wrong are tens of ms off; a time axis that starts later is a clock's, not the release's
#: (the model's lag states are zero at t = 0, and exponentials of a decay at t of 100 s
#: overflowed the fit).
START_MAX_S = 0.5

FloatArray = npt.NDArray[np.float64]


class _Record:
    """What a release and its hold share: channels as coordinates and forces, the sampling.

    A mixin of the two frozen dataclasses below, which declare the fields ``t, h, alpha, lift,
    moment, p, drag``.
    """

    t: FloatArray
    h: FloatArray
    alpha: FloatArray
    lift: FloatArray
    moment: FloatArray
    p: FloatArray | None
    drag: FloatArray | None

    @property
    def n_dof(self) -> int:
        """Degrees of freedom of the record: 2 (heave, pitch) or 3 (with sway)."""
        return 2 if self.p is None else 3

    def coordinates(self, B: float) -> FloatArray:
        """Return ``q = [h/B, alpha(, p/B)]``, shape (n, n_dof), for a deck width ``B`` (m)."""
        columns = [self.h / B, self.alpha] + ([] if self.p is None else [self.p / B])
        return np.column_stack(columns)

    def generalised_forces(self, B: float) -> FloatArray:
        """Return ``f = [L B, M(, D B)]``, shape (n, n_dof), N m/m, for a deck width ``B`` (m)."""
        columns = [self.lift * B, self.moment] + ([] if self.drag is None else [self.drag * B])
        return np.column_stack(columns)

    @property
    def dt(self) -> float:
        """Sampling interval, s."""
        return float((self.t[-1] - self.t[0]) / (self.t.size - 1))


@dataclass(frozen=True, eq=False)
class ReleaseHold(_Record):
    """The record of the model held still in the wind just before a release (times < 0).

    While the model is held the self-excited force is a constant: what the force channels
    show beyond it is the buffeting and the measurement noise alone. E2RFC in turbulence takes
    its noise model from here (:mod:`ident.identification._turbulent_fit`).

    Parameters
    ----------
    t : array_like, shape (n,)
        Time relative to the release instant, s; uniformly sampled, every value < 0.
    h, alpha, lift, moment : array_like, shape (n,)
        The same channels and units as :class:`Release`'s.
    p, drag : array_like, shape (n,), optional
        Sway and drag: both or neither, as for the release they precede.

    Raises
    ------
    ValueError
        Wrong shapes or lengths, non-finite values, a time at or after the release, fewer than
        2 samples.
    NonUniformSamplingError
        Time steps differ by more than ``SAMPLING_RTOL`` of the mean step, or t is not increasing.
    """

    t: FloatArray
    h: FloatArray
    alpha: FloatArray
    lift: FloatArray
    moment: FloatArray
    p: FloatArray | None = None
    drag: FloatArray | None = None

    def __post_init__(self) -> None:
        arrays = _channel_arrays(self, "hold")
        if arrays["t"].size < 2:
            raise ValueError(f"a hold needs at least 2 samples, got {arrays['t'].size}")
        if float(arrays["t"][-1]) >= 0.0:
            raise ValueError(f"a hold's times must all be before the release (< 0 s), its last "
                             f"is {float(arrays['t'][-1])!r} s")
        _check_uniform(arrays["t"])
        for name, arr in arrays.items():
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)

    @property
    def duration(self) -> float:
        """Length of the hold, s: its samples times the sampling interval."""
        return float(self.t.size * self.dt)

    @functools.cached_property
    def random_load(self) -> float:
        """The force channels' fluctuation over their white noise, largest channel.

        Each force's standard deviation about its mean, over its white-noise level from third
        differences (``std(diff3) / sqrt(20)``: a slow load hardly reaches them). About 1 in
        smooth flow, where a held model's force is constant; well above it when the wind
        loads the held model at random (buffeting) or periodically (vortex shedding).
        Measured with 2 % noise: 1.00-1.02 in smooth flow, with or without friction, a base
        vibration or a channel delay; 1.7-1.9 at 0.3 % turbulence and 4-5 at 1 % on the 3-DOF
        bluff deck; 24 with vortex shedding. Computed once (the channels are read-only).
        """
        forces = [self.lift, self.moment] + ([self.drag] if self.drag is not None else [])
        ratios = []
        for x in forces:
            noise = float(white_noise_std(x)) if x.size > 3 else 0.0
            spread = float(np.std(x))
            ratios.append(spread / noise if noise > 0.0 else (math.inf if spread else 1.0))
        return max(ratios)


def _channel_arrays(record: Any, what: str) -> dict[str, FloatArray]:
    """Return private float copies of a record's channels, checked 1-D, equally long, finite."""
    if (record.p is None) != (record.drag is None):
        raise ValueError(f"a {what} with sway needs both p and drag (or neither)")
    arrays = {}
    names = ("t", "h", "alpha", "lift", "moment") + (() if record.p is None else ("p", "drag"))
    for name in names:
        arr = np.array(getattr(record, name), dtype=float)  # a private copy
        if arr.ndim != 1:
            raise ValueError(f"{name} must be a 1-D array, got shape {arr.shape}")
        arrays[name] = arr
    lengths = {name: arr.size for name, arr in arrays.items()}
    if len(set(lengths.values())) != 1:
        raise ValueError(f"{what} channels must have equal lengths, got {lengths}")
    for name, arr in arrays.items():
        v.finite_array(name, arr)
    return arrays


def _check_uniform(t: FloatArray) -> float:
    """Return the mean time step of ``t``, s, after checking it is increasing and uniform."""
    steps = np.diff(t)
    dt = float(steps.mean())
    if not dt > 0.0 or np.any(steps <= 0.0):
        raise NonUniformSamplingError("t must be strictly increasing")
    worst = float(np.abs(steps - dt).max())
    if worst > SAMPLING_RTOL * dt:
        raise NonUniformSamplingError(
            f"t is not uniformly sampled: a step deviates by {worst:.3g} s from the mean "
            f"step {dt:.6g} s (tolerance {SAMPLING_RTOL:g} of the step); resample first"
        )
    return dt


@dataclass(frozen=True, eq=False)
class Release(_Record):
    """One free decay after a release from rest, in SI units.

    Parameters
    ----------
    t : array_like, shape (n,)
        Time since the release instant, s; uniformly sampled, starting at or just after 0 (the lag
        states of the aerodynamic model are zero at t = 0).
    h, alpha : array_like, shape (n,)
        Heave (m, positive down) and pitch (rad, positive nose-up).
    lift, moment : array_like, shape (n,)
        Self-excited lift (N/m, positive down) and moment (N m/m, positive nose-up), e.g. from
        integrated surface pressures.
    U : float
        Mean wind speed, m/s, > 0.
    p, drag : array_like, shape (n,), optional
        Sway (m, positive downwind) and drag (N/m, positive downwind) of a release with three
        degrees of freedom: both or neither (default: a 2-DOF release).
    rho : float, optional
        Air density, kg/m^3 (None: use the section's).
    meta : dict, optional
        Provenance (file, release index, ...), carried along untouched.
    hold : ReleaseHold, optional
        The model held still in the wind just before the release (times < 0), with the same
        channels and sampling interval; None when the record has none.

    Raises
    ------
    ValueError
        Wrong shapes or lengths, non-finite values (NaN marks a gap: cut the release before it),
        a time axis that does not start at the release instant (its first sample before
        ``-dt`` or after :data:`START_MAX_S`), U <= 0, a hold that is not a
        :class:`ReleaseHold` or whose channels or sampling interval differ from the release's.
    NonUniformSamplingError
        Time steps differ by more than ``SAMPLING_RTOL`` of the mean step, or t is not increasing.
    InsufficientDataError
        Fewer than 64 samples or fewer than ``MIN_PERIODS`` oscillation periods.
    """

    t: FloatArray
    h: FloatArray
    alpha: FloatArray
    lift: FloatArray
    moment: FloatArray
    U: float
    rho: float | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    p: FloatArray | None = None
    drag: FloatArray | None = None
    hold: ReleaseHold | None = None

    def __post_init__(self) -> None:
        arrays = _channel_arrays(self, "release")
        if arrays["t"].size < MIN_SAMPLES:
            raise InsufficientDataError(
                f"a release needs at least {MIN_SAMPLES} samples, got {arrays['t'].size}"
            )
        dt = _check_uniform(arrays["t"])
        start = float(arrays["t"][0])
        # An importer starts a release at the sample nearest its instant: up to half a step
        # before it, a step with the float arithmetic of the times.
        if not -dt <= start <= START_MAX_S:
            raise ValueError(
                f"t starts at {start:.6g} s: a release's time is counted from the release "
                f"instant, its first sample at or just after t = 0 (up to {START_MAX_S:g} s); "
                "subtract the instant the model was let go (times before it belong to the hold)")
        if self.hold is not None:
            if not isinstance(self.hold, ReleaseHold):
                raise ValueError(f"hold must be a ReleaseHold, got {type(self.hold).__name__}")
            if self.hold.n_dof != (2 if self.p is None else 3):
                raise ValueError("the hold's channels differ from the release's (sway p and "
                                 "drag in one and not in the other)")
            if abs(self.hold.dt - dt) > 1e-6 * dt:
                raise ValueError(f"the hold's sampling interval {self.hold.dt:.6g} s differs "
                                 f"from the release's {dt:.6g} s")
        U = v.positive("U", self.U)
        rho = None if self.rho is None else v.positive("rho", self.rho)
        for name, arr in arrays.items():
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "U", U)
        object.__setattr__(self, "rho", rho)
        object.__setattr__(self, "meta", dict(self.meta))
        periods = max(_periods(arrays["h"]), _periods(arrays["alpha"]))
        if periods < MIN_PERIODS:
            raise InsufficientDataError(
                f"a release must hold at least {MIN_PERIODS} oscillation periods; the "
                f"displacements show about {periods:.1f} in {self.duration:.3g} s"
            )

    @property
    def fs(self) -> float:
        """Sampling rate, Hz."""
        return 1.0 / self.dt

    @property
    def duration(self) -> float:
        """Length of the record, s."""
        return float(self.t[-1] - self.t[0])

    @classmethod
    def from_simulation(cls, sim: Any, *, meta: dict[str, Any] | None = None) -> Release:
        """Build a release from a :class:`simulators.tunnel.SimulatedRelease`.

        The samples at t >= 0 are the release; those before it (``simulate_release(pre_s=...)``,
        at least 2) are its :attr:`hold`.
        """
        after = sim.t >= 0.0
        sway = getattr(sim, "p", None)
        before = ~after
        hold = None
        if np.count_nonzero(before) >= 2:
            hold = ReleaseHold(
                t=sim.t[before], h=sim.h[before], alpha=sim.alpha[before],
                lift=sim.lift[before], moment=sim.moment[before],
                p=None if sway is None else sway[before],
                drag=None if sway is None else sim.drag[before])
        return cls(
            t=sim.t[after], h=sim.h[after], alpha=sim.alpha[after], lift=sim.lift[after],
            moment=sim.moment[after], U=sim.U, rho=sim.rho, meta=dict(meta or {}),
            p=None if sway is None else sway[after],
            drag=None if sway is None else sim.drag[after], hold=hold,
        )


def _periods(x: FloatArray) -> float:
    """Oscillation periods in a signal, counted as half the number of mean crossings.

    A 5-sample moving average first keeps noise from adding crossings near the end of a decay.
    """
    smooth = np.convolve(x - x.mean(), np.ones(5) / 5, mode="valid")
    if smooth.size < 2 or not np.any(smooth):
        return 0.0
    crossings = np.count_nonzero(np.signbit(smooth[1:]) != np.signbit(smooth[:-1]))
    return math.floor(crossings / 2)
