"""Byte transports opened from URLs: serial ports (pyserial) and TCP sockets.

Responsibility: move bytes with timeouts, and turn every low-level failure into a
:class:`~daq.errors.TransportError` (or :class:`~daq.errors.TransportTimeout`). Not responsible for
framing or protocols (the drivers), nor for Modbus (``daq.transports.modbus``, through pymodbus).

URL schemes (docs/reference/wire_formats.md, "Transports and URLs"):

- ``serial:///dev/ttyUSB0?baudrate=921600&bytesize=7&parity=E&stopbits=1&xonxoff=1``: a serial
  port (also a pty's slave end, e.g. ``serial:///dev/pts/5``);
- ``socket://127.0.0.1:5001``: a serial byte stream carried over TCP (the simulators serve serial
  instruments this way); opened as a plain TCP socket, see :func:`open_transport`;
- ``loop://``: pyserial's in-process loopback, for tests;
- ``tcp://host:port``: a plain TCP client socket (the pressure scanner).

Transports are created closed; :meth:`open` does the I/O. That keeps driver construction free of
I/O (docs/reference/architecture.md, "Design rules").
"""

from __future__ import annotations

import socket
import termios
import time
from collections.abc import Callable
from typing import Protocol, runtime_checkable
from urllib.parse import parse_qs, urlsplit

import serial

from daq.errors import ConfigError, TransportError, TransportTimeout

__all__ = ["LINE_SETTINGS", "SerialTransport", "TcpTransport", "Transport", "open_transport",
           "parse_serial_url"]

#: The line settings a driver's ``transport_defaults`` and a ``serial://`` query may set.
LINE_SETTINGS = ("baudrate", "bytesize", "parity", "stopbits", "xonxoff")

_PARITY = {"N": serial.PARITY_NONE, "E": serial.PARITY_EVEN, "O": serial.PARITY_ODD}
#: Read timeout the port keeps; reads loop on it up to their own deadline (granularity, s).
_POLL_S = 0.01
#: What pyserial can raise: its own exception, OS errors, and termios errors on ptys.
_SERIAL_ERRORS: tuple[type[BaseException], ...] = (serial.SerialException, OSError, termios.error)
#: Opening can also fail on a bad setting (ValueError from pyserial).
_OPEN_ERRORS: tuple[type[BaseException], ...] = (*_SERIAL_ERRORS, ValueError)


@runtime_checkable
class Transport(Protocol):
    """A bidirectional byte stream with timeouts."""

    url: str

    @property
    def is_open(self) -> bool:
        """Measure whether the transport is open."""
        ...

    def open(self) -> None:
        """Open the connection (the only place that does I/O to connect)."""

    def close(self) -> None:
        """Close the connection; idempotent."""

    def write(self, data: bytes) -> None:
        """Send all of ``data``."""

    def read(self, max_bytes: int, timeout_s: float) -> bytes:
        """Return between 1 and ``max_bytes`` bytes, or raise TransportTimeout."""
        ...

    def reset_input(self) -> None:
        """Discard bytes received but not yet read."""


class TransportBase:
    """Shared helpers built on :meth:`read`."""

    url: str

    def read(self, max_bytes: int, timeout_s: float) -> bytes:  # pragma: no cover - abstract
        raise NotImplementedError

    def read_exactly(self, n: int, timeout_s: float) -> bytes:
        """Read exactly ``n`` bytes within ``timeout_s`` in total, or raise TransportTimeout."""
        deadline = time.monotonic() + timeout_s
        chunks = bytearray()
        while len(chunks) < n:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TransportTimeout(
                    f"{self.url}: read {len(chunks)} of {n} bytes within {timeout_s:g} s"
                )
            chunks += self.read(n - len(chunks), remaining)
        return bytes(chunks)

    def read_until(self, terminator: bytes, timeout_s: float, max_bytes: int = 4096) -> bytes:
        """Read up to and including ``terminator`` within ``timeout_s`` (ASCII replies)."""
        deadline = time.monotonic() + timeout_s
        buffer = bytearray()
        while not buffer.endswith(terminator):
            if len(buffer) >= max_bytes:
                raise TransportError(
                    f"{self.url}: no {terminator!r} within {max_bytes} bytes: {bytes(buffer)!r}"
                )
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TransportTimeout(
                    f"{self.url}: no {terminator!r} within {timeout_s:g} s "
                    f"(received {bytes(buffer)!r})"
                )
            buffer += self.read(1, remaining)
        return bytes(buffer)


