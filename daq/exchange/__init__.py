"""Lab data in and out: other formats turned into run files and back.

- :mod:`~daq.exchange.import_map`: the import map (``MAP.toml``) parsed and checked: per
  channel the quantity, its column, unit, linear scale and sign; the time base, the wind, the
  air density, the release instants and the holds; numbers read from a source's properties;
- :mod:`~daq.exchange.sources`: the readers of CSV, MATLAB (v5 through scipy.io, v7.3 through
  h5py) and TDMS (npTDMS) files into tables of columns and properties, one per test;
- :mod:`~daq.exchange.importing`: one table through its map into releases, written as a
  normal run file with its provenance (source, SHA-256, the map's text);
- :mod:`~daq.exchange.import_command`: ``windrig import SOURCE... --map MAP.toml --out DIR``.

``docs/importing.md`` is the guide, with a complete map for each format.
"""
