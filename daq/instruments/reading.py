"""The reading contract: what every driver's ``read()`` returns, and what its ``describe()`` says.

Responsibility: :class:`Reading`, one read of one driver (a block of rows: the channels, the
host arrival times, the device times, the unwrapped counters, the gaps and per-read facts), the
one :class:`Gap` type of every stream (drivers, the engine's dropped blocks, counter unwrapping
in :mod:`daq.sync.counters`), :class:`PollSequence` (the poll numbers and gaps of the polled
drivers), :func:`describe_mismatches` (a ``describe()`` checked against a reading),
:func:`stream_breaches` (what the engine checks of every reading before it records it) and
:class:`ReadingContract` (those checks over one driver's stream, for the engine's readers and
the device check alike).

The contract, for every driver alike:

- ``read()`` returns a :class:`Reading` of ``n >= 1`` rows (a polled driver: ``n = 1``);
- ``describe()`` returns ``{channel: {"units", "dtype", "shape"}}`` with exactly the keys of
  ``Reading.channels``; ``shape`` is the shape of one row (``()`` for a scalar channel), so the
  array of a channel has shape ``(n, *shape)`` and the given dtype;
- ``host_time_ns``, ``device_time`` and ``counter`` are fields of the reading, not channels
  (every reading has host times and counters; only clocked devices have device times);
- ``gaps`` are the rows missing before or inside the reading, counted on ``counter``.

Not responsible for: producing readings (the drivers), or what the engine adds to them (its
device name, block number and the rows it dropped: :class:`daq.acquisition.records.StreamBlock`).
No I/O and no threads.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["GAP_KINDS", "Gap", "PollSequence", "Reading", "ReadingContract",
           "describe_mismatches", "stream_breaches"]

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]

#: Why rows are missing: ``"missing"`` (counted from the device counter, or a failed poll),
#: ``"restart"`` (the device or its scan restarted: the length is measured where the device
#: clock allows it, estimated from the host time, or -1 when unknown), ``"overflow"`` (the
#: engine dropped the rows on a full queue).
GAP_KINDS = ("missing", "restart", "overflow")


@dataclass(frozen=True)
class Gap:
    """Rows missing from a stream, on its unwrapped counter.

    Attributes
    ----------
    after_counter : int
        Unwrapped counter of the last row before the gap.
    length : int
        Number of rows missing; -1 when unknown (a restart whose length cannot be measured).
    kind : str
        One of :data:`GAP_KINDS`.
    """

    after_counter: int
    length: int
    kind: str = "missing"

    @property
    def exact(self) -> bool:
        """Measure whether the length was counted (not estimated after a restart, not unknown)."""
        return self.kind != "restart" and self.length >= 0


@dataclass(frozen=True, eq=False)
class Reading:
    """One read of one driver: ``n`` rows of every channel, stamped and counted.

    Attributes
    ----------
    channels : mapping of str to ndarray
        Channel -> array of shape ``(n, *shape)``, keyed, typed and shaped as the driver's
        ``describe()`` (SI units, or those ``describe()`` names).
    host_time_ns : ndarray of int64, (n,)
        Host ``time.monotonic_ns()`` when each row arrived, ns.
    counter : ndarray of int64, (n,)
        Unwrapped counter of each row: the device's (scanner frames, laser samples) or the
        driver's poll number (each poll uses one, failed or not).
    device_time : ndarray of float64, (n,), or None
        The device's own clock, s (scanner frame time, laser timestamp); None for polled devices.
    gaps : tuple of Gap
        Rows missing before or inside this reading.
    info : mapping
        Facts of this read that are not rows (e.g. the scanner's ``time_base`` and
        ``clock_steps``, the laser's ``bytes_skipped``, the barometer's ``status``).
    """

    channels: Mapping[str, npt.NDArray[Any]]
    host_time_ns: IntArray
    counter: IntArray
    device_time: FloatArray | None = None
    gaps: tuple[Gap, ...] = ()
    info: Mapping[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.host_time_ns.shape[0])


class PollSequence:
    """Poll numbers of a polled driver and the gaps their jumps leave.

    Every poll takes the next number when it starts (:meth:`next`), numbers counting from 1, so
    a poll that fails leaves a hole; the next reading delivered (:meth:`reading`) carries it as
    a gap. That holds for the very first polls too: the sequence starts as if poll 0 had been
    delivered, so a first reading numbered 3 carries ``Gap(0, 2)`` (polls 1 and 2 failed) and
    no row is lost without a trace.
    """

    def __init__(self) -> None:
        self.count = 0
        # Poll 0 stands for the start: a failed first poll is a gap like any other.
        self._delivered = 0

    def next(self) -> int:
        """Take the number of a poll that starts now."""
        self.count += 1
        return self.count

    def reading(self, number: int, values: Mapping[str, Any], dtypes: Mapping[str, str], *,
                host_time_ns: int | None = None, info: Mapping[str, Any] | None = None,
                ) -> Reading:
        """Return poll ``number``'s one-row reading, with a gap after the last one delivered.

        Parameters
        ----------
        number : int
            The poll's number (:meth:`next`).
        values : mapping
            Channel -> scalar value of this poll.
        dtypes : mapping
            Channel -> numpy dtype name (the driver's ``describe()``).
        host_time_ns : int, optional
            When the poll's last reply arrived (default: now), ns.
        info : mapping, optional
            Facts of this poll that are not rows.
        """
        gaps: tuple[Gap, ...] = ()
        if number != self._delivered + 1:
            gaps = (Gap(self._delivered, number - self._delivered - 1),)
        self._delivered = number
        stamp = time.monotonic_ns() if host_time_ns is None else int(host_time_ns)
        return Reading(
            channels={k: np.array([values[k]], dtype=dtypes[k]) for k in dtypes},
            host_time_ns=np.array([stamp], np.int64), counter=np.array([number], np.int64),
            gaps=gaps, info=dict(info or {}))


def describe_mismatches(described: Mapping[str, Mapping[str, Any]], reading: Reading,
                        ) -> list[str]:
    """List how a reading differs from a ``describe()`` (empty: it matches the contract).

    Checks the channel names (both ways), each channel's dtype and shape ``(n, *shape)``, and
    the shapes and dtypes of ``host_time_ns``, ``counter`` and ``device_time``.
    """
    n = len(reading)
    out: list[str] = []
    if set(described) != set(reading.channels):
        out.append(f"channels {sorted(reading.channels)} != described {sorted(described)}")
    for name, info in described.items():
        if name not in reading.channels:
            continue
        arr = np.asarray(reading.channels[name])
        shape = (n, *tuple(info.get("shape", ())))
        if arr.shape != shape:
            out.append(f"{name}: shape {arr.shape} != described {shape}")
        if arr.dtype != np.dtype(info.get("dtype", "float64")):
            out.append(f"{name}: dtype {arr.dtype} != described {info.get('dtype')}")
        if "units" not in info:
            out.append(f"{name}: no units")
    for name, dtype in (("host_time_ns", np.int64), ("counter", np.int64)):
        arr = getattr(reading, name)
        if arr.shape != (n,) or arr.dtype != dtype:
            out.append(f"{name}: {arr.dtype} {arr.shape}, expected int64 ({n},)")
    t = reading.device_time
    if t is not None and (t.shape != (n,) or t.dtype != np.float64):
        out.append(f"device_time: {t.dtype} {t.shape}, expected float64 ({n},)")
    return out


def stream_breaches(described: Mapping[str, Mapping[str, Any]] | None, reading: Any,
                    last_counter: int | None) -> list[str]:
    """List how one reading of a stream breaks the contract the recorder relies on.

    The engine checks every reading with this before it queues it: a reading that is not a
    :class:`Reading`, that differs from the driver's ``describe()`` (the run file's datasets are
    laid out from it, so a wrong shape stops the writer and with it the whole run), or whose
    counter does not increase (within the reading, and after ``last_counter``, the last one of
    the stream: rows recorded out of order, or twice, without a word) is a driver's bug, found
    here and named rather than recorded or crashing downstream.

    Parameters
    ----------
    described : mapping or None
        The driver's ``describe()``; None when the driver has none (its channels are then not
        checked).
    reading : object
        What the driver's ``read()`` (or ``drain()``) returned.
    last_counter : int or None
        The counter of the stream's last row delivered before, None before the first.

    Returns
    -------
    list of str
        The breaches, empty when the reading may be recorded.
    """
    if not isinstance(reading, Reading):
        return [f"read() returned a {type(reading).__name__}, not a "
                "daq.instruments.reading.Reading"]
    stamps = reading.host_time_ns
    if not (isinstance(stamps, np.ndarray) and stamps.ndim == 1):  # len(reading) needs it
        return [f"host_time_ns is a {type(stamps).__name__} of shape "
                f"{getattr(stamps, 'shape', '?')}, expected an int64 array (n,)"]
    out = [] if described is None else describe_mismatches(described, reading)
    counter = np.asarray(reading.counter)
    if out or counter.ndim != 1 or counter.size == 0:
        return out  # the counters' shapes are in ``out`` already, or there are no rows
    if counter.size > 1 and np.any(np.diff(counter) < 1):
        out.append("counter does not increase within the reading")
    if last_counter is not None and int(counter[0]) <= last_counter:
        out.append(f"counter goes back: {int(counter[0])} after {last_counter}")
    return out


class ReadingContract:
    """One driver's stream checked reading by reading (:func:`stream_breaches`).

    The driver's ``describe()`` is taken at the first reading (after ``open()``: some drivers
    learn their channels there), and the last counter of every reading that passed is kept, so
    that a counter going back across readings is found too.

    Parameters
    ----------
    driver : object
        The driver whose readings are checked (its class names it in the message).
    """

    def __init__(self, driver: Any) -> None:
        self._driver = driver
        self._described: dict[str, Any] | None = None
        self._taken = False
        self._last_counter: int | None = None

    def breach(self, reading: Any) -> str | None:
        """Return what breaks the contract in ``reading`` (None: it may be recorded).

        The text names the driver's class and every breach, for the caller's error.
        """
        if not self._taken:
            describe = getattr(self._driver, "describe", None)
            self._described = dict(describe()) if callable(describe) else None
            self._taken = True
        problems = stream_breaches(self._described, reading, self._last_counter)
        if problems:
            kind = type(self._driver)
            return (f"its driver {kind.__module__}.{kind.__qualname__} delivered a reading "
                    "that breaks the reading contract (docs/guides/drivers.md): "
                    f"{'; '.join(problems)}")
        if len(reading):
            self._last_counter = int(reading.counter[-1])
        return None
