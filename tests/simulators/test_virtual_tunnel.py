"""The virtual tunnel holds, releases and re-arms the model consistently with the physics."""

from __future__ import annotations

import numpy as np
import pytest

from ident import AeroelasticSystem, TapLayout
from ident.model import flat_plate
from simulators.clock import DeviceClock, ManualClock
from simulators.tunnel import simulate_release
from simulators.virtual_tunnel import AirState, VirtualTunnel

from support.sections import FLAT_PLATE

TAPS = TapLayout.rectangle(0.3, 0.01, 16)


def tunnel(clock):
    return VirtualTunnel(FLAT_PLATE, flat_plate.jones_model(), TAPS, wind_per_rpm=0.01,
                         hold=(0.004, 0.02), clock=clock, decay_duration_s=10.0)


def test_held_model_is_static_and_release_follows_the_simulated_decay():
    """Before release: hold position; after: the simulate_release decay at the fan's wind."""
    clock = ManualClock()
    vt = tunnel(clock)
    vt.set_fan_speed(700.0)
    clock.advance(3.0)
    held = vt.sample(np.array([1.0, 2.0]))
    assert np.all(held["alpha"] == 0.02) and np.all(held["U"] == pytest.approx(7.0))
    t0 = vt.release()
    assert not vt.armed and vt.release_times() == [t0]
    t = t0 + np.linspace(0.0, 5.0, 101)
    moving = vt.sample(t)
    reference = simulate_release(vt.section, flat_plate.jones_model(), 7.0, 0.004, 0.02,
                                 duration=5.0 + 1e-3, fs=1000.0)
    # Cubic splines of 1 kHz samples of a ~3 Hz signal: error ~ (w dt)^4 ~ 1e-8 relative.
    np.testing.assert_allclose(moving["alpha"], np.interp(t - t0, reference.t, reference.alpha),
                               atol=2e-6)
    assert vt.section.rho == pytest.approx(AirState().density)
    vt.arm()
    assert vt.armed and np.all(vt.sample(t)["alpha"] == 0.02)


def test_a_sample_taken_before_the_catch_still_shows_the_free_decay():
    """Instruments sample a little in the past: the catch must not reach back before the arm.

    A laser's or scanner's sample time lies a few ms before the moment it asks; a tunnel that
    answered with its present (held) state put a step into the decay's last rows, before the
    arm command (seen in recorded campaigns: a release's modal-fit residual 19 times its noise).
    """
    clock = ManualClock()
    vt = tunnel(clock)
    vt.set_fan_speed(700.0)
    clock.advance(1.0)
    t0 = vt.release()
    clock.advance(2.0)
    t = t0 + np.array([1.0, 1.5, 1.99, 2.0, 2.5])
    before = vt.sample(t[:3])
    vt.arm()
    after = vt.sample(t)
    np.testing.assert_array_equal(after["alpha"][:3], before["alpha"])
    assert np.all(after["alpha"][:3] != 0.02)
    assert np.all(after["alpha"][3:] == 0.02) and np.all(after["h"][3:] == 0.004)
    # A second release: the first decay stays where it was, the second starts at its release.
    clock.advance(1.0)
    t1 = vt.release()
    clock.advance(1.0)
    both = vt.sample(np.array([t0 + 1.0, t1 - 0.5, t1 + 0.5]))
    assert both["alpha"][0] == before["alpha"][0] and both["alpha"][1] == 0.02
    assert both["alpha"][2] != 0.02


def test_the_wind_follows_the_fan_after_a_release_too():
    """A fan stopped while the model is free stops the wind (it stayed at the release's)."""
    clock = ManualClock()
    vt = tunnel(clock)
    vt.set_fan_speed(500.0)
    clock.advance(1.0)
    t0 = vt.release()
    clock.advance(2.0)
    vt.set_fan_speed(0.0)
    later = vt.sample(np.array([t0 + 2.5]))
    assert later["U"][0] == 0.0 and later["qd"][0] == 0.0
    _, qd = vt.pressures(np.array([t0 + 2.5]))
    assert qd[0] == 0.0
    # The decay itself goes on as computed (a wind change during a decay is not modelled).
    assert later["alpha"][0] != 0.02


def test_tap_pressures_integrate_to_the_forces_and_pitot_reads_qd():
    """Scanner-side truth: taps integrate to lift and moment, the Pitot to rho U^2 / 2."""
    clock = ManualClock()
    vt = tunnel(clock)
    vt.set_fan_speed(800.0)
    clock.advance(1.0)
    t0 = vt.release()
    t = t0 + np.arange(50) / 500.0
    p, qd = vt.pressures(t)
    lift, moment = TAPS.integrate(p)
    values = vt.sample(t)
    np.testing.assert_allclose(lift, values["lift"], atol=1e-9)
    np.testing.assert_allclose(moment, values["moment"], atol=1e-9)
    np.testing.assert_allclose(qd, 0.5 * AirState().density * 8.0**2)
    assert np.ptp(p, axis=1).min() > 0.1 * qd[0]  # a real distribution, not a constant


