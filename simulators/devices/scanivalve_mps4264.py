"""Simulated Scanivalve MPS4264-class pressure scanner: ASCII command and binary TCP servers.

Responsibility: speak the scanner's wire protocol on 127.0.0.1 (``docs/wire_formats.md``, "Pressure
scanner") from the virtual tunnel's pressures: a TCP command server answering ASCII commands, and
one TCP binary data server per 64-channel module (module ``k`` on port ``data_port + k``, our
[design] for several modules, since the 0x6D packet carries no module field); frames at the
commanded rate on the device's own clock (offset, drift), with seeded noise, sensor zero offsets and
their CALZ, the external-trigger time of the tunnel's trigger line, both byte orders, a bounded
frame buffer that drops frames when the client stalls, and fault injection. It keeps truth counters
(frames produced, sent, dropped with the reason) so tests can prove that no frame was lost that the
simulator did not drop. Not responsible for: UDP/FTP outputs, ASCII/CSV/LabVIEW scan formats, RAW
packets, or anything of the driver (this module imports nothing from ``daq``: the packets are
encoded here from the manual facts, independently of the driver's decoder).

Commands (CR, LF or CR LF terminated, case-insensitive; replies end with CR LF [unverified]):
``STATUS`` -> ``STATUS: READY|SCAN|CALZ``; ``SCAN``; ``STOP``; ``CALZ`` (status ``CALZ`` for
``calz_duration_s``); ``SET RATE <Hz>`` [unverified syntax]; ``SET FORMAT B B`` (binary frames to
the TCP binary server: the only format modelled; the power-up format is ASCII, so ``SCAN`` is
refused until it is set [design]); ``SET SIM 0`` (the MPS4264's own 0x6D packet) or
``SET SIM 0x40`` (the legacy 0x0A packet); ``SET UNITS PSI|KPA|PA``. Successful commands other
than ``STATUS`` answer nothing [unverified]; unknown, malformed or refused ones (e.g. anything
but ``STOP`` while scanning, anything while zeroing) answer ``INVALID COMMAND: <text>`` (the public
MPS emulator's reply). The frame counter starts at 1 at every scan start.

Faults (:meth:`SimScanivalveMps4264.inject`): ``drop_frames`` (counter gaps), buffer overrun (a
client that stalls beyond ``buffer_frames`` frames), ``ptp_absent`` (frame times from epoch 0 at
the scan start), ``ptp_lock`` (a step of the frame time), drift (the :class:`DeviceClock`),
CALZ with the wind on (no injection needed: the zero then holds the wind's pressures, an offset
error on every tap), ``invalid_command``, and ``tcp_reset`` (the data connections are reset with
an RST mid-scan and the scan restarts with the counter from 1).

Longer than 600 lines: the instrument's whole command set (ASCII commands and their
replies, settings, calibration, the binary frame stream and its faults) is one state machine
over one device state; split, each part would reach into the others' state.
"""

from __future__ import annotations

import math
import select
import socket
import struct
import threading
import time
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any

import numpy as np
import numpy.typing as npt

from simulators.clock import DeviceClock
from simulators.noise import KeyedNoise, key_from
from simulators.virtual_tunnel import VirtualTunnel

__all__ = ["FAULTS", "FrameRuns", "SimScanivalveMps4264", "SimTruth"]

#: Faults :meth:`SimScanivalveMps4264.inject` accepts.
FAULTS = ("drop_frames", "tcp_reset", "ptp_absent", "ptp_lock", "invalid_command")

_CHANNELS = 64  # pressure channels per module (mps-protocol.h)
_TEMPS = 8  # temperature channels per module
_PSI_PA = 6894.75977  # Pa per psi: the PA factor of the units table (mps-protocol.h)
#: SET UNITS name -> (Appendix A unit index, conversion factor from psi).
_UNITS = {"PSI": (0, 1.0), "KPA": (14, _PSI_PA / 1000.0), "PA": (23, _PSI_PA)}
_TYPE_EU64, _SIZE_EU64 = 0x6D, 304
_TYPE_LEGACY, _SIZE_LEGACY = 0x0A, 348
_NS = 1_000_000_000
_MAX_BATCH = 2000  # frames produced per generator step at most (catch-up after a stall)
_SEND_BATCH = 256  # frames handed to one send() loop at most


