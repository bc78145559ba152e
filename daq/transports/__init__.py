"""Transports: the bytes and registers drivers talk through, opened from URLs.

- :mod:`~daq.transports.byte_transport`: the :class:`Transport` protocol, ``serial://`` (and
  pyserial's ``socket://``, ``loop://``) and ``tcp://`` transports, ``open_transport(url)``;
- :mod:`~daq.transports.modbus`: ``modbus+tcp://`` and ``modbus+rtu://`` devices as one
  :class:`RegisterBus` (pymodbus), with bounded, logged retries and one error channel;
- :mod:`~daq.transports.scripted`: scripted byte exchanges and register calls for driver tests.

Drivers receive a transport or a bus; they never open a port from a name
(``docs/reference/wire_formats.md``, "Transports and URLs").
"""
