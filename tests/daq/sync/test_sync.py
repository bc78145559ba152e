"""Synchronisation (daq.sync): clock maps, counters, the sync view and its physical conversions.

Simulated device streams use :class:`simulators.clock.DeviceClock`; the host clock is the true time.
A block arrives ``floor + Exp(1 ms)`` after its last sample, 1 % of blocks 50 ms more (the reader
stalls, then the following blocks arrive in a burst behind it).

Tolerance of the clock mapping, 0.2 ms (the issue's requirement), and where it comes from: the
sync view is what identification reads, and a timing error tau between the forces (scanner) and
the motion (lasers) rotates the measured force by ``omega tau``. At the highest modal frequency of
the rig configs (pitch, 4 Hz) 0.2 ms is 5 mrad (0.29 deg): the quadrature (aerodynamic damping)
part of the force moves by 0.5 % of its in-phase part, below the few-percent release-to-release
scatter of free-decay identification. It is also a tenth of the sync period (2 ms at 500 Hz) and
below one laser sample (0.25 ms). The laser's own trigger evidence is quantised to one sample
(+-0.125 ms after the mid-interval correction), so the tolerance leaves room for it and for a
host-side pulse-time uncertainty of +-50 us.
"""

from __future__ import annotations

import math
import pickle
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pytest
from scipy import stats

from daq.errors import SyncError
from daq.instruments.reading import Gap
from daq.sync.clock_map import ClockMap, trigger_times_from_flags, trigger_times_from_latch
from daq.sync.conversions import (
    air_density,
    forces_from_pressures,
    heave_pitch_from_lasers,
    wind_speed,
)
from daq.sync.counters import CounterStep, CounterUnwrapper, find_gaps, unwrap_counter
from daq.sync.resample import Resampler, StreamSpec, SyncBlock, resample
from ident.physics.taps import TapLayout
from simulators.clock import DeviceClock

FloatArray = npt.NDArray[np.float64]

TOLERANCE_S = 0.2e-3


# ------------------------------------------------------------------------------------------------
# Simulated devices
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SimDevice:
    clock: DeviceClock
    rate_hz: float
    block_len: int  # samples per block read by the host
    floor_s: float  # transport latency floor
    tick_s: float  # device timestamp resolution


LASER = SimDevice(DeviceClock(offset_s=0.020, drift_ppm=50.0), 4000.0, 40, 0.4e-3, 1e-5)
# A PTP-timed scanner: device times ~1.7e9 s test the numerical conditioning of the map.
SCANNER = SimDevice(DeviceClock(offset_s=1.7e9 + 0.020, drift_ppm=-35.0), 500.0, 5, 0.15e-3, 1e-9)


def device_time(clock: DeviceClock, t_true: FloatArray) -> FloatArray:
    """DeviceClock.device_time for arrays."""
    return clock.offset_s + (1.0 + 1e-6 * clock.drift_ppm) * np.asarray(t_true)


def samples(dev: SimDevice, duration_s: float) -> tuple[FloatArray, FloatArray]:
    """Device time stamps (uniform on the device clock, quantised) and true sample times."""
    n = int(duration_s * dev.rate_hz)
    d_start = dev.clock.device_time(0.05)
    d = d_start + np.arange(n) / dev.rate_hz
    d = np.floor(d / dev.tick_s + 1e-6) * dev.tick_s
    return d, (d - dev.clock.offset_s) / (1.0 + 1e-6 * dev.clock.drift_ppm)


def block_pairs(dev: SimDevice, d: FloatArray, t_true: FloatArray, rng: np.random.Generator, *,
                mean_s: float = 1e-3, outlier_p: float = 0.01, outlier_s: float = 0.05
                ) -> tuple[FloatArray, FloatArray]:
    """(device time of each block's last sample, host arrival time)."""
    last = np.arange(dev.block_len - 1, d.size, dev.block_len)
    latency = (dev.floor_s + rng.exponential(mean_s, last.size)
               + np.where(rng.random(last.size) < outlier_p, outlier_s, 0.0))
    return d[last], np.maximum.accumulate(t_true[last] + latency)


def laser_anchor_times(dev: SimDevice, d: FloatArray, t_true: FloatArray,
                       pulses: FloatArray) -> FloatArray:
    """Anchor device times from the laser flag on the first sample at or after each pulse."""
    flag = np.zeros(d.size, dtype=bool)
    flag[np.searchsorted(t_true, pulses, side="left")] = True
    return trigger_times_from_flags(d, flag, 1.0 / dev.rate_hz)


def scanner_anchor_times(dev: SimDevice, t_true: FloatArray, pulses: FloatArray) -> FloatArray:
    """Anchor device times from the scanner's latched last-trigger time, repeated per frame."""
    pulse_dev = np.round(device_time(dev.clock, pulses) / 1e-9) * 1e-9
    last = np.searchsorted(pulses, t_true, side="right") - 1
    latched = np.where(last >= 0, pulse_dev[np.maximum(last, 0)], np.nan)
    return trigger_times_from_latch(latched)


def pulse_times(rng: np.random.Generator, start: float, stop: float, every: float) -> FloatArray:
    """PLC pulses every ``every`` s, at a random phase to the devices' sampling (as in reality)."""
    base = np.arange(start, stop, every)
    return base + rng.uniform(0.0, 0.5, base.size)


