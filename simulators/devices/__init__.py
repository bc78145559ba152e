"""Simulated instruments that speak the real wire protocols over real transports.

- :mod:`~simulators.devices.scanivalve_mps4264`: the pressure scanner (a package: the device,
  its packets, its TCP servers, its truth counters);
- :mod:`~simulators.devices.microepsilon_ild1420`: a laser displacement sensor;
- :mod:`~simulators.devices.vaisala_ptb330`: the barometer;
- :mod:`~simulators.devices.abb_acs580`: the fan's drive (Modbus TCP);
- :mod:`~simulators.devices.modbus_plc`: the release PLC (Modbus TCP);
- :mod:`~simulators.devices._modbus_server`: the Modbus TCP server the last two share.
"""
