"""A stand-in for the parts of the ``nidaqmx`` package's Task API that windrig's driver uses.

The NI-DAQmx runtime (a C library and kernel drivers for NI hardware) cannot be installed on a
machine without NI hardware support, so windrig's NI-DAQmx driver is tested against this
stand-in: the same names, signatures and error codes as the documented ``nidaqmx`` API, talking
over loopback TCP to a simulated DAQ device (:class:`simulators.devices.ni_daqmx.SimNiDaqmx`)
that acquires the virtual tunnel's signals on a real clock. It is a stand-in, not NI's
software: what it models is written below, the rest of nidaqmx does not exist here.

What exists (``nidaqmx`` names):

- ``Task(new_task_name="")`` with ``ai_channels.add_ai_voltage_chan(physical_channel,
  name_to_assign_to_channel="", terminal_config=..., min_val=-5.0, max_val=5.0, ...)``,
  ``di_channels.add_di_chan(lines, name_to_assign_to_lines="", line_grouping=...)``,
  ``ci_channels.add_ci_count_edges_chan(counter, name_to_assign_to_channel="", edge=...,
  initial_count=0, count_direction=...)``, ``timing.cfg_samp_clk_timing(rate, source="",
  active_edge=..., sample_mode=AcquisitionType.FINITE, samps_per_chan=1000)``, ``start()``,
  ``stop()``, ``close()``, ``read(number_of_samples_per_channel=..., timeout=10.0)``, and the
  context manager;
- ``Task.in_stream``: ``overwrite``, ``relative_to``, ``offset``, ``total_samp_per_chan_acquired``,
  ``avail_samp_per_chan``, ``input_buf_size``;
- ``stream_readers.AnalogMultiChannelReader(task.in_stream).read_many_sample(data,
  number_of_samples_per_channel=READ_ALL_AVAILABLE, timeout=10.0)`` into a ``(channels,
  samples)`` float64 array, returning the samples read per channel;
- ``errors.DaqError(message, error_code, task_name="")`` with ``error_code``; ``DaqReadError``;
  ``DaqNotFoundError`` (raised, as the real package does, when its C library is missing:
  ``standin_api(..., runtime_missing=True)``) and ``DaqNotSupportedError``;
- ``system.System.local().driver_version`` (``major_version``, ``minor_version``,
  ``update_version``) and ``.devices`` (names);
- ``constants``: ``AcquisitionType``, ``OverwriteMode``, ``ReadRelativeTo``,
  ``TerminalConfiguration``, ``Edge``, ``CountDirection``, ``LineGrouping``, ``READ_ALL_AVAILABLE``.

Error codes the device answers with, as NI-DAQmx's: -200279 (samples no longer available: they
were overwritten in the buffer), -200284 (some or all samples requested have not yet been
acquired: a read timed out), -201003 (device cannot be accessed: lost), -50103 (the specified
resource is reserved: a second analog input task on one device), -200077 (an invalid property
value). The constants' numeric values are placeholders; the driver uses their names only.

Wire (the stand-in's own, loopback only): one TCP connection per started task; a request is a
JSON line; the answer is a JSON line (``{"ok": true, ...}`` or ``{"error": code, "message":
...}``), a read's answer followed by its samples as raw little-endian bytes.
"""

from __future__ import annotations

import enum
import json
import socket
import time
import types
from collections import namedtuple
from typing import Any, Final

import numpy as np

__all__ = ["NAME", "READ_ALL_AVAILABLE", "standin_api"]

#: The stand-in's name, as the driver reports it.
NAME: Final = "nidaqmx stand-in"
#: ``nidaqmx.constants.READ_ALL_AVAILABLE``.
READ_ALL_AVAILABLE: Final = -1

#: Error codes (NI-DAQmx's).
SAMPLES_NO_LONGER_AVAILABLE: Final = -200279
SAMPLES_NOT_YET_AVAILABLE: Final = -200284
DEV_CANNOT_BE_ACCESSED: Final = -201003
RESOURCE_RESERVED: Final = -50103
INVALID_ATTRIBUTE_VALUE: Final = -200077

