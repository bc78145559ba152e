"""One NI-DAQmx task shared by every instrument read through one device: :class:`TaskGroup`.

Responsibility: a multifunction DAQ device runs one hardware-timed analog input task at a time,
so the instruments wired to its inputs (three lasers, a Pitot transducer) share it. The group
creates the task when its first instrument opens (every channel of the URL, the sample clock,
the host buffer; the trigger line as a second task on the analog sample clock), reads it for
whichever instrument asks first and queues the rows for the others, and closes it when the last
one closes. It counts the samples: the counter is the task's sample index (continued across a
reconnection), the device time is the sample index over the rate (the DAQ's sample clock).

Faults, as the other drivers report theirs:

- samples overwritten in the host buffer before they were read (NI-DAQmx error -200279, the
  task runs with ``OverwriteMode.OVERWRITE_UNREAD_SAMPLES``): the read moves on to samples
  still in the buffer and the rows skipped are a :class:`~daq.instruments.reading.Gap` whose
  length is counted on the sample index (exact);
- a device that can no longer be accessed (-201003, e.g. a USB DAQ unplugged): the tasks are
  recreated with a bounded backoff; the sample clock starts again at 0 (the device time goes
  back: a ``restart`` gap of unknown length, which the run writer takes as a clock restart),
  and the counter runs on by the rows missed, estimated from the host time; a device that
  does not come back is a :class:`~daq.errors.TransportError`;
- any other NI-DAQmx error is a :class:`~daq.errors.DeviceError` naming its code.

Not responsible for: scaling voltages (the drivers), the URL
(:mod:`daq.instruments.ni_daqmx.address`), loading the API
(:mod:`daq.instruments.ni_daqmx.runtime`).

Threads: the engine reads each instrument on a thread of its own; one lock serialises the
group's reads (a thread that finds rows queued for it takes them without touching the task).
"""

from __future__ import annotations

import logging
import math
import threading
import time
import weakref
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from daq.errors import ConfigError, DeviceError, TransportError, TransportTimeout
from daq.instruments.ni_daqmx.address import TERMINALS, TaskAddress
from daq.instruments.ni_daqmx.runtime import NiApi
from daq.instruments.reading import Gap

__all__ = ["DEVICE_LOST_CODES", "SAMPLES_OVERWRITTEN", "Chunk", "TaskGroup", "task_group"]

log = logging.getLogger(__name__)

#: NI-DAQmx error: "Attempted to read samples that are no longer available. The requested
#: sample was previously available, but has since been overwritten." (SAMPLES_NO_LONGER_AVAILABLE)
SAMPLES_OVERWRITTEN: Final = -200279
#: NI-DAQmx errors of a device gone: -201003 "Device cannot be accessed" (DEV_CANNOT_BE_ACCESSED:
#: no longer present in the system, powered off, unplugged).
DEVICE_LOST_CODES: Final = frozenset({-201003})

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class Chunk:
    """Rows read from the task, for every channel of it.

    Attributes
    ----------
    volts : ndarray, (n, channels)
        The task's voltages, V, in the URL's channel order.
    triggered : ndarray of bool, (n,)
        Samples at which the trigger line rose (or its counter counted); all False unwired.
    index : ndarray of int64, (n,)
        Sample index in the task (0 at its start; the device time is ``index / rate``).
    counter : ndarray of int64, (n,)
        Unwrapped counter (the sample index, continued across reconnections).
    host_time_ns : ndarray of int64, (n,)
        Host ``monotonic_ns`` when the read found these rows acquired.
    epoch : int
        Tasks started since the first (a reconnection starts a new one).
    gaps : tuple of Gap
        Rows missing before these.
    """

    volts: FloatArray
    triggered: BoolArray
    index: IntArray
    counter: IntArray
    host_time_ns: IntArray
    epoch: int
    gaps: tuple[Gap, ...] = ()

    def __len__(self) -> int:
        return int(self.index.shape[0])


_groups: weakref.WeakValueDictionary[tuple[str, str], TaskGroup] = weakref.WeakValueDictionary()
_groups_lock = threading.Lock()


def task_group(address: TaskAddress, api: NiApi) -> TaskGroup:
    """Return the group of ``address`` (one per URL and API while instruments hold it)."""
    key = (api.name, address.url)
    with _groups_lock:
        group = _groups.get(key)
        if group is None:
            group = TaskGroup(address, api)
            _groups[key] = group
        return group


