"""The linear state-space equations of motion of a section model in the wind.

With the Roger model of the self-excited forces, the aeroelastic equations of motion become a
linear, frequency-independent state-space model whose matrix depends explicitly on the wind speed U
(``docs/conventions.md``, "In the time domain"). The state is ``z = [q, q', x_1, ..., x_m]`` with
``q = [h/B, alpha]`` and one 2-vector of lag states per lag root, ``x_l' = q' - (U/B) d_l x_l``; a
model released from rest has ``x_l = 0`` at the release. The self-excited generalised force is::

    f = [L B, M] = rho/2 [U^2 B^2 A1 q + U B^3 A2 q' + B^4 A3 q'' + U^2 B^2 sum_l A_{l+3} x_l]

written with U factored out so that U = 0 (still air, added mass only) is not a special case.
This module builds the matrices; :mod:`ident.flutter` analyses them and :mod:`ident.simulate`
integrates them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ident import _validate as v
from ident.rfc import RationalFunctionModel
from ident.section import SectionModel

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
    >>> from ident.section import SectionModel
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

    @property
    def n_states(self) -> int:
        """Number of states, ``4 + 2 m``."""
        return 4 + 2 * self.model.n_lags

    def effective_mass(self) -> npt.NDArray[np.float64]:
        """Structural plus aerodynamic (added) mass ``Ms - rho/2 B^4 A3``, shape (2, 2)."""
        s = self.section
        return s.mass_matrix() - 0.5 * s.rho * s.B**4 * self.model.A[2]

    def _aero_terms(self) -> tuple[npt.NDArray[np.float64], ...]:
        """Aerodynamic stiffness, damping and lag-state gains (each 2 x 2) at this U."""
        s, A, U = self.section, self.model.A, self.U
        stiffness = 0.5 * s.rho * U**2 * s.B**2 * A[0]
        damping = 0.5 * s.rho * U * s.B**3 * A[1]
        lags = tuple(0.5 * s.rho * U**2 * s.B**2 * A[3 + l] for l in range(self.model.n_lags))
        return (stiffness, damping, *lags)

    def matrix(self) -> npt.NDArray[np.float64]:
        """Return the state matrix ``A(U)``, shape (n, n), 1/s."""
        s = self.section
        n = self.n_states
        stiffness, damping, *lag_gains = self._aero_terms()
        M_inv = np.linalg.inv(self.effective_mass())
        A = np.zeros((n, n))
        A[0:2, 2:4] = np.eye(2)
        A[2:4, 0:2] = M_inv @ (stiffness - s.stiffness_matrix())
        A[2:4, 2:4] = M_inv @ (damping - s.damping_matrix())
        for l, gain in enumerate(lag_gains):  # noqa: E741 - lag index
            rows = slice(4 + 2 * l, 6 + 2 * l)
            A[2:4, rows] = M_inv @ gain
            A[rows, 2:4] = np.eye(2)
            A[rows, rows] = -(self.U / s.B) * self.model.d[l] * np.eye(2)
        return A

    def force_matrix(self) -> npt.NDArray[np.float64]:
        """Output matrix ``F`` with ``[L B, M] = F z``, shape (2, n).

        The added-mass term needs ``q''``, which is itself linear in the state
        (rows 2:4 of ``A z``).
        """
        s = self.section
        stiffness, damping, *lag_gains = self._aero_terms()
        F = np.zeros((2, self.n_states))
        F[:, 0:2] = stiffness
        F[:, 2:4] = damping
        for l, gain in enumerate(lag_gains):  # noqa: E741 - lag index
            F[:, 4 + 2 * l : 6 + 2 * l] = gain
        added_mass = 0.5 * s.rho * s.B**4 * self.model.A[2]
        return F + added_mass @ self.matrix()[2:4, :]

    def forces(
        self, z: npt.NDArray[np.float64], qdd: npt.NDArray[np.float64]
    ) -> npt.NDArray[np.float64]:
        """Self-excited generalised forces ``[L B, M]`` for states and accelerations.

        Use this instead of :meth:`force_matrix` when the accelerations are not those of the linear
        system (a structure with nonlinear springs or friction still feels the same air).

        Parameters
        ----------
        z : ndarray, shape (..., n)
            States.
        qdd : ndarray, shape (..., 2)
            Accelerations ``q''``, 1/s^2 (first entry ``h''/B``).

        Returns
        -------
        ndarray, shape (..., 2)
            ``[L B, M]``, N m/m.
        """
        s = self.section
        stiffness, damping, *lag_gains = self._aero_terms()
        f = z[..., 0:2] @ stiffness.T + z[..., 2:4] @ damping.T
        for l, gain in enumerate(lag_gains):  # noqa: E741 - lag index
            f = f + z[..., 4 + 2 * l : 6 + 2 * l] @ gain.T
        return np.asarray(f + qdd @ (0.5 * s.rho * s.B**4 * self.model.A[2]).T, dtype=float)

    def initial_state(self, h0: float, alpha0: float) -> npt.NDArray[np.float64]:
        """State at a release from rest at heave ``h0`` (m) and pitch ``alpha0`` (rad)."""
        z0 = np.zeros(self.n_states)
        z0[0] = v.finite("h0", h0) / self.section.B
        z0[1] = v.finite("alpha0", alpha0)
        return z0

    def eigenvalues(self) -> npt.NDArray[np.complex128]:
        """Eigenvalues of ``A(U)``, 1/s."""
        return np.asarray(np.linalg.eigvals(self.matrix()), dtype=complex)
