"""Multimode flutter of a bridge: state space (no iteration) and frequency domain (its check).

**State space** (:func:`analyze`). The matrix ``S(U)`` of :class:`~ident.bridge.statespace.
BridgeStateSpace` depends explicitly on U. The growth ``g(U)``, the largest real part of an
oscillatory eigenvalue, is evaluated on a grid of wind speeds from still air; the first grid
interval where it turns positive brackets the flutter speed, which Brent's method then finds to
machine precision (a root of ``g``: no iteration on a reduced frequency). The same grid gives
every mode's in-wind frequency and damping against U (each branch followed from its still-air
mode to the nearest eigenvalue); :func:`in_wind_modes` gives them at any wind speeds asked
for. The flutter mode's eigenvector tells the participating modes: the share of each mode in
its strain energy ``M_r omega_r^2 |eta_r|^2``.

**Frequency domain** (:func:`frequency_domain`), the classical multimode analysis from flutter
derivatives (Jain, Jones and Scanlan 1996): at a reduced frequency K, harmonic motion
``eta e^{i omega t}`` with ``U = B omega / K`` obeys the quadratic eigenvalue problem::

    [-omega^2 (Ms + rho/2 B^4 Q_modal(iK) / K^2) + i omega Cs + Ks] eta = 0

with ``Q_modal`` the section's ``Q(iK)`` (from the derivatives) projected on the modes. K is
scanned from high to low (wind rising); each branch is followed from its still-air mode; flutter
is where a branch's root becomes real (zero damping), refined by Brent's method on K.

Both run with single-threaded BLAS (:mod:`ident.numerics.threads`): the matrices are small enough
that a thread pool costs more than it saves (eigenvalues of 200 states: 22 ms on one thread, 155 ms
on two of the shared two-core reference machine).

Not responsible for: the bridge's data (:mod:`ident.bridge.model`), the state matrix
(:mod:`ident.bridge.statespace`), where the aerodynamics come from (:mod:`ident.bridge.aero`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.optimize import brentq, linear_sum_assignment

from ident.bridge.model import BridgeModel
from ident.bridge.statespace import BridgeStateSpace
from ident.model.conventions import Q_from_flutter_derivatives
from ident.model.flutter import LostModeError
from ident.model.rfc import RationalFunctionModel
from ident.numerics import validate as v
from ident.numerics.threads import single_threaded_blas

__all__ = [
    "BridgeFlutterResult", "analyze", "default_U_max", "frequency_domain", "in_wind_modes",
]

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]
FlutterDerivativeFunction = Callable[[FloatArray], dict[str, Any]]

#: Reduced frequency of the lowest torsional mode at the default top wind speed (a reduced
#: velocity of about 31, beyond the flutter point of any practical deck).
_K_MIN_DEFAULT = 0.2
#: An eigenvalue is oscillatory when its imaginary part exceeds this fraction of its modulus.
_OSCILLATORY_RTOL = 1e-9
#: Real part, relative to |lambda|, that counts as growth: keeps round-off of an undamped
#: structure in still air (~1e-16 |lambda|) from counting as instability; it moves a flutter
#: speed by ~1e-11 relative.
_GROWTH_RTOL = 1e-12
#: Share of the strain energy above which a mode is listed as participating.
PARTICIPATION_THRESHOLD = 0.01


@dataclass(frozen=True, eq=False)
class BridgeFlutterResult:
    """Outcome of a multimode flutter analysis.

    Attributes
    ----------
    speed, frequency, reduced_frequency : float or None
        Flutter speed (m/s), frequency (Hz) and ``K_F = B omega_F / U_F``; None without flutter
        below ``U_max``.
    critical_mode : int or None
        Index of the still-air mode whose branch goes unstable.
    participation : ndarray, shape (n_modes,), or None
        Share of each mode in the flutter mode's strain energy (sums to 1).
    U_max : float
        Top of the searched range, m/s.
    U : ndarray, shape (n_points,) or (n_points, n_modes)
        Wind speeds of the mode curves, m/s (per branch in the frequency domain, where every
        branch has its own U at a reduced frequency).
    frequencies, damping : ndarray, shape (n_points, n_modes)
        In-wind frequency (Hz) and damping ratio of each mode's branch.
    mode_labels : tuple of str
        One label per mode (column).
    method : str
        ``"state-space"`` or ``"frequency-domain"``.
    divergence_speed : float or None
        Lowest U at which the aeroelastic stiffness loses positive definiteness (state space).
    unstable_at_start : bool
        The frequency domain only: a branch already grows at the highest K scanned (the lowest
        wind speed); ``speed`` is that branch's wind speed there, flutter lies at or below it.
    certification : str or None
        The fast route only (:mod:`ident.bridge.fast_flutter`): which branches were followed
        and what the dense check certified (or why none was made).
    """

    speed: float | None
    frequency: float | None
    reduced_frequency: float | None
    critical_mode: int | None
    participation: FloatArray | None = field(repr=False)
    U_max: float
    U: FloatArray = field(repr=False)
    frequencies: FloatArray = field(repr=False)
    damping: FloatArray = field(repr=False)
    mode_labels: tuple[str, ...] = field(repr=False)
    method: str = "state-space"
    divergence_speed: float | None = None
    unstable_at_start: bool = False
    certification: str | None = None

    @property
    def found(self) -> bool:
        """True when flutter occurs below ``U_max``."""
        return self.speed is not None

    def participating(self, threshold: float = PARTICIPATION_THRESHOLD
                      ) -> list[tuple[str, float]]:
        """Return ``(label, share)`` of the modes above ``threshold``, the largest first."""
        if self.participation is None:
            return []
        order = np.argsort(self.participation)[::-1]
        return [(self.mode_labels[r], float(self.participation[r])) for r in order
                if self.participation[r] >= threshold]

    def summary(self) -> str:
        """One plain-language line."""
        if self.speed is None or self.frequency is None or self.critical_mode is None:
            text = f"no flutter below U_max = {self.U_max:.4g} m/s ({self.method})"
        else:
            shares = ", ".join(f"{label.split(' (')[0]} {100 * share:.0f} %"
                               for label, share in self.participating(0.05))
            text = (f"flutter at U = {self.speed:.4g} m/s, f = {self.frequency:.4g} Hz, "
                    f"branch of {self.mode_labels[self.critical_mode]}; participating: {shares} "
                    f"({self.method})")
        if self.divergence_speed is not None:
            text += f"; torsional divergence at U = {self.divergence_speed:.4g} m/s"
        return text

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-ready dict (curves included; ``certification`` from the fast route)."""
        extra = {} if self.certification is None else {"certification": self.certification}
        return extra | {
            "method": self.method, "flutter_speed": self.speed,
            "flutter_frequency": self.frequency, "reduced_frequency": self.reduced_frequency,
            "critical_mode": None if self.critical_mode is None
            else self.mode_labels[self.critical_mode],
            "participation": [{"mode": label, "share": share}
                              for label, share in self.participating()],
            "divergence_speed": self.divergence_speed, "U_max": self.U_max,
            "mode_labels": list(self.mode_labels), "U": _json_curve(self.U),
            "frequencies": _json_curve(self.frequencies), "damping": _json_curve(self.damping),
        }


