"""A driver's reading that breaks the reading contract is named, never recorded, never a crash.

An outside lab's driver (a plugin) may return a reading whose shape or dtype differs from its
own ``describe()``, with a channel too many, or with a counter that goes back. Before, the
engine queued it as it came: a wrong shape stopped the run writer, and with it the whole run,
on ``error: cannot reshape array of size 2 into shape (1,)`` naming no device; a counter going
back was recorded out of order without a word; and ``windrig check`` judged the first of the
two values as the pressure and passed the device. Now the engine stops that device's reader
with a fatal fault naming the device, the driver and the breach (the other devices go on), and
the device check fails the device with the same words.

The drivers are plain objects standing in for an outside lab's driver (the engine and the check
are never mocked); the device check's driver opens a real transport (pyserial's ``loop://``).
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from daq.acquisition.engine import Acquisition
from daq.acquisition.records import DeviceFault, StreamBlock
from daq.cli import main
from daq.instruments.entry import DriverEntry
from daq.instruments.reading import PollSequence, Reading

from support.drivers_in_code import rigs_with_drivers

pytestmark = pytest.mark.realtime

#: The barometer role's channels, as every barometer describes them.
BAROMETER = {"pressure": "Pa", "temperature": "K", "density": "kg/m^3"}


def corrupt(reading: Reading, breach: str) -> Reading:
    """Return ``reading`` broken as ``breach`` says (how a plugin's bug breaks it)."""
    channels = dict(reading.channels)
    counter = reading.counter
    if breach == "shape":  # two plausible pressures where one is described
        channels["pressure"] = np.array([[101325.0, 101300.0]])
    elif breach == "dtype":
        channels["pressure"] = channels["pressure"].astype(np.float32)
    elif breach == "channel":
        channels["humidity"] = np.array([0.4])
    elif breach == "counter":  # the poll number restarted at 1 (a driver that re-counts)
        counter = np.array([1], np.int64)
    return Reading(channels=channels, host_time_ns=reading.host_time_ns, counter=counter,
                   gaps=reading.gaps, info=reading.info)


#: Each breach, and the words that name it.
BREACHES = {
    "shape": "pressure: shape (1, 2) != described (1,)",
    "dtype": "pressure: dtype float32 != described float64",
    "channel": "channels ['density', 'humidity', 'pressure', 'temperature'] != described "
               "['density', 'pressure', 'temperature']",
    "counter": "counter goes back: 1 after 2",
}


class LabBarometer:
    """An outside lab's barometer: plausible readings, broken as ``breach`` from poll ``bad_from``.

    ``link`` is opened and closed as drivers do (a real transport in the device check, None in
    the engine's tests).
    """

    def __init__(self, link: Any, settings: Mapping[str, Any], *, breach: str,
                 bad_from: int = 1) -> None:
        self.link = link
        self.settings = settings
        self.breach = breach
        self.bad_from = bad_from
        self.polls = PollSequence()

    def open(self) -> None:
        """Open the link."""
        if self.link is not None:
            self.link.open()

    def close(self) -> None:
        """Close the link."""
        if self.link is not None:
            self.link.close()

    def describe(self) -> dict[str, dict[str, Any]]:
        """Describe the barometer role's channels (float64 scalars)."""
        return {k: {"units": u, "dtype": "float64", "shape": ()} for k, u in BAROMETER.items()}

    def read(self) -> Reading:
        """Poll once; the reading is broken from poll ``bad_from`` on."""
        number = self.polls.next()
        reading = self.polls.reading(
            number, {"pressure": 101325.0, "temperature": 293.15, "density": 1.2041},
            dict.fromkeys(BAROMETER, "float64"))
        return corrupt(reading, self.breach) if number >= self.bad_from else reading


#: How the messages name the driver: its module and class.
DRIVER_CLASS = f"{LabBarometer.__module__}.LabBarometer"


class Stream:
    """A laser-like stream of 10 rows per read, counters increasing: the device that goes on."""

    def __init__(self) -> None:
        self.next_counter = 0

    def open(self) -> None:
        """Nothing to open."""

    def close(self) -> None:
        """Nothing to close."""

    def read(self, timeout_s: float = 1.0) -> Reading:
        """Return the next 10 rows (after a pause of 2 ms, as a device's pace)."""
        time.sleep(0.002)
        counter = np.arange(self.next_counter, self.next_counter + 10, dtype=np.int64)
        self.next_counter += 10
        return Reading(channels={"distance": 0.025 + 0 * counter.astype(float)},
                       host_time_ns=np.full(10, time.monotonic_ns(), np.int64),
                       counter=counter, device_time=counter / 4000.0)


class Collector:
    """A subscriber that keeps the blocks and the fault events."""

    def __init__(self) -> None:
        self.blocks: list[StreamBlock] = []
        self.faults: list[DeviceFault] = []

    def __call__(self, name: str, doc: Any) -> None:
        if name == "block":
            self.blocks.append(doc)
        elif isinstance(doc, DeviceFault):
            self.faults.append(doc)

    def of(self, device: str) -> list[StreamBlock]:
        return [b for b in self.blocks if b.device == device]


@pytest.mark.parametrize("breach", sorted(BREACHES))
def test_a_breaking_reading_stops_that_device_alone_named_and_unrecorded(breach, wait_until):
    # The counter breach needs two good polls first (1, 2), then poll 3 numbered 1 again.
    baro = LabBarometer(None, {}, breach=breach, bad_from=3 if breach == "counter" else 1)
    sink = Collector()
    with Acquisition({"barometer": ("barometer", baro), "laser": ("laser", Stream())},
                     subscribers=[sink], poll_interval_s={"barometer": 0.01},
                     read_timeout_s=0.05, join_timeout_s=1.0) as acq:
        wait_until(lambda: not acq.stats()["barometer"].running
                   and len(sink.of("laser")) > 10, "the barometer stopped, the laser went on")
        assert acq.stats()["laser"].running
        summary = acq.stop()
    # The end of the run says it too (`windrig acquire` prints the errors and exits 1).
    (error,) = summary["errors"]
    assert error.startswith("barometer: read no more after its driver failed: its driver ")
    assert error.endswith(BREACHES[breach] + "; not recorded, and this device is read no more")
    (fault,) = sink.faults
    assert fault.fatal and fault.device == "barometer" and fault.error == "PluginError"
    assert f"its driver {DRIVER_CLASS} delivered a reading that breaks the reading contract " \
           "(docs/guides/drivers.md): " in fault.text
    assert BREACHES[breach] in fault.text and "\n" not in fault.text
    # Nothing of the broken reading was recorded; the good polls before it were.
    delivered = sink.of("barometer")
    assert [int(b.counter[0]) for b in delivered] == ([1, 2] if breach == "counter" else [])
    assert all(b.values["pressure"].shape == (1,) for b in delivered)


@pytest.fixture
def lab_rigs(tmp_path: Path) -> Iterator[dict[str, Path]]:
    """Yield a rig config per breach, each with its barometer registered in code on loop://."""
    drivers = {
        breach: (DriverEntry(
            name=f"lab_barometer_{breach}", role="barometer",
            factory=lambda link, settings, breach=breach: LabBarometer(
                link, settings, breach=breach, bad_from=2 if breach == "counter" else 1),
            validate=lambda table, where: dict(table)),
            f'\n[barometer]\ndriver = "lab_barometer_{breach}"\nurl = "loop://"\n')
        for breach in BREACHES}
    with rigs_with_drivers(tmp_path, drivers) as configs:
        yield configs


@pytest.mark.parametrize("breach", sorted(BREACHES))
def test_the_device_check_fails_a_device_whose_reading_breaks_the_contract(
        lab_rigs, breach, capsys):
    assert main(["check", "--config", str(lab_rigs[breach])]) == 1
    captured = capsys.readouterr()
    expected = BREACHES[breach].replace("after 2", "after 1")  # the check polls from 1
    line = next(x for x in captured.out.splitlines() if x.startswith("FAIL barometer"))
    assert line.startswith(f"FAIL barometer (loop://): check failed: its driver {DRIVER_CLASS} "
                           "delivered a reading that breaks the reading contract")
    assert line.endswith(expected)
    assert "Traceback" not in captured.out + captured.err
