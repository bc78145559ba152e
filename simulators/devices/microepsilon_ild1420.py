"""Simulated Micro-Epsilon optoNCDT ILD1420 laser: the sensor's bytes over a real serial seam.

Responsibility: behave on the wire like an ILD1420 looking down at the section model of a
:class:`~simulators.virtual_tunnel.VirtualTunnel`: sample the model's heave and pitch at the
measuring rate on the sensor's own :class:`~simulators.clock.DeviceClock`, add seeded noise, encode
blocks of 3-byte values (distance, then counter, timestamp, status ... as configured) and stream
them in real time through pyserial's ``socket://`` (a TCP server on 127.0.0.1) or a pty pair; answer
the ASCII commands the driver uses; inject the lasers' faults (``docs/reference/wire_formats.md``,
"Faults the simulators inject"); and keep a truth record of every sample (what was measured and
whether it reached the wire intact) so tests can prove that nothing was lost that the simulator did
not drop.

Not responsible for: line timing (neither transport limits the byte rate; blocks are sent every
``period_s`` as they fall due), the analog output, the web interface, or decoding anything (it
never imports :mod:`daq`: its encoder is written here from the manual facts, independently of the
driver's decoder).

Wire facts (``docs/reference/wire_formats.md``, "Laser displacement sensors"): values are 18-bit
words sent as ``L = 00 D5..D0``, ``M = 01 D11..D6``, ``H = 1 f D17..D12`` with ``f = 0`` for the
first value of a block (the distance) and 1 for the others; distance ``x = (100 d / MR + 1) 65520 /
102`` (16 bits), with mastering ``x = (100 d / MR + 51) 65520 / 102`` (18 bits); error values
262075..262082 in the distance word; 18-bit counter; timestamp two 16-bit words in 10 us ticks (low
word first [unverified]); status bits: 2 no peak, 5 before SMR, 6 after EMR, 15 value triggered,
16/17 LED ([unverified] green = bit 16, red = bit 17). ASCII framing [unverified]: commands end with
CR LF (CR or LF alone accepted); the reply is the echoed command line, reply lines ending CR LF,
errors ``Exxx text``, then the prompt ``->``; replies are sent between two blocks.

Geometry: the laser looks down at chord position ``x`` (m, positive downstream of the elastic
axis); with h positive down and alpha positive nose-up (Scanlan), the surface under the spot moves
down by ``h + x alpha`` (small angles), so the reading is ``d = standoff + 1000 (h + x alpha)`` mm.
A sway laser (``axis="sway"``, a tunnel with three degrees of freedom) sits downstream of the
model looking upwind at its trailing face, the spot at height ``z`` (m, positive down from the
elastic axis): the face moves downwind by ``p - z alpha`` (a nose-up pitch takes a point below
the axis upwind), towards the laser, so it reads ``d = standoff - 1000 (p - z alpha)`` mm.
Readings outside ``[-0.01 MR, 1.01 MR]`` give 262077 (peak before the range) / 262078 (behind).

Longer than 600 lines: the laser's ASCII commands, its binary output words and its faults
share one device state and one output loop; one module keeps them in one place.
"""

from __future__ import annotations

import errno
import logging
import math
import os
import select
import socket
import threading
import time
import tty
from collections.abc import Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from simulators.clock import DeviceClock
from simulators.noise import KeyedNoise, key_from
from simulators.virtual_tunnel import VirtualTunnel

__all__ = ["FATES", "SimIld1420Truth", "SimMicroEpsilonIld1420"]

log = logging.getLogger(__name__)

RANGES_MM: Final = (10, 25, 50, 100, 200, 500)
WORDS: Final = {"counter": 1, "timestamp": 2, "status": 1, "exposure": 1, "intensity": 1}
OUTPUT_NAMES: Final = {"counter": "COUNTER", "timestamp": "TIMESTAMP", "status": "STATE",
                       "exposure": "SHUTTER", "intensity": "INTENSITY"}
ERROR_VALUES: Final = (262075, 262076, 262077, 262078, 262080, 262081, 262082)
BAUD_TOO_LOW: Final = 262075
NO_PEAK: Final = 262076
BEFORE_RANGE: Final = 262077
BEHIND_RANGE: Final = 262078