def _json_curve(values: FloatArray) -> list[Any]:
    """Nested lists for JSON, ``null`` where a curve has no value (NaN is no JSON)."""
    out = np.asarray(values, dtype=float).astype(object)
    out[np.isnan(values)] = None
    return list(out.tolist())


def default_U_max(bridge: BridgeModel) -> float:
    """Default top wind speed of a search, m/s.

    It brings the lowest torsional mode (the highest mode if none is torsional) to a reduced
    frequency of 0.2, a reduced velocity ``U / (f B)`` of about 31: beyond the flutter point of
    any practical deck.
    """
    kinds = bridge.mode_kinds()
    torsional = [m.frequency for m, k in zip(bridge.modes, kinds, strict=True) if k == "torsional"]
    f = min(torsional) if torsional else float(bridge.frequencies.max())
    return 2.0 * math.pi * f * bridge.B / _K_MIN_DEFAULT


def _is_oscillatory(lam: ComplexArray, floor: float) -> npt.NDArray[np.bool_]:
    """Eigenvalues with an imaginary part above round-off: relative, and ``floor`` (rad/s).

    The floor keeps the lag states' eigenvalues, which are zero in still air, from counting as
    oscillatory when round-off gives them an imaginary part of ~1e-17.
    """
    return np.asarray(lam.imag > np.maximum(_OSCILLATORY_RTOL * np.abs(lam), floor))


def _floor(bridge: BridgeModel) -> float:
    return 1e-6 * 2.0 * math.pi * float(bridge.frequencies.min())


