"""Roger's rational-function model of the self-excited forces (the object E2RFC identifies).

``Q(p) = A1 + A2 p + A3 p^2 + sum_l A_{l+3} p / (p + d_l)`` with real 2x2 matrices ``A_k`` (3x3
with sway: ``docs/reference/conventions.md``, "Three degrees of freedom") and lag roots ``d_l > 0``
shared by all entries (``docs/reference/conventions.md``, "Reduced frequency and the self-excited
forces"). The model is a value: it is immutable, validated on construction, and serialisable to JSON
through
:meth:`to_dict`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from ident.model.conventions import flutter_derivatives_from_Q, reduced_frequency
from ident.numerics import validate as v

__all__ = ["RationalFunctionModel"]


class RationalFunctionModel:
    """Rational function approximation of the aerodynamic transfer matrix ``Q(p)``.

    Parameters
    ----------
    A : array_like, shape (3 + m, n, n), n = 2 or 3
        Real coefficient matrices ``A1, A2, A3, A4 .. A_{m+3}`` (non-dimensional), for the
        coordinates ``q = [h/B, alpha]`` and forces ``[L B, M]`` (n = 2), or
        ``q = [h/B, alpha, p/B]`` and ``[L B, M, D B]`` (n = 3).
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
        n = A_arr.shape[-1] if A_arr.ndim == 3 and A_arr.shape[-1] in (2, 3) else 2
        expected = (3 + d_arr.size, n, n)
        if A_arr.shape != expected:
            raise ValueError(
                f"A must have shape (3 + m, n, n) = {expected} for m = {d_arr.size} lag root(s) "
                f"and n = 2 or 3 degrees of freedom, got {A_arr.shape}"
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
        """Coefficient matrices, shape (3 + m, n_dof, n_dof), read-only."""
        return self._A

    @property
    def n_dof(self) -> int:
        """Degrees of freedom the model is for: 2 (heave, pitch) or 3 (with sway)."""
        return int(self._A.shape[-1])

    def planar(self) -> RationalFunctionModel:
        """Return the heave-pitch part: the leading 2x2 block of every ``A_k`` (same lags)."""
        return RationalFunctionModel(self._A[:, :2, :2], self._d)

    def with_sway(self, sway: RationalFunctionModel) -> RationalFunctionModel:
        """Return a 3-DOF model: this 2-DOF model plus the sway rows and columns of ``sway``.

        ``sway`` is a 3-DOF model (e.g. :func:`ident.model.quasi_steady.quasi_steady_model`) whose
        heave-pitch block is ignored; the lags of both are kept (the sway terms' own lag
        coefficients on their own roots). Used to complete a 2-DOF model, e.g. a flat plate's
        Theodorsen forces, with drag terms it does not have.
        """
        if self.n_dof != 2 or sway.n_dof != 3:
            raise ValueError(f"with_sway needs a 2-DOF model and a 3-DOF sway model, got "
                             f"{self.n_dof} and {sway.n_dof}")
        m1, m2 = self.n_lags, sway.n_lags
        A = np.zeros((3 + m1 + m2, 3, 3))
        A[: 3 + m1, :2, :2] = self._A
        outside = np.ones((3, 3), dtype=bool)
        outside[:2, :2] = False
        A[:3][:, outside] = sway.A[:3][:, outside]
        A[3 + m1:][:, outside] = sway.A[3:][:, outside]
        return RationalFunctionModel(A, np.concatenate([self._d, sway.d]))

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
        ndarray, shape ``p.shape + (n_dof, n_dof)``, complex
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
        """Scanlan flutter derivatives at reduced frequencies ``K`` (> 0).

        Returns
        -------
        dict
            ``H1..H4, A1..A4`` (2 DOF) or all 18 ``H1..H6, A1..A6, P1..P6`` (3 DOF): arrays of
            the shape of ``K`` (1-D), non-dimensional.
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
