"""The acquisition engine and the live ring buffer, with test doubles of the drivers' I/O.

The fakes below are plain objects with the drivers' read methods (the device I/O is what they
replace); they return the drivers' :class:`~daq.instruments.reading.Reading`, so the engine's
adapters run as they do against real drivers. The fake scanner is the real scanner driver with
its frame reading and commands replaced, so that its restarts are the driver's own. The engine
itself (readers, queues, dispatcher) is never mocked. The whole-rig run against the simulators is
tests/hil/test_acquisition_hil.py.
"""

from __future__ import annotations

import _thread
import threading
import time
import tracemalloc
from collections import defaultdict
from typing import Any
from unittest.mock import MagicMock

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from daq.acquisition.engine import Acquisition
from daq.acquisition.records import DeviceFault, Event, StreamBlock
from daq.console.ring_buffer import Column, RingBuffer
from daq.errors import DeviceError, ProtocolError, SafetyError, TransportError, TransportTimeout
from daq.instruments.modbus_plc.driver import ReleaseTiming
from daq.instruments.reading import Gap, PollSequence, Reading
from daq.instruments.scanivalve_mps4264.blocks import STATUS_OK, ScanBlock
from daq.instruments.scanivalve_mps4264.driver import ScanivalveMps4264
from daq.instruments.scanivalve_mps4264.settings import Mps4264Settings

pytestmark = pytest.mark.realtime


# ------------------------------------------------------------------------------------------------
# Test doubles of device I/O
# ------------------------------------------------------------------------------------------------
class FakeLaser:
    """ILD1420-like: ``read`` returns ``rows`` samples every ``period_s``.

    ``faults`` maps a read number (1-based) to an exception raised instead of data; a
    TransportError also closes the fake (as the real driver does when it gives up), and
    ``open_failures`` makes that many following ``open()`` calls fail.
    """

    def __init__(self, rows: int = 10, period_s: float = 0.002,
                 faults: dict[int, Exception] | None = None, open_failures: int = 0,
                 silent_reads: range = range(0)) -> None:
        self.rows, self.period_s = rows, period_s
        self.faults = dict(faults or {})
        self.open_failures = open_failures
        self.silent_reads = silent_reads
        self.is_open = False
        self.calls: list[str] = []
        self.reads = 0
        self.next_counter = 0

    def open(self) -> None:
        self.calls.append("open")
        if self.reads and self.open_failures > 0:
            self.open_failures -= 1
            raise TransportError("fake laser: port still gone")
        self.is_open = True

    def close(self) -> None:
        self.calls.append("close")
        self.is_open = False

    def read(self, timeout_s: float = 1.0) -> Reading:
        if not self.is_open:
            raise TransportError("fake laser: not open")
        self.reads += 1
        if self.reads in self.faults:
            exc = self.faults[self.reads]
            if isinstance(exc, TransportError):
                self.is_open = False
            raise exc
        if self.reads in self.silent_reads:
            time.sleep(timeout_s)
            raise TransportTimeout("fake laser: nothing within the timeout")
        time.sleep(self.period_s)
        counter = np.arange(self.next_counter, self.next_counter + self.rows, dtype=np.int64)
        self.next_counter += self.rows
        n = self.rows
        channels = {
            "distance": 0.025 + 1e-6 * counter, "error_code": np.zeros(n, np.int32),
            "epoch": np.zeros(n, np.int32), "triggered": np.zeros(n, bool),
            "status": np.zeros(n, np.int64),
        }
        return Reading(channels=channels, host_time_ns=np.full(n, time.monotonic_ns(), np.int64),
                       counter=counter, device_time=counter / 4000.0)


class BlockingLaser(FakeLaser):
    """A read that ignores its timeout and returns only when the port is closed (a hung line)."""

    def __init__(self) -> None:
        super().__init__()
        self.closed = threading.Event()

    def close(self) -> None:
        super().close()
        self.closed.set()

    def read(self, timeout_s: float = 1.0) -> Reading:
        self.closed.wait()
        raise TransportError("fake laser: port closed under the read")


