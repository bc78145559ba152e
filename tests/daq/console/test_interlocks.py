"""The console's interlocks (:mod:`daq.console.interlocks`): pure rules, no Qt, no rig."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from daq.console.interlocks import (
    ACTIONS,
    CALZ_MAX_WIND,
    CALZ_SETTLE_S,
    ConsoleState,
    Interlocks,
)

#: A running rig with every device, the fan stopped long ago, the wind off, armed, not recording.
READY = ConsoleState(running=True, has_fan=True, has_plc=True, has_scanner=True, fan_rpm=0.0,
                     armed=True, wind_m_s=0.2, can_record=True)


def settled(state: ConsoleState = READY) -> tuple[Interlocks, dict[str, str]]:
    """Interlocks that saw the fan stopped for longer than the settling time."""
    rules = Interlocks()
    rules.refusals(state, now_s=0.0)
    return rules, rules.refusals(state, now_s=CALZ_SETTLE_S + 1.0)


def test_a_ready_rig_allows_everything_but_arming_again_and_stopping_a_recording():
    _, reasons = settled()
    assert reasons == {"arm": "arm: already armed", "stop_record": "stop recording: not recording",
                       # the magnet holds the model: no hand can let it go
                       "hand_release": "released by hand: the PLC's magnet holds the model "
                                       "(disarm, or release)"}


def test_releases_by_hand_need_no_plc():
    _, reasons = settled(replace(READY, has_plc=False, armed=None))
    assert "hand_release" not in reasons and "hand_hold" not in reasons
    assert reasons["release"] == "release: no PLC in this rig"
    _, reasons = settled(replace(READY, armed=False))  # a PLC, its magnet off: a hand may
    assert "hand_release" not in reasons


def test_nothing_while_the_acquisition_does_not_run():
    reasons = Interlocks().refusals(ConsoleState(running=False), now_s=0.0)
    assert set(reasons) == set(ACTIONS)
    assert all(why.endswith(": acquisition not running") for why in reasons.values())
    assert reasons["release"] == "release: acquisition not running"


def test_one_blocking_action_at_a_time_but_the_fan_can_always_be_stopped():
    _, reasons = settled(replace(READY, busy="calz"))
    assert {k for k, v in reasons.items() if "busy (calz)" in v} == {"fan_apply", "arm", "release",
                                                                      "calz"}
    assert "fan_stop" not in reasons and "mark" not in reasons and "record" not in reasons


@pytest.mark.parametrize(("armed", "refused", "why"), [
    (None, "release", "release: PLC state not read yet"),
    (False, "release", "release: arm first"),
    (True, "arm", "arm: already armed"),
])
def test_release_needs_the_model_armed_and_arming_needs_it_not(armed, refused, why):
    _, reasons = settled(replace(READY, armed=armed))
    assert reasons[refused] == why
    assert ({"arm", "release"} - {refused}).isdisjoint(reasons)


def test_missing_devices_refuse_their_actions():
    state = replace(READY, has_fan=False, has_plc=False, has_scanner=False)
    reasons = Interlocks().refusals(state, now_s=0.0)
    assert reasons["fan_apply"] == reasons["fan_stop"] == "fan: no fan in this rig"
    assert reasons["arm"] == "arm: no PLC in this rig"
    assert reasons["release"] == "release: no PLC in this rig"
    assert reasons["calz"] == "CALZ: no scanner in this rig"


def test_calz_waits_for_the_fan_to_be_stopped_and_the_air_to_settle():
    rules = Interlocks()
    spinning = replace(READY, fan_rpm=300.0)
    assert rules.refusals(spinning, 0.0)["calz"] == "CALZ: stop the fan first"
    commanded = replace(READY, fan_commanded=True)  # stopped but a start is on its way
    assert rules.refusals(commanded, 0.0)["calz"] == "CALZ: stop the fan first"
    assert rules.refusals(READY, 10.0)["calz"] == ("CALZ: fan stopped 0 s ago, wait "
                                                  f"{CALZ_SETTLE_S:g} s for the air to settle")
    assert rules.refusals(READY, 12.0)["calz"].startswith("CALZ: fan stopped 2 s ago")
    assert "calz" not in rules.refusals(READY, 10.0 + CALZ_SETTLE_S)
    # The fan spinning again restarts the wait.
    rules.refusals(spinning, 20.0)
    assert "calz" in rules.refusals(READY, 21.0)
    assert "calz" not in rules.refusals(READY, 21.0 + CALZ_SETTLE_S)


def test_calz_needs_the_fan_read_and_the_wind_off():
    assert Interlocks().refusals(replace(READY, fan_rpm=math.nan), 0.0)["calz"] == \
        "CALZ: fan speed not read yet"
    _, reasons = settled(replace(READY, wind_m_s=math.nan))
    assert reasons["calz"] == "CALZ: wind speed not measured yet"
    _, reasons = settled(replace(READY, wind_m_s=CALZ_MAX_WIND))
    assert reasons["calz"] == f"CALZ: wind {CALZ_MAX_WIND:.2f} m/s, must be below " \
        f"{CALZ_MAX_WIND:g} m/s"
    # A rig without a fan: the wind alone decides.
    _, reasons = settled(replace(READY, has_fan=False, fan_rpm=math.nan))
    assert "calz" not in reasons


def test_the_wind_is_measured_only_when_the_other_calz_rules_pass():
    measured: list[int] = []

    def wind() -> float:
        measured.append(1)
        return 0.1

    rules = Interlocks()
    rules.refusals(replace(READY, fan_rpm=300.0, wind_m_s=wind), 0.0)  # fan running
    rules.refusals(replace(READY, busy="arm", wind_m_s=wind), 0.0)  # busy
    assert measured == []
    assert "calz" not in rules.refusals(replace(READY, wind_m_s=wind), 0.0 + 2 * CALZ_SETTLE_S)
    assert measured == [1]


@pytest.mark.parametrize(("can_record", "recording", "refused"), [
    (False, False, {"record": "record: this source cannot record",
                    "stop_record": "stop recording: this source cannot record"}),
    (True, False, {"stop_record": "stop recording: not recording"}),
    (True, True, {"record": "record: already recording"}),
])
def test_recording_rules(can_record, recording, refused):
    _, reasons = settled(replace(READY, can_record=can_record, recording=recording))
    assert {k: v for k, v in reasons.items() if k in ("record", "stop_record")} == refused


def test_the_first_reason_found_is_the_one_given():
    reasons = Interlocks().refusals(replace(READY, running=False, has_plc=False), now_s=0.0)
    assert reasons["arm"] == "arm: acquisition not running"