def feed(cm: ClockMap, pairs: tuple[FloatArray, FloatArray], anchors: list[tuple[float, float]],
         chunk_s: float, check: tuple[FloatArray, FloatArray] | None = None,
         check_from_s: float = math.inf) -> float:
    """Feed pairs in chunks of ``chunk_s`` device seconds, each anchor once its block arrived.

    Returns the worst misalignment of the samples mapped right after each chunk (as the engine
    maps them), from ``check_from_s`` of true time on.
    """
    d, h = pairs
    pending = sorted(anchors)
    worst = 0.0
    edges = np.arange(d[0], d[-1] + chunk_s, chunk_s)
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        sel = (d >= lo) & (d < hi)
        cm.update(d[sel], h[sel])
        while pending and pending[0][0] < hi:
            cm.add_anchor(*pending.pop(0))
        if check is not None:
            ds, ts = check
            now = (ds >= lo) & (ds < hi) & (ts >= check_from_s)
            if np.any(now):
                worst = max(worst, float(np.max(np.abs(cm.to_host(ds[now]) - ts[now]))))
    return worst


# ------------------------------------------------------------------------------------------------
# ClockMap
# ------------------------------------------------------------------------------------------------
def test_mapping_misalignment_with_trigger_anchors_is_within_tolerance() -> None:
    """The issue requirement: < 0.2 ms against the truth, for both devices, live and at the end."""
    rng = np.random.default_rng(20261101)
    duration = 300.0
    pulses = pulse_times(rng, 10.0, duration - 5.0, 10.0)  # one PLC pulse every 10 s
    host_pulses = pulses + rng.uniform(-50e-6, 50e-6, pulses.size)  # known to +-50 us
    worst_live, worst_end = {}, {}
    maps = {}
    for name, dev in (("laser", LASER), ("scanner", SCANNER)):
        d, t = samples(dev, duration)
        if name == "laser":
            anchor_dev = laser_anchor_times(dev, d, t, pulses)
        else:
            anchor_dev = scanner_anchor_times(dev, t, pulses)
        assert anchor_dev.size == pulses.size
        anchors = list(zip(anchor_dev.tolist(), host_pulses.tolist(), strict=True))
        cm = ClockMap()
        # Live: from the third pulse on (the floor is then a median of three anchors).
        worst_live[name] = feed(cm, block_pairs(dev, d, t, rng), anchors, 1.0,
                                check=(d, t), check_from_s=pulses[2] + 1.0)
        worst_end[name] = float(np.max(np.abs(cm.to_host(d) - t)))
        maps[name] = (cm, d, t)
        assert cm.n_anchors == pulses.size
        assert abs(cm.latency_floor_s - dev.floor_s) < 0.1e-3
        assert cm.residual_s < 50e-6
    for name in maps:
        assert worst_live[name] < TOLERANCE_S, (name, worst_live[name])
        assert worst_end[name] < TOLERANCE_S, (name, worst_end[name])
    # Relative alignment of the two devices at common true times (what the sync view needs).
    t_common = np.linspace(20.0, duration - 1.0, 2000)
    mapped = {}
    for name, (cm, _, _) in maps.items():
        dev = LASER if name == "laser" else SCANNER
        mapped[name] = cm.to_host(device_time(dev.clock, t_common))
    assert np.max(np.abs(mapped["laser"] - mapped["scanner"])) < TOLERANCE_S


def test_anchors_are_what_removes_the_latency_floor() -> None:
    """Without anchors the map is late by the transport floor, which arrivals cannot reveal."""
    rng = np.random.default_rng(3)
    d, t = samples(LASER, 120.0)
    cm = ClockMap()
    pairs = block_pairs(LASER, d, t, rng)
    cm.update(*pairs)
    late = cm.to_host(d) - t
    assert np.median(late) == pytest.approx(LASER.floor_s, abs=30e-6)
    assert np.max(np.abs(late)) > TOLERANCE_S  # 0.4 ms floor: out of tolerance
    known = ClockMap(assumed_floor_s=LASER.floor_s)  # e.g. a measured USB latency
    known.update(*pairs)
    assert np.max(np.abs(known.to_host(d) - t)) < 50e-6


def test_envelope_fit_beats_least_squares_and_plain_theil_sen() -> None:
    """Why a windowed lower envelope: exponential jitter and outliers bias the usual fits.

    No latency floor here, so the envelope alone should be right. Least squares on all pairs is
    late by the mean latency (1 ms + 1 % x 50 ms + the bursts behind each stall); Theil-Sen on all
    pairs by the median latency (~0.7 ms). A few corrupted device timestamps (a pair that looks
    20 ms *early*) would capture a fit through the absolute minimum; the robust fit of window
    minima outvotes them.
    """
    rng = np.random.default_rng(11)
    dev = SimDevice(LASER.clock, 4000.0, 40, 0.0, 1e-5)
    d, t = samples(dev, 300.0)
    pd, ph = block_pairs(dev, d, t, rng)
    bad = rng.choice(pd.size, 8, replace=False)
    pd = pd.copy()
    pd[bad] += 0.020  # corrupted timestamps: the blocks look 20 ms early
    x = pd - pd[0]
    ols = np.polyfit(x, ph, 1)
    ols_err = np.max(np.abs(np.polyval(ols, d - pd[0]) - t))
    every = slice(None, None, 20)  # Theil-Sen is O(n^2): 1500 pairs show its bias as well
    ts = stats.theilslopes(ph[every], x[every], method="joint")  # intercept: median residual
    ts_err = np.max(np.abs(ts.intercept + ts.slope * (d - pd[0]) - t))
    cm = ClockMap()
    cm.update(pd, ph)
    env_err = np.max(np.abs(cm.to_host(d) - t))

    assert ols_err > 1e-3
    assert ts_err > 0.5e-3
    assert env_err < 30e-6
    assert cm.drift_ppm == pytest.approx(50.0, abs=0.5)


def test_drift_is_estimated_within_a_few_ppm_after_a_few_minutes() -> None:
    rng = np.random.default_rng(5)
    for dev in (LASER, SCANNER):
        d, t = samples(dev, 180.0)
        cm = ClockMap()
        cm.update(*block_pairs(dev, d, t, rng))
        assert cm.drift_ppm == pytest.approx(dev.clock.drift_ppm, abs=1.0)
        assert cm.n_pairs == d.size // dev.block_len


