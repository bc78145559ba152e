"""The operator console, ``windrig gui``: live or replayed, one window.

- :mod:`~daq.console.app`: the command's options, the data source, Qt's event loop;
- :mod:`~daq.console.window`: :class:`ConsoleWindow`: traces, pressures, spectra, health;
- :mod:`~daq.console.controls`: the control panel (fan, arm, release, CALZ, markers, record);
- :mod:`~daq.console.interlocks`: when each control is allowed, and why not (pure, no Qt);
- :mod:`~daq.console.releases_panel`: the releases table and the flutter derivatives;
- :mod:`~daq.console.live_ident`: each release fitted as it ends, then E2RFC (worker process);
- :mod:`~daq.console.auto_release`: a hands-free session on a simulated rig;
- :mod:`~daq.console.display`: numbers the views show (Cp, tap perimeter, spectra);
- :mod:`~daq.console.qt_guard`: a guard against a PySide6 reference-count bug;
- :mod:`~daq.console.source`: the data-source contract the window reads;
- :mod:`~daq.console.replay`: a run file played back in time;
- :mod:`~daq.console.replay_config`: the rig config a replay draws with (a file without taps);
- :mod:`~daq.console.live_source`: a rig acquired now, synchronised into a ring;
- :mod:`~daq.console.ring_recorder`: the live view's run writer target (the ring, no file);
- :mod:`~daq.console.process_source`: the live source in a process of its own;
- :mod:`~daq.console.ring_buffer`, :mod:`~daq.console.shared_ring`: the rows the views draw.
"""
