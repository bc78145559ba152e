"""Three degrees of freedom: sway and drag in the section, the model, the state space and flutter.

Independent checks: the 18-derivative layout against DESIGN's force formulas written out term by
term; the quasi-steady model against the forces of the relative wind computed without
linearisation (small motion); the 3-DOF flat plate against the 2-DOF one (exactly equal when
nothing couples sway); the state-space flutter speed against the frequency-domain one (Scanlan's
iteration on K) on sections where sway couples.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from ident.model import flat_plate
from ident.model import flutter as fl
from ident.model.conventions import (
    FLUTTER_DERIVATIVE_NAMES_3DOF,
    Q_from_flutter_derivatives,
    flutter_derivatives_from_Q,
)
from ident.model.quasi_steady import (
    StaticCoefficients,
    quasi_steady_derivatives,
    quasi_steady_model,
)
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.model.statespace import AeroelasticSystem
from ident.physics.taps import TapLayout
from ident.records.release import Release
from ident.simulation.decay import simulate_decay
from simulators.tunnel import simulate_release

from support.sections import FLAT_PLATE

PLANAR = FLAT_PLATE  # the 2-DOF section that SWAY adds a sway mode to
SWAY = PLANAR.replace(fp=1.3, zeta_p=0.004)
#: A bluff deck's static coefficients at its mean angle (lift down positive, per radian).
BLUFF = StaticCoefficients(C_D=0.9, C_L=-0.15, C_M=0.02, dC_D=-0.4, dC_L=-4.5, dC_M=1.1)


def test_a_section_without_fp_is_2dof_and_sway_only_adds_a_row_and_column():
    assert PLANAR.n_dof == 2 and SWAY.n_dof == 3
    for name in ("mass_matrix", "damping_matrix", "stiffness_matrix"):
        big, small = getattr(SWAY, name)(), getattr(PLANAR, name)()
        assert big.shape == (3, 3)
        np.testing.assert_array_equal(big[:2, :2], small)
        np.testing.assert_array_equal(big[2, :2], 0.0)
    B, w = SWAY.B, 2 * math.pi * 1.3
    assert SWAY.stiffness_matrix()[2, 2] == pytest.approx(3.0 * w**2 * B**2, rel=1e-14)
    assert SWAY.damping_matrix()[2, 2] == pytest.approx(2 * 3.0 * 0.004 * w * B**2, rel=1e-14)
    assert SWAY.replace(m_p=5.0).mass_matrix()[2, 2] == pytest.approx(5.0 * B**2, rel=1e-14)
    assert "fp" not in PLANAR.to_dict()
    assert SectionModel.from_dict(SWAY.to_dict()) == SWAY
    assert SWAY.planar() == PLANAR
    with pytest.raises(ValueError, match="zeta_p needs fp"):
        PLANAR.replace(zeta_p=0.01)
    with pytest.raises(ValueError, match="fp must be > 0"):
        PLANAR.replace(fp=-1.0)


def test_the_18_derivatives_are_designs_force_formulas():
    """Harmonic motion of amplitude (h, alpha, p): forces from DESIGN's three lines vs Q q."""
    rng = np.random.default_rng(7)
    fd = {name: float(rng.normal()) for name in FLUTTER_DERIVATIVE_NAMES_3DOF}
    K, U, B, rho = 0.7, 9.0, 0.3, 1.2
    omega = K * U / B
    qd = 0.5 * rho * U**2
    h, alpha, p = 0.004 + 0.001j, 0.02 - 0.005j, -0.003 + 0.002j  # complex amplitudes
    dot = 1j * omega  # d/dt of exp(i omega t)
    H = {i: fd[f"H{i}"] for i in range(1, 7)}
    A = {i: fd[f"A{i}"] for i in range(1, 7)}
    P = {i: fd[f"P{i}"] for i in range(1, 7)}
    L = qd * B * (K * H[1] * dot * h / U + K * H[2] * B * dot * alpha / U + K**2 * H[3] * alpha
                  + K**2 * H[4] * h / B + K * H[5] * dot * p / U + K**2 * H[6] * p / B)
    M = qd * B**2 * (K * A[1] * dot * h / U + K * A[2] * B * dot * alpha / U
                     + K**2 * A[3] * alpha + K**2 * A[4] * h / B + K * A[5] * dot * p / U
                     + K**2 * A[6] * p / B)
    D = qd * B * (K * P[1] * dot * p / U + K * P[2] * B * dot * alpha / U + K**2 * P[3] * alpha
                  + K**2 * P[4] * p / B + K * P[5] * dot * h / U + K**2 * P[6] * h / B)
    Q = Q_from_flutter_derivatives([K], fd)[0]
    f = qd * B**2 * Q @ np.array([h / B, alpha, p / B])
    np.testing.assert_allclose(f, [L * B, M, D * B], rtol=1e-12)
    back = flutter_derivatives_from_Q([K], Q[None])
    assert set(back) == set(fd)
    for name, value in fd.items():
        assert back[name][0] == pytest.approx(value, rel=1e-12)


