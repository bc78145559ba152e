"""Throughput of the whole recording path on one core: decode -> sync -> HDF5 (issue 5).

What is measured
----------------
The largest rig the drivers support, replayed as fast as one core allows: a Scanivalve scanner
of 8 modules (512 channels: 511 taps and the Pitot) at 500 Hz and three ILD1420 lasers at
4 kHz. Their wire bytes go through the real code, exactly as the acquisition engine would feed
it:

1. **Decode** (the reader threads' work): the real drivers (:class:`ScanivalveMps4264`,
   :class:`MicroEpsilonIld1420`) read in-memory transports through the engine's own adapters
   (``daq.acquisition.adapters.make_adapter``), one driver read per :class:`StreamBlock`: the
   scanner gets one legacy 0x0A packet per frame per module and is read after every frame (on a rig
   that keeps up, ``read`` returns as soon as every module has sent the frame), the lasers are
   read every ``--laser-block`` samples (100 by default: the driver drains ``DRAIN_S`` = 20 ms after
   the first byte, i.e. 80 samples plus what arrived meanwhile; the pipeline sizes its clock windows
   for 20 laser blocks per 0.5 s, the same 100).
2. **RunWriter** (the dispatcher thread's work): every block, as a ``"block"`` doc, into
   :class:`daq.recording.writer.RunWriter`: clock maps, the :class:`~daq.sync.resample.Resampler`, h
   and alpha from the lasers, lift and moment from the 511 taps, U from the Pitot, raw and
   synchronised rows into the HDF5 file through :class:`~daq.recording.recorder.RunRecorder` (gzip 1
   + shuffle, chunked, SWMR), plus the PLC's ``"arm"`` and ``"release"`` events of every template
   loop. RunWriter appends every 0.2 s and the recorder flushes every 0.5 s of *wall* time, so in a
   replay faster than real time each append holds more data (as when a real run catches up after a
   stall).
3. **Plain h5py append** (the limit): the same datasets (final sizes, dtypes, chunks,
   compression, SWMR) appended with ``resize`` + slice assignment, in as many equal batches as
   RunWriter wrote, with no decoding and no synchronisation, from rows read back from our own
   file (so the compressor sees the same data).

Clocks (``--clock``): by default every stage and the plain append are timed by the CPU time of
the thread that runs them (``time.thread_time``; the replay drives the drivers and RunWriter on
one thread, as the engine's dispatcher does), so that a shared host's other load does not move
the ratio (on a 2-core host shared with other work, wall-clock ratios ranged from 19 % to 88 %:
the plain append is timed after the replay, under other load). CPU time still varies from run to
run (three 600 s runs on the idle host: 52, 58 and 47 %; the plain append's CPU time alone
16.5-19.0 s): compare means of several runs. ``--clock wall`` times by ``time.perf_counter``.

Memory: RSS after every tenth of the run; a recorder's chunk caches and the append batches make
it a sawtooth (about 200-300 MiB here), so "flat" is judged by the least-squares trend through
the ten samples (its rise from 10 % to 100 % of the run), not by two of them.

Why: the recording path must keep up with the rig with a wide margin on one core (the GUI,
the other readers and the OS share the machine), cost little more than HDF5 itself, and hold
its memory flat over a long run. The targets reported against: real-time factor >= 10 (data
seconds recorded per wall second), >= 50 % of the plain h5py rate, RSS flat over the run.

What is not timed: making the bytes. Realistic streams (a release at 10 m/s in the simulators'
virtual tunnel, the simulators' packet encoders, sensor noise) are generated once for
``TEMPLATE_S`` seconds and looped; each 1 s chunk gets advancing frame counters, frame times,
laser counters and timestamps (untimed) before it is replayed. Host arrival times are
synthesised (the replay runs faster than real time): every device clock has its own offset
(20 ms plus an epoch) and drift (up to 50 ppm) against the host clock, and every read arrives
with a latency of 0.3 ms plus exponential jitter (mean 0.2 ms). Only the barometer, the fan and
the PLC are left out (a few rows per second).

Options: ``--seconds`` (default 600), ``--profile`` (cProfile the last ``--profile-seconds``
of the run, the steady state, instead of timing it; top functions of RunWriter and of decoding),
``--scan-frames-per-read`` (scanner frames per ``read``: 10, the default, is the driver's
own 20 ms batching; 1 replays it unbatched, ``min_block_s = 0``), ``--laser-block``,
``--out-dir``, ``--keep``.

``--quick`` (CI) replays 20 s instead of 600 (``--seconds`` chooses otherwise); ``--results DIR``
writes the tables (``benchmarks/result_files.py``).

Run: ``.venv/bin/python benchmarks/daq_throughput.py [--seconds 600] [--profile] [--keep]``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"  # one core, before numpy is imported

import argparse  # noqa: E402
import cProfile  # noqa: E402
import math  # noqa: E402
import pstats  # noqa: E402
import re  # noqa: E402
import shutil  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from collections import deque  # noqa: E402
from collections.abc import Callable  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import h5py  # noqa: E402
import numpy as np  # noqa: E402
import numpy.typing as npt  # noqa: E402
from threadpoolctl import threadpool_limits  # noqa: E402

from daq.acquisition import adapters  # noqa: E402
from daq.acquisition.records import Event, StreamBlock  # noqa: E402
from daq.config import RigConfig, parse_rig_config  # noqa: E402
from daq.errors import TransportError, TransportTimeout  # noqa: E402
from daq.instruments.microepsilon_ild1420.driver import MicroEpsilonIld1420  # noqa: E402
from daq.instruments.microepsilon_ild1420.settings import Ild1420Settings  # noqa: E402
from daq.instruments.scanivalve_mps4264.driver import ScanivalveMps4264  # noqa: E402
from daq.instruments.scanivalve_mps4264.settings import Mps4264Settings  # noqa: E402
from daq.recording.writer import RunWriter  # noqa: E402
from simulators.clock import DeviceClock, ManualClock  # noqa: E402
from simulators.devices.microepsilon_ild1420 import SimMicroEpsilonIld1420  # noqa: E402
from simulators.devices.scanivalve_mps4264.packets import words_legacy  # noqa: E402
from simulators.virtual_tunnel import VirtualTunnel  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import result_files  # noqa: E402 - beside this script

ROOT = Path(__file__).resolve().parents[1]
BASE_CONFIG = ROOT / "rig_configs" / "sim_streamlined_deck.toml"

MODULES = 8
N_TAPS = 64 * MODULES - 1  # every channel but the Pitot's
PITOT = 64 * MODULES - 1
SCAN_RATE_HZ = 500.0
LASER_RATE_HZ = 4000.0
#: Data seconds replayed: full run and --quick.
SECONDS = 600.0
QUICK_SECONDS = 20.0
#: Seconds of realistic signal generated once and looped.
TEMPLATE_S = 10.0
#: Release instant inside the template, s (one release event per template loop).
RELEASE_AT_S = 1.0
#: Wind speed of the template's release, m/s (the streamlined deck flutters at 17.7 m/s).
WIND_M_S = 10.0
#: Seconds of data prepared (untimed) and replayed at a time.
CHUNK_S = 1.0
#: Host time of the run start, ns (any monotonic_ns-like value).
T0_HOST_NS = 1_000_000_000_000
#: Transport latency of every read: floor and mean of the exponential jitter, s.
LATENCY_FLOOR_S = 3e-4
LATENCY_JITTER_S = 2e-4
#: Legacy packet constants (mps-protocol.h; what the simulator sends with SET UNITS PA).
PTP_EPOCH_S = 1_767_225_600
PA_UNIT_INDEX = 23
PA_CONVERSION = 6894.75977
PACKET_BYTES = 348
#: Device clocks against the host clock (device = offset + (1 + 1e-6 drift) t_host).
SCANNER_CLOCK = DeviceClock(offset_s=PTP_EPOCH_S + 0.020, drift_ppm=50.0)
LASER_CLOCKS = (DeviceClock(offset_s=100.020, drift_ppm=-30.0),
                DeviceClock(offset_s=250.020, drift_ppm=20.0),
                DeviceClock(offset_s=400.020, drift_ppm=45.0))
#: Targets of issue 5.
TARGET_RTF = 10.0
TARGET_RATIO = 0.5
#: RSS's trend may rise by this fraction between 10 % and 100 % of the run and count as flat.
FLAT_TOLERANCE = 0.10
#: The stage clock: thread CPU time by default (module docstring, "Clocks"); --clock wall
#: switches to time.perf_counter.
CLOCK: Callable[[], float] = time.thread_time

MiB = 1 << 20
ByteArray = npt.NDArray[np.uint8]
IntArray = npt.NDArray[np.int64]


# ------------------------------------------------------------------------------------------------
# One core, memory
# ------------------------------------------------------------------------------------------------
def pin_one_core() -> str:
    """Limit BLAS pools to one thread and pin the process to CPU 0 where possible.

    Returns
    -------
    str
        What was done, for the report.
    """
    threadpool_limits(1)
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {0})
        return "pinned to CPU 0 (sched_setaffinity), BLAS single-threaded (threadpoolctl)"
    return "BLAS single-threaded (threadpoolctl); no sched_setaffinity on this OS"


def memory_mib() -> tuple[float, float]:
    """Return the resident set size and its peak (``VmRSS``, ``VmHWM``), MiB; NaN off Linux."""
    try:
        text = Path("/proc/self/status").read_text()
    except OSError:
        return math.nan, math.nan
    found = dict(re.findall(r"^(VmRSS|VmHWM):\s+(\d+) kB", text, re.M))
    return int(found["VmRSS"]) / 1024, int(found["VmHWM"]) / 1024


# ------------------------------------------------------------------------------------------------
# Rig config and the in-memory instruments
# ------------------------------------------------------------------------------------------------
def build_config(frames_per_read: int = 10) -> RigConfig:
    """Return the streamlined-deck rig widened to 8 scanner modules and 511 taps.

    With ``frames_per_read == 1`` the scanner's ``min_block_s`` is set to 0 (one frame per
    ``read``, the driver's unbatched mode); otherwise the driver's default batching holds
    (``ceil(min_block_s rate)`` = 10 frames at 500 Hz).

    The shipped config's text is edited in memory (taps, modules, Pitot channel) and parsed by
    the real :func:`~daq.config.parse_rig_config`, so the text stored in the run file is a valid
    rig config.
    """
    text = BASE_CONFIG.read_text(encoding="utf-8")
    edits = ((r"(?m)^n_taps = \d+", f"n_taps = {N_TAPS}"),
             (r"(?m)^modules = \d+", f"modules = {MODULES}"),
             (r"(?m)^pitot_channel = \d+", f"pitot_channel = {PITOT}"
              + ("\nmin_block_s = 0.0" if frames_per_read == 1 else "")),
             (r'(?m)^name = "Simulated streamlined-deck rig"',
              'name = "Simulated streamlined-deck rig, 8 modules (benchmark)"'))
    for pattern, replacement in edits:
        text, n = re.subn(pattern, replacement, text, count=1)
        if n != 1:
            raise RuntimeError(f"{BASE_CONFIG.name}: {pattern!r} not found; update the benchmark")
    config = parse_rig_config(text, "daq_throughput (sim_streamlined_deck.toml, widened)")
    assert config.taps.n_taps == N_TAPS and len(config.by_role("lasers")) == 3
    return config


class ReplayTransport:
    """A data connection fed by the benchmark: :meth:`push` is the wire, ``read`` the socket.

    ``read`` returns everything pushed so far (up to ``max_bytes``), as a ``recv`` on a
    socket whose kernel buffer holds it; an empty buffer is a timeout at once (the replay
    never waits).
    """

    def __init__(self, url: str) -> None:
        self.url = url
        self._data: deque[bytes] = deque()
        self._open = False

    @property
    def is_open(self) -> bool:
        """Measure whether the transport is open."""
        return self._open

    def open(self) -> None:
        self._open = True

    def close(self) -> None:
        self._open = False

    def push(self, data: bytes) -> None:
        """Make ``data`` readable (it "arrived")."""
        self._data.append(data)

    def write(self, data: bytes) -> None:
        raise TransportError(f"{self.url}: a data connection takes no commands")

    def read(self, max_bytes: int, timeout_s: float) -> bytes:
        if not self._open:
            raise TransportError(f"{self.url}: not open")
        if not self._data:
            raise TransportTimeout(f"{self.url}: nothing more arrived")
        if len(self._data) == 1 and len(self._data[0]) <= max_bytes:
            return self._data.popleft()
        out = b"".join(self._data)
        self._data.clear()
        if len(out) > max_bytes:
            self._data.append(out[max_bytes:])
            out = out[:max_bytes]
        return out

    def reset_input(self) -> None:
        self._data.clear()


class CommandTransport(ReplayTransport):
    """A command connection answering each written line with ``answer(line)``."""

    def __init__(self, url: str, answer: Callable[[str], bytes]) -> None:
        super().__init__(url)
        self._answer = answer
        self._line = bytearray()

    def write(self, data: bytes) -> None:
        if not self._open:
            raise TransportError(f"{self.url}: not open")
        self._line += data
        while b"\n" in self._line:
            line, _, rest = bytes(self._line).partition(b"\n")
            self._line = bytearray(rest)
            self.push(self._answer(line.decode("ascii").strip()))


class ScannerCommands:
    """The scanner's ASCII command server, reduced to what the driver sends."""

    def __init__(self) -> None:
        self.state = "READY"

    def __call__(self, line: str) -> bytes:
        if line == "SCAN":
            self.state = "SCAN"
        elif line == "STOP":
            self.state = "READY"
        elif line == "STATUS":
            return f"STATUS: {self.state}\r\n".encode("ascii")
        return b""