class FakeScanner(ScanivalveMps4264):
    """MPS4264-like: one-module frames at 500 Hz once scanning; a device gap when asked.

    The real driver with its commands and its frame reading (``read_block``) replaced: its
    ``read``, ``start``, ``recover`` and restarts are the driver's own.
    """

    def __init__(self, frames: int = 5, gap_after: int | None = None,
                 fail_at: int | None = None) -> None:
        super().__init__(MagicMock(url="fake://scanner"),
                         Mps4264Settings.from_table(
                             {"modules": 1, "rate_hz": 500.0, "byte_order": "big",
                              "pitot_channel": 63}, "fake"))
        self.frames = frames
        self.gap_after = gap_after
        self.fail_at = fail_at  # read number whose data connections "stay away"
        self.calls: list[str] = []
        self.scanning = False
        self.next_frame = 1
        self.reads = 0

    def open(self) -> None:
        self.calls.append("open")

    def close(self) -> None:
        self.calls.append("close")

    def configure(self, packet: str = "legacy") -> None:
        self.calls.append("configure")

    def scan(self, *, after_pause: bool = False) -> None:
        self.calls.append("scan")
        self._continuity.restarted(measure=after_pause)  # as the driver's scan() does
        self.scanning = True
        self.next_frame = 1  # the MPS counts frames from 1 at every scan start

    def stop(self) -> None:
        self.calls.append("stop")
        self.scanning = False

    def read_block(self, timeout_s: float | None = None) -> ScanBlock:
        if not self.scanning:
            time.sleep(timeout_s or 0.0)
            raise TransportTimeout("fake scanner: not scanning")
        self.reads += 1
        if self.reads == self.fail_at:
            self.scanning = False
            raise TransportError("fake scanner: module 0 data connection stayed away")
        time.sleep(self.frames / 500.0)
        gaps: tuple[Gap, ...] = ()
        if self.gap_after is not None and self.next_frame > self.gap_after:
            gaps = (Gap(self.next_frame - 1, 3, "missing"),)
            self.next_frame += 3
            self.gap_after = None
        counter = np.arange(self.next_frame, self.next_frame + self.frames, dtype=np.int64)
        self.next_frame += self.frames
        n = self.frames
        pressure = np.zeros((n, 64))
        return ScanBlock(counter=counter, frame_time=counter / 500.0,
                         trigger_time=np.full(n, np.nan),
                         host_time_ns=np.full(n, time.monotonic_ns(), np.int64),
                         pressure=pressure, pitot=pressure[:, 63].copy(),
                         temperature=np.zeros((n, 8)),
                         module_status=np.full((n, 1), STATUS_OK, np.int8), gaps=gaps)


class FakePolled:
    """ABB-drive- or PLC-like ``read()``: one row per poll, numbered as the drivers number them."""

    def __init__(self, channels: tuple[str, ...] = ("speed", "status_word"),
                 faults: dict[int, Exception] | None = None) -> None:
        self.channels = channels
        self.faults = dict(faults or {})
        self.calls: list[str] = []
        self.reads = 0
        self.polls = PollSequence()

    def open(self) -> None:
        self.calls.append("open")

    def close(self) -> None:
        self.calls.append("close")

    def read(self) -> Reading:
        number = self.polls.next()  # a failed poll uses its number too, as in the drivers
        self.reads += 1
        if self.reads in self.faults:
            raise self.faults[self.reads]
        return self.polls.reading(number, dict.fromkeys(self.channels, float(self.reads)),
                                  dict.fromkeys(self.channels, "float64"))


class FakePlc(FakePolled):
    """ModbusPlc-like: polled channels plus arm / release / trigger_pulse."""

    def __init__(self) -> None:
        super().__init__(("armed", "released", "trigger_count"))
        self.armed = False
        self.releases = 0

    def arm(self) -> None:
        self.armed = True

    def release(self) -> ReleaseTiming:
        if not self.armed:
            raise SafetyError("fake plc: release refused: not armed")
        self.armed = False
        command = time.monotonic_ns()
        time.sleep(0.002)
        self.releases += 1
        return ReleaseTiming(command_ns=command, confirmed_ns=time.monotonic_ns())

    def trigger_pulse(self) -> int:
        return time.monotonic_ns()


class FakeBarometer(FakePolled):
    """PTB330-like ``read()``: pressure, temperature and density, with the poll counter."""

    def read(self) -> Reading:
        self.reads += 1
        values = {"pressure": 101325.0, "temperature": 293.15, "density": 1.204}
        return self.polls.reading(self.polls.next(), values, dict.fromkeys(values, "float64"),
                                  info={"status": ""})


