"""The simulated scanner's TCP servers on 127.0.0.1: ASCII commands, and a data port per module.

Responsibility: :func:`serve_commands`, the command server (lines ended by CR, LF or CR LF from
any number of clients, each answered by the scanner's ``handle_command``); :class:`DataPort`,
one 64-channel module's binary data server (module ``k`` on port ``data_port + k``): the frames
waiting for the client (a bounded buffer the scanner fills), the one client it sends them to
(the newest connection wins), the frames that went out (:class:`~.truth.SimTruth`'s ``sent``)
and those lost in a TCP reset, a superseded scan or a client gone (its ``dropped``);
:func:`bind_consecutive`, the consecutive ports of the data servers.

Not responsible for: what the commands do or what the frames hold
(:mod:`simulators.devices.scanivalve_mps4264.scanner`, which owns the lock every server here
takes before it touches the device's state).
"""

from __future__ import annotations

import select
import socket
import struct
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from simulators.devices.scanivalve_mps4264.truth import FrameRuns

__all__ = ["DataPort", "QueuedFrame", "bind_consecutive", "serve_commands"]

SEND_BATCH = 256  # frames handed to one send() loop at most


@dataclass
class QueuedFrame:
    """One encoded frame waiting in a module's buffer."""

    scan_id: int
    counter: int
    data: bytes


def bind_consecutive(n: int) -> list[socket.socket]:
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


def serve_commands(listener: socket.socket, stop: threading.Event,
                   handle_command: Callable[[str], bytes]) -> None:
    """Answer command lines on ``listener`` with ``handle_command(line)`` until ``stop`` is set."""
    clients: dict[socket.socket, bytearray] = {}
    try:
        while not stop.is_set():
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
                    replies += handle_command(line)
                if len(buf) > 4096:  # a line that never ends: answer it and forget it
                    replies += handle_command(bytes(buf[:64]).decode("ascii", "replace"))
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


class DataPort:
    """One module's binary data server: its frame buffer and the client it feeds.

    Parameters
    ----------
    lock : threading.Lock
        The scanner's lock: held by the scanner while it fills :attr:`buffer` or sets a request,
        taken here before either is read.
    stop : threading.Event
        Set when the scanner stops.
    sent : FrameRuns
        Where the frames whose bytes went to a client are recorded (the module's truth).
    dropped : list of (int, int, str)
        Where frames dropped are recorded, ``(scan id, counter, reason)`` (the module's truth).
    send_buffer_bytes : int, optional
        ``SO_SNDBUF`` of the data connections.
    """

    def __init__(self, lock: threading.Lock, stop: threading.Event, sent: FrameRuns,
                 dropped: list[tuple[int, int, str]], send_buffer_bytes: int | None) -> None:
        self._lock = lock
        self._stop = stop
        self._sent = sent
        self._dropped = dropped
        self.send_buffer_bytes = send_buffer_bytes
        #: Frames produced and not yet handed to the client (the scanner appends, under lock).
        self.buffer: deque[QueuedFrame] = deque()
        #: Set by the scanner: reset the connection (RST) and drop the frames in flight.
        self.reset_request = False
        #: Set by the scanner at a new scan: drop the frames in flight ("superseded").
        self.flush_request = False
        #: Set when there is something to do (frames, a request, the stop).
        self.wake = threading.Event()

    def discard(self, reason: str) -> None:
        """Drop every buffered frame for ``reason`` (lock held)."""
        self._dropped.extend((e.scan_id, e.counter, reason) for e in self.buffer)
        self.buffer.clear()

    def serve(self, listener: socket.socket) -> None:
        """Send the buffered frames to the newest client of ``listener`` until the stop."""
        listener.setblocking(False)
        client: socket.socket | None = None
        inflight: list[QueuedFrame] = []
        payload = b""
        ends: list[int] = []
        sent = done = 0

        def requeue(reason: str | None) -> None:
            """Frames of ``inflight`` not fully sent: back to the buffer, or dropped."""
            rest = inflight[done:]
            if reason is None:
                self.buffer.extendleft(reversed(rest))
            else:
                self._dropped.extend((e.scan_id, e.counter, reason) for e in rest)

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
                    if self.reset_request:
                        self.reset_request = False
                        requeue("reset")
                        inflight = []
                        if client is not None:
                            client.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER,
                                              struct.pack("ii", 1, 0))
                            client.close()  # an RST: the peer's next read fails
                            client = None
                    if self.flush_request:
                        self.flush_request = False
                        requeue("superseded")
                        inflight = []
                    if client is not None and not inflight:
                        buffer = self.buffer
                        inflight = [buffer.popleft() for _ in range(min(len(buffer),
                                                                         SEND_BATCH))]
                        payload = b"".join(e.data for e in inflight)
                        ends = np.cumsum([len(e.data) for e in inflight]).tolist()
                        sent = done = 0
                if client is None or not inflight:
                    if client is not None and self._peer_closed(client):
                        client.close()
                        client = None
                    self.wake.wait(0.005)
                    self.wake.clear()
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
                        self._sent.add(inflight[done].scan_id, inflight[done].counter)
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
