"""The adaptive choice (c-optimal prediction, safety bound) and the decay monitor, without a rig.

The releases are simulated by :func:`simulators.campaigns.simulated_campaign` (the flat plate
with Jones aerodynamics, seeded noise): the same identification the runner uses, on data whose
truth is known, so that the predictions can be checked against what more data really does.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from daq.campaign.adaptive import choose_next, predicted_std, safety_bound
from daq.campaign.monitor import DecayMonitor
from ident.campaign import analyze_campaign
from simulators.campaigns import SECTION, simulated_campaign


@pytest.fixture(scope="module")
def two_speeds():
    releases = simulated_campaign(None, seed=3, fractions=(0.4, 0.55), duration=5.0)
    return releases, analyze_campaign(releases, SECTION, table=False)


def test_more_information_closer_to_flutter_predicts_a_smaller_std(two_speeds):
    releases, analysis = two_speeds
    U_F = analysis.flutter_speed
    assert U_F is not None
    candidates = [0.45 * U_F, 0.6 * U_F, 0.75 * U_F]
    stds = predicted_std(analysis, releases, candidates, releases_per_speed=2, decay_s=5.0)
    assert all(s < analysis.flutter_std for s in stds)
    assert stds[0] > stds[1] > stds[2]  # the forces grow as U^2 against the same noise


def test_the_prediction_is_borne_out_by_the_data(two_speeds):
    # Add the chosen speed's releases for real: the std comes down to within a factor of 2 of
    # the prediction (the structure parts move with the data too, not only the noise part).
    releases, analysis = two_speeds
    choice = choose_next(analysis, releases, [0.7 * analysis.flutter_speed], bound=math.inf,
                         releases_per_speed=2, decay_s=5.0)
    assert choice.speed is not None
    predicted = choice.predicted[0][1]
    more = simulated_campaign(None, seed=4, fractions=(0.7,), duration=5.0)
    after = analyze_campaign(releases + more, SECTION, table=False)
    assert after.flutter_std < analysis.flutter_std
    assert 0.5 * predicted < after.flutter_std < 2.0 * predicted


def test_no_candidate_above_the_bound_is_ever_chosen(two_speeds):
    releases, analysis = two_speeds
    bound = safety_bound(analysis, 0.9)
    assert bound == pytest.approx(0.9 * (analysis.flutter_speed - 3 * analysis.flutter_std))
    candidates = list(np.linspace(3.0, 1.3 * analysis.flutter_speed, 12))
    choice = choose_next(analysis, releases, candidates, bound=bound, releases_per_speed=1,
                         decay_s=5.0)
    assert choice.speed is not None and choice.speed <= bound
    assert all(u <= bound for u, _ in choice.predicted)
    assert choice.speed == min(choice.predicted, key=lambda row: row[1])[0]
    # Nothing allowed: stop, and say why.
    stop = choose_next(analysis, releases, [bound + 1.0], bound=bound, releases_per_speed=1,
                       decay_s=5.0)
    assert stop.speed is None and "below the safety bound" in stop.reason


def test_safety_bound_is_infinite_without_an_estimate():
    assert safety_bound(None, 0.9) == math.inf
    assert safety_bound(None, 0.9, held=5.0) == math.inf


def test_a_speed_already_held_stays_allowed_when_the_std_is_wide(two_speeds):
    """A std of U_F / 3 or more makes fraction (U_F - 3 std) zero; the held speed remains."""
    _, analysis = two_speeds
    wide = SimpleNamespace(flutter_speed=analysis.flutter_speed,
                           flutter_std=0.4 * analysis.flutter_speed)
    assert safety_bound(wide, 0.9) == 0.0
    assert safety_bound(wide, 0.9, held=6.5) == 6.5
    # A tight estimate's bound is kept when it is the higher one.
    own = safety_bound(analysis, 0.9)
    assert safety_bound(analysis, 0.9, held=own - 1.0) == own


def _laser_block(t0_ns: int, t: np.ndarray, x: np.ndarray) -> SimpleNamespace:
    return SimpleNamespace(kind="laser", device="laser_front",
                           host_time_ns=(t0_ns + 1e9 * t).astype(np.int64),
                           values={"distance": x})


@pytest.mark.parametrize("damping, grows", [(0.05, False), (0.0, False), (-0.03, True)])
def test_decay_monitor_flags_growth_only(damping, grows):
    monitor = DecayMonitor(window_s=0.5)
    t0 = 10**12
    monitor("event", SimpleNamespace(kind="release", host_time_ns=t0))
    t = np.arange(0, 6.0, 1 / 4000)
    w = 2 * math.pi * 2.0
    x = 0.025 + 0.004 * np.exp(-damping * w * t) * np.cos(w * t)
    for start in range(0, t.size, 80):  # ~20 ms blocks, as the laser reader delivers
        monitor("block", _laser_block(t0, t[start:start + 80], x[start:start + 80]))
    amp = monitor.amplitude()
    assert amp is not None and amp.windows >= 10
    assert monitor.growing.is_set() is grows
    assert (amp.last > amp.first) is grows
    # The next release starts afresh.
    monitor("event", SimpleNamespace(kind="release", host_time_ns=t0 + 10**10))
    assert not monitor.growing.is_set() and monitor.amplitude() is None


def test_decay_monitor_counts_a_lost_target_as_growth():
    monitor = DecayMonitor(window_s=0.5)
    monitor("event", SimpleNamespace(kind="release", host_time_ns=0))
    t = np.arange(0, 3.0, 1 / 1000)
    x = 0.025 + 0.004 * np.cos(2 * math.pi * 2 * t)
    x[t > 0.6] = np.nan  # out of range: the model has left the laser's window
    monitor("block", _laser_block(0, t, x))
    assert monitor.growing.is_set()


def test_decay_monitor_ignores_data_while_the_model_is_held():
    monitor = DecayMonitor(window_s=0.5)
    monitor("event", SimpleNamespace(kind="release", host_time_ns=0))
    monitor("event", SimpleNamespace(kind="arm", host_time_ns=1))
    t = np.arange(0, 3.0, 1 / 1000)
    monitor("block", _laser_block(0, t, 0.025 + 0.004 * np.exp(t)))
    assert monitor.amplitude() is None and not monitor.growing.is_set()
