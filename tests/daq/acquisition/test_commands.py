"""Operator commands go through the engine and are recorded: read back from the run file.

Fake fan and PLC drivers (the device I/O is what they replace) run under the real engine, whose
subscriber is the real :class:`~daq.recording.writer.RunWriter` writing a real run file; every
command of the operator (fan set-point, start, stop; arm, disarm, release; a marker) and a
refused one must be in ``/entry/events``, in order, with the device and the numbers. The
console's acquisition process routes a driver's command to the engine's
(:data:`daq.console.process_source.DRIVER_COMMANDS`): checked on its request handler.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import h5py
import pytest

from daq.acquisition.engine import Acquisition
from daq.acquisition.records import SYSTEM_EVENT_KINDS
from daq.config import parse_rig_config
from daq.console.process_source import DRIVER_COMMANDS, ENGINE_COMMANDS, _Server
from daq.errors import SafetyError
from daq.instruments.modbus_plc.driver import ReleaseTiming
from daq.instruments.reading import PollSequence, Reading
from daq.recording.writer import RunWriter

from support.configs import SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

LIMIT_RPM = 1500.0


class FakeFan:
    """ABB-drive-like: ``set_speed`` (refusing the rig's limit), ``start``, ``stop``, ``read``."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, Any]] = []
        self.polls = PollSequence()

    def open(self) -> None:
        pass

    def close(self) -> None:
        pass

    def set_speed(self, rpm: float) -> None:
        if not 0.0 <= rpm <= LIMIT_RPM:
            raise SafetyError(f"fan speed {rpm} rpm outside [0, {LIMIT_RPM}] (max_fan_rpm)")
        self.calls.append(("set_speed", rpm))

    def start(self) -> None:
        self.calls.append(("start", None))

    def stop(self) -> None:
        self.calls.append(("stop", None))

    def read(self) -> Reading:
        return self.polls.reading(self.polls.next(), {"speed": 0.0, "status_word": 0},
                                  {"speed": "float64", "status_word": "uint16"})


class FakePlc:
    """ModbusPlc-like: arm, disarm, release (armed only), trigger_pulse, read."""

    def __init__(self) -> None:
        self.armed = False
        self.polls = PollSequence()

    def open(self) -> None:
        pass

    def close(self) -> None:
        pass

    def arm(self) -> None:
        self.armed = True

    def disarm(self) -> None:
        self.armed = False

    def release(self) -> ReleaseTiming:
        if not self.armed:
            raise SafetyError("release refused: not armed")
        self.armed = False
        command = time.monotonic_ns()
        return ReleaseTiming(command_ns=command, confirmed_ns=command + 2_000_000)

    def trigger_pulse(self) -> int:
        return time.monotonic_ns()

    def read(self) -> Reading:
        dtypes = {"armed": "bool", "released": "bool", "trigger_count": "uint16"}
        return self.polls.reading(self.polls.next(), dict.fromkeys(dtypes, 0), dtypes)


@pytest.fixture
def config():
    return parse_rig_config(SIM_FLAT_PLATE.read_text(), "sim_flat_plate.toml")


def recorded_events(path: Path) -> list[tuple[float, str, str]]:
    with h5py.File(path, "r") as f:
        rows = f["entry/events"][:]
    return [(float(r["time"]), r["kind"].decode(), r["text"].decode()) for r in rows]


def test_every_operator_command_is_an_event_of_the_run_file(config, tmp_path):
    fan, plc = FakeFan(), FakePlc()
    path = tmp_path / "run.h5"
    writer = RunWriter(path, config, write_interval_s=0.0,
                       recorder_options={"min_free_bytes": 0, "reserve_bytes": 0})
    acq = Acquisition({"fan": ("fan", fan), "plc": ("plc", plc)}, subscribers=[writer],
                      read_timeout_s=0.05, join_timeout_s=1.0)
    with acq:
        set_point = acq.set_fan_speed(600.0)
        started = acq.start_fan()
        with pytest.raises(SafetyError, match="max_fan_rpm"):
            acq.set_fan_speed(LIMIT_RPM + 100.0)
        acq.arm()
        acq.release()
        acq.arm()
        acq.disarm()
        acq.mark("note", "wind 6 m/s")
        stopped = acq.stop_fan()
        time.sleep(0.05)
    assert writer.error is None
    assert fan.calls == [("set_speed", 600.0), ("start", None), ("stop", None)]
    assert (set_point.kind, set_point.device, set_point.data["rpm"]) == ("fan_speed", "fan", 600.0)
    assert started.kind == "fan_start" and stopped.kind == "fan_stop"

    events = recorded_events(path)
    kinds = [kind for _, kind, _ in events]
    assert kinds == ["fan_speed", "fan_start", "fan_failed", "arm", "release", "arm", "disarm",
                     "note", "fan_stop"]
    texts = dict(zip(kinds, (text for _, _, text in events), strict=False))
    assert texts["fan_speed"].startswith("fan: fan speed reference 600 rpm")
    assert '"rpm": 600.0' in texts["fan_speed"]
    failed = texts["fan_failed"]
    assert failed.startswith("fan: fan speed 1600.0 rpm outside")
    assert '"error": "SafetyError"' in failed and '"command": "set_speed"' in failed
    assert texts["note"] == "wind 6 m/s"
    times = [t for t, _, _ in events]
    assert times == sorted(times) and times[0] >= 0.0
    with h5py.File(path, "r") as f:  # the release row: its decay ended by arming again
        (row,) = f["entry/releases"][:]
    release_t = times[kinds.index("release")]
    assert row["release_time"] == pytest.approx(release_t, abs=1e-9)


def test_stop_fan_is_sent_even_when_the_engine_no_longer_runs():
    fan = FakeFan()
    acq = Acquisition({"fan": ("fan", fan)}, read_timeout_s=0.05, join_timeout_s=1.0)
    with acq:
        pass
    event = acq.stop_fan()  # a stop is never refused; it is recorded only while running
    assert fan.calls == [("stop", None)] and event.kind == "fan_stop"
    with pytest.raises(RuntimeError, match="not running"):
        acq.set_fan_speed(100.0)


def test_command_event_kinds_are_reserved_for_the_engine():
    assert {"fan_speed", "fan_start", "fan_stop", "fan_failed", "arm", "arm_failed", "disarm",
            "disarm_failed", "release", "release_failed", "calz", "calz_failed",
            "trigger"} <= SYSTEM_EVENT_KINDS
    acq = Acquisition({"fan": ("fan", FakeFan())}, read_timeout_s=0.05, join_timeout_s=1.0)
    with acq, pytest.raises(ValueError, match="reserved"):
        acq.mark("fan_speed", "not through the engine's command")


class RecordingEngine:
    """What the console's acquisition process calls: the engine's command methods, recorded."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, tuple[Any, ...], dict[str, Any]]] = []
        self.drivers = {"fan": object(), "plc": object()}

    def stats(self) -> dict[str, Any]:
        return {"fan": type("S", (), {"kind": "fan"}), "plc": type("S", (), {"kind": "plc"})}

    def __getattr__(self, name: str) -> Any:
        def call(*args: Any, **kwargs: Any) -> str:
            self.calls.append((name, args, kwargs))
            return name
        return call


def test_the_console_process_runs_driver_commands_as_engine_commands():
    engine = RecordingEngine()
    live = type("Live", (), {"acq": engine})()
    server = _Server(conn=None, live=live)  # type: ignore[arg-type]
    assert server._handle("driver", ("fan", "set_speed", 700.0), {}) == "set_fan_speed"
    assert server._handle("driver", ("fan", "start"), {}) == "start_fan"
    assert server._handle("driver", ("fan", "stop"), {}) == "stop_fan"
    assert server._handle("driver", ("plc", "disarm"), {}) == "disarm"
    assert engine.calls == [("set_fan_speed", (700.0,), {"fan": "fan"}),
                            ("start_fan", (), {"fan": "fan"}), ("stop_fan", (), {"fan": "fan"}),
                            ("disarm", (), {"plc": "plc"})]
    routed = {engine_command for commands in DRIVER_COMMANDS.values()
              for engine_command in commands.values()}
    assert routed <= set(ENGINE_COMMANDS)
