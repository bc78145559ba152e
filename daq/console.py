"""``windrig gui``: start the operator console on a replayed run (live mode comes later).

Responsibility: turn the command-line options into a data source and a
:class:`~daq.live.ConsoleWindow`, run Qt's event loop (or, with ``screenshot``, render headless
for ``after`` seconds, save the window as PNG and return), and turn bad input into one clear
message and exit code 2. Qt is imported only once the input has been checked.

Not responsible for: the window's content (:mod:`daq.live`) or reading files (:mod:`daq.replay`).
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from daq.replay import ReplayError, ReplaySource

__all__ = ["GuiOptions", "run_gui"]

#: Exit code of bad input (argparse's own code for usage errors).
EXIT_USAGE = 2


@dataclass(frozen=True)
class GuiOptions:
    """Options of ``windrig gui``.

    Attributes
    ----------
    replay : Path or None
        Run file to replay.
    config : Path or None
        Rig config of a live console (not yet available).
    simulate : bool
        Live console on the simulated rig (not yet available).
    speed : float
        Replay speed, > 0 (1: real time).
    window_s : float
        Scrolling time window, s.
    screenshot : Path or None
        Save a PNG of the window and exit, instead of showing it.
    after_s : float
        Seconds of wall time to run before the screenshot, >= 0.
    size : tuple of int
        Window size, pixels (width, height): the size of the screenshot.
    """

    replay: Path | None = None
    config: Path | None = None
    simulate: bool = False
    speed: float = 1.0
    window_s: float = 20.0
    screenshot: Path | None = None
    after_s: float = 3.0
    size: tuple[int, int] = (1280, 800)


def _error(message: str) -> int:
    print(f"error: {message}", file=sys.stderr)
    return EXIT_USAGE


def run_gui(options: GuiOptions) -> int:
    """Run the console; return the process exit code (0 ok, 2 bad input).

    Parameters
    ----------
    options : GuiOptions
        What to show and how.

    Returns
    -------
    int
        0 on success, 2 for bad input (missing or unreadable file, bad option values, live
        mode), with a one-line message on stderr.
    """
    if options.replay is None:
        if options.config is not None or options.simulate:
            return _error("live mode: not yet available (use --replay FILE.h5)")
        return _error("give --replay FILE.h5 (live mode: not yet available)")
    if not options.speed > 0:
        return _error(f"--speed {options.speed:g}: must be > 0")
    if not options.window_s > 0:
        return _error(f"--window {options.window_s:g}: must be > 0 s")
    if not options.after_s >= 0:
        return _error(f"--after {options.after_s:g}: must be >= 0 s")
    if min(options.size) < 1:
        return _error(f"--size {options.size[0]} {options.size[1]}: must be >= 1 px")
    if options.screenshot is not None and not options.screenshot.parent.is_dir():
        return _error(f"--screenshot {options.screenshot}: no such directory "
                      f"{options.screenshot.parent}")
    source = ReplaySource(options.replay, speed=options.speed, window_s=options.window_s)
    try:
        source.open()
    except ReplayError as exc:
        return _error(str(exc))
    try:
        return _run_window(source, options)
    finally:
        source.close()


def _run_window(source: ReplaySource, options: GuiOptions) -> int:
    headless = options.screenshot is not None
    if headless and not os.environ.get("QT_QPA_PLATFORM") \
            and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        os.environ["QT_QPA_PLATFORM"] = "offscreen"  # must precede the QApplication
    from PySide6 import QtCore, QtWidgets

    from daq.live import ConsoleWindow

    app: Any = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    window = ConsoleWindow(source, window_s=options.window_s)
    try:
        window.resize(*options.size)
        window.show()
        if options.screenshot is None:  # pragma: no cover - interactive
            return int(app.exec())
        loop = QtCore.QEventLoop()
        QtCore.QTimer.singleShot(int(round(options.after_s * 1000)), loop.quit)
        loop.exec()
        window.tick()  # draw what is due at exactly S s
        image = window.grab()
    finally:
        window.close()
        window.deleteLater()
    if source.error is not None:
        return _error(source.error)
    if not image.save(str(options.screenshot), "PNG"):
        return _error(f"--screenshot {options.screenshot}: could not write the PNG")
    print(f"wrote {options.screenshot} ({image.width()} x {image.height()} px, "
          f"{source.status()})")
    return 0