def test_static_force_of_the_held_model():
    """Held in the wind, the model feels qd B^2 A1 q0 (no motion, lag states at rest)."""
    clock = ManualClock()
    vt = tunnel(clock)
    vt.set_fan_speed(600.0)
    values = vt.sample(np.array([0.0]))
    system = AeroelasticSystem(vt.section, flat_plate.jones_model(), 6.0)
    expected = system.forces(system.initial_state(0.004, 0.02), np.zeros(2))
    assert values["lift"][0] == pytest.approx(expected[0] / FLAT_PLATE.B, rel=1e-12)
    assert values["moment"][0] == pytest.approx(expected[1], rel=1e-12)


def test_device_clock_maps_both_ways():
    """Offset and drift: t_dev = offset + (1 + ppm 1e-6) t, and back."""
    c = DeviceClock(offset_s=0.02, drift_ppm=50.0)
    assert c.device_time(100.0) == pytest.approx(0.02 + 100.005)
    assert c.true_time(c.device_time(123.4)) == pytest.approx(123.4, abs=1e-12)
    with pytest.raises(ValueError, match="cannot go back"):
        ManualClock().advance(-1.0)


def turbulent_tunnel(clock, seed=3, **kwargs):
    from ident.model.quasi_steady import StaticCoefficients
    from ident.physics.turbulence import TurbulenceSpec

    spec = TurbulenceSpec(Iu=0.1, Iw=0.08, Lux=0.6, Lwx=0.25, Cuy=10.0, Cwy=8.0)
    return VirtualTunnel(FLAT_PLATE, flat_plate.jones_model(), TAPS, wind_per_rpm=0.01,
                         hold=(0.004, 0.02), clock=clock, decay_duration_s=4.0,
                         static=StaticCoefficients.flat_plate(), turbulence=spec, span=1.0,
                         seed=seed, **kwargs)


def test_turbulence_buffets_the_held_model_and_the_taps_integrate_to_the_forces():
    """Held: motionless, fluctuating forces (same seed, same forces); taps integrate to them."""
    clock = ManualClock()
    vts = [turbulent_tunnel(clock), turbulent_tunnel(clock), turbulent_tunnel(clock, seed=4)]
    for vt in vts:
        vt.set_fan_speed(600.0)
    clock.advance(5.0)
    t = np.linspace(1.0, 5.0, 2001)
    samples = [vt.sample(t) for vt in vts]
    held = samples[0]
    assert np.all(held["alpha"] == 0.02) and np.all(held["h"] == 0.004)
    assert held["moment"].std() > 0.05 * abs(held["moment"].mean())
    np.testing.assert_array_equal(held["moment"], samples[1]["moment"])
    assert not np.allclose(held["moment"], samples[2]["moment"])
    p, _ = vts[0].pressures(t)
    lift, moment = TAPS.integrate(p)
    np.testing.assert_allclose(lift, held["lift"], atol=1e-9 * np.abs(held["lift"]).max())
    np.testing.assert_allclose(moment, held["moment"], atol=1e-9 * np.abs(held["moment"]).max())


def test_turbulence_keeps_the_model_moving_after_the_computed_decay():
    """After decay_duration_s the response goes on (continued, not frozen) and is continuous.

    Samples 1 ms apart across the seam have second differences no larger than those over a
    second of the later response: no jump where the computed decay ends and the continuation
    begins.
    """
    clock = ManualClock()
    vt = turbulent_tunnel(clock)
    vt.set_fan_speed(600.0)
    clock.advance(2.0)
    t0 = vt.release()
    clock.advance(5.0)  # instruments sample the recent past, in time order
    seam_t = t0 + vt._decay.duration + np.arange(-5, 6) * 1e-3
    seam = vt.sample(seam_t)
    clock.advance(15.0)
    late = vt.sample(t0 + np.linspace(8.0, 18.0, 5001))
    assert late["alpha"].std() > 0.1 * 0.02  # a random response, not a frozen model
    # Across the seam alpha moves as it does elsewhere: its second differences stay within
    # those of a later stretch sampled alike (a jump at the seam would show as one large one).
    elsewhere = vt.sample(t0 + 15.0 + np.arange(-500, 501) * 1e-3)["alpha"]
    assert np.abs(np.diff(seam["alpha"], 2)).max() < 1.5 * np.abs(np.diff(elsewhere, 2)).max()
    # A second tunnel with the same seed and history gives the same motion.
    clock2 = ManualClock()
    vt2 = turbulent_tunnel(clock2)
    vt2.set_fan_speed(600.0)
    clock2.advance(2.0)
    t0_2 = vt2.release()
    clock2.advance(20.0)
    np.testing.assert_array_equal(vt2.sample(t0_2 + np.linspace(8.0, 18.0, 5001))["alpha"],
                                  late["alpha"])
    with pytest.raises(ValueError, match="needs static"):
        VirtualTunnel(FLAT_PLATE, flat_plate.jones_model(), TAPS, wind_per_rpm=0.01,
                      turbulence=vt._gusts.spec, span=1.0, seed=1)
