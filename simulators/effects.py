"""Named physical effects of the virtual tunnel: a re-export of :mod:`ident.physics.effects`.

The effect classes live in :mod:`ident.physics.effects` so that the discrepancy workflow (in
:mod:`ident`, which may not import :mod:`simulators`) can use the same physics; this module keeps
the
``simulators.effects`` names working.
"""

from ident.physics.effects import (
    EFFECT_NAMES,
    AerodynamicNonlinearity,
    BaseVibration,
    ChannelDelay,
    CoulombFriction,
    CubicStiffness,
    Effect,
    QuadraticDamping,
    SensorCrosstalk,
    StaticUnbalance,
    TubingDistortion,
    VortexShedding,
)

__all__ = [
    "EFFECT_NAMES",
    "AerodynamicNonlinearity",
    "BaseVibration",
    "ChannelDelay",
    "CoulombFriction",
    "CubicStiffness",
    "Effect",
    "QuadraticDamping",
    "SensorCrosstalk",
    "StaticUnbalance",
    "TubingDistortion",
    "VortexShedding",
]
