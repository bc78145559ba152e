"""A run file with pressure tubing: recorded, read back corrected by default, and identified."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.cli import main
from daq.config import RigConfig, load_rig_config, parse_rig_config
from daq.recording.synthetic import write_release_run
from ident.model import flat_plate, flutter
from ident.physics.air import R_DRY_AIR
from ident.physics.tubing import Air, Tube, distort, tubing_set
from ident.records.run_file import TUBING_TEMPERATURE_K, read_run
from simulators.campaigns import FRACTIONS, HOLDS, SECTION
from simulators.tunnel import simulate_release

from support.configs import SIM_FLAT_PLATE

SIM_CONFIG = SIM_FLAT_PLATE
#: Every tap on 1.5 m of 1 mm bore into 300 mm^3 (tests/ident/physics/test_tubing.py: 3.9 % off).
TUBES = """
[[taps.tubing]]
taps = "all"
length = 1.5
diameter = 1.0e-3
volume = 300e-9

"""


def _tubed_run(path: Path, config: RigConfig | None = None) -> float:
    """Write a campaign measured behind the tubes of :data:`TUBES`; return the flutter speed.

    ``config`` (default: the flat-plate rig with :data:`TUBES`) is the one the file records.
    """
    tubed = parse_rig_config(SIM_CONFIG.read_text().replace("[limits]", TUBES + "[limits]"))
    config = config or tubed
    taps, fs = config.taps, 500.0
    truth = flat_plate.jones_model()
    speed = flutter.analyze(SECTION, truth).speed
    assert speed is not None
    # The tubes' air as the reader assumes it: the run's density at 20 C.
    air = Air(pressure_pa=SECTION.rho * R_DRY_AIR * TUBING_TEMPERATURE_K,
              temperature_k=TUBING_TEMPERATURE_K)
    tubes = tubing_set(tubed.tubing, taps.n_taps, air)
    releases, pressures = [], []
    for fraction in FRACTIONS:
        for h0, alpha0 in HOLDS:
            sim = simulate_release(SECTION, truth, fraction * speed, h0, alpha0, duration=7.5,
                                   fs=fs, pre_s=1.0)
            measured = distort(sim.pressures(taps), fs, tubes)
            lift, moment = taps.integrate(measured)  # what the sync view records
            releases.append(dataclasses.replace(sim, lift=lift, moment=moment))
            pressures.append(measured)
    write_release_run(path, config, releases, pressures)
    return speed


@pytest.fixture(scope="module")
def tubed_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, float]:
    path = tmp_path_factory.mktemp("tubing") / "tubed.h5"
    return path, _tubed_run(path)


def test_the_run_file_records_the_tubing_of_its_taps(tubed_run):
    path, _ = tubed_run
    with h5py.File(path, "r") as f:
        group = f["entry/metadata/tubing/group_0"]
        assert group["kind"][()].decode() == "bergh_tijdeman"
        assert group["taps"][()].decode() == "all"
        assert group["length"][()] == 1.5 and group["volume"][()] == pytest.approx(300e-9)
    run = read_run(path)
    assert run.tubing is not None and run.tubing_corrected
    assert all(r.meta["file"] == str(path) for r in run.releases)


def test_identify_corrects_by_default_and_compares_without(tubed_run, tmp_path, capsys):
    """The flutter speed off by > 2 % as measured comes back within 0.5 % corrected.

    Noise-free records: the remaining error is the correction's, from the record's ends
    (the release's step response inside the first second of lead, the decay's end tapered).
    """
    path, truth = tubed_run
    corrected, measured = tmp_path / "corrected.json", tmp_path / "measured.json"
    assert main(["identify", str(path), "--json", str(corrected)]) == 0
    out = capsys.readouterr().out
    assert "forces corrected for the pressure tubing of 1 of 1 file(s)" in out
    assert main(["identify", str(path), "--no-tubing-correction", "--json", str(measured)]) == 0
    assert "forces NOT corrected for the pressure tubing" in capsys.readouterr().out
    good = json.loads(corrected.read_text())
    bad = json.loads(measured.read_text())
    assert abs(good["flutter_speed"] / truth - 1.0) < 0.005
    assert abs(bad["flutter_speed"] / truth - 1.0) > 0.02


def test_a_file_without_tubing_reads_as_before(tmp_path):
    config = parse_rig_config(SIM_CONFIG.read_text())
    sim = simulate_release(SECTION, flat_plate.jones_model(), 6.0, 0.004, 0.02, duration=4.0,
                           fs=200.0)
    write_release_run(tmp_path / "plain.h5", config, [sim])
    run = read_run(tmp_path / "plain.h5")
    assert run.tubing is None and not run.tubing_corrected
    np.testing.assert_array_equal(run.releases[0].lift, sim.lift)



def test_a_measured_table_is_recorded_and_corrects_like_the_tube_it_measured(tubed_run, tmp_path):
    """A table of the tube's own response (every 1 Hz to 250 Hz) in the config instead.

    The same records (behind the tube) in a file whose config gives the table: read back, the
    corrected forces agree with the tube's to 1e-3 of their range (the table is linear between
    rows, ~1e-4 in gain near 4 Hz; it reaches the sync view's Nyquist frequency, above the
    tube's cut-off, so both correct the same band).
    """
    path, _ = tubed_run
    air = Air(pressure_pa=SECTION.rho * R_DRY_AIR * TUBING_TEMPERATURE_K,
              temperature_k=TUBING_TEMPERATURE_K)
    f = np.arange(1.0, 251.0)
    H = Tube(length=1.5, diameter=1e-3, volume=300e-9).response(f, air)
    rows = "\n".join(f"{a:g},{float(abs(h))!r},{float(np.degrees(np.angle(h)))!r}"
                     for a, h in zip(f, H, strict=True))
    (tmp_path / "tube.csv").write_text("frequency,gain,phase_deg\n" + rows + "\n")
    config = tmp_path / "rig.toml"
    config.write_text(SIM_CONFIG.read_text().replace(
        "[limits]", '[[taps.tubing]]\ntaps = "all"\ntable = "tube.csv"\n\n[limits]'))
    table_file = tmp_path / "table.h5"
    _tubed_run(table_file, load_rig_config(config))
    by_table, by_tube = read_run(table_file), read_run(path)
    assert by_table.tubing is not None
    assert by_table.tubing.groups[0].model.describe()["kind"] == "table"
    for a, b in zip(by_table.releases, by_tube.releases, strict=True):
        np.testing.assert_allclose(a.lift, b.lift, atol=1e-3 * float(np.ptp(b.lift)))
        np.testing.assert_allclose(a.moment, b.moment, atol=1e-3 * float(np.ptp(b.moment)))


def test_the_tubes_air_has_the_barometers_temperature(tubed_run, tmp_path):
    """A file whose barometer read 5 C: the tubes' air is at 5 C (median of the valid readings).

    The barometer group is added by hand in the layout's form (channel_names attribute, value
    columns); one reading of a disconnected probe (-999 K) and a NaN are not used. The
    correction then differs from the 20 C one: the tube's response depends on the air's
    viscosity and speed of sound, so the corrected forces move (by ~1e-3 of their range).
    """
    path, _ = tubed_run
    copy = tmp_path / "cold.h5"
    copy.write_bytes(path.read_bytes())
    temperatures = [278.0, 278.15, 278.3, -999.0, np.nan]
    with h5py.File(copy, "a") as f:
        group = f.require_group("entry/instrument").create_group("baro")
        group.attrs["channel_names"] = np.array(
            [b"pressure", b"temperature", b"density", b"relative_humidity"])
        group["value"] = np.array([[1.0e5, T, 1.2, np.nan] for T in temperatures])
    cold, warm = read_run(copy), read_run(path)
    assert cold.tubing is not None and warm.tubing is not None
    assert cold.tubing.air.temperature_k == pytest.approx(278.15)
    assert warm.tubing.air.temperature_k == pytest.approx(TUBING_TEMPERATURE_K)
    # Same density either way (the run's measured one): only the temperature moved.
    assert cold.tubing.air.density == pytest.approx(warm.tubing.air.density)
    moved = max(float(np.max(np.abs(a.lift - b.lift))) / float(np.ptp(b.lift))
                for a, b in zip(cold.releases, warm.releases, strict=True))
    assert moved > 5e-4, moved  # 1.5e-3 measured: 15 K colder air; float noise is ~1e-12
