"""Simulated deck aerodynamics beyond the flat plate: a bluff deck outside Roger's low-order form.

Responsibility: :func:`bluff_deck_model` returns the self-excited forces of a synthetic bluff
bridge deck, for benchmarks and tests that need aerodynamics E2RFC's model cannot represent
exactly; :data:`BLUFF_DECK_STATIC` its static coefficients (buffeting); :data:`BLUFF_DECK`
a section model to test it on.

The model (in Roger's notation, ``Q(p)``, Scanlan's signs of
``docs/reference/conventions.md``):

- lift row: 0.7 times the exact-Theodorsen flat plate's (eight lags,
  :func:`ident.model.flat_plate.theodorsen_model`): a lift slope of 0.7 x 2 pi, as decks with edge
  details and barriers have;
- moment from heave: 0.5 times the plate's;
- moment from pitch: ``1.0 + -0.5 p - 0.02 p^2 + 0.6 p/(p + 0.5) - 0.2 p/(p + 3)``, lags of its
  own: a static moment slope of 1.0 per rad and a pitch damping that turns negative at low
  reduced frequency (``A2*`` > 0 above a reduced velocity of about 12), the mark of a bluff
  section prone to torsional flutter.

So the entries do not share their lag roots (ten in all): a model with three shared lags, as
E2RFC fits, approximates it. On :data:`BLUFF_DECK` it flutters in the pitch branch at 13.61 m/s,
2.84 Hz (K = 0.59), the same by the state-space and the frequency-domain analysis.

With sway (three degrees of freedom, :func:`bluff_deck_3dof_model`): the same heave-pitch terms
plus quasi-steady drag and sway terms (:mod:`ident.model.quasi_steady`) from
:data:`BLUFF_DECK_3DOF_STATIC`, the coefficients of a bluffer section (B/D about 2: drag 0.9 on
the width, a drag that falls as the nose rises). On :data:`BLUFF_DECK_3DOF` (sway spring at
2.6 Hz, below pitch) those terms raise the flutter speed by 1.9 %, to 13.87 m/s: a 2-DOF
analysis of this deck is off by more than a test's target accuracy.

Not responsible for: simulating releases (:mod:`simulators.tunnel`).
"""

from __future__ import annotations

import functools

import numpy as np

from ident.model.flat_plate import theodorsen_model
from ident.model.quasi_steady import StaticCoefficients, quasi_steady_model
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel

__all__ = ["BLUFF_DECK", "BLUFF_DECK_3DOF", "BLUFF_DECK_3DOF_STATIC", "BLUFF_DECK_STATIC",
           "bluff_deck_3dof_model", "bluff_deck_model"]

#: A deck section model with a frequency ratio of 3 (mass ratio ~40), in air of 1.225 kg/m^3.
BLUFF_DECK = SectionModel(B=0.45, m=8.0, I=0.16, fh=1.2, fa=3.6, zeta_h=0.003, zeta_a=0.003)

#: Static coefficients consistent with the model's quasi-steady limits (``dC_L`` = 0.7 x the
#: plate's, ``dC_M`` = 1.0), with a bluff section's drag and small mean lift and moment.
BLUFF_DECK_STATIC = StaticCoefficients(C_D=0.3, C_L=-0.1, C_M=0.02, dC_D=0.0,
                                       dC_L=-0.7 * 2.0 * np.pi, dC_M=1.0)

_LIFT_SCALE = 0.7
_CROSS_SCALE = 0.5
_PITCH = {"A1": 1.0, "A2": -0.5, "A3": -0.02}
_PITCH_LAGS = ((0.6, 0.5), (-0.2, 3.0))  # (amplitude, root)


@functools.lru_cache(maxsize=1)
def bluff_deck_model() -> RationalFunctionModel:
    """Return the bluff deck's self-excited forces (module docstring).

    Examples
    --------
    >>> from ident.model import flutter
    >>> result = flutter.analyze(BLUFF_DECK, bluff_deck_model())
    >>> result.critical_mode, round(result.speed, 2)
    ('pitch', 13.61)
    """
    plate = theodorsen_model()
    n_plate = plate.d.size
    d = np.concatenate([plate.d, [root for _, root in _PITCH_LAGS]])
    A = np.zeros((3 + d.size, 2, 2))
    A[:3, 0, :] = _LIFT_SCALE * plate.A[:3, 0, :]
    A[3:3 + n_plate, 0, :] = _LIFT_SCALE * plate.A[3:, 0, :]
    A[:3, 1, 0] = _CROSS_SCALE * plate.A[:3, 1, 0]
    A[3:3 + n_plate, 1, 0] = _CROSS_SCALE * plate.A[3:, 1, 0]
    A[0, 1, 1], A[1, 1, 1], A[2, 1, 1] = _PITCH["A1"], _PITCH["A2"], _PITCH["A3"]
    for l, (amplitude, _) in enumerate(_PITCH_LAGS):
        A[3 + n_plate + l, 1, 1] = amplitude
    return RationalFunctionModel(A, d)


#: The bluff deck on a sway spring at 2.6 Hz (0.3 % damping, the heave mass in sway).
BLUFF_DECK_3DOF = BLUFF_DECK.replace(fp=2.6, zeta_p=0.003)

#: A bluffer section's static coefficients (lift and moment slopes as :data:`BLUFF_DECK_STATIC`).
BLUFF_DECK_3DOF_STATIC = StaticCoefficients(C_D=0.9, C_L=-0.3, C_M=0.05, dC_D=-1.0,
                                            dC_L=-0.7 * 2.0 * np.pi, dC_M=1.0)


def bluff_deck_3dof_model() -> RationalFunctionModel:
    """Return the bluff deck's self-excited forces with quasi-steady sway and drag terms.

    Examples
    --------
    >>> from ident.model import flutter
    >>> result = flutter.analyze(BLUFF_DECK_3DOF, bluff_deck_3dof_model())
    >>> result.critical_mode, round(result.speed, 2)
    ('pitch', 13.87)
    """
    return bluff_deck_model().with_sway(quasi_steady_model(BLUFF_DECK_3DOF_STATIC))
