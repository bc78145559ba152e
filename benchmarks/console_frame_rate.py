"""Frame rate and CPU use of the live operator console, 62 and 511 taps (issue 6).

What is measured
----------------
The real console: :class:`daq.console.window.ConsoleWindow` (1280 x 800, 20 s window, its own
``QTimer`` of ``daq.console.window.FRAME_MS``) under Qt's ``offscreen`` platform, polling the source
``windrig gui`` uses, a :class:`daq.console.process_source.ProcessLiveSource`: the real drivers,
engine and :class:`~daq.recording.writer.RunWriter` run in a child process (the *acquisition
process*) and hand the synchronised rows over shared memory; the simulated instruments run in that
child's own child (:mod:`daq.sim.rig_process`), on the same two cores. The ``threads`` run puts the
acquisition back into this process as threads (:class:`daq.console.live_source.LiveSource`), for
comparison. The fan runs (``--fan-rpm``, 800 rpm = 8 m/s by default, ramped fast) so that pressures,
Cp, lift and moment move, and a helper thread arms and releases the model through ``source.acq``
every ``RELEASE_EVERY_S`` so that the traces show free decays. Rigs:

- ``sim_flat_plate.toml`` as shipped: 1 scanner module, 62 taps + the Pitot.
- The same rig widened to 8 scanner modules x 64 channels: **511 taps + the Pitot** (512
  channels). 512 taps cannot be configured: the config reserves a scanner channel of its own
  for the Pitot (``daq.config._check_scanner_channels``), and 8 modules are the scanner's
  maximum. The taps are spread evenly around the flat plate's outline (a ``polygon`` taps table
  with the plate's B x D corners: the ``rectangle`` shape makes 2 n + 2 (n // 8) taps, 510 at
  most). The TOML text is built here and parsed by :func:`daq.config.parse_rig_config`.
- Optionally (``--runs ...,replay``, on by default) a run of the 511-tap rig recorded first with
  :func:`daq.recording.run.record_run` and played back in real time by
  :class:`daq.console.replay.ReplaySource`: the console's own cost without acquisition in the
  process. The same file is also played with ``frame_ms = 0`` (the timer fires whenever Qt is idle,
  and a replay has new rows at every poll): the most frames/s the GUI thread can draw, i.e. the
  headroom above the 20 frames/s target.

What a "frame" is
-----------------
The window's timer slot :meth:`ConsoleWindow.tick` polls the source; when the source has new
rows it calls :meth:`ConsoleWindow.redraw` (``setData`` on every curve, the spectra, Cp and the
outline's tap colours), which schedules a repaint that Qt performs later in the event loop. A
**frame** here is one redraw; it counts as *rendered* when the plots were repainted after it:
the benchmark counts (and times) every ``paintEvent`` of the window's pyqtgraph views (a
class-level wrapper of ``pyqtgraph.GraphicsView.paintEvent`` in this process only; daq/ is not
edited), and reports the repaints of the h-trace plot per second next to the redraws. After each
run a few ``window.grab()`` calls render the whole window into a pixmap (timed, and the number
of distinct colours in the image is shown, to prove that real content was drawn).

Numbers per run (``--seconds`` after ``--warmup``): ticks/s, frames/s (redraws), h-plot
repaints/s, ring appends/s (how often the live pipeline hands rows to the ring, where it does
so in this process: a tick that finds no new rows draws nothing), tick wall durations (median,
p95, max, ms), CPU of this process in % of one core (split into the GUI thread, from
``/proc/self/task``, and the rest: Qt's threads, and the acquisition's in the ``threads`` run),
CPU of the acquisition process and of the simulated rig's process (``/proc/<pid>/stat``),
resident memory (``VmRSS``), the GUI thread's CPU per frame and the time of the tap colouring
(``_tap_brushes`` and ``ScatterPlotItem.setBrush``). The 511-tap live run is then profiled on
the GUI thread (cProfile, ``--profile-seconds``, CPU time then wall time), ticks and painting
together.

An experiment (not in the default runs): the ``threads`` run again with the GIL's switch
interval at 0.5 ms (``switch``: ``sys.setswitchinterval``; Python's default is 5 ms).

Run: ``.venv/bin/python benchmarks/console_frame_rate.py [--seconds 30] [--warmup 5]
[--runs flat,wide,threads,replay]``. Takes about 5 minutes; the machine's load average is
printed (other work on the two cores lowers every number here). ``--quick`` (CI): the ``flat``
run only, 3 s after a 1 s warm-up (``--runs``, ``--seconds``, ``--warmup`` choose otherwise);
``--results DIR`` writes the tables (``benchmarks/result_files.py``). Where Qt cannot be
imported the result file says so and the script exits 1.
"""

from __future__ import annotations

import os

# Before Qt is imported: headless, as `windrig gui --screenshot` and the tests run it.
os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

import argparse  # noqa: E402
import cProfile  # noqa: E402
import io  # noqa: E402
import math  # noqa: E402
import pstats  # noqa: E402
import re  # noqa: E402
import shutil  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
import tomllib  # noqa: E402
from collections.abc import Callable, Iterator  # noqa: E402
from contextlib import contextmanager  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from daq.config import RigConfig, parse_rig_config  # noqa: E402

#: Why Qt (PySide6, pyqtgraph, the console) could not be imported; None when it could.
QT_ERROR: ImportError | None = None
try:
    import pyqtgraph as pg
    from PySide6 import QtCore, QtGui, QtWidgets

    from daq.console.live_source import LiveSource
    from daq.console.process_source import ProcessLiveSource
    from daq.console.replay import ReplaySource
    from daq.console.source import DataSource
    from daq.console.window import FRAME_MS, ConsoleWindow
