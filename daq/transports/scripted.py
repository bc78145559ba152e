"""Scripted transports for driver tests: byte exchanges and Modbus register calls, no I/O.

``expected_exchange([(sent, reply), ...])`` yields an open :class:`ScriptedTransport`; the driver
under test writes to it and reads from it. Every write must match the next expected ``sent``
bytes exactly (a mismatch fails at once, showing both in hex), after which ``reply`` becomes
readable; on exit every pair must have been consumed. A pair with ``sent = b""`` is unsolicited
data (a stream) that is readable as soon as the previous pair is done. Modelled on pymeasure's
``expected_protocol``.

``expected_bus_calls([(method, address, value, result), ...])`` does the same one level up, for
the Modbus drivers: it yields a :class:`ScriptedBus` (a
:class:`~daq.transports.modbus.RegisterBus`) that plays the expected register calls.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import AbstractContextManager, contextmanager, nullcontext
from typing import Any

from daq.errors import TransportError, TransportTimeout
from daq.transports.byte_transport import TransportBase
from daq.transports.modbus import check_uint16

__all__ = ["ScriptedTransport", "expected_exchange",]


class ScriptedTransport(TransportBase):
    """A transport that plays a fixed script of (expected write, reply) pairs."""

    def __init__(self, exchanges: Sequence[tuple[bytes, bytes]],
                 url: str = "scripted://") -> None:
        self.url = url
        self._script = [(bytes(s), bytes(r)) for s, r in exchanges]
        self._next = 0
        self._pending = bytearray()  # bytes written towards the next expected `sent`
        self._readable = bytearray()
        self._open = False
        self._release_unsolicited()

    @property
    def is_open(self) -> bool:
        """Measure whether the transport is open."""
        return self._open

    def open(self) -> None:
        """Open (no I/O)."""
        self._open = True

    def close(self) -> None:
        """Close; idempotent."""
        self._open = False

    def _release_unsolicited(self) -> None:
        while self._next < len(self._script) and self._script[self._next][0] == b"":
            self._readable += self._script[self._next][1]
            self._next += 1

    def write(self, data: bytes) -> None:
        """Check ``data`` against the script; queue the reply once a `sent` is complete."""
        if not self._open:
            raise TransportError(f"{self.url}: not open")
        for byte in data:
            if self._next >= len(self._script):
                raise AssertionError(f"unexpected write after the script ended: {data.hex(' ')}")
            expected = self._script[self._next][0]
            self._pending.append(byte)
            if not expected.startswith(bytes(self._pending)):
                raise AssertionError(
                    f"exchange {self._next}: expected {expected!r} ({expected.hex(' ')}), "
                    f"got {bytes(self._pending)!r} ({bytes(self._pending).hex(' ')})"
                )
            if bytes(self._pending) == expected:
                self._readable += self._script[self._next][1]
                self._pending.clear()
                self._next += 1
                self._release_unsolicited()

    def read(self, max_bytes: int, timeout_s: float) -> bytes:
        """Return scripted reply bytes; none left is a timeout (without waiting)."""
        if not self._open:
            raise TransportError(f"{self.url}: not open")
        if not self._readable:
            raise TransportTimeout(f"{self.url}: no scripted data left to read")
        out = bytes(self._readable[:max_bytes])
        del self._readable[:max_bytes]
        return out

    def reset_input(self) -> None:
        """Discard readable bytes."""
        self._readable.clear()

    def assert_complete(self) -> None:
        """Fail unless every exchange happened and every reply byte was read."""
        if self._next < len(self._script) or self._pending:
            raise AssertionError(
                f"script incomplete: {self._next} of {len(self._script)} exchanges done; "
                f"next expected {self._script[self._next][0]!r}" if self._next < len(self._script)
                else f"partial write {bytes(self._pending)!r} at the end"
            )
        if self._readable:
            raise AssertionError(f"reply bytes never read: {bytes(self._readable)!r}")


@contextmanager
def expected_exchange(exchanges: Sequence[tuple[bytes, bytes]]) -> Iterator[ScriptedTransport]:
    """Yield an open scripted transport and check on exit that the script was played fully."""
    transport = ScriptedTransport(exchanges)
    transport.open()
    yield transport
    transport.assert_complete()


# -- scripted bus for driver tests ---------------------------------------------------------------
class ScriptedBus:
    """A :class:`RegisterBus` that plays a script of expected calls (driver tests, no I/O).

    Each script entry is ``(method, address, value_or_count, result)``: a write is
    ``("write_register", 0, 0x047F, None)``; a read is ``("read_holding_registers", 3, 2, [0x0237,
    1000])``; ``result`` may also be an exception instance, which the call raises. Any other call
    fails at once with both calls shown; :meth:`assert_complete` checks that the whole script was
    played (the register-level analogue of :func:`daq.transports.scripted.expected_exchange`).
    """

    def __init__(self, script: Sequence[tuple[str, int, Any, Any]],
                 url: str = "modbus+tcp://scripted:502?unit=1") -> None:
        self.url = url
        self._script = list(script)
        self._next = 0
        self._open = False
        self._timeout_s = 1.0

    @property
    def is_open(self) -> bool:
        """Measure whether the scripted bus is open."""
        return self._open

    @property
    def timeout_s(self) -> float:
        """Control the (unused) reply timeout, s."""
        return self._timeout_s

    @timeout_s.setter
    def timeout_s(self, value: float) -> None:
        self._timeout_s = float(value)

    def open(self) -> None:
        """Open (no I/O)."""
        self._open = True

    def exclusive(self) -> AbstractContextManager[Any]:
        """Hold the bus (a script plays in one thread: nothing to hold)."""
        return nullcontext()

    def close(self) -> None:
        """Close; idempotent."""
        self._open = False

    def _play(self, method: str, address: int, arg: Any) -> Any:
        if not self._open:
            raise TransportError(f"{self.url}: bus not open")
        got = (method, address, arg)
        if self._next >= len(self._script):
            raise AssertionError(f"unexpected call after the script ended: {got}")
        expected = self._script[self._next]
        if tuple(expected[:3]) != got:
            raise AssertionError(f"call {self._next}: expected {expected[:3]}, got {got}")
        self._next += 1
        result = expected[3]
        if isinstance(result, BaseException):
            raise result
        return result

    def read_coils(self, address: int, count: int = 1) -> list[bool]:
        """Play a scripted FC01."""
        return list(self._play("read_coils", address, count))

    def read_discrete_inputs(self, address: int, count: int = 1) -> list[bool]:
        """Play a scripted FC02."""
        return list(self._play("read_discrete_inputs", address, count))

    def read_holding_registers(self, address: int, count: int = 1) -> list[int]:
        """Play a scripted FC03."""
        return list(self._play("read_holding_registers", address, count))

    def write_coil(self, address: int, value: bool) -> None:
        """Play a scripted FC05."""
        self._play("write_coil", address, value)

    def write_register(self, address: int, value: int) -> None:
        """Play a scripted FC06."""
        check_uint16(value, "register value")
        self._play("write_register", address, value)

    def assert_complete(self) -> None:
        """Fail unless every scripted call happened."""
        if self._next < len(self._script):
            raise AssertionError(f"script incomplete: {self._next} of {len(self._script)} calls "
                                 f"done; next expected {self._script[self._next][:3]}")


@contextmanager
def expected_bus_calls(script: Sequence[tuple[str, int, Any, Any]]) -> Iterator[ScriptedBus]:
    """Yield an open :class:`ScriptedBus`; on exit check that the script was played fully."""
    bus = ScriptedBus(script)
    bus.open()
    yield bus
    bus.assert_complete()
