"""The drivers of a rig config, built for the engine: :func:`drivers_from_config`.

Responsibility: build (not open) every configured instrument's driver
(:func:`daq.instruments.build.build_driver`) and pair it with the engine's kind of device
(:data:`ROLE_KINDS`: the rig config's roles are plural where a rig has several, ``lasers``;
``analog``: scaled analog inputs such as a Pitot transducer or a balance, clocked streams),
ready for :class:`~daq.acquisition.engine.Acquisition`.

Not responsible for: the URLs (a simulated rig's are filled in by :mod:`daq.sim.rig` before this
is called), or opening the devices (the engine does, in its ``start()``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from daq.config import RigConfig
from daq.instruments.build import build_driver

__all__ = ["ROLE_KINDS", "drivers_from_config"]

#: Rig-config role -> engine kind.
ROLE_KINDS: Mapping[str, str] = {"scanner": "scanner", "lasers": "laser",
                                 "barometer": "barometer", "fan": "fan", "plc": "plc",
                                 "analog": "analog"}


def drivers_from_config(config: RigConfig) -> dict[str, tuple[str, Any]]:
    """Build (do not open) every instrument's driver of a rig config, with its engine kind.

    Parameters
    ----------
    config : daq.config.RigConfig
        A rig config whose URLs are real (a simulated rig's ``rig.config``).

    Returns
    -------
    dict
        Instrument name -> (kind, driver), ready for :class:`~daq.acquisition.engine.Acquisition`.
    """
    return {inst.name: (ROLE_KINDS[inst.role], build_driver(inst, config.limits))
            for inst in config.instruments}
