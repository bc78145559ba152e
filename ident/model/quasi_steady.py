"""Quasi-steady self-excited forces of three degrees of freedom from static coefficients.

A flutter-derivative table of heave and pitch (a published one, or E2RFC's 2-DOF model) says
nothing of drag, yet a deck moving in sway or heave changes the wind it sees: the drag and lift
terms a 3-DOF analysis needs can be taken quasi-steady, from the static coefficients
(:class:`ident.model.quasi_steady.StaticCoefficients`, signs of ``docs/reference/conventions.md``:
``C_L`` along h, downward; ``C_D`` downwind; ``C_M`` nose-up; slopes per radian of alpha).

The derivation, to first order in the motion. A deck moving with ``h'`` (down) and ``p'``
(downwind) at pitch ``alpha`` sees the relative wind ``(U - p', -h')`` (downwind, down
components): the angle of attack grows by ``h'/U`` and the dynamic pressure by the factor
``1 - 2 p'/U``. Drag ``D_w = qd B C_D(alpha_e)`` acts along the relative wind and lift
``L_w = qd B C_L(alpha_e)`` across it (``alpha_e = alpha + h'/U``); turned back to the fixed axes
(by the small angle ``h'/U``) and linearised around the mean state::

    L = qd B   [(dC_L - C_D) h'/U + dC_L alpha - 2 C_L p'/U]
    M = qd B^2 [dC_M h'/U + dC_M alpha - 2 C_M p'/U]
    D = qd B   [(dC_D + C_L) h'/U + dC_D alpha - 2 C_D p'/U]

so the quasi-steady model is exactly of Roger's form without lags: ``Q(p) = A1 + A2 p`` with the
slopes in ``A1``'s alpha column and the rest in ``A2``. In Scanlan's terms (``K = B omega / U``)::

    H1* = (dC_L - C_D)/K   H3* = dC_L/K^2   H5* = -2 C_L/K
    A1* = dC_M/K           A3* = dC_M/K^2   A5* = -2 C_M/K
    P5* = (dC_D + C_L)/K   P3* = dC_D/K^2   P1* = -2 C_D/K

and ``H2, H4, H6, A2, A4, A6, P2, P4, P6`` zero (quasi-steady theory has no pitch-rate or
displacement terms besides alpha). With lift positive upward the signs of ``C_L`` and ``dC_L``
flip (``StaticCoefficients.from_lift_up``): ``P5* = (C_D' - C_L^up)/K``, as in Simiu and
Scanlan (1996) and the buffeting forces of :mod:`ident.physics.turbulence`, which follow from the
same relative-wind argument.

Not responsible for: buffeting (:mod:`ident.physics.turbulence`), unsteady effects (the derivatives
above are the ``K -> 0`` limit of the real ones; :mod:`ident.tables.fd_table` for measured tables).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
import numpy.typing as npt

from ident.model.rfc import RationalFunctionModel
from ident.numerics import validate as v

__all__ = ["StaticCoefficients", "quasi_steady_derivatives", "quasi_steady_model"]


@dataclass(frozen=True)
class StaticCoefficients:
    """Static force coefficients of a section and their slopes (windrig's signs).

    ``L = qd B C_L`` (positive downward, along h), ``D = qd B C_D`` (downwind),
    ``M = qd B^2 C_M`` (nose-up); slopes ``dC_*`` per radian of nose-up alpha.

    Examples
    --------
    >>> plate = StaticCoefficients.flat_plate()
    >>> round(plate.dC_L, 4), round(plate.dC_M, 4)
    (-6.2832, 1.5708)
    >>> StaticCoefficients.from_lift_up(C_D=0.1, C_L=0.2, C_M=0.0, dC_D=0.0, dC_L=5.0,
    ...                                 dC_M=1.0).C_L
    -0.2
    """

    C_D: float
    C_L: float
    C_M: float
    dC_D: float
    dC_L: float
    dC_M: float

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, v.finite(f.name, getattr(self, f.name)))

    @classmethod
    def flat_plate(cls, C_D: float = 0.02) -> StaticCoefficients:
        """Thin flat plate at zero incidence: ``dC_L = -2 pi``, ``dC_M = pi/2`` (mid-chord).

        ``C_D`` is its friction drag (default 0.02); lift and moment are zero at zero incidence.
        """
        return cls(C_D=C_D, C_L=0.0, C_M=0.0, dC_D=0.0, dC_L=-2.0 * math.pi, dC_M=math.pi / 2.0)

    @classmethod
    def from_lift_up(cls, *, C_D: float, C_L: float, C_M: float, dC_D: float, dC_L: float,
                     dC_M: float) -> StaticCoefficients:
        """Convert coefficients from a source with lift positive upward (``C_L``, ``dC_L`` flip)."""
        return cls(C_D=C_D, C_L=-v.finite("C_L", C_L), C_M=C_M, dC_D=dC_D,
                   dC_L=-v.finite("dC_L", dC_L), dC_M=dC_M)

    def to_dict(self) -> dict[str, float]:
        """Return the fields as a JSON-ready dict."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> StaticCoefficients:
        """Build coefficients from :meth:`to_dict` output; unknown keys raise ``TypeError``."""
        return cls(**v.checked_keys(cls, data))

def quasi_steady_model(static: StaticCoefficients) -> RationalFunctionModel:
    """Return the quasi-steady self-excited forces of 3 DOF as a Roger model without lags.

    Parameters
    ----------
    static : StaticCoefficients
        Static coefficients at the mean angle of attack and their slopes, per radian.

    Returns
    -------
    RationalFunctionModel
        ``A`` of shape (3, 3, 3): ``A1`` (stiffness), ``A2`` (damping), ``A3 = 0``.

    Examples
    --------
    The flat plate's lift slope gives Theodorsen's ``H1* = -2 pi / K`` at ``C(k) = 1``:

    >>> import math
    >>> model = quasi_steady_model(StaticCoefficients.flat_plate(C_D=0.0))
    >>> bool(abs(model.flutter_derivatives([0.5])["H1"][0] + 2 * math.pi / 0.5) < 1e-12)
    True
    """
    s = static
    A = np.zeros((3, 3, 3))
    # Stiffness: the slopes in the alpha column (rows L, M, D).
    A[0, :, 1] = [s.dC_L, s.dC_M, s.dC_D]
    # Damping (multiplies p = s B / U, i.e. (B/U) q'): heave rate as an angle of attack (and
    # the drag/lift turned by it), sway rate as a change of dynamic pressure.
    A[1, :, 0] = [s.dC_L - s.C_D, s.dC_M, s.dC_D + s.C_L]
    A[1, :, 2] = [-2.0 * s.C_L, -2.0 * s.C_M, -2.0 * s.C_D]
    return RationalFunctionModel(A, [])


def quasi_steady_derivatives(static: StaticCoefficients,
                             K: Any) -> dict[str, npt.NDArray[np.float64]]:
    """Return the 18 quasi-steady flutter derivatives at reduced frequencies ``K`` (> 0).

    Parameters
    ----------
    static : StaticCoefficients
    K : array_like
        Reduced frequencies ``B omega / U``.

    Returns
    -------
    dict
        ``H1..H6, A1..A6, P1..P6``, arrays of the shape of ``K`` (1-D), non-dimensional.
    """
    return quasi_steady_model(static).flutter_derivatives(K)
