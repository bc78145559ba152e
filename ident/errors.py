"""Exceptions raised by the identification package.

Every exception subclasses a builtin as well (``ValueError``), so that callers who only know the
standard library can still catch bad input, while callers who know windrig can catch the specific
cause. This follows python-control's ``ControlDimension(ValueError)`` pattern.
"""

from __future__ import annotations

__all__ = [
    "FlutterCertificationError",
    "IdentError",
    "InsufficientDataError",
    "NonUniformSamplingError",
    "PlausibilityError",
    "RankDeficiencyError",
    "ReleaseNotFoundError",
]


class IdentError(Exception):
    """Base class of every error raised by :mod:`ident`."""


class InsufficientDataError(IdentError, ValueError):
    """The data cannot determine what was asked for (too short, too few releases, ...)."""


class NonUniformSamplingError(IdentError, ValueError):
    """A time vector is not uniformly sampled within the stated tolerance."""


class RankDeficiencyError(InsufficientDataError):
    """A least-squares problem is rank deficient: the data cannot determine the unknowns."""


class ReleaseNotFoundError(InsufficientDataError):
    """No release (a hold, then a free decay from rest) in the displacements given."""


class FlutterCertificationError(IdentError, RuntimeError):
    """A fast flutter analysis disagrees with its dense check, or could not follow a branch."""


class PlausibilityError(IdentError, ValueError):
    """Data no section model could have produced: a conversion mistake (a unit, a sign).

    Raised where an answer from the data would be meaningless (a pitch in degrees, a lift of
    the wrong sign); the message names the likely mistake. See :mod:`ident.records.plausibility`.
    """
