"""Reading run files: releases and section come back as written; bad files fail clearly."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from ident.records.run_file import FileFormatError, read_run

from support.run_files import write_run
from support.sections import FLAT_PLATE


def test_releases_and_section_round_trip(tmp_path):
    """Every release comes back with time from its release instant and the measured U and rho."""
    path = tmp_path / "run.h5"
    sims = write_run(path)
    run = read_run(path)
    assert run.rig_name == "test" and len(run.releases) == 2
    assert run.depth == 0.01  # [section] depth of the stored config, m
    assert run.section.B == 0.3 and run.section.rho == pytest.approx(FLAT_PLATE.rho)
    for release, sim in zip(run.releases, sims, strict=True):
        after = sim.t >= 0
        np.testing.assert_allclose(release.t, sim.t[after], atol=1e-9)
        np.testing.assert_allclose(release.alpha, sim.alpha[after])
        assert release.U == sim.U and release.meta["file"] == str(path)


def test_a_gap_inside_a_release_is_refused_by_name(tmp_path):
    """A NaN in a release's rows is an error naming release and channel, never interpolated."""
    path = tmp_path / "gap.h5"
    write_run(path, gap=True)
    with pytest.raises(FileFormatError, match="release 1 has 1 gap sample"):
        read_run(path)


@pytest.mark.parametrize("gap_row, gap_s", [(600, 2.5), (300, None)])
def test_a_campaign_reads_a_release_with_a_gap_cut_before_it_or_leaves_it_out(
        tmp_path, gap_row, gap_s):
    """``cut_at_gaps``: a release ends before its first NaN row, or is left out.

    Left out when less than 3 periods of the slower mode (2 Hz: 1.5 s) remain; the other
    release is untouched, the cut is said, nothing is filled.
    """
    path = tmp_path / "gap.h5"
    sims = write_run(path, gap=True, gap_row=gap_row)
    run = read_run(path, cut_at_gaps=True)
    first = run.releases[0]
    np.testing.assert_allclose(first.alpha, sims[0].alpha[sims[0].t >= 0])
    if gap_s is None:
        assert len(run.releases) == 1
        assert run.cuts == ("release 1 left out: a gap 1.00 s after its release (less than 3 "
                            "periods, 1.50 s)",)
        return
    assert len(run.releases) == 2
    cut = run.releases[1]
    # Rows up to the one before the gap (0.005 s at 200 Hz), all finite, values as written.
    assert cut.t[-1] == pytest.approx(gap_s - 0.005, abs=1e-9)
    assert np.all(np.isfinite(cut.h))
    np.testing.assert_allclose(cut.h, sims[1].h[100:gap_row])
    assert run.cuts == ("release 1 cut before a gap 2.50 s after its release",)
    with pytest.raises(FileFormatError, match="release 1 has 1 gap sample"):
        read_run(path)  # the default: refused, as before


def test_not_hdf5_truncated_and_incomplete_files_fail_clearly(tmp_path):
    """Garbage, a truncated copy and a file without the layout: FileFormatError (ValueError)."""
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not an HDF5 file at all")
    with pytest.raises(FileFormatError, match="junk.h5: not an HDF5 file"):
        read_run(junk)
    with pytest.raises(FileFormatError, match="nothing.h5: no such file"):
        read_run(tmp_path / "nothing.h5")
    good = tmp_path / "good.h5"
    write_run(good)
    truncated = tmp_path / "truncated.h5"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 3])
    with pytest.raises(FileFormatError):
        read_run(truncated)
    empty = tmp_path / "empty.h5"
    with h5py.File(empty, "w") as f:
        f.create_group("entry")
    with pytest.raises(FileFormatError, match=r"has no /entry/config: not a windrig run file"):
        read_run(empty)