def _words_eu(frame: npt.NDArray[np.int64], t_ns: npt.NDArray[np.int64],
              temps: npt.NDArray[np.float32], press: npt.NDArray[np.float32]
              ) -> npt.NDArray[np.uint32]:
    """MPS-4264 EU packet (type 0x6D, 304 bytes) as 76 words per row (mps-protocol.h)."""
    words = np.empty((frame.size, _SIZE_EU64 // 4), np.uint32)
    words[:, 0] = _TYPE_EU64
    words[:, 1] = frame % (1 << 32)
    words[:, 2] = t_ns // _NS
    words[:, 3] = t_ns % _NS
    words[:, 4:12] = temps.view(np.uint32)
    words[:, 12:76] = press.view(np.uint32)
    return words


def _words_legacy(frame: npt.NDArray[np.int64], t_ns: npt.NDArray[np.int64],
                  temps: npt.NDArray[np.float32], press: npt.NDArray[np.float32], *,
                  serial: int, rate_hz: float, unit_index: int, conversion: float,
                  start_ns: int, ext_rel_ns: npt.NDArray[np.int64]) -> npt.NDArray[np.uint32]:
    """Legacy 64-channel packet (type 0x0A, 348 bytes) as 87 words per row (mps-protocol.h).

    ``ext_rel_ns`` < 0 means no external trigger yet: every trigger field is 0.
    """
    n = frame.size
    words = np.zeros((n, _SIZE_LEGACY // 4), np.uint32)
    words[:, 0] = _TYPE_LEGACY
    words[:, 1] = _SIZE_LEGACY
    words[:, 2] = frame % (1 << 32)
    words[:, 3] = np.uint32(serial)
    words[:, 4] = np.float32(rate_hz).view(np.uint32)
    words[:, 5] = 0  # valve_status 0 = Px (the MPS4264 has no calibration valve)
    words[:, 6] = unit_index
    words[:, 7] = np.float32(conversion).view(np.uint32)
    words[:, 8] = start_ns // _NS
    words[:, 9] = start_ns % _NS
    has = ext_rel_ns >= 0
    rel = np.where(has, ext_rel_ns, 0)
    words[:, 10] = (rel // 1000) % (1 << 32)  # ext_trigger_time_us
    words[:, 11:19] = temps.view(np.uint32)
    words[:, 19:83] = press.view(np.uint32)
    words[:, 83] = t_ns // _NS
    words[:, 84] = t_ns % _NS
    words[:, 85] = rel // _NS
    words[:, 86] = rel % _NS
    return words


class FrameRuns:
    """Frame counters kept as runs ``[scan id, first, last]``: constant memory while gapless."""

    def __init__(self) -> None:
        self.runs: list[list[int]] = []

    def add(self, scan_id: int, counter: int) -> None:
        """Record one frame."""
        if self.runs and self.runs[-1][0] == scan_id and self.runs[-1][2] + 1 == counter:
            self.runs[-1][2] = counter
        else:
            self.runs.append([scan_id, counter, counter])

    def counters(self, scan_id: int) -> npt.NDArray[np.int64]:
        """Counters recorded for ``scan_id``, in the order recorded."""
        parts = [np.arange(first, last + 1) for s, first, last in self.runs if s == scan_id]
        return np.concatenate(parts).astype(np.int64) if parts else np.zeros(0, np.int64)

    def __len__(self) -> int:
        return sum(last - first + 1 for _, first, last in self.runs)


@dataclass
class SimTruth:
    """What the simulator did, per module: frames produced, sent and dropped.

    A scan id starts at 1 with the first ``SCAN`` and increases at every ``SCAN`` and at every
    restart after a ``tcp_reset``. ``produced`` and ``sent`` (bytes handed to the client's
    connection) are :class:`FrameRuns`; ``dropped`` holds ``(scan id, counter, reason)`` with
    reasons ``"fault"`` (``drop_frames``), ``"overrun"`` (buffer full), ``"reset"`` (lost in a
    TCP reset) and ``"superseded"`` (unsent at the next ``SCAN``). ``calz_wind_speeds`` lists
    the wind speed (m/s) at every CALZ.
    """

    produced: list[FrameRuns] = field(default_factory=list)
    sent: list[FrameRuns] = field(default_factory=list)
    dropped: list[list[tuple[int, int, str]]] = field(default_factory=list)
    calz_wind_speeds: list[float] = field(default_factory=list)

    def sent_counters(self, module: int, scan_id: int) -> npt.NDArray[np.int64]:
        """Counters of the frames of ``scan_id`` whose bytes went to a client, in order."""
        return self.sent[module].counters(scan_id)

    def dropped_counters(self, module: int, scan_id: int,
                         reason: str | None = None) -> npt.NDArray[np.int64]:
        """Counters of the frames of ``scan_id`` dropped (for ``reason``, or any), sorted."""
        return np.array(sorted(c for s, c, r in self.dropped[module]
                               if s == scan_id and (reason is None or r == reason)), np.int64)


@dataclass
class _Entry:
    scan_id: int
    counter: int
    data: bytes


class SimScanivalveMps4264:
    """A simulated MPS4264-class scanner serving the real wire protocol on 127.0.0.1.

    Parameters
    ----------
    tunnel : VirtualTunnel
        Physical truth: taps on global channels ``0 .. n_taps - 1`` (the tunnel's tap order), or
        on ``tap_channels``, the Pitot dynamic pressure on ``pitot_channel``; other channels
        read 0 Pa plus noise.
    modules : int
        64-channel modules, 1..8.
    pitot_channel : int
        Global channel of the Pitot, not a tap channel, ``< 64 * modules``.
    tap_channels : sequence of int, optional
        Global channel (``64 * module + channel``) of each tap, in the tunnel's tap order
        (the rig config's ``[taps] channels``); default ``0 .. n_taps - 1``.
    pitot_error : tuple
        ``(factor, offset_pa)`` or ``(factor table, offset_pa, fan_rpm table)``: the Pitot
        reads ``(qd - offset_pa) / factor`` (the factor interpolated on the tunnel's fan
        speed), the inverse of the rig config's ``[tunnel.pitot]``; default ``(1.0, 0.0)``.
    rate_hz : float
        Frame rate at power-up, Hz (``SET RATE`` changes it; public emulators default to 10).
    max_rate_hz : float
        Highest rate ``SET RATE`` accepts, Hz ([unverified] in the manual: a parameter).
    byte_order : {"big", "little"}
        Byte order of every packet word.
    noise_pa : float
        Standard deviation of the measurement noise, Pa.
    sensor_offset_pa : float
        Standard deviation of the sensors' zero offsets before a CALZ, Pa.
    temperature_noise_c : float
        Standard deviation of the module temperatures' noise, K.
    calz_duration_s : float
        Time a CALZ keeps the status ``CALZ``, s (the real one: "under 10 seconds").
    buffer_frames : int
        Frames buffered per module while the client does not read (the MPS4232 holds 32768 and
        advises 16384 as the target; a frame that finds the buffer full is dropped: ``overrun``).
    send_buffer_bytes : int, optional
        ``SO_SNDBUF`` of data connections (small values make a stall overrun sooner).
    ptp : bool
        PTP locked: frame times are absolute (``ptp_epoch_s`` + device clock); False: relative
        to the scan start, from epoch 0 (``docs/wire_formats.md``, "Pressure scanner", on the
        scan start and the frame time's epoch).
    ptp_epoch_s : int
        PTP (TAI/UTC) seconds at true time 0 of the tunnel clock.
    serial_number : int
        Serial number of module 0 (module ``k`` has ``serial_number + k``; legacy packets).
    clock : DeviceClock, optional
        The scanner's clock against the tunnel's true time (offset, drift).
    rng : numpy.random.Generator or int, optional
        Noise source or its seed.
    """

    def __init__(
        self, tunnel: VirtualTunnel, *, modules: int = 1, pitot_channel: int = 63,
        tap_channels: Sequence[int] | None = None, pitot_error: tuple[Any, ...] = (1.0, 0.0),
        rate_hz: float = 10.0, max_rate_hz: float = 2000.0, byte_order: str = "big",
        noise_pa: float = 1.0, sensor_offset_pa: float = 10.0, temperature_noise_c: float = 0.02,
        calz_duration_s: float = 0.2, buffer_frames: int = 16384,
        send_buffer_bytes: int | None = None, ptp: bool = True,
        ptp_epoch_s: int = 1_767_225_600, serial_number: int = 4264001,
        clock: DeviceClock | None = None, rng: np.random.Generator | int | None = None,
    ) -> None:
        if not (isinstance(modules, int) and 1 <= modules <= 8):
            raise ValueError(f"modules must be an integer in [1, 8], got {modules!r}")
        n_taps = tunnel.taps.n_taps
        if n_taps > _CHANNELS * modules:
            raise ValueError(f"{n_taps} taps do not fit in {modules} module(s) of 64 channels")
        channels = list(range(n_taps)) if tap_channels is None else [int(c) for c in tap_channels]
        if tap_channels is None and not n_taps <= pitot_channel < _CHANNELS * modules:
            raise ValueError(f"pitot_channel must be in [{n_taps}, {_CHANNELS * modules - 1}] "
                             f"(after the {n_taps} taps), got {pitot_channel!r}")
        if len(channels) != n_taps or len(set(channels) | {pitot_channel}) != n_taps + 1 or \
                not all(0 <= c < _CHANNELS * modules for c in [*channels, pitot_channel]):
            raise ValueError(f"tap_channels must be {n_taps} distinct channels in "
                             f"[0, {_CHANNELS * modules - 1}] besides pitot_channel = "
                             f"{pitot_channel}, got {tap_channels!r}")
        self.tap_channels = np.asarray(channels, dtype=np.intp)
        self.pitot_error = tuple(pitot_error)
        if not 0 < rate_hz <= max_rate_hz:
            raise ValueError(f"rate_hz must be in (0, {max_rate_hz}], got {rate_hz!r}")
        if byte_order not in ("big", "little"):
            raise ValueError(f"byte_order must be 'big' or 'little', got {byte_order!r}")
        if buffer_frames < 1 or calz_duration_s < 0 or noise_pa < 0:
            raise ValueError("buffer_frames >= 1, calz_duration_s >= 0, noise_pa >= 0 required")
        self.tunnel = tunnel
        self.modules = modules
        self.pitot_channel = pitot_channel
        self.max_rate_hz = float(max_rate_hz)
        self.byte_order = byte_order
        self.noise_pa = float(noise_pa)
        self.temperature_noise_c = float(temperature_noise_c)
        self.calz_duration_s = float(calz_duration_s)
        self.buffer_frames = int(buffer_frames)
        self.send_buffer_bytes = send_buffer_bytes
        self.ptp_epoch_s = int(ptp_epoch_s)
        self.serial_number = int(serial_number)
        self.clock = clock if clock is not None else DeviceClock()
        self._rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        n_ch = _CHANNELS * modules
        self._sensor_offset = self._rng.normal(0.0, sensor_offset_pa, n_ch)
        # Pressure and temperature noise keyed to the release and the frame (simulators.noise):
        # a seed gives the same noise on every decay whatever the timing of the release.
        self._noise = KeyedNoise(key_from(self._rng), n_ch + _TEMPS * modules, 512)
        self._calz_offset = np.zeros(n_ch)
        self.truth = SimTruth(produced=[FrameRuns() for _ in range(modules)],
                              sent=[FrameRuns() for _ in range(modules)],
                              dropped=[[] for _ in range(modules)])
        # Device state (guarded by _lock).
        self._lock = threading.Lock()
        self._state = "READY"
        self._rate_hz = float(rate_hz)
        self._format = "A"  # ASCII at power-up [unverified]; only "B B" is modelled
        self._packet = "eu"
        self._units = "PA"
        self._ptp = bool(ptp)
        self._calz_end = 0.0
        self._scan_id = 0
        self._next_counter = 1
        self._t0_dev = 0.0
        self._t_start = 0.0
        self._base_ns = 0
        self._step_ns = 0
        # Faults.
        self._drop: dict[int, set[int] | None] = {}  # counter -> modules (None: all)
        self._drop_probability = 0.0
        self._reset_at: int | None = None
        self._invalid_pending = 0
        # Data paths.
        self._buffers: list[deque[_Entry]] = [deque() for _ in range(modules)]
        self._reset_request = [False] * modules
        self._flush_request = [False] * modules
        self._wake = [threading.Event() for _ in range(modules)]
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._cmd_listener: socket.socket | None = None
        self._data_listeners: list[socket.socket] = []
        self.url: str | None = None

    # -- life cycle ------------------------------------------------------------------------------
    @property
    def data_port(self) -> int:
        """TCP port of module 0's binary data server (module ``k``: ``data_port + k``)."""
        if not self._data_listeners:
            raise RuntimeError("the simulator is not started")
        return int(self._data_listeners[0].getsockname()[1])

    @property
    def scan_id(self) -> int:
        """Current scan id (see :class:`SimTruth`)."""
        with self._lock:
            return self._scan_id

    @property
    def state(self) -> str:
        """Device state: ``READY``, ``SCAN`` or ``CALZ``."""
        with self._lock:
            self._update_state()
            return self._state

    @property
    def zero_error_pa(self) -> npt.NDArray[np.float64]:
        """Truth: what each channel reads with no pressure applied, before noise, Pa (a copy).

        The sensors' zero offsets less the zero the last CALZ recorded (every channel's reading
        then, wind included: the taps stay exposed). Shape ``(64 * modules,)``.
        """
        with self._lock:
            return self._sensor_offset - self._calz_offset

    def start(self) -> str:
        """Start the servers on 127.0.0.1 (ephemeral ports); return the command URL.

        The data servers' first port is :attr:`data_port`; give it to the driver's settings.
        """
        if self._threads:
            raise RuntimeError("the simulator is already started")
        self._stop.clear()
        self._cmd_listener = socket.create_server(("127.0.0.1", 0))
        self._data_listeners = self._bind_consecutive(self.modules)
        targets: list[tuple[str, Any, tuple[Any, ...]]] = [
            ("mps4264-cmd", self._serve_commands, ()),
            ("mps4264-gen", self._generate, ()),
        ]
        targets += [(f"mps4264-data{k}", self._serve_data, (k,)) for k in range(self.modules)]
        for name, target, args in targets:
            thread = threading.Thread(target=target, args=args, name=name, daemon=True)
            thread.start()
            self._threads.append(thread)
        self.url = f"tcp://127.0.0.1:{self._cmd_listener.getsockname()[1]}"
        return self.url

    def stop(self) -> None:
        """Stop every thread and close every socket; idempotent."""
        self._stop.set()
        for event in self._wake:
            event.set()
        for thread in self._threads:
            thread.join(timeout=5.0)
        self._threads = []
        for sock in [self._cmd_listener, *self._data_listeners]:
            if sock is not None:
                sock.close()
        self._cmd_listener = None
        self._data_listeners = []

    def __enter__(self) -> SimScanivalveMps4264:
        self.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.stop()

    @staticmethod
    def _bind_consecutive(n: int) -> list[socket.socket]:
        """Bind ``n`` consecutive free ports of 127.0.0.1 (the OS picks the first)."""
        for _ in range(50):
            first = socket.create_server(("127.0.0.1", 0))
            port = first.getsockname()[1]
            socks = [first]
            try:
                for k in range(1, n):
                    socks.append(socket.create_server(("127.0.0.1", port + k)))
            except OSError:
                for sock in socks:
                    sock.close()
                continue
            return socks
        raise OSError(f"no {n} consecutive free ports on 127.0.0.1")

    # -- faults ----------------------------------------------------------------------------------
    def inject(self, fault: str, **params: Any) -> None:
        """Switch on a fault (see the module docstring); unknown faults or parameters raise.

        Parameters
        ----------
        fault : str
            ``"drop_frames"`` (``counters``: iterable of frame counters of the current or next
            scan, ``modules``: iterable of modules, default all; or ``probability``: chance of
            dropping each frame of each module), ``"tcp_reset"`` (``after_frames``: reset after
            that many more frames, default 0), ``"ptp_absent"`` (from the next scan),
            ``"ptp_lock"`` (``step_s``: frame-time step from the next frame, s; a relative
            time base becomes absolute), ``"invalid_command"`` (``count``: the next commands
            other than STATUS answer ``INVALID COMMAND``).
        """
        allowed = {"drop_frames": {"counters", "modules", "probability"},
                   "tcp_reset": {"after_frames"}, "ptp_absent": set(),
                   "ptp_lock": {"step_s"}, "invalid_command": {"count"}}
        if fault not in allowed:
            raise ValueError(f"unknown fault {fault!r}; known: {list(FAULTS)}")
        unknown = set(params) - allowed[fault]
        if unknown:
            raise TypeError(f"{fault}: unknown parameter(s) {sorted(unknown)}")
        with self._lock:
            if fault == "drop_frames":
                modules: Iterable[int] | None = params.get("modules")
                mods = None if modules is None else set(modules)
                for counter in params.get("counters", ()):
                    self._drop[int(counter)] = mods
                if "probability" in params:
                    self._drop_probability = float(params["probability"])
            elif fault == "tcp_reset":
                self._reset_at = self._next_counter + int(params.get("after_frames", 0))
            elif fault == "ptp_absent":
                self._ptp = False
            elif fault == "ptp_lock":
                step_ns = round(float(params.get("step_s", 0.0)) * 1e9)
                if not self._ptp and self._state == "SCAN":
                    step_ns += self._ptp_start_ns()  # relative time jumps onto PTP time
                self._ptp = True
                self._step_ns += step_ns
            else:
                self._invalid_pending += int(params.get("count", 1))

    def true_time_of(self, device_time: Any) -> Any:
        """Return the true time (s, tunnel clock) of frames stamped ``device_time`` (s, driver's).

        The simulated frames are sampled at exactly ``t0_dev + (counter - 1) / rate`` on the
        module clock; their frame time is that instant on the PTP base (``ptp_epoch_s`` +
        device time + any ``ptp_lock`` step) or, without PTP, relative to the scan start. The
        truth against which a recording's clock mapping is checked; valid for the current scan.
        """
        t = np.asarray(device_time, dtype=np.float64)
        if self._ptp:
            t_dev = t - self.ptp_epoch_s - self._step_ns * 1e-9
        else:
            t_dev = t + self._t0_dev
        return (t_dev - self.clock.offset_s) / (1.0 + 1e-6 * self.clock.drift_ppm)

    def _ptp_start_ns(self) -> int:
        return self.ptp_epoch_s * _NS + round(self._t0_dev * 1e9)

    # -- commands --------------------------------------------------------------------------------
    def _serve_commands(self) -> None:
        listener = self._cmd_listener
        assert listener is not None
        clients: dict[socket.socket, bytearray] = {}
        try:
            while not self._stop.is_set():
                readable, _, _ = select.select([listener, *clients], [], [], 0.05)
                for sock in readable:
                    if sock is listener:
                        conn, _ = listener.accept()
                        clients[conn] = bytearray()
                        continue
                    try:
                        data = sock.recv(4096)
                    except OSError:
                        data = b""
                    if not data:
                        del clients[sock]
                        sock.close()
                        continue
                    buf = clients[sock]
                    buf += data
                    replies = bytearray()
                    while True:
                        cut = min((i for i in (buf.find(b"\r"), buf.find(b"\n")) if i >= 0),
                                  default=-1)
                        if cut < 0:
                            break
                        line = bytes(buf[:cut]).decode("ascii", errors="replace")
                        del buf[:cut + 1]
                        replies += self.handle_command(line)
                    if len(buf) > 4096:  # a line that never ends: answer it and forget it
                        replies += self.handle_command(bytes(buf[:64]).decode("ascii", "replace"))
                        buf.clear()
                    if replies:
                        try:
                            sock.sendall(replies)
                        except OSError:
                            del clients[sock]
                            sock.close()
        finally:
            for sock in clients:
                sock.close()

    def handle_command(self, line: str) -> bytes:
        """Execute one command line; return the reply bytes (possibly empty)."""
        text = " ".join(line.split())
        command = text.upper()
        if not command:
            return b""
        invalid = f"INVALID COMMAND: {text}\r\n".encode("ascii", errors="replace")
        with self._lock:
            self._update_state()
            if command == "STATUS":
                return f"STATUS: {self._state}\r\n".encode("ascii")
            if self._invalid_pending > 0:
                self._invalid_pending -= 1
                return invalid
            if self._state == "CALZ":
                return invalid
            if command == "STOP":
                if self._state == "SCAN":
                    # A real scanner samples until STOP; the generator thread may lag (it runs
                    # every few ms, later under load): produce what is due by now first, so that
                    # the frames the scan stops after are the ones the clock says.
                    self._produce_due()
                self._state = "READY"
                return b""
            if self._state == "SCAN":
                return invalid
            parts = command.split()
            if command == "SCAN":
                if self._format != "B B":
                    return invalid
                self._start_scan()
                return b""
            if command == "CALZ":
                self._start_calz()
                return b""
            if len(parts) >= 3 and parts[0] == "SET":
                if self._set(parts[1], parts[2:]):
                    return b""
            return invalid

    def _set(self, name: str, values: list[str]) -> bool:
        if name == "RATE" and len(values) == 1:
            try:
                rate = float(values[0])
            except ValueError:
                return False
            if not 0 < rate <= self.max_rate_hz:
                return False
            self._rate_hz = rate
            return True
        if name == "FORMAT" and values == ["B", "B"]:
            self._format = "B B"
            return True
        if name == "SIM" and len(values) == 1:
            try:
                code = int(values[0], 0)
            except ValueError:
                return False
            if code not in (0, 0x40):
                return False
            self._packet = "legacy" if code == 0x40 else "eu"
            return True
        if name == "UNITS" and len(values) == 1 and values[0] in _UNITS:
            self._units = values[0]
            return True
        return False

    def _update_state(self) -> None:
        if self._state == "CALZ" and time.monotonic() >= self._calz_end:
            self._state = "READY"

    def _start_calz(self) -> None:
        """Record each channel's reading as its zero (no calibration valve: taps stay exposed)."""
        t = self.tunnel.clock.now()
        self._calz_offset = self._sensor_offset + self._truth_pressures(np.array([t]))[0]
        self.truth.calz_wind_speeds.append(self.tunnel.wind_speed())
        self._state = "CALZ"
        self._calz_end = time.monotonic() + self.calz_duration_s

    def _start_scan(self) -> None:
        self._scan_id += 1
        self._next_counter = 1
        self._t_start = self.tunnel.clock.now()
        self._t0_dev = self.clock.device_time(self._t_start)
        self._base_ns = self._ptp_start_ns() if self._ptp else 0
        self._step_ns = 0
        self._reset_at = None
        for k in range(self.modules):
            self._discard(k, "superseded")
            self._flush_request[k] = True
        self._state = "SCAN"

    def _discard(self, module: int, reason: str) -> None:
        buffer = self._buffers[module]
        self.truth.dropped[module].extend((e.scan_id, e.counter, reason) for e in buffer)
        buffer.clear()

    # -- frames ----------------------------------------------------------------------------------
    def _truth_pressures(self, t_true: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Noise-free pressures of every channel at true times ``t_true``, Pa."""
        taps, qd = self.tunnel.pressures(t_true)
        p = np.zeros((t_true.size, _CHANNELS * self.modules))
        p[:, self.tap_channels] = taps
        p[:, self.pitot_channel] = self._pitot_reading(qd)
        return p

    def _pitot_reading(self, qd: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Return what an uncalibrated Pitot reads for the tunnel's dynamic pressure ``qd``, Pa."""
        if len(self.pitot_error) == 3:
            factors, offset, rpm = self.pitot_error
            factor = float(np.interp(self.tunnel.fan_rpm, rpm, factors))
        else:
            factor, offset = (float(v) for v in self.pitot_error)
        return np.asarray((qd - offset) / factor, dtype=np.float64)

    def _generate(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                wait = self._produce_due() if self._state == "SCAN" else 0.005
            self._stop.wait(wait)

    def _produce_due(self) -> float:
        """Produce every frame due by now (lock held); return the wait until the next one, s."""
        now = self.tunnel.clock.now()
        elapsed_dev = self.clock.device_time(now) - self._t0_dev
        last_due = math.floor(elapsed_dev * self._rate_hz + 1e-9) + 1
        n = min(last_due - self._next_counter + 1, _MAX_BATCH)
        reset = self._reset_at is not None and self._next_counter + n - 1 >= self._reset_at
        if reset:
            assert self._reset_at is not None
            n = max(self._reset_at - self._next_counter + 1, 0)
        if n > 0:
            self._produce(np.arange(self._next_counter, self._next_counter + n, dtype=np.int64))
            self._next_counter += n
        if reset:
            self._tcp_reset()
        ahead = (self._next_counter - 1) / self._rate_hz - elapsed_dev
        return min(max(ahead, 0.0005), 0.005)

    def _produce(self, counters: npt.NDArray[np.int64]) -> None:
        n = counters.size
        scale = 1.0 + 1e-6 * self.clock.drift_ppm
        elapsed_ns = ((counters - 1) * _NS / self._rate_hz).round().astype(np.int64)
        t_dev = self._t0_dev + elapsed_ns.astype(np.float64) * 1e-9
        t_true = ((t_dev - self.clock.offset_s) / scale).astype(np.float64)
        p = self._truth_pressures(t_true) + self._sensor_offset - self._calz_offset
        normals = self._noise.sampled(self.tunnel.release_times(), t_true, t_dev, self.clock,
                                      self._rate_hz)
        p += self.noise_pa * normals[:, :p.shape[1]]
        index, conversion = _UNITS[self._units]
        p_units = (p * (conversion / _PSI_PA)).astype(np.float32)
        temps = (self.tunnel.air.temperature_k - 273.15
                 + self.temperature_noise_c * normals[:, p.shape[1]:]).astype(np.float32)
        t_ns = self._base_ns + self._step_ns + elapsed_ns
        ext = np.full(n, -1, np.int64)
        triggers = np.asarray(self.tunnel.trigger_times(since=self._t_start))
        if triggers.size:
            last = np.searchsorted(triggers, t_true, side="right") - 1
            rel = ((triggers * scale + self.clock.offset_s) - self._t0_dev) * 1e9
            ext = np.where(last >= 0, np.round(rel[np.maximum(last, 0)]).astype(np.int64), -1)
        order = ">u4" if self.byte_order == "big" else "<u4"
        for k in range(self.modules):
            chans = slice(_CHANNELS * k, _CHANNELS * (k + 1))
            tk = np.ascontiguousarray(temps[:, _TEMPS * k:_TEMPS * (k + 1)])
            pk = np.ascontiguousarray(p_units[:, chans])
            if self._packet == "eu":
                words = _words_eu(counters, t_ns, tk, pk)
            else:
                words = _words_legacy(
                    counters, t_ns, tk, pk, serial=self.serial_number + k, rate_hz=self._rate_hz,
                    unit_index=index, conversion=conversion,
                    start_ns=self._base_ns + self._step_ns, ext_rel_ns=ext)
            data = words.astype(order).tobytes()
            size = words.shape[1] * 4
            drop = self._drop_mask(counters, k)
            buffer = self._buffers[k]
            for i, counter in enumerate(counters.tolist()):
                self.truth.produced[k].add(self._scan_id, counter)
                if drop[i]:
                    self.truth.dropped[k].append((self._scan_id, counter, "fault"))
                elif len(buffer) >= self.buffer_frames:
                    self.truth.dropped[k].append((self._scan_id, counter, "overrun"))
                else:
                    buffer.append(_Entry(self._scan_id, counter, data[i * size:(i + 1) * size]))
            self._wake[k].set()

    def _drop_mask(self, counters: npt.NDArray[np.int64], module: int) -> npt.NDArray[np.bool_]:
        drop = np.zeros(counters.size, bool)
        for i, counter in enumerate(counters.tolist()):
            if counter in self._drop:
                mods = self._drop[counter]
                drop[i] = mods is None or module in mods
        if self._drop_probability > 0:
            drop |= self._rng.random(counters.size) < self._drop_probability
        return drop

    def _tcp_reset(self) -> None:
        """Fault: reset the data connections (RST) and restart the scan with the counter at 1."""
        for k in range(self.modules):
            self._discard(k, "reset")
            self._reset_request[k] = True
            self._wake[k].set()
        self._drop = {}
        self._scan_id += 1
        self._next_counter = 1
        self._t_start = self.tunnel.clock.now()
        self._t0_dev = self.clock.device_time(self._t_start)
        self._base_ns = self._ptp_start_ns() if self._ptp else 0
        self._step_ns = 0
        self._reset_at = None

    # -- data servers ----------------------------------------------------------------------------
    def _serve_data(self, k: int) -> None:
        listener = self._data_listeners[k]
        listener.setblocking(False)
        client: socket.socket | None = None
        inflight: list[_Entry] = []
        payload = b""
        ends: list[int] = []
        sent = done = 0

        def requeue(reason: str | None) -> None:
            """Frames of ``inflight`` not fully sent: back to the buffer, or dropped."""
            rest = inflight[done:]
            if reason is None:
                self._buffers[k].extendleft(reversed(rest))
            else:
                self.truth.dropped[k].extend((e.scan_id, e.counter, reason) for e in rest)

        try:
            while not self._stop.is_set():
                conn = self._accept(listener)
                with self._lock:
                    if conn is not None:
                        if client is not None:
                            client.close()
                            requeue(None)
                            inflight = []
                        client = conn
                    if self._reset_request[k]:
                        self._reset_request[k] = False
                        requeue("reset")
                        inflight = []
                        if client is not None:
                            client.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER,
                                              struct.pack("ii", 1, 0))
                            client.close()  # an RST: the peer's next read fails
                            client = None
                    if self._flush_request[k]:
                        self._flush_request[k] = False
                        requeue("superseded")
                        inflight = []
                    if client is not None and not inflight:
                        buffer = self._buffers[k]
                        inflight = [buffer.popleft() for _ in range(min(len(buffer),
                                                                         _SEND_BATCH))]
                        payload = b"".join(e.data for e in inflight)
                        ends = np.cumsum([len(e.data) for e in inflight]).tolist()
                        sent = done = 0
                if client is None or not inflight:
                    if client is not None and self._peer_closed(client):
                        client.close()
                        client = None
                    self._wake[k].wait(0.005)
                    self._wake[k].clear()
                    continue
                try:
                    sent += client.send(payload[sent:])
                except BlockingIOError:
                    select.select([], [client], [], 0.01)
                    continue
                except OSError:  # the client went away: keep its unsent frames for the next
                    with self._lock:
                        requeue(None)
                    inflight = []
                    client.close()
                    client = None
                    continue
                with self._lock:
                    while done < len(inflight) and ends[done] <= sent:
                        self.truth.sent[k].add(inflight[done].scan_id, inflight[done].counter)
                        done += 1
                    if done == len(inflight):
                        inflight = []
        finally:
            if client is not None:
                client.close()

    def _accept(self, listener: socket.socket) -> socket.socket | None:
        """Return the newest pending data connection, or None (older pending ones are closed)."""
        newest = None
        while True:
            try:
                conn, _ = listener.accept()
            except (BlockingIOError, InterruptedError):
                return newest
            if newest is not None:
                newest.close()
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            if self.send_buffer_bytes is not None:
                conn.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, self.send_buffer_bytes)
            newest = conn

    @staticmethod
    def _peer_closed(sock: socket.socket) -> bool:
        try:
            data = sock.recv(4096)
        except (BlockingIOError, InterruptedError):
            return False
        except OSError:
            return True
        return not data
