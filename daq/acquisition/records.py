"""The records the acquisition engine hands to its subscribers: blocks, events, faults, counters.

Responsibility: define the immutable records of the engine's ``(name, doc)`` stream
(:mod:`daq.acquisition.engine`): :class:`StreamBlock` (the ``"block"`` doc: one driver
:class:`~daq.instruments.reading.Reading` with its device and block number), :class:`Event` (the
``"event"`` doc) and its :class:`DeviceFault`, and :class:`DeviceStats` (a reader's counters,
:meth:`~daq.acquisition.engine.Acquisition.stats`); with the vocabulary of their ``kind`` fields
(:data:`KINDS`, :data:`SYSTEM_EVENT_KINDS`) and the array aliases they are typed with.

Not responsible for: producing the records (the readers, :mod:`daq.acquisition.reader`; the engine,
:mod:`daq.acquisition.engine`) or consuming them (the subscribers:
:class:`~daq.recording.writer.RunWriter`, the live ring buffers). No I/O and no threads: frozen
dataclasses only.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from daq.instruments.reading import Gap, Reading

__all__ = [
    "KINDS",
    "SYSTEM_EVENT_KINDS",
    "DeviceFault",
    "DeviceStats",
    "Event",
    "FloatArray",
    "Gaps",
    "IntArray",
    "StreamBlock",
]

#: Kinds of device the engine knows how to read.
KINDS = ("scanner", "laser", "barometer", "fan", "plc", "analog")
#: Event kinds the engine itself emits; :meth:`~daq.acquisition.engine.Acquisition.mark` refuses
#: them.
SYSTEM_EVENT_KINDS = frozenset({"fault", "recovered", "overflow", "release", "release_failed",
                                "arm", "arm_failed", "disarm", "disarm_failed", "trigger",
                                "calz", "calz_failed", "fan_speed", "fan_start", "fan_stop",
                                "fan_failed", "fan_reached", "manual_release", "manual_hold",
                                "release_detected", "release_not_detected"})

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]
Gaps = tuple[Gap, ...]


# ------------------------------------------------------------------------------------------------
# Records passed to subscribers
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class StreamBlock:
    """One driver reading as the engine delivers it: the ``"block"`` doc.

    The fields of the driver's :class:`~daq.instruments.reading.Reading` (the same arrays), with
    the device it came from, its block number, and the rows the engine dropped before it.

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
    counter : ndarray of int64, (n,)
        Unwrapped device counter (scanner frames, laser samples) or the driver's poll number
        (the barometer, the fan, the PLC: a failed poll skips one).
    values : mapping of str to ndarray
        The reading's channels: channel -> array of ``n`` rows, as the driver's ``describe()``
        (e.g. ``distance`` in m, ``pressure`` (n, taps) in Pa).
    gaps : tuple of Gap
        Rows missing before or inside this block: the reading's own (counter jumps, restarts,
        failed polls), preceded by those of blocks the engine dropped on a full queue (kind
        ``"overflow"``, see ``overflow_samples``).
    info : mapping
        The reading's facts that are not rows (``Reading.info``).
    overflow_samples : int
        Rows of this device dropped on a full queue just before this block (0 normally).
    """

    device: str
    kind: str
    seq: int
    host_time_ns: IntArray
    device_time: FloatArray | None
    counter: IntArray
    values: Mapping[str, npt.NDArray[Any]]
    gaps: Gaps = ()
    info: Mapping[str, Any] = field(default_factory=dict)
    overflow_samples: int = 0

    @classmethod
    def of(cls, device: str, kind: str, seq: int, reading: Reading) -> StreamBlock:
        """Return driver ``reading`` as block ``seq`` of ``device`` (a ``kind``)."""
        return cls(device=device, kind=kind, seq=seq, host_time_ns=reading.host_time_ns,
                   device_time=reading.device_time, counter=reading.counter,
                   values=reading.channels, gaps=reading.gaps, info=reading.info)

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
        :meth:`~daq.acquisition.engine.Acquisition.mark`.
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
    """Counters of one device's reader (:meth:`~daq.acquisition.engine.Acquisition.stats`).

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
