"""``windrig bridge --uncertainty`` on Dask: an existing scheduler's address, a local cluster.

The test starts a scheduler and two single-threaded worker processes on 127.0.0.1 itself
(``dask.distributed.LocalCluster``) and passes its address, as an engineer would a real
cluster's: the tasks reach the workers as pickles (the bridge model and chunks of sampled
models, no file path), so the distribution must equal the serial one from the same seed, to
the last digit. ``--workers 2`` (a local cluster the command starts) must too.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from daq.cli import main

from support.configs import BRIDGES
from support.identified import identified_flat_plate

pytestmark = pytest.mark.realtime

BRIDGE = BRIDGES / "example_bridge.json"
SAMPLES = "24"


def _run(tmp_path: Path, name: str, *extra: str) -> dict:
    aero = tmp_path / "identified.json"
    if not aero.exists():
        aero.write_text(json.dumps(identified_flat_plate()))
    out = tmp_path / f"{name}.json"
    assert main(["bridge", str(BRIDGE), "--aero", str(aero), "--uncertainty", "--samples",
                 SAMPLES, "--seed", "7", "--json", str(out), *extra]) == 0
    return json.loads(out.read_text())["uncertainty"]


def test_a_scheduler_address_and_a_local_cluster_give_the_serial_distribution(tmp_path):
    from dask.distributed import LocalCluster

    serial = _run(tmp_path, "serial")
    assert serial["executor"] == "serial"
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None, scheduler_kwargs={"dashboard": False}) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tcp://127.0.0.1:")
        remote = _run(tmp_path, "remote", "--scheduler", address)
    assert remote["executor"] == f"Dask scheduler {address}"
    assert remote["executor_rule"] == "asked for"
    assert remote["monte_carlo"] == serial["monte_carlo"]
    assert remote["delta_std"] == serial["delta_std"]
    local = _run(tmp_path, "local", "--workers", "2")
    assert local["executor"] == "local Dask cluster of 2 workers"
    assert local["monte_carlo"] == serial["monte_carlo"]
    assert "cluster_start" in local["wall_time_s"] and "cluster_start" not in serial[
        "wall_time_s"]
