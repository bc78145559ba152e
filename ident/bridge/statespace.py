"""The modal state-space model of a bridge in the wind (modal coordinates and modal lag states).

The section's Roger model projected on the modes (:meth:`ident.bridge.model.BridgeModel.
modal_coefficients`) gives the generalised self-excited force::

    F = rho/2 [U^2 B^2 A1m eta + U B^3 A2m eta' + B^4 A3m eta'' + U^2 B^2 sum_l A(l+3)m x_l]

with ``Akm = sum_ij A_k[i, j] G_ij`` (n_modes x n_modes). The lag states can be modal: at a deck
station the section's lag state of lag ``l`` obeys ``x_l(x)' = q(x)' - (U/B) d_l x_l(x)`` with
``q(x) = Phi(x) eta``; the equation is linear and the same at every station, so
``x_l(x) = Phi(x) x_l`` with one modal vector ``x_l`` of size n_modes per lag and
``x_l' = eta' - (U/B) d_l x_l``. The state is ``z = [eta, eta', x_1, ..., x_m]``:
``n_modes (2 + m)`` states, whatever the number of deck nodes (the nodes only enter the
integrals ``G_ij``).

With the modal structure ``Ms eta'' + Cs eta' + Ks eta = F + F_ext`` (``Ms = diag(M_r)``,
``Cs = diag(2 M_r zeta_r omega_r)``, ``Ks = diag(M_r omega_r^2)``) the model is ``z' = S(U) z
+ E F_ext``. The effective mass ``Ms - rho/2 B^4 A3m`` does not depend on U, so
:class:`BridgeStateSpace` inverts it once and :meth:`BridgeStateSpace.matrix` assembles ``S(U)``
by scaling precomputed blocks: the flutter search calls it many times.

Not responsible for: the bridge's data and strip theory (:mod:`ident.bridge.model`), the flutter
analysis (:mod:`ident.bridge.flutter`), buffeting loads (:mod:`ident.bridge.buffeting`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from ident.bridge.model import BridgeModel
from ident.model.rfc import RationalFunctionModel
from ident.numerics import validate as v

__all__ = ["BridgeStateSpace", "system_matrix"]

FloatArray = npt.NDArray[np.float64]


class BridgeStateSpace:
    """The linear state-space model ``z' = S(U) z + E F_ext`` of a bridge in the wind.

    Parameters
    ----------
    bridge : BridgeModel
        Deck nodes, modes and air density.
    model : RationalFunctionModel
        The deck section's self-excited forces (2 or 3 degrees of freedom). A 2-DOF model acts
        on heave and pitch only: the deck's sway feels no air.

    Examples
    --------
    One uniform heave mode on a 1 m deck, no air (rho small, U = 0): the still-air frequency.

    >>> import numpy as np
    >>> from ident.model import flat_plate
    >>> bridge = BridgeModel.from_dict({"B": 1.0, "rho": 1.2, "nodes_x": [0.0, 1.0],
    ...     "modes": [{"frequency": 2.0, "damping": 0.0, "generalised_mass": 1e9,
    ...                "h": [1.0, 1.0]}]})
    >>> lam = BridgeStateSpace(bridge, flat_plate.jones_model()).eigenvalues(0.0)
    >>> round(float(lam.imag.max()) / (2 * np.pi), 6)
    2.0
    """

    def __init__(self, bridge: BridgeModel, model: RationalFunctionModel) -> None:
        self.bridge = bridge
        self.model = model
        n, m = bridge.n_modes, model.n_lags
        self.n_modes = n
        self.n_lags = m
        self.n_states = n * (2 + m)
        B, rho = bridge.B, bridge.rho
        #: Modal Roger coefficients ``A_k,modal``, shape (3 + m, n_modes, n_modes).
        self.modal_A = np.asarray(bridge.modal_coefficients(model.A), dtype=float)
        self.lag_roots = np.asarray(model.d, dtype=float)
        self.mass = bridge.mass_matrix()
        self.effective_mass = self.mass - 0.5 * rho * B**4 * self.modal_A[2]
        M_inv = np.linalg.inv(self.effective_mass)
        self._M_inv = M_inv
        # Blocks of the eta'' rows, each to be scaled by its power of U.
        self._Ks = M_inv @ bridge.stiffness_matrix()
        self._Cs = M_inv @ bridge.damping_matrix()
        self._A1 = 0.5 * rho * B**2 * M_inv @ self.modal_A[0]
        self._A2 = 0.5 * rho * B**3 * M_inv @ self.modal_A[1]
        self._lags = [0.5 * rho * B**2 * M_inv @ self.modal_A[3 + l] for l in range(m)]

    def matrix(self, U: float) -> FloatArray:
        """Return the state matrix ``S(U)``, shape (n_states, n_states), 1/s.

        Parameters
        ----------
        U : float
            Mean wind speed, m/s, >= 0.
        """
        U = v.finite("U", U)
        if U < 0.0:
            raise ValueError(f"U must be >= 0, got {U!r}")
        n, B = self.n_modes, self.bridge.B
        S = np.zeros((self.n_states, self.n_states))
        eye = np.eye(n)
        S[0:n, n:2 * n] = eye
        S[n:2 * n, 0:n] = U**2 * self._A1 - self._Ks
        S[n:2 * n, n:2 * n] = U * self._A2 - self._Cs
        for l, gain in enumerate(self._lags):  # noqa: E741 - lag index of the paper
            rows = slice((2 + l) * n, (3 + l) * n)
            S[n:2 * n, rows] = U**2 * gain
            S[rows, n:2 * n] = eye
            S[rows, rows] = -(U / B) * self.lag_roots[l] * eye
        return S

    def input_matrix(self) -> FloatArray:
        """``E`` with ``z' = S z + E F_ext``: generalised external forces (N per unit ``eta``).

        Shape (n_states, n_modes): the ``eta''`` rows hold the inverse effective mass.
        """
        E = np.zeros((self.n_states, self.n_modes))
        E[self.n_modes:2 * self.n_modes] = self._M_inv
        return E

    def eigenvalues(self, U: float) -> npt.NDArray[np.complex128]:
        """Eigenvalues of ``S(U)``, 1/s."""
        return np.asarray(np.linalg.eigvals(self.matrix(U)), dtype=complex)

    def eig(self, U: float) -> tuple[npt.NDArray[np.complex128], npt.NDArray[np.complex128]]:
        """Eigenvalues and right eigenvectors of ``S(U)`` (columns)."""
        lam, vec = np.linalg.eig(self.matrix(U))
        return np.asarray(lam, dtype=complex), np.asarray(vec, dtype=complex)

    def modal_part(self, z: Any) -> npt.NDArray[Any]:
        """Return the modal coordinates ``eta`` of states ``z`` (shape (..., n_states))."""
        return np.asarray(z)[..., : self.n_modes]


def system_matrix(bridge: BridgeModel, model: RationalFunctionModel, U: float) -> FloatArray:
    """Return the state matrix ``S(U)`` of ``bridge`` with aerodynamics ``model`` at ``U`` (m/s).

    A one-off convenience; build :class:`BridgeStateSpace` once for many wind speeds.
    """
    return BridgeStateSpace(bridge, model).matrix(U)
