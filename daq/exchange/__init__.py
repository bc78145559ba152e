"""Run files in from, and out to, the formats other laboratories' tools read and write.

Modules
-------
import_map
    The import map (``MAP.toml``) parsed and checked: per channel the quantity, its column,
    unit, linear scale and sign; the taps; the time base, the wind, the air density, the
    release instants and the holds; numbers read from a source's properties.
sources
    The readers of CSV, MATLAB (v5 through scipy.io, v7.3 through h5py) and TDMS (npTDMS)
    files into tables of columns and properties, one per test.
importing
    One table through its map into releases, written as a normal run file with its
    provenance (source, SHA-256, the map's text).
import_command
    ``windrig import SOURCE... --map MAP.toml --out DIR``; ``docs/guides/import_export.md`` is its
    guide, with a complete map for each format.
export_contents
    What a run file holds for other programs (the synchronised view, the releases, the events,
    the calibrations, with their units), read once.
export_command
    ``windrig export``'s parser (light: the writers load only when it runs).
export_run
    ``windrig export``: the command (its checks, the writer chosen, what it says).
export_writers
    One writer per format: a CSV folder (a header naming units), a MATLAB v5 ``.mat``
    (``scipy.io.savemat``), a netCDF-4 file (xarray with h5netcdf), a TDMS file (npTDMS).
"""
