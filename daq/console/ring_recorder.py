"""What the live view's run writer writes into: the console's ring buffer, no file.

Responsibility: :class:`RingRecorder`, a :class:`~daq.recording.recorder_protocol.Recorder` as a
run file is: the live source runs the recording's own :class:`~daq.recording.writer.RunWriter`
into it, so that the live view and a recorded file hold the same sync rows by construction. The sync
rows go to the ring; of the raw streams only the last fan speed and the PLC's last ARM state
are kept (the console shows them); everything else is dropped.

Not responsible for: the sync rows' numbers (the writer), or the ring
(:mod:`daq.console.ring_buffer`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from contextlib import AbstractContextManager, nullcontext
from typing import Any

import numpy as np

from daq.console.ring_buffer import RingBuffer

__all__ = ["RingRecorder"]


class RingRecorder:
    """What :class:`~daq.recording.writer.RunWriter` writes into, for a live view: no file.

    A :class:`~daq.recording.recorder_protocol.Recorder`, as
    :class:`~daq.recording.recorder.RunRecorder` is.
    The sync rows go to ``ring`` (columns of :func:`daq.console.source.sync_columns`); of the raw
    streams only the last fan speed is kept (``fan_rpm``); everything else is dropped. Called on the
    engine's dispatcher thread; the ring is thread-safe, and ``fan_rpm`` is one float (atomic).

    Parameters
    ----------
    ring : RingBuffer
        The console's buffer.
    fan_devices : sequence of str
        Names of the fan drives whose ``speed`` channel is the fan state.
    plc_devices : sequence of str
        Names of the PLCs whose ``armed`` channel is the release state.
    """

    def __init__(self, ring: RingBuffer, fan_devices: Sequence[str] = (),
                 plc_devices: Sequence[str] = ()) -> None:
        self.ring = ring
        self._fans = set(fan_devices)
        self._plcs = set(plc_devices)
        self._channels: dict[str, list[str]] = {}
        self._state = "new"
        #: Last fan speed read, rpm (NaN before the first reading).
        self.fan_rpm = math.nan
        #: Last PLC ARM coil read: (host ``monotonic_ns`` of the reading, armed); None before.
        self.plc_armed: tuple[int, bool] | None = None

    @property
    def state(self) -> str:
        """Measure the phase, as ``RunRecorder.state``."""
        return self._state

    def open(self) -> None:
        """Start declaring streams (nothing to create)."""
        self._state = "declaring"

    def start(self, t0_host_ns: int | None = None) -> None:
        """Start taking rows."""
        self._state = "recording"

    def close(self) -> None:
        """Stop (the ring keeps its rows)."""
        self._state = "closed"

    def batch(self) -> AbstractContextManager[None]:
        """Group appends: nothing to do (the ring has no file to flush)."""
        return nullcontext()

    def add_stream(self, device: str, channels: Sequence[str], units: Any, rate_hz: float,
                   value_dtype: Any = "float32", *,
                   extra: Mapping[str, Any] | None = None) -> None:
        """Remember a stream's channel names."""
        self._channels[device] = list(channels)

    def add_sync(self, tap_names: Sequence[str]) -> None:
        """Declare the sync view (the ring already has its columns)."""

    def append_raw(self, device: str, host_time_ns: Any, device_time: Any, counter: Any,
                   values: Any, *, extra: Mapping[str, Any] | None = None) -> None:
        """Keep the last fan speed and PLC ARM state; drop the other raw samples."""
        channels = self._channels.get(device, ())
        if device in self._fans and "speed" in channels:
            table = np.asarray(values, dtype=np.float64)
            if table.ndim == 2 and table.shape[0]:
                self.fan_rpm = float(table[-1, channels.index("speed")])
        elif device in self._plcs and "armed" in channels:
            table = np.asarray(values, dtype=np.float64)
            hosts = np.asarray(host_time_ns, dtype=np.int64)
            if table.ndim == 2 and table.shape[0] and hosts.size:
                # one tuple, swapped whole (atomic for the GUI thread that reads it)
                self.plc_armed = (int(hosts[-1]), bool(table[-1, channels.index("armed")]))

    def append_sync(self, time: Any, *, h: Any, alpha: Any, lift: Any, moment: Any,
                    pressure: Any, U: Any, rho: Any, p: Any = None, drag: Any = None) -> None:
        """Append sync rows to the ring (a 3-DOF rig's with ``p`` and ``drag``)."""
        sway = {} if p is None else {"p": p, "drag": drag}
        self.ring.append({"time": time, "h": h, "alpha": alpha, "lift": lift, "moment": moment,
                          "U": U, "rho": rho, "pressure": pressure, **sway})

    def add_gap(self, device: str, after_counter: int, length: int) -> None:
        """Ignore (gaps are counted by the engine's stats)."""

    def add_event(self, time: float, kind: str, text: str = "") -> None:
        """Ignore (faults reach the health panel through the live source's own subscriber)."""

    def add_release(self, *, release_time: float, start_index: int, stop_index: int, U: float,
                    h0: float, alpha0: float, p0: float | None = None) -> None:
        """Ignore (the live releases come from the writer's ``release_hook``)."""

    def set_sync_attrs(self, *, clock_offset_s: Mapping[str, float] | None = None,
                       clock_drift_ppm: Mapping[str, float] | None = None,
                       residual_misalignment_s: float | None = None) -> None:
        """Ignore."""

    def add_metadata(self, name: str, value: Any) -> None:
        """Ignore."""

    def add_calibrations(self, records: Mapping[str, tuple[Mapping[str, Any],
                                                           Mapping[str, str]]]) -> None:
        """Ignore (the live view shows the calibrated columns; the run file keeps the values)."""