def test_incremental_updates_equal_one_batch_and_converge() -> None:
    rng = np.random.default_rng(8)
    d, t = samples(LASER, 120.0)
    pd, ph = block_pairs(LASER, d, t, rng)
    pulses = pulse_times(rng, 5.0, 115.0, 10.0)
    anchors = list(zip(laser_anchor_times(LASER, d, t, pulses).tolist(), pulses.tolist(),
                       strict=True))
    batch = ClockMap()
    batch.update(pd, ph)
    step = ClockMap()
    errors, drifts = [], []
    for i in range(pd.size):  # one update per block, as the engine does
        step.update(pd[i], ph[i])
        if i % 250 == 249:  # every 2.5 s
            errors.append(abs(step.to_host(float(d[0])) - float(t[0])))
            drifts.append(abs(step.drift_ppm - 50.0))
    assert step.offset_s == batch.offset_s and step.drift_ppm == batch.drift_ppm
    assert step.n_pairs == batch.n_pairs == pd.size
    # Convergence: the drift error shrinks with the span (~1/T); late estimates stay put.
    assert drifts[0] > 5 * drifts[-1]
    assert max(drifts[-10:]) < 1.0
    assert max(errors[-10:]) - min(errors[-10:]) < 20e-6
    for a in anchors:
        step.add_anchor(*a)
    assert abs(step.to_host(float(d[0])) - float(t[0])) < TOLERANCE_S


def test_state_size_does_not_grow_with_updates() -> None:
    """Two hours of pairs and hundreds of anchors: the map's state stays the same size."""
    rng = np.random.default_rng(9)
    clock = DeviceClock(offset_s=0.02, drift_ppm=50.0)
    cm = ClockMap(window_s=10.0, n_windows=20, max_anchors=16)
    sizes = []
    rate = 20.0  # pairs per second
    for minute in range(120):
        t = minute * 60.0 + np.arange(0.0, 60.0, 1.0 / rate)
        d = clock.offset_s + (1.0 + 50e-6) * t
        cm.update(d, t + 0.3e-3 + rng.exponential(1e-3, t.size))
        cm.add_anchor(float(d[0]), float(t[0]))
        cm.add_anchor(float(d[600]), float(t[600]))
        if minute in (59, 119):
            sizes.append(len(pickle.dumps(cm)))
    assert sizes[0] == sizes[1]
    assert cm.n_windows_held == 20 and cm.n_anchors == 16
    assert cm.n_pairs == 120 * 60 * rate
    t_end = 7199.0
    assert abs(cm.to_host(clock.offset_s + (1.0 + 50e-6) * t_end) - t_end) < 20e-6
    assert cm.drift_ppm == pytest.approx(50.0, abs=0.5)
    # offset_s extrapolates the map back to host time 0 (2 h ago): slope error x 2 h.
    assert cm.offset_s == pytest.approx(0.02, abs=0.2e-3)


def test_cross_device_anchor_aligns_lasers_to_the_scanner() -> None:
    """When the PLC pulse's host time is uncertain (ms), tie the lasers to the scanner instead.

    The scanner stamps the pulse to the nanosecond, so its map (envelope only, late by its
    floor) gives the pulse's host time; the lasers anchored on that agree with the scanner.
    """
    rng = np.random.default_rng(21)
    duration = 120.0
    pulses = pulse_times(rng, 10.0, duration - 5.0, 10.0)
    d_s, t_s = samples(SCANNER, duration)
    d_l, t_l = samples(LASER, duration)
    scanner = ClockMap()
    scanner.update(*block_pairs(SCANNER, d_s, t_s, rng))
    host_of_pulse = scanner.to_host(scanner_anchor_times(SCANNER, t_s, pulses))
    laser = ClockMap()
    laser.update(*block_pairs(LASER, d_l, t_l, rng))
    for dev_t, host_t in zip(laser_anchor_times(LASER, d_l, t_l, pulses), host_of_pulse,
                             strict=True):
        laser.add_anchor(float(dev_t), float(host_t))
    t_common = np.linspace(5.0, duration - 1.0, 1000)
    gap = (laser.to_host(device_time(LASER.clock, t_common))
           - scanner.to_host(device_time(SCANNER.clock, t_common)))
    assert np.max(np.abs(gap)) < TOLERANCE_S


def test_floor_from_the_anchors_of_the_shortest_round_trips() -> None:
    """Uncertain anchors late by up to half their round trip do not move the floor.

    A PLC pulse's host time is the midpoint of a Modbus round trip; on a loaded host the legs
    are unequal and the midpoint is off by up to half the round trip, one-sided. Twelve anchors:
    four with 0.2 ms round trips (their midpoints off by <= 0.1 ms), eight with 6-8 ms round
    trips off by 1-3 ms. The median over all is pulled late (0.5 ms here); the map's floor comes
    from the least uncertain third and says how far it may be off.
    """
    rng = np.random.default_rng(5)
    duration = 60.0
    d, t = samples(LASER, duration)
    cm = ClockMap()
    cm.update(*block_pairs(LASER, d, t, rng))
    pulses = pulse_times(rng, 5.0, duration - 5.0, 4.0)[:12]
    dev_t = laser_anchor_times(LASER, d, t, pulses)
    round_trip = np.where(np.arange(12) % 3 == 0, 0.2e-3, rng.uniform(6e-3, 8e-3, 12))
    error = np.where(round_trip < 1e-3, rng.uniform(-0.1e-3, 0.1e-3, 12),
                     rng.uniform(1e-3, 3e-3, 12))  # the host time given late
    assert np.all(np.abs(error) <= round_trip / 2)
    for k in range(12):
        cm.add_anchor(float(dev_t[k]), float(pulses[k] + error[k]), float(round_trip[k] / 2))
    t_check = np.linspace(5.0, duration - 5.0, 200)
    mapped = cm.to_host(device_time(LASER.clock, t_check))
    # 0.1 ms from the anchors, the laser flag's +-half sample (0.125 ms) and the envelope.
    assert np.max(np.abs(mapped - t_check)) < 0.3e-3
    assert cm.anchor_uncertainty_s == pytest.approx(0.1e-3)
    # Without the uncertainties (all equal) the median of all is the late majority's.
    plain = ClockMap()
    plain.update(*block_pairs(LASER, d, t, np.random.default_rng(5)))
    for k in range(12):
        plain.add_anchor(float(dev_t[k]), float(pulses[k] + error[k]))
    assert np.median(plain.to_host(device_time(LASER.clock, t_check)) - t_check) > 0.4e-3
    with pytest.raises(ValueError, match="uncertainty"):
        cm.add_anchor(1.0, 1.0, -1e-3)