def _relative_wind_forces(static: StaticCoefficients, U: float, B: float, rho: float,
                          h_dot: float, alpha: float, p_dot: float) -> np.ndarray:
    """Quasi-steady [L, M, D] from the relative wind, without linearising (independent check).

    The deck sees the wind (U - p_dot) downwind and h_dot upward; the coefficients are linear
    in the angle of attack (the static slopes) and act along (drag) and across (lift) it.
    """
    Ux, Uz_up = U - p_dot, h_dot
    V2 = Ux**2 + Uz_up**2
    phi = math.atan2(Uz_up, Ux)  # the relative wind comes from below by phi
    a_e = alpha + phi
    C_D = static.C_D + static.dC_D * a_e
    C_L = static.C_L + static.dC_L * a_e
    C_M = static.C_M + static.dC_M * a_e
    q = 0.5 * rho * V2
    D_w, L_w = q * B * C_D, q * B * C_L  # along the wind; across it, "down" sense
    # Turn back: the wind direction is (cos phi, -sin phi) in (downwind, down) axes.
    D = D_w * math.cos(phi) + L_w * math.sin(phi)
    L = -D_w * math.sin(phi) + L_w * math.cos(phi)
    return np.array([L, q * B**2 * C_M, D])


@pytest.mark.parametrize("static", [BLUFF, StaticCoefficients.flat_plate(C_D=0.05)],
                         ids=["bluff", "plate"])
def test_quasi_steady_model_is_the_linearised_relative_wind(static):
    """Forces of small motions (velocities 1e-4 of U): the linear model to 1e-3 of the change.

    The exact forces differ from the linear ones at second order, ~1e-4 of the change for
    velocities 1e-4 of U: 1e-3 leaves a factor 10, and a wrong sign or a missing term (an
    error of order 1 of some entry) cannot pass.
    """
    U, B, rho = 10.0, SWAY.B, SWAY.rho
    model = quasi_steady_model(static)
    system = AeroelasticSystem(SWAY, model, U)
    rest = _relative_wind_forces(static, U, B, rho, 0.0, 0.0, 0.0)
    for h_dot, alpha, p_dot in ((1e-3, 0, 0), (0, 1e-4, 0), (0, 0, 1e-3), (7e-4, -5e-5, 6e-4)):
        z = np.zeros(system.n_states)
        z[1], z[3], z[5] = alpha, h_dot / B, p_dot / B
        f = system.forces(z, np.zeros(3))  # [L B, M, D B]
        change = _relative_wind_forces(static, U, B, rho, h_dot, alpha, p_dot) - rest
        linear = f / np.array([B, 1.0, B])
        scale = np.max(np.abs(change))
        np.testing.assert_allclose(linear, change, rtol=0.0, atol=1e-3 * scale)


def test_quasi_steady_derivatives_are_the_textbook_ones():
    """Simiu and Scanlan's quasi-steady expressions (written with lift up, converted)."""
    K = np.array([0.3, 1.0, 2.5])
    fd = quasi_steady_derivatives(BLUFF, K)
    up_C_L, up_dC_L = -BLUFF.C_L, -BLUFF.dC_L
    np.testing.assert_allclose(fd["P1"], -2 * BLUFF.C_D / K, rtol=1e-13)
    np.testing.assert_allclose(fd["P3"], BLUFF.dC_D / K**2, rtol=1e-13)
    np.testing.assert_allclose(fd["P5"], (BLUFF.dC_D - up_C_L) / K, rtol=1e-13)
    np.testing.assert_allclose(fd["H1"], -(up_dC_L + BLUFF.C_D) / K, rtol=1e-13)
    np.testing.assert_allclose(fd["H3"], -up_dC_L / K**2, rtol=1e-13)
    np.testing.assert_allclose(fd["H5"], 2 * up_C_L / K, rtol=1e-13)
    np.testing.assert_allclose(fd["A1"], BLUFF.dC_M / K, rtol=1e-13)
    np.testing.assert_allclose(fd["A5"], -2 * BLUFF.C_M / K, rtol=1e-13)
    for name in ("H2", "H4", "H6", "A2", "A4", "A6", "P2", "P4", "P6"):
        np.testing.assert_array_equal(fd[name], 0.0)


def _plate_3dof(static: StaticCoefficients) -> RationalFunctionModel:
    return flat_plate.jones_model().with_sway(quasi_steady_model(static))


