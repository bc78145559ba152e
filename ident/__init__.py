"""windrig identification: pure numerical code for the self-excited forces of bridge-deck sections.

Conventions (binding, see README): SI units; Scanlan's signs (h and L positive downward, alpha and M
positive nose-up); generalised coordinates ``q = [h/B, alpha]`` and forces ``f = [L B, M]``, with
sway (p and drag D positive downwind) ``q = [h/B, alpha, p/B]`` and ``f = [L B, M, D B]``;
reduced frequency ``K = B omega / U``; non-dimensional Laplace variable ``p = s B / U``;
self-excited forces ``f = rho U^2 / 2 B^2 Q(p) q`` with Roger's rational form of ``Q``.

This package imports nothing from :mod:`daq`; it reads recorded files through one thin module only
(:mod:`ident.records.run_file`).

Its subpackages form layers, bottom first (``docs/reference/architecture.md``; a module imports from
its own layer and the layers below):

1. :mod:`ident.errors` and :mod:`ident.numerics`: exceptions, input checks, small solvers;
2. :mod:`ident.model`: the section, the conventions, Roger's form, the flutter analysis;
3. :mod:`ident.tables`: flutter-derivative tables, their Roger fits and checks, a section's
   flutter by both routes compared (:func:`section_flutter`);
4. :mod:`ident.physics`: air, turbulence, pressure taps, tubing, the named effects;
5. :mod:`ident.simulation`: simulated decays (the plant and the measurement chain);
6. :mod:`ident.records`: releases and the run files they are read from;
7. :mod:`ident.identification`: E2RFC, modal fits, the indirect route, campaign analysis;
8. :mod:`ident.discrepancy` and :mod:`ident.bridge`: the discrepancy workflow, the full bridge.

This module re-exports the names most scripts start from; everything else is imported from
its own module.
"""

from ident.errors import (
    IdentError,
    InsufficientDataError,
    NonUniformSamplingError,
    PlausibilityError,
    RankDeficiencyError,
)
from ident.identification.e2rfc import identify
from ident.model.rfc import RationalFunctionModel
from ident.model.roger import roger_fit
from ident.model.section import SectionModel
from ident.model.statespace import AeroelasticSystem
from ident.physics.taps import TapLayout
from ident.records.release import Release
from ident.tables.fd_table import FlutterDerivativeTable
from ident.tables.flutter_routes import section_flutter

__all__ = [
    "AeroelasticSystem",
    "FlutterDerivativeTable",
    "IdentError",
    "InsufficientDataError",
    "NonUniformSamplingError",
    "PlausibilityError",
    "RankDeficiencyError",
    "RationalFunctionModel",
    "Release",
    "SectionModel",
    "TapLayout",
    "identify",
    "roger_fit",
    "section_flutter",
]