class SerialTransport(TransportBase):
    """A pyserial port: a device path (``serial://``, also a pty) or pyserial's ``loop://``.

    Parameters
    ----------
    url : str
        ``serial:///dev/ttyUSB0?...`` or ``loop://``.
    baudrate, bytesize, parity, stopbits, xonxoff :
        Line settings.
    """

    def __init__(
        self, url: str, *, baudrate: int = 9600, bytesize: int = 8, parity: str = "N",
        stopbits: float = 1, xonxoff: bool = False,
    ) -> None:
        if parity not in _PARITY:
            raise ConfigError(f"{url}: parity must be one of N, E, O, got {parity!r}")
        self.url = url
        self._port = parse_serial_url(url)
        self._settings = {
            "baudrate": baudrate, "bytesize": bytesize, "parity": _PARITY[parity],
            "stopbits": stopbits, "xonxoff": xonxoff,
        }
        self._serial: serial.SerialBase | None = None

    @property
    def is_open(self) -> bool:
        """Measure whether the port is open."""
        return self._serial is not None and bool(self._serial.is_open)

    def open(self) -> None:
        """Open the port."""
        if self.is_open:
            return
        try:
            self._serial = serial.serial_for_url(self._port, timeout=_POLL_S, **self._settings)
        except _OPEN_ERRORS as exc:
            raise TransportError(f"{self.url}: cannot open: {exc}") from exc

    def close(self) -> None:
        """Close the port; idempotent."""
        # Detach before closing: pyserial drops its descriptor before it clears is_open, so
        # a read in another thread that fails in between must already see the port as ours
        # to close (not a bug to re-raise).
        port, self._serial = self._serial, None
        if port is not None:
            port.close()

    def _port_or_raise(self) -> serial.SerialBase:
        if self._serial is None or not self._serial.is_open:
            raise TransportError(f"{self.url}: not open")
        return self._serial

    def _raise_if_not_closed_under(self, port: serial.SerialBase) -> None:
        """Re-raise the exception being handled unless ``port`` was closed meanwhile.

        pyserial using a port that another thread closed (its descriptor is None) raises
        TypeError or AttributeError: a closed port, not a bug of ours. Anything else is
        re-raised as it is.
        """
        if port.is_open and self._serial is port:
            raise

    def write(self, data: bytes) -> None:
        """Send all of ``data``."""
        port = self._port_or_raise()
        try:
            port.write(data)
            port.flush()
        except _SERIAL_ERRORS as exc:
            raise TransportError(f"{self.url}: write failed: {exc}") from exc
        except (TypeError, AttributeError) as exc:
            self._raise_if_not_closed_under(port)
            raise TransportError(f"{self.url}: closed during the write") from exc

    def read(self, max_bytes: int, timeout_s: float) -> bytes:
        """Return 1..max_bytes bytes, or raise TransportTimeout after ``timeout_s``.

        The port keeps one short read timeout (set at open) and this loops until the deadline:
        changing pyserial's timeout reconfigures the port (a system call per read, and on a pty
        a termios error for settings it cannot take).
        """
        port = self._port_or_raise()
        deadline = time.monotonic() + max(timeout_s, 0.0)
        try:
            while True:
                first = port.read(1)
                if first or time.monotonic() >= deadline:
                    break
            waiting = min(port.in_waiting, max_bytes - 1) if first else 0
            rest = port.read(waiting) if waiting > 0 else b""
        except _SERIAL_ERRORS as exc:
            raise TransportError(f"{self.url}: read failed: {exc}") from exc
        except (TypeError, AttributeError) as exc:
            self._raise_if_not_closed_under(port)
            raise TransportError(f"{self.url}: closed during the read") from exc
        if not first:
            raise TransportTimeout(f"{self.url}: no data within {timeout_s:g} s")
        return first + rest

    def reset_input(self) -> None:
        """Discard unread input."""
        self._port_or_raise().reset_input_buffer()