def test_uncoupled_sway_leaves_the_2dof_flutter_speed_exactly():
    """Friction drag only (no lift, moment or drag slope): sway feels only its own damping."""
    plate = StaticCoefficients(C_D=0.05, C_L=0.0, C_M=0.0, dC_D=0.0, dC_L=-2 * math.pi,
                               dC_M=math.pi / 2)
    three = fl.analyze(SWAY, _plate_3dof(plate))
    two = fl.analyze(PLANAR, flat_plate.jones_model())
    assert three.speed == pytest.approx(two.speed, rel=1e-10)
    assert three.frequency == pytest.approx(two.frequency, rel=1e-10)
    assert three.critical_mode == two.critical_mode == "pitch"
    assert three.mode_names == ("heave", "pitch", "sway")
    np.testing.assert_allclose(three.damping[:, :2], two.damping, atol=1e-9)
    # The sway branch: structural plus drag damping, zeta = zeta_p + rho U C_D B / (2 m_p w_p)
    # (from P1* = -2 C_D / K), never unstable.
    U = three.U[1:]
    expected = 0.004 + 1.225 * U * 0.05 * 0.3 / (2 * 3.0 * 2 * math.pi * 1.3)
    np.testing.assert_allclose(three.damping[1:, 2], expected, rtol=1e-6)


@pytest.mark.parametrize("static", [BLUFF, StaticCoefficients.flat_plate(C_D=0.3)],
                         ids=["bluff-coefficients", "plate-drag"])
def test_state_space_and_frequency_domain_agree_in_3dof(static):
    """The same 3-DOF model two ways: the speeds agree to 1e-6.

    Both refine to ~1e-12; the K grid and Brent's tolerances leave far less than 1e-6.
    """
    model = _plate_3dof(static)
    section = SWAY.replace(S=0.01)  # unbalance couples heave and pitch structurally too
    ss = fl.analyze(section, model)
    fd = fl.frequency_domain(section, model.flutter_derivatives)
    assert ss.speed is not None and fd.speed is not None
    assert fd.speed == pytest.approx(ss.speed, rel=1e-6)
    assert fd.frequency == pytest.approx(ss.frequency, rel=1e-6)
    assert fd.critical_mode == ss.critical_mode


def test_sway_coupling_moves_the_flutter_speed_and_both_methods_see_it():
    """A lift that depends on sway (C_L != 0) and a drag slope move the flutter speed.

    The 3-DOF speed differs from the 2-DOF one by more than 1e-4 (the coupling is physical, not
    round-off), and the frequency domain agrees.
    """
    coupled = StaticCoefficients(C_D=0.5, C_L=-0.4, C_M=0.1, dC_D=-1.5,
                                 dC_L=-2 * math.pi, dC_M=math.pi / 2)
    section = SWAY.replace(fp=3.6)  # sway near pitch: coupling matters
    three = fl.analyze(section, _plate_3dof(coupled))
    two = fl.analyze(PLANAR, flat_plate.jones_model())
    assert three.speed is not None and two.speed is not None
    assert abs(three.speed / two.speed - 1.0) > 1e-4
    fd = fl.frequency_domain(section, _plate_3dof(coupled).flutter_derivatives)
    assert fd.speed == pytest.approx(three.speed, rel=1e-6)


def test_models_and_sections_must_match():
    """A 2-DOF model on a 3-DOF section is refused; 3-DOF on 2-DOF uses its heave-pitch block."""
    with pytest.raises(ValueError, match="no sway or drag terms"):
        AeroelasticSystem(SWAY, flat_plate.jones_model(), 5.0)
    model = _plate_3dof(BLUFF)
    a = fl.analyze(PLANAR, model)
    b = fl.analyze(PLANAR, model.planar())
    assert a.speed == b.speed
    assert model.planar() == flat_plate.jones_model()
    with pytest.raises(ValueError, match="p0 must be 0"):
        AeroelasticSystem(PLANAR, model, 5.0).initial_state(0.01, 0.0, 0.002)
    z0 = AeroelasticSystem(SWAY, model, 5.0).initial_state(0.01, 0.02, 0.003)
    np.testing.assert_allclose(z0[:3], [0.01 / 0.3, 0.02, 0.01])
    with pytest.raises(ValueError, match="give all 18"):
        fl.frequency_domain(SWAY, flat_plate.jones_model().flutter_derivatives)


