"""What many test modules share, written once (not a test package: nothing here is collected).

The suite's ``pythonpath`` (pyproject.toml, ``[tool.pytest.ini_options]``) puts ``tests/`` on
``sys.path``, so a test module imports ``from support.sections import FLAT_PLATE``. A test that
needs other values keeps its own literal: only identical values are shared.

Modules
-------
sections
    The flat-plate section model that most identification and simulator tests fly.
configs
    Where the rig configs are, the default simulated rig's config, and the TOML snippets that
    tests append to it (the fast fan, clocks that drift).
clocks
    A monotonic clock that a test sets by hand.
scanner_stream
    A synthetic pressure-scanner stream with PLC trigger pulses on exact clocks, cut into the
    run writer's blocks and events.
run_files
    Run files written through the real recorder, and read as a live reader would.
outside_library
    Physics outside the discrepancy workflow's library (free play, a heave stop, a mass that
    grows between releases) for its tests and benchmark.
identified
    A seeded E2RFC identification of the flat plate as ``windrig identify --json`` writes it
    (model, parameter covariance, std parts), for the bridge's uncertainty.
iabse
    The IABSE superstructure benchmark's step 1.1a (a flat-plate section) as a bridge, and its
    wind.
"""
