"""How a device reader drives each kind of driver: when to read, and its life cycle.

Responsibility: run a driver's life cycle and call its ``read()``, which returns a
:class:`~daq.instruments.reading.Reading` for every driver alike (the contract of
:mod:`daq.instruments.reading`): :class:`StreamingAdapter` (the scanner and the lasers: ``read``
with the read timeout), :class:`ScannerAdapter` (a streaming one that also starts the scan at
the beginning, stops it at the end, and asks the driver to recover), :class:`PolledAdapter`
(``read()`` on absolute deadlines, for the barometer, the fan drive and the PLC).
:func:`make_adapter` picks one (an ``analog`` device streams as a laser does);
:data:`REQUIRED_METHODS` lists what each kind of driver must have.

Not responsible for: the reader thread, its queue, faults and recovery timing
(:mod:`daq.acquisition.reader`), the device protocols, or a scanner's restarts (the scanner
driver continues its counters and frame times across its scans itself).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Mapping
from typing import Any

from daq.errors import TransportTimeout
from daq.instruments.reading import Reading

__all__ = ["POLL_S", "REQUIRED_METHODS", "Adapter", "PolledAdapter", "ScannerAdapter",
           "StreamingAdapter", "make_adapter"]

log = logging.getLogger(__name__)

#: Methods each kind of driver must have (checked at construction, no I/O).
REQUIRED_METHODS: Mapping[str, tuple[str, ...]] = {
    "scanner": ("open", "close", "start", "stop", "recover", "read", "drain", "note_pause",
                "recent_pressure_mean"),
    "laser": ("open", "close", "read"),
    "analog": ("open", "close", "read"),
    "barometer": ("open", "close", "read"),
    "fan": ("open", "close", "read"),
    "plc": ("open", "close", "read"),
}


#: Default poll period of the polled kinds, s (a driver's own ``settings.poll_interval_s``
#: takes precedence; :func:`daq.instruments.build.build_driver` refuses a polled driver that
#: would hide it).
POLL_S: Mapping[str, float] = {"barometer": 1.0, "fan": 0.1, "plc": 0.1}


class Adapter:
    """Life cycle and reads of one driver; ``read`` returns None when there is nothing yet."""

    streaming = False

    def __init__(self, driver: Any) -> None:
        self.driver = driver

    def open(self) -> None:
        """Open the driver (no data yet)."""
        self.driver.open()

    def begin(self) -> None:
        """Start producing data (after every device is open)."""

    def read(self, stop: threading.Event) -> Reading | None:
        """Read once; return the reading, or None when nothing came (``stop`` ends a wait)."""
        raise NotImplementedError

    def reconnects(self) -> int | None:
        """Count the reconnects the driver made on its own (None: it does not count them).

        ``driver.reconnects`` (the lasers) or ``driver.stats["reconnects"]`` (the scanner, the
        barometer).
        """
        count = getattr(self.driver, "reconnects", None)
        if count is None:
            stats = getattr(self.driver, "stats", None)
            count = stats.get("reconnects") if isinstance(stats, Mapping) else None
        return count if isinstance(count, int) and not isinstance(count, bool) else None

    def recover(self, error: BaseException) -> None:
        """Make the driver readable again after ``error`` (reopen it if it gave up)."""
        if getattr(self.driver, "is_open", True) is False:
            log.info("reopening %r after: %s", self.driver, error)
            self.driver.close()
            self.driver.open()

    def halt(self) -> None:
        """Stop producing data (before the readers stop)."""

    def close(self) -> None:
        """Close the driver."""
        self.driver.close()


class StreamingAdapter(Adapter):
    """A streaming driver: ``read(timeout_s=...)`` with the read timeout, None when it times out."""

    streaming = True

    def __init__(self, driver: Any, read_timeout_s: float) -> None:
        super().__init__(driver)
        self.read_timeout_s = read_timeout_s

    def read(self, stop: threading.Event) -> Reading | None:
        """Read one block within the read timeout (None: nothing came)."""
        try:
            reading: Reading = self.driver.read(timeout_s=self.read_timeout_s)
        except TransportTimeout:
            return None
        return reading


class ScannerAdapter(StreamingAdapter):
    """The scanner: ``start()`` (configure and scan) at begin, STOP at halt, its own recovery."""

    def begin(self) -> None:
        """Configure the scanner and start the scan."""
        self.driver.start()

    def recover(self, error: BaseException) -> None:
        """Let the driver start a new scan on fresh connections (after a lasting loss)."""
        self.driver.recover(error)

    def halt(self) -> None:
        """Stop the scan (STOP)."""
        self.driver.stop()


class PolledAdapter(Adapter):
    """``read()`` every ``interval_s`` on absolute deadlines (missed slots are skipped)."""

    def __init__(self, driver: Any, interval_s: float) -> None:
        super().__init__(driver)
        self.interval_s = interval_s
        self._next: float | None = None

    def read(self, stop: threading.Event) -> Reading | None:
        """Wait for the next poll slot (None if ``stop`` is set meanwhile), then ``read()``."""
        now = time.monotonic()
        if self._next is None:
            self._next = now
        elif self._next > now and stop.wait(self._next - now):
            return None
        now = time.monotonic()
        self._next += self.interval_s
        if self._next < now:  # overran: skip the missed slots rather than burst
            self._next += math.ceil((now - self._next) / self.interval_s) * self.interval_s
        if stop.is_set():
            return None
        reading: Reading = self.driver.read()
        return reading


def make_adapter(kind: str, driver: Any, *, poll_interval_s: float | None,
                 read_timeout_s: float) -> Adapter:
    """Return the adapter of a driver of ``kind`` (a polled one every ``poll_interval_s``).

    ``poll_interval_s`` None: the driver's own ``settings.poll_interval_s`` where it has one
    (the barometer's, or any polled driver's), else :data:`POLL_S`. ``read_timeout_s``: the
    timeout of one streaming read, s.
    """
    if kind == "scanner":
        return ScannerAdapter(driver, read_timeout_s)
    if kind in ("laser", "analog"):
        return StreamingAdapter(driver, read_timeout_s)
    if poll_interval_s is None:
        own = getattr(getattr(driver, "settings", None), "poll_interval_s", None)
        poll_interval_s = (float(own) if isinstance(own, (int, float))
                           and not isinstance(own, bool) else POLL_S[kind])
    return PolledAdapter(driver, poll_interval_s)