def test_a_release_with_sway_carries_p_and_drag():
    """Both or neither; coordinates and forces in windrig's generalised form."""
    t = np.arange(400) / 100.0
    h, alpha = 0.01 * np.cos(9 * t), 0.02 * np.cos(20 * t)
    p, drag = 0.003 * np.cos(7 * t), 0.4 * np.sin(7 * t)
    r = Release(t=t, h=h, alpha=alpha, lift=h, moment=alpha, U=5.0, p=p, drag=drag)
    assert r.n_dof == 3
    np.testing.assert_allclose(r.coordinates(0.3), np.column_stack([h / 0.3, alpha, p / 0.3]))
    np.testing.assert_allclose(r.generalised_forces(0.3)[:, 2], drag * 0.3)
    planar = Release(t=t, h=h, alpha=alpha, lift=h, moment=alpha, U=5.0)
    assert planar.n_dof == 2 and planar.coordinates(0.3).shape == (400, 2)
    with pytest.raises(ValueError, match="both p and drag"):
        Release(t=t, h=h, alpha=alpha, lift=h, moment=alpha, U=5.0, p=p)
    with pytest.raises(ValueError, match="drag contains 1 non-finite"):
        Release(t=t, h=h, alpha=alpha, lift=h, moment=alpha, U=5.0, p=p,
                drag=np.where(t == t[5], np.nan, drag))


def test_3dof_decay_with_uncoupled_sway_is_the_2dof_decay():
    """Nothing couples sway: the heave and pitch channels are the 2-DOF record's.

    Friction drag only, released with p0 = 0: the four channels equal the 2-DOF record to
    round-off (1e-9 of their range), and p and drag stay exactly zero.
    """
    plate = StaticCoefficients(C_D=0.05, C_L=0.0, C_M=0.0, dC_D=0.0, dC_L=-2 * math.pi,
                               dC_M=math.pi / 2)
    three = simulate_decay(SWAY, _plate_3dof(plate), 8.0, 0.004, 0.02, n=1500, fs=250.0)
    two = simulate_decay(PLANAR, flat_plate.jones_model(), 8.0, 0.004, 0.02, n=1500, fs=250.0)
    for name in ("h", "alpha", "lift", "moment"):
        scale = float(np.max(np.abs(getattr(two, name))))
        np.testing.assert_allclose(getattr(three, name), getattr(two, name), rtol=0,
                                   atol=1e-9 * scale)
    assert three.p is not None and three.drag is not None
    assert np.max(np.abs(three.p)) == 0.0 and np.max(np.abs(three.drag)) == 0.0


def test_3dof_decay_agrees_with_an_independent_integrator():
    """The exact stepping agrees with an independent integrator on a coupled 3-DOF deck.

    scipy's solve_ivp (DOP853, rtol 1e-11) on the same state space: the displacements agree
    to 1e-7 of their range (the integrator's tolerance, far above round-off).
    """
    model = _plate_3dof(BLUFF)
    U, fs, n = 9.0, 200.0, 1200
    decay = simulate_decay(SWAY, model, U, 0.003, 0.015, n=n, fs=fs, p0=0.002)
    system = AeroelasticSystem(SWAY, model, U)
    A = system.matrix()
    sol = solve_ivp(lambda _, z: A @ z, (0.0, (n - 1) / fs), system.initial_state(0.003, 0.015,
                    0.002), t_eval=np.arange(n) / fs, method="DOP853", rtol=1e-11, atol=1e-14)
    assert decay.p is not None
    for got, row, scale in ((decay.h, 0, SWAY.B), (decay.alpha, 1, 1.0), (decay.p, 2, SWAY.B)):
        expected = sol.y[row] * scale
        np.testing.assert_allclose(got, expected, rtol=0,
                                   atol=1e-7 * float(np.ptp(expected)))
    assert float(np.ptp(decay.p)) > 1e-4  # sway moved: the coupling is in the record


def test_3dof_release_in_the_wind_holds_its_mean_drag_and_taps_carry_it():
    """The held model feels the mean drag plus that of its held pitch; taps carry the drag.

    Held at alpha0 = 0.01 rad: D = qd B (C_D + dC_D alpha0) (the quasi-steady slope, 0.44 %
    here); a box outline's pressures integrate back to the recorded drag and lift.
    """
    U = 7.0
    sim = simulate_release(SWAY, _plate_3dof(BLUFF), U, 0.0, 0.01, duration=4.0, fs=200.0,
                           static=BLUFF, pre_s=0.5)
    assert sim.drag is not None and sim.p is not None
    held = sim.t < 0
    qd_B = 0.5 * SWAY.rho * U**2 * SWAY.B
    np.testing.assert_allclose(sim.drag[held], qd_B * (BLUFF.C_D + BLUFF.dC_D * 0.01),
                               rtol=1e-12)
    box = TapLayout.rectangle(B=0.3, D=0.05, taps_per_face=12)
    pressures = sim.pressures(box)
    np.testing.assert_allclose(box.integrate_drag(pressures), sim.drag,
                               atol=1e-9 * float(np.max(np.abs(sim.drag))))
    lift, _ = box.integrate(pressures)
    np.testing.assert_allclose(lift, sim.lift, atol=1e-9 * float(np.max(np.abs(sim.lift))))
