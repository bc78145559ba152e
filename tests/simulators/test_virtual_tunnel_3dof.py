"""The virtual tunnel with sway: p and drag follow the 3-DOF physics, the taps carry the drag.

The bluff deck on its sway spring (:mod:`simulators.decks`) in the tunnel: held at ``(h0,
alpha0, p0)`` it feels ``qd B^2 A1 q0`` in all three rows; released, its sway is the
independently simulated release's (:func:`simulators.tunnel.simulate_release`); the tap
pressures of a rectangle integrate to lift, moment and drag; a flat plate's taps, which cannot
carry a drag, still give lift and moment. A 2-DOF tunnel serves neither ``p`` nor ``drag``.
"""

from __future__ import annotations

import numpy as np
import pytest

from ident import AeroelasticSystem, TapLayout
from ident.model import flat_plate
from simulators.clock import ManualClock
from simulators.decks import BLUFF_DECK_3DOF, bluff_deck_3dof_model
from simulators.tunnel import simulate_release
from simulators.virtual_tunnel import VirtualTunnel

BOX = TapLayout.rectangle(0.45, 0.2, 28)  # the shipped 3-DOF rig's taps: end faces
_X = -0.225 + 0.45 / 28 * (np.arange(28) + 0.5)
#: A thin plate's taps: upper and lower faces only (normals along z), so no drag.
PLATE = TapLayout(x=np.concatenate([_X, _X]), z=np.zeros(56),
                  nx=np.zeros(56), nz=np.concatenate([-np.ones(28), np.ones(28)]),
                  length=np.full(56, 0.45 / 28))
HOLD = (0.006, 0.015, 0.004)


def tunnel(clock, taps=BOX):
    return VirtualTunnel(BLUFF_DECK_3DOF, bluff_deck_3dof_model(), taps, wind_per_rpm=0.01,
                         hold=HOLD, clock=clock, decay_duration_s=8.0)


def test_the_held_model_feels_the_static_force_in_three_rows():
    clock = ManualClock()
    vt = tunnel(clock)
    vt.set_fan_speed(900.0)
    values = vt.sample(np.array([0.0]))
    assert values["p"][0] == HOLD[2]
    system = AeroelasticSystem(vt.section, bluff_deck_3dof_model(), 9.0)
    expected = system.forces(system.initial_state(*HOLD), np.zeros(3))
    B = BLUFF_DECK_3DOF.B
    assert values["lift"][0] == pytest.approx(expected[0] / B, rel=1e-12)
    assert values["moment"][0] == pytest.approx(expected[1], rel=1e-12)
    assert values["drag"][0] == pytest.approx(expected[2] / B, rel=1e-12)


def test_the_released_sway_is_the_simulated_release():
    clock = ManualClock()
    vt = tunnel(clock)
    vt.set_fan_speed(900.0)
    clock.advance(1.0)
    t0 = vt.release()
    t = t0 + np.linspace(0.0, 5.0, 201)
    moving = vt.sample(t)
    reference = simulate_release(vt.section, bluff_deck_3dof_model(), 9.0, *HOLD[:2],
                                 p0=HOLD[2], duration=5.0 + 1e-3, fs=1000.0)
    # Cubic splines of 1 kHz samples of <= 3.6 Hz motion: relative error ~ (w dt)^4 ~ 3e-7.
    assert reference.p is not None and reference.drag is not None
    np.testing.assert_allclose(moving["p"], np.interp(t - t0, reference.t, reference.p),
                               atol=1e-8)
    np.testing.assert_allclose(moving["drag"], np.interp(t - t0, reference.t, reference.drag),
                               atol=2e-4 * np.max(np.abs(reference.drag)))
    truth = vt.decay_truth(t)
    np.testing.assert_array_equal(truth["p"], moving["p"])
    vt.arm()
    assert np.all(vt.sample(t)["p"] == HOLD[2])


def test_tap_pressures_integrate_to_lift_moment_and_drag():
    clock = ManualClock()
    vt = tunnel(clock)
    assert vt.pressures_carry_drag
    vt.set_fan_speed(900.0)
    clock.advance(1.0)
    t = vt.release() + np.arange(50) / 500.0
    p, _ = vt.pressures(t)
    values = vt.sample(t)
    lift, moment = BOX.integrate(p)
    np.testing.assert_allclose(lift, values["lift"], atol=1e-9)
    np.testing.assert_allclose(moment, values["moment"], atol=1e-9)
    np.testing.assert_allclose(BOX.integrate_drag(p), values["drag"], atol=1e-9)
    assert np.ptp(values["drag"]) > 0.01  # the drag moves: the check is not of zeros


def test_a_plates_taps_carry_no_drag_but_lift_and_moment_still():
    clock = ManualClock()
    vt = tunnel(clock, PLATE)
    assert not PLATE.carries_drag and not vt.pressures_carry_drag
    vt.set_fan_speed(900.0)
    clock.advance(1.0)
    t = vt.release() + np.arange(50) / 500.0
    p, _ = vt.pressures(t)
    lift, moment = PLATE.integrate(p)
    values = vt.sample(t)
    np.testing.assert_allclose(lift, values["lift"], atol=1e-9)
    np.testing.assert_allclose(moment, values["moment"], atol=1e-9)


def test_a_2dof_tunnel_has_no_sway_and_refuses_a_sway_hold():
    clock = ManualClock()
    section = BLUFF_DECK_3DOF.replace(fp=None, zeta_p=None, m_p=None)
    vt = VirtualTunnel(section, flat_plate.jones_model(), BOX, wind_per_rpm=0.01,
                       hold=HOLD[:2], clock=clock)
    assert set(vt.sample(np.array([0.0]))) == {"h", "alpha", "lift", "moment", "U", "qd"}
    with pytest.raises(ValueError, match=r"hold must be \(h0, alpha0\) or, with sway"):
        VirtualTunnel(section, flat_plate.jones_model(), BOX, wind_per_rpm=0.01, hold=HOLD,
                      clock=clock)
