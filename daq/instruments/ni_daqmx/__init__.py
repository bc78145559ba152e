"""Analog inputs through NI-DAQmx (the optional extra ``windrig[nidaqmx]``).

Modules (each imported on its own; this file imports nothing):

- ``address``: the ``nidaqmx://Dev1/ai0:3?trigger=port0/line0`` URL, one task's device,
  channels, trigger line, input range, buffer and (simulated rig) stand-in address;
- ``settings``: a channel's linear scale, the ``[[lasers]]`` and ``[[analog]]`` tables;
- ``runtime``: the ``nidaqmx`` API, imported lazily, its runtime checked (one line naming what
  to install when it is missing), or the registered stand-in;
- ``task_group``: the one task of a device shared by its instruments: sample counting,
  overwritten samples as counted gaps, a lost device recreated;
- ``driver``: the ``ni_daqmx_laser`` and ``ni_daqmx_analog`` drivers and their registry entries.
"""
