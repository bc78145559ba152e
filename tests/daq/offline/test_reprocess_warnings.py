"""``windrig reprocess`` says what it warns of: on the terminal, in ``summary.json``, in the report.

Two files written with h5py alone (docs/reference/file_format.md's smallest run file,
``support.run_files.write_smallest_run``), as another program would: ``a.h5`` as written
(releases at 5 and 8 m/s), and ``b.h5`` whose config has ``fh = 2.1`` (a slip: the same flat
plate), whose air density column is all NaN and which keeps only the 8 m/s release. Files are
grouped by their stored section, so ``b.h5`` is a campaign of its own that E2RFC cannot
identify (one wind speed). Before: the terminal and ``summary.json`` carried no warning at all
(E2RFC's warnings stayed inside the campaign's task), so neither the slip nor the default air
density was said.
"""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from daq.cli import main

from support.run_files import write_smallest_run

pytestmark = pytest.mark.realtime  # a local Dask cluster: worker processes over sockets


def test_reprocess_prints_and_writes_every_campaigns_warnings(tmp_path, capsys):
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    write_smallest_run(a)
    write_smallest_run(b)
    with h5py.File(b, "r+") as f:
        text = f["entry/config"][()].decode()
        del f["entry/config"]
        f["entry/config"] = text.replace("fh = 2.0", "fh = 2.1")
        f["entry/sync/rho"][...] = np.nan
        table = f["entry/releases"][()]
        del f["entry/releases"]
        f["entry/releases"] = table[1:]
    out = tmp_path / "out"
    assert main(["reprocess", str(a), str(b), "--out", str(out), "--workers", "1",
                 "--no-progress", "--set", "diagnose=false"]) == 0
    said = capsys.readouterr().out.splitlines()
    near = ("campaign_2: its files' section differs from campaign_1's only in fh = 2.1 against "
            "2: one section model with a slip in one file's config?")
    rho = (f"campaign_2: {b}: /entry/sync/rho holds no air density (all NaN): the default "
           "1.225 kg/m^3 is used")
    assert any(line.startswith(f"warning: {near}") for line in said), said
    assert any(line.startswith(f"warning: {rho}") for line in said), said
    # The campaign E2RFC could not identify keeps its files' warnings, and E2RFC's own
    # warnings of the other campaign (its flutter speed is extrapolated) are printed too.
    assert any(line.startswith("campaign_2: 1 file(s): RankDeficiencyError") for line in said)
    assert any(line.startswith("warning: campaign_1: the flutter speed is extrapolated")
               for line in said), said

    summary = json.loads((out / "summary.json").read_text())
    assert summary["warnings"][0].startswith("campaign_1: ")  # in campaign order
    assert any(w.startswith(near) for w in summary["warnings"])
    assert any(w.startswith(rho) for w in summary["warnings"])
    first, second = summary["campaigns"]
    assert all(f"{first['campaign']}: {w}" in summary["warnings"] for w in first["warnings"])
    assert second["warnings"][0].startswith(near.removeprefix("campaign_2: "))
    assert second["warnings"][1].startswith(rho.removeprefix("campaign_2: "))
    assert "fh = 2.1 against 2" in (out / "index.html").read_text()
