"""HIL: the fan-drive and PLC drivers against their simulators over Modbus TCP on 127.0.0.1.

Each driver runs its own decoding against the simulator's own encoding
(docs/reference/wire_formats.md), through
a real pymodbus server and client, so the two implementations cross-check each other; every
fault of docs/reference/wire_formats.md, "Faults") is injected and the driver's reaction checked.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import time
from collections.abc import Iterator

import pytest

from daq.errors import DeviceError, ModbusDeviceError, SafetyError, TransportError, TransportTimeout
from daq.instruments.abb_acs580.driver import AbbAcs580
from daq.instruments.abb_acs580.settings import AbbAcs580Settings
from daq.instruments.modbus_plc.driver import ModbusPlc
from daq.instruments.modbus_plc.settings import ModbusPlcSettings
from daq.transports.modbus import ModbusBus
from ident import TapLayout
from ident.model import flat_plate
from simulators.devices.abb_acs580 import SimAbbAcs580
from simulators.devices.modbus_plc import SimModbusPlc
from simulators.virtual_tunnel import VirtualTunnel

from support.sections import FLAT_PLATE

pytestmark = pytest.mark.realtime

# The rig-config tables the drivers validate; the simulators get the same numbers as plain ints.
FAN_TABLE = {
    "max_rpm": 1500.0,
    # An ACH550/RETA-01 wind tunnel's register map: 0 CW, 1 REF1, 3 SW, 4 ACT1.
    "registers": {"control_word": 0, "reference_1": 1, "status_word": 3, "actual_1": 4},
    "poll_timeout_s": 0.1,
    "ramp_rpm_per_s": 3000.0,  # a fast ramp keeps the tests short
}
LIMIT_RPM = 900.0
PLC_TABLE = {
    "coils": {"release": 0, "arm": 1, "trigger": 2},
    "discrete_inputs": {"released": 0},
    "holding_registers": {"trigger_count": 10},
    "release_timeout_s": 0.3,
    "trigger_pulse_s": 0.002,
}


@pytest.fixture
def tunnel() -> VirtualTunnel:
    return VirtualTunnel(FLAT_PLATE, flat_plate.jones_model(), TapLayout.rectangle(0.3, 0.01, 16),
                         wind_per_rpm=0.01, decay_duration_s=2.0)


@pytest.fixture
def fan(tunnel: VirtualTunnel) -> Iterator[tuple[SimAbbAcs580, AbbAcs580]]:
    sim = SimAbbAcs580(tunnel, **FAN_TABLE["registers"], max_rpm=FAN_TABLE["max_rpm"],
                       ramp_rpm_per_s=FAN_TABLE["ramp_rpm_per_s"], speed_noise_rpm=0.3, rng=1)
    url = sim.start()
    # Short retry budget: a fault surfaces in well under a second.
    driver = AbbAcs580(ModbusBus(url, retries=1, backoff_s=0.01),
                       AbbAcs580Settings.from_table(FAN_TABLE), limit_rpm=LIMIT_RPM)
    try:
        with driver:
            yield sim, driver
    finally:
        sim.stop()


@pytest.fixture
def plc(tunnel: VirtualTunnel) -> Iterator[tuple[SimModbusPlc, ModbusPlc]]:
    sim = SimModbusPlc(tunnel, **PLC_TABLE["coils"], **PLC_TABLE["discrete_inputs"],
                       **PLC_TABLE["holding_registers"], rng=7)
    url = sim.start()
    driver = ModbusPlc(ModbusBus(url, timeout_s=0.2, retries=2, backoff_s=0.02),
                       ModbusPlcSettings.from_table(PLC_TABLE))
    try:
        with driver:
            yield sim, driver
    finally:
        sim.stop()


# -- fan drive -------------------------------------------------------------------------------------
def test_fan_spins_up_along_the_ramp_and_turns_the_tunnel_fan(fan, tunnel):
    sim, drive = fan
    assert drive.status().swc_on_inhib and not drive.status().rdy_on  # power-up state
    drive.set_speed(600.0)
    drive.start()
    status = drive.status()
    assert status.rdy_on and status.rdy_run and status.rdy_ref and not status.tripped
    # 600 rpm at 3000 rpm/s takes 0.2 s: right after the start the fan is still ramping.
    early = drive.speed()
    assert early < 590.0
    actual = drive.wait_for_speed(600.0, tolerance_rpm=2.0, timeout_s=2.0)
    # Tolerance: 0.3 rpm noise (seeded) + 0.075 rpm quantisation, well inside 2 rpm.
    assert actual == pytest.approx(600.0, abs=2.0)
    assert tunnel.fan_rpm == pytest.approx(600.0, abs=1e-9)  # the tunnel gets the true speed
    assert tunnel.wind_speed() == pytest.approx(6.0)
    assert drive.status().at_setpoint
    assert sim.writes_to("reference_1") == [8000]  # 600 / 1500 * 20000 (the wire formats)
    assert sim.writes_to("control_word") == [0x0476, 0x047F]
    reading = drive.read()
    assert set(reading.channels) == set(drive.describe())
    assert reading.channels["speed"][0] == pytest.approx(600.0, abs=1.0)
    drive.stop()  # CW 0x0476: ramp stop
    assert drive.wait_for_speed(0.0, tolerance_rpm=2.0, timeout_s=2.0) == pytest.approx(0, abs=2)
    assert drive.status().rdy_on and not drive.status().rdy_run


def test_fan_trip_coasts_refuses_start_and_resets_on_cw_bit7(fan):
    sim, drive = fan
    drive.set_speed(300.0)
    drive.start()
    drive.wait_for_speed(300.0, tolerance_rpm=2.0, timeout_s=2.0)
    sim.inject("trip", code=0x2310, latched=True)
    status = drive.status()
    assert status.tripped and not status.rdy_ref
    with pytest.raises(DeviceError, match="tripped while waiting"):
        drive.wait_for_speed(600.0, tolerance_rpm=2.0, timeout_s=1.0)
    with pytest.raises(DeviceError, match="tripped.*reset_trip"):
        drive.start()
    with pytest.raises(DeviceError, match="TRIPPED cleared"):  # the cause persists
        drive.reset_trip(timeout_s=0.1)
    assert sim.actual_rpm < 300.0  # coasting at half the ramp rate
    sim.clear("trip")
    status = drive.reset_trip()
    assert not status.tripped and status.rdy_on  # SWITCH-ON INHIBITED, then CW 0x0476
    # The reset was a 0->1 edge of bit 7 (0x04F6 after 0x0476).
    cw = sim.writes_to("control_word")
    assert 0x04F6 in cw and cw[cw.index(0x04F6) - 1] == 0x0476
    drive.start()
    assert drive.wait_for_speed(300.0, tolerance_rpm=2.0, timeout_s=2.0)


def test_fan_refuses_references_outside_the_limit_and_the_drive_never_sees_them(fan, tunnel):
    sim, drive = fan
    for bad in (LIMIT_RPM + 0.01, 1e6, -1.0, math.nan, math.inf):
        with pytest.raises(SafetyError):
            drive.set_speed(bad)
    drive.set_speed(LIMIT_RPM)  # the limit itself is allowed
    assert sim.writes_to("reference_1") == [12000]
    limit_counts = LIMIT_RPM / FAN_TABLE["max_rpm"] * 20000
    assert all(word <= limit_counts for word in sim.writes_to("reference_1"))
    # A reference above the limit left in the drive (a panel, an earlier program) blocks start.
    with ModbusBus(sim.url) as panel:
        panel.write_register(FAN_TABLE["registers"]["reference_1"], 16000)  # 1200 rpm
    with pytest.raises(SafetyError, match="stored Reference 1"):
        drive.start()
    assert sim.writes_to("control_word") == []  # never told to run
    time.sleep(0.02)
    assert tunnel.fan_rpm == 0.0


def test_invalid_register_is_a_device_error_with_the_modbus_code(fan):
    sim, drive = fan
    table = dict(FAN_TABLE, registers=dict(FAN_TABLE["registers"], status_word=2))
    wrong = AbbAcs580(drive.bus, AbbAcs580Settings.from_table(table), limit_rpm=LIMIT_RPM)
    with pytest.raises(ModbusDeviceError, match="illegal data address") as info:
        wrong.status()  # register 2 (REF2) is not in the simulated map
    assert info.value.code == 2 and info.value.function_code == 3
    assert isinstance(info.value, DeviceError)
    with pytest.raises(DeviceError, match="exception 0x02"):
        drive.bus.write_register(FAN_TABLE["registers"]["status_word"], 1)  # read-only
    assert drive.bus.stats["retries"] == 0  # an exception reply is never retried
    assert drive.speed() == pytest.approx(0.0, abs=2.0)  # the bus is fine afterwards


def test_fan_no_reply_times_out_then_recovers(fan, caplog):
    sim, drive = fan
    sim.inject("no_reply", count=1)  # one lost reply: the bus's retry absorbs it, logged
    with caplog.at_level(logging.WARNING, logger="daq.transports.modbus"):
        assert drive.status().swc_on_inhib
    assert any("retry 1 of 1" in r.getMessage() for r in caplog.records)
    sim.inject("no_reply")  # the drive goes silent
    t0 = time.monotonic()
    with pytest.raises(TransportTimeout, match="no reply within 0.1 s"):
        drive.speed()
    # Two attempts of 0.1 s plus 0.01 s backoff (and slack for a loaded machine).
    assert 0.18 < time.monotonic() - t0 < 1.0
    assert sim.counters["replies_dropped"] >= 3
    sim.clear("no_reply")
    assert drive.speed() == pytest.approx(0.0, abs=2.0)  # 0.3 rpm noise: 2 rpm is ~7 sigma


def test_fan_slow_ramp_is_caught_by_wait_for_speed(fan):
    sim, drive = fan
    sim.inject("slow_ramp", rpm_per_s=100.0)
    drive.set_speed(600.0)
    drive.start()
    with pytest.raises(DeviceError, match="did not reach 600"):
        drive.wait_for_speed(600.0, tolerance_rpm=2.0, timeout_s=0.2)
    assert 5.0 < drive.speed() < 60.0  # ~0.2 s at 100 rpm/s, not at 3000 rpm/s
    drive.coast()
    assert drive.status().off_2_sta is False


# -- PLC -------------------------------------------------------------------------------------------
def test_plc_arm_and_release_confirmed_by_released(plc, tunnel):
    sim, drive = plc
    assert drive.armed() and not drive.released() and tunnel.armed  # powers up holding
    timing = drive.release()
    assert not tunnel.armed and len(tunnel.release_times()) == 1
    assert drive.released() and not drive.armed()  # the PLC clears ARM after a release
    # The simulated armature takes 10-50 ms from the release; the driver's clock starts later
    # (at the write's reply, after the tunnel computed the decay) and polls every 2 ms.
    assert 0.0 < timing.delay_s <= sim.release_delays[0] + 0.01
    assert 0.010 <= sim.release_delays[0] <= 0.050
    drive.arm()
    assert tunnel.armed and drive.armed() and not drive.released()
    drive.release()
    assert len(tunnel.release_times()) == 2
    assert sim.write_log.count(("release", True)) == 2


def test_plc_release_refused_when_not_armed(plc, tunnel):
    sim, drive = plc
    drive.release()
    with pytest.raises(SafetyError, match="not armed"):
        drive.release()  # one arming permits one release
    drive.arm()
    drive.disarm()
    with pytest.raises(SafetyError, match="not armed"):
        drive.release()
    assert tunnel.armed and len(tunnel.release_times()) == 1
    assert sim.write_log.count(("release", True)) == 1  # the PLC never saw the refused ones
    assert sim.events["releases_refused"] == 0


def test_plc_release_that_never_happens_is_a_specific_error(plc, tunnel):
    sim, drive = plc
    sim.inject("release_stuck")
    t0 = time.monotonic()
    with pytest.raises(DeviceError, match=r"RELEASED \(discrete input 0\) not set within 0.3 s"):
        drive.release()
    assert time.monotonic() - t0 == pytest.approx(0.3, abs=0.2)
    assert tunnel.armed and tunnel.release_times() == []
    assert sim.events["releases_stuck"] == 1
    assert sim.write_log[-1] == ("release", False)  # the coil is back to 0 for the next try
    sim.clear("release_stuck")
    drive.release()
    assert not tunnel.armed


def test_plc_trigger_pulses_are_counted(plc, tunnel):
    sim, drive = plc
    before = drive.trigger_count()
    t0 = tunnel.clock.now()
    for _ in range(5):
        drive.trigger_pulse()
    assert drive.trigger_count() == before + 5 == sim.trigger_count
    assert len(tunnel.trigger_times(since=t0)) == 5
    assert set(drive.read().channels) == set(drive.describe())


#: How long another thread holds the bus in the round-trip tests below, s. Long against a
#: loopback round trip (1-5 ms; ~25 ms seen on a loaded host) so that the bound of a quarter of
#: it (125 ms) still tells the write alone from one that waited out the hold on a loaded host.
HOLD_S = 0.5


@contextlib.contextmanager
def bus_held_by_another_thread(bus: ModbusBus) -> Iterator[None]:
    """Run the body while another thread holds ``bus`` for HOLD_S (a long poll of the engine).

    The body starts once the bus is held, so its first request waits for the rest of the hold.
    """
    holding = threading.Event()

    def hold() -> None:
        with bus.exclusive():
            holding.set()
            time.sleep(HOLD_S)  # a long poll: the condition under test, not a wait for data

    holder = threading.Thread(target=hold)
    holder.start()
    try:
        assert holding.wait(5.0)
        yield
    finally:
        holder.join()


def test_plc_trigger_round_trip_is_the_write_alone_not_a_wait_for_the_bus(plc, tunnel):
    """Another thread's request holding the bus: the pulse's time is bracketed after the wait.

    The pulse's host time is the midpoint of its write's round trip, and the writer takes it as
    a clock anchor only if the round trip is short (``MAX_ANCHOR_ROUND_TRIP_S``), the map's
    floor from the shortest. A wait for a poll of the same bus (the engine reads the PLC at
    10 Hz) counted in that round trip would refuse good anchors and move the midpoint before
    the edge.
    """
    sim, drive = plc
    drive.trigger_pulse()  # the line is low after a pulse: the next write is the timed one
    with bus_held_by_another_thread(drive.bus):
        t_called = time.monotonic()
        t_pulse_ns = drive.trigger_pulse()
    t_edge = tunnel.clock.origin_s + tunnel.trigger_times()[-1]
    # The call waited for the bus (at least the rest of the hold) ...
    assert time.monotonic() - t_called > 0.5 * HOLD_S
    # ... but the round trip is the write's alone (a loopback write takes ~1-5 ms here;
    # the hold was 500 ms), and the midpoint lies within it of the simulator's edge.
    round_trip_s = drive.last_trigger_round_trip_ns * 1e-9
    assert round_trip_s < 0.25 * HOLD_S
    assert abs(t_pulse_ns * 1e-9 - t_edge) <= round_trip_s


def test_plc_release_round_trip_is_the_write_alone_not_a_wait_for_the_bus(plc, tunnel):
    """The release's time and round trip, with another thread's request holding the bus.

    The release's time (the acknowledgement) starts the free decay in the run file; the round
    trip says how far before it the release may have come. (Here the driver's armed() check
    before the write already waits out the hold, so that the write's exclusive timing, shared
    with the trigger pulse's (``ModbusPlc._timed_set``), is what the test above checks.)
    """
    sim, drive = plc
    assert drive.armed()
    with bus_held_by_another_thread(drive.bus):
        timing = drive.release()
    t_release = tunnel.clock.origin_s + tunnel.release_times()[-1]
    round_trip_s = timing.round_trip_ns * 1e-9
    # The write's alone: ~1-5 ms here, or the simulator's decay computation (~25 ms) on a
    # loaded host, not the 500 ms hold.
    assert 0 < round_trip_s < 0.25 * HOLD_S
    # The simulated PLC releases before it acknowledges, within the round trip.
    assert 0 <= timing.command_ns * 1e-9 - t_release <= round_trip_s


def test_plc_disconnect_is_a_transport_error_then_the_bus_reconnects(plc, caplog):
    sim, drive = plc
    assert drive.armed()
    sim.inject("disconnect")  # dropped connection, server back at once: retry absorbs it
    with caplog.at_level(logging.WARNING, logger="daq.transports.modbus"):
        assert drive.trigger_count() == 0
    assert any("connection failed" in r.getMessage() for r in caplog.records)
    sim.inject("disconnect", outage_s=0.3)  # longer than the bus's retries (0.02 + 0.04 s)
    with pytest.raises(TransportError, match="connection failed"):
        drive.armed()
    time.sleep(0.35)
    # The server listens again after its outage, on its own loop's timer (late on a loaded
    # host): retried until it is back, for a generous while.
    deadline = time.monotonic() + 5.0
    while True:
        try:
            armed = drive.armed()
        except TransportError:
            assert time.monotonic() < deadline, "the bus did not reconnect within 5 s"
            time.sleep(0.05)
        else:
            break
    assert armed  # reconnected
    assert sim.counters["disconnects"] == 2


def test_simulators_check_their_parameters_and_fault_names(tunnel):
    registers = FAN_TABLE["registers"]
    with pytest.raises(ValueError, match="distinct"):
        SimAbbAcs580(tunnel, **dict(registers, actual_1=3), max_rpm=1500.0)
    with pytest.raises(ValueError, match="max_rpm must be > 0"):
        SimAbbAcs580(tunnel, **registers, max_rpm=0.0)
    sim = SimAbbAcs580(tunnel, **registers, max_rpm=1500.0, faults={"slow_ramp": {"rpm_per_s": 1}})
    with pytest.raises(ValueError, match="unknown fault 'fire'"):
        sim.inject("fire")
    with pytest.raises(TypeError, match="takes \\['rpm_per_s'\\]"):
        sim.inject("slow_ramp", rate=3)
    with pytest.raises(ValueError, match="coil addresses must be distinct"):
        SimModbusPlc(tunnel, release=0, arm=0, trigger=2, released=0, trigger_count=0)
    plc = SimModbusPlc(tunnel, **PLC_TABLE["coils"], **PLC_TABLE["discrete_inputs"],
                       **PLC_TABLE["holding_registers"])
    with pytest.raises(ValueError, match="unknown fault"):
        plc.clear("fire")
    sim.stop()  # never started: stop is a no-op