def _growth(lam: ComplexArray, floor: float) -> float:
    """Largest real part of an oscillatory eigenvalue, less the round-off allowance, 1/s."""
    osc = lam[_is_oscillatory(lam, floor)]
    if osc.size == 0:
        return -math.inf
    return float(np.max(osc.real - _GROWTH_RTOL * np.abs(osc)))


def _strain_energy_shares(bridge: BridgeModel, eta: ComplexArray) -> FloatArray:
    energy = np.diag(bridge.stiffness_matrix()) * np.abs(eta) ** 2
    return np.asarray(energy / energy.sum(), dtype=float)


def _still_air_branches(bridge: BridgeModel, ss: BridgeStateSpace) -> ComplexArray:
    """Return the oscillatory eigenvalues at U = 0, one per mode (its share of each vector)."""
    lam, vec = ss.eig(0.0)
    n = bridge.n_modes
    idx = np.flatnonzero(_is_oscillatory(lam, _floor(bridge)))
    if idx.size != n:
        raise ValueError(f"expected {n} oscillatory still-air modes, found {idx.size}: the "
                         "aerodynamic added mass dominates the structure")
    shares = np.array([_strain_energy_shares(bridge, vec[:n, k]) for k in idx])  # (eig, mode)
    rows, cols = linear_sum_assignment(-shares.T)  # mode -> eigenvalue, largest share
    out = np.empty(n, dtype=complex)
    out[rows] = lam[idx[cols]]
    return out


def _follow(guess: ComplexArray, lam: ComplexArray) -> ComplexArray:
    """Continue each branch to the nearest eigenvalue of the upper half plane (one-to-one)."""
    candidates = lam[lam.imag >= -_OSCILLATORY_RTOL * np.maximum(1.0, np.abs(lam))]
    rows, cols = linear_sum_assignment(np.abs(guess[:, None] - candidates[None, :]))
    out = np.empty_like(guess)
    out[rows] = candidates[cols]
    return out


@single_threaded_blas
def analyze(bridge: BridgeModel, model: RationalFunctionModel, U_max: float | None = None, *,
            n_points: int = 120) -> BridgeFlutterResult:
    """State-space multimode flutter analysis: bracket the growth's sign change, then Brent.

    Parameters
    ----------
    bridge : BridgeModel
    model : RationalFunctionModel
        The deck section's self-excited forces (2 or 3 degrees of freedom).
    U_max : float, optional
        Top of the search, m/s; default :func:`default_U_max`.
    n_points : int
        Wind speeds of the grid (>= 20). It must resolve the mode curves: a mode that went
        unstable and stable again between two grid points would be missed; 120 points on the
        default range are 2.2 m/s apart for a deck of B = 31 m and a torsional mode of 0.28 Hz.

    Returns
    -------
    BridgeFlutterResult

    Examples
    --------
    Two uniform modes (heave, pitch) on a 1 m deck are the 2-DOF section (here the flat plate
    with Jones's function):

    >>> from ident.model import flat_plate
    >>> bridge = BridgeModel.from_dict({"B": 0.3, "rho": 1.225, "nodes_x": [0.0, 1.0],
    ...     "modes": [{"frequency": 2.0, "damping": 0.005, "generalised_mass": 3.0,
    ...                "h": [1.0, 1.0]},
    ...               {"frequency": 4.0, "damping": 0.005, "generalised_mass": 0.03,
    ...                "alpha": [1.0, 1.0]}]})
    >>> round(analyze(bridge, flat_plate.jones_model()).speed, 2)
    11.75
    """
    ss = BridgeStateSpace(bridge, model)
    U_max = default_U_max(bridge) if U_max is None else v.positive("U_max", U_max)
    n_points = v.grid_size(n_points)
    U = np.linspace(0.0, U_max, n_points)
    n = bridge.n_modes
    branches = np.empty((n_points, n), dtype=complex)
    growth = np.empty(n_points)
    branches[0] = _still_air_branches(bridge, ss)
    floor = _floor(bridge)
    growth[0] = _growth(ss.eigenvalues(0.0), floor)
    for i in range(1, n_points):
        lam = ss.eigenvalues(float(U[i]))
        growth[i] = _growth(lam, floor)
        # Linear extrapolation of each branch tells crossing branches apart.
        guess = branches[i - 1] if i == 1 else 2 * branches[i - 1] - branches[i - 2]
        branches[i] = _follow(guess, lam)

    speed = frequency = None
    critical: int | None = None
    participation = None
    unstable = np.flatnonzero(growth[1:] > 0.0)
    if unstable.size:
        i = int(unstable[0]) + 1
        speed = float(brentq(lambda u: _growth(ss.eigenvalues(u), floor), U[i - 1], U[i],
                             xtol=1e-12 * U_max, rtol=1e-12))
        lam, vec = ss.eig(speed)
        osc = np.flatnonzero(_is_oscillatory(lam, floor))
        k = int(osc[np.argmax(lam[osc].real - _GROWTH_RTOL * np.abs(lam[osc]))])
        frequency = float(lam[k].imag / (2.0 * math.pi))
        participation = _strain_energy_shares(bridge, vec[:n, k])
        # The branch that went unstable: the one nearest the flutter eigenvalue on the grid.
        critical = int(np.argmin(np.abs(branches[i] - lam[k]) + np.abs(branches[i - 1] - lam[k])))

    return BridgeFlutterResult(
        speed=speed, frequency=frequency,
        reduced_frequency=_reduced_frequency(bridge, speed, frequency),
        critical_mode=critical, participation=participation, U_max=U_max, U=U,
        frequencies=branches.imag / (2.0 * math.pi),
        damping=-branches.real / np.abs(branches),
        mode_labels=tuple(bridge.mode_labels()), method="state-space",
        divergence_speed=_divergence_speed(bridge, ss, U),
    )


