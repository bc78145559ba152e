"""``windrig identify`` without release rows or without taps: the two routes around a PLC.

``--detect-releases`` finds the releases in the lasers' signals; the displacement-only route
identifies a file without forces.

Run files are written by the acquisition's own recorder (:mod:`daq.recording.synthetic`) from
simulated releases of the flat-plate rig (``rig_configs/sim_flat_plate.toml``), each with 1 s
held before it (0.2 % of each displacement's RMS as noise, 1 % on the forces): the same samples
with and without ``/entry/releases`` rows, and with the forces absent (a rig without taps).
"""

from __future__ import annotations

import json
import types

import h5py
import numpy as np
import pytest

from daq.cli import main
from daq.config import parse_rig_config
from daq.offline.displacement_route import CAVEATS
from daq.recording.synthetic import write_release_run
from ident.model import flat_plate, flutter
from simulators.tunnel import simulate_release

from support.configs import SIM_FLAT_PLATE

CONFIG = parse_rig_config(SIM_FLAT_PLATE.read_text(), "sim_flat_plate.toml")
TRUTH = flat_plate.jones_model()
NOISE = {"h": 0.002, "alpha": 0.002, "lift": 0.01, "moment": 0.01}


def _releases(speeds, holds, *, forces: bool = True, duration: float = 6.0):
    out = []
    for k, U in enumerate(speeds):
        for j, (h0, alpha0) in enumerate(holds):
            sim = simulate_release(CONFIG.section, TRUTH, U, h0, alpha0, duration=duration,
                                   fs=500.0, pre_s=1.0, noise=NOISE, rng=10 * k + j)
            if not forces:  # what a rig without taps records: no lift, no moment
                sim = types.SimpleNamespace(t=sim.t, h=sim.h, alpha=sim.alpha, U=sim.U,
                                            rho=sim.rho, lift=np.full(sim.t.size, np.nan),
                                            moment=np.full(sim.t.size, np.nan))
            out.append(sim)
    return out


@pytest.fixture(scope="module")
def two_speeds(tmp_path_factory):
    """Write the same four releases (6 and 8 m/s) with release rows and without any."""
    where = tmp_path_factory.mktemp("detect")
    releases = _releases((6.0, 8.0), ((0.008, 0.04), (0.006, 0.03)))
    with_rows, without = where / "rows.h5", where / "no_rows.h5"
    write_release_run(with_rows, CONFIG, releases)
    write_release_run(without, CONFIG, releases, release_rows=False)
    return with_rows, without


def test_detected_releases_identify_as_the_recorded_rows(two_speeds, tmp_path, capsys):
    with_rows, without = two_speeds
    recorded, detected = tmp_path / "recorded.json", tmp_path / "detected.json"
    assert main(["identify", str(with_rows), "--json", str(recorded)]) == 0
    capsys.readouterr()
    assert main(["identify", str(without), "--detect-releases", "--json", str(detected)]) == 0
    printed = capsys.readouterr().out
    assert "4 release(s) found in the lasers' signals" in printed
    # The detected instants against the true ones (the other file's rows): the detector's
    # 0.1 ms rms at this noise (ident.records.release_onset), 1 ms allowed.
    found = [float(line.split()[1]) for line in printed.splitlines()
             if line.startswith("  at ")]
    with h5py.File(with_rows, "r") as f:
        truth = f["entry/releases"]["release_time"][:]
    assert np.allclose(found, truth, atol=1e-3), (found, truth)
    a, b = json.loads(recorded.read_text()), json.loads(detected.read_text())
    assert b["warnings"] is not None and isinstance(b["warnings"], list)
    # The same flutter speed within the recorded rows' stated std.
    assert abs(a["flutter_speed"] - b["flutter_speed"]) <= a["flutter_speed_std"]


def test_detect_releases_refuses_a_file_with_release_rows(two_speeds, capsys):
    with_rows, _ = two_speeds
    assert main(["identify", str(with_rows), "--detect-releases"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "release row(s)" in err[0]


def test_a_file_without_release_rows_has_nothing_to_identify_without_the_option(two_speeds,
                                                                                capsys):
    _, without = two_speeds
    assert main(["identify", str(without)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ")


@pytest.fixture(scope="module")
def no_taps(tmp_path_factory):
    """Write five speeds, one release each, no forces: a rig without taps."""
    path = tmp_path_factory.mktemp("no_taps") / "no_taps.h5"
    write_release_run(path, CONFIG, _releases((4.0, 5.0, 6.0, 7.0, 8.0), ((0.008, 0.04),),
                                              forces=False, duration=8.0))
    return path


def test_a_file_without_forces_is_identified_by_the_displacement_route(no_taps, tmp_path,
                                                                        capsys):
    out = tmp_path / "fd.json"
    assert main(["identify", str(no_taps), "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "route: displacement only (1 of 1 file(s) hold no forces" in printed
    warnings = [line[len("warning: "):] for line in printed.splitlines()
                if line.startswith("warning: ")]
    assert warnings == list(CAVEATS)
    data = json.loads(out.read_text())
    assert data["route"] == "displacement_only" and data["warnings"] == list(CAVEATS)
    assert data["flutter_speed_std"] is None
    assert data["flutter_derivatives"]["U"] == pytest.approx([4.0, 5.0, 6.0, 7.0, 8.0])
    # The route's known bias: fd_method's own doctest finds the flat plate within 5 % from
    # five noise-free speeds 4-8 m/s; with 0.2 % noise, 10 %.
    truth = flutter.analyze(CONFIG.section, TRUTH).speed
    assert data["flutter_speed"] == pytest.approx(truth, rel=0.10)


def test_e2rfc_refuses_a_file_without_forces_in_one_line(no_taps, capsys):
    assert main(["identify", str(no_taps), "--route", "e2rfc"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds no forces" in err[0] and "--route displacement" in err[0]


def test_the_displacement_route_needs_three_wind_speeds(two_speeds, capsys):
    with_rows, _ = two_speeds
    assert main(["identify", str(with_rows), "--route", "displacement"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "2 wind speed(s)" in err[0]
