"""Flutter analysis: time-domain (state-space eigenvalues against U) and frequency-domain (Scanlan).

The time-domain route is windrig's primary one (``docs/reference/conventions.md``, "In the time
domain"): the state matrix of :class:`~ident.model.statespace.AeroelasticSystem` depends explicitly
on U, so the flutter speed is simply the lowest U at which an oscillatory eigenvalue crosses into
the right half plane; no iteration on the reduced frequency is needed. The classical
frequency-domain route (Scanlan and Tomko) works from flutter-derivative functions and iterates on
K; it is kept as an independent cross-check and as the only route for flutter-derivative tables that
have no rational-function model.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.linalg import eig
from scipy.optimize import brentq, linear_sum_assignment

from ident.model.conventions import Q_from_flutter_derivatives, name_modes
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.model.statespace import AeroelasticSystem
from ident.numerics import validate as v

__all__ = ["FlutterResult", "LostModeError", "StillAirModesError", "analyze", "default_U_max",
           "frequency_domain", "speed_sensitivity"]

#: Branch names, in the order of the coordinates (a 2-DOF section has the first two).
MODE_NAMES: tuple[str, ...] = ("heave", "pitch", "sway")

#: Lowest reduced frequency the default search range reaches for the faster structural mode.
#: Below K ~ 0.2 almost no section-model test has data, so a prediction there is extrapolation.
_K_MIN_DEFAULT = 0.2

#: Real part, relative to |lambda|, above which a grid point counts as unstable.
_UNSTABLE_RTOL = 1e-9


@dataclass(frozen=True)
class FlutterResult:
    """Outcome of a flutter analysis.

    Attributes
    ----------
    speed : float or None
        Flutter speed, m/s; None when no flutter was found below ``U_max``.
    frequency : float or None
        Flutter frequency, Hz (None without flutter).
    critical_mode : str or None
        Which structural mode goes unstable: ``"heave"``, ``"pitch"`` or ``"sway"`` (the branch is
        named by the degree of freedom that dominates it in still air).
    U_max : float
        Upper end of the searched wind-speed range, m/s.
    U : ndarray, shape (n,)
        Wind speeds of the mode curves, m/s.
    frequencies : ndarray, shape (n, n_dof)
        Damped frequency of each mode against U, Hz (0 where a mode is overdamped).
    damping : ndarray, shape (n, n_dof)
        Damping ratio ``-Re(lambda)/|lambda|`` of each mode against U.
    mode_names : tuple of str
        Column names of ``frequencies`` and ``damping``.
    divergence_speed : float or None
        Lowest U below ``U_max`` at which the static aeroelastic stiffness loses positive
        definiteness (torsional divergence), m/s.
    method : str
        ``"state-space"`` or ``"frequency-domain"``.
    reduced_frequency : float or None
        Reduced frequency at flutter ``K_F = B omega_F / U_F`` (None without flutter).
    unstable_at_start : bool
        The frequency domain only: a branch is already unstable at the highest K searched (the
        lowest wind speed): ``speed`` is then that branch's wind speed there, and flutter lies
        at or below it, outside the range searched.
    """

    speed: float | None
    frequency: float | None
    critical_mode: str | None
    U_max: float
    U: npt.NDArray[np.float64] = field(repr=False)
    frequencies: npt.NDArray[np.float64] = field(repr=False)
    damping: npt.NDArray[np.float64] = field(repr=False)
    mode_names: tuple[str, ...] = MODE_NAMES[:2]
    divergence_speed: float | None = None
    method: str = "state-space"
    reduced_frequency: float | None = None
    unstable_at_start: bool = False

    @property
    def found(self) -> bool:
        """True when flutter occurs below ``U_max``."""
        return self.speed is not None

    def summary(self) -> str:
        """One plain-language line for operators and logs."""
        if self.speed is None:
            text = f"no flutter below U_max = {self.U_max:.3g} m/s ({self.method})"
        elif self.unstable_at_start:
            text = (f"unstable from the start of the search: flutter at or below U = "
                    f"{self.speed:.4g} m/s, {self.critical_mode} branch ({self.method})")
        else:
            text = (
                f"flutter at U = {self.speed:.4g} m/s, f = {self.frequency:.4g} Hz, "
                f"{self.critical_mode} branch ({self.method})"
            )
        if self.divergence_speed is not None:
            text += f"; torsional divergence at U = {self.divergence_speed:.4g} m/s"
        return text


def default_U_max(section: SectionModel) -> float:
    """Default upper wind speed of a flutter search, m/s.

    The range reaches a reduced frequency of 0.2 for the faster of heave and pitch, i.e. a
    reduced velocity ``U / (f B)`` of about 31, beyond the flutter point of any practical deck.
    (Sway is left out: it is the slowest mode of most rigs and rarely the one that flutters.)
    """
    return 2.0 * math.pi * max(section.fh, section.fa) * section.B / _K_MIN_DEFAULT


def _oscillatory_candidates(lam: npt.NDArray[np.complex128]) -> npt.NDArray[np.complex128]:
    """Eigenvalues in the upper half plane, plus real ones (a mode may become overdamped)."""
    return lam[lam.imag >= -1e-9 * np.maximum(1.0, np.abs(lam))]


def _follow(
    previous: npt.NDArray[np.complex128], lam: npt.NDArray[np.complex128]
) -> npt.NDArray[np.complex128]:
    """Continue each tracked branch to the nearest candidate eigenvalue (one-to-one)."""
    candidates = _oscillatory_candidates(lam)
    cost = np.abs(previous[:, None] - candidates[None, :])
    rows, cols = linear_sum_assignment(cost)
    out = np.empty_like(previous)
    out[rows] = candidates[cols]
    return out


class LostModeError(ValueError):
    """A frequency-domain search lost a mode: at some K a root is no longer oscillatory.

    Where the aerodynamic stiffness (``H4*``, ``A3*`` over ``K^2``) overcomes a mode's spring:
    a static divergence within the derivatives' reduced frequencies, or derivatives in the
    wrong columns or units (:func:`ident.tables.flutter_routes.frequency_domain_failure`).
    """


class StillAirModesError(ValueError):
    """The model at the start of the search has not one oscillatory mode per degree of freedom.

    A wild refit (an alternative structure, a jackknife refit) can have an added mass that
    overturns the structure's (no oscillatory mode, or one that grows without wind): its flutter
    search has nowhere to start.
    """


def _initial_branches(
    section: SectionModel, model: RationalFunctionModel, U0: float
) -> npt.NDArray[np.complex128]:
    """Return the structural eigenvalues at ``U0``, ordered (heave, pitch(, sway))."""
    system = AeroelasticSystem(section, model, U0)
    lam, vec = np.linalg.eig(system.matrix())
    n = section.n_dof
    # Lag states have real eigenvalues; the structural ones are the complex pairs.
    oscillatory = np.flatnonzero(lam.imag > 1e-9 * np.abs(lam))
    if oscillatory.size != n:
        raise StillAirModesError(
            f"expected {n} oscillatory still-air modes, found {oscillatory.size}: the section is "
            "overdamped or the aerodynamic model dominates the structure at low wind speed"
        )
    growing = lam[oscillatory].real > _UNSTABLE_RTOL * np.abs(lam[oscillatory])
    if growing.any():
        worst = lam[oscillatory][np.argmax(lam[oscillatory].real)]
        raise StillAirModesError(
            f"a mode grows in still air ({abs(worst.imag) / (2 * math.pi):.3g} Hz, damping "
            f"ratio {-worst.real / abs(worst):.3g}): the model's aerodynamic added mass (A3, "
            "which stays as the wind speed goes to zero) overturns the structure's, so no "
            "flutter speed can be defined")
    order = list(name_modes(vec[0:n, oscillatory].T, section.mass_matrix()))
    return np.asarray(lam[oscillatory[order]], dtype=complex)


def analyze(
    section: SectionModel,
    model: RationalFunctionModel,
    U_max: float | None = None,
    *,
    n_points: int = 400,
) -> FlutterResult:
    """Time-domain flutter analysis of a section model with a rational-function aerodynamic model.

    The eigenvalues of the state matrix ``A(U)`` are followed from still air to ``U_max`` on a
    uniform grid (each branch continued to its nearest eigenvalue); the first sign change of the
    real part of an oscillatory branch is then refined with Brent's method to machine precision.

    Parameters
    ----------
    section : SectionModel
        Structure and air density.
    model : RationalFunctionModel
        Self-excited forces.
    U_max : float, optional
        Upper end of the search, m/s; default :func:`default_U_max`.
    n_points : int, optional
        Grid points of the mode curves (>= 20). The grid must be fine enough to follow crossing
        branches; 400 is ample for section models of two or three degrees of freedom.

    Returns
    -------
    FlutterResult
        ``speed`` is None when there is no flutter below ``U_max`` (``summary()`` says so).

    References
    ----------
    M. Gan Chowdhury and P. P. Sarkar, Engineering Structures 27 (2005), section 2.

    Examples
    --------
    >>> from ident.model import flat_plate
    >>> s = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)
    >>> result = analyze(s, flat_plate.jones_model())
    >>> result.critical_mode, round(result.speed, 2)
    ('pitch', 11.75)
    """
    U_max = default_U_max(section) if U_max is None else v.positive("U_max", U_max)
    n_points = v.grid_size(n_points)
    U = np.linspace(0.0, U_max, n_points)
    branches = np.empty((n_points, section.n_dof), dtype=complex)
    branches[0] = _initial_branches(section, model, 0.0)
    for i in range(1, n_points):
        # Linear extrapolation of each branch makes crossing branches easy to tell apart.
        guess = branches[i - 1] if i == 1 else 2 * branches[i - 1] - branches[i - 2]
        lam = AeroelasticSystem(section, model, U[i]).eigenvalues()
        branches[i] = _follow(guess, lam)

    speed = frequency = None
    critical: str | None = None
    # A relative threshold keeps round-off (|Re| ~ 1e-16 |lambda| for an undamped structure in
    # still air) from counting as instability; the crossing itself is then refined exactly.
    unstable = (branches.real > _UNSTABLE_RTOL * np.abs(branches)) & (branches.imag > 0.0)
    unstable[0] = False  # still air: structural damping >= 0 cannot be unstable
    if unstable.any():
        i, j = (int(x) for x in np.argwhere(unstable)[np.argmin(np.argwhere(unstable)[:, 0])])

        def real_part(u: float) -> float:
            lam_u = AeroelasticSystem(section, model, u).eigenvalues()
            return float(_follow(branches[i - 1 : i, j], lam_u)[0].real)

        speed = float(brentq(real_part, U[i - 1], U[i], xtol=1e-12 * U_max, rtol=1e-12))
        lam_speed = AeroelasticSystem(section, model, speed).eigenvalues()
        lam_f = _follow(branches[i : i + 1, j], lam_speed)
        frequency = float(lam_f[0].imag / (2 * math.pi))
        critical = MODE_NAMES[j]

    return FlutterResult(
        speed=speed,
        frequency=frequency,
        critical_mode=critical,
        U_max=U_max,
        U=U,
        frequencies=branches.imag / (2 * math.pi),
        damping=-branches.real / np.abs(branches),
        mode_names=MODE_NAMES[: section.n_dof],
        divergence_speed=_divergence_speed(section, model.A[0, :section.n_dof, :section.n_dof], U),
        method="state-space",
        reduced_frequency=_reduced_frequency(section, speed, frequency),
    )


def _reduced_frequency(
    section: SectionModel, speed: float | None, frequency: float | None
) -> float | None:
    """``K_F = B omega_F / U_F``, or None without flutter."""
    if speed is None or frequency is None:
        return None
    return 2.0 * math.pi * frequency * section.B / speed


def _divergence_speed(
    section: SectionModel, A1: npt.NDArray[np.float64], U: npt.NDArray[np.float64]
) -> float | None:
    """Lowest U on the grid (refined) where ``det(Ks - rho/2 U^2 B^2 A1)`` changes sign."""
    Ks = section.stiffness_matrix()

    def det(u: float) -> float:
        return float(np.linalg.det(Ks - 0.5 * section.rho * u**2 * section.B**2 * A1))

    values = np.array([det(u) for u in U])
    flips = np.flatnonzero(np.sign(values[1:]) != np.sign(values[:-1]))
    if flips.size == 0:
        return None
    i = int(flips[0])
    return float(brentq(det, U[i], U[i + 1], xtol=1e-12 * U[-1]))


FlutterDerivativeFunction = Callable[[npt.NDArray[np.float64]], dict[str, Any]]


def _frequency_roots(
    section: SectionModel, fd: FlutterDerivativeFunction, K: float
) -> npt.NDArray[np.complex128]:
    """Complex circular frequencies (Re > 0) of harmonic motion at reduced frequency ``K``.

    With ``U = B omega / K`` the flutter equation is the quadratic eigenvalue problem
    ``[-omega^2 (Ms + rho/2 B^4 Q(iK)/K^2) + i omega Cs + Ks] q = 0``; growth means Im(omega) < 0.
    """
    n = section.n_dof
    Q = Q_from_flutter_derivatives(np.array([K]), fd(np.array([K])))[0]
    if Q.shape[-1] < n:
        raise ValueError("the section has a lateral spring (3 degrees of freedom) but the flutter "
                         "derivatives are the 8 of heave and pitch: give all 18")
    M = section.mass_matrix() + 0.5 * section.rho * section.B**4 * Q[:n, :n] / K**2
    M_inv = np.linalg.inv(M)
    companion = np.zeros((2 * n, 2 * n), dtype=complex)
    companion[0:n, n:] = np.eye(n)
    companion[n:, 0:n] = -M_inv @ section.stiffness_matrix()
    companion[n:, n:] = -M_inv @ section.damping_matrix()
    omega = -1j * np.linalg.eigvals(companion)  # lambda = i omega
    return np.asarray(np.sort_complex(omega[omega.real > 0.0]), dtype=complex)


def frequency_domain(
    section: SectionModel,
    flutter_derivatives: FlutterDerivativeFunction,
    K_range: tuple[float, float] = (0.05, 5.0),
    *,
    n_points: int = 400,
) -> FlutterResult:
    """Classical frequency-domain flutter analysis from flutter-derivative functions (Scanlan).

    For each reduced frequency K the harmonic flutter equation is a quadratic eigenvalue problem in
    the circular frequency; flutter is where a root becomes real (zero damping). K is scanned from
    high to low (wind speed rising) and the crossing refined by Brent's method on K: the classical
    "iteration on K".

    Parameters
    ----------
    section : SectionModel
    flutter_derivatives : callable
        ``f(K) -> dict`` of ``H1..H4, A1..A4`` arrays (all 18 ``H1..P6`` for a section with
        sway) at an array of reduced frequencies (for example
        :func:`ident.model.flat_plate.flutter_derivatives`,
        :meth:`RationalFunctionModel.flutter_derivatives` or a table's
        :meth:`ident.tables.fd_table.FlutterDerivativeTable.interpolator`).
    K_range : (float, float)
        Reduced frequencies searched, low and high, > 0.
    n_points : int
        Grid points in K (log-spaced).

    Returns
    -------
    FlutterResult
        ``U`` holds the wind speed of each grid point per branch averaged (for plots only);
        ``divergence_speed`` is not computed by this method (None).

    References
    ----------
    R. H. Scanlan and J. J. Tomko, "Airfoil and bridge deck flutter derivatives", Journal of the
    Engineering Mechanics Division 97 (1971).
    """
    K_lo, K_hi = (v.positive("K_range", k) for k in K_range)
    if not K_lo < K_hi:
        raise ValueError(f"K_range must be increasing, got {K_range!r}")
    n_points = v.grid_size(n_points)
    K = np.geomspace(K_hi, K_lo, n_points)  # wind speed rises as K falls

    n = section.n_dof

    def roots(k: float) -> npt.NDArray[np.complex128]:
        omega = _frequency_roots(section, flutter_derivatives, k)
        if omega.size != n:
            raise LostModeError(f"expected {n} oscillatory roots at K = {k:.4g}, found "
                                f"{omega.size}")
        return omega

    branches = np.empty((n_points, n), dtype=complex)
    branches[0] = roots(K[0])
    for i in range(1, n_points):
        cost = np.abs(branches[i - 1][:, None] - roots(K[i])[None, :])
        _, cols = linear_sum_assignment(cost)
        branches[i] = roots(K[i])[cols]
    # At the highest K (lowest wind speed) each root sits near one structural frequency.
    order = _frequency_domain_names(section, branches[0])
    branches = branches[:, order]

    candidates: list[tuple[float, float, str, bool]] = []
    # A branch already growing at the highest K (lowest wind speed): the search starts inside
    # flutter, and no crossing would ever be seen. Its speed there bounds flutter from above.
    at_start = [j for j in range(n) if branches[0, j].imag <= 0.0]
    for j in at_start:
        omega_0 = branches[0, j]
        candidates.append((section.B * omega_0.real / K[0], omega_0.real / (2 * math.pi),
                           MODE_NAMES[j], True))
    for j in range(n):
        growth = branches[:, j].imag
        flips = np.flatnonzero((growth[:-1] > 0.0) & (growth[1:] <= 0.0))
        for i in (int(x) for x in flips):

            def damping(k: float, i: int = i, j: int = j) -> float:
                omega = roots(k)
                return float(omega[np.argmin(np.abs(omega - branches[i, j]))].imag)

            K_f = float(brentq(damping, K[i + 1], K[i], xtol=1e-14, rtol=1e-12))
            omega_f = roots(K_f)
            omega_f = omega_f[np.argmin(np.abs(omega_f - branches[i, j]))]
            U_f = section.B * omega_f.real / K_f
            candidates.append((U_f, omega_f.real / (2 * math.pi), MODE_NAMES[j], False))
    U_grid = section.B * branches.real / K[:, None]
    U_max = float(U_grid.max())
    speed = frequency = None
    critical = None
    starts_unstable = False
    if candidates:
        speed, frequency, critical, starts_unstable = min(candidates)
    return FlutterResult(
        speed=speed,
        frequency=frequency,
        critical_mode=critical,
        U_max=U_max,
        U=U_grid.mean(axis=1),
        frequencies=branches.real / (2 * math.pi),
        damping=branches.imag / np.abs(branches),
        mode_names=MODE_NAMES[:n],
        method="frequency-domain",
        reduced_frequency=_reduced_frequency(section, speed, frequency),
        unstable_at_start=starts_unstable,
    )


def _frequency_domain_names(
    section: SectionModel, omega: npt.NDArray[np.complex128]
) -> list[int]:
    """Order the roots at the highest K (near still air) (heave, pitch(, sway)) by frequency."""
    structural = np.array([section.omega_h, section.omega_a, section.omega_p or 0.0]
                          [: section.n_dof])
    _, cols = linear_sum_assignment(np.abs(structural[:, None] - omega.real[None, :]))
    return [int(c) for c in cols]


def speed_sensitivity(
    section: SectionModel, model: RationalFunctionModel, speed: float, frequency: float
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Gradient of the flutter speed with respect to the RFCs and lag roots.

    At flutter the critical eigenvalue crosses the imaginary axis; to first order a parameter change
    ``dp`` moves its real part by ``Re(w^H dS/dp v) / (w^H v)`` (left and right eigenvectors ``w``,
    ``v`` of the state matrix ``S``), and the flutter speed moves by that amount divided by
    ``-dRe(lambda)/dU``. Used to propagate identification uncertainty to the flutter speed.

    Parameters
    ----------
    section, model :
        As for :func:`analyze`.
    speed, frequency : float
        Flutter speed (m/s) and frequency (Hz) from :func:`analyze`.

    Returns
    -------
    dU_dA : ndarray, shape (3 + m, n_dof, n_dof)
        m/s per unit change of each coefficient.
    dU_dd : ndarray, shape (m,)
        m/s per unit change of each lag root.
    """

    def state(m: RationalFunctionModel, u: float) -> npt.NDArray[np.float64]:
        return AeroelasticSystem(section, m, u).matrix()

    S = state(model, speed)
    lam, w, v = eig(S, left=True, right=True)
    k = int(np.argmin(np.abs(lam - 2j * math.pi * frequency)))
    w_k, v_k = w[:, k], v[:, k]
    norm = w_k.conj() @ v_k

    def d_real(dS: npt.NDArray[np.float64]) -> float:
        return float((w_k.conj() @ dS @ v_k / norm).real)

    h_U = 1e-6 * speed
    slope = d_real((state(model, speed + h_U) - state(model, speed - h_U)) / (2 * h_U))
    if slope <= 0.0:
        raise ValueError("the critical eigenvalue does not cross into the right half plane here")
    dU_dA = np.zeros_like(model.A)
    for idx in np.ndindex(*model.A.shape):
        h = 1e-6 * max(1.0, abs(float(model.A[idx])))
        A_plus, A_minus = model.A.copy(), model.A.copy()
        A_plus[idx] += h
        A_minus[idx] -= h
        dS = (state(RationalFunctionModel(A_plus, model.d), speed)
              - state(RationalFunctionModel(A_minus, model.d), speed)) / (2 * h)
        dU_dA[idx] = -d_real(dS) / slope
    dU_dd = np.zeros(model.n_lags)
    for l in range(model.n_lags):
        h = 1e-6 * model.d[l]
        d_plus, d_minus = model.d.copy(), model.d.copy()
        d_plus[l] += h
        d_minus[l] -= h
        dS = (state(RationalFunctionModel(model.A, d_plus), speed)
              - state(RationalFunctionModel(model.A, d_minus), speed)) / (2 * h)
        dU_dd[l] = -d_real(dS) / slope
    return dU_dA, dU_dd
