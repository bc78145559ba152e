"""The Modbus bus: URLs, 16-bit conversions, exact frames on the wire, and one error channel."""

from __future__ import annotations

import logging
import socket
import threading

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymodbus.exceptions import ConnectionException, ModbusIOException
from pymodbus.pdu import ExceptionResponse, ModbusPDU

from daq.errors import (
    ConfigError,
    DeviceError,
    ModbusDeviceError,
    ProtocolError,
    TransportError,
    TransportTimeout,
)
from daq.transports.modbus import ModbusBus, RegisterBus, from_int16, parse_modbus_url, to_int16
from daq.transports.scripted import ScriptedBus

pytestmark = pytest.mark.realtime


# -- URLs ----------------------------------------------------------------------------------------
def test_tcp_and_rtu_urls():
    tcp = parse_modbus_url("modbus+tcp://10.0.0.7:1502?unit=3")
    assert (tcp.kind, tcp.host, tcp.port, tcp.unit) == ("tcp", "10.0.0.7", 1502, 3)
    assert parse_modbus_url("modbus+tcp://plc.local").port == 502  # Modbus TCP's port
    rtu = parse_modbus_url("modbus+rtu:///dev/ttyUSB0?baudrate=9600&parity=N&stopbits=2&unit=7")
    assert (rtu.kind, rtu.host, rtu.unit) == ("rtu", "/dev/ttyUSB0", 7)
    assert rtu.serial == {"baudrate": 9600, "bytesize": 8, "stopbits": 2, "parity": "N"}
    # MODBUS over serial line v1.02, 2.5.1: the default character format is 8E1.
    assert parse_modbus_url("modbus+rtu:///dev/ttyS1").serial["parity"] == "E"


@pytest.mark.parametrize(("url", "message"), [
    ("modbus+tcp://host:502?unit=300", r"unit = 300 is outside the allowed range \[0, 247\]"),
    ("modbus+tcp://host:502?slave=1", r"unknown Modbus TCP setting\(s\) \['slave'\]"),
    ("modbus+tcp://host:502?unit=one", "unit must be an integer"),
    ("modbus+tcp:///nohost", "expected modbus\\+tcp://host:port"),
    ("modbus+rtu:///dev/ttyUSB0?parity=X", "parity must be one of N, E, O"),
    ("modbus+rtu:///dev/ttyUSB0?unit=0", r"unit = 0 is outside"),  # broadcast gets no reply
    ("modbus+rtu:///dev/ttyUSB0?speed=9600", r"unknown Modbus RTU setting\(s\) \['speed'\]"),
    ("modbus+rtu://host/dev/ttyUSB0", "expected modbus\\+rtu:///dev/ttyX"),
    ("tcp://host:502", "unsupported Modbus URL scheme 'tcp'"),
])
def test_bad_urls_are_config_errors_naming_the_problem(url, message):
    with pytest.raises(ConfigError, match=message):
        ModbusBus(url)


def test_construction_does_no_io_and_unopened_bus_refuses_requests():
    bus = ModbusBus("modbus+tcp://192.0.2.1:502?unit=1")  # TEST-NET: nothing there
    assert not bus.is_open and bus._client is None
    assert isinstance(bus, RegisterBus) and isinstance(ScriptedBus([]), RegisterBus)
    with pytest.raises(TransportError, match="bus not open"):
        bus.read_coils(0)
    with pytest.raises(ValueError, match="retries"):
        ModbusBus("modbus+tcp://h", retries=11)
    with pytest.raises(ValueError, match="timeout_s"):
        ModbusBus("modbus+tcp://h", timeout_s=0.0)
    bus.close()  # idempotent on a never-opened bus


def test_rtu_port_that_does_not_exist_is_a_transport_error():
    bus = ModbusBus("modbus+rtu:///dev/does-not-exist?baudrate=9600", retries=0)
    with pytest.raises(TransportError, match="cannot connect"):
        bus.open()
    assert not bus.is_open


# -- 16-bit conversions --------------------------------------------------------------------------
def test_int16_conversions_at_the_edges():
    assert [to_int16(w) for w in (0, 0x7FFF, 0x8000, 0xFFFF)] == [0, 32767, -32768, -1]
    assert from_int16(-20000) == 0xB1E0  # REF1 full scale in reverse (the wire formats)
    for bad in (-1, 0x10000):
        with pytest.raises(ValueError):
            to_int16(bad)
    for bad in (-0x8001, 0x8000):
        with pytest.raises(ValueError):
            from_int16(bad)


@settings(deadline=None, max_examples=200, database=None)
@given(st.integers(-0x8000, 0x7FFF))
def test_int16_round_trip(value):
    word = from_int16(value)
    assert 0 <= word <= 0xFFFF and to_int16(word) == value


