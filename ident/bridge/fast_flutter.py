"""Many-mode bridge flutter without a dense sweep: the modal rational eigenproblem, followed.

**The exact reduction.** The lag states of :class:`~ident.bridge.statespace.BridgeStateSpace`
are diagonal per lag: for an eigenvalue ``lambda`` the lag equation ``lambda x_l = lambda eta -
(U/B) d_l x_l`` gives ``x_l = p / (p + d_l) eta`` with ``p = lambda B / U``. Substituted into the
modal equations, the ``n (2 + m)`` states become the ``n x n`` rational eigenproblem::

    T(lambda, U) eta = 0,
    T = Ms lambda^2 + Cs lambda + Ks - qd B^2 [A1 + A2 p + A3 p^2 + sum_l A_(l+3) p / (p + d_l)]

with ``qd = rho U^2 / 2`` and the modal Roger matrices of the state space (the same
``modal_A``). Every eigenvalue of the state matrix that is not a lag pole ``-U d_l / B`` is a
root of ``det T``, and the other way round (checked in the tests on random models).

**Screening.** Only a weakly damped branch can reach zero damping: a branch is followed from its
still-air eigenpair when its still-air damping ratio is below ``screen_damping`` (default 0.05,
ten times the 0.5 % of a typical bridge's structure), and dropped once its damping ratio exceeds
``drop_damping`` (default 0.3) and is still rising: the wind damps it hard (a heave mode's
aerodynamic damping) and a branch climbing away from zero is the least likely to come back.
A branch is followed in the **coupling neighbourhood** of its mode: the modes whose aerodynamic
coupling with it, relative to their stiffnesses at ``U_max``, is at least ``coupling_tol``
(default 1e-4). Only the continuation uses the neighbourhood (the flutter point itself is solved
on the whole ``T``), so it only has to keep each branch's damping right to far better than the
damping a crossing is told by: a neglected coupling ``c`` moves an eigenvalue by about
``c^2`` over the modes' frequency gap, by at most about ``c`` relative when two modes share a
frequency. A branch that ends without a crossing but came within ``NEAR_MISS`` (1e-3, ten
times that bound) of zero damping anywhere on its path is followed again among all the modes,
so that no crossing is lost to a neighbourhood. (A tighter tolerance costs much and gains
nothing: on a deck whose modes all couple, as a finite-element model's do, 1e-6 puts most
modes in every neighbourhood, and 200 modes take 23 s instead of 2.9 s for the same flutter
speed.)

**Continuation.** Each followed branch goes up in U by a predictor (the tangent, from the
derivative of ``T v = 0`` with the normalisation ``c^H v = 1``, ``c`` the previous vector) and a
corrector (Newton on ``(lambda, v)``), with a step that grows when Newton converges at once and
halves when it does not, or when the new vector turns away from the old one (a swap to a nearby
branch). When a branch's real part changes sign between two steps, the flutter point
``(U, omega, v)`` is found by Newton on ``T(i omega, U) v = 0, c^H v = 1`` (``2 n + 2`` real
equations and unknowns) on the whole ``T``. The lowest such point of all followed branches is
the flutter speed.

**Certification.** When the state space has at most ``certify_max_states`` states, one dense
eigenvalue solve just below (``(1 - 1e-4) U_F``) and one just above (``(1 + 1e-4) U_F``) check
that no eigenvalue grows below and that exactly the followed pair grows above (without flutter:
none grows at ``U_max``). A failed check raises :class:`ident.errors.FlutterCertificationError`
(a branch the screening skipped crossed first); the result says what was certified, or why not.
What no check at two wind speeds can see: a branch that grew and recovered below ``U_F``
(the dense sweep misses it too between its grid points).

Not responsible for: the state matrix (:mod:`ident.bridge.statespace`), the dense sweep and the
frequency-domain route (:mod:`ident.bridge.flutter`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
import numpy.typing as npt
import scipy.linalg as sla
from scipy.optimize import linear_sum_assignment

from ident.bridge.flutter import (
    _GROWTH_RTOL,
    BridgeFlutterResult,
    _divergence_speed,
    _floor,
    _is_oscillatory,
    _strain_energy_shares,
    default_U_max,
)
from ident.bridge.model import BridgeModel
from ident.bridge.statespace import BridgeStateSpace
from ident.errors import FlutterCertificationError
from ident.model.rfc import RationalFunctionModel
from ident.numerics import validate as v
from ident.numerics.threads import single_threaded_blas

__all__ = ["ModalRationalProblem", "RationalProblem", "analyze", "certify"]

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]

#: Relative distance of the certifying dense solves from the flutter speed: the crossing pair's
#: real part there is ~1e-4 U_F d(Re lambda)/dU, some 1e-6 |lambda| for a bridge, far above the
#: dense solver's round-off (~1e-13 |lambda|), and no closer branch crossing can hide between.
CERTIFY_OFFSET = 1e-4
#: Newton's convergence: the correction relative to the eigenvalue (and the vector's norm 1).
_NEWTON_RTOL = 1e-12
_NEWTON_MAX = 8
#: Along a branch a looser convergence is enough: each point is only the next one's start, and
#: the flutter point is solved to ``_NEWTON_RTOL`` on its own.
_CONTINUATION_RTOL = 1e-8
#: Cosine between consecutive eigenvectors below which a step is taken to have swapped branches.
_SAME_BRANCH_COS = 0.9
#: Damping ratio under which a branch followed in a neighbourhood without crossing is followed
#: again among all the modes (module docstring): ten times the largest error a neglected
#: coupling of the default ``coupling_tol`` can make.
NEAR_MISS = 1e-3


def near_miss(points: Sequence[_Point]) -> bool:
    """Whether a followed branch came within :data:`NEAR_MISS` of zero damping."""
    return any(-p.lam.real < NEAR_MISS * abs(p.lam) for p in points)


class RationalProblem(Protocol):
    """What the continuation needs: ``T(lambda, s)`` of ``n`` modes and its derivatives.

    ``s`` is the parameter followed upwards: the wind speed U here, the reciprocal reduced
    frequency 1/K in :mod:`ident.bridge.fast_flutter_fd`.
    """

    n: int
    #: How messages name the parameter (``"U"``, ``"1/K"``) and the dense route to fall back on.
    parameter: str
    dense_route: str

    def T(self, lam: complex, U: float) -> ComplexArray: ...  # noqa: D102

    def dT_dlam(self, lam: complex, U: float) -> ComplexArray: ...  # noqa: D102

    def dT_dU(self, lam: complex, U: float) -> ComplexArray: ...  # noqa: D102


class ModalRationalProblem:
    """``T(lambda, U)`` of a bridge in the wind and its derivatives (module docstring).

    Parameters
    ----------
    bridge : BridgeModel
    model : RationalFunctionModel
        The deck section's self-excited forces (2 or 3 degrees of freedom).
    """

    parameter = "U"
    dense_route = "ident.bridge.flutter.analyze"

    def __init__(self, bridge: BridgeModel, model: RationalFunctionModel) -> None:
        ss = BridgeStateSpace(bridge, model)
        self.state_space = ss
        self.n = bridge.n_modes
        half_rho, B = 0.5 * bridge.rho, bridge.B
        # The same matrices as the state space's, times the powers of B of its rows.
        self.Ms = bridge.mass_matrix()
        self.Cs = bridge.damping_matrix()
        self.Ks = bridge.stiffness_matrix()
        self.A1 = half_rho * B**2 * ss.modal_A[0]
        self.A2 = half_rho * B**3 * ss.modal_A[1]
        self.M_eff = ss.effective_mass  # Ms - rho/2 B^4 A3
        self.lags = [half_rho * B**2 * ss.modal_A[3 + l] for l in range(ss.n_lags)]
        #: ``d_l / B``, 1/m: the lag pole of lag l is ``-U d_l / B``.
        self.a = ss.lag_roots / B

    def T(self, lam: complex, U: float) -> ComplexArray:
        """``T(lambda, U)``, N per unit modal coordinate."""
        out = (lam**2 * self.M_eff + lam * self.Cs + self.Ks
               - U**2 * self.A1 - U * lam * self.A2).astype(complex)
        for a, A in zip(self.a, self.lags, strict=True):
            # U^2 lambda / (lambda + a U) = qd B^2 p / (p + d) / (rho/2 B^2): finite at U = 0.
            out -= U**2 * lam / (lam + a * U) * A
        return out

    def dT_dlam(self, lam: complex, U: float) -> ComplexArray:
        """``dT / d lambda``, N s per unit modal coordinate."""
        out = (2.0 * lam * self.M_eff + self.Cs - U * self.A2).astype(complex)
        for a, A in zip(self.a, self.lags, strict=True):
            out -= U**2 * a * U / (lam + a * U) ** 2 * A
        return out

    def dT_dU(self, lam: complex, U: float) -> ComplexArray:
        """``dT / dU``, N s/m per unit modal coordinate."""
        out = (-2.0 * U * self.A1 - lam * self.A2).astype(complex)
        for a, A in zip(self.a, self.lags, strict=True):
            out -= U * lam * (2.0 * lam + a * U) / (lam + a * U) ** 2 * A
        return out

    def restricted(self, idx: npt.NDArray[np.intp]) -> ModalRationalProblem:
        """Return the problem on the modes ``idx`` only (their rows and columns of each matrix)."""
        out = object.__new__(ModalRationalProblem)
        grid = np.ix_(idx, idx)
        out.state_space, out.n, out.a = self.state_space, int(idx.size), self.a
        out.Ms, out.Cs, out.Ks = self.Ms[grid], self.Cs[grid], self.Ks[grid]
        out.A1, out.A2, out.M_eff = self.A1[grid], self.A2[grid], self.M_eff[grid]
        out.lags = [A[grid] for A in self.lags]
        return out

    def neighbourhoods(self, U_max: float, tol: float) -> list[npt.NDArray[np.intp]]:
        """Each mode's coupling neighbourhood (module docstring), mode indices (itself first).

        Coupling of modes r and j: ``|X_rj| / sqrt(K_rr K_jj)`` with ``X`` the absolute
        aerodynamic matrices at ``U_max`` and mode r's still-air frequency.
        """
        omega = np.sqrt(np.diag(self.Ks) / np.diag(self.Ms))
        scale = np.sqrt(np.outer(np.diag(self.Ks), np.diag(self.Ks)))
        aero = U_max**2 * (np.abs(self.A1) + sum((np.abs(A) for A in self.lags),
                                                  np.zeros_like(self.A1)))
        out = []
        for r in range(self.n):
            x = (aero[r] + U_max * omega[r] * np.abs(self.A2[r])
                 + omega[r] ** 2 * np.abs(self.M_eff[r] - self.Ms[r])
                 + aero[:, r] + U_max * omega[r] * np.abs(self.A2[:, r])
                 + omega[r] ** 2 * np.abs(self.M_eff[:, r] - self.Ms[:, r])) / scale[r]
            near = np.flatnonzero(x >= tol)
            out.append(np.concatenate([[r], near[near != r]]).astype(np.intp))
        return out


@dataclass
class _Point:
    U: float
    lam: complex
    vec: ComplexArray  # in the neighbourhood, c^H vec = 1 with c the previous vector


def _newton(problem: RationalProblem, lam: complex, vec: ComplexArray, U: float,
            c: ComplexArray, rtol: float = _NEWTON_RTOL
            ) -> tuple[complex, ComplexArray, int] | None:
    """Newton on ``T v = 0, c^H v = 1`` at fixed U; ``(lambda, v, iterations)`` or None."""
    n = vec.size
    for it in range(1, _NEWTON_MAX + 1):
        J = np.zeros((n + 1, n + 1), dtype=complex)
        T = problem.T(lam, U)
        J[:n, :n] = T
        J[:n, n] = problem.dT_dlam(lam, U) @ vec
        J[n, :n] = c.conj()
        rhs = -np.concatenate([T @ vec, [c.conj() @ vec - 1.0]])
        try:
            step = np.linalg.solve(J, rhs)
        except np.linalg.LinAlgError:
            return None
        vec = vec + step[:n]
        lam = lam + step[n]
        if not np.all(np.isfinite(step)):
            return None
        if abs(step[n]) <= rtol * abs(lam) and np.linalg.norm(step[:n]) <= (
                rtol * 10 * np.linalg.norm(vec)):
            return lam, vec, it
    return None


def _tangent(problem: RationalProblem, p: _Point) -> tuple[complex, ComplexArray]:
    """``(d lambda / dU, dv / dU)`` along the branch at ``p`` (normalisation kept)."""
    n = p.vec.size
    J = np.zeros((n + 1, n + 1), dtype=complex)
    J[:n, :n] = problem.T(p.lam, p.U)
    J[:n, n] = problem.dT_dlam(p.lam, p.U) @ p.vec
    J[n, :n] = p.vec.conj() / np.vdot(p.vec, p.vec)
    rhs = np.concatenate([-problem.dT_dU(p.lam, p.U) @ p.vec, [0.0]])
    d = np.linalg.solve(J, rhs)
    return complex(d[n]), d[:n]


def _follow(problem: RationalProblem, start: _Point, U_stop: float,
            drop_damping: float, stop: Callable[[_Point], bool] | None = None
            ) -> tuple[list[_Point], bool]:
    """Follow a branch up to ``U_stop`` (or its crossing); ``(points, dropped)``.

    Stops at the first point with a positive real part (the crossing lies between the last two
    points), when the branch is dropped (module docstring), or at the first point for which
    ``stop`` is true (e.g. past a wind speed, where the parameter is not U).
    """
    points = [start]
    h = U_stop / 40.0
    h_min = U_stop * 1e-7
    while points[-1].U < U_stop:
        p = points[-1]
        dlam, dvec = _tangent(problem, p)
        h = min(h, U_stop - p.U, U_stop / 8.0)
        while True:
            U_new = p.U + h
            c = p.vec / np.vdot(p.vec, p.vec)
            found = _newton(problem, p.lam + h * dlam, p.vec + h * dvec, U_new, c,
                            _CONTINUATION_RTOL)
            if found is not None:
                lam, vec, its = found
                cos = abs(np.vdot(p.vec, vec)) / (np.linalg.norm(p.vec) * np.linalg.norm(vec))
                # The corrector should stay near the predictor, else it may have jumped.
                near = abs(lam - (p.lam + h * dlam)) <= 0.2 * abs(h * dlam) + 1e-6 * abs(lam)
                if cos >= _SAME_BRANCH_COS and near and lam.imag > 0.0:
                    break
            h /= 2.0
            if h < h_min:
                raise FlutterCertificationError(
                    f"the branch from {start.lam.imag / (2 * math.pi):.6g} Hz could not be "
                    f"followed beyond {problem.parameter} = {p.U:.6g} (a step of "
                    f"{h_min:.3g} failed): use {problem.dense_route} (the dense sweep)")
        points.append(_Point(U_new, complex(lam), vec / np.linalg.norm(vec)))
        if its <= 3:
            h *= 1.6
        if lam.real > _GROWTH_RTOL * abs(lam):
            return points, False
        zeta = -lam.real / abs(lam)
        zeta_before = -p.lam.real / abs(p.lam)
        if zeta > drop_damping and zeta > zeta_before:
            return points, True
        if stop is not None and stop(points[-1]):
            break
    return points, False


def _flutter_point(problem: RationalProblem, U0: float, lam0: complex,
                   vec0: ComplexArray) -> tuple[float, float, ComplexArray]:
    """Newton on ``T(i omega, U) v = 0, c^H v = 1`` (whole T); ``(U, omega, v)``."""
    n = problem.n
    U, omega, vec = U0, lam0.imag, vec0.astype(complex)
    c = vec / np.vdot(vec, vec)
    for _ in range(2 * _NEWTON_MAX):
        lam = 1j * omega
        T = problem.T(lam, U)
        F = np.concatenate([T @ vec, [c.conj() @ vec - 1.0]])
        Jc = np.zeros((n + 1, n), dtype=complex)
        Jc[:n] = T
        Jc[n] = c.conj()
        col_w = np.concatenate([1j * problem.dT_dlam(lam, U) @ vec, [0.0]])
        col_u = np.concatenate([problem.dT_dU(lam, U) @ vec, [0.0]])
        # Real form: v complex (2 n unknowns), omega and U real.
        J = np.block([[Jc.real, -Jc.imag, col_w.real[:, None], col_u.real[:, None]],
                      [Jc.imag, Jc.real, col_w.imag[:, None], col_u.imag[:, None]]])
        step = np.linalg.solve(J, -np.concatenate([F.real, F.imag]))
        vec = vec + step[:n] + 1j * step[n:2 * n]
        omega += step[2 * n]
        U += step[2 * n + 1]
        if abs(step[2 * n + 1]) <= 1e-13 * abs(U) and abs(step[2 * n]) <= 1e-13 * abs(omega):
            return float(U), float(omega), vec
    raise FlutterCertificationError(
        f"Newton on the flutter point did not converge from {problem.parameter} = {U0:.6g}: "
        f"use {problem.dense_route} (the dense sweep)")


def _still_air(local: ModalRationalProblem, idx: npt.NDArray[np.intp]) -> _Point:
    """Return the still-air eigenpair of mode ``idx[0]`` in its neighbourhood ``idx``.

    The undamped problem ``Ks v = omega^2 M_eff v`` of the neighbourhood, its eigenvectors
    given to the modes by their largest shares of strain energy (one-to-one), then Newton with
    the damping from the one that is mode ``idx[0]``'s.
    """
    w2, vecs = sla.eig(local.Ks, local.M_eff)
    w2 = np.asarray(w2)
    if np.any(~np.isfinite(w2)) or np.any(w2.real <= 0.0):
        raise ValueError(f"the still-air problem of mode {idx[0]} has a non-oscillatory "
                         "eigenvalue: the aerodynamic added mass dominates the structure")
    stiffness = np.diag(local.Ks)
    energy = stiffness[:, None] * np.abs(vecs) ** 2  # (mode, eigenvector)
    rows, cols = linear_sum_assignment(-(energy / energy.sum(axis=0)))
    k = int(cols[list(rows).index(0)])
    vec = (vecs[:, k] / np.linalg.norm(vecs[:, k])).astype(complex)
    found = _newton(local, 1j * math.sqrt(w2[k].real), vec, 0.0, vec)
    if found is None:
        raise FlutterCertificationError(f"the still-air eigenpair of mode {idx[0]} did not "
                                        "converge")
    return _Point(0.0, complex(found[0]), found[1] / np.linalg.norm(found[1]))


@single_threaded_blas
def analyze(bridge: BridgeModel, model: RationalFunctionModel, U_max: float | None = None, *,
            screen_damping: float = 0.05, drop_damping: float = 0.3,
            coupling_tol: float = 1e-4, certify_max_states: int = 600,
            follow: Sequence[int] | None = None) -> BridgeFlutterResult:
    """Flutter of a bridge from the followed branches of its rational eigenproblem.

    The same answer as :func:`ident.bridge.flutter.analyze` (the dense sweep), found without
    one (module docstring).

    Parameters
    ----------
    bridge : BridgeModel
    model : RationalFunctionModel
        The deck section's self-excited forces (2 or 3 degrees of freedom).
    U_max : float, optional
        Top of the search, m/s; default :func:`ident.bridge.flutter.default_U_max`.
    screen_damping : float
        Still-air damping ratio below which a branch is followed.
    drop_damping : float
        Damping ratio above which a branch whose damping still rises is no longer followed
        (``math.inf``: follow every screened branch to the end).
    coupling_tol : float
        Relative aerodynamic coupling that puts a mode in a branch's neighbourhood (module
        docstring).
    certify_max_states : int
        Largest state space (``n (2 + lags)``) certified by two dense eigenvalue solves.
    follow : sequence of int, optional
        Follow exactly these modes' branches (no screening): for checks and experts.

    Returns
    -------
    BridgeFlutterResult
        ``U`` per branch (shape (n_points, n_modes)) as in the frequency domain: each followed
        branch's wind speeds, NaN past its end and for the branches not followed;
        ``certification`` says what was certified.

    Raises
    ------
    ident.errors.FlutterCertificationError
        The dense check disagrees (an eigenvalue other than the followed pair grows), or a
        branch could not be followed.

    Examples
    --------
    Two uniform modes (heave, pitch) on a 1 m deck, the flat plate: the dense sweep's 11.75 m/s.

    >>> from ident.model import flat_plate
    >>> bridge = BridgeModel.from_dict({"B": 0.3, "rho": 1.225, "nodes_x": [0.0, 1.0],
    ...     "modes": [{"frequency": 2.0, "damping": 0.005, "generalised_mass": 3.0,
    ...                "h": [1.0, 1.0]},
    ...               {"frequency": 4.0, "damping": 0.005, "generalised_mass": 0.03,
    ...                "alpha": [1.0, 1.0]}]})
    >>> result = analyze(bridge, flat_plate.jones_model())
    >>> round(result.speed, 2), result.certification.split(";")[0]
    (11.75, 'fast route: 2 of 2 branches followed')
    """
    U_max = default_U_max(bridge) if U_max is None else v.positive("U_max", U_max)
    screen_damping = v.positive("screen_damping", screen_damping)
    drop_damping = v.positive("drop_damping", drop_damping)
    coupling_tol = v.positive("coupling_tol", coupling_tol)
    problem = ModalRationalProblem(bridge, model)
    n = problem.n
    hoods = problem.neighbourhoods(U_max, coupling_tol)
    locals_ = [problem.restricted(idx) for idx in hoods]
    starts = [_still_air(locals_[r], hoods[r]) for r in range(n)]
    if follow is None:
        followed = [r for r in range(n)
                    if -starts[r].lam.real / abs(starts[r].lam) < screen_damping]
    else:
        followed = sorted({int(r) for r in follow})
        if not followed or followed[0] < 0 or followed[-1] >= n:
            raise ValueError(f"follow must name modes 0..{n - 1}, got {list(follow)!r}")
    paths: dict[int, list[_Point]] = {}
    dropped = refollowed = 0
    best: tuple[float, float, ComplexArray, int] | None = None
    # The lowest modes first: flutter usually starts there, and a found flutter speed caps
    # how far the other branches are followed.
    for r in sorted(followed, key=lambda j: abs(starts[j].lam)):
        idx, local = hoods[r], locals_[r]
        U_stop = U_max if best is None else best[0]
        points, was_dropped = _follow(local, starts[r], U_stop, drop_damping)
        last = points[-1]
        crossed = last.lam.real > _GROWTH_RTOL * abs(last.lam)
        if not crossed and idx.size < n and near_miss(points):
            # Close to zero damping in a neighbourhood: again among all the modes, r first.
            idx = np.concatenate([[r], np.delete(np.arange(n), r)]).astype(np.intp)
            local = problem.restricted(idx)
            points, was_dropped = _follow(local, _still_air(local, idx), U_stop, drop_damping)
            last = points[-1]
            crossed = last.lam.real > _GROWTH_RTOL * abs(last.lam)
            refollowed += 1
        dropped += was_dropped
        paths[r] = points
        if crossed:
            before = points[-2]
            # Linear interpolation of the real part between the bracketing points.
            t = -before.lam.real / (last.lam.real - before.lam.real)
            U0 = before.U + t * (last.U - before.U)
            lam_guess = before.lam + t * (last.lam - before.lam)
            # Newton on the neighbourhood first (cheap), then on the whole T from there: the
            # neglected coupling moves the point by ~coupling_tol^2, one or two iterations.
            U_loc, omega_loc, vec_loc = _flutter_point(
                local, U0, lam_guess, before.vec + t * (last.vec - before.vec))
            full = np.zeros(n, dtype=complex)
            full[idx] = vec_loc
            U_f, omega_f, vec_f = _flutter_point(problem, U_loc, 1j * omega_loc, full)
            if best is None or U_f < best[0]:
                best = (U_f, omega_f, vec_f, r)
    result = _result(bridge, problem, paths, best, U_max)
    return replace(result, certification=certify(problem, result, followed, dropped=dropped,
                                                 refollowed=refollowed,
                                                 max_states=certify_max_states))


def _result(bridge: BridgeModel, problem: ModalRationalProblem, paths: dict[int, list[_Point]],
            best: tuple[float, float, ComplexArray, int] | None, U_max: float
            ) -> BridgeFlutterResult:
    n_points = max((len(p) for p in paths.values()), default=1)
    U = np.full((n_points, problem.n), np.nan)
    lam = np.full((n_points, problem.n), np.nan, dtype=complex)
    for r, points in paths.items():
        U[:len(points), r] = [p.U for p in points]
        lam[:len(points), r] = [p.lam for p in points]
    speed = frequency = K = None
    critical = None
    participation = None
    if best is not None:
        speed, omega, vec, critical = best
        frequency = omega / (2.0 * math.pi)
        K = omega * bridge.B / speed
        participation = _strain_energy_shares(bridge, vec)
    return BridgeFlutterResult(
        speed=speed, frequency=frequency, reduced_frequency=K, critical_mode=critical,
        participation=participation, U_max=U_max, U=U, frequencies=lam.imag / (2.0 * math.pi),
        damping=-lam.real / np.abs(lam), mode_labels=tuple(bridge.mode_labels()),
        method="state-space",
        # The dense route's divergence search (sign of det(Ks - qd B^2 A1), then Brent) over
        # the whole range, as the dense route reports it: 41 speeds, one LU of n x n each
        # (2 s at 1000 modes).
        divergence_speed=_divergence_speed(bridge, problem.state_space,
                                           np.linspace(0.0, U_max, 41)),
    )


def certify(problem: ModalRationalProblem, result: BridgeFlutterResult,
            followed: Sequence[int], *, dropped: int = 0, refollowed: int = 0,
            max_states: int = 600) -> str:
    """Check ``result`` with dense eigenvalue solves; return what was certified.

    Parameters
    ----------
    problem : ModalRationalProblem
    result : BridgeFlutterResult
        The fast route's answer.
    followed : sequence of int
        The modes whose branches were followed (for the message).
    dropped : int
        How many of them were dropped once damped (for the message).
    refollowed : int
        How many were followed again among all the modes (:data:`NEAR_MISS`; for the message).
    max_states : int
        Above this many states no dense solve is made (it would cost more than the route).

    Raises
    ------
    ident.errors.FlutterCertificationError
        An eigenvalue other than the followed pair grows (module docstring).
    """
    ss = problem.state_space
    route = (f"fast route: {len(followed)} of {problem.n} branches followed; {dropped} "
             "dropped once damped")
    if refollowed:
        route += f"; {refollowed} followed again among all modes (near zero damping)"
    if ss.n_states > max_states:
        return f"{route}; not certified ({ss.n_states} states, above the dense limit)"
    floor = _floor(ss.bridge)

    def growing(U: float) -> ComplexArray:
        lam = ss.eigenvalues(U)
        osc = lam[_is_oscillatory(lam, floor)]
        return osc[osc.real > _GROWTH_RTOL * np.abs(osc)]

    if result.speed is None or result.frequency is None:
        grow = growing(result.U_max)
        if grow.size:
            raise FlutterCertificationError(
                f"{route} found no flutter below U_max = {result.U_max:.6g} m/s, but the dense "
                f"eigenvalues there grow at {_hz(grow)}: a branch the screening skipped "
                "fluttered (follow more branches, or use the dense sweep)")
        return f"{route}; certified: no eigenvalue grows at U_max ({ss.n_states} states)"
    below, above = (1.0 - CERTIFY_OFFSET) * result.speed, (1.0 + CERTIFY_OFFSET) * result.speed
    grow = growing(below)
    if grow.size:
        raise FlutterCertificationError(
            f"{route} gives flutter at {result.speed:.6g} m/s, but at {below:.6g} m/s the dense "
            f"eigenvalues already grow at {_hz(grow)}: a branch the screening skipped fluttered "
            "first (follow more branches, or use the dense sweep)")
    grow = growing(above)
    omega = 2.0 * math.pi * result.frequency
    if grow.size != 1 or abs(grow[0].imag - omega) > 1e-3 * omega:
        raise FlutterCertificationError(
            f"{route} gives flutter at {result.speed:.6g} m/s, {result.frequency:.6g} Hz, but "
            f"at {above:.6g} m/s the dense eigenvalues grow at {_hz(grow) or 'no frequency'}: "
            "not exactly the followed pair")
    return (f"{route}; certified by dense eigenvalues ({ss.n_states} states): none grows at "
            f"{below:.6g} m/s, only the followed pair at {above:.6g} m/s")


def _hz(lam: ComplexArray) -> str:
    return ", ".join(f"{x.imag / (2 * math.pi):.6g} Hz" for x in lam)
