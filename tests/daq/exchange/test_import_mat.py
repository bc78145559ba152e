"""``windrig import`` of MATLAB files, v5 (scipy.io) and v7.3 (HDF5), identified to the truth.

Each wind speed's record (:mod:`support.lab_data`) as a MATLAB user saves it: a struct ``test``
with column vectors (time in s, heave in mm, the rest SI per unit span, windrig's signs) and
the wind speed and air density as scalars. The v5 files are written by
:func:`scipy.io.savemat`; the v7.3 files by h5py in MATLAB's layout (a 512-byte header, arrays
transposed, ``MATLAB_class`` attributes, text as uint16), which scipy cannot read. The v5
releases are listed; the v7.3 ones are found in h and alpha.
"""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from daq.cli import main

from support.lab_data import (
    MAP_V5,
    SPEEDS,
    assert_identifies_to_truth,
    imported_deviation,
    lab_record,
    mat_fields,
    write_mat_v5,
)

#: The same map, the releases found in the signals.
MAP_V73 = MAP_V5.replace("times = [1.0, 9.5]", "detect = true")

#: MATLAB's v7.3 header: text in the HDF5 user block, which MATLAB checks.
MAT73_HEADER = (b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Sun Nov 29 10:00:00 2026 "
                b"HDF5 schema 1.00 .")


def write_mat_v73(path, k: int) -> None:
    """Write record k as MATLAB v7.3 does: HDF5, arrays transposed, classes as attributes."""
    r = lab_record(k)
    with h5py.File(path, "w", userblock_size=512) as f:
        test = f.create_group("test")
        test.attrs["MATLAB_class"] = np.bytes_("struct")
        for name, x in mat_fields(k).items():  # an n x 1 column is stored 1 x n
            test.create_dataset(name, data=x[None, :]).attrs["MATLAB_class"] = np.bytes_("double")
        for name, x in (("U", r.U), ("rho", r.rho)):
            f.create_dataset(name, data=np.array([[x]])).attrs["MATLAB_class"] = \
                np.bytes_("double")
        text = np.array([[ord(c)] for c in "lab"], dtype=np.uint16)
        f.create_dataset("operator", data=text).attrs["MATLAB_class"] = np.bytes_("char")
    with open(path, "r+b") as f:
        f.write(MAT73_HEADER.ljust(116) + b"\x00" * 8 + b"\x00\x02IM")


@pytest.fixture(scope="module", params=["v5", "v7.3"])
def imported(request, tmp_path_factory):
    version = request.param
    where = tmp_path_factory.mktemp(f"mat_{version}")
    (where / "map.toml").write_text(MAP_V5 if version == "v5" else MAP_V73)
    write = write_mat_v5 if version == "v5" else write_mat_v73
    sources = []
    for k in range(len(SPEEDS)):
        sources.append(where / f"run_{k}.mat")
        write(sources[-1], k)
    assert main(["import", *map(str, sources), "--map", str(where / "map.toml"),
                 "--out", str(where / "runs"), "--json", str(where / "import.json")]) == 0
    return version, where


def test_the_mat_file_arrives_in_si(imported):
    version, where = imported
    r = lab_record(2)
    with h5py.File(where / "runs" / "run_2.h5", "r") as f:
        assert f["entry/metadata/import/format"][()].decode() == "mat"
        U = f["entry/sync/U"][:]
        rows = f["entry/releases"][:]
    # The decays are the record's samples (float64 throughout, both versions).
    assert max(imported_deviation(where / "runs" / "run_2.h5", r).values()) < 1e-12
    assert U == pytest.approx(SPEEDS[2], rel=1e-12)
    report = json.loads((where / "import.json").read_text())
    found = report["files"][2]["release_times_s"]
    if version == "v5":  # listed: the record's own samples, float64 throughout
        assert found == [1.0, 9.5]
    else:
        # Found in the signals: ident.records.release_onset's 0.1 ms rms at this noise (its
        # docstring); 1 ms allowed. Each row starts at the next sample and each hold at the
        # first sample 1 s before the instant: one more sampling interval (2 ms) either way.
        assert found == pytest.approx([1.0, 9.5], abs=1e-3)
        assert rows["release_time"] == pytest.approx([1.0, 9.48], abs=1e-3 + 2e-3)
    assert report["warnings"] == []


def test_the_imported_mat_identifies_to_the_truth(imported):
    version, where = imported
    assert_identifies_to_truth(where / "runs", f"mat {version}")


@pytest.mark.parametrize("imported", ["v5"], indirect=True)  # v7.3's are the same samples
def test_diagnose_reads_the_imported_files_and_finds_no_effect(imported, capsys):
    _, where = imported
    out = where / "diagnosis.json"
    assert main(["diagnose", *map(str, sorted((where / "runs").glob("*.h5"))),
                 "--out", str(where / "diagnosis"), "--json", str(out)]) == 0
    capsys.readouterr()
    # The simulated campaign has no named effect (linear Roger aerodynamics, a linear
    # structure): the discrepancy workflow must choose none.
    assert json.loads(out.read_text())["effect"] is None
