"""``windrig acquire`` on a rig without a PLC: releases said with keys on the terminal.

The simulated flat plate without its ``[plc]``, acquired by the command line (``--simulate``:
the instruments in a process of their own). The test types on the command's standard input
through a pipe, as an operator at the terminal: Enter 2 s after the recording started (the
simulated operator's hand lets the model go through the virtual tunnel, then the key is
recorded), ``h`` 4 s later (caught and held), ``q`` to end the recording before its duration.
The fan stays off: a still-air decay.
"""

from __future__ import annotations

import io
import os
import re
import sys
import threading
import time

import h5py
import pytest

from daq.cli import main

from support.configs import FAST_FAN, SIM_FLAT_PLATE

pytestmark = [pytest.mark.slow, pytest.mark.realtime]


def test_acquire_records_a_release_by_hand_from_the_terminal(tmp_path, monkeypatch, capsys):
    text, n = re.subn(r"\n\[plc\]\n(?:[^\[\n].*\n|\n)*", "\n",
                      SIM_FLAT_PLATE.read_text())
    assert n == 1
    rig = tmp_path / "no_plc.toml"
    rig.write_text(text + FAST_FAN)
    read_fd, write_fd = os.pipe()
    stdin = io.TextIOWrapper(io.FileIO(read_fd, "r"))
    monkeypatch.setattr(sys, "stdin", stdin)
    typed = io.TextIOWrapper(io.FileIO(write_fd, "w"), write_through=True)
    out = tmp_path / "run.h5"
    log = tmp_path / "run.events.log"  # the run's events as text, as they happen

    def operator() -> None:
        # The operator watches the run start (its log says so), waits for the wind, types.
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline and not (
                log.exists() and "recording_started" in log.read_text()):
            time.sleep(0.05)
        for delay, key in ((2.0, "\n"), (4.0, "h\n"), (1.5, "q\n")):
            time.sleep(delay)
            typed.write(key)
        typed.close()

    typist = threading.Thread(target=operator, daemon=True)
    typist.start()
    assert main(["acquire", "--config", str(rig), "--simulate", "--duration", "30",
                 "--out", str(out), "--skip-check"]) == 0
    typist.join(5.0)
    stdin.close()
    captured = capsys.readouterr()
    assert "manual releases: let the model go by hand" in captured.err
    assert "(the rig has no PLC)" in captured.err
    assert "release 1: recorded" in captured.err and "model held" in captured.err
    assert "1 release(s)" in captured.out
    # No PLC, no trigger pulse: the command warns that the clocks have no anchor, naming them.
    (warning,) = [line for line in captured.err.splitlines()
                  if line.startswith("warning: ") and "anchor" in line]
    assert "no PLC trigger pulse reached this file" in warning
    assert "the clock maps of scanner" in warning and "have no anchor" in warning
    # q ended the recording before its 30 s (the rig's start before it is not counted).
    recorded_s = float(re.search(r"run\.h5: ([0-9.]+) s \(", captured.out).group(1))
    assert recorded_s < 20.0
    with h5py.File(out, "r") as f:
        events = f["entry/events"][:]
        kinds = [k.decode() for k in events["kind"]]
        releases = f["entry/releases"][:]
        t = f["entry/sync/time"][:]
    assert kinds.count("manual_release") == 1 and kinds.count("manual_hold") == 1
    assert kinds.count("release_detected") == 1 and "release_not_detected" not in kinds
    assert releases.shape == (1,)
    # The release found at the key (the simulated hand let go just before it; without trigger
    # pulses the clock maps are good to a few ms here), the decay ending at the hold key.
    key = {k: float(events["time"][kinds.index(k)]) for k in ("manual_release", "manual_hold")}
    assert abs(key["manual_release"] - releases["release_time"][0]) < 0.02
    end = t[releases["stop_index"][0] - 1]
    assert key["manual_hold"] - 0.15 < end <= key["manual_hold"]