def _reduced_frequency(bridge: BridgeModel, speed: float | None,
                       frequency: float | None) -> float | None:
    if speed is None or frequency is None:
        return None
    return 2.0 * math.pi * frequency * bridge.B / speed


def _divergence_speed(bridge: BridgeModel, ss: BridgeStateSpace, U: FloatArray) -> float | None:
    """Lowest U where ``det(Ks - rho/2 U^2 B^2 A1m)`` changes sign (refined), m/s.

    A real eigenvalue of the aeroelastic stiffness crossing zero (a static deflection shape that
    needs no load: divergence) flips the determinant's sign.
    """
    Ks = bridge.stiffness_matrix()
    A1 = 0.5 * bridge.rho * bridge.B**2 * ss.modal_A[0]
    scale = np.sqrt(np.diag(Ks))

    def sign(u: float) -> float:
        # Scaled by the still-air stiffness, so that the determinant neither over- nor
        # underflows with many modes; only its sign matters.
        return float(np.linalg.slogdet((Ks - u**2 * A1) / np.outer(scale, scale))[0])

    def det(u: float) -> float:
        return float(np.linalg.det((Ks - u**2 * A1) / np.outer(scale, scale)))

    values = np.array([sign(float(u)) for u in U])
    flips = np.flatnonzero(values[1:] != values[:-1])
    if flips.size == 0:
        return None
    i = int(flips[0])
    return float(brentq(det, U[i], U[i + 1], xtol=1e-12 * U[-1]))


def _frequency_roots(bridge: BridgeModel, fd: FlutterDerivativeFunction, K: float,
                     vectors: bool = False) -> tuple[ComplexArray, ComplexArray | None]:
    """Circular frequencies (Re > 0; growth is Im < 0) of harmonic motion at reduced freq. K."""
    n = bridge.n_modes
    Q = Q_from_flutter_derivatives(np.array([K]), fd(np.array([K])))[0]
    Qm = bridge.modal_coefficients(Q)
    M = bridge.mass_matrix() + 0.5 * bridge.rho * bridge.B**4 * Qm / K**2
    M_inv = np.linalg.inv(M)
    companion = np.zeros((2 * n, 2 * n), dtype=complex)
    companion[0:n, n:] = np.eye(n)
    companion[n:, 0:n] = -M_inv @ bridge.stiffness_matrix()
    companion[n:, n:] = -M_inv @ bridge.damping_matrix()
    if vectors:
        lam, vec = np.linalg.eig(companion)
    else:
        lam, vec = np.linalg.eigvals(companion), None
    omega = -1j * lam  # lambda = i omega
    keep = omega.real > 0.0
    if int(keep.sum()) != n:
        raise LostModeError(f"expected {n} oscillatory roots at K = {K:.4g}, found "
                            f"{int(keep.sum())}")
    return (np.asarray(omega[keep], dtype=complex),
            None if vec is None else np.asarray(vec[:n, keep], dtype=complex))


