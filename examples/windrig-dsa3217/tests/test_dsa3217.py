"""The DSA3217 driver: windrig's contract kit, scripted bytes, the simulator over TCP, the rig.

Every test but the first two talks to the plugin's simulator over a real loopback TCP
connection; the rig tests run windrig's own commands on the plugin's rig config.
"""

from __future__ import annotations

import os
import struct
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.cli import main
from daq.config import load_rig_config
from daq.instruments.build import build_driver
from daq.sim.rig import start_simulated_rig
from daq.testing.contract import check_driver, construction_problems
from daq.testing.exchange import scripted_driver
from daq.transports.byte_transport import open_transport
from windrig_dsa3217.driver import DRIVER
from windrig_dsa3217.settings import PSI_PA

pytestmark = pytest.mark.realtime

CONFIG = Path(__file__).resolve().parents[1] / "rig_configs" / "sim_dsa3217.toml"
SETTINGS = {"rate_hz": 250.0, "pitot_channel": 15}


def packet(frame: int, psi: list[float], time_us: int) -> bytes:
    """One 'Scan EU with Time' packet, packed from the manual's table by hand."""
    return struct.pack("<hhi16f16hIi", 7, 0, frame, *psi, *([0] * 16), time_us, 1)


def test_the_entry_and_construction_keep_the_contract():
    assert construction_problems(DRIVER, SETTINGS) == []


def test_start_sends_the_configuration_then_scan_and_frames_decode():
    """Scripted bytes: the commands in order, two packets back (a 2-frame gap between)."""
    psi = [float(i) for i in range(16)]
    script = [(b"STOP\r\n", b""), (b"SET PERIOD 250\r\n", b""), (b"SET AVG 1\r\n", b""),
              (b"SET FPS 0\r\n", b""), (b"SET FORMAT B\r\n", b""), (b"SET TIME 1\r\n", b""),
              (b"SET EU 1\r\n", b""),
              (b"SCAN\r\n", packet(1, psi, 4_000) + packet(4, psi, 16_000))]
    with scripted_driver(DRIVER, {**SETTINGS, "min_block_s": 0.0}, script) as driver:
        driver.open()
        driver.start()
        reading = driver.read(timeout_s=0.1)
    assert reading.counter.tolist() == [1, 4]
    assert [(g.after_counter, g.length, g.kind) for g in reading.gaps] == [(1, 2, "missing")]
    # float32 psi to Pa: exact to float32's 7 digits.
    np.testing.assert_allclose(reading.channels["pressure"][0], np.arange(16) * PSI_PA,
                               rtol=1e-7)
    assert reading.channels["pitot"].tolist() == pytest.approx([15 * PSI_PA] * 2, rel=1e-7)
    assert reading.device_time.tolist() == pytest.approx([0.004, 0.016], abs=1e-12)
    assert np.isnan(reading.channels["trigger_time"]).all()  # no trigger input


@pytest.fixture(scope="module")
def rig():
    with start_simulated_rig(load_rig_config(CONFIG)) as running:
        yield running


def test_the_driver_keeps_the_scanner_contract_against_its_simulator(rig):
    inst = rig.config.instrument("scanner")
    readings = check_driver(DRIVER, inst.settings, open_transport(inst.url), n=4)
    assert sum(len(r) for r in readings) >= 4


def test_a_dropped_frame_is_reported_as_a_gap(tmp_path):
    text = CONFIG.read_text() + "\n[simulation.devices.scanner]\ndrop_frames = [12]\n"
    path = tmp_path / "drop.toml"
    path.write_text(text)
    with start_simulated_rig(load_rig_config(path)) as running:
        driver = build_driver(running.config.instrument("scanner"), running.config.limits)
        driver.open()
        driver.start()
        try:
            readings = [driver.read(timeout_s=2.0) for _ in range(6)]
        finally:
            driver.close()
    gaps = [g for r in readings for g in r.gaps]
    assert [(g.after_counter, g.length) for g in gaps] == [(11, 1)]


def test_a_calz_zeroes_the_offsets_and_the_stream_goes_on(rig):
    driver = build_driver(rig.config.instrument("scanner"), rig.config.limits)
    driver.open()
    try:
        driver.start()
        before = np.concatenate([driver.read(timeout_s=2.0).channels["pressure"]
                                 for _ in range(5)])
        mean, frames = driver.recent_pressure_mean()  # what an engine's CALZ records
        assert 0 < frames <= 125 and mean.shape == (16,)  # at most 0.5 s at 250 Hz
        np.testing.assert_allclose(mean, before[-frames:].mean(axis=0), rtol=1e-12)
        driver.stop()
        driver.drain(0.2)
        assert driver.calz(wind_speed_now=0.0, timeout_s=5.0) > 0
        driver.scan(after_pause=True)
        first = driver.read(timeout_s=2.0)
        after = np.concatenate([first.channels["pressure"]]
                               + [driver.read(timeout_s=2.0).channels["pressure"]
                                  for _ in range(5)])
    finally:
        driver.close()
    # Zero offsets of 10 Pa rms before; after, only the 1 Pa noise (wind off): a bound of
    # 3 Pa on the mean over 16 channels and the frames read.
    assert np.abs(before.mean(axis=0)).max() > 5.0
    assert np.abs(after.mean(axis=0)).max() < 3.0
    assert first.gaps and first.gaps[0].kind == "restart"


def test_windrig_check_passes_the_simulated_rig_with_the_plugin(capsys):
    assert main(["check", "--config", str(CONFIG), "--simulate", "--timeout", "5"]) == 0
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.startswith("scanner "))
    assert "scanivalve_dsa3217" in row and row.rstrip().endswith("OK")
    assert "7 of 7 device(s) OK" in out


def test_windrig_acquire_records_the_plugin_scanner(tmp_path, capsys):
    out = tmp_path / "run.h5"
    assert main(["acquire", "--config", str(CONFIG), "--simulate", "--duration", "3",
                 "--out", str(out)]) == 0
    with h5py.File(out, "r") as f:
        pressure = f["entry/sync/pressure"]
        assert pressure.shape[1] == 14  # the rig's taps, from a 16-channel module
        assert f["entry/instrument/scanner/gaps"].shape[0] == 0
        assert pressure.shape[0] > 250  # 250 Hz for most of 3 s
        names = [str(n) for n in f["entry/instrument/scanner"].attrs["channel_names"]]
        assert names[-1] == "pitot" and len(names) == 15  # 14 taps and the Pitot


def test_the_console_runs_on_the_plugin_rig(tmp_path):
    png = tmp_path / "live.png"
    env = {k: v for k, v in os.environ.items()
           if k not in ("QT_QPA_PLATFORM", "DISPLAY", "WAYLAND_DISPLAY")}
    proc = subprocess.run(
        [sys.executable, "-m", "daq.cli", "gui", "--config", str(CONFIG), "--simulate",
         "--screenshot", str(png), "--after", "2", "--size", "800", "600"],
        capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "sync rows" in proc.stdout
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


WINDRIG_ROLE = "scanner"


def test_a_real_dsa3217(windrig_device_url):
    """On the hardware (--windrig-device-url scanner=tcp://HOST:23): the same contract."""
    check_driver(DRIVER, SETTINGS, open_transport(windrig_device_url), n=4, timeout_s=5.0)
