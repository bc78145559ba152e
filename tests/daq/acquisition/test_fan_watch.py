"""The ``fan_reached`` event: the drive's actual speed settled within tolerance of the target."""

from __future__ import annotations

import numpy as np
import pytest

from daq.acquisition.fan_watch import SETTLE_POLLS, FanWatch, reached_tolerance_rpm
from daq.acquisition.records import Event, StreamBlock


def _block(seq: int, t_ns: int, rpm: float, device: str = "fan") -> StreamBlock:
    return StreamBlock(device=device, kind="fan", seq=seq, host_time_ns=np.array([t_ns]),
                       device_time=None, counter=np.array([seq]),
                       values={"speed": np.array([rpm]), "status_word": np.array([0x0237])})


def _feed_ramp(watch: FanWatch, start_ns: int, speeds: list[float]) -> None:
    for i, rpm in enumerate(speeds):
        watch("block", _block(i, start_ns + i * 100_000_000, rpm))  # 10 Hz polls


def test_reached_once_the_speed_stays_within_tolerance_for_three_polls():
    posted: list[Event] = []
    watch = FanWatch("fan", posted.append)
    watch("event", Event(kind="fan_speed", host_time_ns=1_000, device="fan", data={"rpm": 600.0}))
    _feed_ramp(watch, 5_000, [0.0] * 5)
    assert posted == []  # not running: the target is still 0, nothing to reach
    watch("event", Event(kind="fan_start", host_time_ns=2_000, device="fan"))
    # A ramp at 100 rpm/s polled at 10 Hz, one poll inside the 6 rpm band then out (overshoot),
    # then settled: the event is at the first of the three polls in a row.
    _feed_ramp(watch, 10_000, [0, 100, 300, 590, 597, 610, 603, 599, 600, 601])
    assert len(posted) == 1
    event = posted[0]
    assert event.kind == "fan_reached" and event.device == "fan"
    assert event.host_time_ns == 10_000 + 6 * 100_000_000  # 603: first of 603, 599, 600
    assert event.data["rpm"] == 603.0 and event.data["setpoint_rpm"] == 600.0
    assert event.data["after_s"] == pytest.approx(0.6, abs=1e-6)
    # Reached once: further polls in the band post nothing.
    _feed_ramp(watch, 2_000_000_000, [600] * 5)
    assert len(posted) == 1


def test_a_stop_is_reached_at_zero_and_other_devices_are_ignored():
    posted: list[Event] = []
    watch = FanWatch("fan", posted.append)
    watch("event", Event(kind="fan_speed", host_time_ns=0, device="fan", data={"rpm": 300.0}))
    watch("event", Event(kind="fan_start", host_time_ns=0, device="fan"))
    _feed_ramp(watch, 1, [300.0] * SETTLE_POLLS)
    watch("event", Event(kind="fan_stop", host_time_ns=10**9, device="fan"))
    watch("block", _block(0, 2 * 10**9, 0.0, device="other_fan"))  # not this drive
    _feed_ramp(watch, 10**9 + 1, [200.0, 100.0, 4.0, 0.0, 0.0])
    assert [e.data["setpoint_rpm"] for e in posted] == [300.0, 0.0]
    assert posted[1].text == "fan stopped (0 rpm reached)"


def test_the_tolerance_is_one_percent_with_a_floor():
    assert reached_tolerance_rpm(1200.0) == pytest.approx(12.0)
    assert reached_tolerance_rpm(100.0) == 5.0


def test_a_target_not_reached_in_the_ramp_time_is_a_warning_once():
    posted: list[Event] = []
    watch = FanWatch("fan", posted.append, ramp_rpm_per_s=100.0)
    watch("event", Event(kind="fan_speed", host_time_ns=0, device="fan", data={"rpm": 300.0}))
    watch("event", Event(kind="fan_start", host_time_ns=0, device="fan"))
    # 300 rpm at 100 rpm/s from rest: allowed 1.5 x 3 s + 2 s = 6.5 s. The drive stalls at
    # 250 rpm: one warning at the first poll past 6.5 s, then none.
    for i in range(100):  # 10 s at 10 Hz
        watch("block", _block(i, i * 100_000_000, min(100.0 * i / 10, 250.0)))
    assert [e.kind for e in posted] == ["warning"]
    assert posted[0].host_time_ns == 66 * 100_000_000
    assert "has not reached 300 rpm after 6.6 s (actual 250 rpm" in posted[0].text
    # Reached later after all: fan_reached as usual.
    _feed_ramp(watch, 10**10, [300.0] * 3)
    assert [e.kind for e in posted] == ["warning", "fan_reached"]
