"""How a device reader talks to each kind of driver: one adapter per kind.

Responsibility: turn what a driver returns into :class:`Rows` (host times, device times,
counters, values, gaps, the driver's own block) and run its life cycle, per kind of driver:
:class:`ScannerAdapter` (configure and scan at the start, STOP at the end, a new scan to recover
or after the engine's pause for a CALZ, with the gap and the clock across that pause measured),
:class:`LaserAdapter` (``read_block``), :class:`PolledAdapter` (``read()`` on absolute deadlines,
for the barometer, the fan drive and the PLC). :func:`make_adapter` picks one;
:data:`REQUIRED_METHODS` lists what each kind of driver must have.

Not responsible for: the reader thread, its queue, faults and recovery timing
(:mod:`daq.acquisition.reader`), or the device protocols (the drivers).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from daq.acquisition.records import (
    FloatArray,
    Gaps,
    IntArray,
)
from daq.errors import TransportError, TransportTimeout

__all__ = ["POLL_S", "REQUIRED_METHODS", "Adapter", "LaserAdapter", "PolledAdapter", "Rows",
           "ScannerAdapter", "make_adapter"]

log = logging.getLogger(__name__)

#: Methods each kind of driver must have (checked at construction, no I/O).
REQUIRED_METHODS: Mapping[str, tuple[str, ...]] = {
    "scanner": ("open", "close", "configure", "scan", "stop", "read_block"),
    "laser": ("open", "close", "read_block"),
    "barometer": ("open", "close", "read"),
    "fan": ("open", "close", "read"),
    "plc": ("open", "close", "read"),
}


#: Default poll period of the polled kinds, s (the barometer uses its own poll_interval_s).
POLL_S: Mapping[str, float] = {"barometer": 1.0, "fan": 0.1, "plc": 0.1}


class Rows(NamedTuple):
    """What one read of a driver gave, in the form of a :class:`StreamBlock`'s fields."""

    host_time_ns: IntArray
    device_time: FloatArray | None
    counter: IntArray | None
    values: dict[str, npt.NDArray[Any]]
    gaps: Gaps
    raw: Any


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

    def read(self, stop: threading.Event) -> Rows | None:
        """Read once; return the rows, or None when nothing came (``stop`` ends a wait)."""
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


