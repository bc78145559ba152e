"""Recorded run files, again: reprocessing on Dask and the discrepancy diagnosis.

- :mod:`~daq.offline.reprocess`: ``windrig reprocess``: per-file modal fits and per-campaign
  E2RFC on a Dask cluster, with a cache;
- :mod:`~daq.offline.report`: its tables, plots and HTML report;
- :mod:`~daq.offline.diagnosis`: ``windrig diagnose``: the discrepancy workflow with its plots;
- :mod:`~daq.offline.flutter_commands`: ``windrig identify`` (E2RFC on run files; releases
  found in the signals with ``--detect-releases``) and ``windrig flutter`` (a section with a
  model or a flutter-derivative table);
- :mod:`~daq.offline.displacement_route`: ``windrig identify`` on files without forces (a rig
  without taps): the displacement-only route, with its caveats as warnings;
- :mod:`~daq.offline.derivative_table`: an identified model's flutter derivatives (all 18 with
  sway) as ``windrig identify`` prints them, and the check that it has the section's degrees
  of freedom.
- :mod:`~daq.offline.bridge_commands`: ``windrig bridge``: multimode flutter (and buffeting) of
  a full bridge from its modes and the section's model or table (:mod:`ident.bridge`);
- :mod:`~daq.offline.bridge_uncertainty`: ``windrig bridge --uncertainty``: the section's
  uncertainty at the bridge, serially or on Dask, its JSON entry and histogram;
- :mod:`~daq.offline.cluster`: the Dask client of ``reprocess`` and ``bridge --uncertainty``
  (a local cluster, or ``--scheduler ADDRESS``);
- :mod:`~daq.offline.design_report`: the one-page design report of ``windrig flutter --out``
  and ``windrig bridge --out`` (inputs and their hashes, both routes, warnings, plots);
- :mod:`~daq.offline.buffeting_plots`: its buffeting plots (RMS along the span, response
  spectra) and RMS table;
- :mod:`~daq.offline.report_plots`: the flutter-derivative grid and flutter diagram that every
  campaign page draws (``windrig reprocess``'s report, ``windrig campaign``'s, the demo's).
"""
