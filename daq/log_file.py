"""A log file for a command's run: every ``logging`` record of windrig's packages, timestamped.

Responsible for: opening the file (refusing at once, with a specific error, a path that cannot
be written), attaching one handler to the loggers of :mod:`daq`, :mod:`ident` and
:mod:`simulators` (which are otherwise silent: no handler, the records go nowhere), and removing
it again. ``windrig acquire --log-file PATH`` uses it, so that a run's device faults, reconnects,
dropped blocks and clock restarts are on disk beside its run file.

Not responsible for: what is logged (each module logs through ``logging.getLogger(__name__)``).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

__all__ = ["LEVELS", "LOGGERS", "close_log_file", "open_log_file"]

#: The packages whose records go to the file.
LOGGERS = ("daq", "ident", "simulators")

#: Levels a user may choose.
LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR")

_FORMAT = "%(asctime)s.%(msecs)03d %(levelname)-7s %(name)s [%(threadName)s] %(message)s"


def open_log_file(path: str | os.PathLike[str], level: str = "INFO") -> logging.Handler:
    """Start logging windrig's records to ``path`` (appended to, created if missing).

    Parameters
    ----------
    path : path-like
        The log file; its folder must exist.
    level : {"DEBUG", "INFO", "WARNING", "ERROR"}
        The lowest level written.

    Returns
    -------
    logging.Handler
        Pass it to :func:`close_log_file` when the run ends.

    Raises
    ------
    ValueError
        If ``level`` is not one of :data:`LEVELS`.
    OSError
        If the file cannot be opened for appending (no such folder, no permission): raised
        before anything is logged, with the path in ``filename``.
    """
    if level not in LEVELS:
        raise ValueError(f"log level {level!r}: expected one of {', '.join(LEVELS)}")
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(21, "Is a directory (give a file name)", str(path))
    handler = logging.FileHandler(path, mode="a", encoding="utf-8")  # raises OSError now
    handler.setFormatter(logging.Formatter(_FORMAT, datefmt="%Y-%m-%dT%H:%M:%S"))
    handler.setLevel(level)
    for name in LOGGERS:
        logger = logging.getLogger(name)
        logger.addHandler(handler)
        if logger.level == logging.NOTSET or logger.level > handler.level:
            logger.setLevel(handler.level)
    return handler


def close_log_file(handler: logging.Handler) -> None:
    """Stop logging to the file of :func:`open_log_file` and close it."""
    for name in LOGGERS:
        logging.getLogger(name).removeHandler(handler)
    handler.close()
