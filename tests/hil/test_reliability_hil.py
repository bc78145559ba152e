"""Reliability of a recording (issue 5): crash, device disconnect, unwritable path, full disk.

Everything real: ``windrig acquire`` (``python -m daq.cli acquire``) in a subprocess, or
:func:`daq.sim.recording.record_simulated_run` in this process, with the simulated instruments of
``rig_configs/sim_flat_plate.toml`` over their loopback transports, and run files read back with
h5py. Nothing of our own code is mocked.

- **SIGKILL mid-run.** A reader in this process follows the file live (SWMR) while
  ``windrig acquire`` records; the writer is killed with SIGKILL (its simulated instruments, which
  live in the same process, die with it). The file opens read-only without repair and holds
  every row the live reader saw, up to within the flush interval of the kill.
- **Device disconnect.** Two of the three lasers drop their line for 0.8 s (the simulators'
  ``disconnect`` fault, the counter running on) and the PLC's Modbus server refuses
  connections for 0.8 s; later the scanner resets its data connection (``tcp_reset``: an RST,
  then a new scan). The drivers reconnect; the run file holds an exact gap in each raw stream
  (the scanner's: a restart of unknown length), a fault and a recovery event per device, NaN
  in the synchronised view only over the outages, and nothing the simulators did not send.
- **Unwritable path, full disk.** ``windrig acquire`` refuses a missing or read-only directory
  and a nearly full disk before it starts anything; a disk that fills in the middle of a run
  (``RLIMIT_FSIZE``: writes fail with EFBIG, as with ENOSPC, without needing a full disk) leaves
  a file readable up to its last flush, with no invented rows.

Measured on the development machine (2 cores, 10 runs): SIGKILL: the live reader saw the sync
rows grow in steps of 430-900 rows every 1.1-1.4 s (the 1 s flush interval plus the 0.2 s write
batches); after the kill the file held every row seen live and ended 0.31-0.71 s before the kill
(raw laser rows alike; the 1 Hz barometer up to 1.6 s). Disconnect: laser gaps of 3211-3396
samples for the 0.8 s outage (0.803-0.849 s at 4 kHz), each exactly the counters the simulator
could not send; sync NaN from/to within 4 ms of the final clock fit's edges; fault events
0.10-0.21 s after the cut, recoveries 0-40 ms after the first sample after the gap; PLC: 2-3
failed polls, as many fault events, recovery 0.86-1.17 s after the cut; scanner reset: fault
0.10-0.12 s after it, recovery 2-26 ms later, pressures NaN for 0-16 ms around it. Full disk:
1150-2130 sync rows readable; before the fill-value fix 5 runs of 6 also held 300-1100 rows of
zeros after them.
"""

from __future__ import annotations

import contextlib
import inspect
import math
import os
import resource
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from daq.config import parse_rig_config
from daq.recording.layout import SYNC_COLUMNS
from daq.recording.recorder import RunRecorder
from daq.recording.writer import RunWriter
from daq.sim.recording import record_simulated_run
from ident.records.run_file import read_run

from support.configs import REPO, SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

CONFIG = SIM_FLAT_PLATE

#: The recorder flushes at least this often (its default, used by ``windrig acquire``), s.
FLUSH_INTERVAL_S = float(inspect.signature(RunRecorder).parameters["flush_interval_s"].default)
#: The run writer appends raw and sync rows in batches this often (its default), s.
WRITE_INTERVAL_S = float(inspect.signature(RunWriter).parameters["write_interval_s"].default)
#: Slack for what else may trail the newest flushed rows, s: a sync time is written once every
#: stream covers it (laser blocks are read in 20 ms drains, scanner frames in blocks), and ~10
#: threads share 2 cores. Measured: the sync view ends within 10 ms of the raw laser rows.
SYNC_LAG_S = 0.5
#: Most a crash may lose: the last flush interval, the batch not yet appended, the sync lag.
CRASH_LOSS_S = FLUSH_INTERVAL_S + WRITE_INTERVAL_S + SYNC_LAG_S

