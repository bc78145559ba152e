"""``windrig check`` against the simulated rig over its real transports, and what uses it.

The simulators run on 127.0.0.1 (TCP, pyserial ``socket://``, pymodbus); the check reaches them
through the production drivers, from a rig config whose URLs are theirs, as it would a real rig.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from daq.acquisition.device_check import check_rig
from daq.cli import main
from daq.config import load_rig_config, parse_rig_config
from daq.errors import DeviceCheckError
from daq.instruments.build import build_driver
from daq.sim.live_config import write_live_config
from daq.sim.rig import start_simulated_rig

from support.configs import SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

CONFIG = SIM_FLAT_PLATE
DEVICES = ("scanner", "laser_front", "laser_rear", "laser_check", "fan", "plc", "barometer")


@pytest.fixture
def rig():
    with start_simulated_rig(load_rig_config(CONFIG)) as running:
        yield running


def _live_config(rig, tmp_path) -> Path:
    ports = {i.name: i.settings["data_port"] for i in rig.config.instruments
             if "data_port" in i.settings}
    return write_live_config(load_rig_config(CONFIG), rig.urls, tmp_path / "live.toml", ports)


def test_check_passes_on_the_simulated_rig_with_every_device_up(tmp_path, capsys):
    """All up: exit 0, one table row per device, each reachable at its configured rate."""
    out = tmp_path / "check.json"
    # --timeout 5: room for a loaded test machine (a device takes 0.5 s of reading and ~0.05 s
    # of opening when the host is idle).
    assert main(["check", "--config", str(CONFIG), "--simulate", "--json", str(out),
                 "--timeout", "5"]) == 0
    text = capsys.readouterr().out
    for name in DEVICES:
        row = next(line for line in text.splitlines() if line.startswith(name + " "))
        assert row.rstrip().endswith("OK") and " yes " in row
    assert "7 of 7 device(s) OK" in text
    report = json.loads(out.read_text())
    assert report["ok"] is True
    by_name = {d["device"]: d for d in report["devices"]}
    assert set(by_name) == set(DEVICES)
    for name in ("scanner", "laser_front", "laser_rear", "laser_check"):
        d = by_name[name]
        # The simulators run at their configured rates on their own clocks (no drift set):
        # counter over device time is exact to the time stamps' resolution.
        assert d["rate_hz"] == pytest.approx(d["nominal_rate_hz"], rel=1e-3)
    assert "S/N 4264001" in by_name["scanner"]["identity"]  # the legacy packet's serial number
    assert "ILD1420-50" in by_name["laser_front"]["identity"]  # GETINFO
    assert "0 rpm" in by_name["fan"]["readings"]


def test_check_names_a_stopped_device_and_still_checks_the_others(rig, tmp_path, capsys):
    """One simulator stopped: exit 1, that device named with its reason, the others checked."""
    config = _live_config(rig, tmp_path)
    rig.simulators["laser_rear"].stop()
    start = time.monotonic()
    # --timeout 5 as above: the default 2 s can fail a healthy device on a loaded host (the
    # simulators share this process); the stopped one fails at once (refused) either way.
    assert main(["check", "--config", str(config), "--timeout", "5"]) == 1
    took = time.monotonic() - start
    text = capsys.readouterr().out
    failing = [line for line in text.splitlines() if line.startswith("FAIL ")]
    assert len(failing) == 1 and failing[0].startswith("FAIL laser_rear (socket://127.0.0.1:")
    assert "unreachable" in failing[0] and "refused" in failing[0]
    for name in DEVICES:
        row = next(line for line in text.splitlines() if line.startswith(name + " "))
        assert row.rstrip().endswith("FAIL" if name == "laser_rear" else "OK"), row
    assert "failing: laser_rear" in text
    # Each device on its own thread: the whole check takes one device's time (0.5 s of
    # reading, plus opening; measured 0.55 s), not seven (3.5 s and more).
    assert took < 3.4


def test_a_device_that_never_answers_is_given_up_after_the_timeout(rig):
    """A port that accepts and stays silent: that device fails on time, the other passes."""
    import dataclasses
    import socket

    with socket.create_server(("127.0.0.1", 0)) as silent:
        url = f"tcp://127.0.0.1:{silent.getsockname()[1]}"
        instruments = tuple(dataclasses.replace(i, url=url) if i.name == "scanner" else i
                            for i in rig.config.instruments)
        config = dataclasses.replace(rig.config, instruments=instruments)
        start = time.monotonic()
        # 2 s, not 1 s: the fan, checked beside it, needs 0.5 s of reading plus its opening
        # within the same timeout, which a loaded host (simulators in this process) can exceed.
        results = {r.device: r for r in check_rig(config, timeout_s=2.0, only=["scanner",
                                                                             "fan"])}
        took = time.monotonic() - start
    # One line either way the race between the scanner's own 2 s command timeout and the
    # check's 2 s falls: the check's "no answer within 2 s", or the driver's own timeout.
    (problem,) = results["scanner"].problems
    assert problem in ("no answer within 2 s",
                       f"no answer: {url}: no reply line within 2 s (received b'')"), problem
    assert results["fan"].ok
    assert took < 3.5  # the timeout, plus at most 1 s for the closed driver's thread to end


def test_a_silent_device_s_own_timeout_is_named_as_no_answer(rig):
    """The check's timeout above the scanner's 2 s command timeout: the driver's line, once."""
    import dataclasses
    import socket

    with socket.create_server(("127.0.0.1", 0)) as silent:
        url = f"tcp://127.0.0.1:{silent.getsockname()[1]}"
        instruments = tuple(dataclasses.replace(i, url=url) for i in rig.config.instruments
                            if i.name == "scanner")
        config = dataclasses.replace(rig.config, instruments=instruments)
        (result,) = check_rig(config, timeout_s=6.0)
    # Not "unreachable": the port accepted; and the command's timeout, not a read's last slice.
    assert result.problems == (f"no answer: {url}: no reply line within 2 s (received b'')",)
    assert 1.9 < result.elapsed_s < 5.0  # the driver's 2 s, well before the check's 6 s