def laser_commands(line: str) -> bytes:
    """Answer an ILD1420 command line: echo, reply lines, prompt."""
    reply = "GETOUTINFO_RS422 DIST1 COUNTER TIMESTAMP STATE\r\n" \
        if line == "GETOUTINFO_RS422" else ""
    return f"{line}\r\n{reply}->".encode("ascii")


# ------------------------------------------------------------------------------------------------
# Realistic byte streams (generated once, looped with advancing counters and times)
# ------------------------------------------------------------------------------------------------
@dataclass
class Templates:
    """Looped wire data: one packet row per frame and module, one word row per laser sample."""

    packets: list[ByteArray]  # per module, (n_frames, 348) uint8 in the config's byte order
    byte_order: str  # ">" or "<"
    laser_words: list[IntArray]  # per laser, (n_samples, 5): distance, counter, ts lo/hi, status


def make_templates(config: RigConfig, rng: np.random.Generator) -> Templates:
    """Sample a release at ``WIND_M_S`` in the virtual tunnel and encode it as the devices do.

    Pressures and displacements come from :class:`~simulators.virtual_tunnel.VirtualTunnel`
    (the physics every simulated instrument reads); packets from the scanner simulator's
    encoder; laser values as the laser simulator computes them (distance word, status with the
    green LED bit), encoded per chunk by its ``_encode``.
    """
    sim = config.simulation
    assert sim is not None
    tunnel = VirtualTunnel(config.section, config.aerodynamic_model(), config.taps,
                           wind_per_rpm=config.wind_per_rpm, hold=(sim.hold_h, sim.hold_alpha),
                           clock=ManualClock(RELEASE_AT_S))
    tunnel.set_fan_speed(WIND_M_S / config.wind_per_rpm)
    tunnel.release()
    n = round(TEMPLATE_S * SCAN_RATE_HZ)
    t = np.arange(n) / SCAN_RATE_HZ
    taps, qd = tunnel.pressures(t)
    p = np.zeros((n, 64 * MODULES))
    p[:, :N_TAPS] = taps
    p[:, PITOT] = qd
    p += rng.normal(0.0, 1.0, p.shape)  # the simulator's default noise_pa
    scanner = config.by_role("scanner")[0]
    order = ">" if scanner.settings["byte_order"] == "big" else "<"
    frames = np.arange(1, n + 1, dtype=np.int64)
    t_ns = np.zeros(n, np.int64)  # set per chunk
    packets = []
    for k in range(MODULES):
        temps = (21.0 + rng.normal(0.0, 0.02, (n, 8))).astype(np.float32)
        words = words_legacy(frames, t_ns, temps,
                             np.ascontiguousarray(p[:, 64 * k:64 * (k + 1)], np.float32),
                             serial=4264001 + k, rate_hz=SCAN_RATE_HZ,
                             unit_index=PA_UNIT_INDEX, conversion=PA_CONVERSION,
                             start_ns=PTP_EPOCH_S * 10**9, ext_rel_ns=np.full(n, -1, np.int64))
        packets.append(words.astype(order + "u4").view(np.uint8).reshape(n, PACKET_BYTES))
    m = round(TEMPLATE_S * LASER_RATE_HZ)
    t_l = np.arange(m) / LASER_RATE_HZ
    motion = tunnel.sample(t_l)
    laser_words = []
    for inst in config.by_role("lasers"):
        mr = float(inst.settings["range_mm"])
        d_mm = (float(inst.settings["standoff_mm"])
                + 1000.0 * (motion["h"] + float(inst.settings["x"]) * motion["alpha"])
                + rng.normal(0.0, 2.5e-5 * mr, m))
        value = np.clip(np.rint((100.0 * d_mm / mr + 1.0) * 65520.0 / 102.0), 0, 65520)
        laser = np.zeros((m, 5), np.int64)
        laser[:, 0] = value.astype(np.int64)
        laser[:, 4] = 1 << 16  # status: green LED, not triggered
        laser_words.append(laser)
    return Templates(packets=packets, byte_order=order, laser_words=laser_words)