LASERS_CUT = ("laser_front", "laser_rear")
OUTAGE_S = 0.8
LASER_RATE_HZ = 4000.0
SYNC_RATE_HZ = 500.0
#: Where the synchronised view's NaN rows may start and end, against the final clock fit, s.
SYNC_TOL_S = 0.03

# ------------------------------------------------------------------------------------------------
# Helpers
# ------------------------------------------------------------------------------------------------
def acquire_command(out: Path, duration_s: float) -> list[str]:
    """Return the ``windrig acquire --simulate`` command line (this interpreter, ``-m daq.cli``)."""
    return [sys.executable, "-m", "daq.cli", "acquire", "--config", str(CONFIG), "--simulate",
            "--duration", f"{duration_s:g}", "--out", str(out)]


def in_tmpfs(directory: Path, options: str, command: list[str]) -> list[str]:
    """Wrap ``command`` to run with a tmpfs mounted on ``directory`` (a private mount namespace).

    ``unshare --user --map-root-user --mount`` needs no privileges where unprivileged user
    namespaces are enabled; the mount disappears with the command.
    """
    script = f'mount -t tmpfs -o {options} windrig-test "$0" && exec "$@"'
    return ["unshare", "--user", "--map-root-user", "--mount", "sh", "-c", script,
            str(directory), *command]


def tmpfs_available(directory: Path) -> bool:
    """Return whether :func:`in_tmpfs` works on this machine."""
    try:
        done = subprocess.run(in_tmpfs(directory, "size=1m", ["true"]), capture_output=True,
                              timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return done.returncode == 0


def chmod_blocks_writes(directory: Path) -> bool:
    """Return whether a mode-0o500 directory stops this user (it does not stop root)."""
    directory.chmod(0o500)
    try:
        (directory / "probe").touch()
    except PermissionError:
        return True
    (directory / "probe").unlink()
    directory.chmod(0o700)
    return False


@dataclass
class CliRun:
    """Outcome of one ``windrig acquire`` subprocess."""

    returncode: int | None  # None: still running at the timeout (then killed)
    elapsed_s: float
    stdout: str
    stderr: str
    exit_ns: int  # time.monotonic_ns() when it ended (or was killed)


def run_cli(command: list[str], timeout_s: float, **popen: Any) -> CliRun:
    """Run a command; kill it (and report ``returncode=None``) if it outlives ``timeout_s``."""
    start = time.monotonic()
    proc = subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, **popen)
    try:
        out, err = proc.communicate(timeout=timeout_s)
        code: int | None = proc.returncode
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        code = None
    return CliRun(code, time.monotonic() - start, out, err, time.monotonic_ns())


#: Most a refusal of ``--out`` may take beyond a refusal of ``--duration 0`` (the same start of
#: Python and the same imports, s): loading the config and a statvfs. Starting the simulated
#: rig alone took 2.6 s on a loaded 2-core host (its process, its imports, seven simulators),
#: before the recorder connects a driver.
REFUSAL_OVER_START_S = 2.0


def startup_s(out: Path) -> float:
    """Return how long ``windrig acquire --duration 0`` takes to refuse (Python, imports), s.

    Measured beside each refusal: a loaded host slows both alike (a CI run took 4.2 s to
    refuse an unusable ``--out``, 0.8 s on a quiet host).
    """
    run = run_cli(acquire_command(out, 0.0), timeout_s=30.0)
    assert run.returncode == 2 and "--duration 0: must be > 0 s" in run.stderr, run.stderr
    return run.elapsed_s


def assert_refused_at_once(run: CliRun, out: Path, why: str, startup: float) -> None:
    """Check that the run was refused before it started: promptly, non-zero, one clear line.

    Promptly: within :data:`REFUSAL_OVER_START_S` of the start-up alone (``startup``, from
    :func:`startup_s`), so that the simulated rig cannot have been started.
    """
    assert run.returncode is not None, (
        f"still running after {run.elapsed_s:.1f} s: an unusable --out was not refused at once"
        f"\nstderr: {run.stderr[-2000:]}")
    assert run.elapsed_s < startup + REFUSAL_OVER_START_S, (
        f"refused only after {run.elapsed_s:.1f} s (start-up alone {startup:.1f} s)")
    assert run.returncode not in (0, -signal.SIGSEGV), run.returncode
    assert str(out) in run.stderr and why in run.stderr, run.stderr
    assert "Traceback" not in run.stderr, run.stderr