class Collector:
    """A subscriber that keeps every (name, doc), optionally slow."""

    def __init__(self, sleep_s: float = 0.0) -> None:
        self.sleep_s = sleep_s
        self.docs: list[tuple[str, Any]] = []
        self.threads: set[str] = set()

    def __call__(self, name: str, doc: Any) -> None:
        self.threads.add(threading.current_thread().name)
        self.docs.append((name, doc))
        if name == "block" and self.sleep_s:
            time.sleep(self.sleep_s)

    def blocks(self, device: str | None = None) -> list[StreamBlock]:
        return [d for n, d in self.docs if n == "block" and (device is None or d.device == device)]

    def events(self, kind: str | None = None) -> list[Event]:
        return [d for n, d in self.docs if n == "event" and (kind is None or d.kind == kind)]


def fast(**kw: Any) -> dict[str, Any]:
    """Engine options that keep the unit tests short."""
    return {"read_timeout_s": 0.05, "backoff_min_s": 0.01, "backoff_max_s": 0.05,
            "join_timeout_s": 1.0, **kw}


def covered(blocks: list[StreamBlock]) -> np.ndarray:
    """Counters of the delivered rows plus those the gaps account for, sorted."""
    parts = [b.counter for b in blocks if b.counter is not None]
    for b in blocks:
        parts += [np.arange(g.after_counter + 1, g.after_counter + 1 + g.length) for g in b.gaps]
    return np.sort(np.concatenate(parts))


# ------------------------------------------------------------------------------------------------
# Engine
# ------------------------------------------------------------------------------------------------
def test_every_kind_streams_in_order_between_start_and_stop(wait_until):
    scanner, laser, fan, plc, baro = (FakeScanner(gap_after=10), FakeLaser(), FakePolled(),
                                      FakePlc(), FakeBarometer())
    sink = Collector()
    acq = Acquisition({"scanner": ("scanner", scanner), "laser": ("laser", laser),
                       "fan": ("fan", fan), "plc": ("plc", plc), "baro": ("barometer", baro)},
                      subscribers=[sink], poll_interval_s={"baro": 0.05}, **fast())
    assert scanner.calls == laser.calls == fan.calls == []  # construction does no I/O
    devices = ("scanner", "laser", "fan", "plc", "baro")
    with acq:
        time.sleep(0.3)
        wait_until(lambda: all(len(sink.blocks(d)) >= 3 for d in devices), "3 blocks per device")
        live = acq.stats()
    summary = sink.docs[-1][1]

    names = [n for n, _ in sink.docs]
    assert names[0] == "start" and names[-1] == "stop" and names.count("stop") == 1
    assert sink.threads == {"windrig-dispatcher"}  # subscribers run on one thread only
    start = sink.docs[0][1]
    assert start["devices"]["scanner"] == {"kind": "scanner", "describe": scanner.describe()}
    assert scanner.calls == ["open", "configure", "scan", "stop", "close"]
    assert laser.calls == fan.calls == ["open", "close"]
    for device in ("scanner", "laser", "fan", "plc", "baro"):
        blocks = sink.blocks(device)
        assert len(blocks) >= 3, device
        assert [b.seq for b in blocks] == list(range(len(blocks)))
        counters = np.concatenate([b.counter for b in blocks])
        assert np.all(np.diff(counters) > 0)  # per device, in order
        assert np.array_equal(covered(blocks), np.arange(counters[0], counters[-1] + 1))
        stats = summary["devices"][device]
        assert stats["blocks"] == stats["delivered"] == len(blocks)
        assert stats["overflows"] == stats["faults"] == 0 and not stats["running"]
        assert live[device].running and live[device].last_arrival_ns is not None
    assert [b.gaps for b in sink.blocks("scanner") if b.gaps] == [(Gap(10, 3),)]
    fan_block = sink.blocks("fan")[0]
    assert fan_block.device_time is None and set(fan_block.values) == {"speed", "status_word"}
    assert len(fan_block) == 1 and fan_block.counter is not None
    laser_block = sink.blocks("laser")[0]
    assert "distance" in laser_block.values and "counter" not in laser_block.values
    assert laser_block.device_time is not None and laser_block.info == {}
    assert sink.blocks("baro")[0].values["density"][0] == pytest.approx(1.204)
    assert summary["reason"] == "stop" and summary["overflows"] == 0
    assert summary["threads_alive"] == [] and summary["errors"] == []


