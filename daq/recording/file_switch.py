"""Run files started and stopped on request under a running engine (console, campaign).

Responsibility: :class:`FileRecording` feeds the engine's docs to a second, ordinary
:class:`~daq.recording.writer.RunWriter` and its :class:`~daq.recording.recorder.RunRecorder`
(the pair ``windrig acquire`` uses, so the file has the same layout by construction) while a
recording is on: the operator's recordings in the live console, and each wind speed's file of a
campaign (:mod:`daq.recording.session`), one engine running across all of them. The writer
lives on the engine's dispatcher thread (the one thread that touches its h5py file): the
caller's thread (the GUI's, the campaign's) creates the file, then posts a request and waits,
with a timeout, for the dispatcher to start or finish the recording at its next doc. A new
recording's writer is first fed the last ``preroll_s`` of blocks, and the trigger pulses among
them, so that its clock maps start warm (:data:`PREROLL_S` for the console; a campaign asks
for :data:`~daq.recording.devices.CLOCK_SETTLE_S`, so that its releases need not wait for the
maps to settle in every file); a stop waits for the blocks that arrived before it was asked.
:class:`Recording` is what the caller sees of it.

Not responsible for: the live view (:mod:`daq.console.live_source`), the file's content
(:mod:`daq.recording`), or the controls (:mod:`daq.console.controls`).
"""

from __future__ import annotations

import dataclasses
import datetime
import logging
import math
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

from daq.errors import RecordingError

__all__ = ["PREROLL_S", "RECORDING_TIMEOUT_S", "SLOW_BLOCKS_S", "STOP_CATCH_UP_S", "FileRecording",
           "Recording"]

log = logging.getLogger(__name__)

#: A console recording's file writer is first fed this much of the blocks already delivered
#: (and the trigger pulses among them), s: every
#: stream then covers time 0 (no NaN rows at the start of the file's sync view) and the clock
#: maps have closed their first two 0.5 s windows (a fitted slope, not a cold start; see
#: :func:`daq.recording.devices.new_clock_map`). Those raw samples precede time 0 in the file.
#: Cost: ~0.4 s of the dispatcher's time at the start (the maps refit at every block until
#: then); the engine's queues hold several seconds.
PREROLL_S = 1.0


#: How long the GUI thread waits for the dispatcher to start or finish a recording, s. The
#: dispatcher takes a request at its next doc (laser blocks come 50 times a second); finishing
#: writes the last rows and reopens the file for the clock fits (well under a second).
RECORDING_TIMEOUT_S = 10.0


#: A stop waits for the dispatcher to deliver the blocks that arrived before it was asked (it
#: lags by a few ms, by a few tenths of a second after a pre-roll or on a loaded host), at most
#: this long, s (a stalled device is not waited for longer).
STOP_CATCH_UP_S = 3.0


#: Devices whose blocks come further apart than this (polled ones: the 1 Hz barometer) are not
#: waited for by a stop, s.
SLOW_BLOCKS_S = 0.25


@dataclass(frozen=True)
class Recording:
    """A recording to a run file, as the GUI sees it (:attr:`LiveSource.recording`).

    Attributes
    ----------
    path : Path
        The run file.
    notes : str
        The operator notes stored with it (attribute ``operator_notes`` of ``/entry``).
    started_ns : int
        Host ``time.monotonic_ns()`` of the file's time 0, ns (when the dispatcher started it).
    error : str or None
        Why the recording stopped by itself (e.g. the disk filled up): the file is closed and
        readable up to its last flush. None while it records.
    """

    path: Path
    notes: str
    started_ns: int
    error: str | None = None

    def elapsed_s(self, now_ns: int | None = None) -> float:
        """Return the time since the recording started, s.

        Parameters
        ----------
        now_ns : int, optional
            Host ``time.monotonic_ns()`` now (a seam for tests).
        """
        now_ns = time.monotonic_ns() if now_ns is None else now_ns
        return (now_ns - self.started_ns) * 1e-9


@dataclass
class _Request:
    """A start or stop asked by the GUI thread, answered by the dispatcher (``done``)."""

    kind: str  # "start" or "stop"
    requested_ns: int = dataclasses.field(default_factory=time.monotonic_ns)
    reason: str = ""
    writer: Any = None  # start: the RunWriter, its recorder opened
    notes: str = ""
    done: threading.Event = dataclasses.field(default_factory=threading.Event)
    result: dict[str, Any] | None = None
    error: BaseException | None = None