def test_clock_map_conventions_inverse_and_reset() -> None:
    clock = DeviceClock(offset_s=3.0, drift_ppm=-20.0)
    t = np.linspace(0.0, 100.0, 5001)
    d = clock.offset_s + (1.0 - 20e-6) * t
    cm = ClockMap(window_s=1.0)
    with pytest.raises(SyncError, match="no block pair and no anchor"):
        cm.to_host(1.0)
    assert not cm.ready
    cm.update(d, t)
    assert cm.ready
    assert cm.offset_s == pytest.approx(clock.offset_s, abs=1e-9)
    assert cm.drift_ppm == pytest.approx(clock.drift_ppm, abs=1e-6)
    assert cm.to_device(cm.to_host(12.5)) == pytest.approx(12.5, abs=1e-12)
    assert cm.to_host(d[:3]).shape == (3,)
    assert isinstance(cm.to_host(5.0), float)
    cm.reset()
    assert not cm.ready and cm.n_pairs == 0


def test_clock_map_from_anchors_only_and_input_checks() -> None:
    cm = ClockMap()
    cm.add_anchor(10.0, 2.0)
    assert cm.to_host(11.0) == pytest.approx(3.0)  # slope 1 until there is more evidence
    cm.add_anchor(1010.0, 1002.0 - 0.05)
    assert cm.drift_ppm == pytest.approx(50.0, rel=1e-3)
    assert math.isnan(cm.residual_s)
    with pytest.raises(ValueError, match="equal shapes"):
        cm.update([1.0, 2.0], [1.0])
    with pytest.raises(ValueError, match="not finite"):
        cm.update([1.0, np.nan], [1.0, 2.0])
    with pytest.raises(ValueError, match="finite"):
        cm.add_anchor(math.nan, 1.0)
    for bad in ({"window_s": 0.0}, {"n_windows": 2}, {"max_anchors": 0},
                {"assumed_floor_s": -1e-3}):
        with pytest.raises(ValueError):
            ClockMap(**bad)  # type: ignore[arg-type]


def test_trigger_time_helpers() -> None:
    d = np.arange(10) * 0.25e-3
    flag = np.zeros(10, bool)
    flag[[3, 7]] = True
    assert trigger_times_from_flags(d, flag, 0.25e-3) == pytest.approx([0.625e-3, 1.625e-3])
    latched = [np.nan, np.nan, 5.0, 5.0, 5.0, 7.5, 7.5, 9.0]
    assert trigger_times_from_latch(latched).tolist() == [5.0, 7.5, 9.0]
    assert trigger_times_from_latch(latched, after=7.5).tolist() == [9.0]
    with pytest.raises(ValueError, match="shape"):
        trigger_times_from_flags(d, flag[:5], 0.25e-3)


# ------------------------------------------------------------------------------------------------
# Counters
# ------------------------------------------------------------------------------------------------
def test_unwrap_across_wraps_without_gaps() -> None:
    u = unwrap_counter([14, 15, 0, 1, 2, 7, 8], 16)
    assert u.counter.tolist() == [14, 15, 16, 17, 18, 23, 24]
    assert u.gaps == (Gap(after_counter=18, length=4),)
    assert u.steps == ()


def test_unwrap_reports_gaps_repeats_and_backsteps() -> None:
    u = unwrap_counter([5, 6, 6, 4, 9, 0], 16)  # steps 1, 0, -2, +5, +7 (forward: 1..7)
    assert u.counter.tolist() == [5, 6, 6, 4, 9, 16]
    assert u.gaps == (Gap(4, 4), Gap(9, 6))
    assert u.steps == (CounterStep(index=2, after_counter=6, step=0),
                       CounterStep(index=3, after_counter=6, step=-2))
    assert len(u.counter) == 6  # nothing dropped, nothing inserted


def test_unwrap_with_times_resolves_gaps_longer_than_the_modulus() -> None:
    true = np.concatenate([np.arange(0, 6), np.arange(18, 22)])  # 12 lost: more than 8
    raw = true % 8
    times = true * 0.5
    blind = unwrap_counter(raw, 8)  # a counter alone cannot see whole periods: 5 -> 2 looks
    assert blind.gaps == ()  # like a step back by 3
    assert blind.steps == (CounterStep(index=6, after_counter=5, step=-3),)
    timed = unwrap_counter(raw, 8, device_time=times, period_s=0.5)
    assert timed.counter.tolist() == true.tolist()
    assert timed.gaps == (Gap(5, 12),)
    with pytest.raises(ValueError, match="period_s"):
        unwrap_counter(raw, 8, device_time=times)


