"""Moist-air density (CIPM-2007, ident.physics.air) against published values."""

from __future__ import annotations

import numpy as np
import pytest

from ident.physics.air import moist_air_density, saturation_vapour_pressure


@pytest.mark.parametrize(("t_c", "p_kpa"), [(10.0, 1.2282), (20.0, 2.3393), (30.0, 4.2470)])
def test_saturation_vapour_pressure_matches_the_iapws_steam_table(t_c, p_kpa):
    """The CIPM-2007 vapour pressure against the IAPWS-95 saturation table.

    IAPWS-95 saturation pressures (Wagner and Pruss, J. Phys. Chem. Ref. Data 31 (2002),
    the saturation table), given to 5 digits: 0.02 % covers their rounding and the CIPM fit's
    own deviation from IAPWS-95 over 0-30 degC (Picard et al. 2008 quote it as negligible).
    """
    assert float(saturation_vapour_pressure(t_c + 273.15)) == pytest.approx(p_kpa * 1e3,
                                                                            rel=2e-4)


def test_moist_air_density_matches_an_independent_psychrometric_value():
    """Moist air at 20 degC, 101325 Pa, 70 %RH against an independent formulation.

    1.19714 kg/m^3 from the ASHRAE Handbook's formulation
    (Hyland-Wexler, real-gas moist air), as published in the documentation example of the
    Psychro.jl package (``compressfactor(MoistAir, 293.15, RelHum, 0.7, 101325.0)``). Two
    independent real-gas formulations agree to about 1e-4; 0.03 % is the tolerance (the
    difference measured here is 0.007 %).
    """
    assert float(moist_air_density(101325.0, 293.15, 0.7)) == pytest.approx(1.19714, rel=3e-4)


def test_dry_air_limit_and_the_humidity_effect():
    """The dry-air limit, the humidity's and the CO2's effects.

    At 0 %RH the density is the dry-air value windrig used before, p / (287.058 T), to within
    0.05 % (CIPM-2007 adds the compressibility, ~0.04 %, and its argon-corrected molar mass);
    at 20 degC and 50 %RH moist air is lighter by x_v (1 - M_v/M_a) = 0.0116 x 0.378 = 0.44 %
    (x_v from the vapour pressure 2339 Pa and the enhancement factor 1.004), the ~0.4 % the
    barometer driver documents.
    """
    dry = float(moist_air_density(101325.0, 293.15, 0.0))
    assert dry == pytest.approx(101325.0 / (287.058 * 293.15), rel=5e-4)
    moist = float(moist_air_density(101325.0, 293.15, 0.5))
    assert 1.0 - moist / dry == pytest.approx(0.0044, abs=0.0008)
    # the CO2 term: 100 umol/mol more CO2 adds 12.011e-4/28.96546 of the molar mass, 4.1e-5
    more_co2 = float(moist_air_density(101325.0, 293.15, 0.5, co2_mole_fraction=0.0005))
    assert more_co2 / moist - 1.0 == pytest.approx(1.2011e-3 / 28.96546, rel=0.05)


def test_nan_passes_and_a_percentage_is_refused():
    assert np.isnan(moist_air_density(101325.0, np.nan, 0.5))
    with pytest.raises(ValueError, match="fraction in \\[0, 1\\]"):
        moist_air_density(101325.0, 293.15, 50.0)
