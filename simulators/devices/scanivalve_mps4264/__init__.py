"""The simulated Scanivalve MPS4264-class pressure scanner (``docs/reference/wire_formats.md``).

- :mod:`~simulators.devices.scanivalve_mps4264.scanner`: :class:`SimScanivalveMps4264`, the
  device: its ASCII commands, CALZ, scans, frames from the virtual tunnel, and faults;
- :mod:`~simulators.devices.scanivalve_mps4264.packets`: the binary packets (0x6D, legacy 0x0A),
  encoded from the manual's facts;
- :mod:`~simulators.devices.scanivalve_mps4264.servers`: the TCP servers on 127.0.0.1, the
  command server and one binary data port per module;
- :mod:`~simulators.devices.scanivalve_mps4264.truth`: :class:`SimTruth`, the frames produced,
  sent and dropped, which tests check a recording against.
"""
