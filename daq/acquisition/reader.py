"""One instrument's reader: a blocking thread that reads its driver into a bounded queue.

Responsibility: read one instrument in its own blocking reader thread (:class:`DeviceReader`: the
scanner and the lasers streaming, the barometer, the fan drive and the PLC polled, each through
the adapter of its kind of driver, :mod:`daq.acquisition.adapters`), turn the
:class:`~daq.instruments.reading.Reading` every driver's ``read()`` returns into
:class:`~daq.acquisition.records.StreamBlock` records and put them on the reader's bounded queue,
which never blocks the reader: when it is full the oldest block is dropped and the loss accounted
for (counters, and drop runs the dispatcher takes). Driver faults are reported as
:class:`~daq.acquisition.records.DeviceFault` events, retried with backoff and recovered from. A
scanner's reader can also be parked, drained and its scan restarted, for a pause of the engine (a
CALZ).

Not responsible for: the device protocols (the drivers); creating, starting and stopping the
readers (:class:`~daq.acquisition.engine.Acquisition`); dispatching their blocks to
subscribers and marking the overflow gaps on the blocks delivered
(:mod:`daq.acquisition.dispatch`); the CALZ itself (:mod:`daq.acquisition.calz`); the records'
types (:mod:`daq.acquisition.records`).

Design choices:

- **Full queue: drop the oldest block, mark the gap.** A reader never blocks on its queue (a
  blocked reader lets the device's own buffer overrun, which loses data silently or with
  less precise accounting). When its queue is full it removes the oldest queued block and
  enqueues the new one: the newest data is what the operator watches, what a release
  detector needs now, and what bounds the latency of everything downstream; an old backlog is
  worth less. The loss is counted per device (:meth:`~daq.acquisition.engine.Acquisition.stats`) and
  marked exactly: the next delivered block of that device carries a gap covering the dropped
  counters (plus the device gaps the dropped blocks carried) in :attr:`StreamBlock.gaps`, and an
  ``"overflow"`` event precedes it; the ``"stop"`` summary totals them.
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
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from daq.acquisition.adapters import REQUIRED_METHODS, make_adapter
from daq.acquisition.records import (
    KINDS,
    DeviceFault,
    DeviceStats,
    Event,
    FloatArray,
    StreamBlock,
)
from daq.errors import DaqError, PluginError, TransportError, TransportTimeout
from daq.instruments.reading import Gap, Reading, ReadingContract

__all__ = ["DeviceReader"]

log = logging.getLogger(__name__)


#: Device gaps kept per run of dropped blocks (more are counted in the overflow event).
_MAX_DROPPED_GAPS = 256


# ------------------------------------------------------------------------------------------------
# Reader
# ------------------------------------------------------------------------------------------------
@dataclass
class DropRun:
    """Consecutive blocks of one device dropped on a full queue."""

    first_seq: int
    last_seq: int
    blocks: int
    samples: int
    first_counter: int | None
    last_counter: int | None
    first_time_ns: int
    last_time_ns: int
    gaps: list[Gap]
    gaps_truncated: int = 0

    def add(self, block: StreamBlock) -> None:
        self.last_seq = block.seq
        self.blocks += 1
        self.samples += len(block)
        if len(block):
            if self.first_counter is None:
                self.first_counter = int(block.counter[0])
            self.last_counter = int(block.counter[-1])
        if len(block):
            self.last_time_ns = int(block.host_time_ns[-1])
        room = _MAX_DROPPED_GAPS - len(self.gaps)
        self.gaps.extend(block.gaps[:max(room, 0)])
        self.gaps_truncated += max(len(block.gaps) - max(room, 0), 0)

    @classmethod
    def of(cls, block: StreamBlock) -> DropRun:
        t0 = int(block.host_time_ns[0]) if len(block) else time.monotonic_ns()
        run = cls(block.seq, block.seq, 0, 0, None, None, t0, t0, [])
        run.add(block)
        return run

    def gap(self) -> Gap | None:
        """Return the overflow gap (counter units, kind ``"overflow"``), if counted."""
        if self.first_counter is None or self.last_counter is None:
            return None
        return Gap(self.first_counter - 1, self.last_counter - self.first_counter + 1,
                   "overflow")


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
        Poll period of a polled kind, s (default: the driver's own
        ``settings.poll_interval_s``, else 1 s for the barometer, 0.1 s for the fan and the PLC).
    read_timeout_s : float
        Timeout of one streaming ``read``, s: bounds how long a stop waits for a reader.
    stall_s : float
        A streaming device that delivers nothing for this long is reported once as stalled.
    backoff_min_s, backoff_max_s : float
        Wait before the first retry after a fault, s, doubled per further fault up to the max.

    Notes
    -----
    The :class:`~daq.acquisition.engine.Acquisition` creates, starts and stops readers; use it
    rather than this class.
    """

    def __init__(self, name: str, kind: str, driver: Any, *, queue_size: int,
                 on_event: Callable[[Event], None], doorbell: threading.Event,
                 poll_interval_s: float | None = None, read_timeout_s: float = 0.2,
                 stall_s: float = 2.0, backoff_min_s: float = 0.1,
                 backoff_max_s: float = 5.0) -> None:
        if kind not in KINDS:
            raise ValueError(f"device {name!r}: kind must be one of {list(KINDS)}, got {kind!r}")
        missing = [m for m in REQUIRED_METHODS[kind] if not callable(getattr(driver, m, None))]
        if missing:
            raise TypeError(f"device {name!r} ({kind}): the driver {type(driver).__name__} "
                            f"lacks {missing}")
        self.name = name
        self.kind = kind
        self.driver = driver
        self.queue: queue.Queue[StreamBlock] = queue.Queue(maxsize=queue_size)
        self._adapter = make_adapter(kind, driver, poll_interval_s=poll_interval_s,
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
        self._drops: list[DropRun] = []
        self._next_drop_log = 0.0
        self.failed: BaseException | None = None
        # Every reading is checked before it is queued (_breach).
        self._contract = ReadingContract(driver)

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
        self._check_paused_scanner("drain()")
        readings = self.driver.drain(timeout_s)
        for r in readings:
            breach = self._breach(r)
            if breach is not None:
                raise breach
            self._offer(r)
        return len(readings)

    def restart_after_pause(self) -> None:
        """Start a new scan after a pause, its gap measured (the scanner driver's ``scan``)."""
        self._check_paused_scanner("restart_after_pause()")
        self.driver.scan(after_pause=True)

    def note_pause(self, pause_s: float) -> None:
        """Tell the scanner driver how long the scan stood still, s (before :meth:`resume`)."""
        if self.kind == "scanner":
            self.driver.note_pause(pause_s)

    def recent_pressure_mean(self) -> tuple[FloatArray, int]:
        """Mean pressure per channel over the last frames read, Pa, and their number."""
        if self.kind != "scanner":
            raise RuntimeError(f"{self.name}: not a scanner")
        mean, rows = self.driver.recent_pressure_mean()
        return mean, int(rows)

    def _check_paused_scanner(self, what: str) -> None:
        if not self._parked or self.kind != "scanner":
            raise RuntimeError(f"{self.name}: {what} needs a scanner reader paused first")

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

    def take_drops(self, before_seq: int | None = None) -> list[DropRun]:
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
                    reading = adapter.read(stop)
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
                if reading is None:
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
                                    or (len(reading) > 0
                                        and int(reading.host_time_ns[-1]) > reconnected_ns)):
                    self._recovered(consecutive)
                    consecutive, stalled, error, reconnected_ns = 0, False, None, None
                    delay = self._backoff[0]
                breach = self._breach(reading)
                if breach is not None:  # a driver's bug: named once, never recorded
                    log.error("%s: %s", self.name, breach)
                    self.failed = breach
                    self._fault(breach, consecutive + 1, fatal=True)
                    break
                self._offer(reading)
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

    def _breach(self, reading: Reading) -> PluginError | None:
        """Check a reading before it is queued; return the error naming its breaches, if any."""
        breach = self._contract.breach(reading)
        if breach is None:
            return None
        return PluginError(f"{breach}; not recorded, and this device is read no more")

    def _offer(self, reading: Reading) -> None:
        block = StreamBlock.of(self.name, self.kind, self._seq, reading)
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
                self._drops.append(DropRun.of(old))
            total = self._count["overflows"]
        now = time.monotonic()
        if now >= self._next_drop_log:  # at most one log line per 5 s; all are counted
            self._next_drop_log = now + 5.0
            log.warning("%s: queue full (%d blocks): dropping the oldest block (%d dropped so "
                        "far; subscribers too slow)", self.name, self.queue.maxsize, total)