def test_streaming_unwrap_equals_one_shot_for_random_records() -> None:
    rng = np.random.default_rng(4)
    for modulus in (2**8, 2**18, 2**32):
        steps = np.where(rng.random(5000) < 0.01, rng.integers(2, 60, 5000), 1)
        true = 123 + np.cumsum(steps)
        raw = true % modulus
        whole = unwrap_counter(raw, modulus)
        assert (whole.counter - whole.counter[0]).tolist() == (true - true[0]).tolist()
        expect = [Gap(int(whole.counter[i]), int(steps[i + 1] - 1))
                  for i in np.flatnonzero(steps[1:] > 1)]
        assert list(whole.gaps) == expect
        assert find_gaps(whole.counter) == expect
        unwrapper = CounterUnwrapper(modulus)
        cuts = np.sort(rng.choice(np.arange(1, raw.size), 20, replace=False))
        parts = [unwrapper.process(p) for p in np.split(raw, cuts)]
        assert np.concatenate([p.counter for p in parts]).tolist() == whole.counter.tolist()
        assert [g for p in parts for g in p.gaps] == expect


def test_counter_input_checks() -> None:
    with pytest.raises(ValueError, match="modulus"):
        CounterUnwrapper(1)
    with pytest.raises(ValueError, match=r"\[0, 16\)"):
        unwrap_counter([3, 16], 16)
    with pytest.raises(ValueError, match="integer"):
        unwrap_counter([1.5, 2.5], 16)
    with pytest.raises(ValueError, match="not increasing"):
        find_gaps([1, 2, 2])
    assert unwrap_counter([], 16).counter.size == 0


# ------------------------------------------------------------------------------------------------
# Resampling
# ------------------------------------------------------------------------------------------------
AMPS = np.array([0.010, 0.005])  # m
OMEGAS = 2 * np.pi * np.array([2.0, 4.0])  # the configs' heave and pitch frequencies
PHASES = np.array([0.3, 1.1])
SYNC_HZ = 500.0


def signal(t: FloatArray) -> FloatArray:
    return np.sum(AMPS * np.sin(np.outer(t, OMEGAS) + PHASES), axis=1)


def two_streams(duration_s: float) -> tuple[list[StreamSpec], dict[str, tuple[FloatArray,
                                                                                FloatArray]]]:
    """Sample the analytic signal by a 4 kHz laser and a 500 Hz scanner (2 channels: s, -s)."""
    d_l, t_l = samples(LASER, duration_s)
    d_s, t_s = samples(SCANNER, duration_s)
    specs = [StreamSpec("laser", 1 / 4000.0, method="boxcar"),
             StreamSpec("scanner", 1 / 500.0, channels=2)]
    data = {"laser": (t_l, signal(t_l)),
            "scanner": (t_s, np.column_stack([signal(t_s), -signal(t_s)]))}
    return specs, data


def test_resampled_analytic_signal_is_within_the_interpolation_bound() -> None:
    """Two devices, two rates, two clocks (mapped exactly here): error within the stated bound.

    Linear interpolation at period T: at most ``A (w T)^2 / 8`` per sinusoid. Boxcar of width W
    on the 4 kHz interpolant: the gain loss ``A (w W)^2 / 24`` plus the interpolation term.
    """
    specs, data = two_streams(20.0)
    out = resample(specs, data, rate_hz=SYNC_HZ, t_start=0.0)
    truth = signal(out.time)
    W, T_l, T_s = 1 / SYNC_HZ, 1 / 4000.0, 1 / 500.0
    bound_boxcar = np.sum(AMPS * ((OMEGAS * W) ** 2 / 24 + (OMEGAS * T_l) ** 2 / 8))
    bound_linear = np.sum(AMPS * (OMEGAS * T_s) ** 2 / 8)
    laser, scanner = out.values["laser"], out.values["scanner"]
    inside = np.isfinite(laser) & np.isfinite(scanner[:, 0])
    assert inside.sum() > 0.99 * len(out)
    assert np.max(np.abs(laser[inside] - truth[inside])) < 1.01 * bound_boxcar  # ~1.5 um
    assert np.max(np.abs(scanner[inside, 0] - truth[inside])) < 1.01 * bound_linear  # ~4 um
    assert np.array_equal(scanner[inside, 1], -scanner[inside, 0])
    assert out.time == pytest.approx(out.index / SYNC_HZ, abs=1e-12)


def test_boxcar_rejects_what_plain_decimation_aliases() -> None:
    """Why the lasers are averaged: vibration at a multiple of the sync rate folds onto 0 Hz."""
    t = np.arange(0.0, 5.0, 1 / 4000.0) + 1e-5
    vibration = 1e-3 * np.sin(2 * np.pi * 1000.0 * t + 1.2)  # 1 mm at 1 kHz
    picked = resample([StreamSpec("x", 1 / 4000.0)], {"x": (t, vibration)}, rate_hz=SYNC_HZ,
                      t_start=0.01)
    boxcar = resample([StreamSpec("x", 1 / 4000.0, method="boxcar")], {"x": (t, vibration)},
                      rate_hz=SYNC_HZ, t_start=0.01)
    assert np.nanmax(np.abs(picked.values["x"])) > 0.5e-3  # a spurious quasi-static offset
    assert np.nanmax(np.abs(boxcar.values["x"])) < 1e-12


