"""Roger's rational-function model of the self-excited forces (the object E2RFC identifies).

``Q(p) = A1 + A2 p + A3 p^2 + sum_l A_{l+3} p / (p + d_l)`` with real 2x2 matrices ``A_k`` and lag
roots ``d_l > 0`` shared by all four entries (``docs/conventions.md``,
"Reduced frequency and the self-excited forces"). The model is a value: it is
immutable, validated on construction, and serialisable to JSON through :meth:`to_dict`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from ident import _validate as v
from ident.conventions import flutter_derivatives_from_Q, reduced_frequency

__all__ = ["RationalFunctionModel"]


class RationalFunctionModel:
    """Rational function approximation of the aerodynamic transfer matrix ``Q(p)``.

    Parameters
    ----------
    A : array_like, shape (3 + m, 2, 2)
        Real coefficient matrices ``A1, A2, A3, A4 .. A_{m+3}`` (non-dimensional), for the
        coordinates ``q = [h/B, alpha]`` and forces ``[L B, M]``.
    d : array_like, shape (m,)
        Lag roots, non-dimensional (in units of ``U/B``), each > 0. ``m = 0`` is allowed.

    Raises
    ------
    ValueError
        On wrong shapes, non-finite values or a lag root <= 0.

    References
    ----------
    K. L. Roger, "Airplane math modeling methods for active control design", AGARD CP-228, 1977.
    M. Gan Chowdhury and P. P. Sarkar, "Experimental identification of rational function
    coefficients for time-domain flutter analysis", Engineering Structures 27, 2005.

    Examples
    --------
    A quasi-steady model (no lags): ``Q(iK)`` is then a quadratic in ``K``.

    >>> import numpy as np
    >>> A = np.zeros((3, 2, 2)); A[0, 0, 1] = -2 * np.pi
    >>> model = RationalFunctionModel(A, [])
    >>> float(model.flutter_derivatives([1.0])["H3"][0]) == -2 * np.pi
    True
    >>> RationalFunctionModel(np.zeros((4, 2, 2)), [-0.1])
    Traceback (most recent call last):
    ...
    ValueError: d must be > 0 everywhere, got minimum -0.1
    """

    __slots__ = ("_A", "_d")

    def __init__(self, A: Any, d: Any) -> None:
        A_arr = v.finite_array("A", A)
        d_arr = np.atleast_1d(v.finite_array("d", d)).astype(float)
        if d_arr.ndim != 1:
            raise ValueError(f"d must be a 1-D array of lag roots, got shape {d_arr.shape}")
        if d_arr.size and np.any(d_arr <= 0.0):
            raise ValueError(f"d must be > 0 everywhere, got minimum {float(d_arr.min())!r}")
        expected = (3 + d_arr.size, 2, 2)
        if A_arr.shape != expected:
            raise ValueError(
                f"A must have shape (3 + m, 2, 2) = {expected} for m = {d_arr.size} lag root(s), "
                f"got {A_arr.shape}"
            )
        # Immutable copies: a model is a value and may be shared between threads and plots.
        A_arr = A_arr.copy()
        A_arr.flags.writeable = False
        d_arr = d_arr.copy()
        d_arr.flags.writeable = False
        self._A = A_arr
        self._d = d_arr

    @property
    def A(self) -> npt.NDArray[np.float64]:
        """Coefficient matrices, shape (3 + m, 2, 2), read-only."""
        return self._A

    @property
    def d(self) -> npt.NDArray[np.float64]:
        """Lag roots, shape (m,), read-only."""
        return self._d

    @property
    def n_lags(self) -> int:
        """Number of lag terms ``m``."""
        return int(self._d.size)

    def Q(self, p: Any) -> npt.NDArray[np.complex128]:
        """Evaluate ``Q(p)`` at non-dimensional Laplace variables ``p``.

        Parameters
        ----------
        p : array_like, complex
            Any shape; ``p = iK`` for harmonic motion at reduced frequency ``K``.

        Returns
        -------
        ndarray, shape ``p.shape + (2, 2)``, complex
        """
        p_arr = np.asarray(p, dtype=complex)
        if not np.all(np.isfinite(p_arr)):
            raise ValueError("p contains non-finite values")
        pp = p_arr[..., None, None]
        out = self._A[0] + self._A[1] * pp + self._A[2] * pp**2
        for l, d_l in enumerate(self._d):  # noqa: E741 - l is the lag index of the paper
            out = out + self._A[3 + l] * (pp / (pp + d_l))
        return np.asarray(out, dtype=complex)

    def flutter_derivatives(self, K: Any) -> dict[str, npt.NDArray[np.float64]]:
        """Scanlan flutter derivatives ``H1..H4, A1..A4`` at reduced frequencies ``K`` (> 0).

        Returns
        -------
        dict
            Eight arrays of the shape of ``K`` (1-D), non-dimensional.
        """
        K_arr = reduced_frequency(np.atleast_1d(K))
        return flutter_derivatives_from_Q(K_arr, self.Q(1j * K_arr))

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-ready dict: ``{"A": nested lists, "d": list}``."""
        return {"A": self._A.tolist(), "d": self._d.tolist()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RationalFunctionModel:
        """Build a model from :meth:`to_dict` output; other keys raise ``TypeError``."""
        extra = set(data) - {"A", "d"}
        if extra:
            raise TypeError(f"unknown RationalFunctionModel key(s): {sorted(extra)}")
        missing = {"A", "d"} - set(data)
        if missing:
            raise ValueError(f"RationalFunctionModel dict is missing key(s): {sorted(missing)}")
        return cls(data["A"], data["d"])

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, RationalFunctionModel):
            return NotImplemented
        return bool(np.array_equal(self._A, other._A) and np.array_equal(self._d, other._d))

    __hash__ = None  # type: ignore[assignment]  # mutable-looking array value: not hashable

    def __repr__(self) -> str:
        return f"RationalFunctionModel(n_lags={self.n_lags}, d={self._d.tolist()})"
