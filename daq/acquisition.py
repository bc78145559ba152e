"""The acquisition engine: a reader thread per instrument, a dispatcher, (name, doc) subscribers.

Responsibility: open and start the instruments of a rig, read every one of them in its own
blocking reader thread (:class:`DeviceReader`: the scanner and the lasers with ``read_block``,
the barometer, the fan drive and the PLC by polling ``read()``), turn what each driver returns
into one uniform record (:class:`StreamBlock`), pass the records through bounded per-device
queues to one dispatcher thread, and hand them to subscribers as bluesky-style ``(name, doc)``
calls: ``"start"`` (metadata), ``"block"`` (a :class:`StreamBlock`), ``"event"`` (an
:class:`Event`: operator markers, releases, faults, overflows) and ``"stop"`` (a summary).
Operator actions on the PLC (arm, release, trigger) pass through the engine so that each is
recorded as an event with its host time. Every subscriber call happens on the dispatcher
thread, so a subscriber needs no locking of its own.

Not responsible for: the device protocols (the drivers), mapping device clocks onto the host
clock (:mod:`daq.sync`), writing files (:mod:`daq.recorder`), or plotting (:mod:`daq.live`, which
polls a :class:`~daq.ring_buffer.RingBuffer` fed by a subscriber). The acquisition threads never
touch h5py or Qt (STYLE.md, "Threads and GUI").

Design choices:

- **Full queue: drop the oldest block, mark the gap.** A reader never blocks on its queue (a
  blocked reader lets the device's own buffer overrun, which loses data silently or with
  less precise accounting). When its queue is full it removes the oldest queued block and
  enqueues the new one: the newest data is what the operator watches, what a release
  detector needs now, and what bounds the latency of everything downstream; an old backlog is
  worth less. The loss is counted per device (:meth:`Acquisition.stats`) and marked exactly:
  the next delivered block of that device carries a gap covering the dropped counters (plus the
  device gaps the dropped blocks carried) in :attr:`StreamBlock.gaps`, and an ``"overflow"``
  event precedes it; the ``"stop"`` summary totals them.
- **Faults: report, back off, recover.** A :class:`~daq.errors.DaqError` from a driver is logged,
  counted and sent to subscribers as a :class:`DeviceFault`; the reader then waits (1st retry
  after ``backoff_min_s``, doubling to ``backoff_max_s``; the wait ends at once on stop), asks
  the driver to recover where the driver supports it (a laser that gave up is reopened, a
  scanner whose data connections stayed away is reopened and its scan restarted; the Modbus
  bus and the barometer reconnect on their own) and reads again. The first data after a fault
  gives a ``"recovered"`` event. A line the driver lost and reopened by itself within a read
  (the lasers, the scanner's data connections and the barometer do, counting it in
  ``reconnects`` / ``stats["reconnects"]``) raises nothing, yet it is a fault too: the reader
  reports it as a :class:`DeviceFault` when it sees the count grow, and the first data that
  arrives after that gives the ``"recovered"`` event. Any other exception is a bug, not a device
  fault: it is logged with its traceback, reported as a fatal :class:`DeviceFault`, and that
  reader stops (the others continue).
- **Stop is cooperative.** :meth:`Acquisition.stop` stops the scan, sets each reader's
  ``threading.Event`` (polled readers wait on it; streaming reads use a short timeout), joins the
  readers within ``join_timeout_s``, closes the drivers (which also unblocks a reader stuck in a
  read), then lets the dispatcher drain what is queued and deliver ``"stop"``.
"""

from __future__ import annotations

import dataclasses
import datetime
import logging
import math
import queue
import threading
import time
import uuid
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from types import TracebackType
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol

import numpy as np
import numpy.typing as npt

from daq.errors import DaqError, TransportError, TransportTimeout

if TYPE_CHECKING:
    from daq.config import RigConfig

__all__ = [
    "KINDS",
    "ROLE_KINDS",
    "SYSTEM_EVENT_KINDS",
    "Acquisition",
    "CalzError",
    "CalzResult",
    "DeviceFault",
    "DeviceReader",
    "DeviceStats",
    "Event",
    "StreamBlock",
    "Subscriber",
    "drivers_from_config",
]

log = logging.getLogger(__name__)

#: Kinds of device the engine knows how to read.
KINDS = ("scanner", "laser", "barometer", "fan", "plc")
#: Rig-config role -> engine kind.
ROLE_KINDS: Mapping[str, str] = {"scanner": "scanner", "lasers": "laser",
                                 "barometer": "barometer", "fan": "fan", "plc": "plc"}
#: Event kinds the engine itself emits; :meth:`Acquisition.mark` refuses them.
SYSTEM_EVENT_KINDS = frozenset({"fault", "recovered", "overflow", "release", "release_failed",
                                "arm", "trigger", "calz", "calz_failed"})

#: Methods each kind of driver must have (checked at construction, no I/O).
_NEEDS: Mapping[str, tuple[str, ...]] = {
    "scanner": ("open", "close", "configure", "scan", "stop", "read_block"),
    "laser": ("open", "close", "read_block"),
    "barometer": ("open", "close", "read"),
    "fan": ("open", "close", "read"),
    "plc": ("open", "close", "read"),
}
#: Default poll period of the polled kinds, s (the barometer uses its own poll_interval_s).
_POLL_S: Mapping[str, float] = {"barometer": 1.0, "fan": 0.1, "plc": 0.1}
#: Device gaps kept per run of dropped blocks (more are counted in the overflow event).
_MAX_DROPPED_GAPS = 256
#: After a CALZ that timed out the scanner may still be zeroing: how long a restart of the scan
#: keeps trying, s (the manual: a CALZ takes "under 10 seconds").
_RESTART_WAIT_S = 10.0

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]
Gaps = tuple[tuple[int, int], ...]


# ------------------------------------------------------------------------------------------------
# Records passed to subscribers
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class StreamBlock:
    """Rows read from one device in one call: the uniform record of the ``"block"`` doc.

    Attributes
    ----------
    device : str
        Instrument name (the key of the engine's ``drivers``).
    kind : str
        One of :data:`KINDS`.
    seq : int
        Block number of this device, from 0, consecutive as read (a dropped block leaves a
        hole in the delivered sequence, explained by an ``"overflow"`` event).
    host_time_ns : ndarray of int64, (n,)
        Host ``time.monotonic_ns()`` when each row arrived.
    device_time : ndarray of float64, (n,), or None
        The device's own clock, s (scanner frame time, laser timestamp); None for polled devices.
    counter : ndarray of int64, (n,), or None
        Unwrapped device counter (scanner frames, laser samples), the barometer's poll number,
        or the engine's poll number for the fan and the PLC (a failed poll skips one).
    values : mapping of str to ndarray
        Channel -> array of ``n`` rows (e.g. ``distance`` in m, ``pressure`` (n, taps) in Pa).
    gaps : tuple of (int, int)
        ``(after_counter, length)``: ``length`` rows missing after counter ``after_counter``,
        before or inside this block. Device gaps come from the driver (length -1: unknown, a
        scanner restart); polled devices get one per failed poll; rows the engine dropped on a
        full queue are marked here too (see ``overflow_samples``).
    raw : object
        The driver's own block or reading (``ScanBlock``, ``LaserBlock``, ``BarometerReading``,
        the ``read()`` dict) for specialised subscribers.
    overflow_samples : int
        Rows of this device dropped on a full queue just before this block (0 normally).
    """

    device: str
    kind: str
    seq: int
    host_time_ns: IntArray
    device_time: FloatArray | None
    counter: IntArray | None
    values: Mapping[str, npt.NDArray[Any]]
    gaps: Gaps = ()
    raw: Any = None
    overflow_samples: int = 0

    def __len__(self) -> int:
        return int(self.host_time_ns.shape[0])