@dataclass
class Read:
    """One driver read of the replay: its arrival time and the bytes that arrived before it."""

    host_ns: int
    device: str
    pieces: list[bytes]  # per transport (scanner: one per module; laser: one)
    rows: int


def _arrival_ns(t_true_last: npt.NDArray[np.float64], rng: np.random.Generator,
                last: dict[str, int], device: str) -> IntArray:
    """Host arrival times of reads whose last rows were sent at ``t_true_last`` (host s).

    A jittered latency is added, but a connection delivers in order (TCP, a serial line): a
    read never completes before the previous one of its device (``last`` keeps it per device).
    """
    latency = LATENCY_FLOOR_S + rng.exponential(LATENCY_JITTER_S, t_true_last.size)
    arrive = (T0_HOST_NS + np.round((t_true_last + latency) * 1e9)).astype(np.int64)
    arrive = np.maximum.accumulate(np.maximum(arrive, last.get(device, 0)))
    if arrive.size:
        last[device] = int(arrive[-1])
    return arrive


def chunk_reads(tpl: Templates, laser_names: list[str], chunk: int, frames_per_read: int,
                laser_block: int, rng: np.random.Generator, last: dict[str, int]) -> list[Read]:
    """Wire bytes and arrival times of chunk ``chunk`` (``CHUNK_S`` of every device's time).

    Untimed: counters and device times advance; the template's rows are reused cyclically.
    ``last`` holds each device's last arrival time, ns (updated).
    """
    reads: list[Read] = []
    # Scanner: frame k (counter k + 1) at device time offset + k / rate (PTP frame time).
    n = round(CHUNK_S * SCAN_RATE_HZ)
    k = chunk * n + np.arange(n, dtype=np.int64)
    rows = k % tpl.packets[0].shape[0]
    elapsed_ns = np.round(k * (1e9 / SCAN_RATE_HZ)).astype(np.int64)
    t_ns = PTP_EPOCH_S * 10**9 + 20_000_000 + elapsed_ns
    t_true = (elapsed_ns * 1e-9) / (1.0 + 1e-6 * SCANNER_CLOCK.drift_ppm)
    data = []
    for template in tpl.packets:
        packets = template[rows]
        words = packets.view(tpl.byte_order + "u4")  # (n, 87)
        words[:, 2] = (k + 1) % (1 << 32)
        words[:, 83] = t_ns // 10**9
        words[:, 84] = t_ns % 10**9
        data.append(packets.tobytes())
    ends = np.arange(frames_per_read, n + frames_per_read, frames_per_read).clip(max=n)
    arrive = _arrival_ns(t_true[ends - 1], rng, last, "scanner")
    start = 0
    for end, host in zip(ends.tolist(), arrive.tolist(), strict=True):
        a, b = start * PACKET_BYTES, end * PACKET_BYTES
        reads.append(Read(host, "scanner", [d[a:b] for d in data], end - start))
        start = end
    # Lasers: sample j at device time offset + j / rate; timestamps in 10 us ticks.
    m = round(CHUNK_S * LASER_RATE_HZ)
    for name, words_t, clock in zip(laser_names, tpl.laser_words, LASER_CLOCKS, strict=True):
        j = chunk * m + np.arange(m, dtype=np.int64)
        words = words_t[j % words_t.shape[0]]
        tau = clock.offset_s + j / LASER_RATE_HZ
        ticks = np.floor(tau * 1e5 + 0.5).astype(np.int64) % (1 << 32)
        words[:, 1] = j % (1 << 18)
        words[:, 2] = ticks & 0xFFFF
        words[:, 3] = ticks >> 16
        raw = SimMicroEpsilonIld1420._encode(words).tobytes()
        size = 15
        t_true_l = (j / LASER_RATE_HZ) / (1.0 + 1e-6 * clock.drift_ppm)
        ends = np.arange(laser_block, m + laser_block, laser_block).clip(max=m)
        arrive = _arrival_ns(t_true_l[ends - 1], rng, last, name)
        start = 0
        for end, host in zip(ends.tolist(), arrive.tolist(), strict=True):
            reads.append(Read(host, name, [raw[start * size:end * size]], end - start))
            start = end
    reads.sort(key=lambda r: r.host_ns)
    return reads