except ImportError as _exc:  # nothing can be measured: main() writes the result file saying so
    QT_ERROR = _exc
    pg = QtCore = QtGui = QtWidgets = None  # type: ignore[assignment]
    LiveSource = ProcessLiveSource = ReplaySource = DataSource = None  # type: ignore
    FRAME_MS = None  # type: ignore[assignment]
    ConsoleWindow = object  # type: ignore[assignment,misc]

sys.path.insert(0, str(Path(__file__).resolve().parent))
import result_files  # noqa: E402 - beside this script

ROOT = Path(__file__).resolve().parents[1]
BASE_CONFIG = ROOT / "rig_configs" / "sim_flat_plate.toml"
#: The simulated drive ramps at 100 rpm/s by default; the tests' fast ramp reaches the set speed
#: within the warm-up.
FAST_FAN = "\n[simulation.devices.fan]\nramp_rpm_per_s = 4000.0\n"
MODULES = 8
N_TAPS_WIDE = 64 * MODULES - 1  # every channel but the Pitot's
WINDOW_S = 20.0
WINDOW_SIZE = (1280, 800)
#: Issue 6's target, and how far below it still counts as met (frames/s).
TARGET_FPS = 20.0
TARGET_TOLERANCE_FPS = 0.5
#: Arm, then release this long after, every RELEASE_EVERY_S (helper thread), s.
RELEASE_EVERY_S = 10.0
ARM_TO_RELEASE_S = 1.5
#: window.grab() calls after each run (full-window renders, timed).
GRABS = 5
CLK_TCK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
#: Runs, in order (see --runs).
RUNS = ("flat", "wide", "threads", "switch", "replay")
#: Runs when --runs is not given.
DEFAULT_RUNS = ("flat", "wide", "threads", "replay")
#: The GIL switch interval of the "switch" run, s (Python's default is 5 ms).
SWITCH_INTERVAL_S = 0.0005
#: Defaults: (full run, --quick) per option.
DEFAULTS = {"seconds": (30.0, 3.0), "warmup": (5.0, 1.0), "profile_seconds": (5.0, 1.0),
            "runs": (",".join(DEFAULT_RUNS), "flat")}


# ------------------------------------------------------------------------------------------------
# Rig configs
# ------------------------------------------------------------------------------------------------
def flat_plate_config() -> RigConfig:
    """Return ``sim_flat_plate.toml`` as shipped (62 taps, 1 module), with a fast fan ramp."""
    text = BASE_CONFIG.read_text(encoding="utf-8") + FAST_FAN
    return parse_rig_config(text, f"{BASE_CONFIG.name} + fast fan ramp")


def wide_config() -> RigConfig:
    """Return the flat-plate rig with 8 scanner modules and 511 taps around the plate's outline.

    The ``[taps]`` table becomes a ``polygon`` with the corners of the shipped rectangle
    (B x D, centred) and ``n_taps = 511``; ``modules = 8`` and the Pitot on channel 511.
    """
    base = BASE_CONFIG.read_text(encoding="utf-8")
    taps = tomllib.loads(base)["taps"]
    half_b, half_d = 0.5 * float(taps["B"]), 0.5 * float(taps["D"])
    vertices = (f"[[{-half_b}, {-half_d}], [{half_b}, {-half_d}], [{half_b}, {half_d}], "
                f"[{-half_b}, {half_d}]]")
    taps_table = ("[taps]\n# generated by benchmarks/console_frame_rate.py: 511 taps evenly "
                  "around the plate's outline\nshape = \"polygon\"\n"
                  f"vertices = {vertices}\nn_taps = {N_TAPS_WIDE}\n\n")
    edits = ((r"(?ms)^\[taps\]\n.*?\n\n", taps_table),
             (r"(?m)^modules = \d+", f"modules = {MODULES}"),
             (r"(?m)^pitot_channel = \d+", f"pitot_channel = {N_TAPS_WIDE}"),
             (r'(?m)^name = "Simulated flat-plate rig"',
              'name = "Simulated flat-plate rig, 8 modules, 511 taps (benchmark)"'))
    text = base
    for pattern, replacement in edits:
        text, n = re.subn(pattern, replacement.replace("\\", r"\\"), text, count=1)
        if n != 1:
            raise RuntimeError(f"{BASE_CONFIG.name}: {pattern!r} not found; update the benchmark")
    config = parse_rig_config(text + FAST_FAN, f"{BASE_CONFIG.name}, widened to 8 modules")
    assert config.taps.n_taps == N_TAPS_WIDE
    return config


# ------------------------------------------------------------------------------------------------
# /proc: CPU and memory of processes and threads
# ------------------------------------------------------------------------------------------------
def _stat_cpu_s(path: Path) -> float:
    """Return utime + stime of a ``/proc/.../stat`` file, s (NaN when it cannot be read)."""
    try:
        text = path.read_text()
    except OSError:
        return math.nan
    fields = text[text.rindex(")") + 2:].split()  # after "pid (comm) ": state is fields[0]
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def process_cpu_s(pid: int) -> float:
    """CPU time (user + system) of process ``pid`` so far, s."""
    return _stat_cpu_s(Path(f"/proc/{pid}/stat"))


def child_pid(pid: int) -> int | None:
    """Return the pid of process ``pid``'s only child (the simulated rig), None without one."""
    try:
        children = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    except OSError:
        return None
    return int(children[0]) if len(children) == 1 else None


def rss_mib(pid: int) -> float:
    """Resident set size (``VmRSS``) of process ``pid``, MiB; NaN when not readable."""
    try:
        found = re.search(r"^VmRSS:\s+(\d+) kB", Path(f"/proc/{pid}/status").read_text(), re.M)
    except OSError:
        return math.nan
    return math.nan if found is None else int(found.group(1)) / 1024


