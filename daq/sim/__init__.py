"""The simulated rig: simulators started from a rig config, recorded, checked against the truth.

- :mod:`~daq.sim.rig`: every simulated instrument of a config started from one virtual tunnel;
- :mod:`~daq.sim.rig_process`: the same in a process of its own (as real instruments are);
- :mod:`~daq.sim.recording`: ``windrig acquire --simulate``: simulators up, recorded, checked;
- :mod:`~daq.sim.sync_check`: the sync view measured against the simulators' clocks and decays;
- :mod:`~daq.sim.campaign`: a scripted campaign (releases at several wind speeds -> E2RFC);
- :mod:`~daq.sim.demo`: ``windrig demo``;
- :mod:`~daq.sim.commands`: ``windrig check`` and ``windrig simulate`` (they may start the rig);
- :mod:`~daq.sim.live_config`: a running simulated rig's config with its simulators' URLs.

The only part of daq that imports :mod:`simulators`.
"""
