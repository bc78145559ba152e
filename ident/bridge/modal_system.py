"""The bridge in modal coordinates with strip-theory self-excited forces: what buffeting needs.

Modal coordinates ``xi`` (one per still-air mode); at a deck node the section coordinates are
``q(x) = Phi(x) xi`` with the generalised shapes ``Phi = [h/B, alpha, p/B]`` (3 x n_modes, shapes
h and p in m, alpha in rad per unit modal coordinate). Strip theory: the section's self-excited
forces ``f = [L B, M, D B] = qd B^2 Q(p) q`` act per unit span at every node, and their virtual
work ``h L + alpha M + p D = Phi^T f`` integrated along the deck (trapezoid weights ``w_k``)
projects Roger's form term by term::

    Abar_j = sum_k w_k Phi_k^T A_j Phi_k           (n_modes x n_modes, j = 1 .. 3 + m)

so the modal equations are those of a section with ``Ms, Cs, Ks`` replaced by the modal mass,
damping and stiffness (``diag(m_i)``, ``diag(2 m_i zeta_i w_i)``, ``diag(m_i w_i^2)``) and the
lag states ``chi_l`` (one n_modes-vector per lag, ``chi_l' = xi' - (U/B) d_l chi_l``)::

    (M - rho/2 B^4 Abar_3) xi'' = -K xi - C xi' + rho/2 [U^2 B^2 Abar_1 xi + U B^3 Abar_2 xi'
                                  + U^2 B^2 sum_l Abar_{l+3} chi_l] + F_b(t)

with the buffeting modal force ``F_b`` as input. State ``z = [xi, xi', chi_1 .. chi_m]``.

A 2-DOF aerodynamic model (heave and pitch) is padded with zero sway rows and columns: the
sway of the modes then feels the drag buffeting only, no self-excited drag (pass a 3-DOF model,
e.g. ``model.with_sway(quasi_steady_model(static))``, for aerodynamic sway damping).

Not responsible for: reading the bridge file or checking mode shapes (the bridge model module),
flutter (the bridge flutter analysis), the buffeting forces (:mod:`ident.bridge.buffeting`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ident import _validate as v
from ident.rfc import RationalFunctionModel
from ident.turbulence import StaticCoefficients

__all__ = ["ModalSystem", "trapezoid_weights"]

FloatArray = npt.NDArray[np.float64]


def trapezoid_weights(x: Any) -> FloatArray:
    """Strip widths ``w_k`` (m) of the trapezoid rule over increasing nodes ``x`` (m).

    ``sum_k w_k g(x_k)`` integrates ``g`` along the deck; a single node gets width 1 m (a
    section model per unit span).

    Examples
    --------
    >>> trapezoid_weights([0.0, 1.0, 3.0]).tolist()
    [0.5, 1.5, 1.0]
    """
    x_arr = v.finite_array("x", x, ndim=1)
    if x_arr.size == 1:
        return np.ones(1)
    d = np.diff(x_arr)
    if np.any(d <= 0.0):
        raise ValueError("nodes_x must be strictly increasing")
    w = np.zeros_like(x_arr)
    w[:-1] += 0.5 * d
    w[1:] += 0.5 * d
    return w


def _pad3(model: RationalFunctionModel) -> FloatArray:
    if model.n_dof == 3:
        return np.asarray(model.A, dtype=float)
    A = np.zeros((model.A.shape[0], 3, 3))
    A[:, :2, :2] = model.A
    return A


@dataclass(frozen=True, eq=False)
class ModalSystem:
    """Still-air modes of a bridge with the section aerodynamics projected on them.

    Parameters
    ----------
    x : ndarray, shape (nodes,)
        Deck nodes, m, strictly increasing.
    shapes : ndarray, shape (nodes, 3, n_modes)
        Generalised shapes ``[h/B, alpha, p/B]`` at the nodes per unit modal coordinate.
    frequencies, damping, generalised_mass : ndarray, shape (n_modes,)
        Still-air frequencies (Hz, > 0), damping ratios (>= 0) and generalised masses (> 0).
    B, rho : float
        Deck width (m) and air density (kg/m^3).
    model : RationalFunctionModel
        The section's self-excited forces (2 or 3 DOF; 2 is padded, see the module docstring).
    static : StaticCoefficients
        Static coefficients (buffeting).
    """

    x: FloatArray
    shapes: FloatArray
    frequencies: FloatArray
    damping: FloatArray
    generalised_mass: FloatArray
    B: float
    rho: float
    model: RationalFunctionModel
    static: StaticCoefficients
    weights: FloatArray = field(init=False, repr=False)
    aero: FloatArray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        x = v.finite_array("nodes_x", self.x, ndim=1)
        shapes = v.finite_array("shapes", self.shapes, ndim=3)
        if shapes.shape[:2] != (x.size, 3):
            raise ValueError(f"shapes must have shape (nodes, 3, n_modes) with {x.size} nodes, "
                             f"got {shapes.shape}")
        n = shapes.shape[2]
        for name in ("frequencies", "generalised_mass"):
            arr = v.positive_array(name, getattr(self, name), ndim=1)
            if arr.size != n:
                raise ValueError(f"{name} must have one value per mode ({n}), got {arr.size}")
            object.__setattr__(self, name, arr)
        zeta = v.finite_array("damping", self.damping, ndim=1)
        if zeta.size != n or np.any(zeta < 0.0):
            raise ValueError(f"damping must be {n} ratios >= 0, got {zeta.tolist()}")
        object.__setattr__(self, "damping", zeta)
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "shapes", shapes)
        object.__setattr__(self, "B", v.positive("B", self.B))
        object.__setattr__(self, "rho", v.positive("rho", self.rho))
        w = trapezoid_weights(x)
        object.__setattr__(self, "weights", w)
        object.__setattr__(self, "aero", np.einsum("k,kai,jab,kbl->jil", w, shapes,
                                                   _pad3(self.model), shapes))

    @classmethod
    def from_modes(cls, *, x: Any, h: Any, alpha: Any, p: Any | None, frequencies: Any,
                   damping: Any, generalised_mass: Any, B: float, rho: float,
                   model: RationalFunctionModel, static: StaticCoefficients) -> ModalSystem:
        """Build from physical shapes ``h, alpha, p`` of shape (n_modes, nodes) (m, rad, m)."""
        B = v.positive("B", B)
        h_arr = np.atleast_2d(np.asarray(h, dtype=float))
        a_arr = np.atleast_2d(np.asarray(alpha, dtype=float))
        p_arr = np.zeros_like(h_arr) if p is None else np.atleast_2d(np.asarray(p, dtype=float))
        if not h_arr.shape == a_arr.shape == p_arr.shape:
            raise ValueError(f"h, alpha and p must have one shape (n_modes, nodes), got "
                             f"{h_arr.shape}, {a_arr.shape}, {p_arr.shape}")
        shapes = np.stack([h_arr / B, a_arr, p_arr / B], axis=1)  # (n, 3, nodes)
        return cls(x=np.asarray(x, dtype=float), shapes=np.transpose(shapes, (2, 1, 0)),
                   frequencies=np.atleast_1d(np.asarray(frequencies, dtype=float)),
                   damping=np.atleast_1d(np.asarray(damping, dtype=float)),
                   generalised_mass=np.atleast_1d(np.asarray(generalised_mass, dtype=float)),
                   B=B, rho=rho, model=model, static=static)

    @property
    def n_modes(self) -> int:
        """Number of modes."""
        return int(self.shapes.shape[2])

    @property
    def n_states(self) -> int:
        """Number of states, ``n_modes (2 + lags)``."""
        return self.n_modes * (2 + self.model.n_lags)

    def physical_shapes(self) -> FloatArray:
        """Shapes ``[h, alpha, p]`` (m, rad, m per unit modal coordinate), shape (nodes, 3, n)."""
        return self.shapes * np.array([self.B, 1.0, self.B])[None, :, None]

    def structural(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Modal mass, damping and stiffness matrices (diagonal), each (n, n)."""
        w = 2.0 * np.pi * self.frequencies
        m = self.generalised_mass
        return np.diag(m), np.diag(2.0 * m * self.damping * w), np.diag(m * w**2)

    def impedance(self, U: float, f: Any) -> npt.NDArray[np.complex128]:
        """``-omega^2 M + i omega C + K - qd B^2 Qbar(iK)`` at frequencies ``f`` (Hz), (nf, n, n)."""
        U = v.finite("U", U)
        f_arr = np.atleast_1d(np.asarray(f, dtype=float))
        omega = 2.0 * np.pi * f_arr
        M, C, K = self.structural()
        Z = (-omega[:, None, None] ** 2 * M + 1j * omega[:, None, None] * C + K).astype(complex)
        if U <= 0.0:  # still air: only the added mass of the A3 term is left
            return Z + omega[:, None, None] ** 2 * (0.5 * self.rho * self.B**4 * self.aero[2])
        p = 1j * omega * self.B / U
        pp = p[:, None, None]
        Qbar = self.aero[0] + self.aero[1] * pp + self.aero[2] * pp**2
        for l, d_l in enumerate(self.model.d):  # noqa: E741 - lag index
            Qbar = Qbar + self.aero[3 + l] * (pp / (pp + d_l))
        return np.asarray(Z - 0.5 * self.rho * U**2 * self.B**2 * Qbar, dtype=complex)

    def state_space(self, U: float) -> tuple[FloatArray, FloatArray]:
        """State matrix ``A`` (ns, ns) and input matrix ``B_in`` (ns, n) at wind speed ``U``.

        ``z' = A z + B_in F_b`` with ``z = [xi, xi', chi_1 .. chi_m]`` (module docstring).
        """
        U = v.finite("U", U)
        if U < 0.0:
            raise ValueError(f"U must be >= 0, got {U!r}")
        n, m = self.n_modes, self.model.n_lags
        rho, B = self.rho, self.B
        M, C, K = self.structural()
        M_inv = np.linalg.inv(M - 0.5 * rho * B**4 * self.aero[2])
        A = np.zeros((self.n_states, self.n_states))
        A[:n, n:2 * n] = np.eye(n)
        A[n:2 * n, :n] = M_inv @ (0.5 * rho * U**2 * B**2 * self.aero[0] - K)
        A[n:2 * n, n:2 * n] = M_inv @ (0.5 * rho * U * B**3 * self.aero[1] - C)
        for l in range(m):  # noqa: E741 - lag index
            rows = slice((2 + l) * n, (3 + l) * n)
            A[n:2 * n, rows] = M_inv @ (0.5 * rho * U**2 * B**2 * self.aero[3 + l])
            A[rows, n:2 * n] = np.eye(n)
            A[rows, rows] = -(U / B) * self.model.d[l] * np.eye(n)
        B_in = np.zeros((self.n_states, n))
        B_in[n:2 * n] = M_inv
        return A, B_in

    def eigenvalues(self, U: float) -> npt.NDArray[np.complex128]:
        """Eigenvalues of the state matrix at ``U``, 1/s."""
        return np.asarray(np.linalg.eigvals(self.state_space(U)[0]), dtype=complex)
