"""The experiment log: a scripted session's every action in ``/entry/events`` and in RUN.events.log.

The simulated rig over its real transports, recorded by the production recorder; the session
goes through the engine's commands as an operator's would (the console calls the same ones).
"""

from __future__ import annotations

import re
import threading

import h5py
import pytest

from daq.config import load_rig_config
from daq.recording.run import record_run
from daq.sim.rig import start_simulated_rig

from support.configs import SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

CONFIG = SIM_FLAT_PLATE
#: One line of RUN.events.log: UTC time, run time (s), kind, device, text.
LINE = re.compile(r"^(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z) +(-?\d+\.\d{3}) (\S+) +(\S+) +(.*)$")


def test_a_scripted_session_is_in_the_events_and_the_text_log(tmp_path):
    reached = threading.Event()
    done = threading.Event()
    seen: list[str] = []

    def spy(name, doc):  # the test's eyes on the run (dispatcher thread)
        if name == "event":
            seen.append(doc.kind)
            if doc.kind == "fan_reached":
                reached.set()

    def session(acq):
        acq.set_fan_speed(150.0)
        acq.start_fan()
        assert reached.wait(20.0), "the fan did not reach 150 rpm"  # 100 rpm/s ramp
        reached.clear()
        acq.arm()
        acq.release()
        acq.mark("note", "decay looked clean")
        acq.arm()
        acq.stop_fan()
        assert reached.wait(20.0), "the fan did not stop"
        acq.calz(wind_speed_now=0.0)  # wind off: the fan stopped and reached 0 rpm
        done.set()

    out = tmp_path / "session.h5"
    with start_simulated_rig(load_rig_config(CONFIG)) as rig:
        summary = record_run(rig.config, out, duration_s=60.0, actions=session, progress=False,
                             subscribers=[spy], until=done, calz=True)
    assert summary["errors"] == []
    with h5py.File(out, "r") as f:
        rows = [(float(t), k.decode(), x.decode()) for t, k, x in f["entry/events"][()]]
    kinds = [k for _, k, _ in rows if k != "trigger"]
    # Every action of the session, in order, with the drive's two settled speeds.
    expected = ["recording_started", "fan_speed", "fan_start", "fan_reached", "arm", "release",
                "note", "arm", "fan_stop", "fan_reached", "calz", "recording_stopped"]
    assert [k for k in kinds if k in expected] == expected
    reached_rows = [x for _, k, x in rows if k == "fan_reached"]
    assert reached_rows[0].startswith("fan: fan reached 1") and '"setpoint_rpm": 150.0' in \
        reached_rows[0]
    assert reached_rows[1].startswith("fan: fan stopped")
    assert any(x == "decay looked clean" for _, k, x in rows if k == "note")

    log = out.with_suffix(".events.log").read_text(encoding="utf-8").splitlines()
    assert log[0].startswith("# windrig experiment log of session.h5")
    parsed = [LINE.match(line) for line in log[1:]]
    assert all(parsed), [line for line, m in zip(log[1:], parsed, strict=True) if not m]
    # The text log is the file's events (the 0.5 s trigger pulses left out), row for row.
    kept = [(t, k, x) for t, k, x in rows if k != "trigger"]
    assert len(parsed) == len(kept)
    for m, (t, kind, text) in zip(parsed, kept, strict=True):
        assert float(m.group(2)) == pytest.approx(t, abs=5e-4)  # written to the ms
        assert m.group(3) == kind
        device = m.group(4)
        assert (text == m.group(5)) if device == "-" else (text == f"{device}: {m.group(5)}")
    assert "fan_reached" in seen


def test_a_log_file_named_as_the_experiment_log_is_refused(tmp_path, capsys):
    """`acquire --log-file RUN.events.log --out RUN.h5` would write two logs into one file."""
    from daq.cli import main

    out = tmp_path / "run.h5"
    code = main(["acquire", "--config", str(CONFIG), "--simulate", "--duration", "1", "--out",
                 str(out), "--log-file", str(tmp_path / "run.events.log"), "--skip-check"])
    assert code == 2
    assert "is the run's experiment log" in capsys.readouterr().err
    assert not out.exists()