def test_slow_subscriber_overflows_are_counted_marked_and_the_reader_keeps_its_pace():
    """A subscriber sleeping 50 ms per block against a laser giving a block every 1 ms.

    The reader must keep reading at the device's pace (never blocked by the dispatcher), and
    every dropped row must be accounted for: overflow events, gaps in the next delivered block,
    stats and the stop summary, so that delivered rows plus marked gaps are every counter.
    """
    laser = FakeLaser(rows=4, period_s=0.001)
    slow = Collector(sleep_s=0.05)
    acq = Acquisition({"laser": ("laser", laser)}, queue_size=4, subscribers=[slow], **fast())
    t0 = time.monotonic()
    with acq:
        time.sleep(0.5)
        reads_while_running = laser.reads
        elapsed = time.monotonic() - t0
    summary = slow.docs[-1][1]
    stats = summary["devices"]["laser"]
    blocks = slow.blocks()

    # The reader kept the device's pace (~1 read per ms) although delivery took 50 ms a block.
    # A reader held by the dispatcher would read once per delivery (0.02 of that pace); 0.1 of
    # it tells the two apart 5x and leaves a loaded host 10 ms per 1 ms read (a thread woken
    # from a 1 ms sleep waits for a core there; 0.4 of the pace, with 20 ms deliveries, left
    # it 2.5 ms, and "delivered < reads / 4" below about 4 ms).
    assert reads_while_running > 0.1 * elapsed / 0.001
    assert stats["delivered"] == len(blocks) < reads_while_running / 4
    # Every block read was either delivered or dropped and counted.
    assert stats["blocks"] == stats["delivered"] + stats["overflows"]
    assert summary["overflows"] == stats["overflows"] > 0
    assert summary["overflow_samples"] == stats["overflow_samples"] == 4 * stats["overflows"]
    overflow_events = slow.events("overflow")
    assert sum(e.data["samples"] for e in overflow_events) == stats["overflow_samples"]
    assert sum(b.overflow_samples for b in blocks) == stats["overflow_samples"]
    # Never silent: delivered counters plus marked gaps are exactly 0 .. last, no overlap.
    last = int(blocks[-1].counter[-1])
    assert np.array_equal(covered(blocks), np.arange(0, last + 1))
    # An overflow event comes right before the block whose gaps mark it.
    index = next(i for i, (n, d) in enumerate(slow.docs) if n == "event" and d.kind == "overflow")
    name, block = slow.docs[index + 1]
    assert name == "block" and block.overflow_samples > 0
    gap = block.gaps[-1]
    assert gap.kind == "overflow"
    assert (gap.after_counter, gap.length) == slow.docs[index][1].data["gap"]


def test_device_fault_is_reported_retried_with_backoff_and_recovered(wait_until):
    laser = FakeLaser(faults={3: TransportError("fake laser: line dropped")}, open_failures=2)
    other = FakePolled(faults={2: ProtocolError("fake drive: bad reply 01 83 02")})
    sink = Collector()
    with Acquisition({"laser": ("laser", laser), "fan": ("fan", other)}, subscribers=[sink],
                     poll_interval_s={"fan": 0.02}, **fast(backoff_min_s=0.02,
                                                           backoff_max_s=0.04)):
        # Both recovered, and data after it: the laser's blocks, the fan's block with its gap.
        wait_until(lambda: len(sink.events("recovered")) >= 2 and len(sink.blocks("laser")) > 3
                 and any(b.gaps for b in sink.blocks("fan")), "both devices recovered")
        time.sleep(0.05)

    faults = [e for e in sink.events("fault") if e.device == "laser"]
    assert all(isinstance(f, DeviceFault) and not f.fatal for f in faults)
    # The read failed, then two reopen attempts failed: three faults in a row, then data.
    assert [(f.error, f.consecutive) for f in faults] == [
        ("TransportError", 1), ("TransportError", 2), ("TransportError", 3)]
    assert "line dropped" in faults[0].text
    gaps_s = np.diff([f.host_time_ns for f in faults]) * 1e-9
    assert gaps_s[0] >= 0.02 and gaps_s[1] >= 0.04  # backoff 20 ms, then doubled (capped 40)
    assert laser.calls.count("open") == 4  # start + 3 reopen attempts (2 refused)
    recovered = [e for e in sink.events("recovered") if e.device == "laser"]
    assert len(recovered) == 1 and recovered[0].data == {"faults": 3}
    assert recovered[0].host_time_ns > faults[-1].host_time_ns
    fan_faults = [e for e in sink.events("fault") if e.device == "fan"]
    assert [(f.error, f.consecutive) for f in fan_faults] == [("ProtocolError", 1)]
    summary = sink.docs[-1][1]
    assert summary["devices"]["laser"]["faults"] == 3 and summary["faults"] == 4
    # The failed poll of the fan is a gap of one poll in its counter.
    assert [b.gaps for b in sink.blocks("fan") if b.gaps] == [(Gap(1, 1),)]
    assert len(sink.blocks("laser")) > 3  # data flows again after the recovery