#: The runtime version the stand-in reports.
DriverVersion = namedtuple("DriverVersion", "major_version minor_version update_version")
STANDIN_VERSION: Final = DriverVersion(0, 0, 0)


# -- constants -------------------------------------------------------------------------------------
class AcquisitionType(enum.Enum):
    """``nidaqmx.constants.AcquisitionType``."""

    FINITE = 10178
    CONTINUOUS = 10123


class OverwriteMode(enum.Enum):
    """``nidaqmx.constants.OverwriteMode``."""

    OVERWRITE_UNREAD_SAMPLES = 10252
    DO_NOT_OVERWRITE_UNREAD_SAMPLES = 10159


class ReadRelativeTo(enum.Enum):
    """``nidaqmx.constants.ReadRelativeTo``."""

    FIRST_SAMPLE = 10424
    CURR_READ_POS = 10425
    MOST_RECENT_SAMPLE = 10428


class TerminalConfiguration(enum.Enum):
    """``nidaqmx.constants.TerminalConfiguration``."""

    DEFAULT = -1
    RSE = 10083
    NRSE = 10078
    DIFF = 10106


class Edge(enum.Enum):
    """``nidaqmx.constants.Edge``."""

    RISING = 10280
    FALLING = 10171


class CountDirection(enum.Enum):
    """``nidaqmx.constants.CountDirection``."""

    COUNT_UP = 10128
    COUNT_DOWN = 10124


class LineGrouping(enum.Enum):
    """``nidaqmx.constants.LineGrouping``."""

    CHAN_PER_LINE = 0
    CHAN_FOR_ALL_LINES = 1


# -- errors ----------------------------------------------------------------------------------------
class Error(Exception):
    """``nidaqmx.errors.Error``: the base of the package's errors."""


class DaqError(Error):
    """``nidaqmx.errors.DaqError``: an NI-DAQmx error, with its ``error_code``."""

    def __init__(self, message: str, error_code: int, task_name: str = "") -> None:
        if task_name:
            message = f"{message}\n\nTask Name: {task_name}"
        super().__init__(message)
        self._error_code = int(error_code)

    @property
    def error_code(self) -> int:
        """The NI-DAQmx error code."""
        return self._error_code


class DaqReadError(DaqError):
    """``nidaqmx.errors.DaqReadError``: a read's error, with the samples read before it."""

    def __init__(self, message: str, error_code: int, samps_per_chan_read: int,
                 task_name: str = "") -> None:
        super().__init__(message, error_code, task_name)
        self.samps_per_chan_read = samps_per_chan_read


class DaqNotFoundError(Error):
    """``nidaqmx.errors.DaqNotFoundError``: the NI-DAQmx C library is not installed."""


class DaqNotSupportedError(Error):
    """``nidaqmx.errors.DaqNotSupportedError``: NI-DAQmx does not exist for this platform."""


_NOT_FOUND = ("Could not find an installation of NI-DAQmx. Please ensure that NI-DAQmx is "
              "installed on this machine or contact National Instruments for support.")
_MESSAGES = {
    SAMPLES_NO_LONGER_AVAILABLE: "Attempted to read samples that are no longer available. The "
    "requested sample was previously available, but has since been overwritten.",
    SAMPLES_NOT_YET_AVAILABLE: "Some or all of the samples requested have not yet been "
    "acquired.",
    DEV_CANNOT_BE_ACCESSED: "Device cannot be accessed. Possible causes: Device is no longer "
    "present in the system. Device is not powered.",
    RESOURCE_RESERVED: "The specified resource is reserved. The operation could not be "
    "completed as specified.",
}


def _error(code: int, message: str = "", task: str = "") -> DaqError:
    return DaqError(message or _MESSAGES.get(code, f"NI-DAQmx error {code}"), code, task)


