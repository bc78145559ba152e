"""The console's releases table: decays cut from a sync-view buffer, fitted, then E2RFC.

The source here is a real :class:`~daq.console.ring_buffer.RingBuffer` holding the sync rows of a
simulated session (flat plate, Jones aerodynamics, 1 % noise, seeded) and the decay instants
the console's source would report; the fits run on a thread pool (the console's default worker
process is exercised by tests/daq/console/test_releases.py).
"""

from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import pytest

from daq.console.live_ident import DECAY_COLUMNS, MIN_DECAY_S, LiveIdentifier
from daq.console.ring_buffer import RingBuffer
from ident.identification.modal import fit_release_modes
from ident.model import flat_plate, flutter
from ident.model.section import SectionModel
from ident.numerics.selection import structure_label
from simulators import simulate_release

pytestmark = pytest.mark.realtime

RATE = 500.0
SECTION = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005,
                       rho=1.2)
TRUTH = flat_plate.jones_model()
DECAY_S = 7.5
HOLD_S = 0.5


class Session:
    """Sync rows of a simulated test session in a ring buffer, plus its decay instants."""

    def __init__(self, capacity_s: float = 60.0) -> None:
        self.ring = RingBuffer(int(capacity_s * RATE), *DECAY_COLUMNS)
        self.t = 0.0
        self._decays: list[tuple[float, float | None]] = []

    def decays(self) -> list[tuple[float, float | None]]:
        return list(self._decays)

    def snapshot(self, last: int | None = None, columns: Any = None) -> dict[str, Any]:
        return self.ring.snapshot(last, columns)

    def append(self, t: Any, h: Any, alpha: Any, lift: Any, moment: Any, U: float) -> None:
        n = len(t)
        self.ring.append({"time": t, "h": h, "alpha": alpha, "lift": lift, "moment": moment,
                          "U": np.full(n, U), "rho": np.full(n, SECTION.rho)})
        self.t = float(t[-1]) + 1.0 / RATE

    def release(self, U: float, seed: int, *, decay_s: float = DECAY_S, caught: bool = True,
                edit: Any = None) -> None:
        """Hold, release, decay for ``decay_s``; arm again (``caught``) at its end."""
        sim = simulate_release(SECTION, TRUTH, U, 0.004, 0.02, duration=decay_s, fs=RATE,
                               noise=0.01, rng=seed, pre_s=HOLD_S)
        t_release = self.t + HOLD_S
        t = t_release + sim.t
        channels = {name: np.array(getattr(sim, name)) for name in ("h", "alpha", "lift",
                                                                      "moment")}
        if edit is not None:
            edit(sim.t, channels)
        self._decays.append((t_release, None))
        self.append(t, U=U, **channels)
        if caught:
            self._decays[-1] = (t_release, float(t[-1]))

    def wait(self, seconds: float, U: float) -> None:
        """Rows of the model held still."""
        t = self.t + np.arange(int(seconds * RATE)) / RATE
        zero = np.zeros(t.size)
        self.append(t, zero, zero, zero, zero, U)


def settle(ident: LiveIdentifier, source: Session, timeout_s: float = 60.0) -> None:
    """Poll as the GUI timer would until no fit is running."""
    deadline = time.monotonic() + timeout_s
    ident.update(source)
    while ident.busy:
        assert time.monotonic() < deadline, "fits did not finish"
        time.sleep(0.02)
        ident.update(source)


@pytest.fixture
def pool():
    with ThreadPoolExecutor(1) as executor:
        yield executor


def truth_modes(U: float) -> dict[str, float]:
    res = flutter.analyze(SECTION, TRUTH, U_max=max(1.5 * U, 5.0))
    names = list(res.mode_names)
    out = {}
    for key, mode in (("h", "heave"), ("a", "pitch")):
        j = names.index(mode)
        out[f"f_{key}"] = float(np.interp(U, res.U, res.frequencies[:, j]))
        out[f"zeta_{key}"] = float(np.interp(U, res.U, res.damping[:, j]))
    return out


