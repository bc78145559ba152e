"""The rig config of a running simulated rig, as a real rig's: ``windrig simulate --write-config``.

Responsibility: :func:`live_config_text` rewrites a simulated rig's TOML text so that every
instrument's ``url`` is its running simulator's (``tcp://127.0.0.1:port``, ``socket://`` or a pty
path, ``modbus+tcp://127.0.0.1:port``; the scanner gets its binary ``data_port`` too) and its
``[simulation]`` tables are left out: the result is the config of a real rig whose instruments
happen to be simulators, so that ``windrig check --config OUT`` and ``windrig acquire --config
OUT`` go through the production path end to end (no ``--simulate``). The text is edited line by
line (comments and layout kept) and parsed again: the rewritten config must give exactly the
simulators' URLs, else :class:`~daq.errors.ConfigError` says which. :func:`write_live_config`
writes it atomically (a reader never sees half a file).

Not responsible for: starting the simulators (:mod:`daq.sim.rig`).
"""

from __future__ import annotations

import datetime
import os
import re
from collections.abc import Mapping
from pathlib import Path

from daq.config import ROLES, InstrumentConfig, RigConfig, parse_rig_config
from daq.errors import ConfigError

__all__ = ["live_config_text", "write_live_config"]

#: A table header (``[fan]``, ``[[lasers]]``, ``[simulation.devices.fan]``), comment allowed. A
#: name starts with a letter or an underscore, so that a line of a multi-line array (``[0.5]``)
#: is not taken for one.
_HEADER = re.compile(r'^\s*(\[\[?)\s*([A-Za-z_][A-Za-z0-9_.\-]*)\s*\]\]?\s*(#.*)?$')
_KEY = re.compile(r"^\s*(url|data_port)\s*=")


def live_config_text(config: RigConfig, urls: Mapping[str, str],
                     data_ports: Mapping[str, int] | None = None, *, note: str = "") -> str:
    """Return ``config``'s TOML text with the simulators' URLs and no ``[simulation]`` tables.

    Parameters
    ----------
    config : RigConfig
        The simulated rig's config, as loaded (its ``text``).
    urls : mapping of str to str
        URL of every instrument, by name (``SimulatedRig.urls``).
    data_ports : mapping of str to int, optional
        The binary data port of each scanner, by name.
    note : str
        Comment lines put at the top (each prefixed with ``#`` and a space).

    Raises
    ------
    ConfigError
        An instrument has no URL given, or the rewritten text does not give every instrument
        its URL (a ``url`` key the line editor could not find, e.g. in an inline table).
    """
    data_ports = dict(data_ports or {})
    missing = sorted({inst.name for inst in config.instruments} - set(urls))
    if missing:
        raise ConfigError(f"{config.source}: no simulator URL for instrument(s) {missing}")
    seen: dict[str, int] = {}
    table: InstrumentConfig | None = None  # the instrument whose table is being read
    skipping = False
    out = [f"# {line}".rstrip() for line in note.splitlines()]
    for line in config.text.splitlines():
        header = _HEADER.match(line)
        if header is not None:
            name = header.group(2)
            skipping = name == "simulation" or name.startswith("simulation.")
            table = None
            if name in ROLES and not skipping:
                index = seen.get(name, 0)
                seen[name] = index + 1
                of_role = config.by_role(name)
                table = of_role[index] if index < len(of_role) else None
        if skipping:
            continue
        key = _KEY.match(line)
        if key is not None and table is not None:
            inst = table
            if key.group(1) == "data_port":
                continue  # written after the url below
            out.append(f'url = "{urls[inst.name]}"')
            if inst.name in data_ports:
                out.append(f"data_port = {int(data_ports[inst.name])}")
            continue
        out.append(line)
    text = "\n".join(out) + "\n"
    rewritten = parse_rig_config(text, source=config.source)
    wrong = [inst.name for inst in rewritten.instruments
             if inst.url != urls[inst.name] or (inst.name in data_ports and
                                                inst.settings.get("data_port")
                                                != data_ports[inst.name])]
    if wrong or rewritten.simulation is not None:
        raise ConfigError(f"{config.source}: cannot rewrite the URLs of {wrong or 'the rig'}: "
                          "write each instrument's url on a line of its own table")
    return text


def write_live_config(config: RigConfig, urls: Mapping[str, str], out: str | Path,
                      data_ports: Mapping[str, int] | None = None) -> Path:
    """Write :func:`live_config_text` to ``out`` atomically; return its path.

    The file's first lines say what it is: when and from which config it was written, and that
    its URLs are valid while the ``windrig simulate`` process that wrote it runs.
    """
    path = Path(out)
    now = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    note = (f"Written by `windrig simulate --write-config` at {now} (process {os.getpid()}) "
            f"from {config.source}.\nThe URLs are its simulated instruments on 127.0.0.1, "
            "valid while that command runs; its [simulation]\ntables are left out: use it as "
            "a real rig's config (windrig check / acquire --config, no --simulate).")
    text = live_config_text(config, urls, data_ports, note=note)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except OSError as exc:  # name the file asked for, not the temporary beside it
        raise OSError(exc.errno, exc.strerror, str(path)) from exc
    return path