# ------------------------------------------------------------------------------------------------
# The replay
# ------------------------------------------------------------------------------------------------
@dataclass
class Device:
    """A driver on replay transports, read through the engine's adapter."""

    name: str
    kind: str
    driver: Any
    transports: list[ReplayTransport]
    adapter: Any
    seq: int = 0
    wire_bytes: int = 0
    samples: int = 0


def build_devices(config: RigConfig) -> dict[str, Device]:
    """Build the real drivers on replay transports, opened and scanning as the engine leaves them.

    The engine's own adapter (``daq.acquisition.adapters.make_adapter``) opens them, starts the scan
    (configure + SCAN) and turns each driver read into the rows of a :class:`StreamBlock`.
    """
    devices: dict[str, Device] = {}
    inst = config.by_role("scanner")[0]
    settings = Mps4264Settings.from_table(inst.settings, "scanner")
    data = [ReplayTransport(f"replay://scanner/module{k}") for k in range(MODULES)]
    scanner = ScanivalveMps4264(CommandTransport("replay://scanner", ScannerCommands()), settings,
                                data_transports=data)
    devices[inst.name] = Device(inst.name, "scanner", scanner, data,
                                adapters.make_adapter("scanner", scanner,
                                                            poll_interval_s=None,
                                                            read_timeout_s=1.0))
    for inst in config.by_role("lasers"):
        line = CommandTransport(f"replay://{inst.name}", laser_commands)
        laser = MicroEpsilonIld1420(line, Ild1420Settings.from_table(inst.settings, inst.name))
        devices[inst.name] = Device(inst.name, "laser", laser, [line],
                                    adapters.make_adapter("laser", laser,
                                                                poll_interval_s=None,
                                                                read_timeout_s=1.0))
    for dev in devices.values():
        dev.adapter.open()
    for dev in devices.values():
        dev.adapter.begin()
    return devices


def operator_event(chunk: int, loop_chunks: int) -> Event | None:
    """Return the PLC event at the start of chunk ``chunk``, if any.

    The template holds the model until ``RELEASE_AT_S`` and then decays; when it loops, the
    model is back at the hold position. So each loop starts with an ``"arm"`` (the magnet
    catches the model: the previous decay ends) and has a ``"release"`` at ``RELEASE_AT_S``,
    the events the engine records for ``Acquisition.arm()`` and ``Acquisition.release()``.
    """
    ns = T0_HOST_NS + round(chunk * CHUNK_S * 1e9)
    phase = chunk % loop_chunks
    if phase == 0 and chunk > 0:
        return Event(kind="arm", host_time_ns=ns, device="plc", text="release armed")
    if phase == round(RELEASE_AT_S / CHUNK_S):
        return Event(kind="release", host_time_ns=ns, device="plc", text="model released",
                     data={"requested_ns": ns, "command_ns": ns, "confirmed_ns": ns,
                           "delay_s": 0.0})
    return None


@dataclass
class Tenth:
    """One tenth of the run: memory at its end, and the stage times inside it (timed part)."""

    fraction: float
    rss_mib: float
    data_s: float
    decode_s: float
    writer_s: float


@dataclass
class Timers:
    """Wall time per stage over the timed chunks, s, and what was done.

    With profiling, the profiled tail of the run is not timed (cProfile slows it down):
    ``timed_s`` data seconds were.
    """

    decode: dict[str, float] = field(default_factory=lambda: {"scanner": 0.0, "laser": 0.0})
    writer: float = 0.0
    timed_s: float = 0.0
    blocks: int = 0
    writes: int = 0
    tenths: list[Tenth] = field(default_factory=list)

    @property
    def total(self) -> float:
        """Decode plus RunWriter, s."""
        return sum(self.decode.values()) + self.writer


class Stopwatch:
    """Time calls into a stage; optionally profile them instead (then they are not timed)."""

    def __init__(self) -> None:
        self.seconds = 0.0
        self.profile: cProfile.Profile | None = None

    def call(self, fn: Callable[..., Any], *args: Any) -> Any:
        """Return ``fn(*args)``, timed or profiled."""
        if self.profile is not None:
            self.profile.enable()
            try:
                return fn(*args)
            finally:
                self.profile.disable()
        t = CLOCK()
        try:
            return fn(*args)
        finally:
            self.seconds += CLOCK() - t


