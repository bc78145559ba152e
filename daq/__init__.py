"""windrig data acquisition: drivers, transports, synchronisation, HDF5 recording, operator GUI.

For now it holds the command line (:mod:`daq.cli`); the acquisition layers arrive with their issues.
"""