def listening_ports(pid: int) -> list[int]:
    """Return the TCP ports process ``pid`` listens on (its sockets' inodes in /proc/net/tcp*)."""
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        with contextlib.suppress(OSError):
            target = os.readlink(fd)
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    ports = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        with contextlib.suppress(OSError), open(table) as lines:
            next(lines)
            for line in lines:
                fields = line.split()
                if fields[3] == "0A" and fields[9] in inodes:  # 0A: LISTEN
                    ports.append(int(fields[1].rsplit(":", 1)[1], 16))
    return sorted(ports)


def child_pids(pid: int) -> list[int]:
    """Return the child processes of ``pid`` (from every thread's /proc children list)."""
    children: list[int] = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        with contextlib.suppress(OSError):
            children += [int(c) for c in (task / "children").read_text().split()]
    return children


def running(pid: int) -> bool:
    """Whether process ``pid`` still runs (not gone, not a zombie waiting for its parent)."""
    try:
        return "zombie" not in Path(f"/proc/{pid}/status").read_text().lower()
    except OSError:  # gone
        return False


def follow_live(proc: subprocess.Popen[bytes], path: Path, *, steps: int,
                timeout_s: float) -> list[tuple[int, np.ndarray]]:
    """Follow ``/entry/sync/time`` of a file being written, as a live SWMR reader does.

    Returns one ``(monotonic ns, rows seen)`` per read at which the row count changed, until it
    has grown ``steps`` times after the first rows. Each snapshot's times are checked at once:
    finite, on the sync grid, and the earlier snapshots are prefixes (rows never change).
    """
    deadline = time.monotonic() + timeout_s
    seen: list[tuple[int, np.ndarray]] = []
    f = None
    try:
        while len(seen) < steps + 1:
            assert time.monotonic() < deadline, f"the live reader saw only {len(seen)} sizes"
            assert proc.poll() is None, f"windrig acquire ended early ({proc.returncode})"
            time.sleep(0.1)
            if f is None:
                try:  # before the writer switches to SWMR mode its file lock refuses readers
                    f = h5py.File(path, "r", libver="latest", swmr=True)
                except (OSError, FileNotFoundError):
                    continue
            ds = f["entry/sync/time"]
            ds.refresh()
            n = ds.shape[0]
            if n == 0 or (seen and n == seen[-1][1].size):
                continue
            t = ds[:n]
            assert np.all(np.isfinite(t)) and np.allclose(np.diff(t), 1 / SYNC_RATE_HZ), n
            if seen:
                assert n > seen[-1][1].size and np.array_equal(t[:seen[-1][1].size], seen[-1][1])
            seen.append((time.monotonic_ns(), t))
    finally:
        if f is not None:
            f.close()
    return seen


def runs_of(mask: np.ndarray) -> list[tuple[int, int]]:
    """Return the ``[start, stop)`` index ranges where a boolean array is True."""
    edges = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(),
                    strict=True))


def events_of(f: h5py.File) -> list[tuple[float, str, str, str]]:
    """Return ``/entry/events`` as (time s, kind, device, text)."""
    out = []
    for row in f["entry/events"][:]:
        text = row["text"].decode()
        device = text.split(":", 1)[0] if ":" in text else ""
        out.append((float(row["time"]), row["kind"].decode(), device, text))
    return out