def replay(config: RigConfig, tpl: Templates, path: Path, seconds: float, *,
           frames_per_read: int, laser_block: int, seed: int,
           profilers: dict[str, cProfile.Profile] | None = None, profile_s: float = 0.0,
           progress: bool = True) -> tuple[Timers, RunWriter, dict[str, Device]]:
    """Replay ``seconds`` of data through the drivers and a RunWriter into ``path``.

    Parameters
    ----------
    config : RigConfig
        The widened rig.
    tpl : Templates
        The looped wire data.
    path : Path
        Run file to write.
    seconds : float
        Data seconds to replay (whole ``CHUNK_S`` chunks).
    frames_per_read : int
        Scanner frames per driver read (1: a host that keeps up).
    laser_block : int
        Laser samples per driver read.
    seed : int
        Seed of the arrival jitter.
    profilers : dict, optional
        ``{"decode": Profile, "writer": Profile}``: profile the last ``profile_s`` data seconds
        (the steady state: clock fits and chunk caches at their full size) instead of timing
        them.
    profile_s : float
        Length of the profiled tail, s.
    progress : bool
        Print a dot per tenth of the run.

    Returns
    -------
    Timers, RunWriter, dict of str to Device
        The stage times, the writer (its ``summary``, ``error``) and the devices (wire bytes,
        samples).
    """
    rng = np.random.default_rng(seed)
    devices = build_devices(config)
    laser_names = [inst.name for inst in config.by_role("lasers")]
    writer = RunWriter(path, config, operator_notes="benchmarks/daq_throughput.py")
    timers = Timers()
    stop = threading.Event()
    watches = {"scanner": Stopwatch(), "laser": Stopwatch(), "writer": Stopwatch()}
    start_doc = {
        "uid": "daq-throughput", "time": "", "host_time_ns": T0_HOST_NS,
        "devices": {d.name: {"kind": d.kind, "describe": d.driver.describe()}
                    for d in devices.values()},
        "queue_size": 256, "metadata": {"rig": config.name},
    }
    watches["writer"].call(writer, "start", start_doc)
    rec = writer.recorder
    assert rec is not None
    counted = rec.append_sync

    def count_sync_writes(*args: Any, **kwargs: Any) -> None:
        timers.writes += 1
        counted(*args, **kwargs)

    rec.append_sync = count_sync_writes  # type: ignore[method-assign]

    def read_once(dev: Device, n: int, host_ns: int) -> StreamBlock:
        """One driver read through the engine's adapter, as the reader thread makes it."""
        reading = dev.adapter.read(stop)
        assert reading is not None and len(reading) == n, (dev.name, n)
        return StreamBlock(device=dev.name, kind=dev.kind, seq=dev.seq,
                           host_time_ns=np.full(n, host_ns, np.int64),
                           device_time=reading.device_time, counter=reading.counter,
                           values=reading.channels, gaps=reading.gaps, info=reading.info)

    n_chunks = round(seconds / CHUNK_S)
    profile_from = n_chunks - round(profile_s / CHUNK_S) if profilers else n_chunks
    loop_chunks = round(TEMPLATE_S / CHUNK_S)
    marks = deque(round(n_chunks * f / 10) for f in range(1, 11))
    last_arrival: dict[str, int] = {}
    previous = (0.0, 0.0, 0.0)  # data s, decode s, writer s at the previous tenth
    for chunk in range(n_chunks):
        if profilers and chunk == profile_from:
            watches["scanner"].profile = watches["laser"].profile = profilers["decode"]
            watches["writer"].profile = profilers["writer"]
        if chunk < profile_from:
            timers.timed_s += CHUNK_S
        event = operator_event(chunk, loop_chunks)
        if event is not None:
            watches["writer"].call(writer, "event", event)
        for read in chunk_reads(tpl, laser_names, chunk, frames_per_read, laser_block, rng,
                                last_arrival):
            dev = devices[read.device]
            for transport, piece in zip(dev.transports, read.pieces, strict=True):
                transport.push(piece)
                dev.wire_bytes += len(piece)
            block = watches[dev.kind].call(read_once, dev, read.rows, read.host_ns)
            dev.seq += 1
            dev.samples += read.rows
            watches["writer"].call(writer, "block", block)
            timers.blocks += 1
        while marks and chunk + 1 >= marks[0]:
            marks.popleft()
            now = (timers.timed_s, watches["scanner"].seconds + watches["laser"].seconds,
                   watches["writer"].seconds)
            timers.tenths.append(Tenth((chunk + 1) / n_chunks, memory_mib()[0],
                                       *(x - y for x, y in zip(now, previous, strict=True))))
            previous = now
            if progress:
                print(".", end="", flush=True)
    stop_doc = {"reason": "duration", "host_time_ns": T0_HOST_NS + round(seconds * 1e9),
                "duration_s": float(seconds), "devices": {}, "overflows": 0,
                "overflow_samples": 0, "faults": 0, "events_dropped": 0,
                "subscriber_errors": {}, "releases": [], "errors": [], "threads_alive": []}
    watches["writer"].profile = None  # the end of a run (last flush, close) is always timed
    watches["writer"].call(writer, "stop", stop_doc)
    if progress:
        print()
    for dev in devices.values():
        dev.adapter.halt()
        dev.adapter.close()
    timers.decode = {"scanner": watches["scanner"].seconds, "laser": watches["laser"].seconds}
    timers.writer = watches["writer"].seconds
    return timers, writer, devices


# ------------------------------------------------------------------------------------------------
# The limit: plain h5py appends of the same datasets
# ------------------------------------------------------------------------------------------------
@dataclass
class Layout:
    """One appended dataset of our file: its path, final shape and storage options."""

    name: str
    shape: tuple[int, ...]
    dtype: np.dtype[Any]
    chunks: tuple[int, ...] | None
    maxshape: tuple[int | None, ...]
    compression: str | None
    compression_opts: Any
    shuffle: bool
    fillvalue: Any
    sample: npt.NDArray[Any]  # first rows, read back: the data the compressor sees

    @property
    def nbytes(self) -> int:
        """Uncompressed bytes of the final dataset."""
        return int(np.prod(self.shape)) * self.dtype.itemsize


def appended_datasets(path: Path, sample_rows: dict[str, int]) -> list[Layout]:
    """List the row-appended datasets of a run file (raw streams and the sync view).

    ``sample_rows`` maps a group (``entry/sync``, ``entry/instrument/<dev>``) to how many rows
    of each of its datasets to read back as sample data.
    """
    out: list[Layout] = []
    with h5py.File(path, "r") as f:
        groups = [f"entry/instrument/{name}" for name in f["entry/instrument"]] + ["entry/sync"]
        for group in groups:
            for name, ds in f[group].items():
                if name == "gaps" or not isinstance(ds, h5py.Dataset) or ds.shape[0] == 0:
                    continue
                rows = min(ds.shape[0], sample_rows[group])
                out.append(Layout(f"{group}/{name}", ds.shape, ds.dtype, ds.chunks, ds.maxshape,
                                  ds.compression, ds.compression_opts, bool(ds.shuffle),
                                  ds.fillvalue, ds[:rows]))
    return out


