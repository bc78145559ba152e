"""Scanivalve MPS4264-class pressure scanner over TCP: the driver.

Responsibility: command the scanner over its ASCII command connection (status, frame rate, output
format, zero calibration, scan start and stop), receive its binary frames on one TCP data connection
per module, decode them (:class:`~daq.instruments.scanivalve_mps4264.frames.Mps4264Decoder`, pure,
no I/O), unwrap the frame counters, merge the modules frame by frame, and return timestamped blocks
(:class:`~daq.instruments.scanivalve_mps4264.blocks.ScanBlock`) in which every missing frame is a
marked gap and every missing module a NaN with its reason. Lost data connections are re-opened with
a bounded, logged backoff. Not responsible for: deciding whether the wind is off before a zero
calibration (the caller passes the wind speed it knows; the driver refuses a nonzero one), mapping
the device clock onto the host clock (the synchronisation layer does that from the counters, frame
times and host arrival times returned here), threads, or recording.

This module holds the driver (:class:`ScanivalveMps4264`). What needs none of its state has a
module of its own in this package: the settings
(:mod:`daq.instruments.scanivalve_mps4264.settings`), the packet layouts and the decoder
(:mod:`.frames`), one module's data stream (:mod:`.streams`), the merging of the modules' frames
into blocks (:mod:`.merge`) and the blocks returned (:mod:`.blocks`).

Longer than 600 lines: the driver is one state machine. Its command connection, its scan and
its per-module data connections share one lock, the scan state and the reconnect path (a
reconnect restarts the data connection under a running scan, ``scan()`` replaces the streams,
a CALZ needs the scan stopped), so they stay in one class, with the description of the
protocol below, which its methods cite.

Wire protocol (docs/reference/wire_formats.md, "Pressure scanner"; [unverified] marks our choices
where the facts stop):

- Commands are ASCII lines terminated by CR LF [unverified terminator; the simulator accepts CR,
  LF or both]. ``STATUS`` answers ``STATUS: <state>`` with a state of ``READY``, ``SCAN``,
  ``CALZ``, ``SAVE``, ``CALVAL`` or ``PGM`` (mps-protocol.h); an unknown or refused command
  answers ``INVALID COMMAND: <text>`` (the public MPS emulator). Other commands answer nothing
  when they succeed [unverified], so the driver follows every command with ``STATUS`` as a fence:
  an ``INVALID COMMAND`` line before the fence's ``STATUS:`` line is the command's refusal
  (:class:`~daq.errors.DeviceError`), and the fence's state confirms the command's effect.
- Commands used: ``SET FORMAT B B`` (binary frames to the TCP binary server, README "TCP BINARY
  SERVER DATA FORMATTING MATRIX"), ``SET UNITS PA`` (EU in Pa, units index 23, Appendix A),
  ``SET SIM 0x40`` (legacy 0x0A packet, which carries the external-trigger time) or ``SET SIM 0``
  (the model's own packet, 0x6D for the MPS4264), ``SET RATE <Hz>`` (frame rate [unverified
  syntax and range; the rate limit is configurable]), ``CALZ`` (quick zero, "under 10 seconds",
  status ``CALZ`` meanwhile), ``SCAN`` and ``STOP``.
- Binary frames come on a TCP connection to the scanner's binary server (port 503). Module ``k``
  (0-based) of a multi-module scanner serves its frames on port ``data_port + k`` of the command
  host [design: the 0x6D packet has no module field, so the connection identifies the module];
  every module sends one packet per frame with the same frame number (the master starts them
  together, ``MSCAN``).
  Packet layouts and their decoding: :mod:`daq.instruments.scanivalve_mps4264.frames`.
- Frame time is "a time relative to 0 (when PTP is disabled), or an absolute PTP time"; below
  1e9 s (before 2001) the driver reports the block's time base as ``"relative"`` (the epoch-0
  fault).

Batching [design]: :meth:`ScanivalveMps4264.read_block` does not return after every frame. Once a
frame is complete it keeps reading for at most ``min_block_s`` (default 20 ms, 10 frames at 500 Hz;
fewer if that many frames are complete sooner), then decodes the bytes of every module in one numpy
pass (:meth:`~daq.instruments.scanivalve_mps4264.frames.Mps4264Decoder.feed_many`) and returns every
complete frame in one block. A block costs a fixed ~0.2 ms of Python whatever its size; one block
per frame made the decoding most of a core at 8 modules x 500 Hz. The usual block, in which every
module sent the frames that follow the last block, the same ones, is built at once
(:meth:`ScanivalveMps4264._in_step_block`: one decode of all the modules' bytes and one
transposing copy, without holding and merging per module); anything else (a lost, late, duplicated
or split packet, garbage, a restart, a serial number or byte order to check) goes through the
modules' streams and the merger as before, with the same result.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Sequence
from types import TracebackType
from typing import Any
from urllib.parse import urlsplit

import numpy as np

from daq.errors import (
    ConfigError,
    DaqError,
    DeviceError,
    ProtocolError,
    SafetyError,
    TransportError,
    TransportTimeout,
)
from daq.instruments.entry import DriverEntry
from daq.instruments.reading import Reading
from daq.instruments.scanivalve_mps4264.blocks import (
    ScanBlock,
)
from daq.instruments.scanivalve_mps4264.continuity import ScanContinuity
from daq.instruments.scanivalve_mps4264.frames import (
    CHANNELS_PER_MODULE,
    PACKET_SIZES,
    TEMPERATURES_PER_MODULE,
    TYPE_LEGACY,
    Mps4264Decoder,
    PacketBatch,
)
from daq.instruments.scanivalve_mps4264.merge import FrameMerger
from daq.instruments.scanivalve_mps4264.settings import (
    MAX_RATE_HZ,
    Mps4264Settings,
)
from daq.instruments.scanivalve_mps4264.streams import (
    ModuleStream,
    continue_in_step,
    in_step,
)
from daq.transports.byte_transport import Transport, open_transport

__all__ = ["DRIVER", "ScanivalveMps4264"]

log = logging.getLogger(__name__)


#: Longest single wait on one data connection inside :meth:`ScanivalveMps4264.read_block`, s:
#: the other modules are polled at least this often.
_MAX_WAIT_S = 0.05


# ------------------------------------------------------------------------------------------------
# Driver
# ------------------------------------------------------------------------------------------------
class ScanivalveMps4264:
    """Driver of a Scanivalve MPS4264-class scanner (see the module docstring for the protocol).

    Parameters
    ----------
    transport : Transport
        The command connection (``tcp://host:port``), created but not opened.
    settings : Mps4264Settings
        Validated settings.
    data_transports : sequence of Transport, optional
        One data connection per module (tests inject scripted ones). Default: ``tcp://host:
        data_port + k`` on the command connection's host, created at :meth:`scan`.
    reconnect_attempts : int
        Attempts to re-open a lost data connection before :class:`TransportError`, >= 1.
    reconnect_backoff_s : float
        Delay before the first attempt, s; doubled at each further attempt.
    max_pending_frames : int
        Frames one module may hold while another lags; beyond, frames are emitted with the
        lagging module marked ``STATUS_MISSING`` (its later packets count as late frames).
    module_silence_s : float
        A module that sends nothing for this long (s) is no longer waited for: frames are
        emitted with it marked ``STATUS_MISSING``. A reconnect restarts its clock.

    Notes
    -----
    Commands (one lock) and :meth:`read_block` use different connections, so one thread may read
    while another commands (e.g. :meth:`stop`). The driver is not otherwise thread-safe.
    """

    def __init__(
        self, transport: Transport, settings: Mps4264Settings, *,
        data_transports: Sequence[Transport] | None = None, reconnect_attempts: int = 5,
        reconnect_backoff_s: float = 0.1, max_pending_frames: int = 4096,
        module_silence_s: float = 1.0,
    ) -> None:
        if not isinstance(settings, Mps4264Settings):
            raise TypeError(f"settings must be Mps4264Settings, got {type(settings).__name__}")
        if data_transports is not None and len(data_transports) != settings.modules:
            raise ValueError(f"data_transports: need {settings.modules} (one per module), "
                             f"got {len(data_transports)}")
        if (reconnect_attempts < 1 or reconnect_backoff_s < 0 or max_pending_frames < 1
                or not module_silence_s > 0):
            raise ValueError("reconnect_attempts >= 1, reconnect_backoff_s >= 0, "
                             "max_pending_frames >= 1 and module_silence_s > 0 are required")
        self.transport = transport
        self.settings = settings
        self._data_given = list(data_transports) if data_transports is not None else None
        self._attempts = int(reconnect_attempts)
        self._backoff_s = float(reconnect_backoff_s)
        self._max_pending = int(max_pending_frames)
        self._silence_s = float(module_silence_s)
        self._cmd_lock = threading.Lock()
        self._cmd_buf = bytearray()
        self._opened = False
        self._streams: list[ModuleStream] = []
        self._rate_hz = settings.rate_hz
        self._stats = dict.fromkeys(("reconnects", "late_frames", "forced_emissions"), 0)
        self._continuity = ScanContinuity()
        self._reset_run_state()

    # -- life cycle ----------------------------------------------------------------------------
    def open(self) -> None:
        """Connect the command connection and check that a scanner answers ``STATUS``."""
        if self._opened:
            return
        if not self.transport.is_open:
            self.transport.open()
        self._cmd_buf.clear()
        try:
            state = self.status()
        except DaqError:
            self.transport.close()
            raise
        self._opened = True
        log.info("%s: scanner %s", self.transport.url, state)

    def close(self) -> None:
        """Close every connection (sends nothing); idempotent."""
        self._opened = False
        for stream in self._streams:
            stream.transport.close()
        self.transport.close()

    def __enter__(self) -> ScanivalveMps4264:
        self.open()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    # -- description ---------------------------------------------------------------------------
    def describe(self) -> dict[str, dict[str, Any]]:
        """Channels of :meth:`read`: ``{name: {units, dtype, shape}}`` (shape of one frame).

        ``pressure`` (Pa, NaN where ``module_status`` is not OK), ``pitot`` (the Pitot
        channel's pressure, Pa), ``temperature`` (degC), ``trigger_time`` (the last external
        trigger on the frame-time base, s; NaN when none) and ``module_status`` (per module,
        ``STATUS_OK``, ``STATUS_MISSING`` or ``STATUS_VALVE_CAL``). The counter, frame time and
        host times are the reading's own fields.
        """
        m = self.settings.modules
        return {
            "pressure": {"units": "Pa", "dtype": "float64", "shape": (CHANNELS_PER_MODULE * m,)},
            "pitot": {"units": "Pa", "dtype": "float64", "shape": ()},
            "temperature": {"units": "degC", "dtype": "float64",
                            "shape": (TEMPERATURES_PER_MODULE * m,)},
            "trigger_time": {"units": "s", "dtype": "float64", "shape": ()},
            "module_status": {"units": "1", "dtype": "int8", "shape": (m,)},
        }

    @property
    def rate_hz(self) -> float:
        """Measure the frame rate the scanner was last set to (the settings' until then), Hz."""
        return self._rate_hz

    @property
    def serial_numbers(self) -> tuple[int | None, ...]:
        """Measure each module's serial number, from its legacy (0x0A) packets of this scan.

        None for a module that sent none yet (or only 0x6D packets, which carry none).
        """
        return tuple(stream.serial for stream in self._streams)

    @property
    def n_channels(self) -> int:
        """Measure the number of pressure channels (64 per module)."""
        return self.settings.n_channels

    @property
    def stats(self) -> dict[str, int]:
        """Measure the stream counters since :meth:`scan`.

        Packets decoded, bytes skipped, bad and unsupported packets, duplicates, late frames,
        byte-order mismatches, reconnects and forced emissions.
        """
        out = dict(self._stats)
        decoders = [s.decoder for s in self._streams]
        out["packets"] = sum(d.packets for d in decoders)
        out["bytes_skipped"] = sum(d.bytes_skipped for d in decoders)
        out["bad_packets"] = sum(d.bad_packets for d in decoders)
        out["unsupported_packets"] = sum(d.unsupported_packets for d in decoders)
        out["duplicates"] = sum(s.duplicates for s in self._streams)
        out["byte_order_mismatches"] = sum(s.order_mismatches for s in self._streams)
        return out

    # -- commands ------------------------------------------------------------------------------
    def status(self) -> str:
        """Return the scanner state (``READY``, ``SCAN``, ``CALZ``, ...), from ``STATUS``."""
        with self._cmd_lock:
            return self._fence()

    def set_rate(self, hz: float) -> None:
        """Set the frame rate with ``SET RATE <hz>`` ([unverified] syntax), Hz in (0, 2000]."""
        if isinstance(hz, bool) or not (isinstance(hz, (int, float)) and 0 < hz <= MAX_RATE_HZ):
            raise ValueError(f"frame rate must be in (0, {MAX_RATE_HZ:g}] Hz, got {hz!r}")
        self._command(f"SET RATE {float(hz):g}")
        self._rate_hz = float(hz)

    def set_format(self, packet: str = "legacy") -> None:
        """Select binary frames on the TCP server, in Pa, as ``packet`` type.

        Parameters
        ----------
        packet : {"legacy", "eu"}
            ``"legacy"``: the 348-byte 0x0A packet (``SET SIM 0x40``), which carries the
            external-trigger time the synchronisation needs; ``"eu"``: the MPS4264's own
            304-byte 0x6D packet (``SET SIM 0``).
        """
        if packet not in ("legacy", "eu"):
            raise ValueError(f"packet must be 'legacy' or 'eu', got {packet!r}")
        self._command("SET FORMAT B B")
        self._command("SET UNITS PA")
        self._command("SET SIM 0x40" if packet == "legacy" else "SET SIM 0")

    def configure(self, packet: str = "legacy") -> None:
        """Apply the settings: :meth:`set_format` (``packet``) then :meth:`set_rate`."""
        self.set_format(packet)
        self.set_rate(self.settings.rate_hz)

    def check_calz_allowed(self, *, wind_speed_now: float) -> None:
        """Refuse a zero calibration unless the wind is known to be off (no I/O).

        The one wind-off rule of :meth:`calz`, callable on its own so that a caller can refuse
        before it interrupts anything (the acquisition engine stops the scan for a CALZ only
        once this has passed; :meth:`calz` checks again).

        Parameters
        ----------
        wind_speed_now : float
            Current wind speed, m/s. Anything but exactly 0 is refused, NaN (unknown) too.

        Raises
        ------
        SafetyError
            ``wind_speed_now`` is not 0.
        """
        if not wind_speed_now == 0.0:  # NaN compares unequal too: an unknown wind is refused
            raise SafetyError(
                f"{self.transport.url}: refusing CALZ with wind speed {wind_speed_now!r} m/s: "
                "a zero taken wind-on bakes the wind's pressures into every channel's offset"
            )

    def calz(self, *, wind_speed_now: float, timeout_s: float = 30.0,
             poll_s: float = 0.1) -> float:
        """Zero the sensors (``CALZ``) and wait until the scanner is ``READY`` again.

        The MPS4232/4264 have no calibration valve: the zero is taken with the taps exposed, so
        it must be taken wind-off (docs/reference/wire_formats.md, "Pressure scanner"). Deciding
        that the wind is off is the caller's job; it passes the wind speed it knows
        (:meth:`check_calz_allowed`). The scanner refuses CALZ while it scans: :meth:`stop`
        first (:meth:`daq.acquisition.engine.Acquisition.calz` does that during a run).

        Parameters
        ----------
        wind_speed_now : float
            Current wind speed, m/s. Anything but exactly 0 is refused, NaN (unknown) too.
        timeout_s : float
            Longest wait for ``READY`` after ``CALZ``, s (the manual: "under 10 seconds").
        poll_s : float
            Interval between ``STATUS`` polls, s.

        Returns
        -------
        float
            Time from sending ``CALZ`` to seeing ``READY``, s.

        Raises
        ------
        SafetyError
            ``wind_speed_now`` is not 0: nothing is sent.
        DeviceError
            ``CALZ`` refused, or the scanner still busy after ``timeout_s``.
        """
        self.check_calz_allowed(wind_speed_now=wind_speed_now)
        start = time.monotonic()
        state = self._command("CALZ")
        deadline = time.monotonic() + timeout_s  # the wait for READY, after the command
        while state != "READY":
            if state != "CALZ":
                raise DeviceError(f"{self.transport.url}: unexpected state {state!r} during CALZ")
            if time.monotonic() >= deadline:
                raise DeviceError(f"{self.transport.url}: CALZ not finished after {timeout_s:g} s")
            time.sleep(poll_s)
            state = self.status()
        return time.monotonic() - start

    def start(self) -> None:
        """Begin a fresh stream: :meth:`configure`, then :meth:`scan` (the engine's start)."""
        self._continuity = ScanContinuity()
        self.configure()
        self.scan()

    def scan(self, *, after_pause: bool = False) -> None:
        """Start scanning: fresh data connections, reset stream state, then ``SCAN``.

        :meth:`read` continues the counters (and relative frame times) of a new scan after
        those it delivered, behind a ``"restart"`` gap
        (:class:`~daq.instruments.scanivalve_mps4264.continuity.ScanContinuity`).

        Parameters
        ----------
        after_pause : bool
            The scan stood still for a pause of the caller's (STOP, CALZ, SCAN): the gap is
            measured from the frame times (and :meth:`note_pause`). Marked before ``SCAN`` is
            sent, so that a recovery's scan after a failed one is measured the same way.
        """
        self._continuity.restarted(measure=after_pause)
        with self._cmd_lock:
            for stream in self._streams:
                stream.transport.close()
            now = time.monotonic()
            self._streams = [ModuleStream(k, t, now)
                             for k, t in enumerate(self._data_transports())]
            self._reset_run_state()
            for stream in self._streams:
                stream.transport.open()
            state = self._command_locked("SCAN")
        if state != "SCAN":
            raise DeviceError(f"{self.transport.url}: state {state!r} after SCAN (expected SCAN)")

    def stop(self) -> None:
        """Stop scanning (``STOP``); frames already sent stay readable with :meth:`read_block`."""
        state = self._command("STOP")
        if state != "READY":
            raise DeviceError(f"{self.transport.url}: state {state!r} after STOP")

    def note_pause(self, pause_s: float) -> None:
        """Tell how long the scan stood still in the last pause, s (host-measured, STOP to SCAN).

        Without PTP the new scan's frame times are continued with it (see :meth:`scan`).
        """
        self._continuity.note_pause(pause_s)

    def recover(self, error: BaseException) -> None:
        """Start a new scan on fresh connections after a lasting TransportError.

        Anything else (a timeout, a protocol error) needs no recovery: the next read goes on.
        """
        # read_block retried its data connections already: they stayed away. Start afresh.
        if isinstance(error, TransportError) and not isinstance(error, TransportTimeout):
            log.warning("scanner: restarting the scan after: %s", error)
            self.close()
            self.open()
            self.configure()
            self.scan()

    def recent_pressure_mean(self) -> tuple[np.ndarray[Any, np.dtype[np.float64]], int]:
        """Mean pressure per channel over the last 0.5 s of frames read, Pa, and their number.

        NaN rows (a missing module) are left out per channel; before any frame: empty, 0.
        """
        return self._continuity.recent_pressure_mean(self._rate_hz)

    def _data_transports(self) -> list[Transport]:
        if self._data_given is not None:
            return self._data_given
        host = urlsplit(self.transport.url).hostname
        if not host:
            raise ConfigError(f"{self.transport.url}: no host to reach the data ports at; "
                              "pass data_transports")
        return [open_transport(f"tcp://{host}:{self.settings.data_port + k}")
                for k in range(self.settings.modules)]

    def _command(self, text: str) -> str:
        with self._cmd_lock:
            return self._command_locked(text)

    def _command_locked(self, text: str) -> str:
        self.transport.write(text.encode("ascii") + b"\r\n")
        return self._fence(text)

    def _fence(self, after: str | None = None) -> str:
        """Send ``STATUS``; return its state; an ``INVALID COMMAND`` line before it is raised."""
        self.transport.write(b"STATUS\r\n")
        deadline = time.monotonic() + self.settings.command_timeout_s
        refusal: str | None = None
        while True:
            line = self._read_line(deadline)
            upper = line.upper()
            if upper.startswith("INVALID COMMAND"):
                refusal = line
            elif upper.startswith("STATUS:"):
                state = upper.split(":", 1)[1].strip()
                if refusal is not None:
                    what = after if after is not None else "STATUS"
                    raise DeviceError(f"{self.transport.url}: {what!r} refused: {refusal!r}")
                if not state:
                    raise ProtocolError(f"{self.transport.url}: empty state in {line!r}")
                return state
            elif line:
                log.debug("%s: ignored reply line %r", self.transport.url, line)

    def _read_line(self, deadline: float) -> str:
        """One reply line (terminated by CR, LF or CR LF), without its terminator."""
        buf = self._cmd_buf
        while True:
            cut = min((i for i in (buf.find(b"\r"), buf.find(b"\n")) if i >= 0), default=-1)
            if cut >= 0:
                raw = bytes(buf[:cut])
                del buf[:cut + 1]
                return raw.decode("ascii", errors="replace").strip()
            if len(buf) > 4096:
                raise ProtocolError(f"{self.transport.url}: no line end within 4096 bytes: "
                                    f"{bytes(buf[:64]).hex(' ')} ...")
            try:  # a timeout names the command's, not the last read's remaining slice
                if (remaining := deadline - time.monotonic()) <= 0:
                    raise TransportTimeout("past the command's deadline")
                buf += self.transport.read(4096, remaining)
            except TransportTimeout as exc:
                raise TransportTimeout(f"{self.transport.url}: no reply line within "
                                       f"{self.settings.command_timeout_s:g} s (received "
                                       f"{bytes(buf)!r})") from exc

    # -- data ------------------------------------------------------------------------------------
    def _reset_run_state(self) -> None:
        self._merger = FrameMerger(self.settings.modules, self.settings.pitot_channel,
                                   self._rate_hz)
        for key in self._stats:
            self._stats[key] = 0

    def read(self, timeout_s: float | None = None) -> Reading:
        """Return the frames that arrived as one reading of the stream (at least one frame).

        :meth:`read_block`'s frames, their counters and frame times continued across the
        scans of this stream (see :meth:`scan`): channels as :meth:`describe`, the counter,
        the frame time as device time (s), ``info["time_base"]`` and ``info["clock_steps"]``.
        Raises as :meth:`read_block`.
        """
        return self._continuity.reading(self.read_block(timeout_s), self._rate_hz)

    def drain(self, timeout_s: float) -> list[Reading]:
        """Read the frames still in flight after STOP, until ``timeout_s`` (s) of silence."""
        out: list[Reading] = []
        while True:
            try:
                out.append(self.read(timeout_s))
            except TransportTimeout:
                return out

    def read_block(self, timeout_s: float | None = None) -> ScanBlock:
        """Return the frames that arrived, merged over modules (at least one frame).

        Batching: once a frame is complete (every module sent it or a later one, or is silent),
        the read keeps collecting for at most ``min_block_s`` (settings) and then returns every
        complete frame in one block; it returns as soon as ``ceil(min_block_s * rate_hz)``
        frames are complete (so a backlog comes out at once). Frames still waiting for a
        lagging module stay for a later block (see ``max_pending_frames`` and
        ``module_silence_s``). A block is never held past ``timeout_s``.

        Parameters
        ----------
        timeout_s : float, optional
            Longest wait for a complete frame, s (default: ``command_timeout_s``). Without one
            by then, the frames held for a module that stayed silent are returned (marked
            missing there); with none held, TransportTimeout.

        Raises
        ------
        TransportTimeout
            No frame completed within ``timeout_s``.
        TransportError
            A data connection was lost and stayed away after the bounded reconnects.
        """
        if not self._streams:
            raise TransportError(f"{self.transport.url}: no data connections: call scan() first")
        timeout = self.settings.command_timeout_s if timeout_s is None else float(timeout_s)
        streams = self._streams
        deadline = time.monotonic() + timeout
        block_end: float | None = None  # set when the first frame is (very likely) complete
        while True:
            now = time.monotonic()
            waiting = [s for s in streams if not self._is_silent(s, now)] or streams
            laggard = min(waiting, key=ModuleStream.frames_ahead)
            for stream in streams:
                if stream is not laggard:
                    self._pump(stream, 0.0)
            until = deadline if block_end is None else block_end
            self._pump(laggard, min(max(until - time.monotonic(), 0.0), _MAX_WAIT_S))
            now = time.monotonic()
            # Bytes are decoded only when a block is due: the estimates count whole packets.
            if block_end is None and self._likely_complete(now, 1):
                block_end = min(now + self.settings.min_block_s, deadline)
            if block_end is not None and (now >= block_end
                                          or self._likely_complete(now, self._block_frames())):
                block = self._in_step_block()
                if block is None:
                    self._decode_all()
                    block = self._emit()
                if block is not None:
                    return block
                block_end = None  # no complete frame after all (garbage, late or duplicates)
            if now >= deadline:
                # Frames held back for a module that stayed silent for the whole timeout (e.g.
                # its last frames were dropped before STOP): emit them, marked missing there.
                self._decode_all()
                block = self._emit(flush=True)
                if block is not None:
                    return block
                raise TransportTimeout(f"{self.transport.url}: no complete frame within "
                                       f"{timeout:g} s")

    def _block_frames(self) -> int:
        """Complete frames that end the collection early: ``min_block_s`` worth, >= 1."""
        return max(1, math.ceil(self.settings.min_block_s * self._rate_hz - 1e-6))

    def _is_silent(self, stream: ModuleStream, now: float) -> bool:
        """Whether a module holds nothing and sent nothing for ``module_silence_s``."""
        return (not stream.n_pending and not stream.raw_bytes
                and now - stream.last_arrival >= self._silence_s)

    def _likely_complete(self, now: float, n: int) -> bool:
        """Whether at least ``n`` frames are probably complete, from counts of whole packets.

        An estimate (duplicates, late frames or garbage may make it wrong), used only to decide
        when to decode; :meth:`_emit` decides what is complete. Also true when a module holds
        more than ``max_pending_frames`` (its frames are then emitted without the laggards).
        """
        ahead = [s.frames_ahead() for s in self._streams]
        if max(ahead) > self._max_pending:
            return True
        waiting = [a for s, a in zip(self._streams, ahead, strict=True)
                   if not self._is_silent(s, now)]
        return bool(waiting) and min(waiting) >= n

    def _pump(self, stream: ModuleStream, wait_s: float) -> None:
        """Read what one data connection has (waiting at most ``wait_s`` for the first bytes).

        The bytes are stashed with the time of their read, not decoded (:meth:`_decode_all`).
        """
        for _ in range(64):  # bounded: at most 4 MiB per call, then let the others speak
            try:
                data = stream.transport.read(1 << 16, wait_s)
            except TransportTimeout:
                return
            except TransportError as exc:
                self._reconnect(stream, exc)
                return
            host_ns = time.monotonic_ns()
            stream.last_arrival = host_ns * 1e-9
            stream.stash(data, host_ns)
            wait_s = 0.0

    def _decode_all(self, streams: Sequence[ModuleStream] | None = None) -> None:
        """Decode the stashed bytes of ``streams`` (default: all) and hold their frames."""
        todo = [s for s in (self._streams if streams is None else streams) if s.raw]
        if not todo:
            return
        chunks = [s.take_raw() for s in todo]
        self._hold(todo, Mps4264Decoder.feed_many([s.decoder for s in todo], chunks))

    def _hold(self, todo: Sequence[ModuleStream],
              decoded: Sequence[tuple[PacketBatch, np.ndarray[Any, np.dtype[np.int64]]]],
              ) -> None:
        """Check and hold each stream's decoded packets (``decoded``: batch, packet ends)."""
        for stream, (batch, ends) in zip(todo, decoded, strict=True):
            hosts = stream.arrival_times(ends)
            if len(batch):
                stream.packet_size = PACKET_SIZES[int(batch.kind[-1])]
                self._check_packets(stream, batch)
                stream.ingest(batch, hosts)

    def _in_step_block(self) -> ScanBlock | None:
        """Return the usual block at once: every module sent the next frames, the same ones.

        One decode of all the modules' bytes, no per-module holding, one assembly: the block
        :meth:`_decode_all` and :meth:`_emit` would return, and the same state left behind.
        None otherwise, with the bytes decoded and held as :meth:`_decode_all` does (the
        general path then goes on).
        """
        streams = self._streams
        if not in_step(streams, self._merger.last_key):
            return None
        chunks = [s.take_raw() for s in streams]
        decoders = [s.decoder for s in streams]
        joined = Mps4264Decoder.feed_in_step(decoders, chunks)
        if joined is None:
            self._hold(streams, Mps4264Decoder.feed_many(decoders, chunks))
            return None
        batch, ends = joined
        m, n = ends.shape
        frames = batch.frame.reshape(m, n)
        kind = int(batch.kind[0])
        rate = float(batch.rate_hz[-1])
        # Only the common case here, where _check_packets would count, warn of and choose
        # nothing but the last packet's rate: else each stream goes through it. (0x6D packets
        # carry no serial number: -1.)
        known = [s.serial for s in streams]
        usual = (bool(batch.big_endian[0]) == (self.settings.byte_order == "big")
                 and ((rate > 0 and math.isfinite(rate)) or bool(np.isnan(batch.rate_hz).all()))
                 and (kind != TYPE_LEGACY
                      or (None not in known and bool((batch.serial.reshape(m, n)
                                                      == np.array(known)[:, None]).all()))))
        keys = continue_in_step(streams, frames) if usual else None
        if keys is None:
            self._hold(streams, [(batch.take(slice(k * n, (k + 1) * n)), ends[k])
                                 for k in range(m)])
            return None
        host = streams[0].arrival_times(ends[0])
        for k in range(1, m):
            np.maximum(host, streams[k].arrival_times(ends[k]), out=host)
        if rate > 0 and math.isfinite(rate):
            self._rate_hz = rate
        size = PACKET_SIZES[kind]
        for s in streams:
            s.packet_size = size
            s.silent = False
        self._merger.rate_hz = self._rate_hz
        return self._merger.assemble_in_step(keys, batch, host)

    def _check_packets(self, stream: ModuleStream, batch: PacketBatch) -> None:
        expected = self.settings.byte_order == "big"
        big = int(np.count_nonzero(batch.big_endian))
        mismatched = len(batch) - big if expected else big
        if mismatched:
            if stream.order_mismatches == 0:
                log.warning("module %d sends %s-endian packets but byte_order = %r: decoding "
                            "with the detected order (fix the rig config)", stream.index,
                            "little" if expected else "big", self.settings.byte_order)
            stream.order_mismatches += mismatched
        serial = batch.serial
        lo, hi = int(serial.min()), int(serial.max())
        if hi >= 0 and not lo == hi == stream.serial:  # else: no legacy packet, or no change
            serials = serial[serial >= 0]
            if stream.serial is None:
                stream.serial = int(serials[0])
            if np.any(serials != stream.serial):
                log.warning("module %d: serial number changed from %d to %s", stream.index,
                            stream.serial, sorted(set(serials.tolist())))
                stream.serial = int(serials[-1])
        rate = float(batch.rate_hz[-1])
        if rate > 0 and math.isfinite(rate):  # the last packet's rate is the one kept
            self._rate_hz = rate
        else:
            rates = batch.rate_hz[np.isfinite(batch.rate_hz) & (batch.rate_hz > 0)]
            if rates.size:
                self._rate_hz = float(rates[-1])

    def _reconnect(self, stream: ModuleStream, cause: TransportError) -> None:
        log.warning("module %d: data connection lost (%s); reconnecting", stream.index, cause)
        stream.transport.close()
        self._decode_all([stream])  # what the old connection delivered
        discarded = stream.decoder.reset()
        if discarded:
            log.warning("module %d: %d bytes of a partial packet discarded", stream.index,
                        discarded)
        last: TransportError = cause
        for attempt in range(1, self._attempts + 1):
            time.sleep(self._backoff_s * 2 ** (attempt - 1))
            try:
                stream.transport.open()
            except TransportError as exc:
                last = exc
                log.warning("module %d: reconnect attempt %d of %d failed: %s", stream.index,
                            attempt, self._attempts, exc)
                continue
            self._stats["reconnects"] += 1
            stream.last_arrival = time.monotonic()
            log.info("module %d: data connection re-opened (attempt %d)", stream.index, attempt)
            return
        raise TransportError(f"{self.transport.url}: module {stream.index} data connection "
                             f"stayed away after {self._attempts} attempts") from last

    def _emit(self, flush: bool = False) -> ScanBlock | None:
        """Merge and return the frames every module has answered for (or is silent about).

        A frame number is complete when every module has sent it or a later one. A module that
        sent nothing for ``module_silence_s`` (and holds nothing) is not waited for: its
        columns are marked missing. ``flush`` emits everything held (the read timed out).
        """
        streams = self._streams
        last = -1 if self._merger.last_key is None else self._merger.last_key
        for s in streams:
            late = s.drop_upto(last)
            if late:
                self._stats["late_frames"] += late
                log.warning("module %d: %d late frames discarded (already emitted as missing)",
                            s.index, late)
        if flush:
            limit = max((s.watermark for s in streams if s.keys), default=-1)
        else:
            now = time.monotonic()
            waiting = []
            for s in streams:
                silent = not s.keys and now - s.last_arrival >= self._silence_s
                if silent and not s.silent:
                    log.warning("module %d silent for %.1f s: its frames are marked missing",
                                s.index, now - s.last_arrival)
                s.silent = silent
                if not silent:
                    waiting.append(s)
            limit = min((s.watermark for s in waiting), default=-1)
            for s in streams:  # bound what a lagging module can hold back
                n = s.n_pending
                if n > self._max_pending:
                    forced = int(np.concatenate(s.keys)[n - self._max_pending - 1])
                    if forced > limit:
                        limit = forced
                        log.warning("module %d holds %d frames: emitting without the "
                                    "modules that lag", s.index, n)
        if limit <= last:
            return None
        if flush or limit > min(s.watermark for s in streams):
            self._stats["forced_emissions"] += 1
        self._merger.rate_hz = self._rate_hz
        return self._merger.merge([s.take_upto(limit) for s in streams])


def _factory(transport: Transport, settings: Mps4264Settings) -> ScanivalveMps4264:
    return ScanivalveMps4264(transport, settings)


#: This driver's registry entry (collected by :mod:`daq.instruments.registry`).
DRIVER = DriverEntry(name="scanivalve_mps4264", role="scanner", factory=_factory,
                    validate=Mps4264Settings.from_table)
