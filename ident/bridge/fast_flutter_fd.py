"""Many-mode frequency-domain flutter without a dense scan: the branches followed in 1/K.

The frequency-domain check (:func:`ident.bridge.flutter.frequency_domain`) solves, at each of
some 400 reduced frequencies K, the quadratic eigenvalue problem of ``2 n`` states::

    [lambda^2 M(K) + lambda Cs + Ks] eta = 0,   M(K) = Ms + rho/2 B^4 Q_modal(iK) / K^2,

with ``lambda = i omega`` (growth: ``Re lambda > 0``, i.e. ``Im omega < 0``) and
``U = B omega / K``. Here the same problem is followed, branch by branch, in the parameter
``s = 1/K`` (which rises with the wind) exactly as :mod:`ident.bridge.fast_flutter` follows
the state space in U: the same screening (still-air damping ratio below 5 %, a branch dropped
once its damping passes 30 % and still rises), the same coupling neighbourhoods (a branch near
zero damping without a crossing followed again among all the modes), the same
predictor-corrector and the same Newton on the flutter point ``T(i omega, s) v = 0`` (whole
``T``), whose wind speed is ``U_F = B omega_F s_F``. The derivative of ``M`` in ``s`` is a
central difference (step 1e-6 s): the flutter derivatives are a table's monotone cubic
interpolation or a model's closed form, so only the Jacobian is approximate and Newton still
converges to the exact root of the same ``T`` as the dense scan.

**Tabulated aerodynamics while following.** A call of the derivative function costs far more
than the small local problem it feeds (a table's interpolation, a model's conversion, their
checks: 85 % of a 200-mode run). The branches are therefore followed on ``Q(s)`` tabulated
once, in one vectorised call, at ``_TABLE_POINTS`` points uniform in ``log s`` and interpolated
by a cubic spline in ``log s`` (relative error ~1e-9 for a model's rational ``Q``; near a
table's knots, where its monotone cubic has a jump in curvature, larger, still far below what
following needs). Only the flutter point of the whole problem is solved with the function
itself (Newton from the followed point), so the answer is the dense scan's root, not the
spline's; the certification's dense solves use the function too.

**Certification** (up to ``certify_max_states`` = ``2 n`` states, default 200): at
``K_F (1 - 1e-4)`` exactly the followed root must grow among those near ``U_F``. At
``K_F (1 + 1e-4)`` (a little less wind) a growing root whose own wind speed
``B Re(omega) / K`` lies below ``U_F`` means a skipped branch fluttered first:
:class:`ident.errors.FlutterCertificationError`. Branches share K, not U: a root that grows
there at a wind speed above ``U_F`` (a higher mode, past its own flutter) is checked by a
dense solve at the K where its frequency means ``U_F``, repeated (a fixed point) while it
grows there: growing at ``U_F`` is the same error, stable passes; one whose wind speed does
not settle at ``U_F`` leaves the result "not certified" (and says why).

Not responsible for: the dense scan (:mod:`ident.bridge.flutter`), the continuation itself
(:mod:`ident.bridge.fast_flutter`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.interpolate import CubicSpline
from scipy.optimize import linear_sum_assignment

from ident.bridge.fast_flutter import (
    CERTIFY_OFFSET,
    _flutter_point,
    _follow,
    _newton,
    _Point,
    near_miss,
)
from ident.bridge.flutter import (
    BridgeFlutterResult,
    FlutterDerivativeFunction,
    _frequency_roots,
    _strain_energy_shares,
    default_U_max,
)
from ident.bridge.model import BridgeModel
from ident.errors import FlutterCertificationError
from ident.model.conventions import Q_from_flutter_derivatives
from ident.numerics import validate as v
from ident.numerics.threads import single_threaded_blas

__all__ = ["FrequencyDomainProblem", "frequency_domain"]

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]

#: Relative step of the central difference of ``M(s)``: the truncation error (~1e-12
#: relative, s^2 M''' h^2) and the round-off (~1e-16 / 1e-6) are both far below what Newton's
#: Jacobian needs.
_DIFF_STEP = 1e-6
#: Dense solves that bring a higher branch's wind speed to U_F in the certification: its
#: frequency changes by a few per cent between the two K, so each step gains that factor.
_FIXED_POINT_STEPS = 4
#: Points of the tabulated ``Q(s)`` the branches are followed on (module docstring): uniform
#: in ``log s``; over the usual four to six decades a step of ~0.003 in ``ln s``, whose cubic
#: spline is accurate to ~1e-9 relative on a model's smooth ``Q``.
_TABLE_POINTS = 4096
#: A branch whose neighbourhood flutters above the lowest whole-problem flutter speed by more
#: than this is not solved on the whole problem (its coupling outside the neighbourhood, below
#: ``coupling_tol`` = 1e-4 by default, moves its speed by about that much at the most).
_REFINE_MARGIN = 1e-2


class _TabulatedQ:
    """``Q(i/s)`` (rows and columns in the model's coordinates) as a cubic spline in ``ln s``."""

    def __init__(self, flutter_derivatives: FlutterDerivativeFunction,
                 s_range: tuple[float, float]) -> None:
        log_s = np.linspace(math.log(s_range[0]), math.log(s_range[1]), _TABLE_POINTS)
        K = np.exp(-log_s)
        Q = Q_from_flutter_derivatives(K, flutter_derivatives(K))
        self._spline = CubicSpline(log_s, Q, axis=0)

    def __call__(self, s: float) -> ComplexArray:
        return np.asarray(self._spline(math.log(s)), dtype=complex)


class FrequencyDomainProblem:
    """``T(lambda, s) = lambda^2 M(1/s) + lambda Cs + Ks`` of a bridge (module docstring).

    Parameters
    ----------
    bridge : BridgeModel
    flutter_derivatives : callable
        ``f(K) -> dict`` of the 8 or 18 derivatives at an array of K.
    s_range : (float, float)
        The ``1/K`` the derivatives may be asked at (a table's range): the difference of
        ``M`` turns one-sided at its ends.
    idx : ndarray of int, optional
        Only these modes (their rows and columns), e.g. a coupling neighbourhood.
    tabulated : _TabulatedQ, optional
        Evaluate ``Q`` from this spline instead of the function (for following branches;
        module docstring). Default: the function itself.
    """

    parameter = "1/K"
    dense_route = "ident.bridge.flutter.frequency_domain"

    def __init__(self, bridge: BridgeModel, flutter_derivatives: FlutterDerivativeFunction,
                 s_range: tuple[float, float], idx: npt.NDArray[np.intp] | None = None,
                 tabulated: _TabulatedQ | None = None) -> None:
        self.s_range = s_range
        self.idx = np.arange(bridge.n_modes) if idx is None else np.asarray(idx, dtype=np.intp)
        self.n = int(self.idx.size)
        grid = np.ix_(self.idx, self.idx)
        self._fd = flutter_derivatives
        self._tabulated = tabulated
        self._G = bridge.shape_integrals()[:, :, self.idx][:, :, :, self.idx]
        self._c = 0.5 * bridge.rho * bridge.B**4
        self.Ms = bridge.mass_matrix()[grid]
        self.Cs = bridge.damping_matrix()[grid]
        self.Ks = bridge.stiffness_matrix()[grid]
        self._cache: dict[float, ComplexArray] = {}

    def restricted(self, idx: npt.NDArray[np.intp], bridge: BridgeModel,
                   tabulated: _TabulatedQ | None = None) -> FrequencyDomainProblem:
        """Return the problem on the modes ``idx`` (indices of the whole bridge)."""
        return FrequencyDomainProblem(bridge, self._fd, self.s_range, idx, tabulated)

    def Q(self, s: float) -> ComplexArray:
        """Return the section's ``Q(i/s)`` (d x d), from the spline when there is one."""
        if self._tabulated is not None:
            return self._tabulated(s)
        K = np.array([1.0 / s])
        return np.asarray(Q_from_flutter_derivatives(K, self._fd(K))[0], dtype=complex)

    def M(self, s: float) -> ComplexArray:
        """Return the effective mass ``Ms + rho/2 B^4 Q_modal(i/s) s^2``, kg."""
        if s not in self._cache:
            Q = self.Q(s)
            d = Q.shape[-1]
            Qm = np.einsum("ij,ijrs->rs", Q, self._G[:d, :d])
            if len(self._cache) > 64:  # a continuation revisits only its last few s
                self._cache.clear()
            self._cache[s] = self.Ms + self._c * Qm * s**2
        return self._cache[s]

    def T(self, lam: complex, s: float) -> ComplexArray:
        """``T(lambda, s)``, N per unit modal coordinate."""
        return np.asarray(lam**2 * self.M(s) + lam * self.Cs + self.Ks, dtype=complex)

    def dT_dlam(self, lam: complex, s: float) -> ComplexArray:
        """``dT / d lambda``, N s per unit modal coordinate."""
        return np.asarray(2.0 * lam * self.M(s) + self.Cs, dtype=complex)

    def dT_dU(self, lam: complex, s: float) -> ComplexArray:
        """``dT / ds`` (central difference of ``M``, module docstring)."""
        h = _DIFF_STEP * s
        a, b = max(s - h, self.s_range[0]), min(s + h, self.s_range[1])
        return np.asarray(lam**2 * (self.M(b) - self.M(a)) / (b - a), dtype=complex)


def _neighbourhoods(problem: FrequencyDomainProblem, s_at: FloatArray,
                    tol: float) -> list[npt.NDArray[np.intp]]:
    """Each mode's coupling neighbourhood, as in :mod:`ident.bridge.fast_flutter`.

    Mode r's aerodynamic mass row and column at ``s_at[r]`` (where its still-air frequency
    meets the top wind speed; a common ``s`` would put a high mode at many times that wind),
    times its still-air frequency squared, relative to the stiffnesses.
    """
    omega2 = np.diag(problem.Ks).real / np.diag(problem.Ms).real
    stiffness = np.diag(problem.Ks).real
    out = []
    for r in range(problem.n):
        s = float(s_at[r])
        Q = problem.Q(s)
        d = Q.shape[-1]
        G = problem._G[:d, :d]
        row = np.abs(np.einsum("ab,abj->j", Q, G[:, :, r, :]))
        col = np.abs(np.einsum("ab,abj->j", Q, G[:, :, :, r]))
        x = omega2[r] * problem._c * s**2 * (row + col) / np.sqrt(stiffness[r] * stiffness)
        near = np.flatnonzero(x >= tol)
        out.append(np.concatenate([[r], near[near != r]]).astype(np.intp))
    return out


def _start(local: FrequencyDomainProblem, s0: float) -> _Point:
    """Mode ``local.idx[0]``'s root at ``s0``: the local quadratic problem, then Newton."""
    n = local.n
    M = local.M(s0)
    companion = np.zeros((2 * n, 2 * n), dtype=complex)
    companion[:n, n:] = np.eye(n)
    companion[n:, :n] = -np.linalg.solve(M, local.Ks)
    companion[n:, n:] = -np.linalg.solve(M, local.Cs)
    lam, vec = np.linalg.eig(companion)
    upper = np.flatnonzero(lam.imag > 0.0)
    if upper.size != n:
        raise FlutterCertificationError(f"expected {n} oscillatory roots of mode "
                                        f"{local.idx[0]}'s neighbourhood at K = {1 / s0:.4g}")
    energy = np.diag(local.Ks).real[:, None] * np.abs(vec[:n, upper]) ** 2
    rows, cols = linear_sum_assignment(-(energy / energy.sum(axis=0)))
    k = int(upper[cols[list(rows).index(0)]])
    v0 = vec[:n, k] / np.linalg.norm(vec[:n, k])
    found = _newton(local, complex(lam[k]), v0, s0, v0)
    if found is None:
        raise FlutterCertificationError(f"mode {local.idx[0]}'s root at K = {1 / s0:.4g} did "
                                        "not converge")
    return _Point(s0, complex(found[0]), found[1] / np.linalg.norm(found[1]))


@single_threaded_blas
def frequency_domain(bridge: BridgeModel, flutter_derivatives: FlutterDerivativeFunction,
                     K_range: tuple[float, float] | None = None, *,
                     U_max: float | None = None, screen_damping: float = 0.05,
                     drop_damping: float = 0.3, coupling_tol: float = 1e-4,
                     certify_max_states: int = 200, follow: Sequence[int] | None = None
                     ) -> BridgeFlutterResult:
    """Frequency-domain flutter from followed branches (the dense scan's answer, module doc).

    Parameters
    ----------
    bridge : BridgeModel
    flutter_derivatives : callable
        ``f(K) -> dict`` of the derivatives at an array of K.
    K_range : (float, float), optional
        Reduced frequencies, low and high; default as
        :func:`ident.bridge.flutter.frequency_domain`'s.
    U_max : float, optional
        Only for the default ``K_range``, m/s.
    screen_damping, drop_damping, coupling_tol, certify_max_states, follow
        As :func:`ident.bridge.fast_flutter.analyze`'s. ``certify_max_states`` counts the
        ``2 n`` states of the quadratic problem; its default (100 modes) is lower, because
        the check costs a dense solve per higher branch already growing at ``K_F`` (measured:
        200 modes, 66 such branches, 264 solves of 400 states, 90 % of a 126 s run).

    Returns
    -------
    BridgeFlutterResult
        ``method`` ``"frequency-domain"``; ``U`` per branch, NaN past a branch's end;
        ``certification`` says what was certified.

    Raises
    ------
    ident.errors.FlutterCertificationError
        The dense check finds a skipped branch growing below the flutter speed, or a branch
        could not be followed.
    """
    omega = 2.0 * math.pi * bridge.frequencies
    top = math.inf
    if K_range is None:
        top = default_U_max(bridge) if U_max is None else v.positive("U_max", U_max)
        K_range = (float(omega.min() * bridge.B / top),
                   float(omega.max() * bridge.B / (0.05 * top)))
    K_lo, K_hi = (v.positive("K_range", k) for k in K_range)
    if not K_lo < K_hi:
        raise ValueError(f"K_range must be increasing, got {K_range!r}")
    s0, s1 = 1.0 / K_hi, 1.0 / K_lo
    problem = FrequencyDomainProblem(bridge, flutter_derivatives, (s0, s1))
    n = problem.n
    tabulated = _TabulatedQ(flutter_derivatives, (s0, s1))
    # Each mode's s where its still-air frequency meets the top wind speed (all of the range
    # when a K range was given instead).
    s_at = np.clip(top / (bridge.B * omega), s0, s1)
    hoods = _neighbourhoods(problem.restricted(problem.idx, bridge, tabulated), s_at,
                            v.positive("coupling_tol", coupling_tol))
    locals_ = [problem.restricted(idx, bridge, tabulated) for idx in hoods]
    starts = [_start(locals_[r], s0) for r in range(n)]
    if follow is None:
        followed = [r for r in range(n) if -starts[r].lam.real / abs(starts[r].lam)
                    < v.positive("screen_damping", screen_damping)]
    else:
        followed = sorted({int(r) for r in follow})
        if not followed or followed[0] < 0 or followed[-1] >= n:
            raise ValueError(f"follow must name modes 0..{n - 1}, got {list(follow)!r}")
    paths: dict[int, list[_Point]] = {}
    candidates: list[tuple[float, float, float, ComplexArray, int, bool]] = []
    local_points: list[tuple[float, float, float, ComplexArray, int]] = []
    dropped = refollowed = 0
    drop_damping = v.positive("drop_damping", drop_damping)

    def past(point: _Point) -> bool:
        # Beyond the top wind speed, or the lowest crossing found so far: nothing lower there.
        lowest = min((c[0] for c in local_points), default=math.inf)
        return bridge.B * point.lam.imag * point.U > min(top, lowest * (1.0 + _REFINE_MARGIN))

    # The lowest modes first, as in the state space: an early crossing caps the others.
    for r in sorted(followed, key=lambda j: abs(starts[j].lam)):
        start, idx, local = starts[r], hoods[r], locals_[r]
        if start.lam.real > 0.0:  # growing at the highest K: flutter lies at or below
            full = np.zeros(n, dtype=complex)
            full[idx] = start.vec
            candidates.append((bridge.B * start.lam.imag * s0, start.lam.imag, s0, full, r,
                               True))
            paths[r] = [start]
            continue
        points, was_dropped = _follow(local, start, s1, drop_damping, past)
        if points[-1].lam.real <= 0.0 and idx.size < n and near_miss(points):
            # Close to zero damping in a neighbourhood: again among all the modes, r first.
            idx = np.concatenate([[r], np.delete(np.arange(n), r)]).astype(np.intp)
            local = problem.restricted(idx, bridge, tabulated)
            points, was_dropped = _follow(local, _start(local, s0), s1, drop_damping, past)
            refollowed += 1
        dropped += was_dropped
        paths[r] = points
        last = points[-1]
        if last.lam.real > 0.0:
            before = points[-2]
            t = -before.lam.real / (last.lam.real - before.lam.real)
            # The neighbourhood's flutter point first, then the whole T's (as the state space).
            s_loc, omega_loc, vec_loc = _flutter_point(
                local, before.U + t * (last.U - before.U),
                before.lam + t * (last.lam - before.lam),
                before.vec + t * (last.vec - before.vec))
            full = np.zeros(n, dtype=complex)
            full[idx] = vec_loc
            local_points.append((bridge.B * omega_loc * s_loc, s_loc, omega_loc, full, r))
    # The whole T's flutter point (n x n Newton with the function itself) only for the branches
    # that can be the lowest: beyond its neighbourhood a branch couples below coupling_tol, so
    # its whole-problem speed is within far less than _REFINE_MARGIN of its local one.
    for U_loc, s_loc, omega_loc, full, r in sorted(local_points, key=lambda c: c[0]):
        best = min((c[0] for c in candidates), default=math.inf)
        if U_loc > best * (1.0 + _REFINE_MARGIN):
            break
        s_f, omega_f, vec_f = _flutter_point(problem, s_loc, 1j * omega_loc, full)
        candidates.append((bridge.B * omega_f * s_f, omega_f, s_f, vec_f, r, False))
    result = _result(bridge, paths, candidates, s1)
    note = (f"fast route: {len(followed)} of {n} branches followed; {dropped} dropped once "
            "damped; ")
    if refollowed:
        note += f"{refollowed} followed again among all modes (near zero damping); "
    return replace(result, certification=note + _certify(
        bridge, flutter_derivatives, result, max_states=certify_max_states))


def _result(bridge: BridgeModel, paths: dict[int, list[_Point]],
            candidates: list[tuple[float, float, float, ComplexArray, int, bool]],
            s1: float) -> BridgeFlutterResult:
    n = bridge.n_modes
    n_points = max((len(p) for p in paths.values()), default=1)
    lam = np.full((n_points, n), np.nan, dtype=complex)
    s = np.full((n_points, n), np.nan)
    for r, points in paths.items():
        lam[:len(points), r] = [p.lam for p in points]
        s[:len(points), r] = [p.U for p in points]
    U = bridge.B * lam.imag * s
    fields: dict[str, Any] = {"speed": None, "frequency": None, "reduced_frequency": None,
                              "critical_mode": None, "participation": None,
                              "unstable_at_start": False}
    if candidates:
        speed, omega, s_f, vec, r, at_start = min(candidates, key=lambda c: c[0])
        fields = {"speed": float(speed), "frequency": omega / (2.0 * math.pi),
                  "reduced_frequency": 1.0 / s_f, "critical_mode": r,
                  "participation": _strain_energy_shares(bridge, vec),
                  "unstable_at_start": at_start}
    return BridgeFlutterResult(
        U_max=float(np.nanmax(U)) if np.any(np.isfinite(U)) else bridge.B * s1,
        U=U, frequencies=lam.imag / (2.0 * math.pi), damping=-lam.real / np.abs(lam),
        mode_labels=tuple(bridge.mode_labels()), method="frequency-domain", **fields)


def _certify(bridge: BridgeModel, fd: FlutterDerivativeFunction, result: BridgeFlutterResult,
             *, max_states: int) -> str:
    """Check ``result`` with two dense solves (module docstring); return what was certified."""
    if 2 * bridge.n_modes > max_states:
        return f"not certified ({2 * bridge.n_modes} states, above the dense limit)"
    if result.speed is None or result.reduced_frequency is None or result.frequency is None:
        return "not certified: no flutter found (a dense scan alone can tell)"
    if result.unstable_at_start:
        return "not certified: the branch grows from the highest K scanned"
    K_F, U_F = result.reduced_frequency, result.speed
    K_hi, K_lo = K_F * (1.0 + CERTIFY_OFFSET), K_F * (1.0 - CERTIFY_OFFSET)
    omega = _frequency_roots(bridge, fd, K_hi)[0]
    grow = omega[omega.imag < 0.0]
    U_grow = bridge.B * grow.real / K_hi
    if np.any(U_grow < U_F):
        raise FlutterCertificationError(
            f"fast route gives flutter at {U_F:.6g} m/s (K = {K_F:.6g}), but at K = "
            f"{K_hi:.6g} the dense roots already grow at "
            f"{', '.join(f'{u:.6g} m/s' for u in U_grow)}: a branch the screening skipped "
            "fluttered first (follow more branches, or use the dense scan)")
    unsure = []
    for root in grow:
        # A root growing at K_hi whose wind speed there is above U_F: the same branch at the K
        # where its frequency means U_F shows whether it grew by then. Its frequency changes
        # with K: a few fixed-point steps (dense solves) put its wind speed at U_F.
        # Usually the first solve already finds it stable; only a growing one is iterated.
        near = root
        for _ in range(_FIXED_POINT_STEPS):
            K_j = bridge.B * near.real / U_F
            at = _frequency_roots(bridge, fd, K_j)[0]
            near = at[np.argmin(np.abs(at - near))]
            if near.imag >= 0.0:
                break
        U_near = bridge.B * near.real / K_j
        if near.imag < 0.0 and U_near < U_F * (1.0 + CERTIFY_OFFSET):
            raise FlutterCertificationError(
                f"fast route gives flutter at {U_F:.6g} m/s, but the branch at "
                f"{near.real / (2 * math.pi):.6g} Hz already grows at {U_near:.6g} m/s (K = "
                f"{K_j:.6g}): a branch the screening skipped fluttered first")
        if near.imag < 0.0:
            unsure.append(f"{near.real / (2 * math.pi):.6g} Hz")
    if unsure:
        return (f"not certified: the wind speed of the growing branches at "
                f"{', '.join(unsure)} did not settle at U_F")
    checked = (f", {grow.size} branch(es) growing at higher wind speeds checked stable at "
               "U_F") if grow.size else ""
    omega = _frequency_roots(bridge, fd, K_lo)[0]
    # Only the roots near U_F count (higher modes past their own flutter grow at this K at
    # higher wind speeds; checked above); the followed one sits at U_F (1 + 1e-4).
    grow = omega[(omega.imag < 0.0)
                 & (bridge.B * omega.real / K_lo <= U_F * (1.0 + 10.0 * CERTIFY_OFFSET))]
    target = 2.0 * math.pi * result.frequency
    if grow.size != 1 or abs(grow[0].real - target) > 1e-3 * target:
        raise FlutterCertificationError(
            f"fast route gives flutter at {U_F:.6g} m/s, {result.frequency:.6g} Hz, but at "
            f"K = {K_lo:.6g} the dense roots grow at "
            f"{', '.join(f'{x.real / (2 * math.pi):.6g} Hz' for x in grow) or 'no frequency'}"
            ": not exactly the followed root")
    return (f"certified by dense roots ({2 * bridge.n_modes} states): none grows below U_F "
            f"at K = {K_hi:.6g}{checked}, only the followed one at K = {K_lo:.6g}")
