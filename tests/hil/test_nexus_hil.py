"""A recorded run is valid NeXus and a netCDF-4 reader sees ``time`` as its coordinate (issue 17).

One real run: ``windrig acquire --simulate`` on ``rig_configs/sim_flat_plate.toml`` for 2.5 s
(the simulated instruments over loopback, the production recorder). Then:

- xarray with the h5netcdf engine opens ``/entry/sync``: every column's dimension is ``time``
  (a coordinate, the run's time), ``pressure`` is (time, tap), and units come along;
- nexusformat's ``nxcheck`` reports no error, and its ``plottable_data`` is ``/entry/sync``
  (the default plot silx follows too);
- ``punx validate`` is not run here: it needs PyQt5, which must not share a venv with the
  PySide6 console; ``benchmarks/nexus_validation.py`` runs it from a venv of its own.

Measured (2026-11, punx 0.3.5 with NeXus definitions v2018.5, nexusformat 2.1.0): before issue
17 punx gave 16 ERROR and 146 WARN and nxcheck 0 errors and 8 warnings; now punx 0 ERROR, 0 WARN
(1 NOTE: the name ``U``) and nxcheck 0 errors and 8 warnings (windrig's own attributes of
``/`` and ``/entry`` and its ``config``, ``releases`` and ``events`` fields, which NeXus allows
but does not define).
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import nexusformat.nexus as nexus
import numpy as np
import pytest
import xarray as xr

from support.configs import REPO, SIM_FLAT_PLATE

CONFIG = SIM_FLAT_PLATE

pytestmark = [pytest.mark.slow, pytest.mark.realtime]


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("nexus") / "run.h5"
    done = subprocess.run([sys.executable, "-m", "daq.cli", "acquire", "--config", str(CONFIG),
                           "--simulate", "--duration", "2.5", "--out", str(path)], cwd=REPO,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return path


def test_xarray_sees_time_as_the_coordinate_of_the_sync_view(run):
    with xr.open_dataset(run, engine="h5netcdf", group="entry/sync", phony_dims="access") as ds:
        assert set(ds.coords) == {"time", "tap"}
        for name in ("h", "alpha", "lift", "moment", "U", "rho"):
            assert ds[name].dims == ("time",), name
        assert ds["pressure"].dims == ("time", "tap") and ds.sizes["tap"] == 62
        assert ds["tap"].values[0] == "tap000"
        t = ds["time"].values
        assert t.size > 1000 and np.allclose(np.diff(t), 1 / 500.0)
        assert ds["h"].attrs["units"] == "m" and ds["time"].attrs["units"] == "s"
        assert float(ds["h"].sel(time=1.0, method="nearest")) == pytest.approx(
            float(ds["h"].values[500]), abs=0)


def test_nxcheck_finds_no_error_and_the_default_plot(run):
    nxcheck = Path(sys.executable).with_name("nxcheck")
    done = subprocess.run([str(nxcheck), str(run)], capture_output=True, text=True, timeout=300)
    text = re.sub(r"\x1b\[[0-9;]*m", "", done.stdout + done.stderr)
    assert "Total number of errors: 0" in text, text[-3000:]
    warnings = int(re.search(r"Total number of warnings: (\d+)", text).group(1))
    assert warnings <= 8, text  # windrig's own attributes and fields of / and /entry
    root = nexus.nxload(str(run))
    try:
        plot = root.plottable_data
        assert plot.nxpath == "/entry/sync" and plot.nxsignal.nxname == "h"
        assert [a.nxname for a in plot.nxaxes] == ["time"]
        laser = root["entry/instrument/laser_front"]
        assert laser.nxsignal.nxname == "value"
        assert [a.nxname for a in laser.nxaxes] == ["host_time_ns", "channel"]
    finally:
        root.nxfile.close()
