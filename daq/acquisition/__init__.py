"""The acquisition engine: every instrument read in its own thread, one dispatcher, subscribers.

- :mod:`~daq.acquisition.engine`: :class:`Acquisition`: start, stop, the operator's commands;
- :mod:`~daq.acquisition.reader`: one device's reader thread, bounded queue, faults, recovery;
- :mod:`~daq.acquisition.adapters`: when a reader reads (streaming or polled) and the scanner's
  start and stop;
- :mod:`~daq.acquisition.dispatch`: the dispatcher thread and the ``(name, doc)`` subscribers;
- :mod:`~daq.acquisition.records`: the records handed to subscribers (blocks, events, stats);
- :mod:`~daq.acquisition.commands`: what each operator command does and the event it records;
- :mod:`~daq.acquisition.calz`: a CALZ during a run (the scan paused, zeroed, restarted);
- :mod:`~daq.acquisition.sync_pulses`: trigger pulses every 0.5 s, the clocks' anchors;
- :mod:`~daq.acquisition.drivers`: every configured instrument's driver, for the engine;
- :mod:`~daq.acquisition.fan_watch`: the fan's actual speed against its set-point
  (``fan_reached`` events);
- :mod:`~daq.acquisition.device_check`: ``windrig check``: every device contacted, read and
  judged before a test;
- :mod:`~daq.acquisition.operator_keys`: the operator's keys on the terminal during a recording
  (releases by hand: ``manual_release``, ``manual_hold``; ``q`` ends the run).

Nothing here touches h5py or Qt, and nothing knows a simulator.
"""
