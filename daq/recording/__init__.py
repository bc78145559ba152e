"""The run file: one HDF5 file per run, its writer, and the production recorder.

- :mod:`~daq.recording.layout`: the file's layout (groups, row types, units, fill values,
  chunking) and :func:`read_sync`;
- :mod:`~daq.recording.recorder`: :class:`RunRecorder`, the writer of one run file;
- :mod:`~daq.recording.recorder_protocol`: :class:`Recorder`, what the run writer writes into (a
  run file, or the console's ring);
- :mod:`~daq.recording.swmr_file`: the file's life cycle under SWMR, its flushes and failures
  (:func:`failed_writes`, :func:`refuse_existing_run_file`);
- :mod:`~daq.recording.raw_streams`: a device's raw stream, its blocks checked and appended;
- :mod:`~daq.recording.sync_rows`: the synchronised view's rows checked and appended;
- :mod:`~daq.recording.writer`: :class:`RunWriter`, the engine subscriber that maps clocks,
  resamples and writes the raw streams, the sync view, releases and events;
- :mod:`~daq.recording.devices`: what the writer keeps per device (clock map, triggers, restarts);
- :mod:`~daq.recording.trigger_anchors`: the PLC's trigger pulses as clock anchors, and the
  warning of a file whose clock maps have none;
- :mod:`~daq.recording.releases`: the releases table, filled as the decays end;
- :mod:`~daq.recording.sync_view`: the sync view's physical columns from the resampled streams;
- :mod:`~daq.recording.raw_batches`: raw rows buffered between appends;
- :mod:`~daq.recording.run`: :func:`record_run`, a rig with real URLs recorded into one file;
- :mod:`~daq.recording.file_switch`: run files started and stopped on request under a running
  engine (the console's recordings);
- :mod:`~daq.recording.session`: one engine across several run files (a campaign's speeds);
- :mod:`~daq.recording.experiment_log`: the run's events as text beside it (RUN.events.log);
- :mod:`~daq.recording.synthetic`: run files written from releases (test data for readers);
- :mod:`~daq.recording.recover`: ``windrig recover``, a file left open by a crash made readable;
- :mod:`~daq.recording.info`: ``windrig info``, what a run file holds.

It knows no simulator: starting simulators is :mod:`daq.sim`'s decision.
``docs/reference/file_format.md`` is the file's contract for readers.
"""
