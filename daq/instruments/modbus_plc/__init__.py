"""The release and trigger PLC, over Modbus.

- :mod:`.settings`: the ``[plc]`` table (coil, input and register addresses, timings);
- :mod:`.driver`: :class:`ModbusPlc`, arm, disarm, release (confirmed by RELEASED), trigger
  pulses, readings.
"""
