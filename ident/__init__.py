"""windrig identification: pure numerical code for the self-excited forces of bridge-deck sections.

Conventions (binding, see README): SI units; Scanlan's signs (h and L positive downward, alpha and M
positive nose-up); generalised coordinates ``q = [h/B, alpha]`` and forces ``f = [L B, M]``, with
sway (p and drag D positive downwind) ``q = [h/B, alpha, p/B]`` and ``f = [L B, M, D B]``;
reduced frequency ``K = B omega / U``; non-dimensional Laplace variable ``p = s B / U``;
self-excited forces ``f = rho U^2 / 2 B^2 Q(p) q`` with Roger's rational form of ``Q``.

This package imports nothing from :mod:`daq`; it reads recorded files through one thin module only.
"""

from ident import conventions, e2rfc, flat_plate, flutter, modal
from ident.errors import (
    IdentError,
    InsufficientDataError,
    NonUniformSamplingError,
    RankDeficiencyError,
)
from ident.release import Release
from ident.rfc import RationalFunctionModel
from ident.roger import roger_fit
from ident.section import SectionModel
from ident.statespace import AeroelasticSystem
from ident.taps import TapLayout

__all__ = [
    "AeroelasticSystem",
    "IdentError",
    "InsufficientDataError",
    "NonUniformSamplingError",
    "RankDeficiencyError",
    "RationalFunctionModel",
    "Release",
    "SectionModel",
    "TapLayout",
    "conventions",
    "e2rfc",
    "flat_plate",
    "flutter",
    "modal",
    "roger_fit",
]