class FileRecording:
    """Records the engine's docs to a run file while asked to (see the module docstring).

    Threads: :meth:`feed` runs on the engine's dispatcher thread and is the only code that
    calls the file's writer once a recording started; :meth:`start` and :meth:`stop` run on the
    GUI thread, which only opens the file (before the hand-over) and posts a request under
    ``_lock``. The dispatcher serves a request holding ``_lock``, so a request the GUI thread
    finds still posted after its timeout was never touched and can be withdrawn.
    :attr:`recording` is one immutable object, swapped whole (atomic for the GUI thread).

    Parameters
    ----------
    preroll_s : float
        How much of the blocks already delivered a new recording's writer is fed first, s
        (module docstring).
    """

    def __init__(self, preroll_s: float = PREROLL_S) -> None:
        if not (math.isfinite(preroll_s) and preroll_s >= 0):
            raise ValueError(f"preroll_s must be >= 0 s, got {preroll_s!r}")
        self.preroll_s = float(preroll_s)
        self._lock = threading.Lock()
        self._request: _Request | None = None
        self._writer: Any = None  # the active file writer (dispatcher thread only)
        self._start_doc: dict[str, Any] | None = None
        self._preroll: dict[str, deque[Any]] = {}
        self._recent_events: deque[Any] = deque(maxlen=256)  # delivered before a start
        self._events = {"overflow": 0, "fault": 0}  # during the active recording
        #: The active recording, the last one that failed, or None.
        self.recording: Recording | None = None

    # -- dispatcher thread -----------------------------------------------------------------------
    def feed(self, name: str, doc: Any) -> None:
        """Take one engine doc: serve a posted request, write the doc if recording."""
        if name == "start":
            self._start_doc = dict(doc)
            return
        request = self._request
        if request is not None and (request.kind == "start" or name == "stop"
                                    or self._caught_up(request, name, doc)):
            self._serve(request)
        if self._writer is not None:
            if name == "stop":  # the engine stops under an active recording: finish the file
                # a failure is kept in ``recording``
                self._finish("acquisition stopped", time.monotonic_ns())
            else:
                self._write(name, doc)
        if name == "block":
            self._keep(doc)
        elif name == "event":
            self._recent_events.append(doc)

    def _caught_up(self, request: _Request, name: str, doc: Any) -> bool:
        """Tell whether a stop is due: every streaming device's blocks reached its request.

        The dispatcher may lag behind the devices (its queues hold what it has not delivered
        yet): the file ends at the operator's request, not where the dispatcher happened to
        be. Devices with blocks further apart than :data:`SLOW_BLOCKS_S` are not waited for;
        a stalled device at most :data:`STOP_CATCH_UP_S`.
        """
        if time.monotonic_ns() - request.requested_ns > STOP_CATCH_UP_S * 1e9:
            return True
        for device, kept in self._preroll.items():
            last = int(kept[-1].host_time_ns[-1])
            if name == "block" and doc.device == device and len(doc):
                last = max(last, int(doc.host_time_ns[-1]))
            if last >= request.requested_ns:
                continue
            span = int(kept[-1].host_time_ns[-1]) - int(kept[0].host_time_ns[-1])
            if len(kept) < 2 or span > SLOW_BLOCKS_S * 1e9 * (len(kept) - 1):
                continue  # a polled device: its next block may be a second away
            return False
        return True

    def _keep(self, block: Any) -> None:
        """Keep the last ``preroll_s`` of a device's blocks for the next recording."""
        if not len(block):
            return
        kept = self._preroll.setdefault(block.device, deque())
        kept.append(block)
        oldest = int(block.host_time_ns[-1]) - int(self.preroll_s * 1e9)
        while kept and int(kept[0].host_time_ns[-1]) < oldest:
            kept.popleft()

    def _serve(self, request: _Request) -> None:
        with self._lock:
            if self._request is not request:  # withdrawn by the GUI thread after its timeout
                return
            self._request = None
            try:
                if request.kind == "start":
                    self._begin(request)
                else:
                    request.result, request.error = self._finish(request.reason,
                                                                 request.requested_ns)
            except Exception as exc:  # handed to the waiting GUI thread, which raises it
                log.exception("recording %s failed", request.kind)
                request.error = exc
            finally:
                request.done.set()

    @staticmethod
    def _call(writer: Any, name: str, doc: Any) -> BaseException | None:
        """Feed the file's writer one doc; return its failure, if any.

        The writer logs a failure itself (a storage error in one line, anything else with its
        traceback), closes its file and keeps the error in ``writer.error``.
        """
        try:
            writer(name, doc)
        except Exception as exc:  # logged by the writer; returned, never dropped
            return exc
        return cast(BaseException | None, writer.error)

    def _begin(self, request: _Request) -> None:
        if self._start_doc is None:
            raise RecordingError("record: the acquisition has not started yet")
        writer = request.writer
        # Time 0 is the operator's request, not the moment the dispatcher (which may lag behind
        # the devices) serves it: the blocks that arrived after it are still to be delivered.
        t0 = request.requested_ns
        doc = dict(self._start_doc)
        doc["host_time_ns"] = t0  # the file's time 0 is the recording's start
        doc["time"] = datetime.datetime.now(datetime.UTC).isoformat()
        error = self._call(writer, "start", doc)
        if error is not None:
            raise error
        self._events = {"overflow": 0, "fault": 0}
        self._writer = writer
        self.recording = Recording(path=Path(writer.path), notes=request.notes, started_ns=t0)
        log.info("recording to %s", writer.path)
        # The GUI thread goes on now: the pre-roll takes a few tenths of a second (the clock
        # maps refit at every block until their first windows close), a failure in it ends the
        # recording like any later one (``recording.error``).
        request.done.set()
        # Oldest first across devices, as the engine delivered them; before the current doc.
        # The trigger pulses among the pre-roll's blocks go with them: the clock maps' anchors
        # (they precede time 0 in the events table, as the raw samples do).
        blocks = [b for kept in self._preroll.values() for b in kept]
        oldest = min((int(b.host_time_ns[0]) for b in blocks), default=t0)
        pulses = [e for e in self._recent_events if getattr(e, "kind", "") == "trigger"
                  and oldest <= int(getattr(e, "host_time_ns", -1)) < t0]
        preroll = sorted([("block", b, int(b.host_time_ns[-1])) for b in blocks]
                         + [("event", e, int(e.host_time_ns)) for e in pulses],
                         key=lambda item: item[2])
        for name, doc, _ in preroll:
            if self._writer is None:
                return
            self._write(name, doc)
        # Events already delivered that belong to the recording (trigger pulses, faults, made
        # between the request and now).
        for event in list(self._recent_events):
            if self._writer is None:
                return
            if int(getattr(event, "host_time_ns", -1)) >= t0:
                self._write("event", event)

    def _write(self, name: str, doc: Any) -> None:
        writer = self._writer
        if name == "event" and getattr(doc, "kind", "") in self._events:
            self._events[doc.kind] += 1
        error = self._call(writer, name, doc)
        if error is not None:  # e.g. the disk filled up: this recording ends, the live view not
            self._writer = None
            self._failed(error)

    def _finish(self, reason: str,
                end_ns: int) -> tuple[dict[str, Any] | None, BaseException | None]:
        """Write the stop doc (last rows, clock fits, summary) and close the file.

        Parameters
        ----------
        reason : str
            Why it stops (in the summary).
        end_ns : int
            Host ``time.monotonic_ns()`` of the stop (the request), ns.

        Returns
        -------
        (dict or None, exception or None)
            The writer's summary, or the failure (also in :attr:`recording`).
        """
        writer, self._writer = self._writer, None
        rec = self.recording
        if writer is None or rec is None:
            return None, RecordingError("stop recording: not recording")
        doc = {"reason": reason, "host_time_ns": end_ns,
               "duration_s": (end_ns - rec.started_ns) * 1e-9,
               "overflows": self._events["overflow"], "faults": self._events["fault"]}
        error = self._call(writer, "stop", doc)
        if error is not None:
            self._failed(error)
            return None, error
        self.recording = None
        log.info("recorded %s (%s)", writer.path, reason)
        return dict(writer.summary or {}), None

    def _failed(self, error: BaseException) -> None:
        """Keep a failure in :attr:`recording` (the writer closed the file)."""
        rec = self.recording
        text = f"{type(error).__name__}: {error}"
        log.error("recording to %s stopped: %s", None if rec is None else rec.path, text)
        if rec is not None:
            self.recording = dataclasses.replace(rec, error=text)

    # -- GUI thread ------------------------------------------------------------------------------
    def start(self, writer: Any, notes: str, timeout_s: float) -> None:
        """Hand an opened file's writer to the dispatcher and wait until it records.

        Raises
        ------
        RecordingError
            Already recording, or the dispatcher did not answer within ``timeout_s`` (the
            request is withdrawn).
        StorageError
            Writing the file's first rows failed.
        """
        request = _Request("start", writer=writer, notes=notes)
        with self._lock:
            self._check_idle()
            self._request = request
        if not request.done.wait(timeout_s):
            with self._lock:
                withdrawn = self._request is request
                if withdrawn:
                    self._request = None
            if withdrawn:
                raise RecordingError(f"record: the acquisition did not take the request within "
                                     f"{timeout_s:g} s (is it stalled?)")
            request.done.wait()  # served under the lock, so already done
        if request.error is not None:
            raise request.error

    def stop(self, reason: str, timeout_s: float) -> dict[str, Any]:
        """Ask the dispatcher to finish the file and wait; return the writer's summary.

        Raises
        ------
        RecordingError
            Not recording (or the recording had already failed), or the dispatcher did not
            finish within ``timeout_s`` (it still will: the request stays posted).
        StorageError
            Writing the file's last rows failed (also in :attr:`recording`).
        """
        with self._lock:
            request = self._request
            if request is None or request.kind != "stop":
                rec = self.recording
                if rec is None or rec.error is not None:
                    failed = "" if rec is None else f" (the last one failed: {rec.error})"
                    raise RecordingError(f"stop recording: not recording{failed}")
                request = _Request("stop", reason=reason)
                self._request = request
        if not request.done.wait(timeout_s):
            raise RecordingError(f"stop recording: the file is not finished after {timeout_s:g} "
                                 "s; the acquisition finishes it when it can")
        if request.error is not None:
            raise request.error
        return dict(request.result or {})

    def _check_idle(self) -> None:
        """Refuse a start while recording or while a request waits (hold ``_lock``)."""
        if self._request is not None:
            raise RecordingError(f"record: a {self._request.kind} request is pending")
        rec = self.recording
        if rec is not None and rec.error is None:
            raise RecordingError(f"record: already recording to {rec.path}")

    def check_idle(self) -> None:
        """Refuse a start while recording (before any file is created)."""
        with self._lock:
            self._check_idle()