def test_a_scanner_restarted_after_a_lost_connection_keeps_its_counter_increasing(wait_until):
    scanner = FakeScanner(fail_at=6)
    sink = Collector()
    with Acquisition({"scanner": ("scanner", scanner)}, subscribers=[sink], **fast()):
        wait_until(lambda: sink.events("recovered") and any(b.gaps for b in sink.blocks()),
                 "the scanner recovered, its restart gap delivered")
        time.sleep(0.05)
    assert scanner.calls[:8] == ["open", "configure", "scan",  # start
                                 "close", "open", "configure", "scan",  # the recovery
                                 "stop"]
    blocks = sink.blocks()
    counter = np.concatenate([b.counter for b in blocks])
    assert np.all(np.diff(counter) == 1)  # continues after the last frame before the restart
    restart = [b.gaps for b in blocks if b.gaps]
    assert restart == [(Gap(25, -1, "restart"),)]  # 5 good reads of 5 frames, then a restart
    assert [f.error for f in sink.events("fault")] == ["TransportError"]


def test_a_stalled_stream_is_reported_once_and_its_return_announced(wait_until):
    laser = FakeLaser(silent_reads=range(2, 9))  # 7 reads of 50 ms with nothing: 0.35 s
    sink = Collector()
    with Acquisition({"laser": ("laser", laser)}, subscribers=[sink], **fast(stall_s=0.2)):
        wait_until(lambda: sink.events("recovered"), "the stream's return")
    faults = sink.events("fault")
    assert len(faults) == 1 and faults[0].error == "TransportTimeout"
    assert "no data for" in faults[0].text
    assert len(sink.events("recovered")) == 1


def test_a_bug_in_one_reader_is_fatal_for_it_alone(wait_until):
    broken = FakePolled(faults={2: ZeroDivisionError("a bug, not a device fault")})
    laser = FakeLaser()
    sink = Collector()
    with Acquisition({"fan": ("fan", broken), "laser": ("laser", laser)}, subscribers=[sink],
                     poll_interval_s={"fan": 0.01}, **fast()) as acq:
        time.sleep(0.2)
        wait_until(lambda: not acq.stats()["fan"].running and len(sink.blocks("laser")) > 10,
                 "the fan's reader failed, the laser's delivered")
        stats = acq.stats()
        reads_at_failure = broken.reads
        time.sleep(0.1)
    assert broken.reads == reads_at_failure == 2  # no retry of a bug
    assert not stats["fan"].running and "ZeroDivisionError" in str(stats["fan"].failed)
    assert stats["laser"].running
    (fault,) = sink.events("fault")
    assert fault.fatal and fault.error == "ZeroDivisionError" and fault.device == "fan"
    summary = sink.docs[-1][1]
    assert summary["devices"]["laser"]["delivered"] > 10
    assert "ZeroDivisionError" in summary["devices"]["fan"]["failed"]


