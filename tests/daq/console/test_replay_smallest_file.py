"""``gui --replay`` of the smallest run file of docs/reference/file_format.md (offscreen Qt).

Before issue 37 the replay refused it ("object 'pressure' doesn't exist"). A file with the
sync view's scalar columns and a ``[section]`` now plays its traces, with NaN pressures and a
status line that says the file has no taps; one without a column the traces need, or with
pressures but no whole rig config to place them, is refused naming what is missing.
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from daq.cli import main
from daq.console.replay import ReplaySource
from daq.errors import ReplayError

from support.clocks import ManualClock
from support.run_files import write_smallest_run

pytestmark = pytest.mark.realtime


def test_the_smallest_file_replays_its_rows(tmp_path, capsys):
    path = tmp_path / "run.h5"
    write_smallest_run(path)
    clock = ManualClock()
    with ReplaySource(path, speed=1.0, window_s=20.0, clock=clock) as source:
        assert source.info.rate_hz == pytest.approx(200.0)
        source.poll()
        clock.now += 30.0  # past the end (9 s of run)
        source.poll()
        snap = source.snapshot()
        with h5py.File(path, "r") as f:
            np.testing.assert_array_equal(snap["h"], f["entry/sync/h"][()])
        assert np.isnan(snap["pressure"]).all()
        assert source.finished and "no rig config with taps in the file" in source.status()
    png = tmp_path / "shot.png"
    assert main(["gui", "--replay", str(path), "--speed", "20", "--screenshot", str(png),
                 "--after", "0.3", "--size", "640", "480"]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "no rig config with taps in the file" in capsys.readouterr().out


@pytest.mark.parametrize(("omit", "message"), [
    ("sync/alpha", "has no /entry/sync/alpha: replay needs time, h, alpha, lift, moment, U, rho"),
    ("config", "has no /entry/config: replay needs the stored rig config, or at least its "
               "[section]"),
])
def test_a_missing_part_is_named(tmp_path, capsys, omit, message):
    path = tmp_path / "run.h5"
    write_smallest_run(path, omit=(omit,))
    assert main(["gui", "--replay", str(path), "--screenshot", str(tmp_path / "x.png"),
                 "--after", "0"]) == 2
    err = capsys.readouterr().err
    assert err == f"error: {path}: {message} (docs/reference/file_format.md)\n"


def test_pressures_without_a_whole_rig_config_are_refused(tmp_path):
    path = tmp_path / "run.h5"
    write_smallest_run(path)
    with h5py.File(path, "a") as f:
        f["entry/sync/pressure"] = np.zeros((f["entry/sync/time"].shape[0], 4), np.float32)
    with pytest.raises(ReplayError, match=r"the stored rig config is invalid \(.*missing.*\); "
                                          r"the file's pressures need its \[taps\]"):
        ReplaySource(path).open()