@single_threaded_blas
def frequency_domain(bridge: BridgeModel, flutter_derivatives: FlutterDerivativeFunction,
                     K_range: tuple[float, float] | None = None, *, U_max: float | None = None,
                     n_points: int = 400) -> BridgeFlutterResult:
    """Multimode frequency-domain flutter analysis from flutter-derivative functions.

    Parameters
    ----------
    bridge : BridgeModel
    flutter_derivatives : callable
        ``f(K) -> dict`` of the 8 (heave, pitch) or 18 derivatives at an array of K (e.g.
        :meth:`RationalFunctionModel.flutter_derivatives`, :func:`ident.model.flat_plate.
        flutter_derivatives`, a table's interpolator).
    K_range : (float, float), optional
        Reduced frequencies scanned, low and high. Default: from the lowest mode at ``U_max``
        to the highest mode at 5 % of ``U_max``.
    U_max : float, optional
        Only for the default ``K_range`` (default :func:`default_U_max`), m/s.
    n_points : int
        Log-spaced K of the scan (>= 20).

    Returns
    -------
    BridgeFlutterResult
        ``U`` per branch (shape (n_points, n_modes)); ``U_max`` the largest wind speed the scan
        reached; no divergence speed.
    """
    n = bridge.n_modes
    if K_range is None:
        top = default_U_max(bridge) if U_max is None else v.positive("U_max", U_max)
        omega = 2.0 * math.pi * bridge.frequencies
        K_range = (float(omega.min() * bridge.B / top),
                   float(omega.max() * bridge.B / (0.05 * top)))
    K_lo, K_hi = (v.positive("K_range", k) for k in K_range)
    if not K_lo < K_hi:
        raise ValueError(f"K_range must be increasing, got {K_range!r}")
    n_points = v.grid_size(n_points)
    K = np.geomspace(K_hi, K_lo, n_points)  # wind speed rises as K falls

    def roots(k: float) -> ComplexArray:
        return _frequency_roots(bridge, flutter_derivatives, k)[0]

    branches = np.empty((n_points, n), dtype=complex)
    first = roots(float(K[0]))
    # At the highest K (lowest wind) each root sits near one still-air frequency.
    structural = 2.0 * math.pi * bridge.frequencies
    rows, cols = linear_sum_assignment(np.abs(structural[:, None] - first.real[None, :]))
    branches[0, rows] = first[cols]
    for i in range(1, n_points):
        guess = branches[i - 1] if i == 1 else 2 * branches[i - 1] - branches[i - 2]
        omega_i = roots(float(K[i]))
        rows, cols = linear_sum_assignment(np.abs(guess[:, None] - omega_i[None, :]))
        branches[i, rows] = omega_i[cols]

    candidates: list[tuple[float, float, int, float]] = []
    # A branch already growing at the highest K: the scan starts inside flutter (no crossing
    # would be seen); its wind speed there bounds flutter from above.
    at_start = [(bridge.B * branches[0, j].real / K[0], branches[0, j].real / (2 * math.pi), j,
                 float(K[0])) for j in range(n) if branches[0, j].imag <= 0.0]
    for j in range(n):
        growth = branches[:, j].imag
        for i in (int(x) for x in np.flatnonzero((growth[:-1] > 0.0) & (growth[1:] <= 0.0))):

            def on_branch(k: float, i: int = i, j: int = j) -> complex:
                # The root nearest the branch interpolated (in log K) between its two grid
                # points: exactly the branch at both ends, so the bracket holds even where
                # another branch passes close by.
                t = math.log(k / K[i]) / math.log(K[i + 1] / K[i])
                target = branches[i, j] + t * (branches[i + 1, j] - branches[i, j])
                omega_k = roots(k)
                return complex(omega_k[np.argmin(np.abs(omega_k - target))])

            K_f = float(brentq(lambda k: on_branch(k).imag, K[i + 1], K[i], xtol=1e-14,
                               rtol=1e-12))
            omega_f = on_branch(K_f)
            candidates.append((bridge.B * omega_f.real / K_f, omega_f.real / (2 * math.pi), j,
                               K_f))
    U_grid = bridge.B * branches.real / K[:, None]
    speed = frequency = K_flutter = None
    critical = None
    participation = None
    starts_unstable = bool(at_start) and (not candidates or min(at_start) < min(candidates))
    if at_start or candidates:
        speed, frequency, critical, K_flutter = min(at_start + candidates)
        omega_all, vec = _frequency_roots(bridge, flutter_derivatives, K_flutter, vectors=True)
        assert vec is not None
        k = int(np.argmin(np.abs(omega_all.real - 2 * math.pi * frequency)
                          + np.abs(omega_all.imag)))
        participation = _strain_energy_shares(bridge, vec[:, k])
    return BridgeFlutterResult(
        speed=speed, frequency=frequency,
        reduced_frequency=K_flutter, critical_mode=critical, participation=participation,
        U_max=float(U_grid.max()), U=U_grid, frequencies=branches.real / (2 * math.pi),
        damping=branches.imag / np.abs(branches), mode_labels=tuple(bridge.mode_labels()),
        method="frequency-domain", unstable_at_start=starts_unstable,
    )