def test_stop_is_prompt_and_frees_a_reader_stuck_in_a_read_by_closing_its_driver():
    quick, stuck = FakeLaser(), BlockingLaser()
    sink = Collector()
    acq = Acquisition({"quick": ("laser", quick), "stuck": ("laser", stuck)},
                      subscribers=[sink], **fast(join_timeout_s=0.3))
    acq.start()
    time.sleep(0.1)
    t0 = time.monotonic()
    summary = acq.stop()
    took = time.monotonic() - t0
    # join timeout (0.3 s) for the stuck one, then close() frees it at once.
    assert 0.3 <= took < 1.0
    assert summary["threads_alive"] == [] and summary["errors"] == []
    assert summary["faults"] == 0  # an error caused by the stop itself is no device fault
    assert acq.stop() is summary  # idempotent

    free = Acquisition({"quick": ("laser", FakeLaser())}, **fast(read_timeout_s=0.2))
    free.start()
    time.sleep(0.05)
    t0 = time.monotonic()
    free.stop()
    assert time.monotonic() - t0 < 0.5  # one read at most, then the drain and "stop"


def test_operator_actions_are_events_and_a_refused_release_is_recorded():
    plc = FakePlc()
    sink = Collector()
    acq = Acquisition({"plc": ("plc", plc), "laser": ("laser", FakeLaser())},
                      subscribers=[sink], **fast())
    with pytest.raises(RuntimeError, match="not running"):
        acq.release()
    with acq:
        with pytest.raises(SafetyError, match="not armed"):
            acq.release("plc")
        acq.arm()
        before = time.monotonic_ns()
        release = acq.release("plc")
        after = time.monotonic_ns()
        note = acq.mark("note", "wind 8 m/s")
        trigger = acq.trigger()
        with pytest.raises(ValueError, match="reserved"):
            acq.mark("release", "not through the PLC")
        with pytest.raises(ValueError, match="not a device of kind 'plc'"):
            acq.release("laser")
        time.sleep(0.05)
    assert plc.releases == 1
    assert [e.kind for e in sink.events() if e.kind != "fault"] == [
        "release_failed", "arm", "release", "note", "trigger"]
    assert before <= release.host_time_ns <= after and release.device == "plc"
    assert release.data["requested_ns"] <= release.data["command_ns"] == release.host_time_ns
    assert release.data["confirmed_ns"] >= release.host_time_ns
    assert release.data["delay_s"] >= 0.002
    assert note.text == "wind 8 m/s" and trigger.kind == "trigger"
    assert sink.events("release_failed")[0].data["error"] == "SafetyError"
    assert sink.docs[-1][1]["releases"] == [release]


def test_a_failing_subscriber_is_counted_and_does_not_starve_the_others(wait_until):
    def broken(name: str, doc: Any) -> None:
        if name == "block":
            raise ValueError("subscriber bug")

    sink = Collector()
    with Acquisition({"laser": ("laser", FakeLaser())}, subscribers=[broken, sink], **fast()):
        time.sleep(0.1)
        wait_until(lambda: len(sink.blocks()) > 5, "blocks past the failing subscriber")
    summary = sink.docs[-1][1]
    n_blocks = len(sink.blocks())
    assert n_blocks > 5
    assert summary["subscriber_errors"] == {repr(broken): n_blocks}


def test_run_until_stops_cleanly_on_ctrl_c_on_a_duration_and_on_an_event():
    laser = FakeLaser()
    acq = Acquisition({"laser": ("laser", laser)}, **fast())
    timer = threading.Timer(0.2, _thread.interrupt_main)
    timer.start()
    t0 = time.monotonic()
    try:
        summary = acq.run_until(None, poll_s=0.02)  # would run forever without Ctrl-C
    finally:
        timer.join()
    assert summary["reason"] == "interrupted" and 0.2 <= time.monotonic() - t0 < 1.0
    assert summary["devices"]["laser"]["delivered"] > 0 and summary["threads_alive"] == []
    assert laser.calls == ["open", "close"]

    assert Acquisition({"laser": ("laser", FakeLaser())}, **fast()).run_until(0.1)[
        "reason"] == "duration"
    done = threading.Event()
    setter = threading.Timer(0.1, done.set)
    setter.start()
    try:
        assert Acquisition({"laser": ("laser", FakeLaser())}, **fast()).run_until(done)[
            "reason"] == "event"
    finally:
        setter.join()