def plain_append(layouts: list[Layout], path: Path, batches: int) -> float:
    """Append every dataset in ``batches`` equal batches (resize + slice); return the wall time.

    The file is created as ours is (``libver=("v110", "latest")``, SWMR on after the datasets
    exist); each batch appends to every dataset in turn, from a batch of rows prepared
    beforehand from the dataset's own sample (untimed); closing (the last flush) is timed.
    """
    batches = max(1, batches)
    prepared = []
    for lay in layouts:
        rows = math.ceil(lay.shape[0] / batches)
        index = np.arange(rows) % lay.sample.shape[0]
        prepared.append((lay, np.ascontiguousarray(lay.sample[index])))
    f = h5py.File(path, "w", libver=("v110", "latest"))
    datasets = []
    for lay, _ in prepared:
        options: dict[str, Any] = {}
        if lay.compression is not None:
            options = {"compression": lay.compression, "compression_opts": lay.compression_opts}
        ds = f.create_dataset(lay.name, shape=(0, *lay.shape[1:]), maxshape=lay.maxshape,
                              chunks=lay.chunks, dtype=lay.dtype, shuffle=lay.shuffle,
                              fillvalue=lay.fillvalue, **options)
        datasets.append(ds)
    f.swmr_mode = True
    t = CLOCK()
    for _ in range(batches):
        for ds, (lay, batch) in zip(datasets, prepared, strict=True):
            start = ds.shape[0]
            stop = min(start + batch.shape[0], lay.shape[0])
            if stop > start:
                ds.resize(stop, axis=0)
                ds[start:stop] = batch[:stop - start]
    f.close()
    return CLOCK() - t


# ------------------------------------------------------------------------------------------------
# Report
# ------------------------------------------------------------------------------------------------
def print_profile(profile: cProfile.Profile, title: str, top: int = 15, own: int = 10) -> None:
    """Print the ``top`` functions of ``profile`` by cumulative time, then ``own`` by own time.

    cProfile slows Python-heavy code more than numpy and HDF5 calls: read the shares, not the
    absolute times.
    """
    stats = pstats.Stats(profile)
    raw: dict[Any, Any] = stats.stats  # type: ignore[attr-defined]
    # Enabling the profiler around each call leaves the outermost frames' cumulative time a
    # little above the summed own time: take the larger as 100 %.
    total = max([getattr(stats, "total_tt", 0.0), *(v[3] for v in raw.values())])

    def label(key: tuple[str, int, str]) -> str:
        file, line, func = key
        where = file.replace(str(ROOT) + "/", "")
        where = re.sub(r".*(site|dist)-packages/", "", where)
        return (f"{where}:{line}({func})" if line else func)[:88]

    def show(rows: list[Any]) -> None:
        print(f"{'calls':>9} {'own s':>7} {'cum s':>7} {'cum %':>6} {'us/call':>9}  function")
        for key, (_, calls, own_s, cum_s, _) in rows:
            print(f"{calls:>9} {own_s:>7.3f} {cum_s:>7.3f} {100 * cum_s / total:>6.1f} "
                  f"{1e6 * cum_s / max(calls, 1):>9.1f}  {label(key)}")

    print(f"\n{title}: {total:.2f} s under cProfile; top {top} by cumulative time")
    show(sorted(raw.items(), key=lambda item: item[1][3], reverse=True)[:top])
    print(f"top {own} by own time")
    show(sorted(raw.items(), key=lambda item: item[1][2], reverse=True)[:own])


def verdict(ok: bool) -> str:
    """Return ``met`` or ``MISSED``."""
    return "met" if ok else "MISSED"


@dataclass
class Result:
    """What one benchmark run measured."""

    seconds: float
    timers: Timers
    summary: dict[str, Any]
    devices: dict[str, Device]
    wall_all: float
    rss_before: float
    hwm: float
    rows_bytes: int
    file_bytes: int
    plain_wall: float
    plain_bytes: int


def measure(args: argparse.Namespace, out_dir: Path) -> tuple[Result, dict[str, Any]]:
    """Run the replay, then the plain h5py append of the same datasets.

    Returns
    -------
    Result, dict
        The measurements, and the profilers (empty without ``--profile``).
    """
    config = build_config(args.scan_frames_per_read)
    tpl = make_templates(config, np.random.default_rng(args.seed))
    ours = out_dir / "daq_throughput_run.h5"
    plain = out_dir / "daq_throughput_plain.h5"
    for p in (ours, plain):
        p.unlink(missing_ok=True)
    seconds = math.ceil(args.seconds / CHUNK_S) * CHUNK_S
    profilers = ({"decode": cProfile.Profile(), "writer": cProfile.Profile()} if args.profile
                 else {})
    print(f"reads: scanner {args.scan_frames_per_read} frame(s) per read, lasers "
          f"{args.laser_block} samples per read; file {ours}")
    rss_before = memory_mib()[0]
    print("replaying", end="", flush=True)
    t = time.perf_counter()
    timers, writer, devices = replay(config, tpl, ours, seconds,
                                     frames_per_read=args.scan_frames_per_read,
                                     laser_block=args.laser_block, seed=args.seed,
                                     profilers=profilers or None,
                                     profile_s=args.profile_seconds)
    wall_all = time.perf_counter() - t
    hwm = memory_mib()[1]
    if writer.error is not None:
        raise writer.error
    del tpl
    sample_rows = {"entry/sync": round(TEMPLATE_S * SCAN_RATE_HZ)}
    for dev in devices.values():
        rate = SCAN_RATE_HZ if dev.kind == "scanner" else LASER_RATE_HZ
        sample_rows[f"entry/instrument/{dev.name}"] = round(TEMPLATE_S * rate)
    layouts = appended_datasets(ours, sample_rows)
    plain_wall = plain_append(layouts, plain, timers.writes)
    result = Result(seconds=seconds, timers=timers, summary=dict(writer.summary or {}),
                    devices=devices, wall_all=wall_all, rss_before=rss_before, hwm=hwm,
                    rows_bytes=sum(lay.nbytes for lay in layouts),
                    file_bytes=ours.stat().st_size, plain_wall=plain_wall,
                    plain_bytes=plain.stat().st_size)
    return result, profilers


