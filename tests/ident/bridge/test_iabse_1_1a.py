"""The IABSE superstructure benchmark, step 1.1a, at its full granularity (ident.bridge).

Source: IABSE Task Group 3.1 superstructure benchmark (G. Diana et al., "IABSE Task Group 3.1
benchmark results", Structural Engineering International, 2019/2020), step 1.1a: a 2-DOF
flat-plate section (the data in ``support.iabse``), its flutter speed, the torsional branch's
in-wind frequency and damping ratio at five wind speeds, the vertical turbulence spectrum at one
point, and the buffeting RMS at the five speeds (vertical h, torsional alpha B/2, both in m).
Every published number is in :data:`PUBLISHED` with its tolerance; the tolerances are the
benchmark's: the spread of its participants about the published values.

Computed here from the state space (:func:`ident.bridge.flutter.in_wind_modes`, the flutter
search :func:`ident.bridge.flutter.analyze`) and the frequency domain
(:func:`ident.bridge.buffeting.frequency_domain`), measured on 2026-11-29:

====  ==================  =================  ==================  ==================
U     f_alpha (Hz)        zeta_alpha         RMS vertical (m)    RMS torsional (m)
====  ==================  =================  ==================  ==================
15    0.2744 / 0.279      0.0097 / 0.0096    0.2510 / 0.2603     0.0349 / 0.0419
30    0.2676 / 0.2691     0.0188 / 0.0189    0.7811 / 0.778      0.1840 / 0.2027
45    0.2548 / 0.2561     0.0314 / 0.0309    1.3641 / 1.3404     0.4478 / 0.4792
60    0.2330 / 0.2340     0.0438 / 0.0418    2.1452 / 2.1601     0.8872 / 0.9306
75    0.1988 / 0.1994     0.0158 / 0.0148    4.7746 / 4.4848     2.9489 / 2.8414
====  ==================  =================  ==================  ==================

(computed / published); flutter 77.24 m/s against 77.45 (-0.27 %).

**Why the torsional RMS is below the published one at low wind (-17 % at 15 m/s, -9 % at 30,
-7 % at 45, -5 % at 60, +4 % at 75).** Not a fault of the model, by elimination:

- the response is the flat plate's exactly: an independent section computation with the exact
  Theodorsen function (Hankel functions, not the 8-lag fit) on a dense grid gives the same RMS
  as the 8-lag fit on that grid to 1e-4, and as the default grid within 0.5 %
  (:func:`test_response_is_the_exact_theodorsen_plate`): neither the fit nor the integration
  grid is the cause;
- the torsional response is the moment's own: without the lift's gust forcing it moves by
  0.2-2 % up to 60 m/s (:func:`test_torsion_is_driven_by_the_moment_alone`), so the lift slope,
  the drag terms (C_D enters the lift only) and the sign convention of the coupling do not
  matter to it (the slopes' signs are the plate's quasi-steady limit,
  :func:`test_static_slopes_are_the_plates`);
- it is resonant (83-89 % of the variance within 0.2-0.35 Hz), and the torsional branch's
  frequency and damping agree with the published ones (within 2 % and 5 %), the turbulence
  spectrum within 0.04 % of the published point, and alpha B/2 is a constant factor, which
  cannot make a deficit that changes with U.

What is left is the moment's admittance at the torsional frequency, and the deficit follows it:
it grows with Davenport's argument ``7 f B / U`` there (0.58 at 75 m/s, 4.0 at 15 m/s, where
chi^2 = 0.14). The lift's admittance, the same function, reproduces the published vertical RMS
within 4 % from 15 to 60 m/s, so the participants agree on the lift and differ on the moment.
A milder admittance on the moment alone describes the published torsion: with a decay of 5.4
instead of 7 on the moment (lift unchanged) the torsional RMS agrees within 0.3 % at 30, 45 and
60 m/s and within 4 % at 15 m/s (at 75 m/s, 3 % below flutter, both are within the tolerance
and dominated by the damping there). So the remaining difference is the participants' spread on
the moment's admittance, inside the benchmark's 20 %; windrig keeps Davenport's form with decay
7 on every force, as the benchmark states.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from ident.bridge import buffeting as bf
from ident.bridge import flutter as fl
from ident.bridge.model import BridgeModel
from ident.bridge.statespace import BridgeStateSpace
from ident.model import flat_plate
from ident.model.conventions import Q_from_flutter_derivatives
from ident.model.section import SectionModel
from ident.physics.turbulence import davenport_function, von_karman_w

from support.iabse import IABSE_WIND, INERTIA, MASS, B, iabse_bridge, iabse_state_space

#: The benchmark's published values, step 1.1a (source: the module docstring). Per wind speed
#: (m/s): the torsional branch's in-wind frequency (Hz) and damping ratio with their tolerance,
#: then the RMS vertical displacement and the torsional one (alpha B/2), m. Tolerances: the
#: benchmark's, the spread of its participants: 5 % to 25 % on the frequency and damping (wider
#: towards flutter, where the damping changes fastest), 10 % on the vertical and 20 % on the
#: torsional RMS. Flutter speed (m/s, 1 %) and the vertical turbulence spectrum at 45 m/s and
#: 0.278 Hz ((m/s)^2/Hz, 1 %) in the two rows below the speeds.
PUBLISHED: dict[str, Any] = {
    "speeds": {
        # U: (f_alpha, zeta_alpha, tolerance of both, RMS vertical, RMS torsional)
        15.0: (0.279, 0.0096, 0.05, 0.2603, 0.0419),
        30.0: (0.2691, 0.0189, 0.10, 0.778, 0.2027),
        45.0: (0.2561, 0.0309, 0.10, 1.3404, 0.4792),
        60.0: (0.2340, 0.0418, 0.15, 2.1601, 0.9306),
        75.0: (0.1994, 0.0148, 0.25, 4.4848, 2.8414),
    },
    "flutter_speed": (77.45, 0.01),
    "vertical_spectrum_45_0278": (5.26, 0.01),
    "rms_tolerance": (0.10, 0.20),  # vertical, torsional
}
SPEEDS: list[float] = sorted(PUBLISHED["speeds"])
TORSION = 1  # the pitch mode's index in support.iabse's bridge


@pytest.fixture(scope="module")
def iabse() -> BridgeStateSpace:
    return iabse_state_space()


def test_flutter_speed(iabse: BridgeStateSpace) -> None:
    published, tolerance = PUBLISHED["flutter_speed"]
    result = fl.analyze(iabse.bridge, iabse.model)
    assert result.speed == pytest.approx(published, rel=tolerance)
    assert result.critical_mode == TORSION


def test_torsional_branch_in_wind(iabse: BridgeStateSpace) -> None:
    """In-wind frequency and damping ratio of the torsional branch from the state space."""
    f, zeta = fl.in_wind_modes(iabse.bridge, iabse.model, SPEEDS)
    assert f.shape == zeta.shape == (len(SPEEDS), 2)
    for i, U in enumerate(SPEEDS):
        f_pub, zeta_pub, tolerance, *_ = PUBLISHED["speeds"][U]
        assert f[i, TORSION] == pytest.approx(f_pub, rel=tolerance), U
        assert zeta[i, TORSION] == pytest.approx(zeta_pub, rel=tolerance), U
    # The branches are followed, not sorted: heave stays near 0.1 Hz, damped ever more.
    assert np.all(np.abs(f[:, 0] - 0.1) < 0.02) and np.all(np.diff(zeta[:, 0]) > 0.0)


def test_in_wind_modes_are_eigenvalues_of_the_state_matrix(iabse: BridgeStateSpace) -> None:
    """Each branch value is an eigenvalue of S(U) (to rounding), whatever the order of U."""
    U = np.array([60.0, 0.0, 30.0])
    f, zeta = fl.in_wind_modes(iabse.bridge, iabse.model, U)
    for i, u in enumerate(U):
        lam = iabse.eigenvalues(float(u))
        for r in range(2):
            omega = 2.0 * math.pi * f[i, r]
            target = complex(-zeta[i, r] * omega / math.sqrt(1.0 - zeta[i, r] ** 2), omega)
            assert np.min(np.abs(lam - target)) < 1e-9 * abs(target)
    with pytest.raises(ValueError, match="U must be"):
        fl.in_wind_modes(iabse.bridge, iabse.model, [-1.0])


def test_vertical_turbulence_spectrum() -> None:
    """One-sided in Hz, von Karman, sigma_w = Iw U: the published point, and its variance.

    The one-sided spectrum integrates to sigma_w^2 over [0, inf) (to the rounding of von
    Karman's constants 755.2 and 283.2); the log grid misses ~4 L f_min / U (2e-6 relative)
    below 1e-6 Hz and the f^-5/3 tail above 1e6 Hz, 0.144 (f L / U)^-2/3 (3e-5): tolerance
    1e-3.
    """
    published, tolerance = PUBLISHED["vertical_spectrum_45_0278"]
    U = 45.0
    S_w = IABSE_WIND.gust_spectra(np.array([0.278]), U)[1][0]
    assert S_w == pytest.approx(published, rel=tolerance)
    f = np.geomspace(1e-6, 1e6, 200_001)
    variance = np.trapezoid(IABSE_WIND.gust_spectra(f, U)[1], f)
    assert variance == pytest.approx((0.05 * U) ** 2, rel=1e-3)


@pytest.mark.parametrize("U", SPEEDS)
def test_buffeting_rms(iabse: BridgeStateSpace, U: float) -> None:
    *_, vertical_pub, torsional_pub = PUBLISHED["speeds"][U]
    tol_v, tol_t = PUBLISHED["rms_tolerance"]
    r = bf.frequency_domain(iabse, IABSE_WIND, U)
    vertical, torsional = r.rms_h[0], r.rms_alpha[0] * B / 2.0  # torsion as alpha B/2
    assert vertical == pytest.approx(vertical_pub, rel=tol_v)
    assert torsional == pytest.approx(torsional_pub, rel=tol_t)
    # A uniform deck: both nodes move alike, nothing sways, and the modal RMS are the nodes'.
    assert r.rms_h[1] == pytest.approx(r.rms_h[0], rel=1e-12)
    assert np.all(r.rms_p == 0.0)
    assert r.rms_modal == pytest.approx([r.rms_h[0], r.rms_alpha[0]], rel=1e-9)


def test_static_slopes_are_the_plates(iabse: BridgeStateSpace) -> None:
    """The gust slopes are the self-excited model's quasi-steady limit, in the same signs.

    An upward gust w is a nose-up angle of attack w/U: its force is the plate's A1 alpha column
    (Q(0): lift -2 pi, moment pi/2 about mid-chord, lift positive downward), exactly.
    """
    static = iabse.bridge.static
    assert static is not None
    A1 = np.asarray(iabse.model.A)[0]
    assert (static.dC_L, static.dC_M) == pytest.approx(tuple(A1[:, 1]), rel=1e-15)
    assert bf.gust_gain(static)[:2, 1] == pytest.approx(A1[:, 1], rel=1e-15)


def _exact_section_rms(U: float, f: np.ndarray) -> tuple[float, float]:
    """RMS h (m) and alpha (rad) of the section with the exact Theodorsen plate, by hand.

    Independent of ident.bridge: the section's matrices (q = [h/B, alpha]), Q(iK) from the
    exact flutter derivatives (Hankel functions), the gust force ``[L B, M] = qd B^2/U chi
    [dC_L, dC_M] w`` with Davenport's chi and von Karman's S_w.
    """
    section = SectionModel(B=B, m=MASS, I=INERTIA, fh=0.100, fa=0.278, zeta_h=0.003,
                           zeta_a=0.003, rho=1.22)
    K = 2.0 * np.pi * f * B / U
    Q = Q_from_flutter_derivatives(K, flat_plate.flutter_derivatives(K))
    omega = 2.0 * np.pi * f[:, None, None]
    Z = (-omega**2 * section.mass_matrix() + 1j * omega * section.damping_matrix()
         + section.stiffness_matrix() - 0.5 * 1.22 * U**2 * B**2 * Q)
    H = np.linalg.inv(Z)
    gain = 0.5 * 1.22 * U * B**2 * davenport_function(7.0 * f * B / U)[:, None] * np.array(
        [-2.0 * np.pi, np.pi / 2.0])
    S_w = von_karman_w(f, U, 0.05 * U, 20.0)
    response = np.einsum("fij,fj->fi", H, gain)  # per unit w, (nf, 2)
    S_q = np.abs(response) ** 2 * S_w[:, None]
    return (B * math.sqrt(np.trapezoid(S_q[:, 0], f)),
            math.sqrt(np.trapezoid(S_q[:, 1], f)))


@pytest.mark.parametrize("U", [15.0, 30.0])
def test_response_is_the_exact_theodorsen_plate(iabse: BridgeStateSpace, U: float) -> None:
    """The bridge route (8-lag fit, its pole-packed grid) against the exact plate by hand.

    40 000 log-spaced frequencies put ~35 points in the half-power width of the torsional peak
    at 15 m/s (0.0027 Hz). Tolerance 0.6 %: the default grid's own error (measured +0.5 % at
    15 m/s, 0.01-0.3 % above); the fit's error is ~1e-5.
    """
    f = np.geomspace(1e-4, 3.0, 40_000)
    rms_h, rms_alpha = _exact_section_rms(U, f)
    r = bf.frequency_domain(iabse, IABSE_WIND, U)
    assert r.rms_h[0] == pytest.approx(rms_h, rel=6e-3)
    assert r.rms_alpha[0] == pytest.approx(rms_alpha, rel=6e-3)


def test_torsion_is_driven_by_the_moment_alone(iabse: BridgeStateSpace) -> None:
    """Without the lift's gust forcing (dC_L = 0) the torsional RMS moves by under 3 %.

    Measured 0.2 % at 15 m/s to 2.0 % at 60 m/s (the aeroelastic coupling grows with U).

    So the lift slope, C_D (which enters only the lift) and the relative sign of the lift and
    moment forcing cannot explain the torsional RMS's distance from the published one (module
    docstring); the heave, driven by the lift, loses most of its RMS.
    """
    data = iabse_bridge().to_dict()
    data["static"]["dC_L"] = 0.0
    no_lift = BridgeStateSpace(BridgeModel.from_dict(data), iabse.model)
    for U in SPEEDS[:-1]:  # 75 m/s is 3 % below flutter, where the coupling grows
        full = bf.frequency_domain(iabse, IABSE_WIND, U)
        moment_only = bf.frequency_domain(no_lift, IABSE_WIND, U)
        assert moment_only.rms_alpha[0] == pytest.approx(full.rms_alpha[0], rel=0.03), U
        assert moment_only.rms_h[0] < 0.5 * full.rms_h[0]