def test_a_device_that_cannot_open_closes_the_others_and_nothing_runs():
    good = FakeLaser()

    class Unreachable(FakePolled):
        def open(self) -> None:
            raise DeviceError("fake drive: exception code 0x0B")

    acq = Acquisition({"good": ("laser", good), "bad": ("fan", Unreachable())}, **fast())
    with pytest.raises(DeviceError, match="0x0B"):
        acq.start()
    assert good.calls == ["open", "close"]
    assert acq.stop()["reason"] == "never started" and not acq.running
    with pytest.raises(RuntimeError, match="one run per object"):
        acq.start()


def test_arguments_are_checked_without_io():
    with pytest.raises(ValueError, match="kind must be one of"):
        Acquisition({"x": ("camera", FakeLaser())})
    with pytest.raises(TypeError, match=r"lacks \['start', 'stop', 'recover', 'drain'"):
        Acquisition({"x": ("scanner", FakeLaser())})
    with pytest.raises(ValueError, match="queue_size"):
        Acquisition({"x": ("laser", FakeLaser())}, queue_size=0)
    with pytest.raises(ValueError, match="unknown device"):
        Acquisition({"x": ("laser", FakeLaser())}, poll_interval_s={"y": 1.0})
    with pytest.raises(TypeError, match="unexpected keyword"):
        Acquisition({"x": ("laser", FakeLaser())}, no_such_option=1)  # type: ignore[call-arg]
    acq = Acquisition({"x": ("laser", FakeLaser())})
    with pytest.raises(RuntimeError, match="not running"):
        acq.mark("note", "before the start")


def test_ordering_per_device_survives_many_devices_and_a_small_queue(wait_until):
    lasers = {f"laser{i}": ("laser", FakeLaser(rows=3, period_s=0.0005)) for i in range(4)}
    sink = Collector(sleep_s=0.001)
    with Acquisition(lasers, queue_size=2, subscribers=[sink], **fast()):
        time.sleep(0.3)
        wait_until(lambda: {b.device for b in sink.blocks()} == set(lasers), "every laser's blocks")
    per_device: dict[str, list[StreamBlock]] = defaultdict(list)
    for block in sink.blocks():
        per_device[block.device].append(block)
    assert set(per_device) == set(lasers)
    for blocks in per_device.values():
        seqs = [b.seq for b in blocks]
        assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
        last = int(blocks[-1].counter[-1])
        assert np.array_equal(covered(blocks), np.arange(0, last + 1))  # first may be dropped


def test_device_gaps_inside_dropped_blocks_are_passed_on(wait_until):
    """A gap the device reported in a block that was then dropped still reaches subscribers."""

    class GappyLaser(FakeLaser):
        def read(self, timeout_s: float = 1.0) -> Reading:
            block = super().read(timeout_s)
            if self.reads % 7 == 0:  # the device skipped 2 samples before this block
                counter = block.counter + 2
                self.next_counter += 2
                return Reading(channels=block.channels, host_time_ns=block.host_time_ns,
                               counter=counter, device_time=block.device_time,
                               gaps=(Gap(int(counter[0]) - 3, 2),))
            return block

    laser = GappyLaser(rows=2, period_s=0.001)
    sink = Collector(sleep_s=0.01)
    with Acquisition({"laser": ("laser", laser)}, queue_size=3, subscribers=[sink], **fast()):
        time.sleep(0.3)
        # a dropped block that held a device gap: one drop in several, so waited for
        wait_until(lambda: any(e.data["device_gaps"] for e in sink.events("overflow")),
                 "an overflow that dropped a device gap")
    blocks = sink.blocks()
    assert sink.docs[-1][1]["overflows"] > 0
    assert any(e.data["device_gaps"] for e in sink.events("overflow"))  # the case in question
    last = int(blocks[-1].counter[-1])
    assert np.array_equal(covered(blocks), np.arange(0, last + 1))


# ------------------------------------------------------------------------------------------------
# Ring buffer
# ------------------------------------------------------------------------------------------------
@settings(max_examples=200, deadline=None)
@given(capacity=st.integers(1, 16), sizes=st.lists(st.integers(0, 40), max_size=12),
       last=st.none() | st.integers(0, 20))
