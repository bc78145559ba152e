"""The console's releases table and flutter prediction, live and in replay (pytest-qt, offscreen).

Live: a simulated rig (acquired in a child process, its instruments in another, as ``windrig gui``
runs them: :class:`~daq.console.process_source.ProcessLiveSource`), releases
triggered from the window's control panel at two wind speeds; each appears in the releases table
with its modes, then the E2RFC model and the flutter speed. Replay: a run file with releases at
two wind speeds; the table and the model equal what the same numerics give on the file as
:func:`ident.records.run_file.read_run` reads it (the window's fits run in its default worker
process).
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from daq.cli import main
from daq.config import parse_rig_config
from daq.console.auto_release import AutoReleaser
from daq.console.live_ident import identify_releases
from daq.console.process_source import ProcessLiveSource
from daq.console.replay import ReplaySource
from daq.console.window import ConsoleWindow
from daq.recording.synthetic import write_release_run
from ident.identification.modal import fit_release_modes
from ident.model import flat_plate, flutter
from ident.records.run_file import read_run
from ident.records.run_set import campaign_section
from simulators import simulate_release

from support.clocks import ManualClock
from support.configs import FAST_FAN, SIM_FLAT_PLATE

pytestmark = pytest.mark.realtime

#: Decays of the live test, s: long enough for a modal fit (>= 2 s), short for the test's sake.
LIVE_DECAY_S = 4.0


def flat_plate_config() -> Any:
    return parse_rig_config(SIM_FLAT_PLATE.read_text() + FAST_FAN,
                            "sim_flat_plate.toml + fast fan")


def truth_at(config: Any, U: float) -> dict[str, float]:
    """Frequencies (Hz) of the simulated truth's modes at U, m/s."""
    res = flutter.analyze(config.section, flat_plate.jones_model(), U_max=max(1.5 * U, 5.0))
    names = list(res.mode_names)
    return {key: float(np.interp(U, res.U, res.frequencies[:, names.index(mode)]))
            for key, mode in (("f_h", "heave"), ("f_a", "pitch"))}


def test_a_release_from_the_console_appears_in_the_releases_table(qtbot):
    config = flat_plate_config()
    source = ProcessLiveSource(config, simulate=True, window_s=10.0, fan_rpm=600.0)
    source.open()
    try:
        window = ConsoleWindow(source, window_s=10.0, frame_ms=50, confirm=lambda *_: True)
        qtbot.addWidget(window)
        window.show()
        panel, table = window.controls, window.releases_panel
        assert panel is not None and window.identifier is not None
        b = panel.buttons

        def release_at(rpm: float) -> None:
            """Set the fan, release (the PLC holds the model armed), arm again after a while."""
            if abs(source.fan_speed_rpm - rpm) > 5.0:
                panel.apply_fan(rpm)
            qtbot.waitUntil(lambda: abs(source.fan_speed_rpm - rpm) < 5.0, timeout=10_000)
            qtbot.waitUntil(lambda: panel.busy is None, timeout=5_000)
            if not b["release"].isEnabled():  # not armed yet
                qtbot.waitUntil(lambda: b["arm"].isEnabled(), timeout=5_000)
                b["arm"].click()
            qtbot.waitUntil(lambda: b["release"].isEnabled(), timeout=5_000)
            time.sleep(0.5)  # held still before the release (the writer's h0, alpha0)
            b["release"].click()
            qtbot.waitUntil(lambda: panel.busy is None, timeout=5_000)
            assert "release: done" in panel.status_text, panel.status_text
            qtbot.wait(int(LIVE_DECAY_S * 1000))
            qtbot.waitUntil(lambda: b["arm"].isEnabled(), timeout=5_000)
            b["arm"].click()  # catches the model: the decay ends here

        release_at(600.0)
        qtbot.waitUntil(lambda: table.table.rowCount() == 1 and table.cell(0, "status") == "ok",
                        timeout=20_000)  # the worker process starts at the first fit
        U = float(table.cell(0, "U (m/s)"))
        assert U == pytest.approx(600.0 * config.wind_per_rpm, rel=0.05)  # Pitot vs calibration
        truth = truth_at(config, U)
        # 4 s of decay, scanner noise: the modal frequencies to 1 %.
        assert float(table.cell(0, "f_h (Hz)")) == pytest.approx(truth["f_h"], rel=0.01)
        assert float(table.cell(0, "f_a (Hz)")) == pytest.approx(truth["f_a"], rel=0.01)
        # The arm click comes LIVE_DECAY_S after the release, later on a loaded host.
        assert LIVE_DECAY_S - 0.3 <= float(table.cell(0, "length (s)")) <= LIVE_DECAY_S + 3.0
        assert table.title() == "releases (1)"
        assert "two or more wind speeds (have: " in table.model_label.text()
        assert window.flutter_label.text() == "U_F = --"

        release_at(850.0)
        # The worker fits both speeds: seconds on an idle host, over 30 s once while the whole
        # suite ran beside it.
        qtbot.waitUntil(lambda: "flutter speed" in table.model_label.text(), timeout=90_000)
        assert table.table.rowCount() == 2 and table.cell(1, "status") == "ok"
        fit = window.identifier.campaign
        assert fit is not None and fit.n_releases == 2 and fit.flutter_speed is not None
        U_F = float(flutter.analyze(config.section, flat_plate.jones_model()).speed)
        # One 4 s decay per wind speed (the demo records 2 x 7.5 s at 3 speeds for 3 %): a
        # rougher prediction (a development run: +0.2 %); 10 % tells a working fit from a
        # broken one without failing on an unlucky noise draw.
        assert fit.flutter_speed == pytest.approx(U_F, rel=0.10)
        assert window.flutter_label.text().startswith(f"U_F = {fit.flutter_speed:.2f}")
        assert np.all(np.isfinite(window.derivatives_panel.curves["A2"].getData()[1]))

        window.close()  # stops the worker process, the engine and the rig
        assert not source.running
    finally:
        source.close()


