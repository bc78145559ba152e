"""The hold before a release: validated like the release, read from run files and simulations."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from daq.recording.recorder import RunRecorder
from ident import Release
from ident.errors import NonUniformSamplingError
from ident.model import flat_plate
from ident.records.release import ReleaseHold
from ident.records.run_file import HOLD_GUARD_S, HOLD_SETTLE_S, read_run
from simulators import simulate_release

from support.sections import FLAT_PLATE

CONFIG = """[rig]
name = "test"
[section]
B = 0.3
m = 3.0
I = 0.03
fh = 2.0
fa = 4.0
zeta_h = 0.005
zeta_a = 0.005
"""
FS = 200.0
PRE_S = 3.0
#: Where the first release's arm event lies, s before its release.
ARM_BEFORE_S = 2.5
#: The wind dips (U 10 % of the release's) over these times before the first release, s: longer
#: than the running median that judges the wind (ident.records.run_file.HOLD_U_WINDOW_S, 0.5 s),
#: which a single noisy Pitot row must not cut the hold at.
DIP = (-2.0, -1.4)


def write_run(path):
    """Write two releases, each with 3 s of held model before it, through the real recorder.

    The first has an arm event 2.5 s before its release and a wind dip 2.0-1.4 s before it;
    the second has no arm event (its hold starts at the first release's end).
    """
    recorder = RunRecorder(path, config_text=CONFIG, rig_name="test", min_free_bytes=0)
    recorder.open()
    recorder.add_sync(["p0", "p1"])
    recorder.start()
    sims, t0, row = [], 0.0, 0
    for k, U in enumerate((5.0, 8.0)):
        sim = simulate_release(FLAT_PLATE, flat_plate.jones_model(), U, 0.004, 0.02, duration=4.0,
                               fs=FS, noise=0.02, rng=k, pre_s=PRE_S)
        n = sim.t.size
        wind = np.full(n, U)
        if k == 0:
            wind[(sim.t >= DIP[0] - 1e-9) & (sim.t < DIP[1] - 1e-9)] = 0.1 * U
            recorder.add_event(t0 + PRE_S - ARM_BEFORE_S, "arm", "engine: model armed")
        columns = {"h": sim.h, "alpha": sim.alpha, "lift": sim.lift, "moment": sim.moment,
                   "U": wind, "rho": np.full(n, FLAT_PLATE.rho),
                   "pressure": np.zeros((n, 2), dtype=np.float32)}
        recorder.append_sync(t0 + PRE_S + sim.t, **columns)
        after = int(np.flatnonzero(sim.t >= 0)[0])
        recorder.add_release(release_time=t0 + PRE_S, start_index=row + after,
                             stop_index=row + n, U=U, h0=0.004, alpha0=0.02)
        sims.append(sim)
        t0 += PRE_S + 4.0
        row += n
    recorder.close()
    return sims


def test_a_release_read_from_a_run_file_carries_its_hold(tmp_path):
    """The hold is the sync rows after arming (and a wind dip) up to just before the release.

    Independent check: the rows come back as the simulation wrote them (times before the
    release, the held model's forces), and the window's ends are where file_format.md says.
    """
    path = tmp_path / "run.h5"
    sims = write_run(path)
    first, second = read_run(path).releases
    dt = 1.0 / FS
    # After the arm event (+ settle) and then after the wind dip: the dip is the later limit.
    assert first.hold is not None
    assert first.hold.t[0] == pytest.approx(DIP[1], abs=dt / 2)
    assert -HOLD_GUARD_S - dt - 1e-9 <= first.hold.t[-1] < -HOLD_GUARD_S
    # The second release has no arm event: its hold starts at the first release's end, and its
    # first rows are the first release's simulated pre-release samples of the next record.
    assert second.hold is not None
    assert second.hold.t[0] == pytest.approx(-PRE_S, abs=dt / 2)
    for release, sim in zip((first, second), sims, strict=True):
        rows = np.searchsorted(sim.t, release.hold.t - 1e-9)
        np.testing.assert_allclose(release.hold.lift, sim.lift[rows], rtol=1e-12)
        np.testing.assert_allclose(release.hold.alpha, sim.alpha[rows], rtol=1e-12)
        # The held model does not move: its displacement is the hold position plus noise.
        assert abs(float(np.median(release.hold.alpha)) - 0.02) < 1e-3
        assert release.hold.dt == pytest.approx(release.dt, rel=1e-9)
    assert first.hold.duration == pytest.approx(DIP[1] * -1 - HOLD_GUARD_S, abs=2 * dt)


def test_the_settle_after_arming_is_left_out(tmp_path):
    """Without the wind dip the hold starts HOLD_SETTLE_S after the arm event."""
    path = tmp_path / "run.h5"
    write_run(path)
    first = read_run(path).releases[0]
    # The dip (later than arm + settle) decides here; arm + settle must lie before it.
    assert -ARM_BEFORE_S + HOLD_SETTLE_S < first.hold.t[0]


def test_a_simulated_release_carries_the_samples_before_it():
    """Release.from_simulation: the samples at t < 0 of simulate_release(pre_s=...) are the hold."""
    sim = simulate_release(FLAT_PLATE, flat_plate.jones_model(), 5.0, 0.004, 0.02, duration=4.0,
                           fs=FS, pre_s=1.0)
    release = Release.from_simulation(sim)
    assert release.hold is not None and release.hold.t.size == int(FS * 1.0)
    np.testing.assert_array_equal(release.hold.moment, sim.moment[sim.t < 0])
    assert release.hold.duration == pytest.approx(1.0)
    plain = simulate_release(FLAT_PLATE, flat_plate.jones_model(), 5.0, 0.004, 0.02,
                             duration=4.0, fs=FS)
    assert Release.from_simulation(plain).hold is None


def _hold(n=50, dt=0.005, **change):
    t = -np.arange(n, 0, -1) * dt
    fields = {"t": t, "h": np.zeros(n), "alpha": np.full(n, 0.02), "lift": np.ones(n),
              "moment": np.ones(n)}
    fields.update(change)
    return ReleaseHold(**fields)


def _release(**change):
    n = 400
    t = np.arange(n) * 0.005
    fields = {"t": t, "h": 0.004 * np.cos(2 * np.pi * 2 * t), "alpha": 0.02 * np.cos(8 * t),
              "lift": np.sin(t), "moment": np.cos(t), "U": 5.0}
    fields.update(change)
    return Release(**fields)


def test_a_hold_is_validated_like_a_release():
    """Non-finite values, times at or after the release, uneven steps, mismatched channels."""
    with pytest.raises(ValueError, match="lift"):
        _hold(lift=np.r_[np.ones(49), np.nan])
    with pytest.raises(ValueError, match="before the release"):
        _hold(t=np.arange(50) * 0.005)
    uneven = -np.arange(50, 0, -1) * 0.005
    uneven[10] += 0.001
    with pytest.raises(NonUniformSamplingError):
        _hold(t=uneven)
    with pytest.raises(ValueError, match="equal lengths"):
        _hold(h=np.zeros(49))
    with pytest.raises(ValueError, match="both p and drag"):
        _hold(p=np.zeros(50))
    with pytest.raises(ValueError, match="sampling interval"):
        _release(hold=_hold(dt=0.01))
    with pytest.raises(ValueError, match="channels differ"):
        _release(hold=_hold(p=np.zeros(50), drag=np.zeros(50)))
    with pytest.raises(ValueError, match="ReleaseHold"):
        _release(hold={"t": np.zeros(3)})
    release = _release(hold=_hold())
    assert release.hold is not None and release.hold.duration == pytest.approx(0.25)
    assert dataclasses.replace(release, hold=None).hold is None


def test_a_hold_s_random_load_is_its_forces_spread_over_their_white_noise():
    """``random_load``: about 1 for white noise alone, the closed form for a known slow load.

    White noise of any level: the spread over the third-difference estimate is 1 (within 3 %
    on 5000 samples: the estimate's relative standard error is about 1 %). A slow sine of
    amplitude ``a`` on noise ``s`` (its third differences are ``(2 pi f dt)^3`` of its size,
    a millionth of the noise's here): ``sqrt(s^2 + a^2 / 2) / s``, within 3 %. The largest
    force channel counts, the drag's too.
    """
    rng = np.random.default_rng(3)
    n, dt = 5000, 0.002
    t = -dt * np.arange(n, 0, -1)
    still = ReleaseHold(t=t, h=np.zeros(n), alpha=np.zeros(n), lift=rng.normal(5.0, 0.3, n),
                        moment=rng.normal(0.1, 0.01, n))
    assert still.random_load == pytest.approx(1.0, rel=0.03)
    sine = 0.02 * np.sin(2 * np.pi * 1.0 * t)
    loaded = dataclasses.replace(still, moment=still.moment + sine)
    expected = np.sqrt(0.01**2 + 0.02**2 / 2) / 0.01
    assert loaded.random_load == pytest.approx(expected, rel=0.03)
    drag = ReleaseHold(t=t, h=np.zeros(n), alpha=np.zeros(n), lift=still.lift,
                       moment=still.moment, p=np.zeros(n), drag=rng.normal(0.0, 0.1, n) + 5 * sine)
    assert drag.random_load == pytest.approx(np.sqrt(0.1**2 + 0.1**2 / 2) / 0.1, rel=0.03)
