r"""Density of moist air by the CIPM-2007 equation.

Source: A. Picard, R. S. Davis, M. Glaeser and K. Fujii, "Revised formula for the density of moist
air (CIPM-2007)", Metrologia 45 (2008) 149-155. The equation of state::

    rho = p M_a / (Z R T) [1 - x_v (1 - M_v / M_a)]

with the molar mass of dry air ``M_a = (28.96546 + 12.011 (x_CO2 - 0.0004)) g/mol`` (the argon
content of CIPM-2007), water ``M_v = 18.01528 g/mol``, ``R = 8.314472 J/(mol K)``, the mole
fraction of water vapour ``x_v = h f(p, t) p_sv(T) / p`` from the relative humidity ``h``, the
saturation vapour pressure ``p_sv(T) = exp(A T^2 + B T + C + D / T)`` Pa, the enhancement factor
``f = alpha + beta p + gamma t^2`` and the compressibility factor ``Z`` (the paper's eq. A1.4).
The paper states the formula for 600-1100 hPa and 15-27 degC; its vapour-pressure and
enhancement fits hold over 0-30 degC and serve a wind tunnel well beyond that (the wind tunnel's
humidity itself is rarely known to better than 2 %RH, a 0.02 % density change at 20 degC).

Moist air is lighter than dry air at the same pressure and temperature: at 20 degC and 50 %RH by
about 0.4 %. The dry-air value ``p / (287.058 T)`` that windrig used before is within 0.05 % of
this equation at ``h = 0``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["CO2_MOLE_FRACTION", "R_DRY_AIR", "enhancement_factor", "moist_air_density",
           "saturation_vapour_pressure"]

FloatArray = npt.NDArray[np.float64]

#: Default mole fraction of CO2 in the air (the CIPM-2007 reference composition).
CO2_MOLE_FRACTION = 0.0004
#: Specific gas constant of dry air, J/(kg K): windrig's dry-air density ``p / (R_DRY_AIR T)``
#: (the barometer, the air in the tap tubes, the virtual tunnel), in one place.
R_DRY_AIR = 287.058

_R = 8.314472          # J/(mol K), the value CIPM-2007 adopted
_M_V = 18.01528e-3     # kg/mol, water
# Saturation vapour pressure over water (Picard et al. 2008, eq. A1.2).
_A, _B, _C, _D = 1.2378847e-5, -1.9121316e-2, 33.93711047, -6.3431645e3
# Enhancement factor (eq. A1.3).
_ALPHA, _BETA, _GAMMA = 1.00062, 3.14e-8, 5.6e-7
# Compressibility factor (eq. A1.4).
_A0, _A1, _A2 = 1.58123e-6, -2.9331e-8, 1.1043e-10
_B0, _B1 = 5.707e-6, -2.051e-8
_C0, _C1 = 1.9898e-4, -2.376e-6
_DZ, _EZ = 1.83e-11, -0.765e-8


def saturation_vapour_pressure(temperature_k: Any) -> FloatArray:
    """Saturation vapour pressure of water, Pa, at ``temperature_k`` (K; CIPM-2007 eq. A1.2)."""
    T = np.asarray(temperature_k, dtype=np.float64)
    return np.asarray(np.exp(_A * T**2 + _B * T + _C + _D / T), dtype=np.float64)


def enhancement_factor(pressure_pa: Any, temperature_k: Any) -> FloatArray:
    """Enhancement factor of water vapour in air (dimensionless; CIPM-2007 eq. A1.3)."""
    t = np.asarray(temperature_k, dtype=np.float64) - 273.15
    return np.asarray(_ALPHA + _BETA * np.asarray(pressure_pa, dtype=np.float64) + _GAMMA * t**2,
                      dtype=np.float64)


def moist_air_density(pressure_pa: Any, temperature_k: Any, relative_humidity: Any,
                      co2_mole_fraction: float = CO2_MOLE_FRACTION) -> FloatArray:
    """Density of moist air, kg/m^3 (CIPM-2007; see the module docstring).

    Parameters
    ----------
    pressure_pa : array_like
        Absolute pressure, Pa.
    temperature_k : array_like
        Temperature, K.
    relative_humidity : array_like
        Relative humidity as a fraction (0.5 for 50 %RH), in [0, 1]; NaN gives NaN.
    co2_mole_fraction : float
        Mole fraction of CO2 (default 0.0004).

    Returns
    -------
    ndarray
        kg/m^3, broadcast over the inputs (NaN where an input is NaN).

    Examples
    --------
    >>> round(float(moist_air_density(101325.0, 293.15, 0.0)), 4)
    1.2046
    """
    p = np.asarray(pressure_pa, dtype=np.float64)
    T = np.asarray(temperature_k, dtype=np.float64)
    h = np.asarray(relative_humidity, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        if np.any((h < 0.0) | (h > 1.0)):
            raise ValueError(f"relative_humidity must be a fraction in [0, 1] (0.5 = 50 %RH), "
                             f"got {float(np.nanmax(np.abs(h)))!r}")
    t = T - 273.15
    x_v = h * enhancement_factor(p, T) * saturation_vapour_pressure(T) / p
    Z = (1.0 - p / T * (_A0 + _A1 * t + _A2 * t**2 + (_B0 + _B1 * t) * x_v
                        + (_C0 + _C1 * t) * x_v**2)
         + (p / T) ** 2 * (_DZ + _EZ * x_v**2))
    M_a = (28.96546 + 12.011 * (float(co2_mole_fraction) - 0.0004)) * 1e-3
    return np.asarray(p * M_a / (Z * _R * T) * (1.0 - x_v * (1.0 - _M_V / M_a)),
                      dtype=np.float64)
