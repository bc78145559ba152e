"""A pymodbus TCP server on 127.0.0.1 in its own thread: the base of the Modbus simulators.

Shared by the simulated fan drive (:mod:`simulators.devices.abb_acs580`) and the simulated PLC
(:mod:`simulators.devices.modbus_plc`). Responsible for serving, stopping cleanly (no leaked
threads) and the transport-level faults (no reply, disconnect); the devices own their registers.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import threading
from collections.abc import Callable, Mapping, Sequence

from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import SimDevice

__all__ = ["ModbusServerThread", "ModbusSimulator", "bits_into_registers"]

log = logging.getLogger(__name__)


def _free_port() -> int:
    """Return a TCP port on 127.0.0.1 that is free right now (pymodbus wants an explicit one)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


class ModbusServerThread:
    """A pymodbus TCP server on 127.0.0.1 in a background thread with its own asyncio loop.

    Parameters
    ----------
    name : str
        Thread name prefix.
    device : callable
        Builds the :class:`pymodbus.simulator.SimDevice` (called inside the server loop).
    ticks : sequence of (period_s, callable)
        Functions called periodically in the server loop (e.g. a ramp generator).

    Notes
    -----
    Fault hooks shared by the Modbus simulators: :meth:`drop_replies` (the server reads a
    request and sends nothing back: the client times out) and :meth:`disconnect` (every
    connection is closed and new ones are refused for an outage, then the server listens again
    on the same port).
    """

    def __init__(self, name: str, device: Callable[[], SimDevice],
                 ticks: Sequence[tuple[float, Callable[[], None]]] = ()) -> None:
        self.name = name
        self._device = device
        self._ticks = tuple(ticks)
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._server: ModbusTcpServer | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._lock = threading.Lock()
        self._drop_remaining: int | None = 0  # None: drop every reply until cleared
        self.port = 0
        #: Truth counters: request packets received, replies sent, replies dropped by fault
        #: injection, disconnects injected.
        self.counters = {"requests": 0, "replies": 0, "replies_dropped": 0, "disconnects": 0}

    # -- lifecycle -----------------------------------------------------------------------------
    @property
    def running(self) -> bool:
        """Measure whether the server thread is alive."""
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> int:
        """Start the thread; return the port it listens on (127.0.0.1 only)."""
        if self.running:
            return self.port
        for _attempt in range(5):  # a port found free may be taken before we bind it
            self.port = _free_port()
            self._ready.clear()
            self._error = None
            self._thread = threading.Thread(target=self._run, name=f"{self.name}:{self.port}",
                                            daemon=True)
            self._thread.start()
            if not self._ready.wait(10.0):
                raise RuntimeError(f"{self.name}: server did not start within 10 s")
            error = self._start_error()
            if error is None:
                return self.port
            self._thread.join(5.0)
            self._thread = None
        raise RuntimeError(f"{self.name}: could not listen on 127.0.0.1: {self._error}")

    def _start_error(self) -> BaseException | None:
        return self._error  # set by the server thread

    def stop(self) -> None:
        """Stop the server and join its thread; idempotent."""
        thread, loop, stop = self._thread, self._loop, self._stop
        if thread is None:
            return
        if loop is not None and stop is not None and thread.is_alive():
            try:
                loop.call_soon_threadsafe(stop.set)
            except RuntimeError:  # the loop already closed: the thread is ending
                pass
        thread.join(10.0)
        if thread.is_alive():  # pragma: no cover - would be a bug; conftest reports the leak
            raise RuntimeError(f"{self.name}: server thread did not stop")
        self._thread = None

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            loop.run_until_complete(self._main())
        except BaseException as exc:  # reported to start(); the thread must not die silently
            self._error = exc
            self._ready.set()
        finally:
            try:
                pending = [t for t in asyncio.all_tasks(loop) if not t.done()]
                for task in pending:
                    task.cancel()
                if pending:
                    loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
                loop.run_until_complete(loop.shutdown_asyncgens())
            finally:
                loop.close()
                self._loop = None

    async def _main(self) -> None:
        self._stop = asyncio.Event()
        server = ModbusTcpServer(self._device(), address=("127.0.0.1", self.port),
                                 trace_packet=self._trace_packet)
        self._server = server
        await server.serve_forever(background=True)  # RuntimeError if it cannot listen
        tasks = [asyncio.create_task(self._tick(period, fn)) for period, fn in self._ticks]
        self._ready.set()
        try:
            await self._stop.wait()
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            await server.shutdown()
            # Let the transports run their connection_lost callbacks (they close the sockets).
            for _ in range(3):
                await asyncio.sleep(0.005)
            self._server = None

    @staticmethod
    async def _tick(period_s: float, fn: Callable[[], None]) -> None:
        while True:
            fn()
            await asyncio.sleep(period_s)

    # -- running code in the server loop -----------------------------------------------------
    def call_soon(self, fn: Callable[[], None]) -> None:
        """Run ``fn`` in the server loop (thread-safe; for timers and state changes)."""
        if self._loop is None:
            raise RuntimeError(f"{self.name}: not running")
        self._loop.call_soon_threadsafe(fn)

    def call_later(self, delay_s: float, fn: Callable[[], None]) -> None:
        """Run ``fn`` in the server loop after ``delay_s`` (call from the server loop)."""
        if self._loop is None:
            raise RuntimeError(f"{self.name}: not running")
        self._loop.call_later(delay_s, fn)

    # -- faults ----------------------------------------------------------------------------------
    def drop_replies(self, count: int | None) -> None:
        """Send no reply to the next ``count`` requests (None: to every request; 0: stop)."""
        with self._lock:
            self._drop_remaining = count

    def _trace_packet(self, sending: bool, data: bytes) -> bytes:
        # pymodbus calls this with every packet received (sending=False) and every reply about to
        # be sent (sending=True); an empty reply is written as nothing at all.
        if not sending:
            self.counters["requests"] += 1
            return data
        with self._lock:
            drop = self._drop_remaining is None or self._drop_remaining > 0
            if drop and self._drop_remaining is not None:
                self._drop_remaining -= 1
        if drop:
            self.counters["replies_dropped"] += 1
            return b""
        self.counters["replies"] += 1
        return data

    def disconnect(self, outage_s: float = 0.0) -> None:
        """Close every client connection; refuse new ones for ``outage_s``; then listen again.

        Returns once the connections are closed (the outage goes on in the server loop).
        """
        if self._loop is None or self._server is None:
            raise RuntimeError(f"{self.name}: not running")
        closed = threading.Event()

        async def outage() -> None:
            server = self._server
            if server is None:
                return
            server.close()  # the listener and every active connection
            self.counters["disconnects"] += 1
            closed.set()
            await asyncio.sleep(outage_s)
            if self._server is server and not self._stop_requested():
                if not await server.listen():
                    log.error("%s: could not listen again on port %d", self.name, self.port)

        asyncio.run_coroutine_threadsafe(outage(), self._loop)
        if not closed.wait(5.0):
            raise RuntimeError(f"{self.name}: disconnect did not happen")

    def _stop_requested(self) -> bool:
        return self._stop is not None and self._stop.is_set()


