"""A test kit for driver authors: the contract test and the scripted exchanges, installed.

A driver (windrig's own, or a plugin's in its own distribution) tests itself with these:

- :mod:`~daq.testing.contract`: the written contract of each role (docs/guides/drivers.md) as code:
  the channels each role must deliver (:data:`ROLE_CHANNELS`), the methods its users call
  (:data:`ROLE_METHODS`), and the checks, as plain functions that return the problems found
  (:func:`entry_problems`, :func:`construction_problems`, :func:`reading_problems`,
  :func:`sequence_problems`) and one :func:`check_driver` that opens a driver on a live
  transport (a simulator's, or the hardware's), reads it and raises on any breach;
- :mod:`~daq.testing.exchange`: the scripted byte exchanges and Modbus calls of
  :mod:`daq.transports.scripted`, for tests that need no simulator;
- :mod:`~daq.testing.pytest_plugin`: the pytest plugin (entry point ``pytest11``, loaded in
  every project that installs windrig): ``--windrig-device-url URL`` and the fixture
  ``windrig_device_url``, which skips a hardware test unless an address was given.
"""
