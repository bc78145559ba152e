"""``windrig import`` of tap pressures and a Pitot: forces integrated on the rig config's taps.

A European lab's CSV (``;`` between cells, decimal commas, no time column: a sampling rate):
the 62 tap pressures of the flat-plate rig (``P1`` ... ``P62``, in hPa) that integrate to the
record's lift and moment (:meth:`ident.physics.taps.TapLayout.pressures_for`), the Pitot's
dynamic pressure with 1 Pa of seeded noise, heave and pitch; no forces. The map gives the
taps by prefix and the wind by the Pitot; the forces are integrated on import, the pressures
recorded in the sync view.
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from daq.cli import main

from support.lab_data import (
    CONFIG,
    SPEEDS,
    assert_identifies_to_truth,
    imported_deviation,
    lab_record,
)

MAP = """\
config = "sim_flat_plate"
taps = { prefix = "P", unit = "hPa" }
[time]
rate = 500.0
[channels]
h = { column = "h", unit = "m", sign = "down" }
alpha = { column = "alpha", unit = "rad", sign = "nose_up" }
[wind]
pitot = { column = "q", unit = "Pa" }
rho = 1.225
[releases]
times = [1.0, 9.5]
hold = 1.0
"""
PITOT_NOISE_PA = 1.0


def write_european_csv(path, k: int) -> None:
    """Write record k with tap pressures (hPa) and a Pitot, ``;`` and decimal commas."""
    r = lab_record(k)
    taps = CONFIG.taps.pressures_for(r.lift, r.moment) / 100.0  # Pa -> hPa
    q = 0.5 * r.rho * r.U**2 + np.random.default_rng(k).normal(0.0, PITOT_NOISE_PA, r.t.size)
    header = ["h", "alpha", "q"] + [f"P{i + 1}" for i in range(taps.shape[1])]
    rows = np.column_stack([r.h, r.alpha, q, taps])
    path.write_text(";".join(header) + "\n" + "\n".join(
        ";".join(f"{x:.10g}".replace(".", ",") for x in row) for row in rows) + "\n")


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    where = tmp_path_factory.mktemp("taps")
    (where / "map.toml").write_text(MAP)
    sources = []
    for k in range(len(SPEEDS)):
        sources.append(where / f"taps_{k}.csv")
        write_european_csv(sources[-1], k)
    assert main(["import", *map(str, sources), "--map", str(where / "map.toml"),
                 "--out", str(where / "runs"), "--json", str(where / "import.json")]) == 0
    return where


def test_the_taps_integrate_to_the_forces_and_the_pitot_gives_the_wind(imported):
    r = lab_record(0)
    run = imported / "runs" / "taps_0.h5"
    deviation = imported_deviation(run, r)
    # Ten significant digits of hPa, integrated over 62 taps: 1e-8 of each peak.
    assert max(deviation.values()) < 1e-8, deviation
    with h5py.File(run, "r") as f:
        pressure = f["entry/sync/pressure"][:]
        start = int(f["entry/releases"]["start_index"][0])
        U = f["entry/releases"]["U"][:]
    want = CONFIG.taps.pressures_for(r.lift, r.moment)[500]
    # Stored as float32 (the sync view's pressure dtype): 1e-6 of the largest tap pressure.
    assert pressure[start] == pytest.approx(want, abs=1e-6 * np.abs(want).max())
    # U from the mean dynamic pressure over each decay: 1 Pa of noise over ~3700 samples is
    # 0.02 Pa on 21 Pa, 0.04 % of U (three standard errors: 0.1 %).
    assert U == pytest.approx([SPEEDS[0]] * 2, rel=1e-3)


def test_the_imported_taps_identify_to_the_truth(imported):
    assert_identifies_to_truth(imported / "runs", "taps+pitot")
