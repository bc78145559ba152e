"""A run's experiment log: its events as plain text beside the run file (RUN.h5 -> RUN.events.log).

Responsibility: :class:`ExperimentLog` receives every row the recorder appends to
``/entry/events`` (it is the :class:`~daq.recording.recorder.RunRecorder`'s ``event_sink``) and
appends it to a text file as one line: the event's UTC time (ISO 8601, ms), its run time (s
from the run's time 0, as in the file), its kind, its device ("-" when none) and its text (the
file's text without the device prefix). So the log holds what the file's events hold, by
construction, and is readable with no HDF5 tool, during the run too (each line is written and
closed at once, so a crash loses none). The trigger pulses that anchor the clocks (``trigger``,
every 0.5 s) stay in the file only: they are not actions or state changes.

A failure to write the log (a full disk) is logged once and ends the text log; the run file,
which holds the same events, goes on.

Not responsible for: the events themselves (the engine's commands, the run writer) or the HDF5
rows (:mod:`daq.recording.recorder`).
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable, Iterable
from pathlib import Path

from daq.errors import UsageError
from daq.log_file import LOGGERS

__all__ = ["LOG_SKIPPED_KINDS", "ExperimentLog", "experiment_log_path", "refuse_logging_to"]

log = logging.getLogger(__name__)

#: Event kinds kept in the run file but not in its text log.
LOG_SKIPPED_KINDS = frozenset({"trigger"})


def experiment_log_path(run_path: str | Path) -> Path:
    """Return the text log's path of a run file: ``RUN.h5`` -> ``RUN.events.log``.

    Not ``RUN.log``: that is the name a user gives ``--log-file`` (the program's own log).
    """
    return Path(run_path).with_suffix(".events.log")


def refuse_logging_to(path: str | Path) -> None:
    """Refuse a text log that a command's log file already is (``--log-file RUN.events.log``).

    Raises
    ------
    UsageError
        A ``logging`` file handler of windrig's loggers (or the root's) writes to ``path``.
    """
    target = os.path.abspath(path)
    for name in ("", *LOGGERS):
        for handler in logging.getLogger(name).handlers:
            if isinstance(handler, logging.FileHandler) and handler.baseFilename == target:
                raise UsageError(f"--log-file {path} is the run's experiment log (its events "
                                 "as text, beside the run file): give the log file another name")


class ExperimentLog:
    """The text log of one run (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The log file; created (replacing an old one) with a header line.
    devices : iterable of str
        The rig's instrument names: an event text starting ``"<name>: "`` gives its device.
    t0_ns : callable
        Returns the host ``time.monotonic_ns()`` of the run's time 0 (the run writer's
        ``t0_ns``, known once the run started).
    run_file : str
        The run file's name, for the header.
    """

    def __init__(self, path: str | Path, devices: Iterable[str], t0_ns: Callable[[], int],
                 run_file: str = "") -> None:
        self.path = Path(path)
        self._devices = sorted(set(devices), key=len, reverse=True)  # longest name first
        self._t0_ns = t0_ns
        self.error: OSError | None = None
        self.lines = 0
        self._append(f"# windrig experiment log{f' of {run_file}' if run_file else ''}: UTC "
                     "time, run time (s), kind, device, text\n", mode="w")

    def __call__(self, t: float, kind: str, text: str) -> None:
        """Append one event row of the run file (``t`` s from the run's time 0)."""
        if kind in LOG_SKIPPED_KINDS or self.error is not None:
            return
        device = "-"
        for name in self._devices:
            if text.startswith(f"{name}: "):
                device, text = name, text[len(name) + 2:]
                break
        host_ns = self._t0_ns() + round(t * 1e9)
        wall = time.time() - (time.monotonic_ns() - host_ns) * 1e-9
        stamp = time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(wall))
        millis = int(wall % 1.0 * 1000)
        text = " ".join(text.splitlines())
        if self._append(f"{stamp}.{millis:03d}Z {t:10.3f} {kind:<18} {device:<12} {text}\n"):
            self.lines += 1

    def _append(self, line: str, mode: str = "a") -> bool:
        try:
            with self.path.open(mode, encoding="utf-8") as f:
                f.write(line)
        except OSError as exc:  # the run file keeps the events; the text log ends here
            self.error = exc
            log.error("experiment log %s: cannot write (%s); its events stay in the run file",
                      self.path, exc)
            return False
        return True
