"""``/entry/calibration`` is NXparameters (issue 37); files with its old NXcollection read the same.

punx warned on every member of the NXcollection the calibrations were written as (14 WARN on
a simulated run, ``benchmarks/nexus_validation.py``); as NXparameters, the class of
``/entry/metadata`` too, it gives none. Readers find the calibrations by name, so a file of
issues 18 to 36 (NXcollection) must read exactly as a new one: the same dead taps left out of
the tubing correction (``ident.records.run_file``), the same ``windrig info`` and the same
export.
"""

from __future__ import annotations

import shutil

import h5py
import numpy as np

from daq.config import parse_rig_config
from daq.exchange.export_contents import read_contents
from daq.recording.info import run_info
from daq.recording.synthetic import write_release_run
from ident.model import flat_plate
from ident.records.run_file import read_run
from simulators.campaigns import SECTION
from simulators.tunnel import simulate_release

from support.configs import SIM_FLAT_PLATE

TAPS_LINE = "taps_per_face = 28          # 2 x 28 on the faces + 2 x 3 on the edges = 62 taps\n"
TUBES = '\n[[taps.tubing]]\ntaps = "all"\nlength = 1.0\ndiameter = 1.0e-3\nvolume = 300e-9\n\n'


def _files(tmp_path):
    text = SIM_FLAT_PLATE.read_text().replace("[limits]", TUBES + "[limits]")
    text = text.replace(TAPS_LINE, TAPS_LINE + "dead = [10, 45]\n")
    config = parse_rig_config(text, "dead.toml")
    sim = simulate_release(SECTION, flat_plate.jones_model(), 6.0, 0.004, 0.02, duration=2.0,
                           fs=200.0, pre_s=0.5)
    pressures = np.random.default_rng(18).normal(0.0, 5.0, (sim.t.size, config.taps.n_taps))
    new = tmp_path / "new.h5"
    write_release_run(new, config, [sim], [pressures])
    old = tmp_path / "old.h5"
    shutil.copy(new, old)
    with h5py.File(old, "a") as f:  # the layout of issues 18 to 36
        f["entry/calibration"].attrs["NX_class"] = "NXcollection"
        for group in f["entry/calibration"].values():
            group.attrs["NX_class"] = "NXcollection"
    return new, old


def test_calibrations_are_nxparameters_and_old_files_read_the_same(tmp_path):
    new, old = _files(tmp_path)
    with h5py.File(new, "r") as f:
        cal = f["entry/calibration"]
        assert cal.attrs["NX_class"] == "NXparameters"
        assert {name: g.attrs["NX_class"] for name, g in cal.items()} == {
            "taps": "NXparameters", "pitot": "NXparameters", "air": "NXparameters"}
        assert cal["taps"].attrs["configured"] == "yes"  # the group's own attributes kept
        np.testing.assert_array_equal(cal["taps/dead"][()], [10, 45])
    # The tubing correction leaves the dead taps out: identical forces from both layouts.
    a, b = read_run(new), read_run(old)
    assert a.tubing_corrected and b.tubing_corrected
    np.testing.assert_array_equal(a.releases[0].lift, b.releases[0].lift)
    np.testing.assert_array_equal(a.releases[0].moment, b.releases[0].moment)
    info_new, info_old = run_info(new), run_info(old)
    assert info_new["calibrations"] == info_old["calibrations"]
    assert info_new["calibrations"]["taps"]["values"]["dead"] == [10, 45]
    exported = [read_contents(p).calibrations for p in (new, old)]
    assert exported[0].keys() == exported[1].keys() == {"taps", "pitot", "air"}
    np.testing.assert_array_equal(exported[1]["taps"]["values"]["dead"], [10, 45])
