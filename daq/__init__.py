"""windrig's rig side: transports, drivers, acquisition, synchronisation, recording, console.

One subpackage per concern (``docs/reference/architecture.md`` has the tree and the import rules):

- :mod:`daq.transports`: bytes and registers from URLs (serial, TCP, Modbus), scripted fakes;
- :mod:`daq.instruments`: the driver registry, ``build_driver`` and one subpackage per device;
- :mod:`daq.acquisition`: the engine (reader threads, dispatcher, operator commands, CALZ);
- :mod:`daq.sync`: clock maps, counters, resampling, physical conversions (numerics only);
- :mod:`daq.recording`: the HDF5 run file, the run writer, ``record_run``;
- :mod:`daq.console`: the operator console (``windrig gui``);
- :mod:`daq.sim`: the simulated rig, its truth checks, the campaign and ``windrig demo``;
- :mod:`daq.offline`: recorded files again (``windrig reprocess``, ``windrig diagnose``) and the
  flutter plots of every campaign page.

Modules of their own: :mod:`daq.errors` (every exception of daq), :mod:`daq.validation` (checks
of TOML tables), :mod:`daq.config` (rig configs), :mod:`daq.tubing_config` (its pneumatic
tubing tables), :mod:`daq.calibration` (its calibrations: tap wiring, dead taps, Pitot, lasers,
humid air, span), :mod:`daq.procedure` (hold and decay times), :mod:`daq.log_file` (a command's
log file) and :mod:`daq.cli` (the ``windrig`` command line).
"""