# -- exact frames on the wire --------------------------------------------------------------------
class ScriptedPeer:
    """A TCP peer that expects exact request bytes and answers with exact reply bytes."""

    def __init__(self, script: list[tuple[bytes, bytes]]) -> None:
        self.script = script
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.mismatch: tuple[bytes, bytes] | None = None
        self.done = 0
        self.thread = threading.Thread(target=self._serve, name="ScriptedPeer")
        self.thread.start()

    def _serve(self) -> None:
        try:
            conn, _ = self.server.accept()
            with conn:
                conn.settimeout(2.0)
                for request, reply in self.script:
                    got = b""
                    while len(got) < len(request):
                        chunk = conn.recv(len(request) - len(got))
                        if not chunk:
                            return
                        got += chunk
                    if got != request:
                        self.mismatch = (request, got)
                        return
                    conn.sendall(reply)
                    self.done += 1
        finally:
            self.server.close()

    def finish(self) -> None:
        self.thread.join(3.0)
        assert not self.thread.is_alive()
        if self.mismatch:
            expected, got = self.mismatch
            pytest.fail(f"expected {expected.hex(' ')}, got {got.hex(' ')}")
        assert self.done == len(self.script)


def mbap(tid: int, pdu: str, unit: int = 1) -> bytes:
    """Build a Modbus TCP ADU: MBAP header (transaction id, protocol 0, length, unit) + PDU."""
    body = bytes.fromhex(pdu)
    return tid.to_bytes(2, "big") + b"\x00\x00" + (len(body) + 1).to_bytes(2, "big") \
        + bytes([unit]) + body


def test_requests_and_replies_are_the_exact_modbus_tcp_frames():
    # Frames from the Modbus Application Protocol v1.1b3 (6.1 FC01, 6.2 FC02, 6.3 FC03, 6.5 FC05,
    # 6.6 FC06, 7 exception responses) inside MBAP headers (Modbus Messaging on TCP/IP v1.0b, 3.1);
    # register values are the ABB drives profile words of docs/reference/wire_formats.md, "Fan
    # drive".
    peer = ScriptedPeer([
        (mbap(1, "03 0003 0002"), mbap(1, "03 04 0237 03E8")),        # SW, ACT1
        (mbap(2, "06 0000 047F"), mbap(2, "06 0000 047F")),           # CW = run
        (mbap(3, "06 0001 B1E0"), mbap(3, "06 0001 B1E0")),           # REF1 = -20000
        (mbap(4, "05 0005 FF00"), mbap(4, "05 0005 FF00")),           # coil 5 on
        (mbap(5, "01 0000 0003"), mbap(5, "01 01 05")),               # coils 0..2 = 1, 0, 1
        (mbap(6, "02 0002 0001"), mbap(6, "02 01 01")),               # DI 2 = 1
        (mbap(7, "03 0004 0001"), mbap(7, "03 02 FFFF")),             # ACT1 = -1
        (mbap(8, "03 0002 0001"), mbap(8, "83 02")),                  # illegal data address
    ])
    bus = ModbusBus(f"modbus+tcp://127.0.0.1:{peer.port}?unit=1", timeout_s=2.0, retries=0)
    try:
        bus.open()
        assert bus.read_holding_registers(3, 2) == [0x0237, 1000]
        bus.write_register(0, 0x047F)
        bus.write_int16(1, -20000)
        bus.write_coil(5, True)
        assert bus.read_coils(0, 3) == [True, False, True]
        assert bus.read_discrete_inputs(2) == [True]
        assert bus.read_int16(4) == -1
        with pytest.raises(ModbusDeviceError, match=r"exception 0x02 \(illegal data address\)"):
            bus.read_uint16(2)
    finally:
        bus.close()
        peer.finish()


# -- one error channel, bounded retries (a fake pymodbus client, no I/O) ------------------------
class FakeClient:
    """Stands in for a pymodbus sync client: each call pops the next scripted outcome."""

    def __init__(self, outcomes: list[object], connects: list[bool] | None = None) -> None:
        self.outcomes = list(outcomes)
        self.connects = list(connects or [])
        self.calls: list[str] = []
        self.closed = 0

    def connect(self) -> bool:
        return self.connects.pop(0) if self.connects else True

    def close(self) -> None:
        self.closed += 1

    def _next(self, name: str) -> object:
        self.calls.append(name)
        outcome = self.outcomes.pop(0)
        if isinstance(outcome, BaseException):
            raise outcome
        return outcome

    def read_holding_registers(self, address: int, *, count: int, device_id: int) -> object:
        return self._next("read_holding_registers")

    def write_coil(self, address: int, value: bool, *, device_id: int) -> object:
        return self._next("write_coil")


