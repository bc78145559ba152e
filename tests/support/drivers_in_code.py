"""Drivers registered in code for one test, each with a rig config that uses it.

A test that needs an instrument which misbehaves in one particular way (a clock, a crash)
registers a driver entry in code rather than through an entry point, and writes a config of
``tests/daq/minimal_rig.toml`` plus that instrument's table. :func:`rigs_with_drivers` does
both and unregisters every entry it registered afterwards, also when a registration fails
halfway.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path

from daq.instruments import registry
from daq.instruments.entry import DriverEntry

from support.configs import REPO

#: The smallest simulated rig the config tests share.
MINIMAL_RIG = REPO / "tests" / "daq" / "minimal_rig.toml"


@contextmanager
def rigs_with_drivers(folder: Path, drivers: Mapping[str, tuple[DriverEntry, str]]
                      ) -> Iterator[dict[str, Path]]:
    """Register each case's driver entry and write its rig config; yield case -> config path.

    Parameters
    ----------
    folder : Path
        Where the configs are written (``<case>.toml``).
    drivers : mapping of str to (DriverEntry, str)
        Case -> the entry to register and the TOML table(s) appended to the minimal rig.
    """
    registered: list[str] = []
    try:
        configs = {}
        for case, (entry, table) in drivers.items():
            registry.register(entry)
            registered.append(entry.name)
            path = folder / f"{case}.toml"
            path.write_text(MINIMAL_RIG.read_text() + table)
            configs[case] = path
        yield configs
    finally:
        for name in registered:
            registry.unregister(name)
