"""The fan drive: an ABB ACS580-class VFD in the ABB Drives profile, over Modbus.

- :mod:`.settings`: the ``[fan]`` table (maximum speed, ramp, register addresses);
- :mod:`.profile`: the Control Word values and the decoded Status Word;
- :mod:`.driver`: :class:`AbbAcs580`, speed reference (within the rig's limit), start, stop,
  trip reset, readings.
"""
