"""The virtual tunnel's tap pressures behind pneumatic tubes: the tubes' response, causally."""

from __future__ import annotations

import numpy as np
import pytest

from ident import TapLayout
from ident.model import flat_plate
from ident.physics.tubing import Air, Tube, TubingGroup, distort, tubing_set
from simulators.clock import ManualClock
from simulators.tubing import FIR_DT_S, impulse_response
from simulators.virtual_tunnel import AirState, VirtualTunnel

from support.sections import FLAT_PLATE

TAPS = TapLayout.rectangle(0.3, 0.01, 16)
TUBE = Tube(length=1.0, diameter=1e-3, volume=300e-9)
AIR = AirState()


def _tunnel(clock, tubing=None):
    return VirtualTunnel(FLAT_PLATE, flat_plate.jones_model(), TAPS, wind_per_rpm=0.01,
                         hold=(0.004, 0.02), clock=clock, decay_duration_s=6.0, air=AIR,
                         tubing=tubing)


def test_the_impulse_response_is_causal_passes_a_steady_pressure_and_has_the_tubes_response():
    """Sum 1 (H(0) = 1); its DFT matches H to 1e-3 where the tunnel's channels have content."""
    tubes = tubing_set([TubingGroup(None, TUBE)], 1)
    h = impulse_response(TUBE, tubes)
    assert h.sum() == pytest.approx(1.0, abs=1e-12)
    assert 0.01 < h.size * FIR_DT_S < 0.5  # dies out in tens of ms
    f = np.array([2.0, 4.0, 30.0, 80.0])
    dft = np.exp(-2j * np.pi * np.outer(f, np.arange(h.size) * FIR_DT_S)) @ h
    # Tolerance: the cut tail holds 1e-5 of the response; the renormalisation moves it ~1e-5.
    np.testing.assert_allclose(dft, TUBE.response(f, tubes.air), atol=1e-3)


def test_tubed_tap_pressures_are_the_tubes_distortion_of_the_true_ones():
    """Through a release: the streamed pressures equal the offline FFT distortion (ident).

    Taps 0..9 on the tube, the rest none. Two identical tunnels on one manual clock, one
    with tubes, released together; its pressures against ``ident.physics.tubing.distort`` of the
    other's on a 2 kHz grid. Tolerance 1e-3 of the dynamic pressures' range: both are the
    same convolution, discretised differently (the FIR cut at a 1e-5 tail and rolled off
    above 250 Hz, the FFT on the padded record).
    """
    clock = ManualClock()
    tubing = tubing_set([TubingGroup(tuple(range(10)), TUBE)], TAPS.n_taps,
                        Air(pressure_pa=AIR.pressure_pa, temperature_k=AIR.temperature_k))
    plain, tubed = _tunnel(clock), _tunnel(clock, tubing)
    for vt in (plain, tubed):
        vt.set_fan_speed(700.0)
    clock.advance(2.0)
    t0 = plain.release()
    assert tubed.release() == t0
    clock.advance(4.0)
    fs = 2000.0
    t = t0 - 0.5 + np.arange(int(3.0 * fs)) / fs
    truth, _ = plain.pressures(t)
    seen, _ = tubed.pressures(t)
    expected = distort(truth, fs, tubing)
    scale = float(np.ptp(truth[:, :10]))
    # The force jumps at the release (a step of acceleration through the added mass), content
    # up to the grid rate, which the FIR rolls off above 250 Hz: 5e-3 for 10 ms there.
    step = (t >= t0) & (t < t0 + 0.01)
    np.testing.assert_allclose(seen[~step], expected[~step], atol=1e-3 * scale)
    np.testing.assert_allclose(seen[step], expected[step], atol=5e-3 * scale)
    # No tube, no change (to round-off: the same map, written as one matrix product).
    np.testing.assert_allclose(seen[:, 10:], truth[:, 10:], rtol=1e-12, atol=1e-12 * scale)
    # The tube matters: at 4 Hz it lags 6.4 degrees, 4.4 ms, i.e. ~2.8 % of the swing.
    assert np.max(np.abs(seen[:, :10] - truth[:, :10])) > 0.01 * scale
    # Any block of times gives the same answer (no hidden filter state).
    again, _ = tubed.pressures(t[1000:1010])
    np.testing.assert_array_equal(again, seen[1000:1010])
