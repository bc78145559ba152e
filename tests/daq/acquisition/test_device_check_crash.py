"""The device check fails a device whose check raises anything, and names the exception.

The drivers here are registered in code (``registry.register``) and open a real transport
(pyserial's ``loop://``); their ``read()`` raises what a driver's bug would: an
``AttributeError``, a ``KeyError``, a ``ZeroDivisionError``. Before, such an exception escaped
the check's thread (a traceback, then "1 of 1 device(s) OK", exit 0).
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import pytest

from daq.acquisition.device_check import check_rig
from daq.cli import main
from daq.config import load_rig_config
from daq.instruments.entry import DriverEntry

from support.drivers_in_code import rigs_with_drivers

pytestmark = pytest.mark.realtime


#: What each crashing driver's read() raises, and the line the check must print for it.
CRASHES = {
    "attribute": (AttributeError("'NoneType' object has no attribute 'decode'"),
                  "check failed: AttributeError: 'NoneType' object has no attribute 'decode'"),
    "key": (KeyError("pressure"), "check failed: KeyError: 'pressure'"),
    "zero": (ZeroDivisionError("float division by zero"),
             "check failed: ZeroDivisionError: float division by zero"),
}


class CrashingBarometer:
    """A barometer driver whose read() raises ``error`` (a bug, not a device's fault)."""

    def __init__(self, transport: Any, settings: Mapping[str, Any], *, error: Exception,
                 ) -> None:
        self.transport = transport
        self.error = error

    def open(self) -> None:
        """Open the transport (the device is reachable)."""
        self.transport.open()

    def close(self) -> None:
        """Close the transport."""
        self.transport.close()

    def describe(self) -> dict[str, dict[str, Any]]:
        """Describe the barometer role's channels."""
        return {k: {"units": u, "dtype": "float64", "shape": ()}
                for k, u in (("pressure", "Pa"), ("temperature", "K"), ("density", "kg/m^3"))}

    def read(self) -> Any:
        """Raise the driver's bug."""
        raise self.error


@pytest.fixture
def crashing(tmp_path: Path) -> Iterator[dict[str, Path]]:
    """Yield a rig config per crash, each with one crashing barometer registered in code."""
    drivers = {
        case: (DriverEntry(
            name=f"crashing_barometer_{case}", role="barometer",
            factory=lambda link, settings, error=error: CrashingBarometer(link, settings,
                                                                           error=error),
            validate=lambda table, where: dict(table)),
            f'\n[barometer]\ndriver = "crashing_barometer_{case}"\nurl = "loop://"\n')
        for case, (error, _) in CRASHES.items()}
    with rigs_with_drivers(tmp_path, drivers) as configs:
        yield configs


@pytest.mark.parametrize("case", sorted(CRASHES))
def test_an_unexpected_exception_fails_the_device_in_one_line(crashing, case, capsys, tmp_path):
    out = tmp_path / "check.json"
    assert main(["check", "--config", str(crashing[case]), "--json", str(out)]) == 1
    captured = capsys.readouterr()
    expected = CRASHES[case][1]
    assert f"FAIL barometer (loop://): {expected}" in captured.out.splitlines()
    assert "0 of 1 device(s) OK; failing: barometer" in captured.out
    assert "Traceback" not in captured.out + captured.err
    report = json.loads(out.read_text())
    assert report["ok"] is False and report["devices"][0]["problems"] == [expected]
    assert report["devices"][0]["reachable"] is True  # it opened: the crash came after


def test_the_traceback_is_shown_with_debug(crashing, capsys):
    assert main(["--debug", "check", "--config", str(crashing["attribute"])]) == 1
    captured = capsys.readouterr()
    assert "Traceback" in captured.err and "AttributeError" in captured.err
    assert "0 of 1 device(s) OK" in captured.out


def test_the_gate_of_acquire_campaign_and_gui_refuses_it(crashing):
    """require_devices_ok (the gate of acquire, campaign and gui) raises, naming the crash."""
    from daq.acquisition.device_check import require_devices_ok
    from daq.errors import DeviceCheckError

    config = load_rig_config(crashing["key"])
    with pytest.raises(DeviceCheckError, match="barometer .loop://.: check failed: KeyError"):
        require_devices_ok(config)
    assert not check_rig(config)[0].ok