def thread_cpu_s() -> dict[int, tuple[str, float]]:
    """CPU time so far of every thread of this process: tid -> (name, s).

    Python threads are named by ``threading`` (the main thread is the GUI thread); others
    (Qt's, h5py's) by their ``comm``.
    """
    names = {t.native_id: t.name for t in threading.enumerate() if t.native_id is not None}
    names[threading.main_thread().native_id or -1] = "GUI (main thread)"
    out = {}
    for task in Path("/proc/self/task").iterdir():
        tid = int(task.name)
        cpu = _stat_cpu_s(task / "stat")
        if math.isnan(cpu):
            continue
        if tid not in names:
            try:
                names[tid] = "[" + (task / "comm").read_text().strip() + "]"
            except OSError:
                names[tid] = f"[tid {tid}]"
        out[tid] = (names[tid], cpu)
    return out


def schedstat_s(tid: int) -> tuple[float, float]:
    """CPU time and run-queue wait (runnable, no core free) of thread ``tid`` so far, s."""
    try:
        fields = Path(f"/proc/self/task/{tid}/schedstat").read_text().split()
    except OSError:
        return math.nan, math.nan
    return int(fields[0]) * 1e-9, int(fields[1]) * 1e-9


def load_average() -> str:
    """Return the 1, 5 and 15 min load averages, as text."""
    try:
        return "{:.2f} {:.2f} {:.2f}".format(*os.getloadavg())
    except OSError:
        return "n/a"


# ------------------------------------------------------------------------------------------------
# The metered window
# ------------------------------------------------------------------------------------------------
@dataclass
class Meter:
    """What the metered window and the paint hook record while ``on``."""

    on: bool = False
    tick_wall: list[float] = field(default_factory=list)  # s per tick
    tick_cpu: list[float] = field(default_factory=list)  # GUI thread CPU s per tick
    redraws: int = 0
    redraw_wall: float = 0.0
    brushes_wall: float = 0.0  # _tap_brushes
    set_brush_wall: float = 0.0  # ScatterPlotItem.setBrush
    paints: dict[int, int] = field(default_factory=dict)  # id(view) -> paintEvents
    paint_wall: float = 0.0
    ring_appends: int = 0

    def reset(self) -> None:
        """Forget everything recorded so far."""
        fresh = Meter()
        for name in ("tick_wall", "tick_cpu", "redraws", "redraw_wall", "brushes_wall",
                     "set_brush_wall", "paints", "paint_wall", "ring_appends"):
            setattr(self, name, getattr(fresh, name))


METER = Meter()


def _install_paint_hook() -> None:
    """Count and time every paintEvent of a pyqtgraph view (this process only)."""
    original = pg.GraphicsView.paintEvent
    if getattr(original, "_benchmark_hook", False):
        return

    def paint_event(view: Any, ev: Any) -> Any:
        if not METER.on:
            return original(view, ev)
        t0 = time.perf_counter()
        try:
            return original(view, ev)
        finally:
            METER.paint_wall += time.perf_counter() - t0
            METER.paints[id(view)] = METER.paints.get(id(view), 0) + 1

    paint_event._benchmark_hook = True  # type: ignore[attr-defined]
    pg.GraphicsView.paintEvent = paint_event


class MeteredWindow(ConsoleWindow):
    """The console window, its tick, redraw and tap colouring timed into :data:`METER`."""

    def tick(self) -> None:
        if not METER.on:
            super().tick()
            return
        c0, t0 = time.thread_time(), time.perf_counter()
        super().tick()
        METER.tick_wall.append(time.perf_counter() - t0)
        METER.tick_cpu.append(time.thread_time() - c0)

    def redraw(self, snap: dict[str, Any], latest: dict[str, Any] | None = None,
               **kwargs: Any) -> None:
        t0 = time.perf_counter()
        super().redraw(snap, latest, **kwargs)
        if METER.on:
            METER.redraws += 1
            METER.redraw_wall += time.perf_counter() - t0

    def _tap_brushes(self, cp: Any) -> list[Any]:
        t0 = time.perf_counter()
        out = super()._tap_brushes(cp)
        if METER.on:
            METER.brushes_wall += time.perf_counter() - t0
        return out

    def hook_scatter(self) -> None:
        """Time ``setBrush`` of the outline's tap scatter (an instance-level wrapper)."""
        scatter = self._tap_scatter
        original = scatter.setBrush

        def set_brush(*args: Any, **kwargs: Any) -> Any:
            t0 = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                if METER.on:
                    METER.set_brush_wall += time.perf_counter() - t0

        scatter.setBrush = set_brush

    def h_view_id(self) -> int:
        """Return id() of the h-trace plot's view (its paints are the rendered frames)."""
        return id(self._plots[0])  # the h plot, made first

    def view_names(self) -> dict[int, str]:
        """Return id() of each plot's view -> a short name."""
        items: dict[str, Any] = dict(self.curves)
        items |= {"Cp": self.cp_curve, "outline": self._tap_scatter,
                  "spectra": self.spectrum_curves["h"]}
        out = {}
        for name, item in items.items():
            view = item.getViewWidget()
            if view is not None:
                out[id(view)] = name
        return out


def hook_ring(source: Any) -> None:
    """Count the pipeline's appends to a live or replay source's ring (instance wrapper)."""
    ring = getattr(source, "_ring", None)
    if ring is None:
        return
    original = ring.append

    def append(block: Any) -> None:
        before = ring.total_rows
        original(block)
        if METER.on and ring.total_rows > before:
            METER.ring_appends += 1

    ring.append = append


