"""The NI-DAQmx drivers against the stand-in of the nidaqmx API and a simulated DAQ device.

The NI-DAQmx runtime cannot be installed here: the driver talks to
:mod:`simulators.nidaqmx_standin` (nidaqmx's Task API, names and error codes), which reads a
:class:`simulators.devices.ni_daqmx.SimNiDaqmx` over loopback TCP: the virtual tunnel's laser
distances and dynamic pressure as voltages on a real sample clock. Checked: continuous reads
(counters, device times, rate), scaling, the trigger line (digital and counter), overwritten
samples and a lost device as faults, out-of-range voltages, the missing runtime's one line.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from daq.config import load_rig_config
from daq.errors import ConfigError, DeviceError, DriverUnavailableError, TransportError
from daq.instruments.ni_daqmx import runtime
from daq.instruments.ni_daqmx.address import TaskAddress
from daq.instruments.ni_daqmx.driver import NiDaqmxAnalog, NiDaqmxLaser
from daq.instruments.ni_daqmx.settings import NiAnalogSettings, NiLaserSettings
from daq.instruments.reading import Reading, describe_mismatches
from simulators.devices.ni_daqmx import SimNiDaqmx
from simulators.nidaqmx_standin import standin_api
from simulators.virtual_tunnel import VirtualTunnel

from support.configs import SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

CONFIG = load_rig_config(SIM_FLAT_PLATE)
RATE = 2000.0
HOLD = (0.008, 0.04)  # m, rad: the tunnel's held model
LASER = {"kind": "laser", "x": -0.1, "standoff_mm": 25.0, "gain": 5.0, "offset": 0.0,
         "unit_m": 1e-3}
PITOT = {"kind": "pitot", "gain": 100.0, "offset": 0.0, "unit_pa": 1.0}


@pytest.fixture(autouse=True)
def standin() -> Iterator[None]:
    """Register the stand-in (as the simulated rig does), restored after the test."""
    runtime.register_standin(standin_api)
    yield
    runtime.register_standin(standin_api)


@pytest.fixture
def tunnel() -> VirtualTunnel:
    return VirtualTunnel(CONFIG.section, CONFIG.aerodynamic_model(), CONFIG.taps,
                         wind_per_rpm=CONFIG.wind_per_rpm, hold=HOLD)


def start_daq(tunnel: VirtualTunnel, **channels: dict[str, Any]) -> tuple[SimNiDaqmx, str]:
    sim = SimNiDaqmx(tunnel, channels=channels or {"ai0": LASER, "ai1": {**LASER, "x": 0.1}},
                     rng=7)
    return sim, sim.start()


def laser(url: str, channel: str = "ai0", **scale: Any) -> NiDaqmxLaser:
    table = {"channel": channel, "range_mm": 50, "rate_hz": RATE, "x": -0.1, "standoff_mm": 25.0,
             "scale": {"gain": 5.0, "offset": 0.0, "units": "mm", **scale}}
    return NiDaqmxLaser(TaskAddress.parse(url), NiLaserSettings.from_table(table, "test"))


def read_for(driver: Any, seconds: float) -> list[Reading]:
    out: list[Reading] = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        out.append(driver.read(timeout_s=1.0))
    return out


def joined(readings: list[Reading], name: str) -> np.ndarray:
    return np.concatenate([r.channels[name] for r in readings])


def test_construction_does_no_io_and_refuses_unknown_options():
    # Port 9: nothing listens there; building (the API loaded, the task group joined) must
    # not connect, only open() does.
    d = laser("nidaqmx://Dev1/ai0?standin=127.0.0.1:9")
    assert not d.is_open and d.describe()["distance"]["units"] == "m"
    with pytest.raises(TransportError):
        d.open()
    with pytest.raises(TypeError):
        NiDaqmxLaser(d.address, d.settings, no_such_option=1)  # type: ignore[call-arg]


def test_continuous_reads_count_samples_on_the_sample_clock(tunnel):
    sim, standin = start_daq(tunnel)
    try:
        with laser(f"nidaqmx://Dev1/ai0:1?standin={standin}") as d:
            readings = read_for(d, 1.5)
            described = d.describe()
    finally:
        sim.stop()
    assert all(describe_mismatches(described, r) == [] for r in readings)
    counter = np.concatenate([r.counter for r in readings])
    device_time = np.concatenate([r.device_time for r in readings])
    # Counter = sample index, every one delivered; device time = index / rate, exactly.
    assert np.array_equal(counter, np.arange(counter[0], counter[0] + counter.size))
    assert np.array_equal(device_time, counter / RATE)
    assert not any(r.gaps for r in readings)
    # The sample clock against the host's: device time advanced over the arrival times of the
    # first and last reads, within their jitter (a 20 ms block at each end of 1.5 s: 3 %; a
    # loaded host delays a read by tens of ms more: 10 %).
    host_ns = np.concatenate([r.host_time_ns for r in readings])
    span = (host_ns[-1] - host_ns[0]) * 1e-9
    assert (device_time[-1] - device_time[0]) / span == pytest.approx(1.0, rel=0.10)
    # ~20 ms blocks (40 samples), not one read per sample.
    assert np.median([len(r) for r in readings]) >= 30


def test_scaled_distance_is_the_lasers_reading_of_the_held_model(tunnel):
    sim, standin = start_daq(tunnel)
    url = f"nidaqmx://Dev1/ai0:1?standin={standin}"
    front, rear = laser(url, "ai0"), laser(url, "ai1")
    try:
        front.open()
        rear.open()
        a, b = read_for(front, 0.3), read_for(rear, 0.3)
        front.close()
        rear.close()
    finally:
        sim.stop()
    h, alpha = HOLD
    # standoff + h + x alpha: 25 + 8 -+ 4 mm. Noise 0.3 mV and a 0.3 mV LSB are 1.5 um at
    # 5 mm/V; the mean of hundreds of samples is within 1 um.
    assert np.mean(joined(a, "distance")) == pytest.approx(0.025 + h - 0.1 * alpha, abs=2e-6)
    assert np.mean(joined(b, "distance")) == pytest.approx(0.025 + h + 0.1 * alpha, abs=2e-6)
    assert np.all(joined(a, "error_code") == 0)
    # One task, two instruments: the same sample indices on both.
    ca, cb = np.concatenate([r.counter for r in a]), np.concatenate([r.counter for r in b])
    common = np.intersect1d(ca, cb)
    assert common.size > 100
    assert sim.tasks_started == 1


def test_pitot_channel_scales_the_dynamic_pressure(tunnel):
    sim, standin = start_daq(tunnel, ai3=PITOT)
    settings = NiAnalogSettings.from_table({"rate_hz": RATE, "channels": [
        {"name": "pitot", "channel": "ai3", "gain": 100.0, "offset": 0.0, "units": "Pa"}]}, "t")
    tunnel.set_fan_speed(600.0)  # 6 m/s
    try:
        with NiDaqmxAnalog(TaskAddress.parse(f"nidaqmx://Dev1/ai3?standin={standin}"),
                           settings) as d:
            readings = read_for(d, 0.3)
            described = d.describe()
    finally:
        sim.stop()
    assert described["pitot"]["units"] == "Pa"
    assert all(describe_mismatches(described, r) == [] for r in readings)
    qd = 0.5 * tunnel.air.density * 6.0**2
    # 0.3 mV noise is 0.03 Pa at 100 Pa/V: the mean is within 0.01 Pa.
    assert np.mean(joined(readings, "pitot")) == pytest.approx(qd, abs=0.01)


@pytest.mark.parametrize("trigger", ["port0/line0", "ctr0"])
def test_trigger_line_flags_the_first_sample_after_a_pulse(tunnel, trigger):
    sim, standin = start_daq(tunnel)
    try:
        with laser(f"nidaqmx://Dev1/ai0?trigger={trigger}&standin={standin}") as d:
            read_for(d, 0.2)
            pulse = tunnel.trigger()
            readings = read_for(d, 0.2)
    finally:
        sim.stop()
    flags = joined(readings, "triggered")
    t_dev = np.concatenate([r.device_time for r in readings])
    assert flags.sum() == 1
    t_true = float(sim.true_time_of(t_dev[flags])[0])
    # The flagged sample is the first at or after the pulse: within one sample period.
    assert 0.0 <= t_true - pulse < 1.0 / RATE + 1e-9


def test_overwritten_samples_are_a_gap_counted_on_the_sample_index(tunnel):
    sim, standin = start_daq(tunnel)
    # buffer_s 0.05: the 1000-sample minimum, 0.5 s at 2 kHz.
    with laser(f"nidaqmx://Dev1/ai0?buffer_s=0.05&standin={standin}") as d:
        try:
            before = read_for(d, 0.1)
            sim.inject("stall", duration_s=1.2)  # the host gets nothing for 1.2 s
            after = read_for(d, 0.3)
        finally:
            sim.stop()
        overwritten = d.task_group.overwritten
    gaps = [g for r in after for g in r.gaps]
    assert len(gaps) == 1 and gaps[0].kind == "missing"
    gap = gaps[0]
    counter = np.concatenate([r.counter for r in before + after])
    jump = np.flatnonzero(np.diff(counter) != 1)
    assert jump.size == 1  # one hole, everything else contiguous
    # Its length is the hole in the sample index, exactly.
    assert gap.after_counter == counter[jump[0]]
    assert gap.length == counter[jump[0] + 1] - counter[jump[0]] - 1 == overwritten
    # 1.2 s stalled with a 0.5 s buffer: at least 0.7 s lost (1400 samples).
    assert gap.length >= 1400


def test_a_count_answered_late_is_asked_again_before_a_timeout(tunnel, monkeypatch):
    """A stalled link answers the sample count as it was when asked, after the deadline.

    CI once: a stall began right after a read had drained every sample; the count came back
    1.2 s later still saying none, and the read gave up though the device had sampled all
    along. The count asked for after the deadline is what decides.
    """
    sim, standin = start_daq(tunnel)
    with laser(f"nidaqmx://Dev1/ai0?standin={standin}") as d:
        try:
            read_for(d, 0.1)
            group = d.task_group
            real = group._acquired
            late = {"answers": 0}

            def stalled_count():
                if late["answers"] == 0:  # the count when asked, answered past the deadline
                    late["answers"] += 1
                    stale = group._next
                    time.sleep(0.3)
                    return stale
                return real()

            monkeypatch.setattr(group, "_acquired", stalled_count)
            reading = d.read(timeout_s=0.2)
        finally:
            sim.stop()
    assert late["answers"] == 1
    assert reading.counter.size > 0


def test_lost_device_is_recreated_with_a_restart_gap(tunnel):
    sim, standin = start_daq(tunnel)
    try:
        with laser(f"nidaqmx://Dev1/ai0?trigger=port0/line0&standin={standin}") as d:
            before = read_for(d, 0.2)
            sim.inject("device_lost", downtime_s=0.25)
            after = read_for(d, 0.6)
            assert d.reconnects == 1
    finally:
        sim.stop()
    gaps = [g for r in after for g in r.gaps]
    # The new task's clock restarted: a restart of unknown length, as the writer expects.
    assert [(g.kind, g.length) for g in gaps] == [("restart", -1)]
    counter = np.concatenate([r.counter for r in before + after])
    assert np.all(np.diff(counter) >= 1)  # the counter runs on across the new task
    jump = int(np.max(np.diff(counter))) - 1
    epoch = joined(after, "epoch")
    t_dev = np.concatenate([r.device_time for r in after])
    first_new = int(np.argmax(epoch == 1))
    assert epoch[-1] == 1 and t_dev[first_new] < 0.3  # the new task's clock starts again at 0
    # The counter's jump, estimated from the host time: the 0.25 s downtime and the backoff
    # (0.1 + 0.2 s), under 1 s.
    assert gaps[0].after_counter == counter[np.argmax(np.diff(counter))]
    assert 0.25 * RATE <= jump <= 1.0 * RATE
    assert sim.tasks_started == 2


def test_a_device_that_stays_away_fails_clearly(tunnel):
    sim, standin = start_daq(tunnel)
    try:
        d = laser(f"nidaqmx://Dev1/ai0?standin={standin}")
        d.open()
        d.task_group.reconnect_attempts, d.task_group.reconnect_backoff_s = 2, 0.02
        read_for(d, 0.1)
        sim.inject("device_lost", downtime_s=30.0)
        with pytest.raises(TransportError, match="did not come back after 2 attempts"):
            read_for(d, 1.0)
        assert not d.is_open
        d.close()
    finally:
        sim.stop()


def test_out_of_range_voltages_are_flagged_and_not_scaled(tunnel):
    sim, standin = start_daq(tunnel, ai0={"kind": "constant", "volts": 12.0},
                             ai1={"kind": "constant", "volts": -0.5},
                             ai2={"kind": "constant", "volts": 6.0})
    url = f"nidaqmx://Dev1/ai0:2?standin={standin}"
    clipped, dark = laser(url, "ai0", valid_volts=[-0.1, 10.0]), laser(url, "ai1",
                                                                      valid_volts=[-0.1, 10.0])
    far = laser(url, "ai2", gain=10.0)  # 60 mm on a 50 mm laser
    try:
        for d in (clipped, dark, far):
            d.open()
        codes = [joined(read_for(d, 0.1), "error_code") for d in (clipped, dark, far)]
        distance = joined(read_for(far, 0.05), "distance")
        for d in (clipped, dark, far):
            d.close()
    finally:
        sim.stop()
    # 1: at the +-10 V input range's limit; 2: outside valid_volts; 3: beyond the laser's range.
    assert [set(c.tolist()) for c in codes] == [{1}, {2}, {3}]
    assert np.all(np.isnan(distance))


def test_one_device_runs_one_analog_task(tunnel):
    sim, standin = start_daq(tunnel)
    a = laser(f"nidaqmx://Dev1/ai0?standin={standin}", "ai0")
    b = laser(f"nidaqmx://Dev1/ai1?standin={standin}", "ai1")  # another URL: another task
    try:
        a.open()
        with pytest.raises(DeviceError, match="-50103"):
            b.open()
        a.close()
    finally:
        sim.stop()


def test_instruments_of_one_task_share_its_rate(tunnel):
    sim, standin = start_daq(tunnel)
    url = f"nidaqmx://Dev1/ai0:1?standin={standin}"
    a = laser(url, "ai0")
    table = {"channel": "ai1", "range_mm": 50, "rate_hz": 1000.0, "x": 0.1, "standoff_mm": 25.0,
             "scale": {"gain": 5.0, "offset": 0.0, "units": "mm"}}
    b = NiDaqmxLaser(TaskAddress.parse(url), NiLaserSettings.from_table(table, "test"))
    try:
        a.open()
        with pytest.raises(ConfigError, match="share its sample clock"):
            b.open()
        a.close()
    finally:
        sim.stop()


def test_missing_package_is_one_line_naming_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "nidaqmx", None)  # as if not installed
    with pytest.raises(DriverUnavailableError) as info:
        laser("nidaqmx://Dev1/ai0")
    text = str(info.value)
    assert "\n" not in text and "pip install 'windrig[nidaqmx]'" in text


def test_missing_c_library_is_one_line_naming_the_runtime():
    # The stand-in raises what nidaqmx raises without its C library (DaqNotFoundError).
    runtime.register_standin(lambda host, port: standin_api(host, port, runtime_missing=True))
    with pytest.raises(DriverUnavailableError) as info:
        laser("nidaqmx://Dev1/ai0?standin=127.0.0.1:9")
    text = str(info.value)
    assert "\n" not in text and "NI-DAQmx runtime" in text and "installdriver" in text
