"""Synchronisation numerics: device clocks onto the host's, and one time base for all streams.

- :mod:`~daq.sync.clock_map`: :class:`ClockMap` (a device clock mapped onto the host clock:
  offset, drift, latency floor, trigger anchors) and the trigger times that anchor it;
- :mod:`~daq.sync.counters`: counter unwrapping, gaps and backward steps;
- :mod:`~daq.sync.continuous_time`: continuous host times while a clock map keeps improving;
- :mod:`~daq.sync.resample`: the streams on the sync view's uniform time base;
- :mod:`~daq.sync.conversions`: heave and pitch from lasers, forces from taps, wind speed, air
  density;
- :mod:`~daq.sync.checks`: the argument checks these modules share.

Pure numerical code on arrays: no I/O, no threads, no files.
"""
