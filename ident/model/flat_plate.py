"""Analytic truth case: the thin flat plate in incompressible potential flow (Theodorsen).

Three forms are provided: the exact flutter derivatives through Theodorsen's function (Hankel
functions); R. T. Jones's two-lag approximation of that function, with which the flat plate is
*exactly* a Roger rational-function model with lag roots (0.091, 0.6) and ``A3 != 0``
(``docs/reference/conventions.md``, "The analytic truth"), the closed-form RFC truth the tests
identify against; and an eight-lag rational fit of the exact function (:func:`theodorsen_model`,
within 5e-5 of it), with which a simulation stands for the exact plate: aerodynamics that no Roger
model of two or three lags reproduces, the case of a real deck whose forces are not exactly
rational.

The closed-form coefficients below follow from the flat plate's flutter-derivative formulas
(same section of ``docs/reference/conventions.md``) with ``p = iK`` substituted: with ``C = C(p)``,

    Q11 = -(pi/2) p^2 - 2 pi p C            Q12 = -(2 pi + (pi/2) p) C - (pi/2) p
    Q21 = (pi/2) p C                        Q22 = (pi/2 + (pi/8) p) C - (pi/8) p - (pi/64) p^2

and ``C(p) = 1 - sum_l a_l p/(p + d_l)``, ``p C(p) = (1 - sum a_l) p + sum_l a_l d_l p/(p + d_l)``.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares
from scipy.special import hankel2

from ident.model.conventions import reduced_frequency
from ident.model.rfc import RationalFunctionModel

__all__ = [
    "JONES_AMPLITUDES",
    "JONES_LAGS",
    "flutter_derivatives",
    "jones_C",
    "jones_model",
    "plate_model",
    "theodorsen",
    "theodorsen_model",
]

#: Jones's lag roots in windrig's full-chord Laplace variable p = s B / U.
JONES_LAGS: tuple[float, float] = (0.091, 0.6)
#: Jones's amplitudes: C(p) = 1 - 0.165 p/(p + 0.091) - 0.335 p/(p + 0.6).
JONES_AMPLITUDES: tuple[float, float] = (0.165, 0.335)


def theodorsen(k: Any) -> npt.NDArray[np.complex128]:
    """Theodorsen's function ``C(k) = F + iG`` at half-chord reduced frequencies ``k = K/2``.

    ``C(k) = H1(k) / (H1(k) + i H0(k))`` with Hankel functions of the second kind.

    Parameters
    ----------
    k : array_like
        Reduced frequency based on the half chord, ``b omega / U``, > 0.

    Returns
    -------
    ndarray, complex, shape of ``k``

    References
    ----------
    T. Theodorsen, "General theory of aerodynamic instability and the mechanism of flutter",
    NACA Report 496, 1935.

    Examples
    --------
    >>> c = theodorsen(0.1)
    >>> round(float(c.real), 4), round(float(c.imag), 4)
    (0.8319, -0.1723)
    """
    k_arr = np.asarray(k, dtype=float)
    if not np.all(np.isfinite(k_arr)) or np.any(k_arr <= 0.0):
        raise ValueError("k must be finite and > 0 everywhere")
    h1 = hankel2(1, k_arr)
    h0 = hankel2(0, k_arr)
    return np.asarray(h1 / (h1 + 1j * h0), dtype=complex)


def jones_C(p: Any) -> npt.NDArray[np.complex128]:
    """R. T. Jones's rational approximation of Theodorsen's function in ``p = s B / U``."""
    p_arr = np.asarray(p, dtype=complex)
    out = np.ones_like(p_arr)
    for a, d in zip(JONES_AMPLITUDES, JONES_LAGS, strict=True):
        out = out - a * p_arr / (p_arr + d)
    return out


def _fd_from_C(K: npt.NDArray[np.float64], C: npt.NDArray[np.complex128]) -> dict[str, Any]:
    """Flat-plate flutter derivatives (Scanlan notation) from ``C = F + iG`` at ``K``."""
    F, G = C.real, C.imag
    pi = np.pi
    return {
        "H1": -2 * pi * F / K,
        "H2": -(pi / (2 * K)) * (1 + F + 4 * G / K),
        "H3": -(2 * pi / K**2) * (F - K * G / 4),
        "H4": (pi / 2) * (1 + 4 * G / K),
        "A1": pi * F / (2 * K),
        "A2": -(pi / (8 * K)) * (1 - F - 4 * G / K),
        "A3": (pi / (2 * K**2)) * (K**2 / 32 + F - K * G / 4),
        "A4": -pi * G / (2 * K),
    }


def flutter_derivatives(K: Any, *, jones: bool = False) -> dict[str, npt.NDArray[np.float64]]:
    """Flat-plate flutter derivatives in Scanlan notation at full-chord reduced frequencies ``K``.

    Parameters
    ----------
    K : array_like, shape (n,)
        Reduced frequency ``B omega / U`` (B the full chord), > 0.
    jones : bool, optional
        Use Jones's approximation of Theodorsen's function instead of the exact one.

    Returns
    -------
    dict
        ``H1..H4, A1..A4``, each of shape (n,).

    Examples
    --------
    >>> fd = flutter_derivatives([1.0])
    >>> bool(fd["H1"][0] < 0 and fd["A2"][0] < 0)   # heave and pitch damping of a plate
    True
    """
    K_arr = reduced_frequency(np.atleast_1d(K))
    C = jones_C(1j * K_arr) if jones else theodorsen(K_arr / 2.0)
    return {name: np.asarray(val, dtype=float) for name, val in _fd_from_C(K_arr, C).items()}


def jones_model() -> RationalFunctionModel:
    """Return the flat plate with Jones's approximation, as an exact Roger model with two lags.

    Returns
    -------
    RationalFunctionModel
        Lag roots (0.091, 0.6); ``A1..A5`` in closed form (see the module docstring).

    Examples
    --------
    >>> import numpy as np
    >>> model = jones_model()
    >>> K = np.array([0.5, 2.0])
    >>> exact = flutter_derivatives(K, jones=True)
    >>> bool(np.allclose(model.flutter_derivatives(K)["A2"], exact["A2"], rtol=1e-12))
    True
    """
    return plate_model(JONES_AMPLITUDES, JONES_LAGS)


#: Reduced frequencies (full chord) over which :func:`theodorsen_model` fits the exact function:
#: reduced velocities from 0.3 to 1300, far beyond any section-model test.
THEODORSEN_FIT_K: tuple[float, float] = (0.005, 20.0)


@functools.lru_cache(maxsize=4)
def theodorsen_model(n_lags: int = 8) -> RationalFunctionModel:
    """Return the flat plate with a rational fit of the *exact* Theodorsen function.

    ``C(p) = 1 - sum_l a_l p / (p + d_l)`` (``C(0) = 1`` exactly) is fitted to Theodorsen's
    function at 400 log-spaced reduced frequencies over ``THEODORSEN_FIT_K`` by variable
    projection (amplitudes linear, log lag roots searched from a geometric spread). With the
    default eight lags the largest error of ``C`` there is 4.6e-5 (Jones's two lags: 1.2e-2),
    so a simulation with this model stands for the exact plate, and the truth of its flutter
    speed is :func:`ident.model.flutter.frequency_domain` with the exact
    :func:`flutter_derivatives`.

    Parameters
    ----------
    n_lags : int
        Number of lag terms, 2 to 10.

    Returns
    -------
    RationalFunctionModel

    Examples
    --------
    >>> import numpy as np
    >>> K = np.geomspace(0.01, 10.0, 50)
    >>> fit = theodorsen_model().flutter_derivatives(K)["A2"]
    >>> bool(np.max(np.abs(fit - flutter_derivatives(K)["A2"]) / np.abs(fit)) < 1e-3)
    True
    """
    if isinstance(n_lags, bool) or not isinstance(n_lags, int) or not 2 <= n_lags <= 10:
        raise ValueError(f"n_lags must be an integer in 2..10, got {n_lags!r}")
    K = np.geomspace(*THEODORSEN_FIT_K, 400)
    p = 1j * K
    target = theodorsen(K / 2.0) - 1.0

    def amplitudes(log_d: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], Any]:
        columns = -p[:, None] / (p[:, None] + np.exp(log_d))
        design = np.vstack([columns.real, columns.imag])
        rhs = np.concatenate([target.real, target.imag])
        a, *_ = np.linalg.lstsq(design, rhs, rcond=None)
        return a, design @ a - rhs

    start = np.log(np.geomspace(0.01, 3.0, n_lags))
    log_d = least_squares(lambda th: amplitudes(th)[1], start).x
    order = np.argsort(log_d)
    a, _ = amplitudes(log_d[order])
    return plate_model(tuple(a), tuple(np.exp(log_d[order])))


def plate_model(amplitudes: Any, lags: Any) -> RationalFunctionModel:
    """Return the flat plate whose Theodorsen function is ``1 - sum_l a_l p / (p + d_l)``.

    Parameters
    ----------
    amplitudes : sequence of float
        ``a_l``.
    lags : sequence of float
        Lag roots ``d_l`` > 0 (full-chord ``p = s B / U``).

    Returns
    -------
    RationalFunctionModel
        An exact Roger model of that plate (module docstring: ``A1..A3`` and the lag terms).
    """
    pi = np.pi
    a = np.asarray(amplitudes, dtype=float)
    d = np.asarray(lags, dtype=float)
    if a.shape != d.shape or a.ndim != 1:
        raise ValueError(f"amplitudes and lags must be 1-D of one length, got {a.shape}, {d.shape}")
    one_minus = 1.0 - a.sum()  # the factor of p in p C(p)
    A = np.zeros((3 + d.size, 2, 2))
    # A1 (stiffness-like): the quasi-steady value C(0) = 1.
    A[0] = [[0.0, -2 * pi], [0.0, pi / 2]]
    # A2 (damping-like) and A3 (added mass).
    A[1] = [
        [-2 * pi * one_minus, -(pi / 2) * one_minus - pi / 2],
        [(pi / 2) * one_minus, (pi / 8) * one_minus - pi / 8],
    ]
    A[2] = [[-pi / 2, 0.0], [0.0, -pi / 64]]
    # Lag terms: -a_l p/(p+d_l) from C, a_l d_l p/(p+d_l) from p C.
    for l in range(d.size):  # noqa: E741 - lag index
        A[3 + l] = [
            [-2 * pi * a[l] * d[l], 2 * pi * a[l] - (pi / 2) * a[l] * d[l]],
            [(pi / 2) * a[l] * d[l], -(pi / 2) * a[l] + (pi / 8) * a[l] * d[l]],
        ]
    return RationalFunctionModel(A, d)