# ------------------------------------------------------------------------------------------------
# One run
# ------------------------------------------------------------------------------------------------
@dataclass
class Result:
    label: str
    taps: int
    seconds: float
    ticks_ps: float
    frames_ps: float
    paints_ps: float
    appends_ps: float
    tick_ms: tuple[float, float, float]  # median, p95, max
    gui_cpu: float  # % of one core, whole process
    gui_thread_cpu: float
    rig_cpu: float  # NaN without a child process
    acq_cpu: float  # the acquisition process (ProcessLiveSource); NaN without one
    rss: float
    rig_rss: float
    gui_split: tuple[float, float, float, float]  # GUI thread, % of wall: busy (in tick or
    #                                   paint), on a core, in the run queue, blocked (the GIL)
    gui_ms_per_frame: float  # GUI thread CPU per frame
    tick_cpu_share: float  # share of the GUI thread's CPU spent inside tick()
    redraw_ms: float
    brushes_ms: float
    set_brush_ms: float
    paint_ms: float  # all views' paints per frame
    grab_ms: float
    grab_colours: int
    threads: list[tuple[str, float]]  # (name, % of one core), largest first
    paints_per_frame: dict[str, float]  # per plot
    health: list[str]
    load: str


def spin(seconds: float) -> None:
    """Run Qt's event loop for ``seconds`` of wall time."""
    loop = QtCore.QEventLoop()
    QtCore.QTimer.singleShot(int(round(seconds * 1000)), loop.quit)
    loop.exec()