def bits_into_registers(registers: list[int], start: int, bits: Mapping[int, bool]) -> None:
    """Write bit values into pymodbus's packed bit block (16 bits per word, bit 0 first)."""
    for address, value in bits.items():
        index = address // 16 - start
        if 0 <= index < len(registers):
            mask = 1 << (address % 16)
            registers[index] = (registers[index] | mask) if value else (registers[index] & ~mask)


class ModbusSimulator:
    """Lifecycle shared by the Modbus simulators: a :class:`ModbusServerThread` and a unit id.

    Subclasses set ``self._server`` and ``self.unit`` in their constructor.
    """

    _server: ModbusServerThread
    unit: int

    def start(self) -> str:
        """Start the Modbus TCP server on 127.0.0.1; return the driver's URL."""
        self._server.start()
        return self.url

    def stop(self) -> None:
        """Stop the server and join its thread; idempotent."""
        self._server.stop()

    def __enter__(self) -> ModbusSimulator:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def url(self) -> str:
        """Measure the URL of the running server."""
        return f"modbus+tcp://127.0.0.1:{self._server.port}?unit={self.unit}"

    @property
    def counters(self) -> dict[str, int]:
        """Measure the server's truth counters (requests, replies, drops, disconnects)."""
        return dict(self._server.counters)
