"""The engine's dispatcher: one thread handing every record to the subscribers, in order.

Responsibility: :class:`Dispatcher` owns the engine's queue of control docs (``"start"``,
events, posted from any thread by :meth:`Dispatcher.post`), the doorbell the readers ring when
they queue a block, and the ``(name, doc)`` subscribers (bluesky-style callbacks). Its one
thread sweeps the control docs, then the readers' queued blocks round-robin over the devices,
and calls every subscriber in order: a subscriber therefore needs no locking of its own. It
marks the blocks a reader dropped on a full queue (an ``"overflow"`` event before the next
delivered block, which carries the gap), counts each subscriber's failures without letting one
starve the others, and ends with the ``"stop"`` doc once it is told to finish.

Not responsible for: the readers themselves (:mod:`daq.acquisition.reader`), starting and
stopping the devices or the summary's content (:mod:`daq.acquisition.engine`).
"""

from __future__ import annotations

import dataclasses
import logging
import queue
import threading
from collections.abc import Callable, Iterable
from typing import Any, Protocol

from daq.acquisition.reader import DeviceReader, DropRun
from daq.acquisition.records import Event, StreamBlock
from daq.instruments.reading import Gap

__all__ = ["Dispatcher", "Subscriber"]

log = logging.getLogger(__name__)


class Subscriber(Protocol):
    """A ``(name, doc)`` callback, as in bluesky: called on the dispatcher thread only."""

    def __call__(self, name: str, doc: Any, /) -> None:
        """Receive ``"start"`` (dict), ``"block"``, ``"event"`` or ``"stop"`` (dict)."""


class Dispatcher:
    """The control queue, the doorbell, the subscribers and the thread that feeds them.

    Parameters
    ----------
    control_queue_size : int
        Capacity of the queue of events and start/stop docs; a doc that finds it full is
        counted (:attr:`events_dropped`) and logged.
    """

    def __init__(self, control_queue_size: int) -> None:
        #: Rung by the readers when they queue a block, and by :meth:`post`.
        self.doorbell = threading.Event()
        self._control: queue.Queue[tuple[str, Any]] = queue.Queue(maxsize=control_queue_size)
        self._subscribers: list[Subscriber] = []
        self._subscriber_errors: list[int] = []
        self._events_dropped = 0
        self._counts_lock = threading.Lock()
        self._finish = threading.Event()
        self._readers: list[DeviceReader] = []
        self._on_stop: Callable[[], dict[str, Any]] | None = None
        #: The dispatcher thread (None before :meth:`start`).
        self.thread: threading.Thread | None = None

    def subscribe(self, subscriber: Subscriber) -> None:
        """Add a ``(name, doc)`` subscriber (before :meth:`start`)."""
        self._subscribers.append(subscriber)
        self._subscriber_errors.append(0)

    @property
    def events_dropped(self) -> int:
        """Measure the docs dropped on a full control queue."""
        with self._counts_lock:
            return self._events_dropped

    def subscriber_errors(self) -> dict[str, int]:
        """Return the failures of each subscriber that failed, by its ``repr``."""
        with self._counts_lock:
            counts = list(self._subscriber_errors)
        return {repr(sub): n for sub, n in zip(self._subscribers, counts, strict=True) if n}

    def on_own_thread(self) -> bool:
        """Tell whether the caller runs on the dispatcher thread (i.e. in a subscriber)."""
        return self.thread is not None and threading.current_thread() is self.thread

    def alive_elsewhere(self) -> bool:
        """Tell whether the dispatcher thread runs and the caller is not on it."""
        return (self.thread is not None and self.thread.is_alive()
                and threading.current_thread() is not self.thread)

    # -- posting (any thread) --------------------------------------------------------------------
    def post(self, name: str, doc: Any) -> None:
        """Queue a control doc (``"start"``, ``"event"``) for the subscribers."""
        try:
            self._control.put_nowait((name, doc))
        except queue.Full:
            with self._counts_lock:
                self._events_dropped += 1
            log.error("event queue full (%d): %s doc dropped: %r", self._control.maxsize, name,
                      doc)
            return
        self.doorbell.set()

    def post_event(self, event: Event) -> None:
        """Queue an ``"event"`` doc."""
        self.post("event", event)

    # -- life cycle ------------------------------------------------------------------------------
    def start(self, readers: Iterable[DeviceReader], on_stop: Callable[[], dict[str, Any]]) -> None:
        """Start the thread over ``readers``' queues; ``on_stop()`` gives the ``"stop"`` doc."""
        self._readers = list(readers)
        self._on_stop = on_stop
        self.thread = threading.Thread(target=self._run, name="windrig-dispatcher", daemon=True)
        self.thread.start()

    def finish(self, timeout_s: float) -> bool:
        """Deliver what is queued, then ``"stop"``; wait ``timeout_s``; return whether it ended."""
        self._finish.set()
        self.doorbell.set()
        if self.thread is None:
            return True
        self.thread.join(timeout_s)
        return not self.thread.is_alive()

    # -- the dispatcher thread -------------------------------------------------------------------
    def _run(self) -> None:
        while True:
            self.doorbell.wait(0.1)
            self.doorbell.clear()
            finishing = self._finish.is_set()  # read before the sweep: nothing comes after it
            self._sweep()
            if finishing:
                break
        for reader in self._readers:  # drops never followed by a delivered block
            for run in reader.take_drops():
                self._emit("event", self._overflow_event(reader, run))
        assert self._on_stop is not None
        self._emit("stop", self._on_stop())

    def _sweep(self) -> None:
        """Deliver the control docs, then the queued blocks, round-robin over devices."""
        budget = {r: r.queue.qsize() for r in self._readers}
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
            gaps: list[Gap] = []
            for run in runs:
                self._emit("event", self._overflow_event(reader, run))
                # The run's own gap spans its counters; of the device gaps the dropped blocks
                # carried, pass on those before that span (and restart markers, length -1).
                first = run.first_counter
                gaps.extend(g for g in run.gaps
                            if first is None or g.length < 0 or g.after_counter < first - 1)
                gap = run.gap()
                if gap is not None:
                    gaps.append(gap)
            block = dataclasses.replace(block, gaps=(*gaps, *block.gaps),
                                        overflow_samples=sum(r.samples for r in runs))
        self._emit("block", block)
        reader.delivered()

    @staticmethod
    def _overflow_event(reader: DeviceReader, run: DropRun) -> Event:
        return Event(
            kind="overflow", host_time_ns=run.first_time_ns, device=reader.name,
            text=(f"{run.blocks} block(s), {run.samples} sample(s) of {reader.name} dropped: "
                  "queue full (subscribers too slow)"),
            data={"blocks": run.blocks, "samples": run.samples, "first_seq": run.first_seq,
                  "last_seq": run.last_seq, "gap": gap_pair(run.gap()),
                  "first_counter": run.first_counter, "last_counter": run.last_counter,
                  "last_time_ns": run.last_time_ns, "device_gaps": [gap_pair(g) for g in run.gaps],
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


def gap_pair(gap: Gap | None) -> tuple[int, int] | None:
    """Return a gap as ``(after_counter, length)``: plain numbers for an event's data."""
    return None if gap is None else (gap.after_counter, gap.length)