@dataclass(frozen=True, kw_only=True)
class Event:
    """A marker in the run: the ``"event"`` doc.

    Attributes
    ----------
    kind : str
        ``"release"``, ``"arm"``, ``"trigger"``, ``"release_failed"``, ``"fault"``,
        ``"recovered"``, ``"overflow"``, or an operator's own kind given to
        :meth:`Acquisition.mark`.
    host_time_ns : int
        Host ``time.monotonic_ns()`` of the event (for a release: when the PLC acknowledged the
        RELEASE coil).
    text : str
        Human-readable description.
    device : str or None
        The instrument concerned, if any.
    data : mapping
        Further numbers (release timings, dropped counters, ...).
    """

    kind: str
    host_time_ns: int
    text: str = ""
    device: str | None = None
    data: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, kw_only=True)
class DeviceFault(Event):
    """A driver failure reported by a reader (an :class:`Event` of kind ``"fault"``).

    Attributes
    ----------
    error : str
        Exception class name (``TransportError``, ``ProtocolError``, ...).
    consecutive : int
        Faults in a row on this device (1 for the first).
    fatal : bool
        True when the reader gave up (an unexpected exception: a bug); it reads no more.
    """

    kind: str = "fault"
    error: str
    consecutive: int = 1
    fatal: bool = False


@dataclass(frozen=True)
class DeviceStats:
    """Counters of one device's reader (:meth:`Acquisition.stats`).

    Attributes
    ----------
    device, kind : str
        Instrument name and kind.
    blocks, samples : int
        Blocks and rows read from the driver.
    delivered : int
        Blocks handed to subscribers.
    overflows, overflow_samples : int
        Blocks and rows dropped because the queue was full.
    faults : int
        Driver faults reported (stalls included).
    gaps : int
        Gaps the device streams reported (not counting overflows).
    last_arrival_ns : int or None
        Host ``time.monotonic_ns()`` of the last block read.
    queued : int
        Blocks waiting in the queue now.
    running : bool
        The reader thread is alive.
    failed : str or None
        The fatal error that stopped the reader, if any.
    """

    device: str
    kind: str
    blocks: int
    samples: int
    delivered: int
    overflows: int
    overflow_samples: int
    faults: int
    gaps: int
    last_arrival_ns: int | None
    queued: int
    running: bool
    failed: str | None


class CalzError(DaqError, RuntimeError):
    """A zero calibration during a run failed after the scan was interrupted.

    The message says at which step (``pause``, ``stop``, ``calz``, ``restart``) and whether the
    scan runs again; the device's own error is the ``__cause__``.
    """


@dataclass(frozen=True, eq=False)
class CalzResult:
    """What :meth:`Acquisition.calz` did: the pause of the scan and the zero it removed.

    Attributes
    ----------
    device : str
        The scanner.
    wind_speed_now : float
        The wind speed the caller vouched for, m/s (0: the driver refuses anything else).
    stop_ns, stopped_ns : int
        Host ``time.monotonic_ns()`` just before STOP was sent and once it was acknowledged:
        the scanner stopped in between.
    restart_ns, restarted_ns : int
        The same for the new scan: before the (successful) restart began and once SCAN was
        acknowledged.
    pause_s : float
        How long the scanner did not scan, s: from the middle of the STOP command to the
        middle of the restart, each known to within half its duration (a few ms; the bounds
        are ``(restart_ns - stopped_ns)`` and ``(restarted_ns - stop_ns)``).
    calz_s : float
        Time from CALZ to READY, s.
    offsets_before_pa : ndarray of float64, (channels,)
        Mean pressure per channel over the last frames before STOP (``frames_averaged`` of
        them), Pa. Wind-off (as a CALZ must be) this is the zero error the CALZ removed; NaN
        for a channel without a frame.
    frames_averaged : int
        Frames in that mean.
    event : Event
        The ``"calz"`` event posted.
    """

    device: str
    wind_speed_now: float
    stop_ns: int
    stopped_ns: int
    restart_ns: int
    restarted_ns: int
    pause_s: float
    calz_s: float
    offsets_before_pa: FloatArray
    frames_averaged: int
    event: Event

    def summary(self) -> dict[str, float | int]:
        """Zero-offset figures for an event or a status line (Pa): RMS, max and where."""
        return _offsets_summary(self.offsets_before_pa, self.frames_averaged)


def _offsets_summary(offsets: FloatArray, frames: int) -> dict[str, float | int]:
    finite = np.isfinite(offsets)
    if not finite.any():
        return {"frames_averaged": frames, "channels": 0}
    abs_off = np.where(finite, np.abs(offsets), -1.0)
    worst = int(np.argmax(abs_off))
    return {"frames_averaged": frames, "channels": int(finite.sum()),
            "offset_mean_pa": float(np.mean(offsets[finite])),
            "offset_rms_pa": float(np.sqrt(np.mean(offsets[finite] ** 2))),
            "offset_max_abs_pa": float(abs_off[worst]), "offset_max_channel": worst}


class Subscriber(Protocol):
    """A ``(name, doc)`` callback, as in bluesky: called on the dispatcher thread only."""

    def __call__(self, name: str, doc: Any, /) -> None:
        """Receive ``"start"`` (dict), ``"block"``, ``"event"`` or ``"stop"`` (dict)."""


# ------------------------------------------------------------------------------------------------
# Adapters: how a reader talks to each kind of driver
# ------------------------------------------------------------------------------------------------
class _Rows(NamedTuple):
    host_time_ns: IntArray
    device_time: FloatArray | None
    counter: IntArray | None
    values: dict[str, npt.NDArray[Any]]
    gaps: Gaps
    raw: Any


class _Adapter:
    """Life cycle and reads of one driver; ``read`` returns None when there is nothing yet."""

    streaming = False

    def __init__(self, driver: Any) -> None:
        self.driver = driver

    def open(self) -> None:
        self.driver.open()

    def begin(self) -> None:
        """Start producing data (after every device is open)."""

    def read(self, stop: threading.Event) -> _Rows | None:
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
        self.driver.close()


class _ScannerAdapter(_Adapter):
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
        self.driver.configure()
        self.driver.scan()

    def read(self, stop: threading.Event) -> _Rows | None:
        return self.read_within(self.read_timeout_s)

    def read_within(self, timeout_s: float) -> _Rows | None:
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
        return _Rows(block.host_time_ns, frame_time, counter, values, tuple(gaps), block)

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

    def drain(self, timeout_s: float) -> list[_Rows]:
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
        self.driver.stop()


class _LaserAdapter(_Adapter):
    streaming = True
    _TIME_KEYS = ("host_time_ns", "device_time", "counter")

    def __init__(self, driver: Any, read_timeout_s: float) -> None:
        super().__init__(driver)
        self.read_timeout_s = read_timeout_s

    def read(self, stop: threading.Event) -> _Rows | None:
        try:
            block = self.driver.read_block(timeout_s=self.read_timeout_s)
        except TransportTimeout:
            return None
        ch = block.channels
        values = {k: v for k, v in ch.items() if k not in self._TIME_KEYS}
        return _Rows(ch["host_time_ns"], ch["device_time"], ch["counter"], values,
                     tuple((g.after_counter, g.length) for g in block.gaps), block)