def test_each_release_gets_its_modes_and_two_wind_speeds_give_the_flutter_speed(pool):
    U_F = float(flutter.analyze(SECTION, TRUTH).speed)
    speeds = (0.5 * U_F, 0.65 * U_F)
    session = Session()
    ident = LiveIdentifier(SECTION, RATE, decay_s=DECAY_S, executor=pool)
    for seed, U in enumerate((speeds[0], speeds[0], speeds[1], speeds[1])):
        session.release(U, seed)
        session.wait(0.3, U)
        settle(ident, session)
        assert ident.rows[-1].status == "ok"
    assert [row.number for row in ident.rows] == [1, 2, 3, 4]
    for row in ident.rows:
        truth = truth_modes(row.U)
        modal = row.modal
        assert modal is not None
        # 7.5 s decays with 1 % noise: frequencies to 0.5 %, damping ratios to 0.003 (the
        # modal fit resolves ~1e-4 here; the margin covers the seeds' noise).
        assert modal.f_h == pytest.approx(truth["f_h"], rel=5e-3)
        assert modal.f_a == pytest.approx(truth["f_a"], rel=5e-3)
        assert modal.zeta_h == pytest.approx(truth["zeta_h"], abs=3e-3)
        assert modal.zeta_a == pytest.approx(truth["zeta_a"], abs=3e-3)
        assert row.length_s == pytest.approx(DECAY_S, abs=2.0 / RATE)
    fit = ident.campaign
    assert fit is not None and fit.n_releases == 4 and len(fit.wind_speeds) == 2
    # Two wind speeds, four 7.5 s decays, 1 % noise: the demo's campaigns land within 1 %;
    # 3 % is the acceptance level for the flutter speed.
    assert fit.flutter_speed == pytest.approx(U_F, rel=0.03)
    assert fit.flutter_std is not None and 0 < fit.flutter_std < 0.03 * U_F
    assert "flutter speed" in ident.campaign_status
    # The chosen structure first among those the data cannot tell apart, its speed the one shown.
    spread = fit.structures
    assert spread is not None and spread.speeds[0] == fit.flutter_speed
    diagnostics = fit.model.diagnostics
    assert spread.labels[0] == structure_label(diagnostics.n_lags, diagnostics.with_A3)
    assert spread.labels[0] == fit.structure
    # The range is in the summary when the data leave several structures open.
    assert (spread.summary() in fit.summary()) == (len(spread.labels) > 1)
    # The model's derivatives against the truth where the releases are (the big ones, 5 %).
    exact = TRUTH.flutter_derivatives(fit.K)
    for name in ("H1", "A2", "A3"):
        assert np.allclose(fit.derivatives[name], exact[name], rtol=0.05), name
    # The indirect table: one row per wind speed, its A3 (the pitch stiffness, the term it
    # gets best) within 5 % of the truth at its own K.
    table = fit.table
    assert table is not None and table.U.size == 2
    assert np.allclose(table.derivatives["A3"], exact_at(table.K_a, "A3"), rtol=0.05)


def exact_at(K: Any, name: str) -> Any:
    return TRUTH.flutter_derivatives(np.asarray(K))[name]


def test_a_decay_is_cut_only_when_it_is_complete(pool):
    session = Session()
    ident = LiveIdentifier(SECTION, RATE, decay_s=DECAY_S, executor=pool)
    session.release(6.0, 1, decay_s=5.0, caught=False)  # still decaying: 5 s of 7.5
    settle(ident, session)
    assert [row.status for row in ident.rows] == ["decaying"]
    assert math.isnan(ident.rows[0].length_s)
    session.wait(3.0, 6.0)  # now past the default length: cut at 7.5 s
    settle(ident, session)
    assert ident.rows[0].status == "ok"
    assert ident.rows[0].length_s == pytest.approx(DECAY_S, abs=2.0 / RATE)
    session.release(6.0, 2, decay_s=4.0)  # caught after 4 s: cut there
    settle(ident, session)
    assert ident.rows[1].length_s == pytest.approx(4.0, abs=2.0 / RATE)
    assert "two or more wind speeds (have: 6.00 m/s)" in ident.campaign_status
    assert ident.campaign is None


def test_releases_that_cannot_be_used_say_why(pool):
    session = Session(capacity_s=30.0)
    ident = LiveIdentifier(SECTION, RATE, decay_s=DECAY_S, executor=pool)

    def gap(t: Any, channels: dict[str, Any]) -> None:
        channels["lift"][(t > 3.0) & (t < 3.1)] = np.nan

    session.release(6.0, 1, edit=gap)
    session.release(6.0, 2, decay_s=1.0)  # caught after 1 s
    session.release(0.0, 3)  # wind off
    settle(ident, session)
    statuses = [row.status for row in ident.rows]
    assert statuses[0].startswith("gap: 49 rows without lift from 3.00 s"), statuses[0]
    assert statuses[1] == f"too short (1.0 s < {MIN_DECAY_S:g} s); not used"
    assert statuses[2] == "still air"
    still = ident.rows[2].modal
    assert still is not None  # the section's modes with the still air's added mass
    truth = truth_modes(0.0)
    assert still.f_h == pytest.approx(truth["f_h"], rel=5e-3)
    assert still.f_a == pytest.approx(truth["f_a"], rel=5e-3)
    assert not any(row.usable for row in ident.rows)
    assert "have: none" in ident.campaign_status
    # A decay that left the buffer before it could be cut (the GUI stalled for > 30 s).
    session._decays.append((session.t + 0.1, session.t + 5.0))
    session.wait(40.0, 6.0)
    settle(ident, session)
    assert ident.rows[3].status.startswith("not in the buffer any more")


def test_modes_are_named_by_the_mass_matrix_not_by_frequency():
    # A section whose pitch frequency is below its heave frequency, in (nearly) no air.
    section = SectionModel(B=0.3, m=3.0, I=0.03, fh=4.0, fa=2.5, zeta_h=0.01, zeta_a=0.02,
                           rho=1e-6)
    sim = simulate_release(section, TRUTH, 0.0, 0.004, 0.02, duration=8.0, fs=RATE)
    modal = fit_release_modes(sim.t, sim.h, sim.alpha, section)
    assert modal.f_h == pytest.approx(4.0, rel=2e-3) and modal.f_a == pytest.approx(2.5, rel=2e-3)
    assert modal.zeta_h == pytest.approx(0.01, abs=5e-4)
    assert modal.zeta_a == pytest.approx(0.02, abs=5e-4)


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="rate_hz"):
        LiveIdentifier(SECTION, 0.0)
    with pytest.raises(ValueError, match="decay_s"):
        LiveIdentifier(SECTION, RATE, decay_s=1.0)