@single_threaded_blas
def in_wind_modes(bridge: BridgeModel, model: RationalFunctionModel, U: Any, *,
                  max_step: float | None = None) -> tuple[FloatArray, FloatArray]:
    """In-wind frequency and damping ratio of each still-air mode's branch at wind speeds ``U``.

    The modal frequency and damping of each branch at U, from the eigenvalues of the state
    matrix ``S(U)`` (:class:`~ident.bridge.statespace.BridgeStateSpace`): each branch starts at
    its still-air mode (the eigenvalue with the largest share of that mode's strain energy) and
    is followed up in wind speed, in steps of at most ``max_step``, to the nearest eigenvalue
    (one-to-one, extrapolated linearly as in :func:`analyze`), so that branches that come close
    are not swapped.

    Parameters
    ----------
    bridge : BridgeModel
    model : RationalFunctionModel
        The deck section's self-excited forces.
    U : array_like, shape (n,)
        Wind speeds, m/s, >= 0 (any order).
    max_step : float, optional
        Largest step of the continuation, m/s; default 1/200 of :func:`default_U_max` (about
        1.1 m/s for a deck of B = 31 m with a torsional mode of 0.28 Hz).

    Returns
    -------
    frequencies : ndarray, shape (n, n_modes)
        Damped in-wind frequency ``Im(lambda) / 2 pi`` of each mode's branch, Hz.
    damping : ndarray, shape (n, n_modes)
        Its damping ratio ``-Re(lambda) / |lambda|`` (negative: the branch grows).

    Examples
    --------
    Without wind each branch is its mode (the flat plate's added mass lowers the frequency):

    >>> from ident.model import flat_plate
    >>> bridge = BridgeModel.from_dict({"B": 0.3, "rho": 1.225, "nodes_x": [0.0, 1.0],
    ...     "modes": [{"frequency": 2.0, "damping": 0.005, "generalised_mass": 3.0,
    ...                "h": [1.0, 1.0]},
    ...               {"frequency": 4.0, "damping": 0.005, "generalised_mass": 0.03,
    ...                "alpha": [1.0, 1.0]}]})
    >>> f, zeta = in_wind_modes(bridge, flat_plate.jones_model(), [0.0, 5.0])
    >>> bool(f[0, 0] < 2.0 and zeta[1, 0] > zeta[0, 0])  # heave damped by the wind
    True
    """
    U_arr = np.atleast_1d(np.asarray(U, dtype=float))
    if U_arr.ndim != 1 or U_arr.size == 0 or not np.all(np.isfinite(U_arr)) or np.any(U_arr < 0):
        raise ValueError(f"U must be a non-empty 1-D array of finite wind speeds >= 0 m/s, "
                         f"got {U!r}")
    step = (default_U_max(bridge) / 200.0 if max_step is None
            else v.positive("max_step", max_step))
    ss = BridgeStateSpace(bridge, model)
    top = float(U_arr.max())
    grid = np.unique(np.concatenate([np.linspace(0.0, top, int(math.ceil(top / step)) + 1),
                                     U_arr]))
    branches = np.empty((grid.size, bridge.n_modes), dtype=complex)
    branches[0] = _still_air_branches(bridge, ss)
    for i in range(1, grid.size):
        guess = branches[i - 1] if i == 1 else (
            branches[i - 1] + (branches[i - 1] - branches[i - 2])
            * (grid[i] - grid[i - 1]) / (grid[i - 1] - grid[i - 2]))
        branches[i] = _follow(guess, ss.eigenvalues(float(grid[i])))
    at = branches[np.searchsorted(grid, U_arr)]
    return (np.asarray(at.imag / (2.0 * math.pi), dtype=float),
            np.asarray(-at.real / np.abs(at), dtype=float))