def fake_bus(outcomes: list[object], **options: object) -> tuple[ModbusBus, FakeClient]:
    client = FakeClient(outcomes)
    bus = ModbusBus("modbus+tcp://fake:502?unit=1", client=client, **options)
    bus.open()
    return bus, client


def registers(*words: int) -> ModbusPDU:
    return ModbusPDU(registers=list(words))


def test_exception_response_is_a_device_error_and_never_retried():
    bus, client = fake_bus([ExceptionResponse(3, 2)], retries=3)
    with pytest.raises(ModbusDeviceError) as info:
        bus.read_holding_registers(9)
    assert isinstance(info.value, DeviceError)
    assert (info.value.code, info.value.function_code) == (2, 3)
    assert "read 1 holding register(s) at 9" in str(info.value)
    assert client.calls == ["read_holding_registers"] and bus.stats["device_errors"] == 1


def test_lost_connection_is_retried_with_logged_exponential_backoff(monkeypatch, caplog):
    sleeps: list[float] = []
    monkeypatch.setattr("daq.transports.modbus.time.sleep", sleeps.append)
    bus, client = fake_bus([ConnectionException("reset"), ConnectionException("reset"),
                            registers(42)], retries=2, backoff_s=0.1)
    with caplog.at_level(logging.WARNING, logger="daq.transports.modbus"):
        assert bus.read_uint16(0) == 42
    assert sleeps == [0.1, 0.2]
    assert [r.getMessage().split("; ")[-1] for r in caplog.records] == [
        "retry 1 of 2 in 0.100 s", "retry 2 of 2 in 0.200 s"]
    assert client.closed == 2  # each failure drops the connection; the next call reconnects
    assert bus.stats["retries"] == 2 and bus.stats["transport_errors"] == 2


@pytest.mark.parametrize(("failure", "error", "message"), [
    (ConnectionException("Connection unexpectedly closed"), TransportError, "connection failed"),
    (OSError(104, "Connection reset by peer"), TransportError, "connection failed"),
    (ModbusIOException("No response received after 0 retries"), TransportTimeout,
     "no reply within 0.5 s"),
    (ModbusIOException("Unable to decode request"), ProtocolError, "bad reply"),
])
def test_persistent_failures_surface_as_one_specific_error(monkeypatch, failure, error, message):
    monkeypatch.setattr("daq.transports.modbus.time.sleep", lambda s: None)
    bus, client = fake_bus([failure] * 3, retries=2, timeout_s=0.5)
    with pytest.raises(error, match=message) as info:
        bus.write_coil(1, True)
    assert info.value.__cause__ is failure  # the low-level cause stays visible
    assert len(client.calls) == 3  # 1 + retries, no more
    if error is TransportTimeout:
        assert isinstance(info.value, TimeoutError) and bus.stats["timeouts"] == 3


def test_short_or_bad_replies_are_protocol_errors(monkeypatch):
    monkeypatch.setattr("daq.transports.modbus.time.sleep", lambda s: None)
    bus, _ = fake_bus([registers(1)], retries=0)
    with pytest.raises(ProtocolError, match=r"reply holds \[1\]"):
        bus.read_holding_registers(0, 2)


def test_connect_failure_is_retried_then_a_transport_error(monkeypatch):
    monkeypatch.setattr("daq.transports.modbus.time.sleep", lambda s: None)
    client = FakeClient([], connects=[False, False])
    bus = ModbusBus("modbus+tcp://fake:502", client=client, retries=1)
    with pytest.raises(TransportError, match="cannot connect"):
        bus.open()
    assert not bus.is_open


def test_arguments_are_checked_before_anything_is_sent():
    bus, client = fake_bus([])
    for call in (lambda: bus.read_holding_registers(-1), lambda: bus.read_holding_registers(0, 126),
                 lambda: bus.read_coils(65535, 2), lambda: bus.write_register(0, 0x10000),
                 lambda: bus.write_register(0, -1), lambda: bus.write_int16(0, 40000),
                 lambda: bus.write_coil(0, 1)):  # type: ignore[arg-type]
        with pytest.raises(ValueError):
            call()
    assert client.calls == []


def test_scripted_bus_checks_every_call():
    bus = ScriptedBus([("write_register", 0, 0x0476, None),
                       ("read_coils", 1, 1, [True])])
    bus.open()
    bus.write_register(0, 0x0476)
    with pytest.raises(AssertionError, match="expected \\('read_coils', 1, 1\\)"):
        bus.read_coils(2)
    with pytest.raises(AssertionError, match="script incomplete"):
        bus.assert_complete()