def report(r: Result) -> tuple[list[result_files.Table], list[str], list[str]]:
    """Print the table, the ratio, the memory samples, sanity checks and the targets.

    Returns
    -------
    list of Table, list of str, list of str
        The same figures as tables for the result files, notes, and the targets missed.
    """
    tm = r.timers
    per_s = r.rows_bytes / r.seconds  # uncompressed bytes appended per data second
    scan_wire = sum(d.wire_bytes for d in r.devices.values() if d.kind == "scanner")
    laser_wire = sum(d.wire_bytes for d in r.devices.values() if d.kind == "laser")
    rows = [
        ("decode scanner (8 modules, read)", tm.decode["scanner"], tm.timed_s,
         scan_wire / r.seconds),
        ("decode lasers (3, read)", tm.decode["laser"], tm.timed_s, laser_wire / r.seconds),
        ("RunWriter (sync + HDF5)", tm.writer, tm.timed_s, per_s),
        ("total pipeline (decode + RunWriter)", tm.total, tm.timed_s, per_s),
        ("plain h5py append (the limit)", r.plain_wall, r.seconds, per_s),
    ]
    clock = "cpu s" if CLOCK is time.thread_time else "wall s"
    print(f"\n{'stage':<40}{clock:>9}{'data s':>8}{'x real time':>13}{'MB/s':>8}")
    stage_rows = []
    for label, wall, data_s, bytes_per_s in rows:
        print(f"{label:<40}{wall:>9.2f}{data_s:>8.0f}{data_s / wall:>13.1f}"
              f"{bytes_per_s * data_s / 1e6 / wall:>8.1f}")
        stage_rows.append([label, wall, data_s, data_s / wall,
                           bytes_per_s * data_s / 1e6 / wall])
    notes = ["Throughput: wire bytes decoded for the decode rows, else uncompressed rows "
             f"appended ({r.rows_bytes / 1e6:.0f} MB in all; files {r.file_bytes / 1e6:.0f} MB "
             f"ours, {r.plain_bytes / 1e6:.0f} MB plain)."]
    print(f"MB/s: wire bytes decoded (decode rows), else uncompressed rows appended "
          f"({r.rows_bytes / 1e6:.0f} MB in all; files {r.file_bytes / 1e6:.0f} MB ours, "
          f"{r.plain_bytes / 1e6:.0f} MB plain)")
    if tm.timed_s < r.seconds:
        print(f"our stages timed over the first {tm.timed_s:g} s; the last "
              f"{r.seconds - tm.timed_s:g} s were profiled (below)")
        notes.append(f"Our stages were timed over the first {tm.timed_s:g} s; the last "
                     f"{r.seconds - tm.timed_s:g} s were profiled, not timed.")
    print(f"{tm.blocks} blocks; RunWriter wrote {tm.writes} batches "
          f"({r.summary.get('sync_rows', 0) / max(tm.writes, 1):.0f} sync rows each: it writes "
          "every 0.2 s of wall time), the plain append as many; replay wall time with the "
          f"untimed byte preparation {r.wall_all:.1f} s")
    speeds = [(f"{t.data_s / t.decode_s:.1f}", f"{t.data_s / t.writer_s:.1f}")
              for t in tm.tenths if t.data_s > 0 and t.decode_s > 0 and t.writer_s > 0]
    print("x real time per tenth of the run, decode: " + " ".join(d for d, _ in speeds))
    print("x real time per tenth of the run, RunWriter: " + " ".join(w for _, w in speeds))
    rtf = tm.timed_s / tm.total
    ratio = rtf / (r.seconds / r.plain_wall)
    print(f"\nours / plain h5py rate: {100 * ratio:.0f} %")

    print(f"\nmemory (VmRSS, MiB): before the run {r.rss_before:.0f}; " + ", ".join(
        f"{100 * t.fraction:.0f} %: {t.rss_mib:.0f}" for t in tm.tenths)
        + f"; peak (VmHWM) {r.hwm:.0f}")
    first, last = tm.tenths[0].rss_mib, tm.tenths[-1].rss_mib
    fractions = np.array([t.fraction for t in tm.tenths])
    rss = np.array([t.rss_mib for t in tm.tenths])
    slope = float(np.polyfit(fractions, rss, 1)[0]) if rss.size > 1 else 0.0
    growth = slope * float(fractions[-1] - fractions[0])
    per_tenth = {round(100 * t.fraction): (t.data_s / t.decode_s, t.data_s / t.writer_s)
                 for t in tm.tenths if t.data_s > 0 and t.decode_s > 0 and t.writer_s > 0}
    memory_rows = [[100 * t.fraction, t.rss_mib, *per_tenth.get(round(100 * t.fraction),
                                                                  (math.nan, math.nan))]
                   for t in tm.tenths]
    print(f"  10 % -> 100 %: samples {last - first:+.1f} MiB; least-squares trend "
          f"{growth:+.1f} MiB ({100 * growth / float(rss.mean()):+.1f} % of the mean)")

    s = r.summary
    print(f"\nchecks: sync rows {s.get('sync_rows')} (expected ~{r.seconds * SCAN_RATE_HZ:.0f}),"
          f" releases {s.get('releases')}, gaps {sum(s.get('gaps', {}).values())}, samples "
          f"{s.get('samples')}")
    lasers = [name for name, dev in r.devices.items() if dev.kind == "laser"]
    truth = {"scanner": SCANNER_CLOCK, **dict(zip(lasers, LASER_CLOCKS, strict=True))}
    clock_rows = []
    for name, fit in s.get("clock_fits", {}).items():
        print(f"  clock {name:<12} drift {fit['drift_ppm']:+8.3f} ppm (truth "
              f"{truth[name].drift_ppm:+.0f}), residual {1e6 * fit['residual_s']:.1f} us")
        clock_rows.append([name, fit["drift_ppm"], truth[name].drift_ppm,
                           1e6 * fit["residual_s"]])
    late = {k: v for k, v in s.get("late_samples", {}).items() if v}
    if late:
        print(f"  late samples (resampler): {late}")
        notes.append("Late samples (resampler): "
                      + ", ".join(f"{k} {v}" for k, v in late.items()) + ".")

    print("\ntargets:")
    print(f"  real-time factor >= {TARGET_RTF:g} on one core: {rtf:.1f} -> "
          f"{verdict(rtf >= TARGET_RTF)}")
    print(f"  >= {100 * TARGET_RATIO:.0f} % of the plain h5py rate: {100 * ratio:.0f} % -> "
          f"{verdict(ratio >= TARGET_RATIO)}")
    print(f"  memory flat (RSS trend 10 % -> 100 % <= {100 * FLAT_TOLERANCE:.0f} % of its mean): "
          f"{growth:+.1f} MiB -> {verdict(growth <= FLAT_TOLERANCE * float(rss.mean()))}")

    cpu = "CPU time (s)" if CLOCK is time.thread_time else "wall time (s)"
    mbs, real = "throughput (MB/s)", "x real time"
    gaps = sum(s.get("gaps", {}).values())
    tables = [
        result_files.Table(
            f"Recording path on one core: {MODULES}-module scanner at {SCAN_RATE_HZ:g} Hz and "
            f"{len(lasers)} lasers at {LASER_RATE_HZ:g} Hz, per stage, against a plain h5py "
            "append of the same datasets.",
            ["stage", cpu, "data (s)", real, mbs], stage_rows,
            formats={cpu: ".2f", "data (s)": ".0f", real: ".1f", mbs: ".1f"}),
        result_files.Table(
            "The targets: real-time factor of the pipeline, its share of the plain h5py rate, "
            "and the resident memory's trend over the run.",
            ["target", "threshold", "measured", "verdict"],
            [["real-time factor on one core (x)", TARGET_RTF, rtf, verdict(rtf >= TARGET_RTF)],
             ["share of the plain h5py rate (%)", 100 * TARGET_RATIO, 100 * ratio,
              verdict(ratio >= TARGET_RATIO)],
             ["RSS trend from 10 % to 100 % of the run (% of its mean, at most)",
              100 * FLAT_TOLERANCE, 100 * growth / float(rss.mean()),
              verdict(growth <= FLAT_TOLERANCE * float(rss.mean()))]],
            formats={"threshold": ".0f", "measured": ".1f"}),
        result_files.Table(
            "Resident memory and speed per tenth of the run.",
            ["run done (%)", "RSS (MiB)", "decode x real time", "RunWriter x real time"],
            memory_rows, formats={"run done (%)": ".0f", "RSS (MiB)": ".0f",
                                  "decode x real time": ".1f", "RunWriter x real time": ".1f"}),
        result_files.Table(
            "Checks of the written run file.",
            ["sync rows", "expected sync rows", "releases", "gaps", "blocks",
             "RunWriter batches", "peak RSS (MiB)"],
            [[s.get("sync_rows"), round(r.seconds * SCAN_RATE_HZ), s.get("releases"), gaps,
              tm.blocks, tm.writes, r.hwm]], formats={"peak RSS (MiB)": ".0f"}),
    ]
    if clock_rows:
        tables.append(result_files.Table(
            "Clock fits of the run file against the simulated device clocks.",
            ["clock", "fitted drift (ppm)", "true drift (ppm)", "residual (us)"], clock_rows,
            formats={"fitted drift (ppm)": "+.3f", "true drift (ppm)": "+.0f",
                     "residual (us)": ".1f"}))
    notes.append(f"Memory before the run {r.rss_before:.0f} MiB; least-squares RSS trend from "
                 f"10 % to 100 % of the run {growth:+.1f} MiB.")
    missed = [f"target missed: {row[0]} {row[2]:.1f} against {row[1]:g}"
              for row in tables[1].rows if row[3] != verdict(True)]
    return tables, notes, missed