# ------------------------------------------------------------------------------------------------
# 1. SIGKILL mid-run, with a live reader in another process
# ------------------------------------------------------------------------------------------------
def test_sigkill_mid_run_keeps_every_flushed_row_and_a_live_reader_follows(tmp_path):
    path = tmp_path / "killed.h5"
    with open(tmp_path / "stdout.txt", "wb") as out, open(tmp_path / "stderr.txt", "wb") as err:
        proc = subprocess.Popen(acquire_command(path, 120.0), cwd=REPO, stdout=out, stderr=err)
        try:
            # 60 s, as test_recover_hil's: the process, its simulators' process and the first
            # flushes can take seconds each to come on a loaded host
            live = follow_live(proc, path, steps=3, timeout_s=60.0)
            children = child_pids(proc.pid)
            ports = [port for child in children for port in listening_ports(child)]
            kill_ns = time.monotonic_ns()
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    assert proc.returncode == -signal.SIGKILL

    # The simulated instruments lived in a child of the killed process (windrig acquire
    # --simulate serves them from their own process): it sees its pipe close and stops them.
    # (1 scanner command + 1 data port, 3 lasers, fan, PLC, barometer.)
    assert len(ports) >= 8, ports
    deadline = time.monotonic() + 10.0
    while any(running(child) for child in children):
        assert time.monotonic() < deadline, f"the simulators' process {children} outlived it"
        time.sleep(0.05)
    for port in ports:
        with pytest.raises(ConnectionRefusedError):
            socket.create_connection(("127.0.0.1", port), timeout=1.0).close()

    # The file opens as it is (still flagged "open for SWMR write"; no h5clear, no repair).
    last_seen = live[-1][1]
    with h5py.File(path, "r", libver="latest", swmr=True) as f:
        t0_ns = int(f["entry/sync"].attrs["t0_host_ns"])
        kill_s = (kill_ns - t0_ns) * 1e-9
        sync = f["entry/sync"]
        n = min(sync[name].shape[0] for name in SYNC_COLUMNS)
        columns = {name: sync[name][:n] for name in SYNC_COLUMNS}
        raw = {}
        for device, group in f["entry/instrument"].items():
            m = min(group[k].shape[0] for k in ("host_time_ns", "device_time", "counter", "value"))
            raw[device] = (group["host_time_ns"][:m], group["counter"][:m], group["value"][:m],
                           float(group.attrs["rate"]))
        assert f["entry/releases"].shape == (0,)
    t = columns["time"]
    # Every row a live reader saw is still there, unchanged: all data up to the last flush.
    assert n >= last_seen.size and np.array_equal(t[:last_seen.size], last_seen)
    assert np.all(np.isfinite(t)) and np.allclose(np.diff(t), 1 / SYNC_RATE_HZ)
    assert np.isfinite(columns["h"]).mean() > 0.98 and np.isfinite(columns["U"]).mean() > 0.98
    assert kill_s - CRASH_LOSS_S < t[-1] < kill_s, (t[-1], kill_s)
    assert set(raw) == {"scanner", "laser_front", "laser_rear", "laser_check", "fan", "plc",
                        "barometer"}
    for device, (host_ns, counter, value, rate) in raw.items():
        assert counter.size > 0 and value.shape[0] == counter.size, device
        assert np.all(np.diff(counter) > 0) and np.all(np.diff(host_ns) >= 0), device
        assert np.all(host_ns >= t0_ns - 10**9), device  # written, not fill values
        last_s = (int(host_ns[-1]) - t0_ns) * 1e-9
        # A polled device's newest row may also be one poll period old.
        assert kill_s - CRASH_LOSS_S - 1 / rate < last_s < kill_s, (device, last_s, kill_s)

    # ident's reader opens the crashed file too (no release was commanded: none to read).
    run = read_run(path)
    assert run.releases == () and run.section.B == pytest.approx(0.3)