class TcpTransport(TransportBase):
    """A TCP client socket (``tcp://host:port``)."""

    def __init__(self, url: str, *, connect_timeout_s: float = 3.0) -> None:
        parts = urlsplit(url)
        if parts.scheme not in ("tcp", "socket") or not parts.hostname or parts.port is None:
            raise ConfigError(f"expected tcp://host:port (or socket://host:port), got {url!r}")
        self.url = url
        self.host, self.port = parts.hostname, parts.port
        self.connect_timeout_s = connect_timeout_s
        self._socket: socket.socket | None = None

    @property
    def is_open(self) -> bool:
        """Measure whether the socket is connected."""
        return self._socket is not None

    def open(self) -> None:
        """Connect."""
        if self._socket is not None:
            return
        try:
            sock = socket.create_connection((self.host, self.port), self.connect_timeout_s)
        except OSError as exc:
            raise TransportError(f"{self.url}: cannot connect: {exc}") from exc
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._socket = sock

    def close(self) -> None:
        """Close the socket; idempotent."""
        if self._socket is not None:
            try:
                self._socket.close()
            finally:
                self._socket = None

    def _socket_or_raise(self) -> socket.socket:
        if self._socket is None:
            raise TransportError(f"{self.url}: not connected")
        return self._socket

    def write(self, data: bytes) -> None:
        """Send all of ``data``."""
        sock = self._socket_or_raise()
        try:
            sock.settimeout(self.connect_timeout_s)
            sock.sendall(data)
        except OSError as exc:
            raise TransportError(f"{self.url}: send failed: {exc}") from exc

    def read(self, max_bytes: int, timeout_s: float) -> bytes:
        """Return 1..max_bytes bytes, or raise TransportTimeout; a closed peer is an error."""
        sock = self._socket_or_raise()
        try:
            sock.settimeout(max(timeout_s, 1e-6))
            data = sock.recv(max_bytes)
        except TimeoutError as exc:
            raise TransportTimeout(f"{self.url}: no data within {timeout_s:g} s") from exc
        except OSError as exc:
            raise TransportError(f"{self.url}: receive failed: {exc}") from exc
        if not data:
            raise TransportError(f"{self.url}: connection closed by the peer")
        return data

    def reset_input(self) -> None:
        """Discard whatever is already received."""
        sock = self._socket_or_raise()
        sock.setblocking(False)
        try:
            while sock.recv(65536):
                pass
        except (BlockingIOError, InterruptedError):
            pass  # nothing more waiting: exactly what we wanted
        finally:
            sock.setblocking(True)


def parse_serial_url(url: str) -> str:
    """Map ``serial:///dev/x?...`` to pyserial's port name; pass pyserial URLs through."""
    parts = urlsplit(url)
    if parts.scheme == "serial":
        if not parts.path:
            raise ConfigError(f"serial URL needs a device path: {url!r}")
        return parts.path
    if parts.scheme == "loop":
        return url.split("?", 1)[0]
    raise ConfigError(f"not a serial URL (serial://, loop://): {url!r}")


def open_transport(url: str, **defaults: object) -> SerialTransport | TcpTransport:
    """Create (not open) the transport for ``url``.

    Query parameters of a ``serial://`` URL override ``defaults`` (baudrate, bytesize, parity,
    stopbits, xonxoff); an unknown key, in either, is a :class:`ConfigError` (whatever the
    scheme: a misspelt driver default must not pass unnoticed on the simulator's
    ``socket://`` and fail only on the real port). Line settings mean nothing to ``socket://``
    and ``tcp://`` streams and are ignored there.
    """
    unknown = sorted(set(defaults) - set(LINE_SETTINGS))
    if unknown:
        raise ConfigError(f"{url}: unknown line setting(s) {unknown} in the driver's "
                          f"transport_defaults; allowed: {list(LINE_SETTINGS)}")
    parts = urlsplit(url)
    if parts.scheme in ("tcp", "socket"):
        # socket:// is a serial byte stream carried over TCP. pyserial's own handler reports at
        # most one waiting byte (so a 4 kHz stream costs ~24 000 reads/s) and sleeps 0.3 s on
        # close; a plain TCP socket carries the same bytes without either cost.
        return TcpTransport(url)
    if parts.scheme in ("serial", "loop"):
        settings = dict(defaults)
        converters: dict[str, Callable[[str], object]] = {
            "baudrate": int, "bytesize": int, "parity": str, "stopbits": float,
            "xonxoff": lambda s: s not in ("0", "false", "False"),
        }
        for key, values in parse_qs(parts.query).items():
            if key not in converters:
                raise ConfigError(f"{url}: unknown serial setting {key!r}; "
                                  f"allowed: {sorted(converters)}")
            try:
                settings[key] = converters[key](values[-1])
            except ValueError as exc:
                raise ConfigError(f"{url}: bad value for {key}: {values[-1]!r}") from exc
        return SerialTransport(url if parts.scheme == "serial" else url.split("?", 1)[0],
                               **settings)  # type: ignore[arg-type]
    raise ConfigError(f"unsupported transport URL scheme {parts.scheme!r} in {url!r}; "
                      "use serial://, socket://, loop:// or tcp://")
