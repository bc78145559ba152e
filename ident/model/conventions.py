"""The one place where windrig's aerodynamic conventions are written down as code.

Scanlan's flutter derivatives and windrig's aerodynamic transfer matrix ``Q`` are two views of the
same self-excited forces. With generalised coordinates ``q = [h/B, alpha]``, generalised forces
``f = [L B, M]`` and ``f = qd B^2 Q(p) q`` (``qd = rho U^2 / 2``, ``p = s B / U``), harmonic motion
(``p = iK``) gives (``docs/reference/conventions.md``, "Reduced frequency and the self-excited
forces")::

    Q(iK) = K^2 [[H4* + i H1*, H3* + i H2*],
                 [A4* + i A1*, A3* + i A2*]]

and with the lateral degree of freedom (``q = [h/B, alpha, p/B]``, ``f = [L B, M, D B]``, p and
the drag D positive downwind; ``docs/reference/conventions.md``, "Three degrees of freedom") the 18
of Scanlan's later work::

    Q(iK) = K^2 [[H4* + i H1*, H3* + i H2*, H6* + i H5*],
                 [A4* + i A1*, A3* + i A2*, A6* + i A5*],
                 [P6* + i P5*, P3* + i P2*, P4* + i P1*]]

Signs are Scanlan's: h positive downward, alpha positive nose-up, L positive downward, M positive
nose-up. Everything else in :mod:`ident` converts through the two functions here.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

from ident.numerics import validate as v

__all__ = [
    "FLUTTER_DERIVATIVE_NAMES",
    "FLUTTER_DERIVATIVE_NAMES_3DOF",
    "derivative_names",
    "flutter_derivatives_from_Q",
    "name_modes",
    "Q_from_flutter_derivatives",
    "reduced_frequency",
]

#: The eight flutter derivatives, in the order used by tables and plots.
FLUTTER_DERIVATIVE_NAMES: tuple[str, ...] = ("H1", "H2", "H3", "H4", "A1", "A2", "A3", "A4")
#: The 18 of three degrees of freedom, in the order used by tables and plots.
FLUTTER_DERIVATIVE_NAMES_3DOF: tuple[str, ...] = tuple(
    f"{letter}{i}" for letter in "HAP" for i in range(1, 7))

# (row, column, part) of Q(iK)/K^2 that holds each flutter derivative.
_LAYOUT: dict[str, tuple[int, int, str]] = {
    "H1": (0, 0, "imag"),
    "H4": (0, 0, "real"),
    "H2": (0, 1, "imag"),
    "H3": (0, 1, "real"),
    "A1": (1, 0, "imag"),
    "A4": (1, 0, "real"),
    "A2": (1, 1, "imag"),
    "A3": (1, 1, "real"),
}
# ... and of the ten more of three degrees of freedom.
_LAYOUT_3DOF: dict[str, tuple[int, int, str]] = {
    **_LAYOUT,
    "H5": (0, 2, "imag"),
    "H6": (0, 2, "real"),
    "A5": (1, 2, "imag"),
    "A6": (1, 2, "real"),
    "P5": (2, 0, "imag"),
    "P6": (2, 0, "real"),
    "P2": (2, 1, "imag"),
    "P3": (2, 1, "real"),
    "P1": (2, 2, "imag"),
    "P4": (2, 2, "real"),
}


def derivative_names(n_dof: int) -> tuple[str, ...]:
    """Return the flutter derivatives of ``n_dof`` (2 or 3) degrees of freedom, in table order."""
    if n_dof == 2:
        return FLUTTER_DERIVATIVE_NAMES
    if n_dof == 3:
        return FLUTTER_DERIVATIVE_NAMES_3DOF
    raise ValueError(f"n_dof must be 2 or 3, got {n_dof!r}")


def derivative_layout(n_dof: int) -> dict[str, tuple[int, int, str]]:
    """Return where each flutter derivative sits in ``Q(iK) / K^2``.

    ``name -> (row, column, "real" or "imag")`` for ``n_dof`` (2 or 3) degrees of freedom.
    """
    derivative_names(n_dof)  # validates n_dof
    return dict(_layout(n_dof))


def _layout(n_dof: int) -> dict[str, tuple[int, int, str]]:
    return _LAYOUT if n_dof == 2 else _LAYOUT_3DOF


def reduced_frequency(K: Any) -> npt.NDArray[np.float64]:
    """Validate reduced frequencies ``K = B omega / U`` (finite, > 0) and return them as an array.

    Raises
    ------
    ValueError
        If any K is <= 0 or not finite.
    """
    return v.positive_array("K", K)


def flutter_derivatives_from_Q(
    K: Any, Q: npt.NDArray[np.complex128]
) -> dict[str, npt.NDArray[np.float64]]:
    """Convert ``Q(iK)`` to Scanlan's flutter derivatives (8 for 2x2, 18 for 3x3).

    Parameters
    ----------
    K : array_like, shape (n,)
        Reduced frequencies ``B omega / U``, > 0.
    Q : ndarray, shape (n, 2, 2) or (n, 3, 3), complex
        Aerodynamic transfer matrix at ``p = iK``.

    Returns
    -------
    dict
        Keys ``H1..H4, A1..A4`` (or ``H1..H6, A1..A6, P1..P6``) in sorted order; each value has
        shape (n,) (non-dimensional).
    """
    K = reduced_frequency(np.atleast_1d(K))
    Q = np.asarray(Q, dtype=complex)
    n_dof = Q.shape[-1] if Q.ndim == K.ndim + 2 else 0
    if n_dof not in (2, 3) or Q.shape != K.shape + (n_dof, n_dof):
        raise ValueError(f"Q must have shape {K.shape + (2, 2)} or {K.shape + (3, 3)}, got "
                         f"{Q.shape}")
    scaled = Q / (K**2)[..., None, None]
    return {
        name: np.array(getattr(scaled[..., i, j], part), dtype=float)
        for name, (i, j, part) in sorted(_layout(n_dof).items(), key=lambda kv: kv[0])
    }


def Q_from_flutter_derivatives(K: Any, fd: dict[str, Any]) -> npt.NDArray[np.complex128]:
    """Convert Scanlan's flutter derivatives at reduced frequencies ``K`` to ``Q(iK)``.

    Parameters
    ----------
    K : array_like, shape (n,)
        Reduced frequencies, > 0.
    fd : dict
        Keys ``H1..H4, A1..A4`` (2 DOF) or ``H1..H6, A1..A6, P1..P6`` (3 DOF) with arrays
        broadcastable to shape (n,); all of the one set or the other are required (a table with
        missing derivatives fills them explicitly: :mod:`ident.tables.fd_table`).

    Returns
    -------
    ndarray, shape (n, 2, 2) or (n, 3, 3), complex
    """
    K = reduced_frequency(np.atleast_1d(K))
    n_dof = 3 if set(fd) - set(FLUTTER_DERIVATIVE_NAMES) else 2
    names = derivative_names(n_dof)
    extra = sorted(set(fd) - set(names))
    if extra:
        raise ValueError(f"unknown flutter derivative name(s): {extra}")
    missing = [name for name in names if name not in fd]
    if missing:
        raise ValueError(f"flutter derivatives missing: {missing}")
    Q = np.zeros(K.shape + (n_dof, n_dof), dtype=complex)
    for name, (i, j, part) in _layout(n_dof).items():
        values = np.broadcast_to(v.finite_array(name, fd[name]), K.shape)
        Q[..., i, j] += values if part == "real" else 1j * values
    return Q * (K**2)[..., None, None]


ComplexArray = npt.NDArray[np.complex128]
FloatArray = npt.NDArray[np.float64]


def name_modes(shapes: ComplexArray, mass_matrix: FloatArray) -> tuple[int, ...]:
    """Return the indices of the heave-, pitch- (and sway-) dominated modes by kinetic energy.

    ``|phi|^2`` weighted by the diagonal of the mass matrix is each coordinate's share of a
    mode's kinetic energy; comparing shares (not raw amplitudes) makes ``h/B``, ``alpha`` and
    ``p/B`` comparable. With more modes than coordinates, the ones that are most heave, most
    pitch (and most sway) jointly, an assignment, are named.

    Parameters
    ----------
    shapes : ndarray, complex, shape (n_modes, n)
        Each mode's amplitudes of ``[h/B, alpha]`` or ``[h/B, alpha, p/B]`` (any complex scale
        per mode), n_modes >= n.
    mass_matrix : ndarray, shape (n, n)
        The section's mass matrix for those coordinates (:meth:`SectionModel.mass_matrix`).

    Returns
    -------
    tuple of int
        Row of ``shapes`` of the heave mode, then of the pitch mode (then of the sway mode).
    """
    share = np.abs(np.asarray(shapes).T) ** 2 * np.diag(mass_matrix)[:, None]  # (coord, mode)
    share = share / share.sum(axis=0, keepdims=True)
    rows, cols = linear_sum_assignment(-share)  # row 0 = heave, row 1 = pitch, row 2 = sway
    by_row = dict(zip(rows.tolist(), cols.tolist(), strict=True))
    return tuple(int(by_row[i]) for i in range(share.shape[0]))