# ------------------------------------------------------------------------------------------------
# 2. A device disconnect mid-run: reconnect, exact gaps, events, nothing invented
# ------------------------------------------------------------------------------------------------
def test_device_disconnects_mid_run_are_marked_gaps_with_fault_and_recovery_events(tmp_path):
    config = parse_rig_config(CONFIG.read_text(), CONFIG.name)
    seen: dict[str, Any] = {}

    def actions(acq: Any, rig: Any) -> None:
        seen["rig"] = rig
        seen["true_offset_s"] = time.monotonic() - rig.tunnel.clock.now()
        time.sleep(1.5)
        seen["cut_ns"] = time.monotonic_ns()
        for name in LASERS_CUT:  # the line drops; no reconnection accepted for 0.8 s
            rig.simulators[name].inject("disconnect", downtime_s=OUTAGE_S, restart=False)
        rig.simulators["plc"].inject("disconnect", outage_s=OUTAGE_S)  # connections refused
        time.sleep(OUTAGE_S + 0.7)
        scanner = rig.simulators["scanner"]
        seen["first_scan"] = scanner.scan_id
        seen["reset_ns"] = time.monotonic_ns()
        scanner.inject("tcp_reset")  # RST on the data connection; the scan restarts at frame 1

    path = tmp_path / "disconnect.h5"
    summary = record_simulated_run(config, path, duration_s=4.5, actions=actions,
                                   progress=False)
    rig = seen["rig"]
    truth = {name: rig.simulators[name].truth() for name in LASERS_CUT}
    scan_truth = rig.simulators["scanner"].truth
    assert summary["errors"] == [] and summary["subscriber_errors"] == {}
    assert summary["overflows"] == 0

    with h5py.File(path, "r") as f:
        t0_ns = int(f["entry/sync"].attrs["t0_host_ns"])
        cut_s = (seen["cut_ns"] - t0_ns) * 1e-9
        reset_s = (seen["reset_ns"] - t0_ns) * 1e-9
        sync = {name: f["entry/sync"][name][:] for name in SYNC_COLUMNS}
        clock = {k: float(v) for k, v in f["entry/sync"].attrs.items() if k.startswith("clock_")
                 and not k.startswith("clock_model")}
        events = events_of(f)
        streams = {}
        for device, group in f["entry/instrument"].items():
            streams[device] = {k: group[k][:] for k in ("host_time_ns", "device_time",
                                                         "counter", "value", "gaps")}

    # -- the raw laser streams: one exact gap, reconnected, nothing invented ----------------------
    resumed_s, mapped_s = {}, {}
    for name in LASERS_CUT:
        s, tr = streams[name], truth[name]
        (gap,) = s["gaps"].tolist()
        after, length = gap
        counter, host_s = s["counter"], (s["host_time_ns"] - t0_ns) * 1e-9
        steps = np.flatnonzero(np.diff(counter) != 1)
        assert steps.tolist() == [np.flatnonzero(counter == after)[0]], name
        i = int(steps[0])
        assert counter[i + 1] - counter[i] - 1 == length, name
        # The gap is exactly what the simulator could not send (nobody connected), and every
        # sample in the file is one it sent, with its value (1 LSB = 0.78 um at MR 50 mm).
        sent = tr.counter[tr.fate == 0]
        sent = sent[(sent >= counter[0]) & (sent <= counter[-1])]
        assert np.array_equal(counter, sent), name
        lost = tr.counter[(tr.counter > after) & (tr.counter <= after + length)]
        assert lost.size == length and np.all(tr.fate[np.isin(tr.counter, lost)] == 4), name
        index = np.searchsorted(tr.counter, counter)
        assert np.max(np.abs(s["value"][:, 0] - 1e-3 * tr.distance_mm[index])) < 1e-6, name
        # 0.8 s at 4 kHz, plus what the simulator produced but had not sent when the fault hit
        # and until the driver's reopen was served (its threads run late on 2 busy cores:
        # +5-68 ms when measured alone, +286 ms once in a full suite run). The gap's exactness
        # is checked above against the simulator's truth; this bound only says the outage was
        # the injected one, not a second: 0.4 s.
        assert OUTAGE_S * LASER_RATE_HZ <= length <= (OUTAGE_S + 0.4) * LASER_RATE_HZ, name
        # The device clock ran on through the outage (no restart): its step is the gap's.
        step = s["device_time"][i + 1] - s["device_time"][i]
        assert step == pytest.approx((length + 1) / LASER_RATE_HZ, abs=2e-4), name
        assert cut_s - 0.1 < host_s[i] < cut_s + 0.1, name
        assert host_s[i + 1] - host_s[i] >= OUTAGE_S - 0.05, name
        assert host_s[-1] > host_s[i + 1] + 1.0, name  # samples went on after the reconnect
        resumed_s[name] = (float(host_s[i]), float(host_s[i + 1]))
        # The samples on either side of the gap on the run's time base (the final clock fit,
        # /entry/sync attrs: device_time = offset + (1 + 1e-6 drift) t).
        offset, drift = clock[f"clock_offset_s__{name}"], clock[f"clock_drift_ppm__{name}"]
        edges = (s["device_time"][i:i + 2] - offset) / (1 + 1e-6 * drift)
        mapped_s[name] = (float(edges[0]), float(edges[1]))

    # -- the PLC: its failed polls are the gap, each one a fault event ----------------------------
    plc = streams["plc"]
    (plc_gap,) = plc["gaps"].tolist()
    plc_faults = [e for e in events if e[1] == "fault" and e[2] == "plc"]
    assert plc_gap[1] == len(plc_faults) >= 1
    assert all(cut_s < e[0] < cut_s + OUTAGE_S + 0.2 for e in plc_faults)
    steps = np.flatnonzero(np.diff(plc["counter"]) != 1)  # the poll number skips the failed
    assert steps.size == 1 and plc["counter"][steps[0]] == plc_gap[0]
    assert plc["counter"][steps[0] + 1] - plc_gap[0] - 1 == plc_gap[1]
    assert plc["counter"].size - steps[0] - 1 >= 10  # 10 Hz polls went on for > 1 s

    # -- the scanner: a restart gap (length unknown), frames on both sides ------------------------
    scan = streams["scanner"]
    (scan_gap,) = scan["gaps"].tolist()
    counter, host_s = scan["counter"], (scan["host_time_ns"] - t0_ns) * 1e-9
    assert scan_gap[1] == -1  # a new scan: how many frames were missed is unknown
    # The driver keeps the stream's counter increasing across the restart.
    assert np.all(np.diff(counter) == 1)
    before = counter <= scan_gap[0]
    assert reset_s - 0.1 < host_s[before][-1] < reset_s + 0.1
    assert host_s[-1] > reset_s + 0.8  # frames of the new scan went on
    # Before the reset: every frame the simulator sent in that span, no other.
    sent = scan_truth.sent_counters(0, seen["first_scan"])
    assert np.array_equal(counter[before], sent[(sent >= counter[0]) & (sent <= scan_gap[0])])

    # -- events: a fault and a recovery for every device cut -------------------------------------
    for name in (*LASERS_CUT, "plc", "scanner"):
        faults = [e[0] for e in events if e[1] == "fault" and e[2] == name]
        recovered = [e[0] for e in events if e[1] == "recovered" and e[2] == name]
        assert faults and len(recovered) == 1, (name, events)
        assert (reset_s if name == "scanner" else cut_s) < faults[0], name
        # Reported while the line is still down (OUTAGE_S): a laser's fault is posted when the
        # read that saw the driver reopen its line returns: 0.10-0.11 s after the cut on an
        # idle host (the 0.1 s backoff, then the reopen; the PLC 0.16-0.37 s), but 0.51 s once
        # in a full suite run, where a reopen needed its second attempt (0.1 + 0.2 s backoff);
        # the former 0.5 s bound did not allow for that path.
        assert faults[0] < (reset_s if name == "scanner" else cut_s) + OUTAGE_S, name
        assert max(faults) < recovered[0], name
        if name in resumed_s:  # the recovery is the first data after the reconnect
            assert resumed_s[name][1] - 0.01 < recovered[0] < resumed_s[name][1] + 0.3, name
        elif name == "plc":  # polls resume within the engine's backoff (0.1, 0.2, 0.4 s)
            assert cut_s + OUTAGE_S < recovered[0] < cut_s + OUTAGE_S + 1.0, name
        else:  # the driver reconnects after 0.1 s; the simulator kept the new scan's frames
            assert reset_s < faults[0] < recovered[0] < reset_s + 0.6, name
    others = {device: s["gaps"].size for device, s in streams.items()
              if device not in (*LASERS_CUT, "plc", "scanner")}
    assert others == dict.fromkeys(others, 0)  # the other devices were not disturbed
    assert summary["faults"] == sum(e[1] == "fault" for e in events)

    # -- the synchronised view: NaN exactly over the outage, right values around it ---------------
    t, h, alpha = sync["time"], sync["h"], sync["alpha"]
    window = (t > cut_s - 1.0) & (t < reset_s - 0.1)
    (nan_run,) = runs_of(window & ~np.isfinite(h))
    start, stop = nan_run
    # h needs two lasers of three: NaN from the later of the last samples before the gaps to the
    # earlier of the first after them. The view was resampled with the clock maps of the moment,
    # which differ from the final fit used here: by < 4 ms in the final runs; by 21-22 ms at the
    # gap in 2 of ~12 exploratory runs (reader threads held up by ~40 ms on 2 busy cores): 30 ms.
    nan_from = max(edge[0] for edge in mapped_s.values())
    nan_to = min(edge[1] for edge in mapped_s.values())
    assert abs(t[start] - nan_from) < SYNC_TOL_S, (t[start], nan_from, mapped_s, resumed_s)
    assert abs(t[stop - 1] - nan_to) < SYNC_TOL_S, (t[stop - 1], nan_to, mapped_s, resumed_s)
    assert np.array_equal(np.isfinite(alpha[window]), np.isfinite(h[window]))
    for column in ("pressure", "lift", "moment", "U"):  # the scanner was not cut
        assert np.all(np.isfinite(sync[column][window])), column
    # Before and after the outage h and alpha are the tunnel's truth (the model is held).
    ok = window & np.isfinite(h)
    true = rig.tunnel.sample(t[ok] + t0_ns * 1e-9 - seen["true_offset_s"])
    assert np.max(np.abs(h[ok] - true["h"])) < 1e-4  # 0.1 mm (noise ~1 um)
    assert np.max(np.abs(alpha[ok] - true["alpha"])) < 1e-3  # 1 mrad
    # Around the scanner's reset: pressures missing at most for the frames lost in flight (the
    # simulator keeps the new scan's frames while the driver reconnects; measured 0-16 ms), in
    # one run near the reset; h and alpha untouched.
    window = (t > reset_s - 0.5) & (t < t[-1] - 0.05)
    lost = window & ~np.all(np.isfinite(sync["pressure"]), axis=1)
    for column in ("lift", "moment", "U"):
        assert np.array_equal(~np.isfinite(sync[column][window]), lost[window]), column
    assert np.all(np.isfinite(h[window])) and np.all(np.isfinite(alpha[window]))
    runs = runs_of(lost)
    assert len(runs) <= 1, [(t[a], t[b - 1]) for a, b in runs]
    for a, b in runs:
        assert reset_s - 0.05 < t[a] and t[b - 1] < reset_s + 0.3, (t[a], t[b - 1], reset_s)