def test_resampling_with_fitted_clock_maps_end_to_end() -> None:
    rng = np.random.default_rng(17)
    duration = 60.0
    pulses = pulse_times(rng, 5.0, duration - 2.0, 5.0)
    mapped = {}
    for name, dev in (("laser", LASER), ("scanner", SCANNER)):
        d, t = samples(dev, duration)
        cm = ClockMap()
        cm.update(*block_pairs(dev, d, t, rng))
        anchor = (laser_anchor_times(dev, d, t, pulses) if name == "laser"
                  else scanner_anchor_times(dev, t, pulses))
        for a, p in zip(anchor, pulses, strict=True):
            cm.add_anchor(float(a), float(p))
        mapped[name] = cm.to_host(d), t
    specs = [StreamSpec("laser", 1 / 4000.0, method="boxcar"), StreamSpec("scanner", 1 / 500.0)]
    data = {name: (mt, signal(t)) for name, (mt, t) in mapped.items()}
    out = resample(specs, data, rate_hz=SYNC_HZ, t_start=1.0)
    truth = signal(out.time)
    slope_max = np.sum(AMPS * OMEGAS)
    bound = np.sum(AMPS * (OMEGAS / SYNC_HZ) ** 2 / 8) + TOLERANCE_S * slope_max  # ~54 um
    for name in ("laser", "scanner"):
        v = out.values[name]
        ok = np.isfinite(v)
        assert ok.sum() > 0.99 * len(out)
        assert np.max(np.abs(v[ok] - truth[ok])) < bound


def test_gaps_and_invalid_samples_become_nan_and_nothing_else() -> None:
    specs, data = two_streams(4.0)
    t_l, v_l = data["laser"]
    t_s, v_s = data["scanner"]
    keep_l = np.ones(t_l.size, bool)
    keep_l[4000:4010] = False  # 10 laser samples lost (2.5 ms)
    keep_s = np.ones(t_s.size, bool)
    keep_s[900:903] = False  # 3 scanner frames lost
    v_l = v_l.copy()
    v_l[8000] = np.nan  # a laser error value (out of range)
    v_s = v_s.copy()
    v_s[1500:1510, 1] = np.nan  # one module missing: its channel only
    data = {"laser": (t_l[keep_l], v_l[keep_l]), "scanner": (t_s[keep_s], v_s[keep_s])}
    out = resample(specs, data, rate_hz=SYNC_HZ, t_start=0.1)
    T, W = out.time, 1 / SYNC_HZ
    # Laser (boxcar): NaN exactly where the averaging interval reaches into a missing stretch.
    tl = data["laser"][0]
    gap_a, gap_b = tl[3999], tl[4000]
    err_a, err_b = t_l[7999], t_l[8001]
    expect_l = (((T - W / 2 < gap_b) & (T + W / 2 >= gap_a))
                | ((T - W / 2 < err_b) & (T + W / 2 >= err_a)))
    inside = (T - W / 2 >= tl[0]) & (T + W / 2 < tl[-1])
    assert np.array_equal(np.isnan(out.values["laser"]) & inside, expect_l & inside)
    assert 2 <= expect_l.sum() <= 6
    # Scanner (linear): NaN strictly between the frames around the gap; other channel intact.
    ts = data["scanner"][0]
    expect_s = (T > ts[899]) & (T < ts[900])
    sc = out.values["scanner"]
    inside_s = (T >= ts[0]) & (T < ts[-1])
    assert np.array_equal(np.isnan(sc[:, 0]) & inside_s, expect_s & inside_s)
    assert expect_s.sum() == 4
    hole = (T > t_s[1499]) & (T < t_s[1510])
    assert np.all(np.isnan(sc[hole, 1])) and np.all(np.isfinite(sc[hole, 0]))
    # Relaxing max_gap_s bridges the short laser gap on purpose.
    relaxed = [StreamSpec("laser", 1 / 4000.0, method="boxcar", max_gap_s=3e-3), specs[1]]
    out2 = resample(relaxed, data, rate_hz=SYNC_HZ, t_start=0.1)
    assert np.isnan(out2.values["laser"][inside]).sum() < np.isnan(
        out.values["laser"][inside]).sum()


def test_block_by_block_output_equals_one_shot_with_bounded_buffers() -> None:
    rng = np.random.default_rng(12)
    specs, data = two_streams(10.0)
    one_shot = resample(specs, data, rate_hz=SYNC_HZ, t_start=0.05)
    r = Resampler(specs, rate_hz=SYNC_HZ, t_start=0.05)
    # Blocks of random sizes (up to 50 ms), pushed in order of their last sample (arrival).
    blocks = []
    for name, (t, v) in data.items():
        per_block = int(0.05 * (4000 if name == "laser" else 500))
        cuts = np.cumsum(rng.integers(1, per_block + 1, t.size))
        cuts = cuts[cuts < t.size]
        blocks += [(float(tt[-1]), name, tt, vv)
                   for tt, vv in zip(np.split(t, cuts), np.split(v, cuts), strict=True)]
    blocks.sort(key=lambda b: b[0])
    out, most = [], 0
    for _, name, tt, vv in blocks:
        r.push(name, tt, vv)
        out.append(r.pull())
        most = max(most, max(r.buffered.values()))
    out.append(r.flush())
    streamed = SyncBlock.concatenate(out)
    assert np.array_equal(streamed.index, one_shot.index)
    assert np.array_equal(streamed.time, one_shot.time)
    for name in data:
        assert np.array_equal(streamed.values[name], one_shot.values[name], equal_nan=True)
    assert most <= 4000 * 0.1  # two blocks' worth (the other stream's latest block), not 10 s
    assert r.late_samples == {"laser": 0, "scanner": 0}


