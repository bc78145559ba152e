"""Simulated Scanivalve MPS4264-class pressure scanner: the device, its commands and its frames.

Responsibility: :class:`SimScanivalveMps4264`, the scanner as one state machine over one device
state, speaking the wire protocol on 127.0.0.1 (``docs/reference/wire_formats.md``, "Pressure
scanner") from the virtual tunnel's pressures: the ASCII commands and their replies
(:meth:`~SimScanivalveMps4264.handle_command`), frames at the commanded rate on the device's own
clock (offset, drift), with seeded noise, sensor zero offsets and their CALZ, the
external-trigger time of the tunnel's trigger line, both byte orders, a bounded frame buffer per
module that drops frames when the client stalls, and fault injection. Its parts: the packets
(:mod:`~simulators.devices.scanivalve_mps4264.packets`), the TCP servers, a command server and
one binary data server per 64-channel module (module ``k`` on port ``data_port + k``, our
[design] for several modules, since the 0x6D packet carries no module field:
:mod:`~simulators.devices.scanivalve_mps4264.servers`), and the truth counters (frames produced,
sent, dropped with the reason: :mod:`~simulators.devices.scanivalve_mps4264.truth`) by which
tests prove that no frame was lost that the simulator did not drop. Not responsible for:
UDP/FTP outputs, ASCII/CSV/LabVIEW scan formats, RAW packets, or anything of the driver (this
package imports nothing from ``daq``: the packets are encoded from the manual facts,
independently of the driver's decoder).

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
"""

from __future__ import annotations

import math
import socket
import threading
import time
from collections.abc import Iterable, Sequence
from types import TracebackType
from typing import Any

import numpy as np
import numpy.typing as npt

from simulators.clock import DeviceClock
from simulators.devices.scanivalve_mps4264.packets import (
    CHANNELS,
    NS,
    PSI_PA,
    TEMPS,
    UNITS,
    words_eu,
    words_legacy,
)
from simulators.devices.scanivalve_mps4264.servers import (
    DataPort,
    QueuedFrame,
    bind_consecutive,
    serve_commands,
)
from simulators.devices.scanivalve_mps4264.truth import FrameRuns, SimTruth
from simulators.noise import KeyedNoise, key_from
from simulators.virtual_tunnel import VirtualTunnel

__all__ = ["FAULTS", "SimScanivalveMps4264"]

#: Faults :meth:`SimScanivalveMps4264.inject` accepts.
FAULTS = ("drop_frames", "tcp_reset", "ptp_absent", "ptp_lock", "invalid_command")

