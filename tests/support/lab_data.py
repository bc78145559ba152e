"""A lab's records of known truth, for the import tests: simulated flat-plate free decays.

The flat-plate rig (``rig_configs/sim_flat_plate.toml``: B = 0.3 m, fh = 2 Hz, fa = 4 Hz) with
R. T. Jones's aerodynamics (:func:`ident.model.flat_plate.jones_model`, flutter at
:data:`TRUTH_SPEED`), released at three wind speeds (0.5, 0.65 and 0.8 of it, as the demo),
twice per speed (from 8 mm and 0.04 rad, then from 6 mm and 0.03 rad), by
:func:`simulators.tunnel.simulate_release` (:func:`ident.simulation.decay.simulate_decay`, plus
its hold and seeded noise). Each speed is one continuous record as a data logger writes it:
:data:`HOLD_S` held, the release, :data:`DECAY_S` of decay, held again, the second release,
with a magnet current that drops at each release. The tests write these arrays in a lab's
units and layouts (CSV, MATLAB, TDMS), import them, and identify.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
from scipy.io import savemat

from daq.cli import main
from daq.config import parse_rig_config
from ident.model import flat_plate, flutter
from simulators.tunnel import simulate_release

from support.configs import SIM_FLAT_PLATE

FloatArray = npt.NDArray[np.float64]

CONFIG = parse_rig_config(SIM_FLAT_PLATE.read_text(), "sim_flat_plate.toml")
SECTION = CONFIG.section
TRUTH = flat_plate.jones_model()
#: The truth's flutter speed, m/s (state space, 11.75 m/s).
TRUTH_SPEED = flutter.analyze(SECTION, TRUTH).speed
#: Wind speeds of the releases, m/s: 0.5, 0.65 and 0.8 of the flutter speed.
SPEEDS = tuple(round(f * TRUTH_SPEED, 2) for f in (0.5, 0.65, 0.8))
FS = 500.0  # Hz
HOLD_S = 1.0  # s held before each release
DECAY_S = 7.5  # s of decay after each
HOLDS = ((0.008, 0.04), (0.006, 0.03))  # m, rad
#: Measurement noise, fraction of each channel's RMS (as tests/daq/offline's identify tests).
NOISE = {"h": 0.002, "alpha": 0.002, "lift": 0.01, "moment": 0.01}
MAGNET_ON = 5.0  # V across the magnet while it holds


@dataclass(frozen=True)
class LabRecord:
    """One wind speed's continuous record, SI and windrig's signs.

    Attributes
    ----------
    t : ndarray
        s from the record's start (uniform, 1 / FS).
    h, alpha, lift, moment : ndarray
        m (down), rad (nose-up), N/m (down), N m/m (nose-up).
    magnet : ndarray
        V, MAGNET_ON while held, 0 from each release on.
    U, rho : float
        m/s, kg/m^3.
    releases : tuple of float
        The release instants, s.
    """

    t: FloatArray
    h: FloatArray
    alpha: FloatArray
    lift: FloatArray
    moment: FloatArray
    magnet: FloatArray
    U: float
    rho: float
    releases: tuple[float, ...]


@functools.cache
def lab_record(k: int) -> LabRecord:
    """Return the record at ``SPEEDS[k]`` (seeded: the same arrays every call)."""
    U = SPEEDS[k]
    parts = [simulate_release(SECTION, TRUTH, U, h0, a0, duration=DECAY_S, fs=FS,
                              pre_s=HOLD_S, noise=NOISE, rng=100 * k + j)
             for j, (h0, a0) in enumerate(HOLDS)]
    n = sum(p.t.size for p in parts)
    t = np.arange(n) / FS
    starts = np.cumsum([0] + [p.t.size for p in parts[:-1]])
    releases = tuple(float(t[s + np.searchsorted(p.t, 0.0)]) for s, p in zip(starts, parts,
                                                                               strict=True))
    magnet = np.concatenate([np.where(p.t < 0.0, MAGNET_ON, 0.0) for p in parts])
    return LabRecord(t=t, **{c: np.concatenate([getattr(p, c) for p in parts])
                             for c in ("h", "alpha", "lift", "moment")},
                     magnet=magnet, U=U, rho=SECTION.rho, releases=releases)


def imported_deviation(path: object, record: LabRecord) -> dict[str, float]:
    """Return how far an imported run file's decays lie from the record, per channel.

    Each release row of the file (read by h5py) is matched to the record's sample at its
    release instant; its rows up to ``stop_index`` are compared with the record's from there.

    Returns
    -------
    dict
        Channel (``h``, ``alpha``, ``lift``, ``moment``) -> the largest absolute difference
        over every decay, as a fraction of the channel's peak in the record.
    """
    import h5py  # only the tests that read run files back need it

    out = dict.fromkeys(("h", "alpha", "lift", "moment"), 0.0)
    with h5py.File(path, "r") as f:
        sync = f["entry/sync"]
        rows = f["entry/releases"][:]
        for name in out:
            x = sync[name][:]
            want = getattr(record, name)
            for row, instant in zip(rows, record.releases, strict=True):
                first = int(round(instant * FS))
                n = int(row["stop_index"] - row["start_index"])
                got = x[row["start_index"]:row["stop_index"]]
                worst = float(np.max(np.abs(got - want[first:first + n])))
                out[name] = max(out[name], worst / float(np.max(np.abs(want))))
    return out


#: The map of a lab record's columns by their own names (t, h, alpha, lift, moment, U: SI,
#: windrig's signs), one release listed at 1 s after a 1 s hold: the import tests' CSV layout.
MAP = """\
config = "sim_flat_plate"
[time]
column = "t"
unit = "s"
[channels]
h = { column = "h", unit = "m", sign = "down" }
alpha = { column = "alpha", unit = "rad", sign = "nose_up" }
lift = { column = "lift", unit = "N/m", sign = "down" }
moment = { column = "moment", unit = "N m/m", sign = "nose_up" }
[wind]
U = { column = "U", unit = "m/s" }
rho = 1.225
[releases]
times = [1.0]
hold = 1.0
"""


#: The map of the MATLAB v5 records :func:`write_mat_v5` writes (listed release instants).
MAP_V5 = """\
config = "sim_flat_plate"
[time]
column = "test.time"
unit = "s"
[channels]
h = { column = "test.h_mm", unit = "mm", sign = "down" }
alpha = { column = "test.alpha", unit = "rad", sign = "nose_up" }
lift = { column = "test.lift", unit = "N/m", sign = "down" }
moment = { column = "test.moment", unit = "N m/m", sign = "nose_up" }
[wind]
U = { property = "U" }
rho = { property = "rho" }
[releases]
times = [1.0, 9.5]
hold = 1.0
"""


def mat_fields(k: int) -> dict[str, np.ndarray]:
    """Return record k as a MATLAB user keeps it: time in s, heave in mm, the rest SI."""
    r = lab_record(k)
    return {"time": r.t, "h_mm": r.h * 1e3, "alpha": r.alpha, "lift": r.lift,
            "moment": r.moment}


def write_mat_v5(path, k: int) -> None:
    """Write record k as MATLAB v5 (column vectors in a struct, scalars beside)."""
    r = lab_record(k)
    savemat(path, {"test": {name: x[:, None] for name, x in mat_fields(k).items()},
                   "U": r.U, "rho": r.rho, "operator": "lab"}, format="5")


def assert_identifies_to_truth(runs: object, label: str) -> dict:
    """Identify the run files of the folder ``runs`` with ``windrig identify``; check the answer.

    E2RFC's accuracy on this campaign (README: the demo's -0.42 to +0.50 %, std 0.6-0.9 %):
    within 2 % of :data:`TRUTH_SPEED` and within three of its own standard deviations. Returns
    the identify JSON (written beside the runs as ``identified.json``).
    """
    folder = Path(str(runs))
    out = folder.parent / "identified.json"
    files = sorted(folder.glob("*.h5"))
    assert main(["identify", *map(str, files), "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    error = result["flutter_speed"] / TRUTH_SPEED - 1.0
    print(f"{label}: {result['flutter_speed']:.3f} +- {result['flutter_speed_std']:.3f} m/s, "
          f"truth {TRUTH_SPEED:.3f} m/s, error {error:+.2%}")
    assert abs(error) < 0.02
    assert abs(result["flutter_speed"] - TRUTH_SPEED) < 3 * result["flutter_speed_std"]
    return result

