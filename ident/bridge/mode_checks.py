"""Plausibility of a bridge's modes: masses and damping that no deck has, named by their slip.

A bridge model file (:mod:`ident.bridge.model`) can be valid and still wrong by a unit: a
generalised mass in tonnes, shapes in mm, mass-normalised shapes given with the finite-element
program's modal mass, a damping ratio written as a percentage. Each moves the flutter speed
without an error, so each is a warning naming the file, the mode, the value and the slip:

- a mode's equivalent deck mass per metre, ``M / int (h^2 + (alpha B/2)^2 + p^2) dx``, more than
  :data:`MASS_SPREAD` times from the median of the other modes' (the example bridge's six modes
  lie within a factor 2.2: 10 281 kg/m in torsion, I / (B/2)^2, to 22 740 kg/m), or below
  :data:`LIGHTEST_DECK` kg/m (:func:`mass_warnings`);
- the median of those masses over ``rho B^2``, the deck's mass ratio, outside
  :data:`ident.model.section.MASS_RATIO_RANGE`: a slip made in every mode, which the comparison
  between modes cannot see, named when undoing it gives a deck's ratio
  (:func:`deck_mass_ratio_warning`);
- a damping ratio of :data:`IMPLAUSIBLE_DAMPING` or more (:func:`damping_warning`).

Not responsible for: reading or refusing the file (:mod:`ident.bridge.model`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np
import numpy.typing as npt

from ident.model.section import MASS_RATIO_RANGE
from ident.numerics.quadrature import trapezoid_weights

__all__ = ["IMPLAUSIBLE_DAMPING", "LIGHTEST_DECK", "MASS_SPREAD", "damping_warning",
           "deck_mass_ratio_warning", "equivalent_masses", "mass_warnings"]

FloatArray = npt.NDArray[np.float64]


class Mode(Protocol):
    """What the checks read of a mode (:class:`ident.bridge.model.Mode`, which imports them)."""

    @property
    def name(self) -> str: ...
    @property
    def generalised_mass(self) -> float: ...
    @property
    def h(self) -> FloatArray: ...
    @property
    def alpha(self) -> FloatArray: ...
    @property
    def p(self) -> FloatArray: ...

#: A mode's equivalent deck mass per metre this many times from the others' median is flagged.
MASS_SPREAD = 100.0
#: An equivalent deck mass per metre below this, kg/m, is lighter than any deck (a 1:300
#: aeroelastic model of a 20 t/m deck weighs 0.2 kg/m).
LIGHTEST_DECK = 0.1
#: A damping ratio at or above this is warned of: a whole bridge's modes have 0.2 % to 2 % of
#: critical (EN 1991-1-4, Table F.2: logarithmic decrements 0.02 to 0.1), a few per cent with
#: dampers; 0.1 is what "0.1 %" or "0.5 %" written as a ratio looks like.
IMPLAUSIBLE_DAMPING = 0.1
#: Slips common to every mode that :func:`deck_mass_ratio_warning` tries to undo: the factor
#: to kg of the generalised masses (None: each taken as 1 kg), the factor on the squared
#: translations ``h^2, p^2`` (mm to m: 1e-6), and the message naming the slip.
_COMMON_SLIPS: tuple[tuple[float | None, float, str], ...] = (
    (1e3, 1.0, "the generalised masses look given in tonnes"),
    (None, 1.0, "the shapes look mass-normalised (generalised mass 1 kg) while "
                "generalised_mass gives the finite-element program's modal mass"),
    (1.0, 1e-6, "h and p look given in mm (shapes in m, generalised masses in kg)"),
)
#: The mass ratio an undone slip must reach to be named: a deck's, not merely a possible one.
_TYPICAL_DECK_RATIO = (2.0, 500.0)


def mass_warnings(modes: Sequence[Mode], labels: list[str], B: float, x: FloatArray,
                  defaults: list[str]) -> list[str]:
    """Return the generalised masses that cannot belong with their shapes or the other modes'.

    The equivalent deck mass per metre ``M / int (h^2 + (alpha B/2)^2 + p^2) dx`` (kg/m) puts
    every mode on one scale whatever its normalisation; a mode's that is :data:`MASS_SPREAD`
    times from the median of the others' (or lighter than :data:`LIGHTEST_DECK`) is named with
    its generalised mass. A tower's or a cable's mode with little deck motion is heavy per deck
    metre for a reason: the warning says so.

    Parameters
    ----------
    modes : sequence of Mode
    labels : list of str
        Each mode's name in messages (its file and index).
    B : float
        Deck width, m.
    x : ndarray
        Deck nodes, m.
    defaults : list of str
        The defaults taken (a mass left at its default is said so).

    Returns
    -------
    list of str
        One line per implausible mode.
    """
    per_metre = equivalent_masses(modes, B, x)
    out = []
    for r, mode in enumerate(modes):
        label = f"{labels[r]} ({mode.name})" if mode.name else labels[r]
        default = (" (the default: give the mode's generalised_mass)"
                   if any(d.startswith(f"{label}: no generalised_mass") for d in defaults)
                   else "")
        if per_metre[r] < LIGHTEST_DECK:
            out.append(f"{label}: generalised_mass = {mode.generalised_mass:g} kg{default} gives "
                       f"an equivalent deck mass of {per_metre[r]:.3g} kg/m, lighter than any "
                       f"deck ({LIGHTEST_DECK:g} kg/m): the mass and the shapes in different "
                       "normalisations?")
            continue
        if len(modes) < 2:
            continue
        others = float(np.median(np.delete(per_metre, r)))
        ratio = per_metre[r] / others
        if ratio > MASS_SPREAD or ratio < 1.0 / MASS_SPREAD:
            out.append(f"{label}: generalised_mass = {mode.generalised_mass:g} kg{default} gives "
                       f"an equivalent deck mass of {per_metre[r]:.3g} kg/m, {ratio:.3g} times "
                       f"the median of the other modes' ({others:.3g} kg/m): a mass in other "
                       "units or normalisation, or a mode with little deck motion (a tower's or "
                       "a cable's)?")
    return out


def equivalent_masses(modes: Sequence[Mode], B: float, x: FloatArray,
                       mass_factor: float | None = 1.0,
                       translation_factor: float = 1.0) -> FloatArray:
    """Each mode's equivalent deck mass per metre, ``M / int (h^2 + (alpha B/2)^2 + p^2) dx``.

    Parameters
    ----------
    modes : sequence of Mode
    B : float
        Deck width, m (``alpha B/2`` is the deck edge's displacement in pitch).
    x : ndarray
        Deck nodes, m (trapezoid rule).
    mass_factor : float or None
        Multiplies every generalised mass (None: each taken as 1 kg), to try a unit slip.
    translation_factor : float
        Multiplies ``h^2`` and ``p^2``, to try a unit slip of the translations.

    Returns
    -------
    ndarray, shape (n_modes,)
        kg/m.
    """
    w = trapezoid_weights(x)
    out = []
    for m in modes:
        mass = 1.0 if mass_factor is None else mass_factor * m.generalised_mass
        motion = float(w @ (translation_factor * (m.h**2 + m.p**2) + (m.alpha * B / 2.0) ** 2))
        out.append(mass / motion)
    return np.array(out)


def deck_mass_ratio_warning(modes: Sequence[Mode], B: float, rho: float, x: FloatArray,
                             where: str) -> list[str]:
    """Warn when the modes' equivalent deck mass is no deck's, for a slip common to all.

    :func:`mass_warnings` compares each mode with the others, so a slip made in every mode
    (generalised masses in tonnes: 1000 times lighter; mass-normalised shapes given with the
    finite-element program's modal mass ``M``: ``M`` times heavier) passes it, and the flutter
    speed moves with the mass ratio without a word (the example bridge in tonnes: "no flutter"
    instead of 77 m/s). The median over the modes of the equivalent deck mass per metre, over
    ``rho B^2``, is the deck's mass ratio (19 for the Great Belt's and the example's); outside
    :data:`ident.model.section.MASS_RATIO_RANGE` it is named, with the common slip whose undoing
    brings it to a deck's (:data:`_COMMON_SLIPS`).

    Parameters
    ----------
    modes : sequence of Mode
    B : float
        Deck width, m.
    rho : float
        Air density, kg/m^3.
    x : ndarray
        Deck nodes, m.
    where : str
        The file's prefix (``"bridge.json: "``) or empty.

    Returns
    -------
    list of str
        Empty, or one line.
    """
    def ratio(mass_factor: float | None, translation_factor: float) -> float:
        per_metre = equivalent_masses(modes, B, x, mass_factor, translation_factor)
        return float(np.median(per_metre)) / (rho * B**2)

    mu = ratio(1.0, 1.0)
    if MASS_RATIO_RANGE[0] <= mu <= MASS_RATIO_RANGE[1]:
        return []
    causes = [f"{text}, which undone gives {ratio(factor, square):.3g}"
              for factor, square, text in _COMMON_SLIPS
              if _TYPICAL_DECK_RATIO[0] <= ratio(factor, square) <= _TYPICAL_DECK_RATIO[1]]
    cause = "; or ".join(causes) if causes else "check the units of generalised_mass and h, p"
    return [f"{where}the modes' equivalent deck mass per metre (median {mu * rho * B**2:.3g} "
            f"kg/m) over rho B^2 is a mass ratio of {mu:.3g}, no deck's ({MASS_RATIO_RANGE[0]:g} "
            f"to {MASS_RATIO_RANGE[1]:g}; the example bridge's 19): {cause}; the flutter speed "
            "and the buffeting response depend on it"]


def damping_warning(label: str, damping: float) -> list[str]:
    """Warn of a damping ratio no bridge mode has (a percentage written as a ratio).

    Accepted (a heavily damped mode can be meant), but it decides flutter and buffeting: 0.5
    meant as 0.5 % hid the example bridge's flutter (77 m/s) behind "no flutter".

    Parameters
    ----------
    label : str
        The mode, with its file (``"bridge.json: modes[4] (T1S)"``).
    damping : float
        Its damping ratio (fraction of critical), in [0, 1).

    Returns
    -------
    list of str
        Empty, or one line.
    """
    if damping < IMPLAUSIBLE_DAMPING:
        return []
    return [f"{label}: damping = {damping:g} is {100 * damping:g} % of critical, far above a "
            "bridge mode's structural damping (0.2 % to 2 %): a percentage given as a ratio? "
            f"{damping:g} % is {damping / 100:g}"]
