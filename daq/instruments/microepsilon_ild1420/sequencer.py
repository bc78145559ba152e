"""The ILD1420-class laser's counters and timestamps unwrapped, gaps and restarts marked.

Responsibility: :class:`Ild1420Sequencer` (pure) unwraps the 18-bit counter and the 32-bit
timestamp of decoded samples, and marks the samples that are missing (a
:class:`~daq.instruments.reading.Gap`, counted) and the sensor's restarts (a ``"restart"`` gap
of estimated length).

Not responsible for: decoding bytes (:mod:`daq.instruments.microepsilon_ild1420.decoder`),
reading the line or building the driver's :class:`~daq.instruments.reading.Reading`
(:mod:`daq.instruments.microepsilon_ild1420.driver`).
"""

from __future__ import annotations

import logging

import numpy as np
import numpy.typing as npt

from daq.instruments.microepsilon_ild1420.decoder import (
    COUNTER_MODULUS,
    TIMESTAMP_MODULUS,
    TIMESTAMP_TICK_S,
)
from daq.instruments.reading import Gap

__all__ = ["Ild1420Sequencer"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

log = logging.getLogger(__name__)


class Ild1420Sequencer:
    """Unwrap the 18-bit counter and the 32-bit timestamp across chunks; find gaps and restarts.

    Within one epoch (one run of the sensor since power-on) counter steps are taken modulo 2**18
    and timestamp steps modulo 2**32; a counter step that disagrees with the timestamp step by a
    whole number of counter periods (a gap longer than 2**18 samples) is corrected with the
    timestamp. A timestamp that goes backwards is a restart: a new epoch begins, the unwrapped
    counter continues after an estimated gap (host time x ``rate_hz``), and the device time
    restarts with the device. After a reconnect the first step is also checked against the host
    time elapsed, so a restart that happened while the line was down is found.

    Parameters
    ----------
    rate_hz : float
        Nominal measuring rate, Hz (to resolve counter wraps and estimate restart gaps).
    """

    #: Slack when checking a step against the host time elapsed, s.
    RESTART_SLACK_S = 1.0

    def __init__(self, rate_hz: float) -> None:
        self.rate_hz = float(rate_hz)
        self.epoch = 0
        self._last: tuple[int, int, int, int, int] | None = None  # raw c, raw ts, c, ticks, ns
        self._check_next = False

    def expect_discontinuity(self) -> None:
        """Check the next step against the host time (call after a reconnect)."""
        self._check_next = True

    def process(self, counter: IntArray, timestamp: IntArray, host_ns: IntArray,
                ) -> tuple[IntArray, FloatArray, npt.NDArray[np.int32], list[Gap]]:
        """Unwrap one batch; return (counter, device time s, epoch per sample, gaps).

        ``counter`` and ``timestamp`` are the raw values, ``host_ns`` the arrival times (ns).
        """
        n = int(counter.size)
        out_c = np.empty(n, dtype=np.int64)
        out_t = np.empty(n, dtype=np.int64)
        epochs = np.empty(n, dtype=np.int32)
        gaps: list[Gap] = []
        if n == 0:
            return out_c, out_t.astype(np.float64), epochs, gaps
        if self._last is not None and not self._check_next:
            fast = self._consecutive(counter, timestamp, host_ns)
            if fast is not None:
                return fast
        first_ever = self._last is None
        if self._last is None:
            prev = (int(counter[0]), int(timestamp[0]), 0, 0, int(host_ns[0]))
        else:
            prev = self._last
        raw_c = np.concatenate(([prev[0]], counter))
        ns = np.concatenate(([prev[4]], host_ns))
        dc = np.diff(raw_c) % COUNTER_MODULUS
        dt = np.diff(np.concatenate(([prev[1]], timestamp))) % TIMESTAMP_MODULUS
        # A gap longer than a counter period: the timestamp tells how many periods passed.
        expected = dt * (TIMESTAMP_TICK_S * self.rate_hz)
        dc = dc + COUNTER_MODULUS * np.maximum(
            np.round((expected - dc) / COUNTER_MODULUS), 0).astype(np.int64)
        restart = dt >= TIMESTAMP_MODULUS // 2  # the timestamp went backwards: a restart
        if first_ever:
            restart[0] = True
        elif self._check_next:
            restart[0] |= not self._continues(int(dc[0]), int(dt[0]), int(ns[1] - ns[0]))
        self._check_next = False
        c, t = prev[2], prev[3]
        bounds = sorted({0, n, *np.flatnonzero(restart).tolist()})
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            if restart[a]:  # sample a starts an epoch
                if first_ever and a == 0:
                    c, t = int(counter[0]), int(timestamp[0])
                else:
                    self.epoch += 1
                    elapsed_s = max(0.0, (int(ns[a + 1]) - int(ns[a])) * 1e-9)
                    missing = max(0, round(elapsed_s * self.rate_hz) - 1)
                    log.warning("ILD1420 restarted (counter %d, timestamp %d): epoch %d, about "
                                "%d samples missing", int(counter[a]), int(timestamp[a]),
                                self.epoch, missing)
                    gaps.append(Gap(after_counter=c, length=missing, kind="restart"))
                    c, t = c + 1 + missing, int(timestamp[a])
                out_c[a], out_t[a], epochs[a] = c, t, self.epoch
                a += 1
            if b > a:  # samples a..b-1 continue from (c, t)
                run = c + np.cumsum(dc[a:b])
                out_c[a:b] = run
                out_t[a:b] = t + np.cumsum(dt[a:b])
                epochs[a:b] = self.epoch
                for j in np.flatnonzero(dc[a:b] != 1).tolist():
                    step = int(dc[a + j])
                    if step > 1:
                        gaps.append(Gap(after_counter=int(run[j]) - step, length=step - 1))
                    else:
                        log.warning("ILD1420 counter %d repeated", int(run[j]))
                c, t = int(run[-1]), int(out_t[b - 1])
        self._last = (int(counter[-1]), int(timestamp[-1]), c, t, int(host_ns[-1]))
        return out_c, out_t.astype(np.float64) * TIMESTAMP_TICK_S, epochs, gaps  # ticks -> s

    def _consecutive(self, counter: IntArray, timestamp: IntArray, host_ns: IntArray,
                     ) -> tuple[IntArray, FloatArray, npt.NDArray[np.int32], list[Gap]] | None:
        """:meth:`process` of a batch that continues the last one sample by sample, else None.

        The usual batch: every counter step is 1 and every timestamp step is forward and too
        short to hide a counter wrap. Its counters and ticks then follow by a cumulative sum,
        without the general path's wrap corrections, restart search and per-gap loop (the same
        numbers).
        """
        assert self._last is not None
        raw_c, raw_t, c, t, _ = self._last
        n = int(counter.size)
        if (int(counter[0]) - raw_c) % COUNTER_MODULUS != 1:
            return None
        steps = counter[1:] - counter[:-1]
        if not (steps == 1).all():  # a wrap of the counter inside the batch, or not consecutive
            steps %= COUNTER_MODULUS
            if not (steps == 1).all():
                return None
        dt = np.empty(n, np.int64)
        dt[0] = (int(timestamp[0]) - raw_t) % TIMESTAMP_MODULUS
        np.subtract(timestamp[1:], timestamp[:-1], out=dt[1:])
        if n > 1 and int(dt[1:].min()) < 0:  # the timestamp wrapped inside the batch
            dt[1:] %= TIMESTAMP_MODULUS
        longest = int(dt.max())
        # No restart (a timestamp going back), and no step long enough for the timestamp to
        # correct the counter by a whole period (round((expected - 1) / 2**18) would be >= 1).
        if (longest >= TIMESTAMP_MODULUS // 2
                or (longest * (TIMESTAMP_TICK_S * self.rate_hz) - 1) / COUNTER_MODULUS >= 0.5):
            return None
        out_c = np.arange(c + 1, c + n + 1, dtype=np.int64)
        out_t = np.cumsum(dt)
        out_t += t
        self._last = (int(counter[-1]), int(timestamp[-1]), c + n, int(out_t[-1]),
                      int(host_ns[-1]))
        epochs = np.full(n, self.epoch, dtype=np.int32)
        return out_c, out_t.astype(np.float64) * TIMESTAMP_TICK_S, epochs, []

    def _continues(self, dc: int, dt: int, elapsed_ns: int) -> bool:
        """Whether a step across a reconnect is consistent with the host time elapsed."""
        dt_s = dt * TIMESTAMP_TICK_S
        if dt_s > elapsed_ns * 1e-9 + self.RESTART_SLACK_S:
            return False
        expected = dt_s * self.rate_hz
        return abs(dc - expected) <= 0.05 * expected + 2
