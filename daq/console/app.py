"""``windrig gui``: start the operator console on a replayed run or a live (simulated) rig.

Responsibility: turn the command-line options into a data source (a
:class:`~daq.console.replay.ReplaySource`, or a
:class:`~daq.console.process_source.ProcessLiveSource`: the acquisition in a child process, the
simulated rig in another) and a :class:`~daq.console.window.ConsoleWindow`, run Qt's event loop (or,
with ``screenshot``, render headless for ``after`` seconds, save the window as PNG and return), and
turn bad input into one clear message and exit code 2. Qt is imported only once the input has been
checked.

Not responsible for: the window's content (:mod:`daq.console.window`), reading files
(:mod:`daq.console.replay`) or acquiring (:mod:`daq.console.live_source`).
"""

from __future__ import annotations

import os
import signal
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from daq.config import load_rig_config
from daq.console.process_source import ProcessLiveSource
from daq.console.replay import ReplaySource
from daq.console.source import DataSource
from daq.errors import ConfigError, DaqError, ReplayError
from daq.procedure import default_decay_s

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
        Rig config of a live console.
    simulate : bool
        Live console on the config's simulated rig (started in a child process).
    fan_rpm : float or None
        Live: start the fan at this speed (within the config's limits); None leaves it alone.
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
    record_dir : Path or None
        Live: directory of the run files recorded from the console (it must exist); None: the
        current directory.
    auto_release : tuple of float
        Simulated live rig only: fan speeds (rpm) of a hands-free programme, one release each
        (:mod:`daq.console.auto_release`); empty: none.
    check : bool
        Live: check every device before the engine starts (``windrig check``); a failing
        device stops the console before it opens, every failing one named.
    """

    replay: Path | None = None
    config: Path | None = None
    simulate: bool = False
    fan_rpm: float | None = None
    speed: float = 1.0
    window_s: float = 20.0
    screenshot: Path | None = None
    after_s: float = 3.0
    size: tuple[int, int] = (1280, 800)
    record_dir: Path | None = None
    auto_release: tuple[float, ...] = ()
    check: bool = True


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
        0 on success, 2 for bad input (missing or unreadable file or config, bad option values),
        1 when the live rig fails to start or stops with an error, with a one-line message on
        stderr.
    """
    if options.replay is None and options.config is None:
        return _error("give --replay FILE.h5, or --config CONFIG.toml [--simulate] (live)")
    if options.replay is not None and (options.config is not None or options.simulate):
        return _error("--replay FILE.h5 and --config/--simulate (live) exclude each other")
    if options.fan_rpm is not None and not options.fan_rpm >= 0:
        return _error(f"--fan-rpm {options.fan_rpm:g}: must be >= 0 rpm")
    if not options.speed > 0:
        return _error(f"--speed {options.speed:g}: must be > 0")
    if not options.window_s > 0:
        return _error(f"--window {options.window_s:g}: must be > 0 s")
    if not options.after_s >= 0:
        return _error(f"--after {options.after_s:g}: must be >= 0 s")
    if min(options.size) < 1:
        return _error(f"--size {options.size[0]} {options.size[1]}: must be >= 1 px")
    if options.record_dir is not None:
        if options.replay is not None:
            return _error("--record-dir is for the live console (--config), not --replay")
        if not options.record_dir.is_dir():
            return _error(f"--record-dir {options.record_dir}: no such directory")
    if options.auto_release and not options.simulate:
        return _error("--auto-release drives the rig by itself: only for a simulated live rig "
                      "(--config C --simulate)")
    if options.screenshot is not None and not options.screenshot.parent.is_dir():
        return _error(f"--screenshot {options.screenshot}: no such directory "
                      f"{options.screenshot.parent}")
    if options.replay is None:
        return _run_live(options)
    source = ReplaySource(options.replay, speed=options.speed, window_s=options.window_s)
    try:
        source.open()
    except ReplayError as exc:
        return _error(str(exc))
    try:
        return _run_window(source, options)
    finally:
        source.close()


def _run_live(options: GuiOptions) -> int:
    assert options.config is not None
    try:
        config = load_rig_config(options.config)
    except ConfigError as exc:
        return _error(str(exc))
    if config.limits is not None and options.fan_rpm is not None \
            and options.fan_rpm > config.limits.max_fan_rpm:
        return _error(f"--fan-rpm {options.fan_rpm:g}: above the rig's max_fan_rpm "
                      f"{config.limits.max_fan_rpm:g}")
    for rpm in options.auto_release:
        if config.limits is not None and not 0 < rpm <= config.limits.max_fan_rpm:
            return _error(f"--auto-release {rpm:g}: fan speeds must be in (0, max_fan_rpm = "
                          f"{config.limits.max_fan_rpm:g}] rpm")
    if not options.simulate:
        auto = [inst.name for inst in config.instruments if inst.url == "auto"]
        if auto:
            return _error(f"{options.config}: instrument(s) {auto} have url = 'auto' (a "
                          "simulated rig): pass --simulate, or give their real URLs")
    # The console's recording row suggests files in record_dir (ControlPanel reads it from the
    # source: the window needs no option of its own).
    source = ProcessLiveSource(config, simulate=options.simulate, window_s=options.window_s,
                               fan_rpm=options.fan_rpm, record_dir=options.record_dir,
                               check=options.check)
    try:
        source.open()
    except (DaqError, RuntimeError, TimeoutError, OSError) as exc:
        first, *more = str(exc).splitlines() or [""]  # a device check: one line per device
        print("\n".join(f"error: {line}" for line in
                        [f"the live rig did not start: {first}", *more]), file=sys.stderr)
        return 1
    try:
        return _run_window(source, options)
    finally:
        source.close()


def _run_window(source: DataSource, options: GuiOptions) -> int:
    headless = options.screenshot is not None
    if headless and not os.environ.get("QT_QPA_PLATFORM") \
            and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        os.environ["QT_QPA_PLATFORM"] = "offscreen"  # must precede the QApplication
    # Qt only now: the input is checked, and QT_QPA_PLATFORM must be set before it loads.
    from PySide6 import QtCore, QtWidgets

    from daq.console.window import ConsoleWindow

    app: Any = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    window = ConsoleWindow(source, window_s=options.window_s)
    auto = None
    if options.auto_release and window.controls is not None:
        from daq.console.auto_release import AutoReleaser  # Qt, as the window

        auto = AutoReleaser(window.controls, source, options.auto_release,
                            default_decay_s(source.info.config.section), parent=window)
        auto.start()
    try:
        window.resize(*options.size)
        window.show()
        if options.screenshot is None:  # pragma: no cover - interactive
            # Ctrl-C closes the window as its close button does (the timer's ticks let Python
            # run the handler): the source then closes in order.
            signal.signal(signal.SIGINT, lambda *_: window.close())
            return int(app.exec())
        loop = QtCore.QEventLoop()
        QtCore.QTimer.singleShot(int(round(options.after_s * 1000)), loop.quit)
        loop.exec()
        window.tick()  # draw what is due at exactly S s
        image = window.grab()
        status = source.status()
    finally:
        if auto is not None:
            auto.stop()
        window.close()
        window.deleteLater()
    if source.error is not None:
        print(f"error: {source.error}", file=sys.stderr)
        return 1 if options.replay is None else EXIT_USAGE
    if not image.save(str(options.screenshot), "PNG"):
        return _error(f"--screenshot {options.screenshot}: could not write the PNG")
    print(f"wrote {options.screenshot} ({image.width()} x {image.height()} px, {status})")
    return 0
