"""The test helpers themselves (:mod:`daq.transports.scripted`).

The scripted-exchange harness must catch wrong, missing and extra bytes; the run-file writer
must put each release where its row says.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.config import load_rig_config
from daq.errors import TransportTimeout
from daq.recording.synthetic import write_release_run
from daq.transports.scripted import ScriptedTransport, expected_exchange
from ident import flat_plate
from simulators import simulate_release

CONFIG = Path(__file__).resolve().parents[2] / "rig_configs" / "sim_flat_plate.toml"


def test_a_complete_exchange_passes():
    """Writes matching the script release the replies, in order."""
    with expected_exchange([(b"", b"HELLO\r\n"), (b"SEND\r\n", b"1013.2\r\n")]) as t:
        assert t.read_until(b"\r\n", 1.0) == b"HELLO\r\n"
        t.write(b"SE")
        with pytest.raises(TransportTimeout):
            t.read(1, 0.1)  # no reply before the command is complete
        t.write(b"ND\r\n")
        assert t.read_until(b"\r\n", 1.0) == b"1013.2\r\n"


def test_wrong_bytes_fail_immediately_with_hex():
    """A byte that differs from the script fails at once and shows both sides."""
    t = ScriptedTransport([(b"SCAN\r\n", b"")])
    t.open()
    with pytest.raises(AssertionError, match=r"expected b'SCAN\\r\\n' \(53 43 41 4e 0d 0a\)"):
        t.write(b"STOP\r\n")


def test_unplayed_script_or_unread_reply_fails_on_exit():
    """Leaving an exchange undone, or a reply unread, is a failure."""
    with pytest.raises(AssertionError, match="1 of 2 exchanges done"):
        with expected_exchange([(b"A", b""), (b"B", b"")]) as t:
            t.write(b"A")
    with pytest.raises(AssertionError, match="reply bytes never read"):
        with expected_exchange([(b"A", b"ok")]) as t:
            t.write(b"A")


def test_releases_with_and_without_a_held_start_land_where_their_rows_say(tmp_path):
    config = load_rig_config(CONFIG)
    section, model = config.section.replace(rho=1.2), flat_plate.jones_model()
    held = simulate_release(section, model, 6.0, 0.004, 0.02, duration=3.0, fs=200.0,
                            pre_s=0.5)  # 100 held samples, t from -0.5 s
    free = simulate_release(section, model, 8.0, -0.003, 0.01, duration=2.0, fs=200.0)
    path = tmp_path / "run.h5"
    write_release_run(path, config, [held, free])
    with h5py.File(path, "r") as f:
        t, h = f["entry/sync/time"][:], f["entry/sync/h"][:]
        rows = f["entry/releases"][:]
    assert t.size == held.t.size + free.t.size and np.allclose(np.diff(t), 1 / 200.0)
    first, second = rows
    # The held release: its row starts at the release instant, after the 100 held samples.
    assert first["start_index"] == 100 and first["stop_index"] == held.t.size
    assert first["release_time"] == pytest.approx(0.5) and t[100] == pytest.approx(0.5)
    assert (first["h0"], first["alpha0"]) == (0.004, 0.02)  # the release's own hold
    np.testing.assert_array_equal(h[:held.t.size], held.h)
    # The next release follows one sample later; it starts at its first sample.
    assert second["start_index"] == held.t.size and second["stop_index"] == t.size
    assert second["release_time"] == pytest.approx(held.t[-1] + 0.5 + 1 / 200.0)
    assert second["U"] == 8.0 and second["h0"] == -0.003
