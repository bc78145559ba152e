"""Transports from URLs: loopback serial, TCP against a local server, errors and timeouts."""

from __future__ import annotations

import socket
import threading

import pytest

from daq.errors import ConfigError, TransportError, TransportTimeout
from daq.transports.byte_transport import SerialTransport, TcpTransport, open_transport

pytestmark = pytest.mark.realtime


def test_loop_url_round_trip_and_timeout():
    """Pyserial's loop:// echoes bytes; an empty read times out with a specific error."""
    t = open_transport("loop://")
    assert not t.is_open  # construction does no I/O
    t.open()
    try:
        t.write(b"SEND\r\n")
        assert t.read_until(b"\r\n", timeout_s=1.0) == b"SEND\r\n"
        with pytest.raises(TransportTimeout, match="no data within"):
            t.read(1, timeout_s=0.05)
    finally:
        t.close()
    t.close()  # idempotent


def test_serial_url_settings_come_from_the_query():
    """serial:// query parameters set the line; unknown ones are refused by name."""
    t = open_transport("serial:///dev/ttyUSB7?baudrate=9600&bytesize=7&parity=E&xonxoff=1")
    assert isinstance(t, SerialTransport)
    assert t._settings["baudrate"] == 9600 and t._settings["bytesize"] == 7
    with pytest.raises(ConfigError, match="unknown serial setting 'speed'"):
        open_transport("serial:///dev/ttyUSB0?speed=9600")
    with pytest.raises(ConfigError, match="unsupported transport URL scheme 'http'"):
        open_transport("http://127.0.0.1:80")
    with pytest.raises(TransportError, match="cannot open"):
        open_transport("serial:///dev/does-not-exist").open()


def test_tcp_transport_against_a_loopback_server():
    """A TCP client exchanges bytes, reads exactly, and reports a closed peer."""
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]

    def serve():
        conn, _ = server.accept()
        with conn:
            assert conn.recv(6) == b"STATUS"
            conn.sendall(b"STATUS: READY\r\n" + bytes(range(10)))
        server.close()

    thread = threading.Thread(target=serve)
    thread.start()
    t = open_transport(f"tcp://127.0.0.1:{port}")
    assert isinstance(t, TcpTransport)
    t.open()
    try:
        t.write(b"STATUS")
        assert t.read_until(b"\r\n", 2.0) == b"STATUS: READY\r\n"
        assert t.read_exactly(10, 2.0) == bytes(range(10))
        thread.join(10.0)  # the server has closed its end (a loaded host: not within 1 s)
        assert not thread.is_alive()
        with pytest.raises(TransportError, match="closed by the peer"):
            t.read(1, 1.0)
    finally:
        t.close()


def test_tcp_connect_refused_is_a_transport_error():
    """Nothing listening: a TransportError naming the URL (a ConnectionError too)."""
    probe = socket.create_server(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    t = TcpTransport(f"tcp://127.0.0.1:{port}", connect_timeout_s=1.0)
    with pytest.raises(ConnectionError, match="cannot connect"):
        t.open()
    with pytest.raises(ConfigError, match="expected tcp://host:port"):
        TcpTransport("tcp://nohostport")


def test_a_serial_read_interrupted_by_a_close_from_another_thread_is_a_transport_error():
    """A read ended by a close from another thread is a TransportError.

    windrig check closes a device's driver under a read that outlived its timeout; pyserial
    itself raises TypeError on the closed descriptor. pyserial drops the descriptor before it
    clears ``is_open``, and a read failing in that window once escaped as a TypeError (1 in
    100 on a loaded host): the close is repeated so that the window is met.
    """
    import os

    for _ in range(50):
        master, slave = os.openpty()
        try:
            t = open_transport(f"serial://{os.ttyname(slave)}")
            t.open()
            started, outcome = threading.Event(), []

            def read(transport=t, started=started, outcome=outcome) -> None:
                started.set()
                try:
                    transport.read(16, timeout_s=5.0)
                except BaseException as exc:  # recorded for the assertion, whatever it is
                    outcome.append(exc)

            reader = threading.Thread(target=read)
            reader.start()
            assert started.wait(5.0)
            t.close()
            reader.join(10.0)
            assert not reader.is_alive()
            assert len(outcome) == 1 and isinstance(outcome[0], TransportError), outcome
            assert not t.is_open
        finally:
            os.close(master)
            os.close(slave)