#: What happened to each produced sample (``SimIld1420Truth.fate``).
FATES: Final = ("sent", "desync", "corrupted", "overrun", "no_client", "output_off")
_SENT, _DESYNC, _CORRUPTED, _OVERRUN, _NO_CLIENT, _OUTPUT_OFF = range(6)

#: Bytes the simulator queues for a slow reader before it drops blocks: a serial-to-TCP
#: converter buffers a lot; a UART little (the pty's own kernel buffer comes on top), so that a
#: port opened late does not receive seconds-old data.
_OUTBUF_LIMIT = {"socket": 1 << 20, "pty": 1 << 12}


@dataclass(frozen=True)
class SimIld1420Truth:
    """Every sample the simulated sensor produced, in order.

    Attributes
    ----------
    counter : ndarray of int64
        The 18-bit counter value sent (restarts at 0 after a simulated reboot).
    epoch : ndarray of int64
        Power-on epoch of the sensor (increments at each reboot).
    t_true : ndarray of float64
        True time of the sample, s (tunnel clock).
    device_time : ndarray of float64
        Device time of the sample, s (its timestamp before wrapping and quantisation).
    distance_mm : ndarray of float64
        What the sensor measured (with noise, before quantisation), mm.
    code : ndarray of int64
        Error value sent instead of the distance, 0 when the distance was sent.
    triggered : ndarray of bool
        Status bit 15 (the sample follows a tunnel trigger pulse).
    fate : ndarray of int64
        Index into :data:`FATES`: ``sent`` reached the wire intact; ``desync`` lost bytes and
        ``corrupted`` had bytes inserted (fault injection); ``overrun`` the reader fell behind;
        ``no_client`` nobody was connected; ``output_off`` after ``OUTPUT NONE``.
    """

    counter: npt.NDArray[np.int64]
    epoch: npt.NDArray[np.int64]
    t_true: npt.NDArray[np.float64]
    device_time: npt.NDArray[np.float64]
    distance_mm: npt.NDArray[np.float64]
    code: npt.NDArray[np.int64]
    triggered: npt.NDArray[np.bool_]
    fate: npt.NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.counter.shape[0])

    @property
    def sent(self) -> npt.NDArray[np.bool_]:
        """Samples that reached the wire intact."""
        return self.fate == _SENT


