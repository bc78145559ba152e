"""ContinuousTimeline: host times that stay continuous when the clock map is refitted."""

from __future__ import annotations

import numpy as np
import pytest

from daq.sync.continuous_time import ContinuousTimeline

PERIOD = 1 / 4000.0  # a 4 kHz laser
BLOCK = 200


def blocks(n_blocks: int, start: int = 0):
    for k in range(start, start + n_blocks):
        yield (k * BLOCK + np.arange(BLOCK)) * PERIOD


def run(timeline, maps):
    """Map consecutive blocks, block k through maps[k]; return all host times."""
    return np.concatenate([timeline.map(t, m) for t, m in zip(blocks(len(maps)), maps,
                                                               strict=True)])


@pytest.mark.parametrize("step", [1e-3, -1e-3, 2e-5])
def test_a_map_step_is_slewed_not_stepped(step):
    before = [lambda t: t + 10.0] * 5
    after = [lambda t, s=step: t + 10.0 + s] * 40
    tl = ContinuousTimeline(PERIOD, max_slew=0.01)
    host = run(tl, before + after)
    spacing = np.diff(host)
    # Every spacing within the slew rate of the period (the resampler's gap test is 1.5 periods).
    assert np.all(np.abs(spacing / PERIOD - 1.0) <= 0.01 + 1e-9)
    # Paid off at 1 % of device time: |step| / 0.01 s later the timeline is on the new map.
    t_dev = np.concatenate(list(blocks(45)))
    settled = t_dev >= t_dev[5 * BLOCK] + abs(step) / 0.01 + PERIOD
    np.testing.assert_allclose(host[settled], t_dev[settled] + 10.0 + step, rtol=0, atol=1e-12)
    assert tl.correction_s == pytest.approx(0.0, abs=1e-12)
    assert tl.steps == 0 and tl.largest_slewed_s == pytest.approx(abs(step), rel=1e-9)


def test_a_device_time_gap_restarts_on_the_map():
    tl = ContinuousTimeline(PERIOD)
    first = next(blocks(1))
    tl.map(first, lambda t: t + 10.0)
    later = first + 0.5  # samples lost: no continuity to keep
    host = tl.map(later, lambda t: t + 10.003)
    np.testing.assert_allclose(host, later + 10.003, rtol=0, atol=1e-12)
    assert tl.steps == 1


def test_a_step_larger_than_max_step_is_taken_as_a_step():
    tl = ContinuousTimeline(PERIOD, max_step_s=0.05)
    b0, b1 = blocks(2)
    tl.map(b0, lambda t: t)
    host = tl.map(b1, lambda t: t + 0.2)  # a re-initialised map: 200 ms
    np.testing.assert_allclose(host, b1 + 0.2, rtol=0, atol=1e-12)
    assert tl.steps == 1


def test_device_time_going_backwards_restarts():
    tl = ContinuousTimeline(PERIOD)
    b0 = next(blocks(1))
    tl.map(b0, lambda t: t)
    host = tl.map(b0 - 1.0, lambda t: t + 5.0)  # a device restart
    np.testing.assert_allclose(host, b0 - 1.0 + 5.0, rtol=0, atol=1e-12)
    assert tl.steps == 1


@pytest.mark.parametrize("kwargs", [{"period_s": 0.0}, {"period_s": float("nan")},
                                    {"period_s": 1e-3, "max_slew": 0.0},
                                    {"period_s": 1e-3, "max_slew": 0.5},
                                    {"period_s": 1e-3, "max_step_s": -1.0}])
def test_invalid_settings_are_refused(kwargs):
    with pytest.raises(ValueError):
        ContinuousTimeline(**kwargs)