def test_auto_release_runs_a_session_through_the_panel(qtbot):
    config = flat_plate_config()
    source = ProcessLiveSource(config, simulate=True, window_s=10.0)
    source.open()
    try:
        window = ConsoleWindow(source, window_s=10.0, frame_ms=50, confirm=lambda *_: False)
        qtbot.addWidget(window)
        panel = window.controls
        assert panel is not None
        auto = AutoReleaser(panel, source, [700.0], decay_s=3.0, parent=window)
        auto.start()
        qtbot.waitUntil(lambda: auto.step == "done", timeout=30_000)
        assert auto.releases == 1 and len(source.events("release")) == 1
        assert panel.message == "auto: 1 release(s) done; the fan stays at 700 rpm"
        assert panel.fan_spin.value() == 700.0  # the setpoint shown is the one commanded
        # the release was not asked about (confirm answers no): the programme's own consent.
        # Its modal fit runs in the worker process: seconds on an idle host, but a CI run with
        # another job beside it once took over 20 s (as the fit of two speeds above, 90 s).
        qtbot.waitUntil(lambda: window.releases_panel.cell(0, "status") == "ok", timeout=90_000)
        assert float(window.releases_panel.cell(0, "U (m/s)")) == pytest.approx(7.0, rel=0.05)
        window.close()
    finally:
        source.close()


@pytest.mark.parametrize(("args", "message"), [
    (["--auto-release", "600"], "only for a simulated live rig"),
    (["--simulate", "--auto-release", "600,5000"], "--auto-release 5000: fan speeds must be in"),
    (["--simulate", "--auto-release", "600,fast"], "expected fan speeds in rpm"),
])
def test_auto_release_is_refused_unless_simulated_and_within_limits(capsys, args, message):
    try:
        code = main(["gui", "--config", str(SIM_FLAT_PLATE), *args])
    except SystemExit as exc:  # argparse's own refusal of a malformed value
        code = exc.code
    assert code == 2
    assert message in capsys.readouterr().err


# -- replay ------------------------------------------------------------------------------------

REPLAY_RATE = 200.0
REPLAY_SPEEDS = (5.9, 5.9, 7.7, 7.7)
REPLAY_DECAY_S = 6.0


@pytest.fixture(scope="module")
def releases_file(tmp_path_factory) -> Path:
    """Write a run file with four simulated releases at two wind speeds (1 % noise, seeded)."""
    config = flat_plate_config()
    section, truth = config.section.replace(rho=1.2), flat_plate.jones_model()
    path = tmp_path_factory.mktemp("releases") / "run.h5"
    write_release_run(path, config, [
        simulate_release(section, truth, U, 0.004, 0.02, duration=REPLAY_DECAY_S,
                         fs=REPLAY_RATE, noise=0.01, rng=seed, pre_s=1.0)  # 1 s held first
        for seed, U in enumerate(REPLAY_SPEEDS)])
    return path


def test_replay_shows_the_releases_and_model_that_the_file_gives(qtbot, releases_file):
    run = read_run(releases_file)
    assert len(run.releases) == len(REPLAY_SPEEDS)
    clock = ManualClock()
    source = ReplaySource(releases_file, speed=1.0, window_s=10.0, clock=clock)
    source.open()
    window = ConsoleWindow(source, window_s=10.0, frame_ms=10_000_000)  # ticks by hand
    qtbot.addWidget(window)
    ident = window.identifier
    assert ident is not None
    window.tick()
    for _ in range(int(math.ceil(run.releases[-1].t[-1] + 8.0 * len(REPLAY_SPEEDS)))):
        clock.now += 1.0  # play one second, as the timer would in real time
        window.tick()
    deadline = time.monotonic() + 30.0
    while ident.busy or ident.campaign is None:
        assert time.monotonic() < deadline, ident.campaign_status
        qtbot.wait(50)
        window.tick()

    section = campaign_section([run])
    assert [row.status for row in ident.rows] == ["ok"] * len(REPLAY_SPEEDS)
    for row, release in zip(ident.rows, run.releases, strict=True):
        # The same rows as h5py reads through ident.records.run_file: the same fit, to rounding.
        expected = fit_release_modes(release.t, release.h, release.alpha, section)
        assert row.modal is not None
        for name in ("f_h", "zeta_h", "f_a", "zeta_a"):
            assert getattr(row.modal, name) == pytest.approx(getattr(expected, name),
                                                             rel=1e-9), name
        assert row.U == pytest.approx(release.U, rel=1e-12)
        assert window.releases_panel.cell(row.number - 1, "f_h (Hz)") == f"{expected.f_h:.3f}"
    expected_fit = identify_releases(run.releases, section)
    fit = ident.campaign
    assert fit.flutter_speed == pytest.approx(expected_fit.flutter_speed, rel=1e-6)
    assert window.flutter_label.text().startswith(f"U_F = {fit.flutter_speed:.2f}")
    # The range over the structures within one SE is shown when there are several, not else.
    spread = fit.structures
    assert spread is not None
    assert (spread.range_text() in window.flutter_label.text()) == (len(spread.labels) > 1)
    # The table values drawn are the indirect method's, one point per wind speed.
    assert fit.table is not None
    xs, ys = window.derivatives_panel.points["A3"].getData()
    assert np.allclose(sorted(1.0 / xs), sorted(fit.table.K_a), rtol=1e-12)
    window.close()