# ------------------------------------------------------------------------------------------------
# 3. Unwritable path, full disk
# ------------------------------------------------------------------------------------------------
def test_acquire_refuses_a_missing_directory_at_once(tmp_path):
    out = tmp_path / "nonexistent_dir" / "x.h5"
    startup = startup_s(out)
    run = run_cli(acquire_command(out, 60.0), timeout_s=startup + 6.0)
    assert_refused_at_once(run, out, "does not exist", startup)
    assert not out.parent.exists()


def test_acquire_refuses_a_read_only_directory_at_once(tmp_path):
    directory = tmp_path / "read_only"
    directory.mkdir()
    out = directory / "x.h5"
    command = acquire_command(out, 60.0)
    startup = startup_s(out)
    try:
        if chmod_blocks_writes(directory):
            why = "Permission denied"
        elif tmpfs_available(directory):  # root ignores modes: a read-only file system then
            command, why = in_tmpfs(directory, "ro,size=4g", command), "Read-only file system"
        else:
            pytest.skip("chmod does not stop this user and no tmpfs can be mounted")
        run = run_cli(command, timeout_s=startup + 6.0)
    finally:
        directory.chmod(0o700)
    assert_refused_at_once(run, out, why, startup)
    assert not out.exists()


def test_acquire_refuses_a_nearly_full_disk_at_once(tmp_path):
    """A real 16 MiB file system (statvfs), below the recorder's 1 GiB minimum free space."""
    directory = tmp_path / "small_disk"
    directory.mkdir()
    if not tmpfs_available(directory):
        pytest.skip("no tmpfs can be mounted (no unprivileged user namespaces)")
    out = directory / "x.h5"
    startup = startup_s(out)
    run = run_cli(in_tmpfs(directory, "size=16m", acquire_command(out, 60.0)),
                  timeout_s=startup + 6.0)
    assert_refused_at_once(run, out, "only 16.0 MiB free", startup)


