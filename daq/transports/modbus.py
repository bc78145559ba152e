"""A thin Modbus register bus over pymodbus's synchronous clients, with one error channel.

Responsibility: open a Modbus client from a URL, move coils, discrete inputs and holding
registers with explicit 16-bit conversions, and turn every failure into one of windrig's
exceptions (docs/reference/architecture.md, "Design rules": one error channel):

- an exception response (``.isError()``: the device answered with a Modbus exception code) is a
  :class:`ModbusDeviceError` (a :class:`~daq.errors.DeviceError`) carrying the code and its text;
  it is never retried (asking again gets the same answer);
- no reply within the timeout is a :class:`~daq.errors.TransportTimeout`;
- a refused, reset or closed connection is a :class:`~daq.errors.TransportError`;
- a reply that cannot be decoded, or of the wrong length, is a :class:`~daq.errors.ProtocolError`.

Retries live here and only here (pymodbus's own retries are set to 0): a transport or protocol
failure closes the client and tries again after an exponential backoff, at most ``retries`` more
times, each retry logged at WARNING; then the last failure is raised. Every operation this bus
offers is idempotent (FC01/02/03 reads, FC05 write single coil, FC06 write single register: each
sets an absolute value), so repeating a request whose reply was lost is safe.

Not responsible for what the registers mean (the drivers), for scheduling polls, nor for byte
transports of non-Modbus devices (:mod:`daq.transports.byte_transport`).

URL schemes (docs/reference/wire_formats.md, "Transports and URLs"):

- ``modbus+tcp://host:port?unit=1`` (port 502 when omitted);
- ``modbus+rtu:///dev/ttyUSB0?baudrate=19200&parity=E&bytesize=8&stopbits=1&unit=1``.

Addresses are the zero-based addresses of the Modbus PDU ("holding register 40002 is addressed
as 0001 in a Modbus message", docs/reference/wire_formats.md, "Fan drive").
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar, runtime_checkable
from urllib.parse import parse_qs, unquote, urlsplit

from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException
from pymodbus.framer import FramerType
from pymodbus.pdu import ModbusPDU

from daq.errors import (
    ConfigError,
    ModbusDeviceError,
    ProtocolError,
    TransportError,
    TransportTimeout,
)

__all__ = [
    "EXCEPTION_CODES",
    "ModbusBus",
    "ModbusUrl",
    "RegisterBus",
    "from_int16",
    "parse_modbus_url",
    "to_int16",
]

log = logging.getLogger(__name__)

#: Modbus exception codes and their meaning (Modbus Application Protocol v1.1b3, section 7).
EXCEPTION_CODES: dict[int, str] = {
    0x01: "illegal function",
    0x02: "illegal data address",
    0x03: "illegal data value",
    0x04: "server device failure",
    0x05: "acknowledge",
    0x06: "server device busy",
    0x07: "negative acknowledge",
    0x08: "memory parity error",
    0x0A: "gateway path unavailable",
    0x0B: "gateway target device failed to respond",
}

#: Most bits / registers one read may ask for (Modbus Application Protocol v1.1b3, 6.1-6.3).
MAX_BITS = 2000
MAX_REGISTERS = 125

_T = TypeVar("_T")


# -- 16-bit conversions (explicit: a register is an unsigned 16-bit word on the wire) -----------
def to_int16(word: int) -> int:
    """Read an unsigned register word (0..65535) as a two's-complement signed value.

    >>> to_int16(0xFFFF), to_int16(20000), to_int16(0x8000)
    (-1, 20000, -32768)
    """
    if not 0 <= word <= 0xFFFF:
        raise ValueError(f"a register word is 0..65535, got {word!r}")
    return word - 0x10000 if word & 0x8000 else word


def from_int16(value: int) -> int:
    """Encode a signed value (-32768..32767) as the unsigned register word sent on the wire.

    >>> from_int16(-1), from_int16(20000)
    (65535, 20000)
    """
    if not -0x8000 <= value <= 0x7FFF:
        raise ValueError(f"a signed 16-bit value is -32768..32767, got {value!r}")
    return value & 0xFFFF


def check_uint16(value: int, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFFFF:
        raise ValueError(f"{what} must be an int 0..65535, got {value!r}")
    return value


# -- URLs ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ModbusUrl:
    """A parsed Modbus URL.

    Attributes
    ----------
    kind : str
        ``"tcp"`` or ``"rtu"``.
    host : str
        Host name (TCP) or serial device path (RTU).
    port : int
        TCP port (0 for RTU).
    unit : int
        Modbus unit / device id, 0..247.
    serial : dict
        ``baudrate``, ``parity``, ``bytesize``, ``stopbits`` (RTU only).
    """

    kind: str
    host: str
    port: int
    unit: int
    serial: dict[str, Any] = field(default_factory=dict)


def parse_modbus_url(url: str) -> ModbusUrl:
    """Parse ``modbus+tcp://host:port?unit=1`` or ``modbus+rtu:///dev/tty?baudrate=...``.

    Raises
    ------
    ConfigError
        Unknown scheme, missing host or device, unknown query key or a value out of range.
    """
    parts = urlsplit(url)
    query = {key: values[-1] for key, values in parse_qs(parts.query).items()}

    def integer(key: str, default: int, lo: int, hi: int) -> int:
        text = query.pop(key, None)
        if text is None:
            return default
        try:
            value = int(text)
        except ValueError as exc:
            raise ConfigError(f"{url}: {key} must be an integer, got {text!r}") from exc
        if not lo <= value <= hi:
            raise ConfigError(f"{url}: {key} = {value} is outside the allowed range [{lo}, {hi}]")
        return value

    if parts.scheme == "modbus+tcp":
        if not parts.hostname:
            raise ConfigError(f"expected modbus+tcp://host:port?unit=N, got {url!r}")
        try:
            port = parts.port or 502
        except ValueError as exc:
            raise ConfigError(f"{url}: bad port") from exc
        unit = integer("unit", 1, 0, 247)
        if query:
            raise ConfigError(f"{url}: unknown Modbus TCP setting(s) {sorted(query)}; "
                              "allowed: ['unit']")
        return ModbusUrl("tcp", parts.hostname, port, unit)
    if parts.scheme == "modbus+rtu":
        device = unquote(parts.path)
        if not device or parts.netloc:
            raise ConfigError(f"expected modbus+rtu:///dev/ttyX?baudrate=..., got {url!r}")
        unit = integer("unit", 1, 1, 247)  # 0 is broadcast on a serial line: no reply
        serial: dict[str, Any] = {
            "baudrate": integer("baudrate", 19200, 300, 4_000_000),
            "bytesize": integer("bytesize", 8, 7, 8),
            "stopbits": integer("stopbits", 1, 1, 2),
        }
        parity = query.pop("parity", "E")  # Modbus RTU's default framing is 8E1 (MODBUS over
        if parity not in ("N", "E", "O"):   # serial line v1.02, 2.5.1)
            raise ConfigError(f"{url}: parity must be one of N, E, O, got {parity!r}")
        serial["parity"] = parity
        if query:
            raise ConfigError(f"{url}: unknown Modbus RTU setting(s) {sorted(query)}; allowed: "
                              "['baudrate', 'bytesize', 'parity', 'stopbits', 'unit']")
        return ModbusUrl("rtu", device, 0, unit, serial)
    raise ConfigError(f"unsupported Modbus URL scheme {parts.scheme!r} in {url!r}; use "
                      "modbus+tcp:// or modbus+rtu://")


# -- the seam drivers depend on ------------------------------------------------------------------
@runtime_checkable
class RegisterBus(Protocol):
    """What a Modbus driver needs from its bus (implemented by :class:`ModbusBus`)."""

    url: str

    @property
    def is_open(self) -> bool:
        """Measure whether the bus is connected."""
        ...

    @property
    def timeout_s(self) -> float:
        """Control the reply timeout of one request, s."""
        ...

    @timeout_s.setter
    def timeout_s(self, value: float) -> None: ...

    def open(self) -> None:
        """Connect."""

    def close(self) -> None:
        """Disconnect; idempotent."""

    def exclusive(self) -> AbstractContextManager[Any]:
        """Hold the bus: no other thread's request runs until the block ends (reentrant)."""
        ...

    def read_coils(self, address: int, count: int = 1) -> list[bool]:
        """Read ``count`` coils (FC01)."""
        ...

    def read_discrete_inputs(self, address: int, count: int = 1) -> list[bool]:
        """Read ``count`` discrete inputs (FC02)."""
        ...

    def read_holding_registers(self, address: int, count: int = 1) -> list[int]:
        """Read ``count`` holding registers as unsigned words (FC03)."""
        ...

    def write_coil(self, address: int, value: bool) -> None:
        """Write one coil (FC05)."""

    def write_register(self, address: int, value: int) -> None:
        """Write one holding register, an unsigned word 0..65535 (FC06)."""


