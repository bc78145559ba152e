"""Measurement noise keyed to (release, sample): a seed gives the same decay whatever the timing."""

from __future__ import annotations

import numpy as np
import pytest

from ident import TapLayout
from ident.model import flat_plate
from simulators.clock import DeviceClock, ManualClock
from simulators.devices.microepsilon_ild1420 import SimMicroEpsilonIld1420
from simulators.noise import KeyedNoise, sample_keys
from simulators.virtual_tunnel import VirtualTunnel

from support.sections import FLAT_PLATE

TAPS = TapLayout.rectangle(0.3, 0.01, 16)


def test_a_sample_s_noise_depends_on_its_key_only_not_on_the_batches():
    noise = KeyedNoise(key=11, width=3, chunk=100)
    epoch = np.array([0] * 250 + [1] * 250)
    index = np.concatenate([np.arange(250), np.arange(250)])
    whole = noise.normal(epoch, index)
    # Drawn again in other batches and orders, from a fresh instance (no cache shared).
    other = KeyedNoise(key=11, width=3, chunk=100)
    parts = [other.normal(epoch[i:i + 37], index[i:i + 37]) for i in range(0, 500, 37)[::-1]]
    np.testing.assert_array_equal(np.concatenate(parts[::-1]), whole)
    # Another epoch, or another key, is another realisation.
    assert not np.allclose(whole[:250], whole[250:])
    assert not np.allclose(KeyedNoise(key=12, width=3, chunk=100).normal(epoch, index), whole)
    # Standard normal: 1500 values, the mean's std is 0.026 and the variance's 0.037; 4 of them.
    assert abs(whole.mean()) < 0.11 and whole.var() == pytest.approx(1.0, abs=0.15)


def test_keys_count_the_samples_from_the_last_release_on_the_device_clock():
    clock = DeviceClock(offset_s=3.0, drift_ppm=50.0)
    rate = 1000.0
    releases = [2.00031, 7.5]
    # 12 s of a drifting device's grid: true times of device times k / rate.
    tau = np.arange(0.0, 12.0, 1.0 / rate) + clock.device_time(0.0)
    t_true = clock.true_time(tau)
    epoch, index = sample_keys(releases, t_true, tau, clock.device_time(np.array(releases)),
                               rate)
    for e, t0 in enumerate(releases, start=1):
        mine = epoch == e
        # The index is the sample's time since the release in periods, rounded: the noise
        # stays with the time after the release (to half a period), whatever the grid's phase.
        assert t_true[mine].min() >= t0
        phase = (clock.device_time(t_true[mine][0]) - clock.device_time(t0)) * rate
        assert index[mine][0] == round(phase) and 0 <= phase < 1
        # One index per sample, consecutive (the drift does not skip or repeat one).
        np.testing.assert_array_equal(np.diff(index[mine]), 1)
    assert np.all(epoch[t_true < releases[0]] == 0)


def _laser(seed: int) -> tuple[SimMicroEpsilonIld1420, VirtualTunnel, ManualClock]:
    clock = ManualClock()
    tunnel = VirtualTunnel(FLAT_PLATE, flat_plate.jones_model(), TAPS, wind_per_rpm=0.01,
                           clock=clock, decay_duration_s=3.0)
    tunnel.set_fan_speed(600.0)
    laser = SimMicroEpsilonIld1420(tunnel, range_mm=50, rate_hz=4000.0, x=0.1,
                                   standoff_mm=25.0, rng=seed)
    return laser, tunnel, clock


def _run(seed: int, hold_s: float, step_s: float) -> dict[int, float]:
    """Hold ``hold_s``, release, sample 2 s in steps of ``step_s``; return the noise after.

    The noise (mm) by the sample's time since the release in periods, rounded (the laser's
    clock is the true one).
    """
    laser, tunnel, clock = _laser(seed)
    for _ in range(int(round(hold_s / step_s))):
        clock.advance(step_s)
        laser._produce(clock.now())  # the sensor's sampling step, without its thread
    t0 = tunnel.release()
    for _ in range(int(round(2.0 / step_s))):
        clock.advance(step_s)
        laser._produce(clock.now())
    truth = laser.truth()
    after = truth.t_true >= t0
    physics = tunnel.sample(truth.t_true[after])
    clean = 25.0 + 1000.0 * (physics["h"] + 0.1 * physics["alpha"])
    index = np.rint((truth.t_true[after] - t0) * 4000.0).astype(int)
    return dict(zip(index.tolist(), (truth.distance_mm[after] - clean).tolist(), strict=True))


def test_a_seed_gives_the_same_noise_on_a_decay_whatever_the_release_timing():
    # Released after 0.7 s or 1.33337 s of hold (other counts of samples drawn before, another
    # place of the 4 kHz grid), the sensor woken every 3 ms or 11 ms.
    noise_a = _run(5, 0.7, 0.003)
    noise_b = _run(5, 1.33337, 0.011)
    common = sorted(set(noise_a) & set(noise_b))
    assert len(common) > 7900  # 2 s at 4 kHz, less the ends
    # The same noise on the sample at the same time after the release (to the round-off of
    # adding it to ~25 mm: 4e-15 mm).
    a = np.array([noise_a[k] for k in common])
    np.testing.assert_allclose(a, [noise_b[k] for k in common], rtol=0, atol=1e-12)
    # Another seed: another realisation of the same level (2.5e-5 x 50 mm = 1.25 um).
    noise_c = _run(6, 0.7, 0.003)
    assert not np.allclose([noise_c[k] for k in common], a)
    assert np.std(a) == pytest.approx(1.25e-3, rel=0.05)  # 8000 samples: 0.8 % std