class _PolledAdapter(_Adapter):
    """``read()`` every ``interval_s`` on absolute deadlines (missed slots are skipped)."""

    def __init__(self, driver: Any, kind: str, interval_s: float) -> None:
        super().__init__(driver)
        self.kind = kind
        self.interval_s = interval_s
        self._next: float | None = None
        self._polls = 0  # the engine's poll number (fan, PLC)
        self._last_counter: int | None = None

    def read(self, stop: threading.Event) -> _Rows | None:
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
        return _Rows(np.array([host_ns], np.int64), None, np.array([counter], np.int64), values,
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


def _make_adapter(kind: str, driver: Any, *, poll_interval_s: float | None,
                  read_timeout_s: float) -> _Adapter:
    if kind == "scanner":
        return _ScannerAdapter(driver, read_timeout_s)
    if kind == "laser":
        return _LaserAdapter(driver, read_timeout_s)
    if poll_interval_s is None:
        settings = getattr(driver, "settings", None)
        own = getattr(settings, "poll_interval_s", None) if kind == "barometer" else None
        poll_interval_s = float(own) if isinstance(own, (int, float)) else _POLL_S[kind]
    return _PolledAdapter(driver, kind, poll_interval_s)


# ------------------------------------------------------------------------------------------------
# Reader
# ------------------------------------------------------------------------------------------------
@dataclass
class _DropRun:
    """Consecutive blocks of one device dropped on a full queue."""

    first_seq: int
    last_seq: int
    blocks: int
    samples: int
    first_counter: int | None
    last_counter: int | None
    first_time_ns: int
    last_time_ns: int
    gaps: list[tuple[int, int]]
    gaps_truncated: int = 0

    def add(self, block: StreamBlock) -> None:
        self.last_seq = block.seq
        self.blocks += 1
        self.samples += len(block)
        if block.counter is not None and len(block):
            if self.first_counter is None:
                self.first_counter = int(block.counter[0])
            self.last_counter = int(block.counter[-1])
        if len(block):
            self.last_time_ns = int(block.host_time_ns[-1])
        room = _MAX_DROPPED_GAPS - len(self.gaps)
        self.gaps.extend(block.gaps[:max(room, 0)])
        self.gaps_truncated += max(len(block.gaps) - max(room, 0), 0)

    @classmethod
    def of(cls, block: StreamBlock) -> _DropRun:
        t0 = int(block.host_time_ns[0]) if len(block) else time.monotonic_ns()
        run = cls(block.seq, block.seq, 0, 0, None, None, t0, t0, [])
        run.add(block)
        return run

    def gap(self) -> tuple[int, int] | None:
        """Return the overflow gap ``(after_counter, length)`` (counter units), if counted."""
        if self.first_counter is None or self.last_counter is None:
            return None
        return (self.first_counter - 1, self.last_counter - self.first_counter + 1)


class DeviceReader:
    """One instrument's blocking reader thread and bounded queue.

    Parameters
    ----------
    name : str
        Instrument name.
    kind : str
        One of :data:`KINDS`.
    driver : object
        The driver (not necessarily open yet).
    queue_size : int
        Blocks the queue holds (>= 1); when full the oldest is dropped and accounted.
    on_event : callable
        Called with each :class:`DeviceFault` / recovery :class:`Event` (from this thread).
    doorbell : threading.Event
        Set after every enqueued block (wakes the dispatcher).
    poll_interval_s : float, optional
        Poll period of a polled kind, s (default: the barometer's own ``poll_interval_s``, else
        1 s; 0.1 s for the fan and the PLC).
    read_timeout_s : float
        Timeout of one streaming ``read_block``, s: bounds how long a stop waits for a reader.
    stall_s : float
        A streaming device that delivers nothing for this long is reported once as stalled.
    backoff_min_s, backoff_max_s : float
        Wait before the first retry after a fault, s, doubled per further fault up to the max.

    Notes
    -----
    The :class:`Acquisition` creates, starts and stops readers; use it rather than this class.
    """

    def __init__(self, name: str, kind: str, driver: Any, *, queue_size: int,
                 on_event: Callable[[Event], None], doorbell: threading.Event,
                 poll_interval_s: float | None = None, read_timeout_s: float = 0.2,
                 stall_s: float = 2.0, backoff_min_s: float = 0.1,
                 backoff_max_s: float = 5.0) -> None:
        if kind not in KINDS:
            raise ValueError(f"device {name!r}: kind must be one of {list(KINDS)}, got {kind!r}")
        missing = [m for m in _NEEDS[kind] if not callable(getattr(driver, m, None))]
        if missing:
            raise TypeError(f"device {name!r} ({kind}): the driver {type(driver).__name__} "
                            f"lacks {missing}")
        self.name = name
        self.kind = kind
        self.driver = driver
        self.queue: queue.Queue[StreamBlock] = queue.Queue(maxsize=queue_size)
        self._adapter = _make_adapter(kind, driver, poll_interval_s=poll_interval_s,
                                      read_timeout_s=read_timeout_s)
        self._on_event = on_event
        self._doorbell = doorbell
        self._stall_s = stall_s
        self._backoff = (backoff_min_s, backoff_max_s)
        self._stop = threading.Event()
        # Pausing (see pause()): the thread parks between reads while _pause_requested is set.
        self._park = threading.Condition()
        self._pause_requested = False
        self._parked = False
        self._ended = False
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()  # guards the counters and the drop ledger
        self._seq = 0
        self._count = dict.fromkeys(("blocks", "samples", "delivered", "overflows",
                                     "overflow_samples", "faults", "gaps"), 0)
        self._last_arrival_ns: int | None = None
        self._drops: list[_DropRun] = []
        self._next_drop_log = 0.0
        self.failed: BaseException | None = None

    # -- life cycle (called by the Acquisition) --------------------------------------------------
    def open_device(self) -> None:
        """Open the driver."""
        self._adapter.open()

    def begin(self) -> None:
        """Start the device's data (the scanner: configure, then scan)."""
        self._adapter.begin()

    def halt(self) -> None:
        """Stop the device's data (the scanner: STOP)."""
        self._adapter.halt()

    def close_device(self) -> None:
        """Close the driver (idempotent in every driver)."""
        self._adapter.close()

    def start(self) -> None:
        """Start the reader thread."""
        self._thread = threading.Thread(target=self._run, name=f"windrig-reader-{self.name}",
                                        daemon=True)
        self._thread.start()

    def request_stop(self) -> None:
        """Ask the thread to finish after its current read (a parked thread finishes too)."""
        with self._park:
            self._stop.set()
            self._park.notify_all()

    def pause(self, timeout_s: float) -> bool:
        """Park the thread between two reads; return True once it is parked.

        While parked the thread touches neither the driver nor its queue, so the caller may
        command the device and read from it (:meth:`drain`). Call :meth:`resume` afterwards in
        every case (also when this returned False: the request stays pending until then).

        Parameters
        ----------
        timeout_s : float
            Longest wait for the current read (or retry wait) to end, s.

        Returns
        -------
        bool
            True when the thread is parked; False when it did not park within ``timeout_s``
            or is not running.
        """
        with self._park:
            self._pause_requested = True
            self._park.notify_all()  # ends a retry wait early
            return self._park.wait_for(
                lambda: self._parked or self._ended or not self.alive or self._stop.is_set(),
                timeout=max(timeout_s, 0.0)) and self._parked

    def resume(self) -> None:
        """Let a paused thread read again (see :meth:`pause`)."""
        with self._park:
            self._pause_requested = False
            self._park.notify_all()

    @property
    def paused(self) -> bool:
        """Measure whether the thread is parked by :meth:`pause`."""
        return self._parked

    def drain(self, timeout_s: float) -> int:
        """Deliver the scanner frames still in flight after STOP; return the blocks delivered.

        Only while the thread is parked (:meth:`pause`): the caller's thread then reads in its
        place, and the blocks go to the queue as the thread's own would.

        Parameters
        ----------
        timeout_s : float
            The reading ends after this long without a frame, s.
        """
        if not self._parked or not isinstance(self._adapter, _ScannerAdapter):
            raise RuntimeError(f"{self.name}: drain() needs a scanner reader paused first")
        rows = self._adapter.drain(timeout_s)
        for r in rows:
            self._offer(r)
        return len(rows)

    def restart_after_pause(self) -> None:
        """Start a new scan after a pause (scanner only; see ``_ScannerAdapter``)."""
        if not self._parked or not isinstance(self._adapter, _ScannerAdapter):
            raise RuntimeError(f"{self.name}: restart_after_pause() needs a paused scanner")
        self._adapter.restart_after_pause()

    def note_pause(self, pause_s: float) -> None:
        """Tell the scanner adapter how long the scan stood still, s (before :meth:`resume`)."""
        if isinstance(self._adapter, _ScannerAdapter):
            self._adapter.note_pause(pause_s)

    def recent_pressure_mean(self) -> tuple[FloatArray, int]:
        """Mean pressure per channel over the last frames read, Pa, and their number."""
        if not isinstance(self._adapter, _ScannerAdapter):
            raise RuntimeError(f"{self.name}: not a scanner")
        return self._adapter.recent_pressure_mean()

    def report_fault(self, exc: BaseException) -> None:
        """Report a failure found outside the thread (e.g. a scan not restarted) as a fault."""
        self._fault(exc, 1)

    def _wait(self, seconds: float) -> bool:
        """Wait ``seconds`` between retries; end early on stop or pause; True on stop."""
        with self._park:
            self._park.wait_for(lambda: self._stop.is_set() or self._pause_requested,
                                timeout=seconds)
        return self._stop.is_set()

    def _park_if_asked(self) -> bool:
        """Park while a pause is requested; return True when the thread was parked."""
        with self._park:
            if not self._pause_requested or self._stop.is_set():
                return False
            self._parked = True
            self._park.notify_all()
            self._park.wait_for(lambda: not self._pause_requested or self._stop.is_set())
            self._parked = False
            return True

    def join(self, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for the thread; return True when it has finished."""
        if self._thread is not None:
            self._thread.join(max(timeout_s, 0.0))
        return not self.alive

    @property
    def alive(self) -> bool:
        """Measure whether the reader thread is running."""
        return self._thread is not None and self._thread.is_alive()

    # -- accounting ----------------------------------------------------------------------------
    def stats(self) -> DeviceStats:
        """Return a consistent snapshot of this reader's counters."""
        with self._lock:
            c = dict(self._count)
            last = self._last_arrival_ns
        return DeviceStats(device=self.name, kind=self.kind, last_arrival_ns=last,
                           queued=self.queue.qsize(), running=self.alive,
                           failed=None if self.failed is None else repr(self.failed), **c)

    def take_drops(self, before_seq: int | None = None) -> list[_DropRun]:
        """Remove and return the drop runs before block ``before_seq`` (all if None)."""
        with self._lock:
            if before_seq is None:
                out, self._drops = self._drops, []
            else:
                out = [r for r in self._drops if r.last_seq < before_seq]
                self._drops = [r for r in self._drops if r.last_seq >= before_seq]
            return out

    def delivered(self) -> None:
        """Count one block handed to the subscribers (dispatcher thread)."""
        with self._lock:
            self._count["delivered"] += 1

    # -- thread ----------------------------------------------------------------------------------
    def _run(self) -> None:
        adapter, stop = self._adapter, self._stop
        delay = self._backoff[0]
        error: BaseException | None = None  # the fault being recovered from
        needs_recover = False
        consecutive = 0
        stalled = False
        last_data = time.monotonic()
        reconnects = adapter.reconnects()
        reconnected_ns: int | None = None  # when a reconnect made by the driver was seen
        try:
            while not stop.is_set():
                if self._park_if_asked():
                    # A pause is not a stall; the driver may have reset its reconnect count.
                    last_data, reconnects = time.monotonic(), adapter.reconnects()
                    continue
                if needs_recover:
                    if self._wait(delay):
                        break
                    if self._pause_requested:
                        continue
                    delay = min(2.0 * delay, self._backoff[1])
                    try:
                        assert error is not None
                        adapter.recover(error)
                        needs_recover = False
                    except DaqError as exc:
                        if stop.is_set():
                            break
                        error, consecutive = exc, consecutive + 1
                        self._fault(exc, consecutive)
                        continue
                try:
                    rows = adapter.read(stop)
                except DaqError as exc:
                    if stop.is_set():  # closed under us while stopping: not a fault
                        log.debug("%s: read ended by stop: %s", self.name, exc)
                        break
                    error, consecutive, needs_recover = exc, consecutive + 1, True
                    self._fault(exc, consecutive)
                    continue
                count = adapter.reconnects()
                if reconnects is not None and count is not None and count > reconnects:
                    consecutive += 1
                    reconnected_ns = time.monotonic_ns()
                    self._fault(TransportError(
                        f"line lost; the driver reconnected by itself "
                        f"({count - reconnects} reconnect(s))"), consecutive)
                reconnects = count  # also a new baseline when the driver reset its count
                if rows is None:
                    idle = time.monotonic() - last_data
                    if adapter.streaming and not stalled and idle > self._stall_s:
                        stalled = True
                        consecutive += 1
                        self._fault(TransportTimeout(f"{self.name}: no data for {idle:.1f} s"),
                                    consecutive)
                    continue
                last_data = time.monotonic()
                # After a reconnect seen in this read, the rows may predate it (read before the
                # line dropped): the recovery is the first data that arrived after it was seen.
                if consecutive and (reconnected_ns is None
                                    or (len(rows.host_time_ns) > 0
                                        and int(rows.host_time_ns[-1]) > reconnected_ns)):
                    self._recovered(consecutive)
                    consecutive, stalled, error, reconnected_ns = 0, False, None, None
                    delay = self._backoff[0]
                self._offer(rows)
        except Exception as exc:  # a bug, not a device fault: reported as fatal, never retried
            log.exception("%s: reader failed; it reads no more", self.name)
            self.failed = exc
            self._fault(exc, consecutive + 1, fatal=True)
        finally:
            with self._park:  # a pause() waiting for this thread learns that it ended
                self._ended = True
                self._park.notify_all()

    def _fault(self, exc: BaseException, consecutive: int, *, fatal: bool = False) -> None:
        with self._lock:
            self._count["faults"] += 1
        if not fatal:
            log.warning("%s: %s: %s (fault %d in a row; retrying)", self.name,
                        type(exc).__name__, exc, consecutive)
        self._on_event(DeviceFault(host_time_ns=time.monotonic_ns(), device=self.name,
                                   text=str(exc), error=type(exc).__name__,
                                   consecutive=consecutive, fatal=fatal))

    def _recovered(self, faults: int) -> None:
        log.info("%s: data again after %d fault(s)", self.name, faults)
        self._on_event(Event(kind="recovered", host_time_ns=time.monotonic_ns(),
                             device=self.name, text=f"data again after {faults} fault(s)",
                             data={"faults": faults}))

    def _offer(self, rows: _Rows) -> None:
        block = StreamBlock(device=self.name, kind=self.kind, seq=self._seq,
                            host_time_ns=rows.host_time_ns, device_time=rows.device_time,
                            counter=rows.counter, values=rows.values, gaps=rows.gaps,
                            raw=rows.raw)
        self._seq += 1
        with self._lock:
            self._count["blocks"] += 1
            self._count["samples"] += len(block)
            self._count["gaps"] += len(block.gaps)
            self._last_arrival_ns = time.monotonic_ns()
        try:
            self.queue.put_nowait(block)
        except queue.Full:
            self._drop_oldest()
            self.queue.put_nowait(block)  # this thread is the only producer: there is room now
        self._doorbell.set()

    def _drop_oldest(self) -> None:
        # Under the lock, so that the dispatcher, which takes the ledger after getting the next
        # block (which it can only get once this one is out), always finds the record.
        with self._lock:
            try:
                old = self.queue.get_nowait()
            except queue.Empty:  # the dispatcher emptied it meanwhile
                return
            self._count["overflows"] += 1
            self._count["overflow_samples"] += len(old)
            if self._drops and self._drops[-1].last_seq == old.seq - 1:
                self._drops[-1].add(old)
            else:
                self._drops.append(_DropRun.of(old))
            total = self._count["overflows"]
        now = time.monotonic()
        if now >= self._next_drop_log:  # at most one log line per 5 s; all are counted
            self._next_drop_log = now + 5.0
            log.warning("%s: queue full (%d blocks): dropping the oldest block (%d dropped so "
                        "far; subscribers too slow)", self.name, self.queue.maxsize, total)


# ------------------------------------------------------------------------------------------------
# Engine
# ------------------------------------------------------------------------------------------------
class Acquisition:
    """Run a rig's instruments: reader threads, a dispatcher, and ``(name, doc)`` subscribers.

    Parameters
    ----------
    drivers : mapping of str to (kind, driver)
        Instrument name -> (one of :data:`KINDS`, driver object). Drivers are opened by
        :meth:`start` and closed by :meth:`stop`. See :func:`drivers_from_config`.
    queue_size : int
        Blocks each device's queue holds, >= 1 (a laser gives ~50 blocks/s, the scanner up to
        one per frame): when full, the oldest block is dropped and the gap marked.
    subscribers : iterable of Subscriber
        ``callback(name, doc)``, called in order on the dispatcher thread. An exception in one
        is logged and counted (``"stop"`` summary) and does not stop the others.
    metadata : mapping, optional
        Added to the ``"start"`` doc under ``"metadata"`` (operator, section, config text ...).
    poll_interval_s : mapping of str to float, optional
        Poll period per device name for polled kinds, s (defaults in :class:`DeviceReader`).
    read_timeout_s : float
        Timeout of one streaming read, s (> 0); bounds the stop latency of a quiet stream.
    stall_s : float
        A stream silent this long (s) is reported as a fault (once per stall).
    join_timeout_s : float
        Time :meth:`stop` gives all readers together to finish, s, before closing the drivers
        under them. A driver that retries internally (e.g. a laser reopening its line) may need
        a few seconds.
    backoff_min_s, backoff_max_s : float
        Retry wait after a fault, s: the first, and the cap of its doubling.
    control_queue_size : int
        Capacity of the queue of events and start/stop docs; an event that finds it full is
        counted (``events_dropped``) and logged.

    Notes
    -----
    One run per object: :meth:`start` once, :meth:`stop` once (further calls return the same
    summary). Use it as a context manager, or :meth:`run_until`.
    """

    def __init__(self, drivers: Mapping[str, tuple[str, Any]], *, queue_size: int = 1024,
                 subscribers: Iterable[Subscriber] = (), metadata: Mapping[str, Any] | None = None,
                 poll_interval_s: Mapping[str, float] | None = None, read_timeout_s: float = 0.2,
                 stall_s: float = 2.0, join_timeout_s: float = 5.0, backoff_min_s: float = 0.1,
                 backoff_max_s: float = 5.0, control_queue_size: int = 4096) -> None:
        if isinstance(queue_size, bool) or not isinstance(queue_size, int) or queue_size < 1:
            raise ValueError(f"queue_size must be an integer >= 1, got {queue_size!r}")
        if isinstance(control_queue_size, bool) or not isinstance(control_queue_size, int) \
                or control_queue_size < 1:
            raise ValueError(f"control_queue_size must be an integer >= 1, got "
                             f"{control_queue_size!r}")
        for key, value in (("read_timeout_s", read_timeout_s), ("stall_s", stall_s),
                           ("join_timeout_s", join_timeout_s), ("backoff_min_s", backoff_min_s),
                           ("backoff_max_s", backoff_max_s)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"{key} must be a finite number > 0, got {value!r}")
        if backoff_max_s < backoff_min_s:
            raise ValueError(f"backoff_max_s = {backoff_max_s!r} is below backoff_min_s = "
                             f"{backoff_min_s!r}")
        polls = dict(poll_interval_s or {})
        unknown = sorted(set(polls) - set(drivers))
        if unknown:
            raise ValueError(f"poll_interval_s names unknown device(s) {unknown}; devices: "
                             f"{sorted(drivers)}")
        for key, value in polls.items():
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"poll_interval_s[{key!r}] must be > 0, got {value!r}")
        if not drivers:
            raise ValueError("drivers is empty: nothing to acquire")
        self._doorbell = threading.Event()
        self._control: queue.Queue[tuple[str, Any]] = queue.Queue(maxsize=control_queue_size)
        self._readers: dict[str, DeviceReader] = {}
        for name, pair in drivers.items():
            if not (isinstance(pair, (tuple, list)) and len(pair) == 2):
                raise TypeError(f"drivers[{name!r}] must be a (kind, driver) tuple, got {pair!r}")
            kind, driver = pair
            self._readers[name] = DeviceReader(
                name, kind, driver, queue_size=queue_size, on_event=self._post_event,
                doorbell=self._doorbell, poll_interval_s=polls.get(name),
                read_timeout_s=read_timeout_s, stall_s=stall_s, backoff_min_s=backoff_min_s,
                backoff_max_s=backoff_max_s)
        self._state = "idle"  # idle -> starting -> running -> stopping -> stopped (or failed)
        self._state_lock = threading.Lock()
        self._subscribers: list[Subscriber] = []
        self._subscriber_errors: list[int] = []
        for sub in subscribers:
            self.subscribe(sub)
        self._metadata = dict(metadata or {})
        self._queue_size = queue_size
        self._join_timeout_s = float(join_timeout_s)
        self._dispatcher: threading.Thread | None = None
        self._finish = threading.Event()
        self._events_dropped = 0
        self._counts_lock = threading.Lock()
        self._releases: list[Event] = []
        self._calz_lock = threading.Lock()  # one CALZ at a time; stop() waits for it
        self._errors: list[str] = []
        self._stop_done: set[str] = set()
        self._reason = ""
        self._t0_ns = 0
        self._summary: dict[str, Any] | None = None

    # -- configuration ---------------------------------------------------------------------------
    def subscribe(self, subscriber: Subscriber) -> None:
        """Add a ``(name, doc)`` subscriber (before :meth:`start` only)."""
        if not callable(subscriber):
            raise TypeError(f"a subscriber is a callable (name, doc), got {subscriber!r}")
        if self._state != "idle":
            raise RuntimeError("subscribe before start(): subscribers are fixed while running")
        self._subscribers.append(subscriber)
        self._subscriber_errors.append(0)

    @property
    def drivers(self) -> dict[str, Any]:
        """Measure the driver of each device (for operator commands such as the fan speed)."""
        return {name: r.driver for name, r in self._readers.items()}

    @property
    def running(self) -> bool:
        """Measure whether the engine is acquiring (started and not yet stopping)."""
        return self._state == "running"

    def stats(self) -> dict[str, DeviceStats]:
        """Return the counters of every device: blocks, samples, overflows, faults, ..."""
        return {name: r.stats() for name, r in self._readers.items()}

    # -- life cycle ------------------------------------------------------------------------------
    def start(self) -> None:
        """Open every driver, start the scan, then the dispatcher and the reader threads.

        A driver that fails to open (or a scan that fails to start) closes the ones already
        opened and re-raises: nothing runs.
        """
        with self._state_lock:
            if self._state != "idle":
                raise RuntimeError(f"start(): the acquisition is {self._state} (one run per "
                                   "object)")
            self._state = "starting"
        opened: list[DeviceReader] = []
        try:
            for reader in self._readers.values():
                reader.open_device()
                opened.append(reader)
            for reader in self._readers.values():
                reader.begin()
        except BaseException:
            for reader in reversed(opened):
                self._cleanup(reader.close_device, f"closing {reader.name}")
            self._state = "failed"
            raise
        self._t0_ns = time.monotonic_ns()
        self._post("start", {
            "uid": uuid.uuid4().hex,
            "time": datetime.datetime.now(datetime.UTC).isoformat(),
            "host_time_ns": self._t0_ns,
            "devices": {name: {"kind": r.kind, "describe": _describe(r.driver)}
                        for name, r in self._readers.items()},
            "queue_size": self._queue_size,
            "metadata": self._metadata,
        })
        self._dispatcher = threading.Thread(target=self._dispatch, name="windrig-dispatcher",
                                            daemon=True)
        self._dispatcher.start()
        for reader in self._readers.values():
            reader.start()
        self._state = "running"
        log.info("acquisition started: %s", ", ".join(
            f"{n} ({r.kind})" for n, r in self._readers.items()))

    def stop(self, reason: str = "stop") -> dict[str, Any]:
        """Stop the scan, the readers (joined within ``join_timeout_s``), the drivers, dispatch.

        Returns the ``"stop"`` summary (also sent to the subscribers). Idempotent; safe to call
        again after an interruption (steps already done are skipped). Must not be called from
        a subscriber (the dispatcher thread).

        Returns
        -------
        dict
            ``reason``, ``duration_s``, ``devices`` (per-device :class:`DeviceStats` as dicts),
            ``overflows`` and ``overflow_samples`` (totals), ``faults``, ``events_dropped``,
            ``subscriber_errors``, ``releases`` (their events), ``errors`` (failures while
            stopping), ``threads_alive`` (threads that did not finish: should be empty).
        """
        if threading.current_thread() is self._dispatcher:
            raise RuntimeError("stop() called from a subscriber: it would wait for itself")
        with self._state_lock:
            if self._state == "stopped" and self._summary is not None:
                return self._summary
            if self._state in ("idle", "failed", "starting"):
                return self._build_summary("never started")
            if self._state == "running":
                self._reason = reason
            self._state = "stopping"
        # A CALZ in progress first restarts the scan and resumes its reader (bounded by its own
        # timeouts): stopping under it would interleave STOP with its commands. calz() refuses
        # to begin once the state is "stopping".
        with self._calz_lock:
            pass
        readers = list(self._readers.values())
        if "halt" not in self._stop_done:
            for reader in readers:
                self._cleanup(reader.halt, f"stopping {reader.name}")
            self._stop_done.add("halt")
        for reader in readers:
            reader.request_stop()
        deadline = time.monotonic() + self._join_timeout_s
        for reader in readers:
            reader.join(deadline - time.monotonic())
        if "close" not in self._stop_done:
            for reader in readers:
                self._cleanup(reader.close_device, f"closing {reader.name}")
            self._stop_done.add("close")
        for reader in readers:  # closing a driver unblocks a reader stuck in a read
            if reader.alive and not reader.join(1.0):
                msg = f"reader {reader.name} did not finish within the join timeout"
                log.error(msg)
                self._errors.append(msg)
        self._finish.set()
        self._doorbell.set()
        if self._dispatcher is not None:
            self._dispatcher.join(self._join_timeout_s)
            if self._dispatcher.is_alive():
                msg = "dispatcher did not finish (a subscriber blocks?)"
                log.error(msg)
                self._errors.append(msg)
        summary = self._summary if self._summary is not None else self._build_summary(
            self._reason)
        self._summary = summary
        self._state = "stopped"
        log.info("acquisition stopped (%s): %d overflow(s), %d fault(s)", summary["reason"],
                 summary["overflows"], summary["faults"])
        return summary

    def __enter__(self) -> Acquisition:
        self.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if exc_type is None:
            self.stop()
        elif issubclass(exc_type, KeyboardInterrupt):
            self.stop("interrupted")
        else:
            self.stop(f"error: {exc_type.__name__}: {exc}")

    def run_until(self, until: float | threading.Event | None = None, *,
                  poll_s: float = 0.1) -> dict[str, Any]:
        """Start (unless running), acquire until ``until``, stop cleanly; return the summary.

        Parameters
        ----------
        until : float, threading.Event or None
            A duration in s (>= 0), an event to wait for, or None to run until Ctrl-C.
        poll_s : float
            Slice of the wait, s: how quickly Ctrl-C is acted on.

        Returns
        -------
        dict
            The ``"stop"`` summary; its ``reason`` is ``"duration"``, ``"event"`` or
            ``"interrupted"`` (Ctrl-C: KeyboardInterrupt is handled, the engine stopped, the
            summary returned; a second Ctrl-C while stopping does not abort the stop).
        """
        if isinstance(until, (int, float)) and not isinstance(until, bool):
            if not (math.isfinite(until) and until >= 0):
                raise ValueError(f"until must be a duration >= 0 s, got {until!r}")
        elif until is not None and not isinstance(until, threading.Event):
            raise TypeError(f"until must be a duration (s), a threading.Event or None, got "
                            f"{until!r}")
        reason = "stop"
        try:
            if self._state == "idle":
                self.start()
            if isinstance(until, threading.Event):
                while not until.wait(poll_s):
                    pass
                reason = "event"
            elif until is None:
                while True:
                    time.sleep(poll_s)
            else:
                end = time.monotonic() + float(until)
                while (left := end - time.monotonic()) > 0:
                    time.sleep(min(poll_s, left))
                reason = "duration"
        except KeyboardInterrupt:
            log.warning("interrupted: stopping the acquisition cleanly")
            reason = "interrupted"
        while True:
            try:
                return self.stop(reason)
            except KeyboardInterrupt:
                log.warning("interrupted again: still stopping (bounded by the join timeouts)")

    # -- operator actions --------------------------------------------------------------------------
    def mark(self, kind: str, text: str = "") -> Event:
        """Record an operator marker (``kind`` of the operator's choosing, e.g. ``"note"``).

        Raises
        ------
        ValueError
            ``kind`` is empty or one the engine reserves (:data:`SYSTEM_EVENT_KINDS`).
        RuntimeError
            The engine is not running (the marker would be recorded nowhere).
        """
        if not isinstance(kind, str) or not kind.strip():
            raise ValueError(f"a marker kind is a non-empty string, got {kind!r}")
        if kind in SYSTEM_EVENT_KINDS:
            raise ValueError(f"marker kind {kind!r} is reserved for the engine's own events "
                             f"{sorted(SYSTEM_EVENT_KINDS)}")
        self._require_running(f"mark({kind!r})")
        event = Event(kind=kind, host_time_ns=time.monotonic_ns(), text=str(text))
        self._post_event(event)
        return event

    def release(self, plc: str | None = None) -> Event:
        """Release the model through the PLC and record a ``"release"`` event; return it.

        The event's ``host_time_ns`` is when the PLC acknowledged the RELEASE coil
        (``ReleaseTiming.command_ns``); ``data`` holds ``requested_ns`` (before the command),
        ``command_ns``, ``confirmed_ns`` (RELEASED read set) and ``delay_s``.

        Parameters
        ----------
        plc : str, optional
            Name of the PLC device; default: the only device of kind ``"plc"``.

        Raises
        ------
        SafetyError, DeviceError, TransportError
            From ``plc.release()`` (not armed; RELEASED never came; link lost); a
            ``"release_failed"`` event is recorded first.
        RuntimeError
            The engine is not running (a release must be recorded).
        """
        name, driver = self._plc(plc, "release")
        requested = time.monotonic_ns()
        try:
            timing = driver.release()
        except DaqError as exc:
            self._post_event(Event(kind="release_failed", host_time_ns=requested, device=name,
                                   text=str(exc), data={"error": type(exc).__name__}))
            raise
        command = int(getattr(timing, "command_ns", requested))
        confirmed = int(getattr(timing, "confirmed_ns", command))
        event = Event(kind="release", host_time_ns=command, device=name, text="model released",
                      data={"requested_ns": requested, "command_ns": command,
                            "confirmed_ns": confirmed, "delay_s": (confirmed - command) * 1e-9})
        with self._counts_lock:
            self._releases.append(event)
        self._post_event(event)
        return event

    def arm(self, plc: str | None = None) -> Event:
        """Arm the PLC (magnet on, one release permitted) and record an ``"arm"`` event.

        The event's ``host_time_ns`` is when the command was requested: arming catches a
        decaying model, and the decay is certainly free before that instant (the magnet acts
        somewhere between the request and the acknowledgement, ``data["acknowledged_ns"]``).
        """
        name, driver = self._plc(plc, "arm")
        requested = time.monotonic_ns()
        driver.arm()
        event = Event(kind="arm", host_time_ns=requested, device=name, text="release armed",
                      data={"acknowledged_ns": time.monotonic_ns()})
        self._post_event(event)
        return event

    def trigger(self, plc: str | None = None) -> Event:
        """Pulse the trigger line and record a ``"trigger"`` event at the rising edge's time."""
        name, driver = self._plc(plc, "trigger_pulse")
        t_ns = int(driver.trigger_pulse())
        round_trip = int(getattr(driver, "last_trigger_round_trip_ns", 0))
        event = Event(kind="trigger", host_time_ns=t_ns, device=name, text="trigger pulse",
                      data={"round_trip_s": round_trip * 1e-9})
        self._post_event(event)
        return event

    def calz(self, device: str | None = None, *, wind_speed_now: float,
             timeout_s: float = 30.0) -> CalzResult:
        """Zero the pressure scanner (CALZ) during the run, wind-off; return what it did.

        The scanner refuses every command but STOP while it scans, so the scan is interrupted:
        the scanner's reader is parked between two reads, STOP is sent, the frames still in
        flight are read and delivered, the driver's CALZ runs (its wind-off rule stays in
        force: ``wind_speed_now`` is passed through), a new scan is started and the reader
        resumed. The interruption is marked, never silent: the scanner stream gets a gap over
        the pause (its length in frames where the frame times are absolute, else -1; see
        ``_ScannerAdapter``), so the sync view has NaN pressures and forces there, and a
        ``"calz"`` event (at ``stop_ns``) carries the pause and the zero-offset summary.

        Parameters
        ----------
        device : str, optional
            The scanner's name; default: the only device of kind ``"scanner"``.
        wind_speed_now : float
            The wind speed now, m/s, as measured by the caller with the fan stopped. The
            driver refuses anything but 0 (:meth:`~daq.scanivalve_mps4264.ScanivalveMps4264.
            check_calz_allowed`), before anything is interrupted.
        timeout_s : float
            Longest wait for the scanner to finish zeroing, s (> 0; the manual: "under 10
            seconds"). Parking the reader is bounded separately by ``join_timeout_s``.

        Returns
        -------
        CalzResult
            Pause, CALZ duration, the zero it removed, the event posted.

        Raises
        ------
        RuntimeError
            The engine is not running, or a CALZ is already in progress (nothing is done).
        ValueError
            ``device`` is not a scanner of this engine, or ``timeout_s`` is not > 0.
        TypeError
            The scanner's driver has no ``calz()``.
        SafetyError
            The driver refuses: the wind is not off. Nothing was interrupted; a
            ``"calz_failed"`` event is posted.
        CalzError
            A step after the refusal check failed (the reader did not pause, STOP, CALZ or the
            restart of the scan failed); a ``"calz_failed"`` event is posted, the restart of
            the scan was tried in any case and the reader resumed. When the scan could not be
            restarted, a fault of the scanner is posted too and the reader's recovery (reopen,
            new scan) takes over.
        """
        if not (isinstance(timeout_s, (int, float)) and math.isfinite(timeout_s)
                and timeout_s > 0):
            raise ValueError(f"timeout_s must be a finite number > 0, got {timeout_s!r}")
        name, reader = self._scanner(device)
        if not self._calz_lock.acquire(blocking=False):
            raise RuntimeError(f"calz({name!r}): a CALZ is already in progress; wait for it")
        try:
            # Checked again under the lock: stop() waits for this lock once it is "stopping".
            self._require_running(f"calz({name!r})")
            if not reader.alive:
                raise RuntimeError(f"calz({name!r}): the scanner's reader has stopped "
                                   f"({reader.failed!r}); restart the acquisition")
            self._refuse_unsafe_calz(name, reader.driver, wind_speed_now)
            return self._calz_paused(name, reader, float(wind_speed_now), float(timeout_s))
        finally:
            self._calz_lock.release()

    def _scanner(self, name: str | None) -> tuple[str, DeviceReader]:
        self._require_running("calz()")
        scanners = [n for n, r in self._readers.items() if r.kind == "scanner"]
        if name is None:
            if len(scanners) != 1:
                raise ValueError(f"name the scanner: devices of kind 'scanner' are {scanners}")
            name = scanners[0]
        elif name not in scanners:
            raise ValueError(f"{name!r} is not a device of kind 'scanner'; those are "
                             f"{scanners}")
        driver = self._readers[name].driver
        if not callable(getattr(driver, "calz", None)):
            raise TypeError(f"scanner {name!r} driver {type(driver).__name__} has no calz()")
        return name, self._readers[name]

    def _refuse_unsafe_calz(self, name: str, driver: Any, wind_speed_now: float) -> None:
        """Apply the driver's wind-off rule before the scan is touched (a refusal costs no data)."""
        check = getattr(driver, "check_calz_allowed", None)
        if not callable(check):
            return  # the driver's calz() still applies its rule, after STOP
        try:
            check(wind_speed_now=wind_speed_now)
        except DaqError as exc:
            self._post_event(Event(
                kind="calz_failed", host_time_ns=time.monotonic_ns(), device=name,
                text=f"CALZ refused, the scan goes on: {exc}",
                data={"stage": "refused", "error": type(exc).__name__,
                      "wind_speed_now": wind_speed_now, "scan_interrupted": False}))
            raise

    def _calz_paused(self, name: str, reader: DeviceReader, wind_speed_now: float,
                     timeout_s: float) -> CalzResult:
        """Park the reader, STOP, drain, CALZ, restart the scan, resume: the steps of calz()."""
        driver = reader.driver
        if not reader.pause(self._join_timeout_s):
            reader.resume()
            why = (f"the reader of {name!r} did not pause within {self._join_timeout_s:g} s "
                   "(stuck in a read or a reconnect?)")
            self._calz_failed(name, "pause", why, time.monotonic_ns(), restarted=None)
            raise CalzError(f"CALZ of {name!r} not started: {why}; nothing was interrupted, "
                            "the scan goes on")
        stage = "stop"
        failure: DaqError | None = None
        calz_s = math.nan
        offsets, frames = np.zeros(0), 0
        stop_ns = stopped_ns = time.monotonic_ns()
        try:
            try:
                driver.stop()
                stopped_ns = time.monotonic_ns()
                # Frames sent before STOP are data like any other: deliver them, so that the
                # gap is only the time the scanner stood still.
                rate = float(getattr(driver, "rate_hz", 0.0) or 0.0)
                reader.drain(max(0.05, 5.0 / rate) if rate > 0 else 0.2)
                offsets, frames = reader.recent_pressure_mean()
                stage = "calz"
                took = driver.calz(wind_speed_now=wind_speed_now, timeout_s=timeout_s)
                calz_s = float(took) if isinstance(took, (int, float)) else math.nan
                stage = "restart"
            except DaqError as exc:
                failure = exc
            finally:  # also on a bug or Ctrl-C: the scan must run again if at all possible
                restart_error, restart_ns = self._restart_scan(name, reader)
                restarted_ns = time.monotonic_ns()
                # Each end of the standstill is known to within half its command's duration.
                pause_s = ((restart_ns + restarted_ns) - (stop_ns + stopped_ns)) * 0.5e-9
                reader.note_pause(pause_s)
        finally:
            reader.resume()
        if restart_error is not None:
            reader.report_fault(restart_error)
            if failure is None:
                stage, failure = "restart", restart_error
        if failure is not None:
            self._calz_failed(name, stage, failure, stop_ns, restarted=restart_error is None,
                              pause_s=pause_s)
            state = (f"the scan was restarted after {pause_s:.2f} s" if restart_error is None
                     else f"the scan could NOT be restarted ({restart_error}); the reader's "
                     "recovery retries")
            raise CalzError(f"CALZ of {name!r} failed at {stage}: {failure}; {state}") \
                from failure
        summary = _offsets_summary(offsets, frames)
        event = Event(kind="calz", host_time_ns=stop_ns, device=name,
                      text=f"scanner zeroed (CALZ, wind {wind_speed_now:g} m/s); scan paused "
                           f"{pause_s:.3f} s",
                      data={"pause_s": pause_s, "calz_s": calz_s, "stop_ns": stop_ns,
                            "stopped_ns": stopped_ns, "restart_ns": restart_ns,
                            "restarted_ns": restarted_ns, "wind_speed_now": wind_speed_now,
                            **summary})
        self._post_event(event)
        log.info("%s: CALZ done; scan paused %.3f s; zero removed: %s", name, pause_s, summary)
        return CalzResult(device=name, wind_speed_now=wind_speed_now, stop_ns=stop_ns,
                          stopped_ns=stopped_ns, restart_ns=restart_ns,
                          restarted_ns=restarted_ns, pause_s=pause_s, calz_s=calz_s,
                          offsets_before_pa=offsets, frames_averaged=frames, event=event)

    def _restart_scan(self, name: str, reader: DeviceReader) -> tuple[DaqError | None, int]:
        """Start the scan again after a pause; return the error when it could not be.

        A refused SCAN is retried while the scanner still zeroes (a CALZ that timed out),
        for at most ``_RESTART_WAIT_S``; a scanner found scanning already (STOP had failed)
        counts as restarted: it streams to the fresh data connections. Also returns the host
        time (ns) at which the last attempt began.
        """
        end = time.monotonic() + _RESTART_WAIT_S
        while True:
            began = time.monotonic_ns()
            try:
                reader.restart_after_pause()
                return None, began
            except DaqError as exc:
                error = exc
            try:
                state = reader.driver.status()
            except DaqError as exc:
                log.error("%s: scan not restarted (%s); status failed too: %s", name, error, exc)
                return error, began
            if state == "SCAN":
                return None, began
            if state != "CALZ" or time.monotonic() >= end:
                log.error("%s: scan not restarted (state %s): %s", name, state, error)
                return error, began
            time.sleep(0.1)

    def _calz_failed(self, name: str, stage: str, error: BaseException | str, at_ns: int, *,
                     restarted: bool | None, pause_s: float = 0.0) -> None:
        log.error("%s: CALZ failed at %s: %s", name, stage, error)
        self._post_event(Event(
            kind="calz_failed", host_time_ns=at_ns, device=name,
            text=f"CALZ failed at {stage}: {error}",
            data={"stage": stage,
                  "error": "timeout" if isinstance(error, str) else type(error).__name__,
                  "scan_interrupted": restarted is not None, "scan_restarted": restarted,
                  "pause_s": pause_s}))

    def _plc(self, name: str | None, method: str) -> tuple[str, Any]:
        self._require_running(f"{method}()")
        plcs = [n for n, r in self._readers.items() if r.kind == "plc"]
        if name is None:
            if len(plcs) != 1:
                raise ValueError(f"name the PLC: devices of kind 'plc' are {plcs}")
            name = plcs[0]
        elif name not in plcs:
            raise ValueError(f"{name!r} is not a device of kind 'plc'; those are {plcs}")
        driver = self._readers[name].driver
        if not callable(getattr(driver, method, None)):
            raise TypeError(f"PLC {name!r} driver {type(driver).__name__} has no {method}()")
        return name, driver

    def _require_running(self, what: str) -> None:
        if self._state != "running":
            raise RuntimeError(f"{what}: the acquisition is {self._state}, not running")

    # -- dispatch ----------------------------------------------------------------------------------
    def _post(self, name: str, doc: Any) -> None:
        try:
            self._control.put_nowait((name, doc))
        except queue.Full:
            with self._counts_lock:
                self._events_dropped += 1
            log.error("event queue full (%d): %s doc dropped: %r", self._control.maxsize, name,
                      doc)
            return
        self._doorbell.set()

    def _post_event(self, event: Event) -> None:
        self._post("event", event)

    def _dispatch(self) -> None:
        while True:
            self._doorbell.wait(0.1)
            self._doorbell.clear()
            finishing = self._finish.is_set()  # read before the sweep: nothing comes after it
            self._sweep()
            if finishing:
                break
        for reader in self._readers.values():  # drops never followed by a delivered block
            for run in reader.take_drops():
                self._emit("event", self._overflow_event(reader, run))
        self._summary = self._build_summary(self._reason)
        self._emit("stop", self._summary)

    def _sweep(self) -> None:
        """Deliver the control docs, then the queued blocks, round-robin over devices."""
        budget = {r: r.queue.qsize() for r in self._readers.values()}
        while True:
            while True:
                try:
                    name, doc = self._control.get_nowait()
                except queue.Empty:
                    break
                self._emit(name, doc)
            busy = False
            for reader, left in budget.items():
                if left <= 0:
                    continue
                try:
                    block = reader.queue.get_nowait()
                except queue.Empty:
                    budget[reader] = 0
                    continue
                budget[reader] = left - 1
                busy = True
                self._deliver(reader, block)
            if not busy:
                return

    def _deliver(self, reader: DeviceReader, block: StreamBlock) -> None:
        runs = reader.take_drops(block.seq)
        if runs:
            gaps: list[tuple[int, int]] = []
            for run in runs:
                self._emit("event", self._overflow_event(reader, run))
                # The run's own gap spans its counters; of the device gaps the dropped blocks
                # carried, pass on those before that span (and restart markers, length -1).
                first = run.first_counter
                gaps.extend(g for g in run.gaps
                            if first is None or g[1] < 0 or g[0] < first - 1)
                gap = run.gap()
                if gap is not None:
                    gaps.append(gap)
            block = dataclasses.replace(block, gaps=(*gaps, *block.gaps),
                                        overflow_samples=sum(r.samples for r in runs))
        self._emit("block", block)
        reader.delivered()

    @staticmethod
    def _overflow_event(reader: DeviceReader, run: _DropRun) -> Event:
        return Event(
            kind="overflow", host_time_ns=run.first_time_ns, device=reader.name,
            text=(f"{run.blocks} block(s), {run.samples} sample(s) of {reader.name} dropped: "
                  "queue full (subscribers too slow)"),
            data={"blocks": run.blocks, "samples": run.samples, "first_seq": run.first_seq,
                  "last_seq": run.last_seq, "gap": run.gap(),
                  "first_counter": run.first_counter, "last_counter": run.last_counter,
                  "last_time_ns": run.last_time_ns, "device_gaps": list(run.gaps),
                  "device_gaps_truncated": run.gaps_truncated})

    def _emit(self, name: str, doc: Any) -> None:
        for index, subscriber in enumerate(self._subscribers):
            try:
                subscriber(name, doc)
            except Exception:  # one subscriber's bug must not starve the others: counted, logged
                with self._counts_lock:
                    self._subscriber_errors[index] += 1
                    n = self._subscriber_errors[index]
                if n <= 3:
                    log.exception("subscriber %r failed on a %r doc%s", subscriber, name,
                                  " (further failures are counted, not logged)" if n == 3
                                  else "")

    # -- helpers -----------------------------------------------------------------------------------
    def _cleanup(self, step: Callable[[], None], what: str) -> None:
        """Run one clean-up step; a failure is logged and kept for the summary, never raised."""
        try:
            step()
        except Exception as exc:  # the remaining steps must still run; reported in "errors"
            log.error("%s failed: %s: %s", what, type(exc).__name__, exc)
            self._errors.append(f"{what}: {type(exc).__name__}: {exc}")

    def _build_summary(self, reason: str) -> dict[str, Any]:
        stats = self.stats()
        with self._counts_lock:
            sub_errors = list(self._subscriber_errors)
            dropped = self._events_dropped
            releases = list(self._releases)
        alive = [f"reader {s.device}" for s in stats.values() if s.running]
        if self._dispatcher is not None and self._dispatcher.is_alive() \
                and threading.current_thread() is not self._dispatcher:
            alive.append("dispatcher")
        now = time.monotonic_ns()
        return {
            "reason": reason,
            "host_time_ns": now,
            "duration_s": (now - self._t0_ns) * 1e-9 if self._t0_ns else 0.0,
            "devices": {name: dataclasses.asdict(s) for name, s in stats.items()},
            "overflows": sum(s.overflows for s in stats.values()),
            "overflow_samples": sum(s.overflow_samples for s in stats.values()),
            "faults": sum(s.faults for s in stats.values()),
            "events_dropped": dropped,
            "subscriber_errors": {repr(sub): n for sub, n in zip(self._subscribers, sub_errors,
                                                                 strict=True) if n},
            "releases": releases,
            "errors": list(self._errors),
            "threads_alive": alive,
        }


def _describe(driver: Any) -> dict[str, Any]:
    describe = getattr(driver, "describe", None)
    if not callable(describe):
        return {}
    return dict(describe())


def drivers_from_config(config: RigConfig) -> dict[str, tuple[str, Any]]:
    """Build (do not open) every instrument's driver of a rig config, with its engine kind.

    Parameters
    ----------
    config : daq.config.RigConfig
        A rig config whose URLs are real (a simulated rig's ``rig.config``).

    Returns
    -------
    dict
        Instrument name -> (kind, driver), ready for :class:`Acquisition`.
    """
    from daq.instruments import build_driver  # late: imports every driver module

    return {inst.name: (ROLE_KINDS[inst.role], build_driver(inst, config.limits))
            for inst in config.instruments}