#: File size limit of the "disk fills mid-run" child, bytes: ~2 s of recording at ~0.7 MB/s.
FSIZE_LIMIT = 1_500_000


@pytest.fixture(scope="module")
def disk_full_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, CliRun]:
    """Run ``windrig acquire`` (10 s) whose writes fail with EFBIG once the file reaches 1.5 MB."""
    path = tmp_path_factory.mktemp("disk_full") / "full.h5"

    def limit_file_size() -> None:  # in the child, before exec
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # else the kernel kills it at the limit
        resource.setrlimit(resource.RLIMIT_FSIZE, (FSIZE_LIMIT, FSIZE_LIMIT))

    run = run_cli(acquire_command(path, 10.0), timeout_s=30.0, preexec_fn=limit_file_size)
    return path, run


def test_disk_full_mid_run_leaves_the_file_readable_up_to_its_last_flush(disk_full_run):
    """The file holds the rows flushed before the failure; nothing after them looks like data.

    A failed flush may have recorded a dataset's new size but not its new chunk, each dataset of
    a group on its own: such rows must read as the fill values (NaN, -1), never as zeros (before
    the fix, 5 runs of 6 ended with 300-1100 sync rows of time 0 s, h 0 m and raw rows with
    counter 0 and host time 0).
    """
    path, _ = disk_full_run
    assert 0.9 * FSIZE_LIMIT < path.stat().st_size <= FSIZE_LIMIT
    with h5py.File(path, "r", libver="latest", swmr=True) as f:  # the close failed: SWMR flag
        t0_ns = int(f["entry/sync"].attrs["t0_host_ns"])
        sync = {name: f["entry/sync"][name][:] for name in SYNC_COLUMNS}
        raw = {device: (group["counter"][:], group["host_time_ns"][:], group["value"][:])
               for device, group in f["entry/instrument"].items()}
    t = sync["time"]
    n = int(np.count_nonzero(np.isfinite(t)))
    # The rows written before the failure: a prefix, on the sync grid, > 1 s of data ...
    assert n > SYNC_RATE_HZ and np.isfinite(t[:n]).all()
    assert np.allclose(np.diff(t[:n]), 1 / SYNC_RATE_HZ) and t[0] < 0.1
    assert np.isfinite(sync["h"][:n]).mean() > 0.98
    # ... and no invented zeros anywhere (the model is held at h = 8 mm, alpha = 0.04 rad).
    for name in ("h", "alpha", "rho"):
        assert not np.any(sync[name] == 0.0), name
    for device, (counter, host_ns, value) in raw.items():
        written = counter >= 0  # -1: the fill value
        k = int(np.count_nonzero(written))
        assert k > 0 and written[:k].all() and np.all(np.diff(counter[:k]) > 0), device
        stamped = host_ns > 0
        k = int(np.count_nonzero(stamped))
        assert k > 0 and stamped[:k].all() and np.all(host_ns[:k] > t0_ns - 10**9), device
        assert np.all(host_ns[k:] == -1), device
        finite = np.isfinite(value).all(axis=1)  # these streams have no NaN samples here
        k = int(np.count_nonzero(finite))
        assert finite[:k].all(), device


def test_disk_full_mid_run_stops_the_run_with_a_clear_error(disk_full_run):
    path, run = disk_full_run
    with h5py.File(path, "r", libver="latest", swmr=True) as f:
        t0_ns = int(f["entry/sync"].attrs["t0_host_ns"])
        t = f["entry/sync/time"][:]
    last_s = float(np.nanmax(t))
    exit_s = (run.exit_ns - t0_ns) * 1e-9
    assert run.returncode == 1, (run.returncode, run.stderr[-3000:])  # not -11: SIGSEGV
    assert str(path) in run.stderr and "File too large" in run.stderr, run.stderr[-3000:]
    assert "Traceback" not in run.stderr, run.stderr[-3000:]
    # The write fails at the first flush after the last good one; the run ends right after it.
    assert exit_s - last_s < FLUSH_INTERVAL_S + WRITE_INTERVAL_S + 2.0, (last_s, exit_s)
    assert math.isfinite(last_s)
