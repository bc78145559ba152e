"""``windrig check`` and ``windrig simulate``: the two commands that may start a simulated rig.

Responsibility: the bodies of two subcommands of :mod:`daq.cli` (which parses their arguments):
:func:`run_check` checks every device of a rig (:mod:`daq.acquisition.device_check`), its real
URLs or, with ``simulate``, the simulators it starts here, prints one table and one line per
failing device, and writes the results as JSON on request; :func:`run_simulate` starts the
simulated instruments of a rig config, prints their URLs and, on request, writes a rig config
whose URLs are theirs (:mod:`daq.sim.live_config`), then serves until Ctrl-C or a duration.

Not responsible for: the checks themselves (:mod:`daq.acquisition.device_check`) or the
simulators (:mod:`daq.sim.rig`).
"""

from __future__ import annotations

import json
import logging
import sys
import time
from contextlib import ExitStack
from pathlib import Path

from daq.acquisition.device_check import check_rig, failure_lines, format_table
from daq.config import RigConfig, load_rig_config
from daq.errors import UsageError
from daq.sim.live_config import write_live_config
from daq.sim.rig import start_simulated_rig

__all__ = ["refuse_auto_urls", "run_check", "run_simulate"]


def run_check(config_path: Path, *, simulate: bool = False, json_path: Path | None = None,
              timeout_s: float = 2.0, debug: bool = False) -> int:
    """Check every device of a rig; print the table; return 0 when all pass, else 1.

    Parameters
    ----------
    config_path : Path
        The rig config.
    simulate : bool
        Start the rig's simulated instruments and check them (else: the config's URLs).
    json_path : Path, optional
        Also write every device's result to this JSON file.
    timeout_s : float
        Longest check of one device, s.
    debug : bool
        Also print the traceback of every exception a device's check raised (``--debug``;
        without it each is one line of the table's failures).
    """
    if debug:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("%(name)s: %(message)s"))
        check_log = logging.getLogger("daq.acquisition.device_check")
        check_log.addHandler(handler)
        check_log.setLevel(logging.DEBUG)
    try:
        return _run_check(config_path, simulate, json_path, timeout_s)
    finally:
        if debug:
            check_log.removeHandler(handler)
            check_log.setLevel(logging.NOTSET)


def _run_check(config_path: Path, simulate: bool, json_path: Path | None,
               timeout_s: float) -> int:
    if not (timeout_s > 0.5):
        raise UsageError(f"--timeout {timeout_s:g}: must be > 0.5 s (each device is read for "
                         "0.5 s)")
    if json_path is not None and not json_path.parent.is_dir():
        # Checked first: a report that cannot be written is known before the devices are.
        raise UsageError(f"--json {json_path}: folder {json_path.parent} does not exist")
    config = load_rig_config(config_path)
    with ExitStack() as stack:
        live = config
        if simulate:
            live = stack.enter_context(start_simulated_rig(config)).config
        else:
            refuse_auto_urls(config, config_path)
        results = check_rig(live, timeout_s=timeout_s)
    print(f"{config.name} ({config.source}): {len(results)} device(s)")
    print(format_table(results))
    failed = failure_lines(results)
    for line in failed:
        print(f"FAIL {line}")
    names = ", ".join(r.device for r in results if not r.ok)
    print(f"{len(results) - len(failed)} of {len(results)} device(s) OK"
          + (f"; failing: {names}" if failed else ""))
    if json_path is not None:
        json_path.write_text(json.dumps({
            "config": config.source, "rig": config.name, "simulated": simulate,
            "ok": not failed, "devices": [r.to_dict() for r in results]}, indent=2))
        print(f"wrote {json_path}")
    return 0 if not failed else 1


def run_simulate(config_path: Path, *, serial: str = "socket", duration_s: float | None = None,
                 write_config: Path | None = None) -> int:
    """Start a rig config's simulated instruments, print their URLs, serve until stopped.

    Parameters
    ----------
    config_path : Path
        A simulated rig's config (its ``[simulation]`` table).
    serial : {"socket", "pty"}
        How serial instruments are served.
    duration_s : float, optional
        Stop after this long, s (default: until Ctrl-C).
    write_config : Path, optional
        Write a rig config whose URLs are the simulators' (:mod:`daq.sim.live_config`), once
        they all run.
    """
    if duration_s is not None and not duration_s > 0:
        raise UsageError(f"--duration {duration_s:g}: must be > 0 s")
    config = load_rig_config(config_path)
    with start_simulated_rig(config, serial=serial) as rig:
        print(f"{config.name}: simulated instruments on 127.0.0.1 (Ctrl-C stops them)")
        for inst in rig.config.instruments:
            extra = (f"  (binary data port {inst.settings['data_port']})"
                     if "data_port" in inst.settings else "")
            print(f"  {inst.name:<14} {inst.driver:<22} {inst.url}{extra}")
        if write_config is not None:
            ports = {inst.name: int(inst.settings["data_port"])
                     for inst in rig.config.instruments if "data_port" in inst.settings}
            written = write_live_config(config, rig.urls, write_config, ports)
            print(f"wrote {written}: windrig check --config {written}")
        sys.stdout.flush()
        try:
            if duration_s is None:
                while True:
                    time.sleep(1.0)
            else:
                time.sleep(duration_s)
        except KeyboardInterrupt:
            print("stopping the simulators")
    return 0


def refuse_auto_urls(config: RigConfig, path: Path) -> None:
    """Refuse a config whose instruments have ``url = "auto"`` (simulators not started)."""
    auto = [inst.name for inst in config.instruments if inst.url == "auto"]
    if auto:
        raise UsageError(f"{path}: instrument(s) {auto} have url = 'auto' (a simulated rig): "
                         "pass --simulate, or give their real URLs")