# -- the task --------------------------------------------------------------------------------------
class _Link:
    """A task's connection to the simulated device (opened when the task starts)."""

    def __init__(self, address: tuple[str, int], task: str) -> None:
        self.address = address
        self.task = task
        self.sock: socket.socket | None = None
        self.rfile: Any = None

    def connect(self) -> None:
        try:
            self.sock = socket.create_connection(self.address, timeout=5.0)
        except OSError as exc:
            raise _error(DEV_CANNOT_BE_ACCESSED, task=self.task) from exc
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.rfile = self.sock.makefile("rb")

    def call(self, request: dict[str, Any]) -> tuple[dict[str, Any], bytes]:
        """Send one request; return the answer and its payload (raise its DaqError)."""
        if self.sock is None:
            raise _error(INVALID_ATTRIBUTE_VALUE, "the task is not running", self.task)
        try:
            self.sock.sendall(json.dumps(request).encode() + b"\n")
            line = self.rfile.readline()
            if not line:
                raise ConnectionError("the simulated device closed the connection")
            answer = json.loads(line)
            payload = self.rfile.read(int(answer.get("bytes", 0))) if answer.get("bytes") else b""
        except (OSError, ValueError) as exc:
            self.close()
            raise _error(DEV_CANNOT_BE_ACCESSED, task=self.task) from exc
        if "error" in answer:
            raise _error(int(answer["error"]), str(answer.get("message", "")), self.task)
        return answer, payload

    def close(self) -> None:
        if self.sock is not None:
            try:
                self.sock.close()
            finally:
                self.sock = None
                self.rfile = None


class _Collection:
    """A task's channel collection (``ai_channels``, ``di_channels``, ``ci_channels``)."""

    def __init__(self, task: _TaskBase, kind: str) -> None:
        self._task = task
        self._kind = kind

    def add_ai_voltage_chan(self, physical_channel: str, name_to_assign_to_channel: str = "",
                            terminal_config: TerminalConfiguration = TerminalConfiguration.DEFAULT,
                            min_val: float = -5.0, max_val: float = 5.0, units: Any = None,
                            custom_scale_name: str = "") -> None:
        """Add analog voltage input channels (``Dev1/ai0`` or ``Dev1/ai0:3``)."""
        self._task._add("ai", physical_channel, min=float(min_val), max=float(max_val),
                        terminal=terminal_config.name)

    def add_di_chan(self, lines: str, name_to_assign_to_lines: str = "",
                    line_grouping: LineGrouping = LineGrouping.CHAN_FOR_ALL_LINES) -> None:
        """Add a digital input line (``Dev1/port0/line0``)."""
        self._task._add("di", lines)

    def add_ci_count_edges_chan(self, counter: str, name_to_assign_to_channel: str = "",
                                edge: Edge = Edge.RISING, initial_count: int = 0,
                                count_direction: CountDirection = CountDirection.COUNT_UP
                                ) -> None:
        """Add a counter that counts the edges of its input (``Dev1/ctr0``)."""
        self._task._add("ci", counter, initial=int(initial_count))


class _Timing:
    def __init__(self, task: _TaskBase) -> None:
        self._task = task

    def cfg_samp_clk_timing(self, rate: float, source: str = "", active_edge: Edge = Edge.RISING,
                            sample_mode: AcquisitionType = AcquisitionType.FINITE,
                            samps_per_chan: int = 1000) -> None:
        """Configure the sample clock: its rate (Hz), source, mode and buffer size (samples)."""
        if sample_mode is not AcquisitionType.CONTINUOUS:
            raise _error(INVALID_ATTRIBUTE_VALUE, "the stand-in acquires continuously only")
        self._task._timing = {"rate": float(rate), "source": source,
                              "buffer": int(samps_per_chan)}


