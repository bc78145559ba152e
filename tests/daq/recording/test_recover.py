"""``windrig recover`` and ``windrig info`` on real crashed files (issue 17).

The crashed files are made by a child process (``_crash_child.py``) that writes a run in SWMR
mode with the layout's own functions, leaves a last append half-done as a crash can, and kills
itself with SIGKILL. Files are read back with plain h5py.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.cli import main
from daq.errors import RecoveryError
from daq.recording.layout import STREAM_TABLES, read_sync
from daq.recording.recover import (
    RECOVERED_EVENT,
    clear_status_flags,
    lookup3,
    needs_recovery,
    read_superblock,
    recover_run,
)
from daq.recording.synthetic import write_release_run

from support.configs import SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

CHILD = Path(__file__).with_name("_crash_child.py")
_spec = importlib.util.spec_from_file_location("_crash_child", CHILD)
assert _spec is not None and _spec.loader is not None
child = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(child)


def crashed(path: Path) -> Path:
    done = subprocess.run([sys.executable, str(CHILD), "crash", str(path)], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == -9, done.stderr  # it killed itself
    return path


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_lookup3_matches_hdf5s_own_superblock_checksum(tmp_path):
    """The checksum HDF5 wrote into a real superblock v3 is what lookup3 computes."""
    path = crashed(tmp_path / "run.h5")
    block = path.read_bytes()[:48]
    assert block[8] == 3  # superblock version 3 (SWMR)
    assert lookup3(block[:44]) == int.from_bytes(block[44:48], "little")
    assert lookup3(block[:43]) != lookup3(block[:44])


def test_recover_trims_a_half_done_append_and_marks_the_run(tmp_path, capsys):
    path = crashed(tmp_path / "run.h5")
    assert needs_recovery(path) and read_superblock(path).flags == 0b101
    with pytest.raises(OSError, match="already open for write"):
        h5py.File(path, "r").close()
    # windrig's readers read it as it is; info says what to do.
    t = read_sync(path)["time"]  # the shortest column, fill rows and all
    assert t.size == child.SYNC_ROWS + child.PARTIAL[0] and np.isnan(t[child.SYNC_ROWS:]).all()
    assert main(["info", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["state"] == "crashed" and info["status_flags"] == 5
    assert info["sync"]["rows"] == child.SYNC_ROWS
    assert info["sync"]["unwritten_rows"] == child.PARTIAL[0]
    assert info["sync"]["duration_s"] == pytest.approx(0.598)
    assert main(["info", str(path)]) == 0
    assert "run `windrig recover" in capsys.readouterr().out.splitlines()[0]

    assert main(["recover", str(path)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"recovered {path}: status flags 0x05 cleared; 300 sync rows kept")
    assert not needs_recovery(path)

    sync_trim = {f"/entry/sync/{name}": child.PARTIAL[0] for name in child.expected_sync()}
    with h5py.File(path) as f:  # plain h5py: any HDF5 tool
        for name, values in child.expected_sync().items():
            np.testing.assert_array_equal(f["entry/sync"][name][:], values, err_msg=name)
        laser = f["entry/instrument/laser"]
        assert {laser[k].shape[0] for k in laser if k not in STREAM_TABLES} == {child.RAW_ROWS}
        assert laser["host_time_ns"][-1] == 10**9 + (child.RAW_ROWS - 1) * 10**6
        assert laser["gaps"][:].tolist() == [(100, 5)]
        releases = f["entry/releases"][:]
        assert releases["stop_index"].tolist() == [200]  # the decay in the lost rows is gone
        events = f["entry/events"][:]
        assert [k.decode() for k in events["kind"]] == ["arm", "release", RECOVERED_EVENT]
        assert events["time"][-1] == pytest.approx(0.598)
        entry = f["entry"]
        assert entry.attrs["recovered"].endswith("+00:00") and "crash" in \
            entry.attrs["recovered_note"]
        recovery = f["entry/metadata/recovery"]
        assert recovery["status_flags_found"][()] == 5 and recovery["sync_rows"][()] == 300
        trimmed = {k: int(v[()]) for k, v in recovery["rows_trimmed"].items()}
    assert trimmed == {k.strip("/").replace("/", "__"): n for k, n in {
        **sync_trim, "/entry/instrument/laser/host_time_ns": 3,
        "/entry/instrument/laser/value": 3, "/entry/instrument/laser/gaps": 1,
        "/entry/releases": 1, "/entry/events": 1}.items()}

    # Recovered: info says so; a second recover changes nothing.
    assert main(["info", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["state"] == "recovered" and info["recovery"]["sync_rows"] == 300
    assert info["events"]["counts"] == {"arm": 1, RECOVERED_EVENT: 1, "release": 1}
    assert info["devices"]["laser"] == {
        "driver": None, "rate_hz": 1000.0, "channels": ["distance"], "samples": 600,
        "time_span_s": [0.0, 0.599], "gaps": 1, "missing_samples": 5, "restarts": 0,
        "clock_fit": None}
    before = digest(path)
    assert main(["recover", str(path)]) == 0
    assert "already recovered" in capsys.readouterr().out and digest(path) == before


def test_a_cleanly_closed_file_is_left_untouched(tmp_path, capsys):
    path = tmp_path / "clean.h5"
    write_release_run(path, _config(), [])
    before = digest(path)
    report = recover_run(path)
    assert not report.recovered and report.flags_before == 0 and digest(path) == before
    assert clear_status_flags(path) == 0 and digest(path) == before
    assert main(["info", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["state"] == "closed"


def test_a_file_still_being_written_is_refused(tmp_path, capsys):
    path = tmp_path / "live.h5"
    proc = subprocess.Popen([sys.executable, str(CHILD), "hold", str(path)],
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        assert main(["info", str(path), "--json"]) == 0
        info = json.loads(capsys.readouterr().out)
        assert info["state"] == "writing" and info["open_in_processes"] == [proc.pid]
        before = digest(path)
        assert main(["recover", str(path)]) == 1
        err = capsys.readouterr().err.strip()
        assert err.startswith("error: ") and f"still open in process {proc.pid}" in err
        assert digest(path) == before
    finally:
        proc.kill()
        proc.communicate()


def test_a_damaged_superblock_is_not_rewritten(tmp_path):
    path = crashed(tmp_path / "run.h5")
    data = bytearray(path.read_bytes())
    data[40] ^= 0xFF  # the root group's address: the stored checksum no longer matches
    path.write_bytes(bytes(data))
    with pytest.raises(RecoveryError, match="checksum does not match"):
        clear_status_flags(path)
    assert path.read_bytes() == bytes(data)


def _config():
    from daq.config import load_rig_config

    return load_rig_config(SIM_FLAT_PLATE)


#: A program other than windrig writing the smallest run file (docs/reference/file_format.md:
#: no raw streams) in SWMR mode, killed before it closes the file.
FOREIGN_WRITER = """
import os, signal, sys
import h5py, numpy as np
with h5py.File(sys.argv[1], "w", libver="latest") as f:
    f["entry/config"] = "[section]\\nB = 0.3\\nm = 3.0\\nI = 0.03\\nfh = 2.0\\nfa = 4.0\\n" \\
        "zeta_h = 0.005\\nzeta_a = 0.005\\n"
    for name in ("time", "h", "alpha", "lift", "moment", "U", "rho"):
        f.create_dataset(f"entry/sync/{name}", data=np.arange(100.0) / 100.0, maxshape=(None,),
                         chunks=(64,))
    f.swmr_mode = True
    f.flush()
    os.kill(os.getpid(), signal.SIGKILL)
"""


def test_a_crashed_file_without_raw_streams_is_recovered(tmp_path, capsys):
    # Before: "has no /entry/instrument: not a windrig run file", for a layout that every
    # reader takes (docs/reference/file_format.md) and that info describes as "crashed".
    path = tmp_path / "foreign.h5"
    done = subprocess.run([sys.executable, "-c", FOREIGN_WRITER, str(path)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == -9, done.stderr
    assert read_superblock(path).flags != 0
    assert main(["recover", str(path)]) == 0
    assert capsys.readouterr().out.startswith(f"recovered {path}: status flags")
    assert read_superblock(path).flags == 0
    with h5py.File(path, "r") as f:  # any HDF5 tool opens it now
        assert f["entry/sync/time"].shape == (100,) and "recovered" in f["entry"].attrs