# -- the bus -------------------------------------------------------------------------------------
_Client = ModbusTcpClient | ModbusSerialClient


class ModbusBus:
    """One Modbus device (a unit on a TCP connection or a serial line), through pymodbus.

    Parameters
    ----------
    url : str
        ``modbus+tcp://host:port?unit=1`` or ``modbus+rtu:///dev/ttyUSB0?baudrate=19200&...``.
    timeout_s : float
        Reply timeout of one request (also the connect timeout), s.
    retries : int
        How many times a request that failed on the transport is repeated (0..10).
    backoff_s : float
        Wait before the first retry, s; doubled for each further retry.
    client : pymodbus sync client, optional
        A client to use instead of the one built from ``url`` (tests inject fakes here).

    Notes
    -----
    The constructor does no I/O; :meth:`open` connects. Methods are thread-safe (one lock
    serialises requests, retries included). A closed connection is re-opened by the next
    request, so a driver survives a device that went away and came back.
    """

    def __init__(self, url: str, *, timeout_s: float = 1.0, retries: int = 2,
                 backoff_s: float = 0.05, client: Any = None) -> None:
        self.url = url
        self.address = parse_modbus_url(url)
        if not (math.isfinite(timeout_s) and timeout_s > 0):
            raise ValueError(f"timeout_s must be > 0, got {timeout_s!r}")
        if isinstance(retries, bool) or not isinstance(retries, int) or not 0 <= retries <= 10:
            raise ValueError(f"retries must be an int 0..10, got {retries!r}")
        if not (math.isfinite(backoff_s) and backoff_s >= 0):
            raise ValueError(f"backoff_s must be >= 0, got {backoff_s!r}")
        self.unit = self.address.unit
        self.retries = retries
        self.backoff_s = float(backoff_s)
        self._timeout_s = float(timeout_s)
        self._client: Any = client
        self._injected = client is not None
        self._open = False
        self._lock = threading.RLock()
        #: Counters since construction: requests, retries, failures by kind.
        self.stats = {"requests": 0, "retries": 0, "device_errors": 0, "timeouts": 0,
                      "transport_errors": 0, "protocol_errors": 0}

    @classmethod
    def from_url(cls, url: str, **options: Any) -> ModbusBus:
        """Build a bus for ``url`` (same keyword options as the constructor)."""
        return cls(url, **options)

    def __repr__(self) -> str:
        return f"ModbusBus({self.url!r}, open={self._open})"

    # -- lifecycle -----------------------------------------------------------------------------
    def _make_client(self) -> _Client:
        a = self.address
        # retries=0: retrying is this layer's job only (docs/reference/architecture.md, "Design
        # rules").
        if a.kind == "tcp":
            return ModbusTcpClient(a.host, port=a.port, timeout=self._timeout_s, retries=0,
                                   name=self.url)
        return ModbusSerialClient(a.host, framer=FramerType.RTU, timeout=self._timeout_s,
                                  retries=0, name=self.url, **a.serial)

    @property
    def is_open(self) -> bool:
        """Measure whether :meth:`open` was called and :meth:`close` was not."""
        return self._open

    @property
    def timeout_s(self) -> float:
        """Control the reply timeout of one request (and the connect timeout), s."""
        return self._timeout_s

    @timeout_s.setter
    def timeout_s(self, value: float) -> None:
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"timeout_s must be > 0, got {value!r}")
        with self._lock:
            self._timeout_s = float(value)
            if self._client is not None and not self._injected:
                # pymodbus reads this field for connect, recv and the reply deadline.
                self._client.comm_params.timeout_connect = self._timeout_s

    def open(self) -> None:
        """Connect (with the bus's retries); idempotent.

        Raises
        ------
        TransportError
            The device cannot be reached.
        """
        with self._lock:
            if self._open:
                return
            if self._client is None:
                self._client = self._make_client()
            self._open = True
            try:
                self._with_retries("connect", self._connect)
            except BaseException:
                self._open = False
                self._client.close()
                raise

    def _connect(self, client: Any) -> None:
        if not client.connect():
            raise ConnectionException(f"cannot connect to {self.url}")

    def close(self) -> None:
        """Disconnect; idempotent."""
        with self._lock:
            self._open = False
            if self._client is not None:
                self._client.close()

    def __enter__(self) -> ModbusBus:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the one error channel ----------------------------------------------------------------
    def _with_retries(self, what: str, call: Callable[[Any], _T]) -> _T:
        """Run ``call(client)``; retry transport/protocol failures; normalise every error."""
        if not self._open:
            raise TransportError(f"{self.url}: bus not open")
        attempts = self.retries + 1
        for attempt in range(attempts):
            try:
                return call(self._client)
            except ModbusDeviceError:
                self.stats["device_errors"] += 1
                raise
            except (ModbusException, OSError) as exc:
                error = self._normalise(what, exc)
            self._client.close()  # a fresh connection discards any late reply
            if attempt + 1 == attempts:
                raise error from error.__cause__
            delay = self.backoff_s * 2**attempt
            self.stats["retries"] += 1
            log.warning("%s: %s failed (%s); retry %d of %d in %.3f s", self.url, what, error,
                        attempt + 1, self.retries, delay)
            time.sleep(delay)
        raise AssertionError("unreachable")  # pragma: no cover

    def _normalise(self, what: str, exc: BaseException) -> TransportError | ProtocolError:
        """Map a pymodbus / socket exception onto windrig's errors (cause attached)."""
        error: TransportError | ProtocolError
        if isinstance(exc, ModbusIOException) and "No response" in str(exc):
            # pymodbus transaction.py raises ModbusIOException("No response received ...")
            # when the reply deadline passes.
            self.stats["timeouts"] += 1
            error = TransportTimeout(f"{self.url}: {what}: no reply within {self._timeout_s:g} s")
        elif isinstance(exc, (ConnectionException, OSError)):
            self.stats["transport_errors"] += 1
            error = TransportError(f"{self.url}: {what}: connection failed: {exc}")
        else:  # ModbusIOException (undecodable reply, wrong id), ModbusException
            self.stats["protocol_errors"] += 1
            error = ProtocolError(f"{self.url}: {what}: bad reply: {exc}")
        error.__cause__ = exc
        return error

    def exclusive(self) -> AbstractContextManager[Any]:
        """Hold the bus: no other thread's request runs until the block ends (reentrant).

        For a caller that times a request (the PLC's trigger pulse): its clock readings then
        bracket the request alone, not the wait for another thread's poll.
        """
        return self._lock

    def _request(self, what: str, function_code: int,
                 send: Callable[[Any], ModbusPDU]) -> ModbusPDU:
        def call(client: Any) -> ModbusPDU:
            response = send(client)
            if response is None:
                raise ModbusIOException("No response received (empty result)")
            if response.isError():
                code = int(getattr(response, "exception_code", 0))
                text = EXCEPTION_CODES.get(code, "unknown exception code")
                raise ModbusDeviceError(
                    f"{self.url} unit {self.unit}: {what}: Modbus exception {code:#04x} "
                    f"({text})", code=code, function_code=function_code)
            return response

        with self._lock:
            self.stats["requests"] += 1
            return self._with_retries(what, call)

    # -- typed access ----------------------------------------------------------------------------
    @staticmethod
    def _check(address: int, count: int, max_count: int) -> None:
        check_uint16(address, "address")
        if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= max_count:
            raise ValueError(f"count must be an int 1..{max_count}, got {count!r}")
        if address + count > 0x10000:
            raise ValueError(f"address {address} + count {count} passes the end of the map")

    def _bits(self, response: ModbusPDU, count: int, what: str) -> list[bool]:
        bits = list(response.bits)
        if len(bits) < count:
            raise ProtocolError(f"{self.url}: {what}: {len(bits)} bits in the reply, "
                                f"expected {count}")
        return [bool(b) for b in bits[:count]]

    def read_coils(self, address: int, count: int = 1) -> list[bool]:
        """Read ``count`` coils from ``address`` (FC01)."""
        self._check(address, count, MAX_BITS)
        what = f"read {count} coil(s) at {address}"
        response = self._request(what, 1, lambda c: c.read_coils(
            address, count=count, device_id=self.unit))
        return self._bits(response, count, what)

    def read_discrete_inputs(self, address: int, count: int = 1) -> list[bool]:
        """Read ``count`` discrete inputs from ``address`` (FC02)."""
        self._check(address, count, MAX_BITS)
        what = f"read {count} discrete input(s) at {address}"
        response = self._request(what, 2, lambda c: c.read_discrete_inputs(
            address, count=count, device_id=self.unit))
        return self._bits(response, count, what)

    def read_holding_registers(self, address: int, count: int = 1) -> list[int]:
        """Read ``count`` holding registers from ``address`` as unsigned words 0..65535 (FC03)."""
        self._check(address, count, MAX_REGISTERS)
        what = f"read {count} holding register(s) at {address}"
        response = self._request(what, 3, lambda c: c.read_holding_registers(
            address, count=count, device_id=self.unit))
        registers = [int(r) for r in response.registers]
        if len(registers) != count or not all(0 <= r <= 0xFFFF for r in registers):
            raise ProtocolError(f"{self.url}: {what}: reply holds {registers!r}")
        return registers

    def read_uint16(self, address: int) -> int:
        """Read one holding register as an unsigned value 0..65535."""
        return self.read_holding_registers(address, 1)[0]

    def read_int16(self, address: int) -> int:
        """Read one holding register as a two's-complement signed value -32768..32767."""
        return to_int16(self.read_holding_registers(address, 1)[0])

    def write_coil(self, address: int, value: bool) -> None:
        """Write one coil (FC05)."""
        check_uint16(address, "address")
        if not isinstance(value, bool):
            raise ValueError(f"a coil value is a bool, got {value!r}")
        self._request(f"write coil {address} = {int(value)}", 5, lambda c: c.write_coil(
            address, value, device_id=self.unit))

    def write_register(self, address: int, value: int) -> None:
        """Write one holding register, an unsigned word 0..65535 (FC06)."""
        check_uint16(address, "address")
        check_uint16(value, "register value")
        self._request(f"write register {address} = {value:#06x}", 6, lambda c: c.write_register(
            address, value, device_id=self.unit))

    def write_uint16(self, address: int, value: int) -> None:
        """Write one holding register from an unsigned value 0..65535."""
        self.write_register(address, value)

    def write_int16(self, address: int, value: int) -> None:
        """Write one holding register from a signed value -32768..32767 (two's complement)."""
        self.write_register(address, from_int16(value))