class _InStream:
    """``Task.in_stream``: where reads start, and how much was acquired."""

    def __init__(self, task: _TaskBase) -> None:
        self._task = task
        self.overwrite = OverwriteMode.DO_NOT_OVERWRITE_UNREAD_SAMPLES
        self.relative_to = ReadRelativeTo.CURR_READ_POS
        self.offset = 0
        self.curr_read_pos = 0

    @property
    def input_buf_size(self) -> int:
        """Samples per channel the buffer holds."""
        return int(self._task._timing.get("buffer", 0))

    @property
    def total_samp_per_chan_acquired(self) -> int:
        """Samples acquired per channel since the task started."""
        answer, _ = self._task._link.call({"op": "total"})
        return int(answer["total"])

    @property
    def avail_samp_per_chan(self) -> int:
        """Samples available to read from the current read position."""
        return max(0, self.total_samp_per_chan_acquired - self.curr_read_pos)

    def _start(self, n: int) -> tuple[int, int]:
        """First sample of a read and how many (``n``; -1: all available)."""
        total = self.total_samp_per_chan_acquired
        if self.relative_to is ReadRelativeTo.FIRST_SAMPLE:
            first = self.offset
        elif self.relative_to is ReadRelativeTo.MOST_RECENT_SAMPLE:
            first = total + self.offset
        else:
            first = self.curr_read_pos + self.offset
        count = max(0, total - first) if n == READ_ALL_AVAILABLE else int(n)
        return first, count

    def _fetch(self, n: int, timeout: float) -> np.ndarray:
        """Read ``n`` samples per channel at the read position; rows are samples."""
        first, count = self._start(n)
        deadline = time.monotonic() + float(timeout)
        while True:
            answer, payload = self._task._link.call({"op": "read", "from": first, "n": count})
            if int(answer["n"]) == count:
                break
            if time.monotonic() >= deadline:
                raise DaqReadError(_MESSAGES[SAMPLES_NOT_YET_AVAILABLE],
                                   SAMPLES_NOT_YET_AVAILABLE, 0, self._task.name)
            time.sleep(0.001)
        self.curr_read_pos = first + count
        return np.frombuffer(payload, dtype=answer["dtype"]).reshape(answer["shape"])


class _TaskBase:
    """``nidaqmx.Task`` (see the module docstring); bound to a device by :func:`standin_api`."""

    _address: tuple[str, int] = ("127.0.0.1", 0)
    _runtime_missing = False
    _count = 0

    def __init__(self, new_task_name: str = "") -> None:
        if self._runtime_missing:
            raise DaqNotFoundError(_NOT_FOUND)
        type(self)._count += 1
        self.name = new_task_name or f"_unnamedTask<{type(self)._count}>"
        self.ai_channels = _Collection(self, "ai")
        self.di_channels = _Collection(self, "di")
        self.ci_channels = _Collection(self, "ci")
        self.timing = _Timing(self)
        self.in_stream = _InStream(self)
        self._kind = ""
        self._device = ""
        self._lines: list[str] = []
        self._options: dict[str, Any] = {}
        self._timing: dict[str, Any] = {}
        self._link = _Link(self._address, self.name)

    def _add(self, kind: str, physical: str, **options: Any) -> None:
        device, _, line = physical.partition("/")
        if self._kind and (kind != self._kind or device != self._device):
            raise _error(INVALID_ATTRIBUTE_VALUE, f"a task's channels are of one kind on one "
                         f"device: {physical!r} after {self._kind} on {self._device}", self.name)
        self._kind, self._device = kind, device
        self._lines.append(line)
        self._options.update(options)

    @property
    def number_of_channels(self) -> int:
        """Channels in the task."""
        return len(_expand(self._lines)) if self._kind == "ai" else len(self._lines)

    def start(self) -> None:
        """Start the task (connect to the device, which starts acquiring)."""
        if not self._timing:
            raise _error(INVALID_ATTRIBUTE_VALUE, "no sample clock configured", self.name)
        self._link.connect()
        self._link.call({"op": "start", "kind": self._kind, "device": self._device,
                         "lines": _expand(self._lines) if self._kind == "ai" else self._lines,
                         **self._timing, **self._options})
        self.in_stream.curr_read_pos = 0

    def stop(self) -> None:
        """Stop the task."""
        if self._link.sock is not None:
            self._link.call({"op": "stop"})

    def close(self) -> None:
        """Close the task (its connection); idempotent."""
        try:
            if self._link.sock is not None:
                self._link.call({"op": "stop"})
        finally:
            self._link.close()

    def read(self, number_of_samples_per_channel: int = READ_ALL_AVAILABLE,
             timeout: float = 10.0) -> Any:
        """Read samples: a list per channel (one channel: a list of samples)."""
        rows = self.in_stream._fetch(number_of_samples_per_channel, timeout)
        if rows.ndim == 1 or rows.shape[1] == 1:
            values = rows.reshape(-1)
            return [bool(v) for v in values] if self._kind == "di" else values.tolist()
        return rows.T.tolist()

    def __enter__(self) -> _TaskBase:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class AnalogMultiChannelReader:
    """``nidaqmx.stream_readers.AnalogMultiChannelReader``."""

    def __init__(self, task_in_stream: _InStream) -> None:
        self._in_stream = task_in_stream

    def read_many_sample(self, data: np.ndarray, number_of_samples_per_channel: int =
                         READ_ALL_AVAILABLE, timeout: float = 10.0) -> int:
        """Read into ``data`` of shape (channels, samples); return the samples per channel."""
        n = number_of_samples_per_channel
        if n == READ_ALL_AVAILABLE:
            n = min(data.shape[1], self._in_stream._start(READ_ALL_AVAILABLE)[1])
        if data.ndim != 2 or data.shape[1] < n:
            raise _error(INVALID_ATTRIBUTE_VALUE, f"data of shape {data.shape} cannot hold "
                         f"{n} samples per channel")
        rows = self._in_stream._fetch(n, timeout)
        data[:, :rows.shape[0]] = rows.T
        return int(rows.shape[0])


