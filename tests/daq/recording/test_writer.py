"""RunWriter fed synthetic StreamBlocks (no threads, no devices): the run file's contents."""

from __future__ import annotations

import math

import h5py
import numpy as np
import pytest

from daq.acquisition.records import Event, StreamBlock
from daq.config import parse_rig_config
from daq.instruments.reading import Gap
from daq.recording.writer import DEFAULT_RHO, RunWriter

from support.configs import SIM_FLAT_PLATE

T0_NS = 10_000_000_000
LASERS = {"laser_front": -0.1, "laser_rear": 0.1, "laser_check": 0.0}  # x, m (config)
STANDOFF = 0.025
LASER_OFFSET = 5.0       # laser device time at the run start, s
SCANNER_OFFSET = 1000.0  # scanner device time at the run start, s
RELEASE_S = 1.0
DURATION_S = 3.0
QD = 38.4                # Pitot dynamic pressure, Pa
RHO = 1.15               # the barometer's density


def truth(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Held at (4 mm, 0.02 rad) until the release, then a two-frequency decay."""
    tau = np.clip(t - RELEASE_S, 0.0, None)
    h = 0.004 * np.cos(2 * np.pi * 2.0 * tau) * np.exp(-0.1 * tau)
    alpha = 0.02 * np.cos(2 * np.pi * 4.0 * tau) * np.exp(-0.2 * tau)
    return h, alpha


def ns(t: np.ndarray) -> np.ndarray:
    return (T0_NS + np.round(np.asarray(t) * 1e9)).astype(np.int64)


@pytest.fixture(scope="module")
def config():
    return parse_rig_config(SIM_FLAT_PLATE.read_text(), "sim_flat_plate.toml")


def start_doc() -> dict:
    laser = {"distance": {"shape": []}, "error_code": {"shape": []}}
    return {"host_time_ns": T0_NS, "devices": {
        "scanner": {"kind": "scanner", "describe": {}},
        **{name: {"kind": "laser", "describe": laser} for name in LASERS},
        "barometer": {"kind": "barometer", "describe": {
            "pressure": {"units": "Pa", "shape": ()}, "temperature": {"units": "K", "shape": ()},
            "density": {"units": "kg/m^3", "shape": ()}}},
    }}


def synthetic_docs(config, tap_pressure: np.ndarray,
                   latency=lambda t: 0.0) -> list[tuple[str, object]]:
    """Blocks of 3 lasers (4 kHz, 40 ms blocks), the scanner (500 Hz, 20 ms), a barometer.

    ``latency(t)``: arrival delay of a block whose last sample was taken at ``t``, s.
    """
    items: list[tuple[float, str, object]] = []
    seq: dict[str, int] = {}

    def block(device, kind, t, device_time, counter, values, gaps=()):
        seq[device] = seq.get(device, -1) + 1
        # Arrival exactly when the last sample was taken: the clock maps are then exact.
        host = np.full(t.size, ns(t[-1:] + latency(float(t[-1])))[0], dtype=np.int64)
        items.append((float(t[-1]), "block", StreamBlock(
            device=device, kind=kind, seq=seq[device], host_time_ns=host,
            device_time=device_time, counter=counter, values=values, gaps=gaps)))

    t_laser = np.arange(0.0, DURATION_S, 1 / 4000.0)
    h, alpha = truth(t_laser)
    for name, x in LASERS.items():
        d = STANDOFF + h + x * alpha
        counter = np.arange(t_laser.size, dtype=np.int64)
        triggered = np.zeros(t_laser.size, bool)
        for lo in range(0, t_laser.size, 160):
            sl = slice(lo, lo + 160)
            gaps = ((Gap(int(counter[lo]) - 1, 0),) if (name == "laser_check" and lo == 1600)
                    else ())
            block(name, "laser", t_laser[sl], t_laser[sl] + LASER_OFFSET, counter[sl],
                  {"distance": d[sl], "error_code": np.zeros(160, np.int32),
                   "triggered": triggered[sl]}, gaps)
    t_scan = np.arange(0.0, DURATION_S, 1 / 500.0)
    n_ch = 64
    pressure = np.zeros((t_scan.size, n_ch))
    pressure[:, :config.taps.n_taps] = tap_pressure
    pressure[:, 63] = QD
    for lo in range(0, t_scan.size, 10):
        sl = slice(lo, lo + 10)
        block("scanner", "scanner", t_scan[sl], t_scan[sl] + SCANNER_OFFSET,
              np.arange(lo, lo + t_scan[sl].size, dtype=np.int64) + 1,
              {"pressure": pressure[sl], "pitot": pressure[sl, 63],
               "trigger_time": np.full(t_scan[sl].size, np.nan)})
    for k, t in enumerate((0.5, 1.5, 2.5)):
        block("barometer", "barometer", np.array([t]), None, np.array([k + 1]),
              {"pressure": np.array([99000.0]), "temperature": np.array([300.0]),
               "density": np.array([RHO])})
    items.append((RELEASE_S + 1e-3, "event", Event(
        kind="release", host_time_ns=int(ns(np.array([RELEASE_S]))[0]), device="plc",
        text="model released", data={"command_ns": int(ns(np.array([RELEASE_S]))[0])})))
    items.append((0.2, "event", Event(kind="note", host_time_ns=int(ns(np.array([0.2]))[0]),
                                      text="operator note")))
    items.sort(key=lambda item: item[0])
    return [("start", start_doc()), *[(n, d) for _, n, d in items],
            ("stop", {"reason": "duration", "duration_s": DURATION_S})]


@pytest.fixture(scope="module", params=[0.0, 10.0], ids=["write-every-block", "batched"])
def run(request, config, tmp_path_factory):
    rng = np.random.default_rng(3)
    tap_pressure = rng.normal(0.0, 20.0, config.taps.n_taps)
    path = tmp_path_factory.mktemp("run") / "run.h5"
    writer = RunWriter(path, config, operator_notes="synthetic",
                       write_interval_s=request.param)
    for name, doc in synthetic_docs(config, tap_pressure):
        writer(name, doc)
    assert writer.error is None
    return path, writer, tap_pressure


def test_raw_streams_hold_every_sample_with_their_clocks(run):
    path, writer, tap_pressure = run
    with h5py.File(path, "r") as f:
        laser = f["entry/instrument/laser_front"]
        n = int(DURATION_S * 4000)
        assert laser["value"].shape == (n, 1) and laser["counter"][-1] == n - 1
        t = np.arange(n) / 4000.0
        h, alpha = truth(t)
        np.testing.assert_allclose(laser["value"][:, 0], STANDOFF + h - 0.1 * alpha, atol=1e-12)
        np.testing.assert_allclose(laser["device_time"][:], t + LASER_OFFSET)
        assert laser["triggered"].dtype == bool and laser["error_code"].shape == (n,)
        assert list(laser.attrs["channel_names"]) == ["distance"]
        # A zero-length restart gap is recorded as unknown length (-1).
        gaps = f["entry/instrument/laser_check/gaps"][:]
        assert gaps.tolist() == [(1599, -1)]
        scanner = f["entry/instrument/scanner"]
        assert scanner["value"].shape == (1500, 63)  # 62 taps + pitot
        np.testing.assert_allclose(scanner["value"][5, :62], tap_pressure, rtol=1e-6, atol=1e-5)
        np.testing.assert_allclose(scanner["value"][:, 62], QD, rtol=1e-6)
        assert np.all(np.isnan(scanner["trigger_time"][:]))
        baro = f["entry/instrument/barometer"]
        assert np.all(np.isnan(baro["device_time"][:]))
        assert baro["value"][:, 2].tolist() == [RHO] * 3
    assert writer.summary is not None
    assert writer.summary["samples"]["laser_rear"] == 12000
    assert writer.summary["samples"]["scanner"] == 1500


def test_sync_view_has_the_known_motion_forces_and_wind(run, config):
    path, writer, tap_pressure = run
    with h5py.File(path, "r") as f:
        sync = f["entry/sync"]
        t = sync["time"][:]
        h, alpha = sync["h"][:], sync["alpha"][:]
        U, rho = sync["U"][:], sync["rho"][:]
        lift, moment = sync["lift"][:], sync["moment"][:]
        pressure = sync["pressure"][:]
        attrs = dict(sync.attrs)
    assert t.size >= 1490
    np.testing.assert_allclose(np.diff(t), 1 / 500.0, rtol=1e-9)
    assert t[0] == 0.0  # s from run start
    ok = np.isfinite(h)
    assert ok.sum() > 0.98 * t.size
    h_true, alpha_true = truth(t[ok])
    # Boxcar over 2 ms of a 4 Hz motion: gain loss (pi f W)^2 / 6 ~ 1e-4; plus the kink at
    # the release.
    assert np.max(np.abs(h[ok] - h_true)) < 2e-6
    assert np.max(np.abs(alpha[ok] - alpha_true)) < 2e-5
    lift_true, moment_true = config.taps.integrate(tap_pressure[None, :])
    good = np.isfinite(lift)
    assert good.sum() > 0.98 * t.size
    np.testing.assert_allclose(lift[good], lift_true[0], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(moment[good], moment_true[0], rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(pressure[good][:, :3], np.broadcast_to(tap_pressure[:3], (
        good.sum(), 3)), rtol=1e-5, atol=1e-4)
    # rho: the default before the first barometer reading (t = 0.5 s in data time; the sync
    # rows written before that block arrived), the barometer's afterwards.
    assert set(np.unique(rho)) <= {DEFAULT_RHO, RHO} and rho[-1] == RHO
    late = np.isfinite(U) & (rho == RHO)
    np.testing.assert_allclose(U[late], math.sqrt(2 * QD / RHO), rtol=1e-6)
    assert math.isclose(attrs["clock_offset_s__laser_front"], LASER_OFFSET, abs_tol=1e-6)
    assert math.isclose(attrs["clock_offset_s__scanner"], SCANNER_OFFSET, abs_tol=1e-6)
    assert abs(attrs["clock_drift_ppm__laser_rear"]) < 1e-3


def test_release_row_and_events(run):
    path, writer, _ = run
    with h5py.File(path, "r") as f:
        releases = f["entry/releases"][:]
        events = f["entry/events"][:]
        n_sync = f["entry/sync/time"].shape[0]
        t = f["entry/sync/time"][:]
        summary = f["entry/metadata/acquisition_summary"]
        assert summary["samples/scanner"][()] == 1500
    assert releases.shape == (1,)
    (row,) = releases
    assert math.isclose(row["release_time"], RELEASE_S, abs_tol=1e-9)
    assert row["start_index"] == int(np.searchsorted(t, RELEASE_S)) == 500
    assert row["stop_index"] == n_sync
    assert math.isclose(row["h0"], 0.004, rel_tol=1e-4)
    assert math.isclose(row["alpha0"], 0.02, rel_tol=1e-4)
    assert math.isclose(row["U"], math.sqrt(2 * QD / RHO), rel_tol=1e-6)
    kinds = [k.decode() for k in events["kind"]]
    # These docs have no PLC trigger pulse: the file says its clock maps had no anchor.
    assert kinds == ["note", "release", "warning"]
    assert b"command_ns" in events["text"][1]
    assert events["text"][2].decode().startswith("no PLC trigger pulse reached this file")
    assert events["time"][2] >= t[-1]  # at the file's end


def test_two_releases_split_the_decays(config, tmp_path):
    docs = synthetic_docs(config, np.zeros(config.taps.n_taps))
    second = Event(kind="release", host_time_ns=int(ns(np.array([2.0]))[0]), device="plc",
                   data={"command_ns": int(ns(np.array([2.0]))[0])})
    stop = docs.pop()
    index = next(i for i, (n, d) in enumerate(docs)
                 if n == "block" and d.device == "scanner" and d.device_time[0] > 1002.05)
    docs.insert(index, ("event", second))
    docs.append(stop)
    writer = RunWriter(tmp_path / "two.h5", config)
    for name, doc in docs:
        writer(name, doc)
    assert writer.error is None
    with h5py.File(tmp_path / "two.h5", "r") as f:
        rows = f["entry/releases"][:]
    assert rows["start_index"].tolist() == [500, 1000]
    assert rows["stop_index"][0] == 1000
    assert writer.summary is not None and writer.summary["releases"] == 2


def test_arm_event_ends_the_release_before_the_model_is_caught(config, tmp_path):
    docs = synthetic_docs(config, np.zeros(config.taps.n_taps))
    arm = Event(kind="arm", host_time_ns=int(ns(np.array([2.2]))[0]), device="plc")
    stop = docs.pop()
    index = next(i for i, (n, d) in enumerate(docs)
                 if n == "block" and d.device == "scanner" and d.device_time[0] > 1002.25)
    docs.insert(index, ("event", arm))
    docs.append(stop)
    writer = RunWriter(tmp_path / "arm.h5", config)
    for name, doc in docs:
        writer(name, doc)
    assert writer.error is None
    with h5py.File(tmp_path / "arm.h5", "r") as f:
        (row,) = f["entry/releases"][:]
        t = f["entry/sync/time"][:]
    # The decay ends one sync period before the arm command (a sync row averages the lasers
    # over +- half a period): its last row is the last one before 2.2 s - 2 ms.
    end = 2.2 - 1 / 500.0
    assert row["start_index"] == 500
    assert row["stop_index"] == int(np.searchsorted(t, end))
    assert t[row["stop_index"] - 1] < end <= t[row["stop_index"]] + 1e-9
    assert 2.19 < t[row["stop_index"] - 1]


def test_clock_map_refits_leave_no_gap_rows_in_the_sync_view(config, tmp_path):
    """Arrivals 3 ms late for 1.2 s, then on time: the maps jump by ~3 ms when they see it.

    Mapped block by block, the forward jump would open a 3 ms hole between two consecutive
    laser samples (a NaN row although nothing was lost); the continuous timeline slews it.
    """
    docs = synthetic_docs(config, np.zeros(config.taps.n_taps),
                          latency=lambda t: 3e-3 if t < 1.2 else 0.0)
    writer = RunWriter(tmp_path / "refit.h5", config)
    for name, doc in docs:
        writer(name, doc)
    assert writer.error is None
    with h5py.File(tmp_path / "refit.h5", "r") as f:
        t = f["entry/sync/time"][:]
        h = f["entry/sync/h"][:]
        lift = f["entry/sync/lift"][:]
    timelines = writer.summary["timelines"]
    assert timelines["laser_front"]["largest_slewed_s"] > 1e-3  # the refit did happen
    # Every row is finite but the first few (the first blocks, 3 ms late, are mapped 3 ms
    # late: the rows before them have no data, which is marked, not invented).
    assert np.all(np.isfinite(h[t > 0.01]))
    assert np.all(np.isfinite(lift[t > 0.01]))
    assert t[-1] > DURATION_S - 0.05


def test_existing_file_is_an_error_kept_by_the_writer(config, tmp_path):
    path = tmp_path / "exists.h5"
    path.write_bytes(b"")
    writer = RunWriter(path, config)
    writer("start", start_doc())  # a StorageError is kept (and logged), not raised
    assert isinstance(writer.error, OSError) and "exists" in str(writer.error)
    writer("stop", {})  # later docs are ignored


def test_cli_acquire_refuses_auto_urls_without_simulate(tmp_path, capsys):
    from daq.cli import main

    out = tmp_path / "never.h5"
    code = main(["acquire", "--config", str(SIM_FLAT_PLATE), "--duration", "1",
                 "--out", str(out)])
    assert code == 2 and not out.exists()
    assert "url = 'auto'" in capsys.readouterr().err


def test_record_run_refuses_an_existing_file_before_starting_anything(config, tmp_path):
    from daq.sim.recording import record_simulated_run

    path = tmp_path / "exists.h5"
    path.write_bytes(b"")
    with pytest.raises(OSError, match="already exists"):
        record_simulated_run(config, path, duration_s=1.0, progress=False)