def test_a_stalled_stream_holds_the_others_back_only_for_max_hold() -> None:
    specs, data = two_streams(6.0)
    r = Resampler(specs, rate_hz=SYNC_HZ, t_start=0.0, max_hold_s=0.5)
    t_l, v_l = data["laser"]
    t_s, v_s = data["scanner"]
    r.push("scanner", t_s[:250], v_s[:250])  # the scanner delivers 0.5 s, then stalls
    r.push("laser", t_l, v_l)
    out = r.pull()
    assert out.time[-1] == pytest.approx(t_l[-1] - 0.5, abs=2 / SYNC_HZ)
    late_part = out.time > t_s[249]
    assert np.all(np.isnan(out.values["scanner"][late_part]))
    laser_on = out.time > t_l[0] + 1 / SYNC_HZ
    assert np.all(np.isfinite(out.values["laser"][laser_on]))
    assert max(r.buffered.values()) <= 0.5 * 4000 + 20
    r.push("scanner", t_s[250:], v_s[250:])  # it comes back: the missed part is counted
    assert r.late_samples["scanner"] > 0
    r.push("laser", t_l[-5:] - 1.0, v_l[-5:])  # not after the previous samples: counted
    assert r.overlapping_samples["laser"] == 5


def test_resampler_input_checks() -> None:
    spec = StreamSpec("x", 1e-3)
    assert spec.max_gap_s == pytest.approx(1.5e-3)
    with pytest.raises(ValueError, match="method"):
        StreamSpec("x", 1e-3, method="cubic")
    with pytest.raises(ValueError, match="below the sample period"):
        StreamSpec("x", 1e-3, max_gap_s=1e-4)
    with pytest.raises(ValueError, match="distinct"):
        Resampler([spec, spec], rate_hz=500.0, t_start=0.0)
    r = Resampler([spec], rate_hz=500.0, t_start=0.0)
    with pytest.raises(KeyError, match="unknown stream"):
        r.push("y", [0.0], [1.0])
    with pytest.raises(ValueError, match="shape"):
        r.push("x", [0.0, 1.0], [[1.0, 2.0]])
    with pytest.raises(ValueError, match="increase"):
        r.push("x", [1.0, 0.5], [1.0, 2.0])
    with pytest.raises(ValueError, match="no data"):
        resample([spec], {}, rate_hz=500.0, t_start=0.0)
    assert len(r.pull()) == 0


# ------------------------------------------------------------------------------------------------
# Physical conversions
# ------------------------------------------------------------------------------------------------
def laser_readings(h: FloatArray, alpha: FloatArray, x: FloatArray, standoff: float) -> FloatArray:
    return standoff + h[:, None] + np.outer(alpha, x)


def test_heave_and_pitch_from_two_and_three_lasers_are_exact() -> None:
    rng = np.random.default_rng(1)
    h = rng.uniform(-0.01, 0.01, 200)
    alpha = rng.uniform(-0.05, 0.05, 200)
    x3 = np.array([-0.1, 0.1, 0.0])
    two = heave_pitch_from_lasers(laser_readings(h, alpha, x3[:2], 0.025), x3[:2], 0.025)
    np.testing.assert_allclose(two.h, h, rtol=0, atol=1e-15)
    np.testing.assert_allclose(two.alpha, alpha, rtol=0, atol=1e-14)
    assert np.all(np.isnan(two.check))
    three = heave_pitch_from_lasers(laser_readings(h, alpha, x3, 0.025), x3, [0.025] * 3)
    np.testing.assert_allclose(three.h, h, rtol=0, atol=1e-15)
    np.testing.assert_allclose(three.alpha, alpha, rtol=0, atol=1e-14)
    np.testing.assert_allclose(three.check, 0.0, atol=1e-15)


def test_signs_follow_scanlan() -> None:
    """Nose-up: the leading edge (x < 0) comes up, nearer to its laser; heave down: all farther."""
    x = np.array([-0.1, 0.1])
    nose_up = heave_pitch_from_lasers([[0.025 - 0.001, 0.025 + 0.001]], x, 0.025)
    assert nose_up.alpha[0] == pytest.approx(0.01) and nose_up.h[0] == pytest.approx(0.0)
    down = heave_pitch_from_lasers([[0.027, 0.027]], x, 0.025)
    assert down.h[0] == pytest.approx(0.002) and down.alpha[0] == pytest.approx(0.0)


def test_check_residual_reveals_a_mispositioned_laser() -> None:
    rng = np.random.default_rng(2)
    h = rng.uniform(-0.01, 0.01, 100)
    alpha = rng.uniform(0.01, 0.05, 100)
    true_x = np.array([-0.1, 0.1, 0.02])  # the check laser sits 20 mm off its configured x = 0
    d = laser_readings(h, alpha, true_x, 0.025)
    result = heave_pitch_from_lasers(d, [-0.1, 0.1, 0.0], 0.025)
    np.testing.assert_allclose(result.check, 0.02 * alpha, atol=1e-15)
    assert np.min(np.abs(result.check)) > 1e-4  # 0.2 mm and more: far above laser noise


def test_a_missing_laser_value_falls_back_to_the_other_two() -> None:
    h, alpha = np.array([0.001, 0.002, 0.003]), np.array([0.01, -0.02, 0.03])
    x = np.array([-0.1, 0.1, 0.0])
    d = laser_readings(h, alpha, x, 0.025)
    d[0, 2] = np.nan  # the check laser out of range: h, alpha from the pair
    d[1, 0] = np.nan  # the front laser out of range: from rear and check
    d[2, [0, 1]] = np.nan  # only one value: nothing made up
    r = heave_pitch_from_lasers(d, x, 0.025)
    np.testing.assert_allclose(r.h[:2], h[:2], atol=1e-15)
    np.testing.assert_allclose(r.alpha[:2], alpha[:2], atol=1e-14)
    assert np.isnan(r.h[2]) and np.isnan(r.alpha[2])
    assert np.all(np.isnan(r.check))


def test_heave_pitch_input_checks() -> None:
    with pytest.raises(ValueError, match="shape"):
        heave_pitch_from_lasers(np.zeros((3, 4)), [0, 1, 2, 3], 0.0)
    with pytest.raises(ValueError, match="distinct"):
        heave_pitch_from_lasers(np.zeros((3, 2)), [0.1, 0.1], 0.0)
    with pytest.raises(ValueError, match="positions"):
        heave_pitch_from_lasers(np.zeros((3, 2)), [0.1], 0.0)
    assert heave_pitch_from_lasers(np.zeros((0, 3)), [-0.1, 0.1, 0.0], 0.0).h.size == 0