def _expand(lines: list[str]) -> list[str]:
    """``ai0:2`` -> ``ai0, ai1, ai2`` (NI's range syntax)."""
    out: list[str] = []
    for spec in lines:
        for part in spec.split(","):
            name, _, hi = part.strip().partition(":")
            lo = int(name[2:])
            out += [f"ai{i}" for i in range(lo, (int(hi) if hi else lo) + 1)]
    return out


def standin_api(host: str, port: int, *, runtime_missing: bool = False) -> Any:
    """Return the stand-in ``nidaqmx`` API bound to the simulated device at ``host:port``.

    Parameters
    ----------
    host, port : str, int
        The simulated device (:class:`simulators.devices.ni_daqmx.SimNiDaqmx`; loopback).
    runtime_missing : bool
        Behave as the real package does when the NI-DAQmx C library is not installed:
        ``Task()`` and ``System.local().driver_version`` raise ``DaqNotFoundError``.
    """
    if host not in ("127.0.0.1", "localhost"):
        raise ValueError(f"the stand-in reaches simulated devices on loopback only, not {host!r}")
    task = type("Task", (_TaskBase,), {"_address": (host, int(port)),
                                       "_runtime_missing": runtime_missing, "_count": 0})

    class _System:
        @staticmethod
        def local() -> Any:
            return _System()

        @property
        def driver_version(self) -> DriverVersion:
            if runtime_missing:
                raise DaqNotFoundError(_NOT_FOUND)
            return STANDIN_VERSION

        @property
        def devices(self) -> list[str]:
            link = _Link((host, int(port)), "system")
            link.connect()
            try:
                answer, _ = link.call({"op": "devices"})
            finally:
                link.close()
            return list(answer["devices"])

    return types.SimpleNamespace(
        name=NAME, Task=task,
        constants=types.SimpleNamespace(
            AcquisitionType=AcquisitionType, OverwriteMode=OverwriteMode,
            ReadRelativeTo=ReadRelativeTo, TerminalConfiguration=TerminalConfiguration,
            Edge=Edge, CountDirection=CountDirection, LineGrouping=LineGrouping,
            READ_ALL_AVAILABLE=READ_ALL_AVAILABLE),
        errors=types.SimpleNamespace(Error=Error, DaqError=DaqError, DaqReadError=DaqReadError,
                                     DaqNotFoundError=DaqNotFoundError,
                                     DaqNotSupportedError=DaqNotSupportedError),
        stream_readers=types.SimpleNamespace(AnalogMultiChannelReader=AnalogMultiChannelReader),
        system=types.SimpleNamespace(System=_System))