def test_a_running_fan_fails_the_wind_off_check(rig):
    """A plausibility rule: the fan must be stopped before a test (wind off)."""
    inst = rig.config.instrument("fan")
    fan = build_driver(inst, rig.config.limits)
    with fan:
        fan.set_speed(200.0)
        fan.start()
        fan.wait_for_speed(200.0, tolerance_rpm=20.0)
        try:
            # timeout 5 s, as the CLI tests: the plc must pass on a loaded host too
            results = {r.device: r for r in check_rig(rig.config, timeout_s=5.0,
                                                      only=["fan", "plc"])}
        finally:
            fan.stop()
    assert not results["fan"].ok and "fan running at" in results["fan"].problems[0]
    assert results["plc"].ok


def test_acquire_refuses_to_record_when_a_device_fails_the_check(rig, tmp_path, capsys):
    """`windrig acquire` names every failing device and records nothing."""
    config = _live_config(rig, tmp_path)
    rig.simulators["barometer"].stop()
    rig.simulators["laser_check"].stop()
    out = tmp_path / "run.h5"
    assert main(["acquire", "--config", str(config), "--duration", "1", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("error: ")]
    assert any(line.startswith("error: laser_check (") for line in lines)
    assert any(line.startswith("error: barometer (") for line in lines)
    assert not out.exists() and not out.with_suffix(".events.log").exists()


def test_the_live_console_source_runs_the_same_check(rig, tmp_path):
    """The console's live source refuses to start, naming the device."""
    from daq.console.live_source import LiveSource

    config = load_rig_config(_live_config(rig, tmp_path))
    rig.simulators["plc"].stop()
    source = LiveSource(config, simulate=False, check=True)
    with pytest.raises(DeviceCheckError, match=r"(?m)^plc \(modbus\+tcp://127\.0\.0\.1:\d+"):
        source.open()
    source.close()
    assert source.acq is None


def test_simulate_write_config_gives_a_real_config_that_check_and_acquire_use(tmp_path):
    """`windrig simulate --write-config`: a config of real URLs; check and acquire pass on it."""
    out = tmp_path / "live.toml"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "daq.cli", "simulate", "--config",
                             str(CONFIG), "--write-config", str(out), "--duration", "120"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        deadline = time.monotonic() + 60.0
        while not out.exists():  # written once every simulator runs (atomically)
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no config written within 60 s"
            time.sleep(0.1)
        config = parse_rig_config(out.read_text(), source=str(out))
        assert config.simulation is None
        schemes = {i.name: i.url.split("://")[0] for i in config.instruments}
        assert schemes == {"scanner": "tcp", "laser_front": "socket", "laser_rear": "socket",
                           "laser_check": "socket", "fan": "modbus+tcp", "plc": "modbus+tcp",
                           "barometer": "socket"}
        assert all("127.0.0.1:" in i.url for i in config.instruments)
        assert isinstance(config.instrument("scanner").settings["data_port"], int)
        assert main(["check", "--config", str(out), "--timeout", "5"]) == 0
        run = tmp_path / "run.h5"
        assert main(["acquire", "--config", str(out), "--duration", "1.5", "--out",
                     str(run)]) == 0
        assert run.exists() and run.with_suffix(".events.log").exists()
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0


def test_a_campaign_checks_every_device_before_the_fan_moves(rig, tmp_path, capsys):
    """`windrig campaign` names the failing device, moves nothing and writes nothing."""
    config = _live_config(rig, tmp_path)
    plan = tmp_path / "plan.toml"
    plan.write_text('[campaign]\nmode = "fixed"\n\n[speeds]\nwind_speeds = [5.0, 7.0]\n')
    rig.simulators["laser_rear"].stop()
    out = tmp_path / "campaign"
    assert main(["campaign", str(plan), "--config", str(config), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert any(line.startswith("error: laser_rear (") for line in err.splitlines()), err
    assert "nothing recorded" in err
    assert not out.exists()  # no directory, no run file, no report
    fan = build_driver(load_rig_config(config).instrument("fan"), rig.config.limits)
    with fan:
        assert fan.speed() == 0.0  # never started
