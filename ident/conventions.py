"""The one place where windrig's aerodynamic conventions are written down as code.

Scanlan's flutter derivatives and windrig's aerodynamic transfer matrix ``Q`` are two views of the
same self-excited forces. With generalised coordinates ``q = [h/B, alpha]``, generalised forces
``f = [L B, M]`` and ``f = qd B^2 Q(p) q`` (``qd = rho U^2 / 2``, ``p = s B / U``), harmonic motion
(``p = iK``) gives (``docs/conventions.md``, "Reduced frequency and the self-excited forces")::

    Q(iK) = K^2 [[H4* + i H1*, H3* + i H2*],
                 [A4* + i A1*, A3* + i A2*]]

Signs are Scanlan's: h positive downward, alpha positive nose-up, L positive downward, M positive
nose-up. Everything else in :mod:`ident` converts through the two functions here.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from ident import _validate as v

__all__ = [
    "FLUTTER_DERIVATIVE_NAMES",
    "flutter_derivatives_from_Q",
    "Q_from_flutter_derivatives",
    "reduced_frequency",
]

#: The eight flutter derivatives, in the order used by tables and plots.
FLUTTER_DERIVATIVE_NAMES: tuple[str, ...] = ("H1", "H2", "H3", "H4", "A1", "A2", "A3", "A4")

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
    """Convert ``Q(iK)`` to Scanlan's eight flutter derivatives.

    Parameters
    ----------
    K : array_like, shape (n,)
        Reduced frequencies ``B omega / U``, > 0.
    Q : ndarray, shape (n, 2, 2), complex
        Aerodynamic transfer matrix at ``p = iK``.

    Returns
    -------
    dict
        Keys ``H1..H4, A1..A4``; each value has shape (n,) (non-dimensional).
    """
    K = reduced_frequency(np.atleast_1d(K))
    Q = np.asarray(Q, dtype=complex)
    if Q.shape != K.shape + (2, 2):
        raise ValueError(f"Q must have shape {K.shape + (2, 2)}, got {Q.shape}")
    scaled = Q / (K**2)[..., None, None]
    return {
        name: np.array(getattr(scaled[..., i, j], part), dtype=float)
        for name, (i, j, part) in sorted(_LAYOUT.items(), key=lambda kv: kv[0])
    }


def Q_from_flutter_derivatives(K: Any, fd: dict[str, Any]) -> npt.NDArray[np.complex128]:
    """Convert Scanlan's flutter derivatives at reduced frequencies ``K`` to ``Q(iK)``.

    Parameters
    ----------
    K : array_like, shape (n,)
        Reduced frequencies, > 0.
    fd : dict
        Keys ``H1..H4, A1..A4`` with arrays broadcastable to shape (n,); all eight are required.

    Returns
    -------
    ndarray, shape (n, 2, 2), complex
    """
    K = reduced_frequency(np.atleast_1d(K))
    missing = [name for name in FLUTTER_DERIVATIVE_NAMES if name not in fd]
    if missing:
        raise ValueError(f"flutter derivatives missing: {missing}")
    extra = sorted(set(fd) - set(FLUTTER_DERIVATIVE_NAMES))
    if extra:
        raise ValueError(f"unknown flutter derivative name(s): {extra}")
    Q = np.zeros(K.shape + (2, 2), dtype=complex)
    for name, (i, j, part) in _LAYOUT.items():
        values = np.broadcast_to(v.finite_array(name, fd[name]), K.shape)
        Q[..., i, j] += values if part == "real" else 1j * values
    return Q * (K**2)[..., None, None]
