"""What the run writer writes a run into: the :class:`Recorder` protocol.

Responsibility: the methods, in one place, that :class:`~daq.recording.writer.RunWriter` and its
helpers (:mod:`daq.recording.devices`, :mod:`daq.recording.releases`,
:mod:`daq.recording.raw_batches`) call on what they write into. Two classes implement it:
:class:`daq.recording.recorder.RunRecorder` (a run file) and
:class:`daq.console.ring_recorder.RingRecorder` (the live console's ring buffer, no file).

Not responsible for: any implementation; the methods' meaning is
:class:`~daq.recording.recorder.RunRecorder`'s.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from contextlib import AbstractContextManager
from typing import Any, Protocol

__all__ = ["Recorder"]


class Recorder(Protocol):
    """What :class:`~daq.recording.writer.RunWriter` writes a run into.

    :class:`~daq.recording.recorder.RunRecorder` (a run file) and
    :class:`daq.console.ring_recorder.RingRecorder` (the live console's ring buffer, no file)
    implement it; the methods and their meaning are
    :class:`~daq.recording.recorder.RunRecorder`'s.
    """

    @property
    def state(self) -> str:
        """Measure the phase: ``"new"``, ``"declaring"``, ``"recording"`` or ``"closed"``."""
        ...

    def open(self) -> None:
        """Start declaring streams."""
        ...

    def start(self, t0_host_ns: int | None = None) -> None:
        """Start taking rows (time 0 at ``t0_host_ns``)."""
        ...

    def close(self) -> None:
        """Finish."""
        ...

    def batch(self) -> AbstractContextManager[None]:
        """Group appends (raw rows and the sync rows made from them) for one flush."""
        ...

    def add_stream(self, device: str, channels: Sequence[str], units: Any, rate_hz: float,
                   value_dtype: Any = "float32", *,
                   extra: Mapping[str, Any] | None = None) -> None:
        """Declare a device's raw stream."""
        ...

    def add_sync(self, tap_names: Sequence[str]) -> None:
        """Declare the synchronised view."""
        ...

    def append_raw(self, device: str, host_time_ns: Any, device_time: Any, counter: Any,
                   values: Any, *, extra: Mapping[str, Any] | None = None) -> None:
        """Append a device's raw samples."""
        ...

    def append_sync(self, time: Any, *, h: Any, alpha: Any, lift: Any, moment: Any,
                    pressure: Any, U: Any, rho: Any, p: Any = None, drag: Any = None) -> None:
        """Append rows of the synchronised view (``p``, ``drag``: a 3-DOF rig's)."""
        ...

    def add_gap(self, device: str, after_counter: int, length: int) -> None:
        """Mark a gap in a device's stream."""
        ...

    def add_event(self, time: float, kind: str, text: str = "") -> None:
        """Add an operator or system event."""
        ...

    def add_release(self, *, release_time: float, start_index: int, stop_index: int, U: float,
                    h0: float, alpha0: float, p0: float | None = None) -> Any:
        """Add a free decay to the releases table (``p0``: a 3-DOF rig's)."""
        ...

    def set_sync_attrs(self, *, clock_offset_s: Mapping[str, float] | None = None,
                       clock_drift_ppm: Mapping[str, float] | None = None,
                       residual_misalignment_s: float | None = None) -> None:
        """Store the clock fits with the synchronised view."""
        ...

    def add_metadata(self, name: str, value: Any) -> None:
        """Store a metadata entry."""
        ...

    def add_calibrations(self, records: Mapping[str, tuple[Mapping[str, Any],
                                                           Mapping[str, str]]]) -> None:
        """Store the calibrations the run applies (before start)."""
        ...
