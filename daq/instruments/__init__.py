"""The instrument drivers: one subpackage per device, a registry, and the driver builder.

- :mod:`~daq.instruments.entry`: :class:`DriverEntry`, what each driver tells the registry;
- :mod:`~daq.instruments.reading`: the reading contract: the :class:`Reading` every driver's
  ``read()`` returns (channels as its ``describe()``, host times, counters, device times,
  gaps of the one :class:`Gap` type);
- :mod:`~daq.instruments.registry`: the shipped drivers by name (imported statically),
  the validation of an instrument table's settings;
- :mod:`~daq.instruments.build`: :func:`build_driver`, a configured instrument's driver on the
  transport its URL names;
- :mod:`~daq.instruments.scanivalve_mps4264`: the pressure scanner (TCP commands and frames);
- :mod:`~daq.instruments.microepsilon_ild1420`: the laser displacement sensors (RS-422);
- :mod:`~daq.instruments.abb_acs580`: the fan drive (ABB Drives profile, Modbus);
- :mod:`~daq.instruments.modbus_plc`: the release and trigger PLC (Modbus);
- :mod:`~daq.instruments.vaisala_ptb330`: the barometer (RS-232 ASCII);
- :mod:`~daq.instruments.ni_daqmx`: analog inputs through NI-DAQmx (lasers with an analog
  output, ``[[analog]]`` transducers; the optional ``nidaqmx`` package, imported lazily).

Every driver's constructor does no I/O (``open()`` does), and a driver's settings class
validates its table of the rig config. ``docs/reference/wire_formats.md`` describes what each
speaks.
"""