def run(args: argparse.Namespace) -> None:
    """Run the benchmark and print the report (files removed unless ``--keep``)."""
    pinned = pin_one_core()
    print(f"windrig recording throughput: scanner {MODULES} modules x 64 ch ({N_TAPS} taps + "
          f"Pitot) at {SCAN_RATE_HZ:g} Hz, 3 x ILD1420 at {LASER_RATE_HZ:g} Hz")
    print(f"{math.ceil(args.seconds / CHUNK_S) * CHUNK_S:g} s of data on one core: {pinned}")
    out_dir = Path(args.out_dir) if args.out_dir else Path(tempfile.mkdtemp(prefix="windrig-"))
    out_dir.mkdir(parents=True, exist_ok=True)
    try:
        result, profilers = measure(args, out_dir)
        tables, notes, missed = report(result)
        clock = "thread CPU time" if args.clock == "cpu" else "wall clock (time.perf_counter)"
        notes.append(f"Stages timed by {clock}; {pinned}.")
        result_files.write(
            "daq_throughput", "Recording throughput: decode, sync, HDF5", tables,
            results=args.results, quick=args.quick,
            parameters={"seconds": result.seconds, "scan_frames_per_read":
                        args.scan_frames_per_read, "laser_block": args.laser_block,
                        "seed": args.seed, "clock": args.clock, "profile": args.profile,
                        "profile_seconds": args.profile_seconds if args.profile else None},
            notes=notes, warnings=missed)
        if args.results is not None:
            print(f"results: {args.results / 'daq_throughput.json'} and .md")
        if profilers:
            tail = f"last {args.profile_seconds:g} s of the run"
            print_profile(profilers["writer"], f"where RunWriter's time goes ({tail})")
            print_profile(profilers["decode"], f"where decoding's time goes ({tail})")
    finally:
        if args.keep:
            print(f"\nkept: {out_dir}")
        else:
            for name in ("daq_throughput_run.h5", "daq_throughput_plain.h5"):
                (out_dir / name).unlink(missing_ok=True)
            if not args.out_dir:
                shutil.rmtree(out_dir, ignore_errors=True)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--seconds", type=float, default=None,
                        help=f"data seconds to replay (default {SECONDS:g}: a 10-minute run; "
                        f"--quick: {QUICK_SECONDS:g})")
    parser.add_argument("--out-dir", default=None,
                        help="directory of the files (default: a new temporary directory)")
    parser.add_argument("--keep", action="store_true", help="keep the HDF5 files")
    parser.add_argument("--profile", action="store_true",
                        help="profile the last --profile-seconds of the run (RunWriter and "
                        "decoding) instead of timing them")
    parser.add_argument("--profile-seconds", type=float, default=30.0,
                        help="length of the profiled tail, s (default 30)")
    parser.add_argument("--scan-frames-per-read", type=int, default=10,
                        help="scanner frames per read (default 10: the driver's 20 ms "
                        "blocks; 1: unbatched, min_block_s = 0)")
    parser.add_argument("--laser-block", type=int, default=100,
                        help="laser samples per read (default 100, 25 ms)")
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--clock", choices=("cpu", "wall"), default="cpu",
                        help="time stages by thread CPU time (default; robust on a shared host) "
                        "or by wall clock")
    result_files.add_arguments(parser)
    args = parser.parse_args(argv)
    if args.seconds is None:
        args.seconds = QUICK_SECONDS if args.quick else SECONDS
    if not args.seconds > 0 or args.scan_frames_per_read < 1 or args.laser_block < 1:
        parser.error("--seconds must be > 0, --scan-frames-per-read and --laser-block >= 1")
    if args.profile and not CHUNK_S <= args.profile_seconds <= args.seconds - 10 * CHUNK_S:
        parser.error("--profile needs 1 <= --profile-seconds <= --seconds - 10 (a timed part)")
    return args


def main(argv: list[str] | None = None) -> None:
    """Entry point."""
    global CLOCK
    args = parse_args(argv)
    CLOCK = time.thread_time if args.clock == "cpu" else time.perf_counter
    run(args)


if __name__ == "__main__":
    main()