class ScannerAdapter(Adapter):
    """Scanner: configure + scan at begin, STOP at halt, a new scan to recover.

    A new scan restarts the driver's counter unwrapping (and the device's frame counter), so
    after a restart made here the counters are shifted to continue after the last one
    delivered, with a ``(last, -1)`` restart gap: the stream's counter stays increasing, as the
    driver keeps it across restarts within one scan.

    A restart after a pause of the engine's own (:meth:`restart_after_pause`, a CALZ) is
    measured instead where the device clock allows it: with absolute (PTP) frame times on both
    sides the gap is the number of frame periods the scan stood still, ``(last, n)``, and the
    counter continues after it. With frame times relative to the scan start (PTP absent) the
    new scan's clock starts again at 0 and the length is unknown (-1); its frame times are then
    continued on the previous scan's base with the host-measured time from STOP to SCAN (the
    only measure of it there is; off by less than a frame period plus half the two commands'
    durations), so that the clock map of the stream stays valid.
    """

    streaming = True
    #: Frames kept for :meth:`recent_pressure_mean`: the last this many seconds of them.
    RECENT_S = 0.5
    _MAX_RECENT_ROWS = 4096

    def __init__(self, driver: Any, read_timeout_s: float) -> None:
        super().__init__(driver)
        self.read_timeout_s = read_timeout_s
        self._offset = 0
        self._last: int | None = None
        self._restarted = False
        self._measure_gap = False  # the next restart follows a pause of ours: measure its gap
        self._time_shift = 0.0  # s added to frame times (a relative base continued)
        self._last_time = math.nan  # last finite frame time delivered (shifted), s
        self._last_host_ns = 0  # its host arrival time, ns
        self._last_base: str | None = None  # time base of the block that held it
        self._pause_s: float | None = None  # STOP to SCAN of the last pause, host-measured, s
        self._recent: deque[FloatArray] = deque()  # pressure rows of the last RECENT_S
        self._recent_rows = 0

    def begin(self) -> None:
        """Configure the scanner and start the scan."""
        self.driver.configure()
        self.driver.scan()

    def read(self, stop: threading.Event) -> Rows | None:
        """Read one block within the read timeout (None: nothing came)."""
        return self.read_within(self.read_timeout_s)

    def read_within(self, timeout_s: float) -> Rows | None:
        """Read one block, waiting at most ``timeout_s`` (s); None when nothing came."""
        try:
            block = self.driver.read_block(timeout_s=timeout_s)
        except TransportTimeout:
            return None
        values = {"pressure": block.pressure, "pitot": block.pitot,
                  "temperature": block.temperature, "trigger_time": block.trigger_time,
                  "module_status": block.module_status}
        gaps = [(g.after_counter, g.length) for g in block.gaps]
        counter = block.counter
        if self._restarted and len(block):
            self._restarted = False
            if self._last is not None:
                length = self._restart_gap(block)
                self._offset = self._last + 1 + max(length, 0) - int(counter[0])
                gaps = [(a, n) for a, n in gaps if a >= int(counter[0]) - 1 or n < 0]
                gaps.insert(0, (self._last - self._offset, length))
        if self._offset:
            counter = counter + self._offset
            gaps = [(a + self._offset, n) for a, n in gaps]
        frame_time = block.frame_time
        if self._time_shift:
            frame_time = frame_time + self._time_shift
        if len(block):
            self._last = int(counter[-1])
            self._remember(block, frame_time)
        return Rows(block.host_time_ns, frame_time, counter, values, tuple(gaps), block)

    def _restart_gap(self, block: Any) -> int:
        """Length of the gap before the first block of a restarted scan (-1: unknown).

        Also sets the frame-time shift of the new scan (see the class docstring).
        """
        measure, self._measure_gap = self._measure_gap, False
        if not measure:  # a restart of the recovery: as it always was
            self._time_shift = 0.0
            return -1
        base = getattr(block, "time_base", "ptp")
        finite = np.flatnonzero(np.isfinite(block.frame_time))
        if finite.size == 0 or not math.isfinite(self._last_time):
            return -1
        first = int(finite[0])
        t_first = float(block.frame_time[first])
        if base == "ptp":
            self._time_shift = 0.0  # absolute times continue by themselves
            if self._last_base != "ptp":
                return -1
            rate = float(getattr(self.driver, "rate_hz", math.nan))
            # Frames the scanner would have sent at its rate while it stood still; the new
            # scan's frames are not on the old frame grid, hence the rounding.
            n = round((t_first - self._last_time) * rate) - 1 if rate > 0 else -1
            return n if n >= 1 else -1
        pause_s = self._pause_s
        if pause_s is not None:
            # Relative frame time 0 is the SCAN; the last frame preceded STOP by less than a
            # period: on the old base, the new scan starts the pause after that frame.
            self._time_shift = self._last_time + pause_s
        else:  # the reader's recovery restarted it: the arrival times are all there is
            pause_s = (int(block.host_time_ns[first]) - self._last_host_ns) * 1e-9
            self._time_shift = self._last_time + pause_s - t_first
        log.warning("scanner: frame times restarted at 0 with the scan (PTP absent): continued "
                    "on the previous base with the host-measured pause, %.3f s", pause_s)
        return -1

    def _remember(self, block: Any, frame_time: FloatArray) -> None:
        """Keep the last frame time and the last ``RECENT_S`` of pressure rows."""
        finite = np.flatnonzero(np.isfinite(frame_time))
        if finite.size:
            self._last_time = float(frame_time[finite[-1]])
            self._last_host_ns = int(block.host_time_ns[finite[-1]])
            self._last_base = getattr(block, "time_base", "ptp")
        rate = float(getattr(self.driver, "rate_hz", 0.0) or 0.0)
        keep = min(max(math.ceil(self.RECENT_S * rate), 1), self._MAX_RECENT_ROWS)
        self._recent.append(np.asarray(block.pressure, dtype=np.float64))
        self._recent_rows += len(block)
        while self._recent_rows - len(self._recent[0]) >= keep:
            self._recent_rows -= len(self._recent.popleft())

    def recent_pressure_mean(self) -> tuple[FloatArray, int]:
        """Mean pressure per channel over the last ``RECENT_S`` of frames read, Pa, and rows.

        NaN rows (a missing module) are left out per channel; an empty history gives an empty
        array and 0.
        """
        if not self._recent:
            return np.zeros(0), 0
        rows = np.concatenate(list(self._recent))
        rate = float(getattr(self.driver, "rate_hz", 0.0) or 0.0)
        rows = rows[-min(max(math.ceil(self.RECENT_S * rate), 1), self._MAX_RECENT_ROWS):]
        with np.errstate(invalid="ignore"):
            counted = np.isfinite(rows).sum(axis=0)
            mean = np.where(counted > 0, np.nansum(rows, axis=0) / np.maximum(counted, 1),
                            np.nan)
        return mean, int(rows.shape[0])

    def drain(self, timeout_s: float) -> list[Rows]:
        """Read the frames still in flight after STOP, until ``timeout_s`` (s) of silence."""
        out = []
        while (rows := self.read_within(timeout_s)) is not None:
            out.append(rows)
        return out

    def restart_after_pause(self) -> None:
        """Start a new scan after a pause of the engine; its gap is measured (class docstring).

        The restart is marked before the scan is sent, so that a scan the reader's own recovery
        starts instead (this one failed) is marked and measured the same way.
        """
        self._restarted = True
        self._measure_gap = True
        self._pause_s = None
        self.driver.scan()

    def note_pause(self, pause_s: float) -> None:
        """Tell the host-measured time from STOP to SCAN, s (used without PTP: class doc)."""
        self._pause_s = float(pause_s)

    def recover(self, error: BaseException) -> None:
        """Start a new scan on fresh connections after a lasting TransportError."""
        # The driver already retried its data connections (bounded, logged); a TransportError
        # here means they stayed away: start over with fresh connections and a new scan.
        if isinstance(error, TransportError) and not isinstance(error, TransportTimeout):
            log.warning("scanner: restarting the scan after: %s", error)
            self._restarted = True
            self.driver.close()
            self.driver.open()
            self.driver.configure()
            self.driver.scan()

    def halt(self) -> None:
        """Stop the scan (STOP)."""
        self.driver.stop()