_MAX_BATCH = 2000  # frames produced per generator step at most (catch-up after a stall)


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
        to the scan start, from epoch 0 (``docs/reference/wire_formats.md``, "Pressure scanner", on
        the scan start and the frame time's epoch).
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
        if n_taps > CHANNELS * modules:
            raise ValueError(f"{n_taps} taps do not fit in {modules} module(s) of 64 channels")
        channels = list(range(n_taps)) if tap_channels is None else [int(c) for c in tap_channels]
        if tap_channels is None and not n_taps <= pitot_channel < CHANNELS * modules:
            raise ValueError(f"pitot_channel must be in [{n_taps}, {CHANNELS * modules - 1}] "
                             f"(after the {n_taps} taps), got {pitot_channel!r}")
        if len(channels) != n_taps or len(set(channels) | {pitot_channel}) != n_taps + 1 or \
                not all(0 <= c < CHANNELS * modules for c in [*channels, pitot_channel]):
            raise ValueError(f"tap_channels must be {n_taps} distinct channels in "
                             f"[0, {CHANNELS * modules - 1}] besides pitot_channel = "
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
        n_ch = CHANNELS * modules
        self._sensor_offset = self._rng.normal(0.0, sensor_offset_pa, n_ch)
        # Pressure and temperature noise keyed to the release and the frame (simulators.noise):
        # a seed gives the same noise on every decay whatever the timing of the release.
        self._noise = KeyedNoise(key_from(self._rng), n_ch + TEMPS * modules, 512)
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
        self._stop = threading.Event()
        self._ports = [DataPort(self._lock, self._stop, self.truth.sent[k], self.truth.dropped[k],
                                send_buffer_bytes) for k in range(modules)]
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
        self._data_listeners = bind_consecutive(self.modules)
        targets: list[tuple[str, Any, tuple[Any, ...]]] = [
            ("mps4264-cmd", serve_commands, (self._cmd_listener, self._stop,
                                             self.handle_command)),
            ("mps4264-gen", self._generate, ()),
        ]
        targets += [(f"mps4264-data{k}", self._ports[k].serve, (self._data_listeners[k],))
                    for k in range(self.modules)]
        for name, target, args in targets:
            thread = threading.Thread(target=target, args=args, name=name, daemon=True)
            thread.start()
            self._threads.append(thread)
        self.url = f"tcp://127.0.0.1:{self._cmd_listener.getsockname()[1]}"
        return self.url

    def stop(self) -> None:
        """Stop every thread and close every socket; idempotent."""
        self._stop.set()
        for port in self._ports:
            port.wake.set()
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
        return self.ptp_epoch_s * NS + round(self._t0_dev * 1e9)

    # -- commands --------------------------------------------------------------------------------
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
        if name == "UNITS" and len(values) == 1 and values[0] in UNITS:
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
            self._ports[k].discard("superseded")
            self._ports[k].flush_request = True
        self._state = "SCAN"

    # -- frames ----------------------------------------------------------------------------------
    def _truth_pressures(self, t_true: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Noise-free pressures of every channel at true times ``t_true``, Pa."""
        taps, qd = self.tunnel.pressures(t_true)
        p = np.zeros((t_true.size, CHANNELS * self.modules))
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
        elapsed_ns = ((counters - 1) * NS / self._rate_hz).round().astype(np.int64)
        t_dev = self._t0_dev + elapsed_ns.astype(np.float64) * 1e-9
        t_true = ((t_dev - self.clock.offset_s) / scale).astype(np.float64)
        p = self._truth_pressures(t_true) + self._sensor_offset - self._calz_offset
        normals = self._noise.sampled(self.tunnel.release_times(), t_true, t_dev, self.clock,
                                      self._rate_hz)
        p += self.noise_pa * normals[:, :p.shape[1]]
        index, conversion = UNITS[self._units]
        p_units = (p * (conversion / PSI_PA)).astype(np.float32)
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
            chans = slice(CHANNELS * k, CHANNELS * (k + 1))
            tk = np.ascontiguousarray(temps[:, TEMPS * k:TEMPS * (k + 1)])
            pk = np.ascontiguousarray(p_units[:, chans])
            if self._packet == "eu":
                words = words_eu(counters, t_ns, tk, pk)
            else:
                words = words_legacy(
                    counters, t_ns, tk, pk, serial=self.serial_number + k, rate_hz=self._rate_hz,
                    unit_index=index, conversion=conversion,
                    start_ns=self._base_ns + self._step_ns, ext_rel_ns=ext)
            data = words.astype(order).tobytes()
            size = words.shape[1] * 4
            drop = self._drop_mask(counters, k)
            buffer = self._ports[k].buffer
            for i, counter in enumerate(counters.tolist()):
                self.truth.produced[k].add(self._scan_id, counter)
                if drop[i]:
                    self.truth.dropped[k].append((self._scan_id, counter, "fault"))
                elif len(buffer) >= self.buffer_frames:
                    self.truth.dropped[k].append((self._scan_id, counter, "overrun"))
                else:
                    buffer.append(QueuedFrame(self._scan_id, counter,
                                              data[i * size:(i + 1) * size]))
            self._ports[k].wake.set()

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
            self._ports[k].discard("reset")
            self._ports[k].reset_request = True
            self._ports[k].wake.set()
        self._drop = {}
        self._scan_id += 1
        self._next_counter = 1
        self._t_start = self.tunnel.clock.now()
        self._t0_dev = self.clock.device_time(self._t_start)
        self._base_ns = self._ptp_start_ns() if self._ptp else 0
        self._step_ns = 0
        self._reset_at = None