class SimMicroEpsilonIld1420:
    """A simulated ILD1420 laser (see the module docstring).

    Parameters
    ----------
    tunnel : VirtualTunnel
        The physical truth (``sample(t)`` gives h and alpha; ``trigger_times()`` the pulses).
    range_mm : int
        Measuring range MR, mm.
    rate_hz : float
        Measuring rate, Hz (device clock), in (0, 4000].
    x : float
        Chord position of the laser spot, m (a vertical laser).
    axis : {"vertical", "sway"}
        What the laser looks at (module docstring, "Geometry"); a sway laser needs a tunnel with
        sway.
    z : float
        A sway laser's spot height, m, positive down from the elastic axis.
    standoff_mm : float, optional
        Vertical distance at the model's rest position (h = alpha = 0), mm; default MR / 2.
    reading_error : tuple of float
        ``(gain, offset_mm, angle_deg)`` of a sensor that needs a calibration: its beam tilted by
        ``angle_deg`` from the vertical reads the distance along the beam, ``d / cos(angle)``,
        and reports ``(d / cos(angle) - offset_mm) / gain`` (the inverse of the rig config's
        ``[lasers.calibration]``); default ``(1, 0, 0)``, a perfect sensor.
    baudrate : int
        The sensor's baud rate: only used for the budget check (``33 x values x rate``); when
        exceeded every distance is 262075, as the sensor does.
    output : sequence of str
        Additional values in block order (``counter``, ``timestamp``, ``status``, ``exposure``,
        ``intensity``).
    noise_mm : float, optional
        Standard deviation of the measurement noise, mm; default 2.5e-5 MR (about 1.6 LSB).
    counter_start : int
        First counter value (0..262143), e.g. 262140 to test the wrap.
    clock : DeviceClock
        The sensor's clock (offset: timestamp at true time 0, e.g. 42949.6 s to test the wrap;
        drift, ppm).
    rng : numpy.random.Generator or int, optional
        Noise source or its seed.
    master_timeout_s : float
        How long MASTERMV waits for a value before ``E104 Timeout`` (2 s on the sensor).
    period_s : float
        Interval between two sends of the blocks that fell due, s.
    truth_limit : int
        Most samples kept in the truth record (oldest dropped beyond it).
    """

    def __init__(
        self,
        tunnel: VirtualTunnel,
        *,
        range_mm: int = 10,
        rate_hz: float = 4000.0,
        x: float = 0.0,
        axis: str = "vertical",
        z: float = 0.0,
        standoff_mm: float | None = None,
        reading_error: tuple[float, float, float] = (1.0, 0.0, 0.0),
        baudrate: int = 921600,
        output: Sequence[str] = ("counter", "timestamp", "status"),
        noise_mm: float | None = None,
        counter_start: int = 0,
        clock: DeviceClock | None = None,
        rng: np.random.Generator | int | None = None,
        master_timeout_s: float = 2.0,
        period_s: float = 0.002,
        truth_limit: int = 2_000_000,
    ) -> None:
        if range_mm not in RANGES_MM:
            raise ValueError(f"range_mm must be one of {RANGES_MM}, got {range_mm!r}")
        if not 0 < rate_hz <= 4000:
            raise ValueError(f"rate_hz must be in (0, 4000], got {rate_hz!r}")
        if any(o not in WORDS for o in output) or len(set(output)) != len(output):
            raise ValueError(f"output must name distinct values of {sorted(WORDS)}: {output!r}")
        if not 0 <= counter_start < 1 << 18:
            raise ValueError(f"counter_start must be in [0, 262143], got {counter_start!r}")
        if period_s <= 0 or master_timeout_s <= 0:
            raise ValueError("period_s and master_timeout_s must be > 0")
        if axis not in ("vertical", "sway"):
            raise ValueError(f"axis must be 'vertical' or 'sway', got {axis!r}")
        if axis == "sway" and "p" not in tunnel.channels:
            raise ValueError("a sway laser (axis='sway') needs a tunnel with sway: a section "
                             "with fp and a 3x3 aerodynamic model")
        self.axis = axis
        self.z = float(z)
        self.tunnel = tunnel
        self.range_mm = int(range_mm)
        self.rate_hz = float(rate_hz)
        self.x = float(x)
        self.standoff_mm = self.range_mm / 2 if standoff_mm is None else float(standoff_mm)
        gain, offset_mm, angle_deg = (float(v) for v in reading_error)
        if not (gain > 0 and abs(angle_deg) < 90):
            raise ValueError(f"reading_error (gain, offset_mm, angle_deg) needs gain > 0 and "
                             f"|angle_deg| < 90, got {reading_error!r}")
        self.reading_error = (gain, offset_mm, angle_deg)
        self.baudrate = int(baudrate)
        self.output = tuple(output)
        self.noise_mm = 2.5e-5 * self.range_mm if noise_mm is None else float(noise_mm)
        self.counter_start = int(counter_start)
        self.clock = clock if clock is not None else DeviceClock()
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        # The distance noise is keyed to the release and the sample (simulators.noise): a
        # seed gives the same noise on every decay whatever the timing of the release.
        self._noise = KeyedNoise(key_from(self.rng), 1, 4096)
        self.master_timeout_s = float(master_timeout_s)
        self.period_s = float(period_s)
        self.truth_limit = int(truth_limit)
        self.values_per_block = 1 + sum(WORDS[o] for o in self.output)
        self.block_bytes = 3 * self.values_per_block
        #: Whether the line cannot carry the block rate: the sensor then sends 262075.
        self.baud_overflow = 33 * self.values_per_block * self.rate_hz > self.baudrate

        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.url: str | None = None
        self.transport: str | None = None
        # I/O endpoints
        self._listener: socket.socket | None = None
        self._client: socket.socket | None = None
        self._master_fd: int | None = None
        self._slave_fd: int | None = None
        self._outbuf = bytearray()
        self._inbuf = bytearray()
        self._accept_after = -math.inf
        # Sensor state (touched by the server thread; faults are queued under the lock)
        self._epoch = 0
        self._grid_origin = 0.0  # device time of grid index 0 in this epoch, s
        self._ts_origin = 0.0  # device time whose timestamp is 0, s
        self._next_index = 0  # next grid index to sample
        self._counter = self.counter_start
        self._output_on = True
        self._mastered: tuple[float, float] | None = None  # (master position, master value), mm
        self._pending_master: tuple[float, float] | None = None  # (value, true deadline)
        self._pending_line = ""
        self._last_trigger = -math.inf
        self._pending_triggers: list[float] = []
        self._reboot_at: float | None = None
        # Faults
        self._code_runs: list[list[int]] = []  # [code, samples left]
        self._byte_faults: list[tuple[str, int, bytes, int]] = []  # kind, offset, data, n
        self._stall_until = -math.inf
        self._disconnect: tuple[float, bool] | None = None
        # Truth
        self._truth: list[dict[str, npt.NDArray[Any]]] = []
        self._truth_size = 0
        #: Samples produced, and samples that did not reach the wire intact, since start.
        self.produced = 0
        self.dropped = 0

    # -- life cycle ---------------------------------------------------------------------------
    def start(self, transport: str = "socket") -> str:
        """Start streaming; return the URL a driver opens (``socket://...`` or ``serial://...``).

        Parameters
        ----------
        transport : {"socket", "pty"}
            A TCP server on 127.0.0.1 speaking the raw serial byte stream (pyserial's
            ``socket://``), or a pty pair whose slave is the serial port.
        """
        if self._thread is not None:
            raise RuntimeError("simulator already started")
        if transport == "socket":
            listener = socket.create_server(("127.0.0.1", 0))
            listener.setblocking(False)
            self._listener = listener
            self.url = f"socket://127.0.0.1:{listener.getsockname()[1]}"
        elif transport == "pty":
            master, slave = os.openpty()
            tty.setraw(slave)  # no echo, no CR/LF translation, no flow control: raw bytes
            os.set_blocking(master, False)
            self._master_fd, self._slave_fd = master, slave
            self.url = f"serial://{os.ttyname(slave)}"
        else:
            raise ValueError(f"transport must be 'socket' or 'pty', got {transport!r}")
        self.transport = transport
        now = self.tunnel.clock.now()
        self._grid_origin = self.clock.device_time(now)
        self._last_trigger = now
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=f"SimILD1420 {self.url}",
                                        daemon=True)
        self._thread.start()
        return self.url

    def stop(self) -> None:
        """Stop streaming, join the thread and close every endpoint; idempotent."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        for sock in (self._client, self._listener):
            if sock is not None:
                sock.close()
        self._client = self._listener = None
        for fd in (self._master_fd, self._slave_fd):
            if fd is not None:
                os.close(fd)
        self._master_fd = self._slave_fd = None

    def __enter__(self) -> SimMicroEpsilonIld1420:
        if self._thread is None:
            self.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.stop()

    # -- faults -------------------------------------------------------------------------------
    def inject(self, fault: str, **params: Any) -> None:
        r"""Schedule a fault (``docs/reference/wire_formats.md``, "Faults the simulators inject").

        Faults and their parameters:

        - ``"error_code"``, ``code`` (262075..262082), ``count``: the next ``count`` samples send
          ``code`` instead of the distance;
        - ``"dark_target"``, ``count``: 262076 (no peak) with status bit 2;
        - ``"drop_bytes"``, ``n``, ``offset`` (default 1, i.e. mid-word): the next block loses
          ``n`` bytes from ``offset`` on (the blocks touched are truth ``desync``); ``offset`` 0
          with a new client is "starting mid-word";
        - ``"insert_bytes"``, ``data`` (default ``b"\\xc5"``), ``offset`` (default 1): bytes
          inserted into the next block (truth ``corrupted`` unless at a block boundary);
        - ``"stall"``, ``duration_s``: no values for a while (as with external triggering and no
          trigger); MASTERMV then times out;
        - ``"disconnect"``, ``downtime_s``, ``restart`` (default True): socket only; the
          connection is closed, no connection is accepted for ``downtime_s``, and with
          ``restart`` the sensor reboots (counter and timestamp begin again at 0).

        The counter wrap, the timestamp wrap, the baud budget and clock drift are constructor
        options (``counter_start``, ``clock``, ``baudrate``); 262077/262078 follow from geometry.
        """
        with self._lock:
            if fault in ("error_code", "dark_target"):
                code = NO_PEAK if fault == "dark_target" else int(params.pop("code"))
                count = int(params.pop("count", 1))
                if code not in ERROR_VALUES or count < 1:
                    raise ValueError(f"code must be one of {ERROR_VALUES} and count >= 1")
                self._code_runs.append([code, count])
            elif fault == "drop_bytes":
                n, offset = int(params.pop("n", 1)), int(params.pop("offset", 1))
                if n < 1 or offset < 0:
                    raise ValueError("drop_bytes needs n >= 1 and offset >= 0")
                self._byte_faults.append(("drop", offset, b"", n))
            elif fault == "insert_bytes":
                data, offset = bytes(params.pop("data", b"\xc5")), int(params.pop("offset", 1))
                if not data or offset < 0:
                    raise ValueError("insert_bytes needs data and offset >= 0")
                self._byte_faults.append(("insert", offset, data, len(data)))
            elif fault == "stall":
                duration = float(params.pop("duration_s"))
                self._stall_until = self.tunnel.clock.now() + duration
            elif fault == "disconnect":
                if self.transport != "socket":
                    raise ValueError("a disconnect needs the socket transport")
                self._disconnect = (float(params.pop("downtime_s", 0.2)),
                                    bool(params.pop("restart", True)))
            else:
                raise ValueError(f"unknown fault {fault!r}")
            if params:
                raise TypeError(f"unknown parameter(s) for {fault!r}: {sorted(params)}")

    def truth(self) -> SimIld1420Truth:
        """Return the truth record so far (a copy)."""
        with self._lock:
            parts = list(self._truth)
        names = ("counter", "epoch", "t_true", "device_time", "distance_mm", "code",
                 "triggered", "fate")
        dtypes = (np.int64, np.int64, np.float64, np.float64, np.float64, np.int64, np.bool_,
                  np.int64)
        return SimIld1420Truth(**{
            name: (np.concatenate([p[name] for p in parts]) if parts
                   else np.empty(0, dtype=dtype))
            for name, dtype in zip(names, dtypes, strict=True)})

    # -- server thread ------------------------------------------------------------------------
    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                self._poll_io(self.period_s)
                now = self.tunnel.clock.now()
                self._handle_disconnect(now)
                self._produce(now)
                self._expire_master(now)
                self._flush()
        except Exception:  # the thread must not die silently: log, then stop serving
            log.exception("simulated ILD1420 %s failed", self.url)
            raise

    def _poll_io(self, timeout: float) -> None:
        """Wait up to ``timeout`` for a connection or command bytes, and take them."""
        readable: list[Any] = []
        if self._listener is not None:
            if self.tunnel.clock.now() >= self._accept_after:
                readable.append(self._listener)
            if self._client is not None:
                readable.append(self._client)
        elif self._master_fd is not None:
            readable.append(self._master_fd)
        ready = select.select(readable, [], [], timeout)[0] if readable else []
        if not readable:
            self._stop.wait(timeout)
        # The client first, then a new connection: when a client closes and the next one
        # connects within one wait, both are ready, and accepting first would replace (and
        # close) the socket whose EOF is still to be read.
        client = self._client
        if client is not None and client in ready:
            try:
                data = client.recv(4096)
            except (BlockingIOError, InterruptedError):
                data = None
            except OSError:
                data = b""
            if data == b"":
                self._drop_client("peer closed")
            elif data:
                self._take_command_bytes(data)
        if self._listener is not None and self._listener in ready:
            self._accept()
        if self._master_fd is not None and self._master_fd in ready:
            try:
                data = os.read(self._master_fd, 4096)
            except (BlockingIOError, InterruptedError):
                data = b""
            except OSError as exc:  # EIO: no slave open (we keep one, so rare)
                if exc.errno != errno.EIO:
                    raise
                data = b""
            if data:
                self._take_command_bytes(data)

    def _accept(self) -> None:
        assert self._listener is not None
        try:
            conn, _ = self._listener.accept()
        except (BlockingIOError, InterruptedError):
            return
        if self._client is not None:
            self._drop_client("replaced by a new connection")
        conn.setblocking(False)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._client = conn
        self._outbuf.clear()
        self._inbuf.clear()
        log.debug("simulated ILD1420 %s: client connected", self.url)

    def _drop_client(self, why: str) -> None:
        if self._client is not None:
            log.debug("simulated ILD1420 %s: client gone (%s)", self.url, why)
            self._client.close()
            self._client = None
        self._outbuf.clear()

    def _connected(self) -> bool:
        return self._master_fd is not None or self._client is not None

    def _handle_disconnect(self, now: float) -> None:
        with self._lock:
            request, self._disconnect = self._disconnect, None
        if request is not None:
            downtime, restart = request
            self._flush(block_s=1.0)
            self._drop_client("disconnect fault")
            self._accept_after = now + downtime
            if restart:
                self._reboot_at = now + downtime
        if self._reboot_at is not None and now >= self._reboot_at:
            self._reboot(self._reboot_at)

    def _reboot(self, t_true: float) -> None:
        """Begin a new power-on epoch: counter and timestamp start again at 0."""
        self._reboot_at = None
        self._epoch += 1
        self._grid_origin = self._ts_origin = self.clock.device_time(t_true)
        self._next_index = 0
        self._counter = 0
        self._mastered = None
        log.debug("simulated ILD1420 %s: rebooted (epoch %d)", self.url, self._epoch)

    # -- commands -----------------------------------------------------------------------------
    def _take_command_bytes(self, data: bytes) -> None:
        self._inbuf += data
        while True:
            ends = [i for i in (self._inbuf.find(b"\r"), self._inbuf.find(b"\n")) if i >= 0]
            if not ends:
                if len(self._inbuf) > 4096:
                    self._inbuf.clear()  # garbage without a line end
                return
            end = min(ends)
            line = bytes(self._inbuf[:end]).decode("ascii", "replace").strip()
            del self._inbuf[:end + 1]
            if line:
                self._command(line)

    def _reply(self, line: str, lines: Sequence[str] = (), error: str | None = None) -> None:
        text = line + "\r\n" + "".join(f"{r}\r\n" for r in lines)
        if error is not None:
            text += error + "\r\n"
        self._send(text.encode("ascii") + b"->")

    def _command(self, line: str) -> None:
        words = line.split()
        name = words[0].upper()
        args = [w.upper() for w in words[1:]]
        if name == "GETOUTINFO_RS422" and not args:
            names = " ".join(["DIST1", *(OUTPUT_NAMES[o] for o in self.output)])
            self._reply(line, [f"GETOUTINFO_RS422 {names}"])
        elif name == "OUTPUT" and not args:
            self._reply(line, [f"OUTPUT {'RS422' if self._output_on else 'NONE'}"])
        elif name == "OUTPUT" and args[0] in ("NONE", "RS422", "ANALOG") and len(args) == 1:
            self._output_on = args[0] == "RS422"
            self._reply(line)
        elif name == "MASTERMV" and args == ["NONE"]:
            self._mastered = None
            self._reply(line)
        elif name == "MASTERMV" and len(args) == 2 and args[0] == "MASTER":
            try:
                value = float(args[1])
            except ValueError:
                value = math.nan
            if not 0.0 <= value <= 2.0 * self.range_mm:
                self._reply(line, error="E210 Parameter out of range")  # [unverified] code
            else:
                self._pending_master = (value, self.tunnel.clock.now() + self.master_timeout_s)
                self._pending_line = line
        elif name == "GETINFO" and not args:
            self._reply(line, [f"Name: ILD1420-{self.range_mm}", "Serial: 00000000",
                               "Option: 000", "Article: 0000000",
                               f"Measuring range: {self.range_mm:.2f}mm",
                               "Version: simulated"])
        else:
            self._reply(line, error="E200 Unknown command")  # [unverified] code and text

    def _expire_master(self, now: float) -> None:
        if self._pending_master is not None and now >= self._pending_master[1]:
            self._pending_master = None
            self._reply(self._pending_line, error="E104 Timeout")

    def true_time_of(self, device_time: Any) -> Any:
        """Return the true time (s, tunnel clock) of samples stamped ``device_time`` (unwrapped).

        The timestamp counts from the sensor's power-on (the device time ``ts_origin``); the
        truth against which a recording's clock mapping is checked, valid within the current
        power-on epoch (to the timestamp's 10 us resolution).
        """
        t = np.asarray(device_time, dtype=np.float64)
        return (t + self._ts_origin - self.clock.offset_s) / (1.0 + 1e-6 * self.clock.drift_ppm)

    # -- measurement --------------------------------------------------------------------------
    def _produce(self, now: float) -> None:
        """Sample every grid point due by ``now`` (true time) and queue its blocks."""
        if self._reboot_at is not None:  # rebooting: the sensor measures nothing
            return
        due = math.floor((self.clock.device_time(now) - self._grid_origin) * self.rate_hz) + 1
        if due <= self._next_index:
            return
        index = np.arange(self._next_index, due)
        self._next_index = due
        tau = self._grid_origin + index / self.rate_hz
        # DeviceClock is affine: true = a + b tau.
        a = self.clock.true_time(0.0)
        t_true = a + (self.clock.true_time(1.0) - a) * tau
        if now < self._stall_until:  # no values while stalled: the counter does not move
            return
        n = index.size
        physics = self.tunnel.sample(t_true)
        # Small angles: the surface under the spot moves down by h + x alpha, a sway laser's
        # face towards it by p - z alpha (module docstring).
        if self.axis == "sway":
            distance = self.standoff_mm - 1000.0 * (physics["p"] - self.z * physics["alpha"])
        else:
            distance = self.standoff_mm + 1000.0 * (physics["h"] + self.x * physics["alpha"])
        gain, offset_mm, angle_deg = self.reading_error
        if (gain, offset_mm, angle_deg) != (1.0, 0.0, 0.0):  # along the beam, uncalibrated
            distance = (distance / math.cos(math.radians(angle_deg)) - offset_mm) / gain
        if self.noise_mm > 0:
            distance = distance + self.noise_mm * self._noise.sampled(
                self.tunnel.release_times(), t_true, tau, self.clock, self.rate_hz)[:, 0]
        code = np.zeros(n, dtype=np.int64)
        lo, hi = -0.01 * self.range_mm, 1.01 * self.range_mm
        code[distance < lo] = BEFORE_RANGE
        code[distance > hi] = BEHIND_RANGE
        with self._lock:
            runs = self._code_runs
            start = 0
            while runs and start < n:
                take = min(runs[0][1], n - start)
                code[start:start + take] = runs[0][0]
                start += take
                runs[0][1] -= take
                if runs[0][1] == 0:
                    runs.pop(0)
            byte_faults, self._byte_faults = self._byte_faults, []
        if self.baud_overflow:
            code[:] = BAUD_TOO_LOW
        triggered = self._triggered(t_true)
        counter = (self._counter + np.arange(n)) % (1 << 18)
        self._counter = int((self._counter + n) % (1 << 18))
        ticks = np.floor((tau - self._ts_origin) * 1e5 + 0.5).astype(np.int64) % (1 << 32)
        if self._pending_master is not None:  # MASTERMV takes the first new value
            value, _ = self._pending_master
            self._pending_master = None
            self._mastered = (float(distance[0]), value)
            self._reply(self._pending_line)  # the reply precedes the first mastered block
        words = self._words(distance, code, counter, ticks, triggered)
        blocks = self._encode(words)
        fate = np.full(n, _SENT, dtype=np.int64)
        data = self._apply_byte_faults(blocks, byte_faults, fate)
        if not self._output_on:
            fate[:] = _OUTPUT_OFF
        elif not self._connected():
            fate[:] = _NO_CLIENT
        elif len(self._outbuf) + len(data) > _OUTBUF_LIMIT[self.transport or "socket"]:
            fate[:] = _OVERRUN
        else:
            self._send(data)
        self._record(counter, t_true, tau, distance, code, triggered, fate)

    def _triggered(self, t_true: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
        """Status bit 15 for the first sample at or after each trigger pulse."""
        pulses = self.tunnel.trigger_times(since=self._last_trigger)
        if pulses:
            self._last_trigger = max(pulses)
            self._pending_triggers.extend(pulses)
        flag = np.zeros(t_true.size, dtype=bool)
        keep = []
        for pulse in self._pending_triggers:
            after = np.flatnonzero(t_true >= pulse)
            if after.size:
                flag[after[0]] = True
            else:
                keep.append(pulse)
        self._pending_triggers = keep
        return flag

    def _words(self, distance: npt.NDArray[np.float64], code: npt.NDArray[np.int64],
               counter: npt.NDArray[np.int64], ticks: npt.NDArray[np.int64],
               triggered: npt.NDArray[np.bool_]) -> npt.NDArray[np.int64]:
        """Return the 18-bit values of each block: distance (or error value), then outputs."""
        mr = self.range_mm
        if self._mastered is None:
            value = np.rint((100.0 * distance / mr + 1.0) * 65520.0 / 102.0)
            value = np.clip(value, 0, 65520)
        else:
            position, master = self._mastered
            shifted = distance - position + master
            value = np.clip(np.rint((100.0 * shifted / mr + 51.0) * 65520.0 / 102.0),
                            0, 262074)
        first = np.where(code != 0, code, value.astype(np.int64))
        status = np.where(code == 0, 1 << 16, 1 << 17)  # LED green / red [unverified]
        status |= np.where(code == NO_PEAK, 1 << 2, 0)
        status |= np.where(code == BEFORE_RANGE, 1 << 5, 0)
        status |= np.where(code == BEHIND_RANGE, 1 << 6, 0)
        status |= np.where(triggered, 1 << 15, 0)
        n = distance.size
        columns = [first]
        for name in self.output:
            if name == "counter":
                columns.append(counter)
            elif name == "timestamp":
                columns += [ticks & 0xFFFF, ticks >> 16]
            elif name == "status":
                columns.append(status)
            elif name == "exposure":  # 0.1 us steps, about 500 us
                columns.append(np.full(n, 5000) + self.rng.integers(-20, 21, n))
            else:  # intensity, 1/65472 steps, about 60 %
                columns.append(np.full(n, 39283) + self.rng.integers(-300, 301, n))
        return np.column_stack(columns).astype(np.int64)

    @staticmethod
    def _encode(words: npt.NDArray[np.int64]) -> npt.NDArray[np.uint8]:
        """Three bytes per value, L M H, with the block flag f in the H byte."""
        n, m = words.shape
        out = np.empty((n, m, 3), dtype=np.uint8)
        out[:, :, 0] = words & 0x3F  # 00 D5..D0
        out[:, :, 1] = 0x40 | ((words >> 6) & 0x3F)  # 01 D11..D6
        out[:, :, 2] = 0x80 | ((words >> 12) & 0x3F)  # 1 f D17..D12
        out[:, 1:, 2] |= 0x40  # f = 1 for the additional values
        return out.reshape(n, 3 * m)

    def _apply_byte_faults(self, blocks: npt.NDArray[np.uint8],
                           faults: list[tuple[str, int, bytes, int]],
                           fate: npt.NDArray[np.int64]) -> bytes:
        size = self.block_bytes
        if not faults:
            return blocks.tobytes()
        data = bytearray(blocks.tobytes())
        shift = 0  # bytes removed or added so far (faults go into successive blocks)
        for row, (kind, offset, extra, n) in enumerate(faults):
            if row >= blocks.shape[0]:
                with self._lock:
                    self._byte_faults.insert(0, (kind, offset, extra, n))
                break
            where = row * size + offset + shift
            if kind == "drop":
                del data[where:where + n]
                last = min(blocks.shape[0] - 1, row + (offset + n - 1) // size)
                fate[row:last + 1] = _DESYNC
                shift -= n
            else:
                data[where:where] = extra
                if offset % size:
                    fate[row + offset // size] = _CORRUPTED
                shift += n
        return bytes(data)

    def _send(self, data: bytes) -> None:
        if self._connected():
            self._outbuf += data

    def _flush(self, block_s: float = 0.0) -> None:
        """Write queued bytes without blocking (or for up to ``block_s``)."""
        deadline = time.monotonic() + block_s
        while self._outbuf:
            try:
                if self._client is not None:
                    sent = self._client.send(self._outbuf)
                elif self._master_fd is not None:
                    sent = os.write(self._master_fd, self._outbuf)
                else:
                    self._outbuf.clear()
                    return
            except (BlockingIOError, InterruptedError):
                sent = 0
            except OSError as exc:
                self._drop_client(f"send failed: {exc}")
                return
            del self._outbuf[:sent]
            if sent == 0:
                if time.monotonic() >= deadline:
                    return
                writer: Any = self._client if self._client is not None else self._master_fd
                select.select([], [writer], [], 0.01)

    def _record(self, counter: npt.NDArray[np.int64], t_true: npt.NDArray[np.float64],
                tau: npt.NDArray[np.float64], distance: npt.NDArray[np.float64],
                code: npt.NDArray[np.int64], triggered: npt.NDArray[np.bool_],
                fate: npt.NDArray[np.int64]) -> None:
        n = counter.size
        part = {"counter": counter.astype(np.int64), "epoch": np.full(n, self._epoch),
                "t_true": t_true, "device_time": tau - self._ts_origin,
                "distance_mm": distance, "code": code, "triggered": triggered, "fate": fate}
        with self._lock:
            self.produced += n
            self.dropped += int(np.count_nonzero(fate != _SENT))
            self._truth.append(part)
            self._truth_size += n
            while self._truth_size - self._truth[0]["counter"].size >= self.truth_limit:
                self._truth_size -= self._truth.pop(0)["counter"].size