def grab_stats(window: QtWidgets.QWidget) -> tuple[float, int]:
    """Render the whole window ``GRABS`` times; return ms per grab and the colours drawn."""
    t0 = time.perf_counter()
    pixmap = None
    for _ in range(GRABS):
        pixmap = window.grab()
    ms = (time.perf_counter() - t0) / GRABS * 1e3
    assert pixmap is not None
    image = pixmap.toImage().convertToFormat(QtGui.QImage.Format.Format_RGB32)
    raw = np.frombuffer(image.constBits(), dtype=np.uint32,
                        count=image.sizeInBytes() // 4)
    return ms, int(np.unique(raw).size)


def cycle_releases(acq: Any, stop: threading.Event, first_s: float = 1.0) -> None:
    """Arm, then release the model, every RELEASE_EVERY_S until ``stop`` (helper thread)."""
    if stop.wait(first_s):
        return
    while True:
        try:
            acq.arm()
            if stop.wait(ARM_TO_RELEASE_S):
                return
            acq.release()
        except Exception as exc:  # the engine stopped under us: nothing more to do
            if not stop.is_set() and "not running" not in str(exc):
                print(f"  (arm/release: {type(exc).__name__}: {exc})", file=sys.stderr)
            return
        if stop.wait(RELEASE_EVERY_S - ARM_TO_RELEASE_S):
            return


@contextmanager
def console(source: DataSource, frame_ms: int) -> Iterator[MeteredWindow]:
    """Show a metered console window over ``source``; close it (and the source) at the end."""
    app: Any = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    assert app is not None
    window = MeteredWindow(source, window_s=WINDOW_S, frame_ms=frame_ms)
    window.hook_scatter()
    hook_ring(source)
    window.resize(*WINDOW_SIZE)
    window.show()
    try:
        yield window
    finally:
        METER.on = False
        window.close()  # stops the timer and closes the source
        window.deleteLater()
        QtCore.QCoreApplication.sendPostedEvents(None, QtCore.QEvent.Type.DeferredDelete)


def measure(label: str, source: DataSource, *, rig_pid: int | None, acq_pid: int | None,
            warmup_s: float, seconds: float, frame_ms: int = FRAME_MS,
            profile: Callable[[MeteredWindow], None] | None = None) -> Result:
    """Warm up, then measure ``seconds`` of the console over an opened ``source``."""
    taps = source.info.config.taps.n_taps
    with console(source, frame_ms) as window:
        spin(warmup_s)
        METER.reset()
        rig0 = process_cpu_s(rig_pid) if rig_pid is not None else math.nan
        acq0 = process_cpu_s(acq_pid) if acq_pid is not None else math.nan
        gui_tid = threading.main_thread().native_id or -1
        sched0 = schedstat_s(gui_tid)
        threads0 = thread_cpu_s()
        proc0 = os.times()
        wall0 = time.perf_counter()
        METER.on = True
        spin(seconds)
        METER.on = False
        wall = time.perf_counter() - wall0
        proc1 = os.times()
        threads1 = thread_cpu_s()
        sched1 = schedstat_s(gui_tid)
        rig1 = process_cpu_s(rig_pid) if rig_pid is not None else math.nan
        acq1 = process_cpu_s(acq_pid) if acq_pid is not None else math.nan
        load = load_average()
        rss = rss_mib(os.getpid())
        rig_rss = rss_mib(rig_pid) if rig_pid is not None else math.nan
        health = []
        if hasattr(source, "health"):
            for dev in source.health():
                health.append(f"{dev.device} {dev.rate_hz:.0f}/s gaps {dev.gaps} overflow "
                              f"{dev.overflow_samples} faults {dev.faults}"
                              + (f" ALARM {dev.alarm}" if dev.alarm else ""))
        paints_h = METER.paints.get(window.h_view_id(), 0)
        names = window.view_names()
        per_view = {names.get(k, "other"): v / max(METER.redraws, 1)
                    for k, v in METER.paints.items()}
        grab_ms, colours = grab_stats(window)
        if profile is not None:
            profile(window)

    m = METER
    per_thread: dict[str, float] = {}
    for tid, (name, cpu1) in threads1.items():
        cpu0 = threads0.get(tid, (name, 0.0))[1]
        key = re.sub(r"-\d+$", "", name)
        per_thread[key] = per_thread.get(key, 0.0) + (cpu1 - cpu0)
    gui_thread_s = threads1[gui_tid][1] - threads0[gui_tid][1] if gui_tid in threads1 else math.nan
    proc_s = (proc1.user - proc0.user) + (proc1.system - proc0.system)
    ticks = np.asarray(m.tick_wall) * 1e3
    frames = max(m.redraws, 1)
    tick_cpu_s = float(np.sum(m.tick_cpu))
    gui_cpu_s, runq_s = sched1[0] - sched0[0], sched1[1] - sched0[1]
    busy_s = float(np.sum(m.tick_wall)) + m.paint_wall
    split = (100 * busy_s / wall, 100 * gui_cpu_s / wall, 100 * runq_s / wall,
             100 * max(busy_s - gui_cpu_s - runq_s, 0.0) / wall)
    return Result(
        label=label, taps=taps, seconds=wall, ticks_ps=ticks.size / wall,
        frames_ps=m.redraws / wall, paints_ps=paints_h / wall, appends_ps=m.ring_appends / wall,
        tick_ms=((float(np.median(ticks)), float(np.percentile(ticks, 95)), float(ticks.max()))
                 if ticks.size else (math.nan,) * 3),
        gui_cpu=100 * proc_s / wall, gui_thread_cpu=100 * gui_thread_s / wall,
        rig_cpu=100 * (rig1 - rig0) / wall, acq_cpu=100 * (acq1 - acq0) / wall, rss=rss,
        rig_rss=rig_rss,
        gui_split=split, gui_ms_per_frame=1e3 * gui_thread_s / frames,
        tick_cpu_share=tick_cpu_s / gui_thread_s if gui_thread_s > 0 else math.nan,
        redraw_ms=1e3 * m.redraw_wall / frames, brushes_ms=1e3 * m.brushes_wall / frames,
        set_brush_ms=1e3 * m.set_brush_wall / frames, paint_ms=1e3 * m.paint_wall / frames,
        grab_ms=grab_ms, grab_colours=colours,
        threads=sorted(((k, 100 * v / wall) for k, v in per_thread.items()),
                       key=lambda kv: -kv[1]),
        paints_per_frame=per_view, health=health, load=load)


def run_live(label: str, config: RigConfig, args: argparse.Namespace,
             profile: Callable[[MeteredWindow], None] | None = None,
             threads: bool = False) -> Result:
    """Measure the console over a live simulated rig, fan on, releases cycling.

    The source is the console's: a :class:`ProcessLiveSource` (the acquisition in a child
    process, the simulated rig in the child's child), or with ``threads`` the acquisition's
    threads in this process (:class:`LiveSource`, as before the acquisition process).
    """
    print(f"- {label}: starting the simulated rig ({config.taps.n_taps} taps) ...", flush=True)
    source: Any = (LiveSource if threads else ProcessLiveSource)(
        config, simulate=True, window_s=WINDOW_S, fan_rpm=args.fan_rpm)
    t0 = time.perf_counter()
    source.open()
    print(f"  rig up in {time.perf_counter() - t0:.1f} s; measuring", flush=True)
    if threads:
        acq_pid = None
        rig_pid = getattr(getattr(getattr(source, "_rig", None), "_process", None), "pid", None)
    else:
        acq_pid = source._process.pid
        rig_pid = child_pid(acq_pid)
    stop = threading.Event()
    actions = threading.Thread(target=cycle_releases, args=(source.acq, stop),
                               name="benchmark-releases", daemon=True)
    actions.start()
    try:
        return measure(label, source, rig_pid=rig_pid, acq_pid=acq_pid, warmup_s=args.warmup,
                       seconds=args.seconds, profile=profile)
    finally:
        stop.set()
        actions.join(10.0)
        source.close()


def record_file(config: RigConfig, path: Path, duration_s: float, fan_rpm: float) -> None:
    """Record a simulated run of ``config`` (fan on, releases cycling) for the replay runs."""
    from daq.sim.recording import record_simulated_run

    def actions(acq: Any, rig: Any) -> None:
        fan = acq.drivers["fan"]
        fan.set_speed(fan_rpm)
        fan.start()
        stop = threading.Event()
        timer = threading.Timer(duration_s - 1.0, stop.set)
        timer.start()
        try:
            cycle_releases(acq, stop)
        finally:
            timer.cancel()

    record_simulated_run(config, path, duration_s=duration_s, actions=actions, progress=False)


def run_replay(label: str, path: Path, args: argparse.Namespace, frame_ms: int,
               seconds: float) -> Result:
    """Measure the console over a replayed run file (no acquisition in the process)."""
    print(f"- {label}: replaying {path.name}", flush=True)
    source = ReplaySource(path, speed=1.0, window_s=WINDOW_S)
    source.open()
    try:
        return measure(label, source, rig_pid=None, acq_pid=None, warmup_s=args.warmup,
                       seconds=seconds,
                       frame_ms=frame_ms)
    finally:
        source.close()


# ------------------------------------------------------------------------------------------------
# Profile
# ------------------------------------------------------------------------------------------------
def profiler(seconds: float, out: list[str]) -> Callable[[MeteredWindow], None]:
    """Return a :func:`measure` hook: cProfile the GUI thread for ``seconds`` of the event loop."""

    def listing(prof: cProfile.Profile, key: str, n: int, title: str) -> str:
        text = io.StringIO()
        pstats.Stats(prof, stream=text).strip_dirs().sort_stats(key).print_stats(n)
        body = text.getvalue()
        return f"{title}, sorted by {key}:\n" + body[body.find("   ncalls"):].rstrip()

    def run(window: MeteredWindow) -> None:
        # CPU time of the GUI thread (what its own work costs) ...
        cpu = cProfile.Profile(time.thread_time)
        cpu.enable()  # this thread only: the GUI thread's ticks and paints
        spin(seconds)
        cpu.disable()
        # ... then wall time (the same plus where it waits: for the GIL, after each C++ call)
        wall = cProfile.Profile()
        wall.enable()
        spin(seconds)
        wall.disable()
        what = f"GUI thread, {seconds:g} s of the event loop"
        out.append(listing(cpu, "tottime", 16, f"{what}, CPU time (thread_time)"))
        out.append(listing(cpu, "cumulative", 22, f"{what}, CPU time (thread_time)"))
        out.append(listing(wall, "tottime", 12, f"{what}, WALL time (perf_counter)"))

    return run


# ------------------------------------------------------------------------------------------------
# Report
# ------------------------------------------------------------------------------------------------
def print_report(results: list[Result], profiles: list[str], args: argparse.Namespace) -> None:
    """Print the tables, the verdict and the profiles."""
    print()
    print(f"Console frame rate (issue 6): {args.seconds:g} s after {args.warmup:g} s warm-up, "
          f"window {WINDOW_SIZE[0]}x{WINDOW_SIZE[1]}, {WINDOW_S:g} s traces, timer "
          f"{FRAME_MS} ms, Qt platform {QtGui.QGuiApplication.platformName()}, "
          f"{os.cpu_count()} CPUs, fan {args.fan_rpm:g} rpm")
    print("frames/s = redraws (a tick that found new rows and called redraw); paints/s = "
          "repaints of the h plot by Qt;")
    print("ring/s = the source's appends to the ring buffer (new rows available; counted only "
          "where they are made in this")
    print("process); CPU in % of one core: GUI proc = the console's process, acq proc = the "
          "acquisition process, rig")
    print("proc = the simulated rig's process; RSS MiB = this process after the run (the runs "
          "share it: it accumulates).")
    print()
    head = (f"{'config':<34} {'taps':>4} {'ticks/s':>7} {'frames/s':>8} {'paints/s':>8} "
            f"{'ring/s':>6} {'tick ms med/p95/max':>20} {'GUI proc %':>10} {'GUI thr %':>9} "
            f"{'acq proc %':>10} {'rig proc %':>10} {'RSS MiB':>8} {'rig RSS':>7}")
    print(head)
    print("-" * len(head))
    for r in results:
        ticks = "{:.1f}/{:.1f}/{:.1f}".format(*r.tick_ms)
        rig = "-" if math.isnan(r.rig_cpu) else f"{r.rig_cpu:.0f}"
        acq = "-" if math.isnan(r.acq_cpu) else f"{r.acq_cpu:.0f}"
        ring = "-" if not math.isnan(r.acq_cpu) else f"{r.appends_ps:.1f}"
        rig_rss = "-" if math.isnan(r.rig_rss) else f"{r.rig_rss:.0f}"
        print(f"{r.label:<34} {r.taps:>4} {r.ticks_ps:>7.1f} {r.frames_ps:>8.1f} "
              f"{r.paints_ps:>8.1f} {ring:>6} {ticks:>20} {r.gui_cpu:>10.0f} "
              f"{r.gui_thread_cpu:>9.0f} {acq:>10} {rig:>10} {r.rss:>8.0f} {rig_rss:>7}")
    print()
    print("Per frame (GUI thread): CPU, inside tick(), redraw, tap colours (_tap_brushes + "
          "setBrush), paints of all plots; full-window grab()")
    head2 = (f"{'config':<34} {'CPU ms':>7} {'in tick':>7} {'redraw':>7} {'brushes':>8} "
             f"{'setBrush':>8} {'paint':>7} {'max fps':>7} {'grab ms':>7} {'colours':>7} "
             f"{'load avg':>15}")
    print(head2)
    print("-" * len(head2))
    for r in results:
        cap = 1e3 / r.gui_ms_per_frame if r.gui_ms_per_frame > 0 else math.nan
        print(f"{r.label:<34} {r.gui_ms_per_frame:>7.1f} {100 * r.tick_cpu_share:>6.0f}% "
              f"{r.redraw_ms:>7.1f} {r.brushes_ms:>8.1f} {r.set_brush_ms:>8.1f} "
              f"{r.paint_ms:>7.1f} {cap:>7.0f} {r.grab_ms:>7.1f} {r.grab_colours:>7} "
              f"{r.load:>15}")
    print("(max fps = 1000 / GUI-thread CPU ms per frame: the rate one free core could draw)")
    print()
    print("The GUI thread's wall time (% of the measured wall time): busy = inside tick() or a "
          "plot's paintEvent;")
    print("on a core (CPU); runnable but no core free (run queue, /proc/.../schedstat); blocked "
          "= busy - CPU - run")
    print("queue: asleep inside tick/paint, i.e. waiting for the GIL (held by the acquisition "
          "threads) after a Qt call")
    head3 = f"{'config':<34} {'busy':>6} {'CPU':>6} {'run q':>6} {'blocked':>7}"
    print(head3)
    print("-" * len(head3))
    for r in results:
        print(f"{r.label:<34} " + " ".join(f"{x:>5.0f}%" for x in r.gui_split[:3])
              + f" {r.gui_split[3]:>6.0f}%")
    for r in results:
        print()
        print(f"{r.label}: threads of the GUI process (% of one core)")
        for name, pct in r.threads:
            if pct >= 0.5:
                print(f"  {name:<34} {pct:6.1f}")
        print("  paints per frame: " + ", ".join(f"{k} {v:.1f}"
                                                  for k, v in r.paints_per_frame.items()))
        for line in r.health:
            print(f"  health: {line}")
    print()
    for r in results:
        if r.label.endswith("(frame_ms=0)"):
            continue
        verdict = "MET" if met_target(r) else "MISSED"
        print(f"target >= {TARGET_FPS:g} frames/s, {r.label} ({r.taps} taps): {verdict} "
              f"({r.frames_ps:.1f} frames/s drawn, {r.paints_ps:.1f} repaints/s; tick p95 "
              f"{r.tick_ms[1]:.1f} ms of the {FRAME_MS} ms budget)")
    print(f"(the timer runs at {1000 / FRAME_MS:g}/s; within {TARGET_TOLERANCE_FPS:g} frames/s of "
          "the target counts as met)")
    for text in profiles:
        print()
        print(text)


def met_target(r: Result) -> bool | None:
    """Return whether a run drew the target frame rate; None for the frame_ms=0 replay."""
    if r.label.endswith("(frame_ms=0)"):
        return None
    low = TARGET_FPS - TARGET_TOLERANCE_FPS
    return r.frames_ps >= low and r.paints_ps >= low


def write_results(results: list[Result], args: argparse.Namespace, loads: tuple[str, str],
                  warnings: list[str]) -> None:
    """Write the result files (``--results``): the report's tables."""
    tick = ("tick median (ms)", "tick p95 (ms)", "tick max (ms)")
    rate = ("tick rate (1/s)", "frame rate (frames/s)", "h-plot repaints (1/s)",
            "ring appends (1/s)")
    cpu = ("GUI process CPU (% of a core)", "GUI thread CPU (% of a core)",
           "acquisition process CPU (% of a core)", "rig process CPU (% of a core)")
    mem = ("RSS (MiB)", "rig RSS (MiB)")
    live = [[r.label, r.taps, r.ticks_ps, r.frames_ps, r.paints_ps,
             r.appends_ps if math.isnan(r.acq_cpu) else math.nan, *r.tick_ms, r.gui_cpu,
             r.gui_thread_cpu, r.acq_cpu, r.rig_cpu, r.rss, r.rig_rss] for r in results]
    per = ("GUI CPU per frame (ms)", "share inside tick (%)", "redraw (ms)",
           "tap colours (ms)", "setBrush (ms)", "paint (ms)", "max frame rate (frames/s)",
           "grab (ms)")
    frames = [[r.label, r.gui_ms_per_frame, 100 * r.tick_cpu_share, r.redraw_ms, r.brushes_ms,
               r.set_brush_ms, r.paint_ms,
               1e3 / r.gui_ms_per_frame if r.gui_ms_per_frame > 0 else math.nan, r.grab_ms,
               r.grab_colours, r.load] for r in results]
    split = ("busy (%)", "on a core (%)", "run queue (%)", "blocked (%)")
    targets = [[r.label, r.taps, TARGET_FPS, r.frames_ps, r.paints_ps, r.tick_ms[1], FRAME_MS,
                "met" if met_target(r) else "MISSED"]
               for r in results if met_target(r) is not None]
    fmt1 = ".1f"
    tables = [
        result_files.Table(
            f"The console over {args.seconds:g} s per run after {args.warmup:g} s warm-up "
            f"({WINDOW_SIZE[0]}x{WINDOW_SIZE[1]}, {WINDOW_S:g} s traces, timer {FRAME_MS} ms): "
            "rates, tick durations, CPU and memory.",
            ["run", "taps", *rate, *tick, *cpu, *mem], live,
            formats={**dict.fromkeys(rate, fmt1), **dict.fromkeys(tick, fmt1),
                     **dict.fromkeys(cpu, ".0f"), **dict.fromkeys(mem, ".0f")}),
        result_files.Table(
            "Per frame on the GUI thread: CPU, the share inside tick(), redraw, tap colouring, "
            "paints, the rate one free core could draw, and a full-window grab().",
            ["run", *per, "colours drawn", "load average (1, 5, 15 min)"], frames,
            formats={**dict.fromkeys(per, fmt1), "share inside tick (%)": ".0f",
                     "max frame rate (frames/s)": ".0f"}),
        result_files.Table(
            "The GUI thread's measured wall time: inside tick() or a paint, on a core, runnable "
            "without a free core, blocked (waiting for the GIL after a Qt call).",
            ["run", *split], [[r.label, *r.gui_split] for r in results],
            formats=dict.fromkeys(split, ".0f")),
        result_files.Table(
            f"The target of {TARGET_FPS:g} frames/s drawn and repainted (within "
            f"{TARGET_TOLERANCE_FPS:g} frames/s counts as met).",
            ["run", "taps", "target (frames/s)", "frame rate (frames/s)",
             "h-plot repaints (1/s)", "tick p95 (ms)", "frame budget (ms)", "verdict"],
            targets, formats={"target (frames/s)": ".0f", "frame rate (frames/s)": fmt1,
                              "h-plot repaints (1/s)": fmt1, "tick p95 (ms)": fmt1}),
        result_files.Table(
            "Threads of the GUI process using at least 0.5 % of a core.",
            ["run", "thread", "CPU (% of a core)"],
            [[r.label, name, pct] for r in results for name, pct in r.threads if pct >= 0.5],
            formats={"CPU (% of a core)": fmt1}),
        result_files.Table(
            "Paints of each plot per frame (redraw).",
            ["run", "plot", "paints per frame"],
            [[r.label, k, v] for r in results for k, v in r.paints_per_frame.items()],
            formats={"paints per frame": fmt1}),
    ]
    health = [[r.label, line] for r in results for line in r.health]
    if health:
        tables.append(result_files.Table(
            "The live sources' device health at the end of each measurement.",
            ["run", "device health"], health))
    notes = [f"Load average before the runs {loads[0]}, after {loads[1]} (1, 5, 15 min), on "
             f"{os.cpu_count()} CPUs: other work on the cores lowers every figure.",
             "A frame is one redraw (a tick that found new rows); max frame rate is 1000 over "
             "the GUI thread's CPU ms per frame."]
    if "wide" in args.runs:
        notes.append(f"The GUI thread of the 511-tap live run was profiled for "
                     f"{args.profile_seconds:g} s (CPU, then wall time) after its measurement; "
                     "the listings are printed only.")
    result_files.write(
        "console_frame_rate", "Frame rate of the live operator console", tables,
        results=args.results, quick=args.quick,
        parameters={"runs": args.runs, "seconds": args.seconds, "warmup_s": args.warmup,
                    "fan_rpm": args.fan_rpm, "profile_seconds": args.profile_seconds,
                    "qt_platform": os.environ.get("QT_QPA_PLATFORM", "")},
        notes=notes, warnings=warnings)
    if args.results is not None:
        print(f"results: {args.results / 'console_frame_rate.json'} and .md")


def run(args: argparse.Namespace) -> None:
    load_before = load_average()
    print(f"load average before: {load_before} (1, 5, 15 min), {os.cpu_count()} CPUs")
    _install_paint_hook()
    results: list[Result] = []
    profiles: list[str] = []
    wide = wide_config()
    if "flat" in args.runs:
        results.append(run_live("live, sim_flat_plate (1 module)", flat_plate_config(), args))
    if "wide" in args.runs:
        results.append(run_live("live, 8 modules", wide, args,
                                profile=profiler(args.profile_seconds, profiles)))
    if "threads" in args.runs:
        results.append(run_live("live, 8 modules, acq. threads", wide, args, threads=True))
    if "switch" in args.runs:
        default = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        try:
            results.append(run_live(f"live, 8 modules, switch {SWITCH_INTERVAL_S * 1e3:g} ms",
                                    wide, args, threads=True))
        finally:
            sys.setswitchinterval(default)
    if "replay" in args.runs:
        tmp = Path(tempfile.mkdtemp(prefix="console_frame_rate_"))
        try:
            path = tmp / "wide.h5"
            duration = args.warmup + args.seconds + 5.0
            print(f"- recording {duration:g} s of the 511-tap rig for the replay ...", flush=True)
            record_file(wide, path, duration, args.fan_rpm)
            results.append(run_replay("replay, 8 modules", path, args, FRAME_MS, args.seconds))
            results.append(run_replay("replay, 8 modules (frame_ms=0)", path, args, 0,
                                      min(args.seconds, 15.0)))
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    load_after = load_average()
    print(f"load average after: {load_after}")
    print_report(results, profiles, args)
    missed = [f"target of {TARGET_FPS:g} frames/s missed: {r.label} drew {r.frames_ps:.1f} "
              f"frames/s, {r.paints_ps:.1f} repaints/s" for r in results if met_target(r) is False]
    write_results(results, args, (load_before, load_after), missed)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=None,
                        help="measured wall time per run, s (default 30; --quick: 3)")
    parser.add_argument("--warmup", type=float, default=None,
                        help="warm-up before measuring, s (default 5; --quick: 1)")
    parser.add_argument("--fan-rpm", type=float, default=800.0,
                        help="fan speed, rpm (default 800: 8 m/s on the flat-plate rig)")
    parser.add_argument("--profile-seconds", type=float, default=None,
                        help="cProfile the GUI thread of the 511-tap live run this long (s; "
                        "default 5, --quick: 1)")
    parser.add_argument("--runs", default=None,
                        help=f"comma-separated runs among {', '.join(RUNS)} (default "
                        f"{','.join(DEFAULT_RUNS)}; --quick: flat): flat = live 62 taps, "
                        "wide = live 511 taps (profiled), threads = wide with the "
                        "acquisition's threads in the GUI's process (LiveSource), switch = "
                        f"threads with sys.setswitchinterval({SWITCH_INTERVAL_S:g}), replay = "
                        f"a recorded 511-tap run replayed (timer {FRAME_MS} ms, then 0 ms)")
    result_files.add_arguments(parser)
    args = parser.parse_args(argv)
    result_files.resolve_defaults(args, DEFAULTS)
    args.runs = [r.strip() for r in args.runs.split(",") if r.strip()]
    if not args.runs or set(args.runs) - set(RUNS):
        parser.error(f"--runs: choose among {', '.join(RUNS)}")
    if not (args.seconds > 0 and args.warmup >= 0 and args.profile_seconds > 0):
        parser.error("--seconds and --profile-seconds must be > 0, --warmup >= 0")
    return args


def main(argv: list[str] | None = None) -> int:
    """Entry point: 0, or 1 when Qt could not be imported (nothing measured)."""
    args = parse_args(argv)
    if QT_ERROR is not None:
        why = f"{type(QT_ERROR).__name__}: {QT_ERROR}"
        print(f"error: Qt could not be imported ({why}); nothing measured", file=sys.stderr)
        result_files.write(
            "console_frame_rate", "Frame rate of the live operator console", [],
            results=args.results, quick=args.quick, parameters={"runs": args.runs},
            warnings=[f"nothing was measured: Qt (PySide6, pyqtgraph, the console) could not "
                      f"be imported here ({why})."])
        return 1
    run(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
