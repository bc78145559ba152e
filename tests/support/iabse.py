"""The IABSE superstructure benchmark's step 1.1a as a bridge: a flat-plate deck section.

The benchmark (IABSE Task Group 3.1, Diana et al. 2019/2020) step 1.1a: a 2-DOF section with
B = 31 m, m = 22 740 kg/m, I = 2.47e6 kg m^2/m, f_h = 0.10 Hz, f_alpha = 0.278 Hz, both damped
0.3 % of critical, rho = 1.22 kg/m^3, in vertical turbulence only (von Karman, Iw = 0.05,
Lwx = 20 m, full span-wise coherence) with Davenport's admittance of decay 7 on every force.
As a bridge it is a uniform deck 1 m long with one heave and one pitch mode of shape 1 (per unit
span, the section itself), the flat plate's static slopes in windrig's signs (lift positive
downward: dC_L = -2 pi; moment nose-up about mid-chord: dC_M = pi/2) and its self-excited forces
from :func:`ident.model.flat_plate.theodorsen_model` (the exact Theodorsen function as an 8-lag
rational fit, within 5e-5 of it). The published values are in the test module that checks them
(``tests/ident/bridge/test_iabse_1_1a.py``).
"""

from __future__ import annotations

import math

from ident.bridge.model import BridgeModel
from ident.bridge.statespace import BridgeStateSpace
from ident.bridge.wind import wind_from_dict
from ident.model import flat_plate
from ident.physics.turbulence import TurbulenceSpec

#: Deck width (m), mass (kg/m) and polar inertia (kg m^2/m) of the benchmark's section.
B, MASS, INERTIA = 31.0, 22740.0, 2.47e6


def iabse_bridge() -> BridgeModel:
    """Return the benchmark's section as a uniform bridge 1 m long (two modes: heave, pitch)."""
    return BridgeModel.from_dict({
        "name": "IABSE 1.1a", "B": B, "rho": 1.22, "nodes_x": [0.0, 1.0],
        "modes": [{"frequency": 0.100, "damping": 0.003, "generalised_mass": MASS,
                   "h": [1.0, 1.0]},
                  {"frequency": 0.278, "damping": 0.003, "generalised_mass": INERTIA,
                   "alpha": [1.0, 1.0]}],
        "static": {"C_D": 0.0, "C_L": 0.0, "C_M": 0.0, "dC_D": 0.0, "dC_L": -2.0 * math.pi,
                   "dC_M": math.pi / 2.0}})


def iabse_state_space() -> BridgeStateSpace:
    """Return the benchmark's bridge with the exact flat plate (8-lag Theodorsen fit)."""
    return BridgeStateSpace(iabse_bridge(), flat_plate.theodorsen_model())


#: The benchmark's wind: vertical gusts only, fully coherent along the span, Davenport's
#: admittance of decay 7 on every force (u is absent: Iu = 0, its length scale unused).
IABSE_WIND: TurbulenceSpec = wind_from_dict({
    "Iu": 0.0, "Iw": 0.05, "Lux": 1.0, "Lwx": 20.0, "Cuy": 0.0, "Cwy": 0.0,
    "admittance": {"kind": "davenport", "decay": 7.0}})