def test_forces_from_pressures_round_trip_and_nan() -> None:
    taps = TapLayout.rectangle(0.3, 0.01, 28)
    lift, moment = np.array([1.0, -2.0, 0.5]), np.array([0.1, 0.05, -0.2])
    p = taps.pressures_for(lift, moment)
    got_l, got_m = forces_from_pressures(p, taps)
    np.testing.assert_allclose(got_l, lift, atol=1e-12)
    np.testing.assert_allclose(got_m, moment, atol=1e-12)
    uniform_l, uniform_m = forces_from_pressures(np.full((1, taps.n_taps), 100.0), taps)
    assert abs(uniform_l[0]) < 1e-12 and abs(uniform_m[0]) < 1e-12
    p[1, 5] = np.nan
    nan_l, _ = forces_from_pressures(p, taps)
    assert np.isnan(nan_l[1]) and np.isfinite(nan_l[[0, 2]]).all()
    with pytest.raises(ValueError, match="shape"):
        forces_from_pressures(np.zeros((2, taps.n_taps + 1)), taps)


def test_wind_speed_against_hand_values() -> None:
    # 60 Pa at 1.2 kg/m^3: sqrt(2 * 60 / 1.2) = 10 m/s; 137.8125 Pa at 1.225: 15 m/s.
    w = wind_speed([60.0, 137.8125 * 1.2 / 1.225, -2.0, -40.0, np.nan], 1.2)
    assert w.speed[:2] == pytest.approx([10.0, 15.0])
    assert w.speed[2] == 0.0 and w.clipped.tolist() == [False, False, True, False, False]
    assert np.isnan(w.speed[3]) and w.rejected.tolist() == [False, False, False, True, False]
    assert np.isnan(w.speed[4])
    per_sample = wind_speed([60.0, 60.0], [1.2, np.nan])
    assert per_sample.speed[0] == pytest.approx(10.0) and np.isnan(per_sample.speed[1])
    assert wind_speed(-2.0, 1.2, zero_tolerance_pa=1.0).rejected
    with pytest.raises(ValueError, match="rho"):
        wind_speed([60.0], 0.0)
    with pytest.raises(ValueError, match="zero_tolerance_pa"):
        wind_speed([60.0], 1.2, zero_tolerance_pa=-1.0)


def test_air_density_against_hand_values() -> None:
    # ISA sea level: 101325 / (287.058 * 288.15) = 1.22498 kg/m^3.
    assert float(air_density(101325.0, 288.15)) == pytest.approx(1.22498, abs=1e-5)
    # 95 kPa, 300 K: 95000 / 86117.4 = 1.10314 kg/m^3.
    rho = air_density([95000.0, np.nan], [300.0, 300.0])
    assert rho[0] == pytest.approx(1.10314, abs=1e-5) and np.isnan(rho[1])
    with pytest.raises(ValueError, match="degC"):
        air_density(101325.0, 20.0)
    with pytest.raises(ValueError, match="hPa"):
        air_density(1013.25, 293.15)



def test_push_many_equals_a_push_per_piece_with_overlaps_and_late_samples() -> None:
    """The run writer's one push per pull gives the rows and counts of a push per block."""
    rng = np.random.default_rng(3)
    specs = [StreamSpec("p", 1 / 500, "linear", 3), StreamSpec("x", 1 / 4000, "boxcar")]

    def pieces(start: float, period: float, width: int | None, count: int = 40) -> list:
        out, t0 = [], start
        for _ in range(count):
            n = int(rng.integers(1, 30))
            t = t0 + period * np.arange(n)
            # Some blocks start before the previous one ended (a clock-map correction).
            t0 = float(t[-1]) + period - (5 * period if rng.random() < 0.2 else 0.0)
            out.append((t, rng.normal(size=(n,) if width is None else (n, width))))
        return out

    streams = {"p": pieces(0.0, 1 / 500, 3), "x": pieces(0.0, 1 / 4000, None)}
    one, many = (Resampler(specs, rate_hz=500.0, t_start=0.0, max_hold_s=0.1)
                 for _ in range(2))
    rows_one, rows_many = [], []

    def feed(name: str, ps: list) -> None:
        for t, v in ps:
            one.push(name, t, v)
        many.push_many(name, ps)

    for lo, hi in ((0, 10), (10, 25), (25, 40)):  # a pull after each group of pieces
        for name, ps in streams.items():
            feed(name, ps[lo:hi])
        rows_one.append(one.pull())
        rows_many.append(many.pull())
    # The pressures run 0.5 s ahead: past max_hold_s the rows go out without the lasers,
    # whose samples for those times then come late.
    feed("p", pieces(float(streams["p"][-1][0][-1]) + 0.002, 1 / 500, 3, count=20)[:])
    rows_one.append(one.pull())
    rows_many.append(many.pull())
    feed("x", pieces(float(streams["x"][-1][0][-1]) + 0.00025, 1 / 4000, None, count=20))
    rows_one.append(one.flush())
    rows_many.append(many.flush())
    for a, b in zip(rows_one, rows_many, strict=True):
        assert np.array_equal(a.time, b.time)
        for name in ("p", "x"):
            assert np.array_equal(a.values[name], b.values[name], equal_nan=True)
    assert one.overlapping_samples == many.overlapping_samples
    assert one.overlapping_samples["p"] > 0 and one.overlapping_samples["x"] > 0
    assert one.late_samples == many.late_samples and one.late_samples["x"] > 0
