"""The structural model of a spring-mounted section model (two degrees of freedom: heave and pitch).

This module owns the structural matrices in windrig's generalised coordinates ``q = [h/B, alpha]``
(``docs/conventions.md``, "Signs and coordinates"). It knows nothing of aerodynamics;
:mod:`ident.statespace` couples it with a :class:`~ident.rfc.RationalFunctionModel`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
import numpy.typing as npt

from ident import _validate as v

__all__ = ["SectionModel"]


@dataclass(frozen=True)
class SectionModel:
    """Mass, stiffness and damping of a two-degree-of-freedom section model, per unit span.

    Parameters
    ----------
    B : float
        Deck width (chord), m. The reference length of every non-dimensional quantity.
    m : float
        Mass per unit span, kg/m.
    I : float
        Mass moment of inertia per unit span about the elastic axis, kg m^2/m.
    fh, fa : float
        Uncoupled natural frequencies in still vacuum of heave and pitch, Hz
        (``k_h = m (2 pi fh)^2``, ``k_a = I (2 pi fa)^2``).
    zeta_h, zeta_a : float
        Structural damping ratios of heave and pitch, in [0, 1).
    rho : float, optional
        Air density, kg/m^3. Default 1.225 (ISA sea level).
    S : float, optional
        Static unbalance ``m x_cg`` per unit span, kg m/m (x_cg: distance from the elastic axis to
        the centre of mass, positive downstream). Default 0.

    Raises
    ------
    ValueError
        If a mass, frequency, width or density is not > 0, a damping ratio is outside [0, 1), or
        the mass matrix is not positive definite (``S^2 >= m I``). The message names the field.

    Examples
    --------
    >>> s = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)
    >>> s.mass_matrix()
    array([[0.27, 0.  ],
           [0.  , 0.03]])
    >>> SectionModel(B=0.3, m=-3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.0, zeta_a=0.0)
    Traceback (most recent call last):
    ...
    ValueError: m must be > 0, got -3.0
    """

    B: float
    m: float
    I: float  # noqa: E741 - the standard symbol for the moment of inertia
    fh: float
    fa: float
    zeta_h: float
    zeta_a: float
    rho: float = 1.225
    S: float = 0.0

    def __post_init__(self) -> None:
        # Convert and check every field once, here, so nothing downstream sees a bad value.
        for name in ("B", "m", "I", "fh", "fa", "rho"):
            object.__setattr__(self, name, v.positive(name, getattr(self, name)))
        for name in ("zeta_h", "zeta_a"):
            object.__setattr__(self, name, v.in_range(name, getattr(self, name), 0.0, 1.0))
        object.__setattr__(self, "S", v.finite("S", self.S))
        if self.S**2 >= self.m * self.I:
            raise ValueError(
                f"S must satisfy S^2 < m I for a positive-definite mass matrix, got S={self.S!r} "
                f"with m I={self.m * self.I!r}"
            )

    @property
    def omega_h(self) -> float:
        """Heave natural circular frequency, rad/s."""
        return 2.0 * math.pi * self.fh

    @property
    def omega_a(self) -> float:
        """Pitch natural circular frequency, rad/s."""
        return 2.0 * math.pi * self.fa

    def mass_matrix(self) -> npt.NDArray[np.float64]:
        """Structural mass matrix ``Ms`` for ``q = [h/B, alpha]``, shape (2, 2), kg m^2/m."""
        B = self.B
        return np.array([[self.m * B**2, self.S * B], [self.S * B, self.I]])

    def damping_matrix(self) -> npt.NDArray[np.float64]:
        """Structural damping matrix ``Cs`` for ``q = [h/B, alpha]``, shape (2, 2), kg m^2/(m s)."""
        B = self.B
        return np.diag(
            [
                2.0 * self.m * self.zeta_h * self.omega_h * B**2,
                2.0 * self.I * self.zeta_a * self.omega_a,
            ]
        )

    def stiffness_matrix(self) -> npt.NDArray[np.float64]:
        """Structural stiffness matrix ``Ks`` for ``q = [h/B, alpha]``, shape (2, 2), N m/m."""
        return np.diag([self.m * self.omega_h**2 * self.B**2, self.I * self.omega_a**2])

    def replace(self, **changes: Any) -> SectionModel:
        """Return a copy with some fields changed (validated again)."""
        unknown = set(changes) - {f.name for f in fields(self)}
        if unknown:
            raise TypeError(f"unknown SectionModel field(s): {sorted(unknown)}")
        return SectionModel(**{**asdict(self), **changes})

    def to_dict(self) -> dict[str, float]:
        """Return the fields as a plain dict of floats (JSON-ready)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SectionModel:
        """Build a section from :meth:`to_dict` output; unknown keys raise ``TypeError``."""
        known = {f.name for f in fields(cls)}
        unknown = set(data) - known
        if unknown:
            raise TypeError(f"unknown SectionModel field(s): {sorted(unknown)}")
        return cls(**data)
