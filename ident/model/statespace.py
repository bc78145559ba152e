"""The linear state-space equations of motion of a section model in the wind.

With the Roger model of the self-excited forces, the aeroelastic equations of motion become a
linear, frequency-independent state-space model whose matrix depends explicitly on the wind speed U
(``docs/reference/conventions.md``, "In the time domain"). The state is ``z = [q, q', x_1, ...,
x_m]`` with ``q = [h/B, alpha]`` (or ``[h/B, alpha, p/B]`` with sway: n = 3 degrees of freedom) and
one n-vector of lag states per lag root, ``x_l' = q' - (U/B) d_l x_l``; a model released from rest
has ``x_l = 0`` at the release. The self-excited generalised force is::

    f = [L B, M(, D B)]
      = rho/2 [U^2 B^2 A1 q + U B^3 A2 q' + B^4 A3 q'' + U^2 B^2 sum_l A_{l+3} x_l]

written with U factored out so that U = 0 (still air, added mass only) is not a special case.
This module builds the matrices; :mod:`ident.model.flutter` analyses them and
:mod:`ident.simulation.decay` integrates them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.numerics import validate as v

__all__ = ["AeroelasticSystem"]


@dataclass(frozen=True)
class AeroelasticSystem:
    """State-space model ``z' = A z`` of a section model at wind speed ``U``.

    Parameters
    ----------
    section : SectionModel
        Structure (and air density ``section.rho``).
    model : RationalFunctionModel
        Self-excited forces.
    U : float
        Mean wind speed, m/s, >= 0.

    Examples
    --------
    In still air without added mass the eigenvalues are the structural ones.

    >>> import numpy as np
    >>> from ident.model.section import SectionModel
    >>> s = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.0, zeta_a=0.0)
    >>> still = RationalFunctionModel(np.zeros((3, 2, 2)), [])
    >>> lam = AeroelasticSystem(s, still, 0.0).eigenvalues()
    >>> np.round(np.sort(lam.imag[lam.imag > 0]) / (2 * np.pi), 6).tolist()
    [2.0, 4.0]
    """

    section: SectionModel
    model: RationalFunctionModel
    U: float

    def __post_init__(self) -> None:
        U = v.finite("U", self.U)
        if U < 0.0:
            raise ValueError(f"U must be >= 0, got {U!r}")
        object.__setattr__(self, "U", U)
        if self.model.n_dof > self.section.n_dof:
            # A 2-DOF section feels the heave-pitch block of a 3-DOF model: sway is held.
            object.__setattr__(self, "model", self.model.planar())
        elif self.model.n_dof < self.section.n_dof:
            raise ValueError(
                "the section has a lateral spring (3 degrees of freedom) but the aerodynamic model "
                "has no sway or drag terms: give a 3-DOF model (e.g. model.with_sway("
                "ident.model.quasi_steady.quasi_steady_model(static)))")

    @property
    def n_dof(self) -> int:
        """Degrees of freedom n: 2 or 3."""
        return self.section.n_dof

    @property
    def n_states(self) -> int:
        """Number of states, ``2 n + n m``."""
        return self.n_dof * (2 + self.model.n_lags)

    def effective_mass(self) -> npt.NDArray[np.float64]:
        """Structural plus aerodynamic (added) mass ``Ms - rho/2 B^4 A3``, shape (n, n)."""
        s = self.section
        return s.mass_matrix() - 0.5 * s.rho * s.B**4 * self.model.A[2]

    def _aero_terms(self) -> tuple[npt.NDArray[np.float64], ...]:
        """Aerodynamic stiffness, damping and lag-state gains (each n x n) at this U."""
        s, A, U = self.section, self.model.A, self.U
        stiffness = 0.5 * s.rho * U**2 * s.B**2 * A[0]
        damping = 0.5 * s.rho * U * s.B**3 * A[1]
        lags = tuple(0.5 * s.rho * U**2 * s.B**2 * A[3 + l] for l in range(self.model.n_lags))
        return (stiffness, damping, *lags)

    def matrix(self) -> npt.NDArray[np.float64]:
        """Return the state matrix ``A(U)``, shape (n, n), 1/s."""
        s, k = self.section, self.n_dof
        q, qd = slice(0, k), slice(k, 2 * k)
        stiffness, damping, *lag_gains = self._aero_terms()
        M_inv = np.linalg.inv(self.effective_mass())
        A = np.zeros((self.n_states, self.n_states))
        A[q, qd] = np.eye(k)
        A[qd, q] = M_inv @ (stiffness - s.stiffness_matrix())
        A[qd, qd] = M_inv @ (damping - s.damping_matrix())
        for l, gain in enumerate(lag_gains):  # noqa: E741 - lag index
            rows = slice((2 + l) * k, (3 + l) * k)
            A[qd, rows] = M_inv @ gain
            A[rows, qd] = np.eye(k)
            A[rows, rows] = -(self.U / s.B) * self.model.d[l] * np.eye(k)
        return A

    def force_matrix(self, state_matrix: npt.NDArray[np.float64] | None = None
                     ) -> npt.NDArray[np.float64]:
        """Output matrix ``F`` with ``f = F z`` (``[L B, M]``, with sway ``[L B, M, D B]``).

        Shape (n, n_states). The added-mass term needs ``q''``, which is itself linear in the
        state (the rows of ``q''`` in ``A z``). ``state_matrix``: this system's :meth:`matrix`
        when the caller has it already (a fit builds both for every parameter it perturbs).
        """
        s, k = self.section, self.n_dof
        stiffness, damping, *lag_gains = self._aero_terms()
        F = np.zeros((k, self.n_states))
        F[:, 0:k] = stiffness
        F[:, k : 2 * k] = damping
        for l, gain in enumerate(lag_gains):  # noqa: E741 - lag index
            F[:, (2 + l) * k : (3 + l) * k] = gain
        added_mass = 0.5 * s.rho * s.B**4 * self.model.A[2]
        if state_matrix is None:
            A = self.matrix()
        else:
            A = np.asarray(state_matrix, dtype=float)
            if A.shape != (self.n_states, self.n_states):
                raise ValueError(f"state_matrix must be this system's matrix(), shape "
                                 f"{(self.n_states, self.n_states)}, got {A.shape}")
        return F + added_mass @ A[k : 2 * k, :]

    def forces(
        self, z: npt.NDArray[np.float64], qdd: npt.NDArray[np.float64]
    ) -> npt.NDArray[np.float64]:
        """Self-excited generalised forces ``[L B, M(, D B)]`` for states and accelerations.

        Use this instead of :meth:`force_matrix` when the accelerations are not those of the linear
        system (a structure with nonlinear springs or friction still feels the same air).

        Parameters
        ----------
        z : ndarray, shape (..., n)
            States.
        qdd : ndarray, shape (..., n)
            Accelerations ``q''``, 1/s^2 (first entry ``h''/B``).

        Returns
        -------
        ndarray, shape (..., n)
            ``[L B, M(, D B)]``, N m/m.
        """
        s, k = self.section, self.n_dof
        stiffness, damping, *lag_gains = self._aero_terms()
        f = z[..., 0:k] @ stiffness.T + z[..., k : 2 * k] @ damping.T
        for l, gain in enumerate(lag_gains):  # noqa: E741 - lag index
            f = f + z[..., (2 + l) * k : (3 + l) * k] @ gain.T
        return np.asarray(f + qdd @ (0.5 * s.rho * s.B**4 * self.model.A[2]).T, dtype=float)

    def initial_state(self, h0: float, alpha0: float, p0: float = 0.0) -> npt.NDArray[np.float64]:
        """Return the state at a release from rest at ``h0`` (m), ``alpha0`` (rad), ``p0`` (m).

        ``p0`` must be 0 for a 2-DOF section (it has no sway).
        """
        z0 = np.zeros(self.n_states)
        z0[0] = v.finite("h0", h0) / self.section.B
        z0[1] = v.finite("alpha0", alpha0)
        p0 = v.finite("p0", p0)
        if self.n_dof == 3:
            z0[2] = p0 / self.section.B
        elif p0 != 0.0:
            raise ValueError(f"p0 must be 0 for a section without sway, got {p0!r}")
        return z0

    def eigenvalues(self) -> npt.NDArray[np.complex128]:
        """Eigenvalues of ``A(U)``, 1/s."""
        return np.asarray(np.linalg.eigvals(self.matrix()), dtype=complex)