def test_ring_buffer_holds_exactly_the_last_capacity_rows_in_order(capacity, sizes, last):
    ring = RingBuffer(capacity, "t", Column("p", np.float32, (3,)), Column("n", np.int64))
    appended = 0
    for size in sizes:
        t = np.arange(appended, appended + size, dtype=np.float64)
        ring.append({"t": t, "p": np.repeat(t[:, None], 3, axis=1), "n": t.astype(np.int64)})
        appended += size
        held = min(appended, capacity)
        expected = np.arange(appended - held, appended, dtype=np.float64)
        snap = ring.snapshot()
        assert np.array_equal(snap["t"], expected)
        assert np.array_equal(snap["p"], np.repeat(expected[:, None], 3, axis=1))
        assert snap["n"].dtype == np.int64 and np.array_equal(snap["n"], expected)
        assert len(ring) == held and ring.total_rows == appended
        if last is not None:
            assert np.array_equal(ring.snapshot(last)["t"], expected[len(expected) - min(
                last, held):])


def test_ring_buffer_snapshots_are_copies_and_appends_are_copied():
    ring = RingBuffer(4, "t")
    source = np.array([1.0, 2.0])
    ring.append({"t": source})
    source[:] = 99.0
    snap = ring.snapshot()
    snap["t"][:] = -1.0
    assert ring.snapshot()["t"].tolist() == [1.0, 2.0]


def test_ring_buffer_snapshot_of_some_columns_holds_the_same_rows():
    ring = RingBuffer(5, "t", Column("p", shape=(3,)))
    t = np.arange(8.0)  # wraps around the capacity
    ring.append({"t": t, "p": np.repeat(t[:, None], 3, axis=1)})
    only_t = ring.snapshot(columns=["t"])
    assert list(only_t) == ["t"] and only_t["t"].tolist() == [3.0, 4.0, 5.0, 6.0, 7.0]
    last_p = ring.snapshot(2, columns=("p",))
    assert list(last_p) == ["p"] and last_p["p"].tolist() == [[6.0] * 3, [7.0] * 3]
    with pytest.raises(KeyError, match=r"no column\(s\) \['x'\]"):
        ring.snapshot(columns=("t", "x"))


def test_ring_buffer_refuses_bad_blocks_and_writes_nothing_then():
    ring = RingBuffer(4, "t", Column("n", np.int64))
    ring.append({"t": [0.0], "n": [0]})
    with pytest.raises(KeyError, match="missing"):
        ring.append({"t": [1.0]})
    with pytest.raises(KeyError, match="unknown"):
        ring.append({"t": [1.0], "n": [1], "x": [1.0]})
    with pytest.raises(ValueError, match="different row counts"):
        ring.append({"t": [1.0, 2.0], "n": [1]})
    with pytest.raises(ValueError, match="expected shape"):
        ring.append({"t": [[1.0]], "n": [1]})
    with pytest.raises(TypeError, match="cannot cast"):
        ring.append({"t": [1.0], "n": [1.5]})
    assert ring.total_rows == 1 and ring.snapshot()["t"].tolist() == [0.0]
    with pytest.raises(ValueError, match="capacity_rows"):
        RingBuffer(0, "t")
    with pytest.raises(ValueError, match="distinct"):
        RingBuffer(2, "t", "t")
    ring.clear()
    assert len(ring) == 0 and ring.snapshot()["t"].shape == (0,)


def test_ring_buffer_memory_does_not_grow_with_appends():
    ring = RingBuffer(1000, "t", Column("p", shape=(64,)))
    block = {"t": np.zeros(100), "p": np.zeros((100, 64))}
    ring.append(block)
    tracemalloc.start()
    try:
        before, _ = tracemalloc.get_traced_memory()
        for _ in range(500):  # 50 times the capacity
            ring.append(block)
        after, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert after - before < 10_000  # bytes: nothing per row is kept


def test_ring_buffer_snapshots_are_consistent_under_concurrent_appends():
    ring = RingBuffer(50, "t", "twice")
    stop = threading.Event()

    def writer() -> None:
        n = 0
        while not stop.is_set():
            t = np.arange(n, n + 7, dtype=np.float64)
            ring.append({"t": t, "twice": 2 * t})
            n += 7

    thread = threading.Thread(target=writer)
    thread.start()
    try:
        for _ in range(2000):
            snap = ring.snapshot()
            t = snap["t"]
            assert np.array_equal(snap["twice"], 2 * t)  # rows never mixed between columns
            assert np.all(np.diff(t) == 1.0)  # time-ordered, no torn append
    finally:
        stop.set()
        thread.join()
