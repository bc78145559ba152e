"""The rig configs the tests read, and the TOML snippets they append to them.

``CONFIGS`` is the repository's ``rig_configs`` (a link to the shipped ``daq/rig_configs``);
``SIM_FLAT_PLATE`` is the default simulated rig. ``FAST_FAN`` and ``DRIFTING_CLOCKS`` are
``[simulation.devices.*]`` tables, simulator options only: appended to a config they change what
the simulated instruments do, never what the drivers or the recording see of the config.
"""

from __future__ import annotations

from pathlib import Path

#: The repository's root (``tests/support/configs.py`` is two folders below it).
REPO = Path(__file__).resolve().parents[2]
#: The rig configs, as the README and the command line name them.
CONFIGS = REPO / "rig_configs"
#: The default simulated rig: the flat plate (``windrig demo``'s config).
SIM_FLAT_PLATE = CONFIGS / "sim_flat_plate.toml"
#: The example bridges (`windrig bridge`'s TOML descriptions of full-scale decks).
BRIDGES = CONFIGS / "bridges"

#: The simulated fan ramps at 4000 rpm/s instead of its drive's 100 rpm/s: a test reaches its
#: speed in a fraction of a second instead of several (a simulator option).
FAST_FAN = "\n[simulation.devices.fan]\nramp_rpm_per_s = 4000.0\n"

#: The fast fan, and the scanner and lasers on clocks 20 ms off the host's and 50 ppm fast or
#: slow: between the scanner and laser_front 40 ms and 100 ppm for the clock maps to undo.
DRIFTING_CLOCKS = """
[simulation.devices.fan]
ramp_rpm_per_s = 4000.0
[simulation.devices.scanner]
clock_offset_s = 0.02
clock_drift_ppm = 50.0
[simulation.devices.laser_front]
clock_offset_s = -0.02
clock_drift_ppm = -50.0
[simulation.devices.laser_rear]
clock_offset_s = 0.02
clock_drift_ppm = -50.0
[simulation.devices.laser_check]
clock_offset_s = -0.02
clock_drift_ppm = 50.0
"""


def flat_plate_text(extra: str = "") -> str:
    """Return the default simulated rig's config text, with ``extra`` TOML appended."""
    return SIM_FLAT_PLATE.read_text() + extra


def live_config_text() -> str:
    """Return the default simulated rig's config with the fast fan (the console's live tests)."""
    return flat_plate_text(FAST_FAN)