class LaserAdapter(Adapter):
    """Laser: ``read_block`` with the read timeout; its channels become the rows."""

    streaming = True
    _TIME_KEYS = ("host_time_ns", "device_time", "counter")

    def __init__(self, driver: Any, read_timeout_s: float) -> None:
        super().__init__(driver)
        self.read_timeout_s = read_timeout_s

    def read(self, stop: threading.Event) -> Rows | None:
        """Read one block within the read timeout (None: nothing came)."""
        try:
            block = self.driver.read_block(timeout_s=self.read_timeout_s)
        except TransportTimeout:
            return None
        ch = block.channels
        values = {k: v for k, v in ch.items() if k not in self._TIME_KEYS}
        return Rows(ch["host_time_ns"], ch["device_time"], ch["counter"], values,
                     tuple((g.after_counter, g.length) for g in block.gaps), block)


class PolledAdapter(Adapter):
    """``read()`` every ``interval_s`` on absolute deadlines (missed slots are skipped)."""

    def __init__(self, driver: Any, kind: str, interval_s: float) -> None:
        super().__init__(driver)
        self.kind = kind
        self.interval_s = interval_s
        self._next: float | None = None
        self._polls = 0  # the engine's poll number (fan, PLC)
        self._last_counter: int | None = None

    def read(self, stop: threading.Event) -> Rows | None:
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
        self._polls += 1
        reading = self.driver.read()
        if self.kind == "barometer":
            host_ns = int(reading.host_time_ns)
            counter = int(reading.counter)
            values = {k: np.array([v], dtype=np.float64) for k, v in reading.values().items()}
        else:
            host_ns, counter, values = self._from_dict(reading)
        gaps: Gaps = ()
        if self._last_counter is not None and counter != self._last_counter + 1:
            gaps = ((self._last_counter, counter - self._last_counter - 1),)
        self._last_counter = counter
        return Rows(np.array([host_ns], np.int64), None, np.array([counter], np.int64), values,
                     gaps, reading)

    def _from_dict(self, reading: Mapping[str, Any],
                   ) -> tuple[int, int, dict[str, npt.NDArray[Any]]]:
        """``{channel: {value, timestamp_ns}}`` (or plain values) -> one row.

        The row's host time is that of the channel that arrived last (the row is complete then).
        """
        stamps: list[int] = []
        values: dict[str, npt.NDArray[Any]] = {}
        for name, item in reading.items():
            if isinstance(item, Mapping) and "value" in item:
                values[name] = np.array([item["value"]])
                if "timestamp_ns" in item:
                    stamps.append(int(item["timestamp_ns"]))
            else:
                values[name] = np.array([item])
        host_ns = max(stamps) if stamps else time.monotonic_ns()
        return host_ns, self._polls, values


def make_adapter(kind: str, driver: Any, *, poll_interval_s: float | None,
                 read_timeout_s: float) -> Adapter:
    """Return the adapter of a driver of ``kind`` (a polled one every ``poll_interval_s``).

    ``poll_interval_s`` None: the barometer's own ``poll_interval_s`` setting, else
    :data:`POLL_S`. ``read_timeout_s``: the timeout of one streaming read, s.
    """
    if kind == "scanner":
        return ScannerAdapter(driver, read_timeout_s)
    if kind == "laser":
        return LaserAdapter(driver, read_timeout_s)
    if poll_interval_s is None:
        settings = getattr(driver, "settings", None)
        own = getattr(settings, "poll_interval_s", None) if kind == "barometer" else None
        poll_interval_s = float(own) if isinstance(own, (int, float)) else POLL_S[kind]
    return PolledAdapter(driver, kind, poll_interval_s)