class TaskGroup:
    """The task of one URL, shared by its instruments (see the module docstring).

    Parameters
    ----------
    address : TaskAddress
        The task's device, channels and options.
    api : NiApi
        The nidaqmx API (real or stand-in).
    reconnect_attempts : int
        Attempts to recreate the tasks after the device was lost.
    reconnect_backoff_s : float
        First wait before an attempt, s; doubled after each.
    """

    #: Time a read keeps collecting after rows are available, s: blocks of ~20 ms, as the
    #: lasers' serial driver gives, so that the engine and the writer run per block.
    DRAIN_S = 0.02

    def __init__(self, address: TaskAddress, api: NiApi, *, reconnect_attempts: int = 5,
                 reconnect_backoff_s: float = 0.1) -> None:
        self.address = address
        self.api = api
        self.reconnect_attempts = int(reconnect_attempts)
        self.reconnect_backoff_s = float(reconnect_backoff_s)
        self.rate_hz: float | None = None
        self.buffer = 0
        #: Reconnections made so far; samples skipped as overwritten so far.
        self.reconnects = 0
        self.overwritten = 0
        self._lock = threading.RLock()
        self._ai: Any = None
        self._trigger: Any = None
        self._reader: Any = None
        self._queues: dict[int, list[Chunk]] = {}
        self._next = 0  # task sample index of the next row to read
        self._base = 0  # counter of sample index 0 in this epoch
        self._epoch = 0
        self._previous: int | None = None  # trigger line level or count before _next
        self._gaps: list[Gap] = []
        self._last_host_ns = 0

    # -- members -------------------------------------------------------------------------------
    def open(self, member: int, rate_hz: float) -> None:
        """Open the task for ``member`` (create and start it if it is the first)."""
        with self._lock:
            if self.rate_hz is not None and self._queues and rate_hz != self.rate_hz:
                raise ConfigError(
                    f"url {self.address.url!r}: an instrument asks {rate_hz:g} Hz but the task "
                    f"runs at {self.rate_hz:g} Hz: the instruments of one NI-DAQmx task share "
                    "its sample clock (give them the same rate_hz)")
            if not self._queues:
                self.rate_hz = float(rate_hz)
                self.buffer = self.address.buffer_samples(self.rate_hz)
                try:
                    self._start_tasks()
                except self.api.errors.DaqError as exc:
                    raise _as_daq_error(self.address.url, exc) from exc
                self._next, self._base, self._epoch, self._previous = 0, 0, 0, None
                self._gaps = []
                self._last_host_ns = time.monotonic_ns()
            self._queues[member] = []

    def close(self, member: int) -> None:
        """Close ``member``; the last one out stops and closes the task."""
        with self._lock:
            if self._queues.pop(member, None) is not None and not self._queues:
                self._close_tasks()

    def is_open(self, member: int) -> bool:
        """Whether ``member`` is open on a running task."""
        with self._lock:
            return member in self._queues

    def read(self, member: int, timeout_s: float) -> list[Chunk]:
        """Return the rows queued for ``member``; read the task first if there are none.

        Raises
        ------
        TransportTimeout
            No new sample within ``timeout_s``.
        TransportError
            The member is not open, or the device was lost and did not come back.
        DeviceError
            Any other NI-DAQmx error.
        """
        with self._lock:
            if member not in self._queues:
                raise TransportError(f"{self.address.url}: not open")
            if not self._queues[member]:
                chunk = self._pull(timeout_s)
                for queue in self._queues.values():
                    queue.append(chunk)
                self._bound_queues()
            chunks, self._queues[member] = self._queues[member], []
            return chunks

    def _bound_queues(self) -> None:
        """Drop the oldest rows of an instrument that stopped reading (an ``overflow`` gap).

        The bound is four host buffers: an instrument whose reader waits for the lock while
        another reads a buffer's worth after a stall must not lose rows; one that stopped
        reading must not keep the others' rows forever.
        """
        for queue in self._queues.values():
            while sum(len(c) for c in queue) > 4 * self.buffer and len(queue) > 1:
                dropped = queue.pop(0)
                head = queue[0]
                queue[0] = Chunk(head.volts, head.triggered, head.index, head.counter,
                                 head.host_time_ns, head.epoch,
                                 (*dropped.gaps, Gap(int(dropped.counter[0]) - 1, len(dropped),
                                                     "overflow"), *head.gaps))

    # -- the tasks -----------------------------------------------------------------------------
    def _start_tasks(self) -> None:
        api, a = self.api, self.address
        c = api.constants
        assert self.rate_hz is not None
        ai = api.Task()
        trigger = None
        try:
            terminal = getattr(c.TerminalConfiguration, TERMINALS[a.terminal])
            for channel in a.channels:
                ai.ai_channels.add_ai_voltage_chan(a.physical(channel), terminal_config=terminal,
                                                   min_val=a.min_v, max_val=a.max_v)
            ai.timing.cfg_samp_clk_timing(self.rate_hz,
                                          sample_mode=c.AcquisitionType.CONTINUOUS,
                                          samps_per_chan=self.buffer)
            _read_anywhere(ai, c)
            if a.trigger:
                trigger = api.Task()
                if a.counter_trigger:
                    trigger.ci_channels.add_ci_count_edges_chan(
                        a.physical(a.trigger), edge=c.Edge.RISING, initial_count=0,
                        count_direction=c.CountDirection.COUNT_UP)
                else:
                    trigger.di_channels.add_di_chan(a.physical(a.trigger),
                                                    line_grouping=c.LineGrouping.CHAN_PER_LINE)
                # On the analog task's sample clock: row k of both tasks is one instant.
                trigger.timing.cfg_samp_clk_timing(self.rate_hz,
                                                   source=f"/{a.device}/ai/SampleClock",
                                                   sample_mode=c.AcquisitionType.CONTINUOUS,
                                                   samps_per_chan=self.buffer)
                _read_anywhere(trigger, c)
                trigger.start()  # armed first: it samples from the analog task's first clock
            ai.start()
        except BaseException:
            for task in (trigger, ai):
                if task is not None:
                    _close_quietly(task, a.url)
            raise
        self._ai, self._trigger = ai, trigger
        self._reader = api.stream_readers.AnalogMultiChannelReader(ai.in_stream)

    def _close_tasks(self) -> None:
        for task in (self._ai, self._trigger):
            if task is not None:
                _close_quietly(task, self.address.url)
        self._ai = self._trigger = self._reader = None

    # -- reading ---------------------------------------------------------------------------------
    def _acquired(self) -> int:
        """Return the samples acquired so far by both tasks (the trigger task may lag a read)."""
        total = int(self._ai.in_stream.total_samp_per_chan_acquired)
        if self._trigger is not None:
            total = min(total, int(self._trigger.in_stream.total_samp_per_chan_acquired))
        return total

    def _pull(self, timeout_s: float) -> Chunk:
        assert self.rate_hz is not None
        deadline = time.monotonic() + timeout_s
        target = max(1, math.ceil(self.rate_hz * self.DRAIN_S))
        first_seen: float | None = None
        errors = self.api.errors
        while True:
            if self._ai is None:
                raise TransportError(f"{self.address.url}: the task is closed")
            try:
                asked = time.monotonic()
                total = self._acquired()
                host_ns = time.monotonic_ns()
                now = time.monotonic()
                n = total - self._next
                if n > 0 and first_seen is None:
                    first_seen = now
                full = n >= target or (first_seen is not None
                                       and now >= first_seen + self.DRAIN_S)
                if n > 0 and (full or now >= deadline):
                    return self._read_rows(min(n, self.buffer), host_ns)
            except errors.DaqError as exc:
                self._fault(exc)
                continue
            # Only a count asked for after the deadline says that none came in time: one asked
            # before it may have been answered late (a stalled link), counting from then.
            if asked >= deadline:
                raise TransportTimeout(f"{self.address.url}: no sample within {timeout_s:g} s")
            # Sleep until the block is due (or the deadline): few status queries per block.
            wait = (target - max(n, 0)) / self.rate_hz
            if first_seen is not None:
                wait = min(wait, first_seen + self.DRAIN_S - now)
            time.sleep(max(0.0005, min(wait, deadline - now)))

    def _read_rows(self, n: int, host_ns: int) -> Chunk:
        start = self._next
        self._ai.in_stream.offset = start
        volts = np.empty((len(self.address.channels), n), dtype=np.float64)
        got = int(self._reader.read_many_sample(volts, number_of_samples_per_channel=n,
                                                timeout=10.0))
        volts = volts[:, :got]
        flags = np.zeros(got, dtype=bool)
        if self._trigger is not None and got:
            self._trigger.in_stream.offset = start
            values = np.asarray(self._trigger.read(number_of_samples_per_channel=got,
                                                   timeout=10.0), dtype=np.int64).reshape(-1)
            previous = values[0] if self._previous is None else self._previous
            flags = np.diff(values, prepend=previous) > 0  # a rising line, or a new count
            self._previous = int(values[-1])
        index = np.arange(start, start + got, dtype=np.int64)
        self._next = start + got
        self._last_host_ns = host_ns
        gaps, self._gaps = tuple(self._gaps), []
        return Chunk(volts=np.ascontiguousarray(volts.T), triggered=flags, index=index,
                     counter=self._base + index, host_time_ns=np.full(got, host_ns, np.int64),
                     epoch=self._epoch, gaps=gaps)

    def _fault(self, exc: Any) -> None:
        """Handle an NI-DAQmx error of a read: skip overwritten rows, reconnect, or raise."""
        code = int(exc.error_code)
        if code == SAMPLES_OVERWRITTEN:
            total = self._acquired()
            # The oldest samples still in the buffer, with a tenth of it as margin: they are
            # being overwritten while we read.
            resume = min(total, max(self._next, total - self.buffer) + self.buffer // 10)
            lost = resume - self._next
            log.warning("%s: %d sample(s) overwritten in the host buffer before they were "
                        "read (NI-DAQmx %d); reading on from sample %d", self.address.url,
                        lost, code, resume)
            self._gaps.append(Gap(self._base + self._next - 1, lost, "missing"))
            self.overwritten += lost
            self._next = resume
            self._previous = None  # the line's level before the gap is unknown
            return
        if code in DEVICE_LOST_CODES:
            self._reconnect(exc)
            return
        raise _as_daq_error(self.address.url, exc) from exc

    def _reconnect(self, cause: Any) -> None:
        url = self.address.url
        log.warning("%s: device lost (NI-DAQmx %d: %s); recreating the task", url,
                    int(cause.error_code), _first_line(cause))
        self._close_tasks()
        delay = self.reconnect_backoff_s
        last: BaseException = cause
        for attempt in range(1, self.reconnect_attempts + 1):
            time.sleep(delay)
            delay *= 2
            try:
                self._start_tasks()
            except self.api.errors.DaqError as exc:
                last = exc
                log.warning("%s: attempt %d of %d failed: %s", url, attempt,
                            self.reconnect_attempts, _first_line(exc))
                continue
            assert self.rate_hz is not None
            # The sample clock starts again at 0: a restart gap of unknown length (-1), which
            # tells the run writer to map the new clock afresh. The counter runs on by the
            # rows missed meanwhile, estimated from the host time.
            missing = max(0, round((time.monotonic_ns() - self._last_host_ns) * 1e-9
                                   * self.rate_hz))
            last_counter = self._base + self._next - 1
            self._gaps.append(Gap(last_counter, -1, "restart"))
            self._base = last_counter + 1 + missing
            self._next, self._previous = 0, None
            self._epoch += 1
            self.reconnects += 1
            log.warning("%s: task recreated after %d attempt(s); about %d sample(s) missed",
                        url, attempt, missing)
            return
        self._queues.clear()
        raise TransportError(f"{url}: the NI-DAQmx device did not come back after "
                             f"{self.reconnect_attempts} attempts") from last


def _as_daq_error(url: str, exc: Any) -> DeviceError | TransportError:
    """Return an NI-DAQmx error as daq's: a device not accessible, or the device's error."""
    code = int(exc.error_code)
    text = f"{url}: NI-DAQmx error {code}: {_first_line(exc)}"
    return TransportError(text) if code in DEVICE_LOST_CODES else DeviceError(text)


def _read_anywhere(task: Any, c: Any) -> None:
    """Let reads address samples by index (and keep the newest on overflow: counted gaps)."""
    task.in_stream.overwrite = c.OverwriteMode.OVERWRITE_UNREAD_SAMPLES
    task.in_stream.relative_to = c.ReadRelativeTo.FIRST_SAMPLE


def _close_quietly(task: Any, url: str) -> None:
    """Close a task; a failure (a device already gone) is logged: the task is abandoned anyway."""
    try:
        task.close()
    except Exception as exc:  # noqa: BLE001 - logged, not swallowed: closing a lost device fails
        log.warning("%s: closing the NI-DAQmx task failed: %s", url, _first_line(exc))


def _first_line(exc: BaseException) -> str:
    lines = str(exc).strip().splitlines()
    return lines[0] if lines else type(exc).__name__
