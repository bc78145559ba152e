"""A simulated DSA3217: its commands and binary packets over TCP on 127.0.0.1.

Serves one client at a time on an ephemeral loopback port (``start()`` returns the
``tcp://`` URL), answers ``STATUS``, takes the ``SET`` commands the driver sends, and while
scanning sends one 112-byte "Scan EU with Time" packet per frame (packed here with
``struct``, independently of the driver's numpy decoder), the pressures the virtual tunnel
gives at each frame's true time, in psi, with noise and a zero offset that ``CALZ`` removes.
``drop_frames`` numbers frames it counts but never sends (a gap the driver must report).
"""

from __future__ import annotations

import math
import socket
import struct
import threading
from collections.abc import Sequence
from typing import Any

import numpy as np

from daq.sim.devices import SimulatorEntry
from simulators.clock import DeviceClock
from windrig_dsa3217.settings import CHANNELS, PSI_PA

_PACKET = struct.Struct("<hhi16f16hIi")


class SimDsa3217:
    """A DSA3217 of the virtual tunnel, serving its protocol on 127.0.0.1."""

    def __init__(self, tunnel: Any, *, rate_hz: float = 100.0, pitot_channel: int = 15,
                 tap_channels: Sequence[int] | None = None,
                 pitot_error: tuple[Any, ...] = (1.0, 0.0), noise_pa: float = 1.0,
                 sensor_offset_pa: float = 10.0, calz_duration_s: float = 0.2,
                 drop_frames: Sequence[int] = (), clock: DeviceClock | None = None,
                 rng: np.random.Generator | int | None = None) -> None:
        n_taps = tunnel.taps.n_taps
        self.tap_channels = list(range(n_taps)) if tap_channels is None else list(tap_channels)
        if n_taps + 1 > CHANNELS or pitot_channel in self.tap_channels:
            raise ValueError(f"{n_taps} taps and the Pitot (channel {pitot_channel}) do not fit "
                             f"in {CHANNELS} channels")
        self.tunnel, self.rate_hz, self.pitot_channel = tunnel, float(rate_hz), pitot_channel
        self.pitot_error, self.noise_pa = tuple(pitot_error), float(noise_pa)
        self.calz_duration_s, self.drop_frames = float(calz_duration_s), set(drop_frames)
        self.clock = clock if clock is not None else DeviceClock()
        self._rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self._offset = self._rng.normal(0.0, sensor_offset_pa, CHANNELS)
        self._zero = np.zeros(CHANNELS)
        self._state, self._calz_end = "READY", 0.0
        self._stop = threading.Event()
        self._listener: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self.url: str | None = None

    def start(self) -> str:
        """Listen on 127.0.0.1 (loopback only); return the ``tcp://`` URL."""
        self._listener = socket.create_server(("127.0.0.1", 0))
        self._listener.settimeout(0.1)
        self.url = f"tcp://127.0.0.1:{self._listener.getsockname()[1]}"
        self._thread = threading.Thread(target=self._serve, name="sim-dsa3217", daemon=True)
        self._thread.start()
        return self.url

    def stop(self) -> None:
        """Stop serving; idempotent."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
        if self._listener is not None:
            self._listener.close()

    def true_time_of(self, device_time: Any) -> Any:
        """Return the true time (s, tunnel clock) of frames stamped ``device_time`` (s)."""
        t = np.asarray(device_time, dtype=np.float64)
        return (t - self.clock.offset_s) / (1.0 + 1e-6 * self.clock.drift_ppm)

    # -- serving -----------------------------------------------------------------------------
    def _serve(self) -> None:
        assert self._listener is not None
        while not self._stop.is_set():
            try:
                conn, _ = self._listener.accept()
            except TimeoutError:
                continue
            with conn:
                self._session(conn)
            self._state = "READY"  # a dropped client ends its scan

    def _session(self, conn: socket.socket) -> None:
        conn.settimeout(0.002)
        pending, frame, t0 = b"", 0, 0.0
        while not self._stop.is_set():
            try:
                data = conn.recv(4096)
                if not data:
                    return
                pending += data
            except TimeoutError:
                pass
            except OSError:
                return
            while b"\n" in pending:
                line, pending = pending.split(b"\n", 1)
                reply, started = self._command(line.strip().decode("ascii", "replace"))
                if started:
                    frame, t0 = 0, self.clock.device_time(self.tunnel.clock.now())
                if reply:
                    conn.sendall(reply)
            if self._state == "SCAN":
                frame = self._send_due(conn, frame, t0)

    def _command(self, line: str) -> tuple[bytes, bool]:
        now = self.tunnel.clock.now()
        if self._state == "CALZ" and now >= self._calz_end:
            self._zero = self._offset.copy()
            self._state = "READY"
        word = line.split(" ", 1)[0].upper()
        if word == "STATUS":
            return f"STATUS: {self._state}\r\n".encode("ascii"), False
        if word == "SCAN" and self._state == "READY":
            self._state = "SCAN"
            return b"", True
        if word == "STOP" and self._state == "SCAN":
            self._state = "READY"
        elif word == "CALZ" and self._state == "READY":
            self._state, self._calz_end = "CALZ", now + self.calz_duration_s
        return b"", False

    def _send_due(self, conn: socket.socket, sent: int, t0: float) -> int:
        """Send every frame due by now after frame ``sent``; return the last frame number."""
        t_dev_now = self.clock.device_time(self.tunnel.clock.now())
        due = math.floor((t_dev_now - t0) * self.rate_hz + 1e-9) + 1
        if due <= sent:
            return sent
        numbers = np.arange(sent + 1, due + 1)
        t_dev = t0 + (numbers - 1) / self.rate_hz
        t_true = np.array([self.clock.true_time(t) for t in t_dev])
        taps, qd = self.tunnel.pressures(t_true)
        p = np.zeros((numbers.size, CHANNELS))
        p[:, self.tap_channels] = taps
        factor, offset = (float(v) for v in self.pitot_error[:2])
        p[:, self.pitot_channel] = (qd - offset) / factor
        p += self._offset - self._zero + self.noise_pa * self._rng.standard_normal(p.shape)
        out = bytearray()
        for i, number in enumerate(numbers.tolist()):
            if number in self.drop_frames:
                continue
            stamp = round(t_dev[i] * 1e6) & 0xFFFFFFFF  # microseconds, 32 bits
            out += _PACKET.pack(7, 0, number, *(p[i] / PSI_PA), *([2500] * CHANNELS), stamp, 1)
        try:
            conn.sendall(out)
        except OSError:
            self._state = "READY"
        return int(numbers[-1])


def _build(tunnel: Any, settings: Any, **options: Any) -> SimDsa3217:
    return SimDsa3217(tunnel, rate_hz=float(settings["rate_hz"]),
                      pitot_channel=int(settings.get("pitot_channel", CHANNELS - 1)), **options)


SIMULATOR = SimulatorEntry("scanivalve_dsa3217", _build, SimDsa3217)
