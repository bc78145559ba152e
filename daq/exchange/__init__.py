"""Run files in from, and out to, the formats other laboratories' tools read and write.

Modules
-------
export_contents
    What a run file holds for other programs (the synchronised view, the releases, the events,
    the calibrations, with their units), read once.
export_run
    ``windrig export``: the command (its checks, the writer chosen, what it says).
export_writers
    One writer per format: a CSV folder (a header naming units), a MATLAB v5 ``.mat``
    (``scipy.io.savemat``), a netCDF-4 file (xarray with h5netcdf), a TDMS file (npTDMS).
"""
