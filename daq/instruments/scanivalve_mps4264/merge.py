"""The Scanivalve MPS4264-class scanner's frames, merged over modules into blocks (pure).

Responsibility: :class:`FrameMerger` takes the frames each module's stream released for one
block (:data:`~daq.instruments.scanivalve_mps4264.streams.Part`: merge keys, packets, arrival
times) and builds the :class:`~daq.instruments.scanivalve_mps4264.blocks.ScanBlock`: every
module's channels side by side (a missing module or a valve in calibration is NaN with its
status), one frame time and trigger time per frame, the latest arrival, the counter unwrapped
across the scan's counter epochs (a restarted scan continues the counter with a ``restart``
gap), the frames missing (``missing`` gaps), the jumps of the frame time against the counter
(clock steps) and the block's time base (absolute PTP times, or times relative to the scan
start). No I/O and no clock.

Not responsible for: reading and decoding the modules' bytes
(:mod:`daq.instruments.scanivalve_mps4264.streams`), or deciding when a block is due
(:mod:`daq.instruments.scanivalve_mps4264.driver`).
"""

from __future__ import annotations

import logging
import math

import numpy as np
import numpy.typing as npt

from daq.instruments.reading import Gap
from daq.instruments.scanivalve_mps4264.blocks import (
    STATUS_MISSING,
    STATUS_OK,
    STATUS_VALVE_CAL,
    ClockStep,
    ScanBlock,
)
from daq.instruments.scanivalve_mps4264.frames import (
    CHANNELS_PER_MODULE,
    TEMPERATURES_PER_MODULE,
    PacketBatch,
)
from daq.instruments.scanivalve_mps4264.streams import KEY_BITS, KEY_MASK, Part, aligned

__all__ = ["FrameMerger"]

log = logging.getLogger(__name__)


class FrameMerger:
    """The frames of every module merged into blocks, with counters, gaps and clock steps.

    Parameters
    ----------
    modules : int
        Modules of the scanner (64 channels each).
    pitot_channel : int
        The channel of the Pitot's pressure (its column of the block).
    rate_hz : float
        The frame rate, Hz (the driver keeps it up to date: :attr:`rate_hz`).

    Attributes
    ----------
    last_key : int or None
        Merge key of the last frame returned (None before the first).
    """

    def __init__(self, modules: int, pitot_channel: int, rate_hz: float) -> None:
        self.modules = modules
        self.pitot_channel = pitot_channel
        self.rate_hz = rate_hz
        self.last_key: int | None = None
        self._last_counter = 0
        self._last_time = math.nan
        self._last_time_counter = 0
        self._last_time_key = -1
        self._steps_seen = 0
        self._epoch_base: dict[int, int] = {}
        self._pending_gaps: list[Gap] = []
        self._pending_steps: list[ClockStep] = []
        self._time_base: str | None = None

    def merge(self, parts: list[Part]) -> ScanBlock | None:
        """Return the block of the modules' frames ``parts`` (None when there are none)."""
        if aligned(parts):
            return self.assemble_aligned(parts)
        all_keys = np.unique(np.concatenate([p[0] for p in parts]))
        if all_keys.size == 0:
            return None
        return self.assemble(all_keys, parts)

    def assemble(self, keys: npt.NDArray[np.int64], parts: list[Part]) -> ScanBlock:
        """Merge the modules' frames of merge keys ``keys`` (sorted) into one block."""
        n, m = keys.size, self.modules
        pressure = np.full((n, CHANNELS_PER_MODULE * m), np.nan)
        temperature = np.full((n, TEMPERATURES_PER_MODULE * m), np.nan)
        status = np.full((n, m), STATUS_MISSING, np.int8)
        frame_time = np.full(n, np.nan)
        trigger = np.full(n, np.nan)
        host = np.zeros(n, np.int64)
        have = np.zeros(n, bool)
        for k, (mkeys, batch, hosts) in enumerate(parts):
            if not mkeys.size:
                continue
            idx = np.searchsorted(keys, mkeys)
            cols = slice(CHANNELS_PER_MODULE * k, CHANNELS_PER_MODULE * (k + 1))
            p = batch.pressure
            if batch.valve_cal.any():
                p = p.copy()
                p[batch.valve_cal] = np.nan
            pressure[idx, cols] = p
            temperature[idx, TEMPERATURES_PER_MODULE * k:TEMPERATURES_PER_MODULE * (k + 1)] = \
                batch.temperature
            status[idx, k] = np.where(batch.valve_cal, STATUS_VALVE_CAL, STATUS_OK)
            first = ~have[idx]
            frame_time[idx[first]] = batch.frame_time[first]
            trigger[idx[first]] = batch.trigger_time[first]
            have[idx] = True
            host[idx] = np.maximum(host[idx], hosts)
        return self._finish(keys, frame_time, trigger, host, pressure, temperature, status)

    def assemble_aligned(self, parts: list[Part]) -> ScanBlock:
        """:meth:`assemble` when every module sent the same frames (the usual case)."""
        keys, first, host = parts[0]
        n, m = keys.size, self.modules
        pressure = np.empty((n, CHANNELS_PER_MODULE * m))
        temperature = np.empty((n, TEMPERATURES_PER_MODULE * m))
        status = np.zeros((n, m), np.int8)  # STATUS_OK
        host = host.copy()
        for k, (_, batch, hosts) in enumerate(parts):
            cols = slice(CHANNELS_PER_MODULE * k, CHANNELS_PER_MODULE * (k + 1))
            pressure[:, cols] = batch.pressure
            temperature[:, TEMPERATURES_PER_MODULE * k:TEMPERATURES_PER_MODULE * (k + 1)] = \
                batch.temperature
            valve = batch.valve_cal
            if valve.any():
                pressure[valve, cols] = np.nan
                status[valve, k] = STATUS_VALVE_CAL
            if k:
                np.maximum(host, hosts, out=host)
        return self._finish(keys, first.frame_time.copy(), first.trigger_time.copy(), host,
                            pressure, temperature, status)

    def assemble_in_step(self, keys: npt.NDArray[np.int64], batch: PacketBatch,
                         host: npt.NDArray[np.int64]) -> ScanBlock:
        """:meth:`assemble_aligned` of one batch holding every module's packets of ``keys``.

        ``batch`` holds module 0's ``n = keys.size`` packets, then module 1's, ...; ``host`` is
        each frame's latest arrival over the modules, ns. The same block, without a part per
        module: the modules' columns are put side by side by one transposing copy.
        """
        n, m = keys.size, self.modules
        pressure = batch.pressure.reshape(m, n, CHANNELS_PER_MODULE).transpose(1, 0, 2) \
            .reshape(n, CHANNELS_PER_MODULE * m)
        temperature = batch.temperature.reshape(m, n, TEMPERATURES_PER_MODULE) \
            .transpose(1, 0, 2).reshape(n, TEMPERATURES_PER_MODULE * m)
        status = np.zeros((n, m), np.int8)  # STATUS_OK
        valve = batch.valve_cal.reshape(m, n)
        if valve.any():
            for k in np.flatnonzero(valve.any(axis=1)).tolist():
                cols = slice(CHANNELS_PER_MODULE * k, CHANNELS_PER_MODULE * (k + 1))
                pressure[valve[k], cols] = np.nan
                status[valve[k], k] = STATUS_VALVE_CAL
        return self._finish(keys, batch.frame_time[:n].copy(), batch.trigger_time[:n].copy(),
                            host, pressure, temperature, status)

    def _finish(self, keys: npt.NDArray[np.int64], frame_time: npt.NDArray[np.float64],
                trigger: npt.NDArray[np.float64], host: npt.NDArray[np.int64],
                pressure: npt.NDArray[np.float64], temperature: npt.NDArray[np.float64],
                status: npt.NDArray[np.int8]) -> ScanBlock:
        """Counters, gaps, clock steps and time base of merged frames; the block."""
        counter = self._counters(keys)
        self._find_clock_steps(counter, keys, frame_time)
        base = self._block_time_base(frame_time)
        gaps, steps = tuple(self._pending_gaps), tuple(self._pending_steps)
        self._pending_gaps, self._pending_steps = [], []
        self.last_key = int(keys[-1])
        self._last_counter = int(counter[-1])
        return ScanBlock(
            counter=counter, frame_time=frame_time, trigger_time=trigger, host_time_ns=host,
            pressure=pressure, pitot=pressure[:, self.pitot_channel].copy(),
            temperature=temperature, module_status=status, gaps=gaps, clock_steps=steps,
            time_base=base,
        )

    def _counters(self, keys: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
        """Unwrapped counters of merged keys; records the gaps and restarts before them.

        Within a counter epoch the counter is ``base + u``; the first frame of a restarted epoch
        continues at the previous counter + 1 (the true gap is unknown: a ``restart`` gap).
        """
        n = int(keys.size)
        if (self.last_key is not None and int(keys[0]) == self.last_key + 1
                and int(keys[-1]) - self.last_key == n):
            # The usual case: the frames that follow the last one, none missing (keys increase
            # strictly, so first and last tell it), in the same counter epoch.
            return self._last_counter + np.arange(1, n + 1, dtype=np.int64)
        epochs = keys >> KEY_BITS
        u = keys & KEY_MASK
        counter = np.empty(keys.size, np.int64)
        prev_counter = self._last_counter
        for epoch in np.unique(epochs).tolist():
            lo, hi = np.searchsorted(epochs, [epoch, epoch + 1])  # keys are sorted
            if epoch not in self._epoch_base:
                self._epoch_base[epoch] = (0 if self.last_key is None and lo == 0
                                           else prev_counter + 1 - int(u[lo]))
            counter[lo:hi] = self._epoch_base[epoch] + u[lo:hi]
            prev_counter = int(counter[hi - 1])
        prev_keys = np.concatenate([[-1 if self.last_key is None else self.last_key],
                                    keys[:-1]])
        prev_counts = np.concatenate([[self._last_counter], counter[:-1]])
        new_epoch = (prev_keys >> KEY_BITS) != epochs
        restart = new_epoch & (prev_keys >= 0)
        jump = ~new_epoch & (keys - prev_keys > 1)
        gaps = []
        if self.last_key is None and u[0] > 1:  # frames missing at the start of the scan
            gaps.append(Gap(0, int(u[0]) - 1, "missing"))
        for i in np.flatnonzero(restart | jump).tolist():
            length = -1 if restart[i] else int(keys[i] - prev_keys[i] - 1)
            gaps.append(Gap(int(prev_counts[i]), length, "restart" if restart[i] else "missing"))
        for gap in gaps:
            log.warning("scanner gap: %s", gap)
        self._pending_gaps.extend(gaps)
        return counter

    def _find_clock_steps(self, counter: npt.NDArray[np.int64], keys: npt.NDArray[np.int64],
                          frame_time: npt.NDArray[np.float64]) -> None:
        """Record jumps of the frame time against ``counter / rate`` (same counter epoch)."""
        ok = np.isfinite(frame_time)
        epoch = int(keys[0]) >> KEY_BITS
        last_key = self._last_time_key
        # The usual block: every frame timed, one counter epoch (keys are sorted), the one of
        # the last timed frame: no row to leave out and no epoch to compare.
        one_epoch = (bool(ok.all()) and int(keys[-1]) >> KEY_BITS == epoch
                     and (last_key < 0 or last_key >> KEY_BITS == epoch))
        if one_epoch:
            c, t = counter, frame_time
        else:
            c, t, e = counter[ok], frame_time[ok], (keys >> KEY_BITS)[ok]
        if last_key >= 0 and c.size:
            c = np.concatenate([[self._last_time_counter], c])
            t = np.concatenate([[self._last_time], t])
            if not one_epoch:
                e = np.concatenate([[last_key >> KEY_BITS], e])
        if c.size:
            self._last_time, self._last_time_counter = float(t[-1]), int(c[-1])
            self._last_time_key = (int(keys[-1]) if one_epoch
                                   else int(keys[ok][-1]) if ok.any() else last_key)
        if c.size < 2:
            return
        if one_epoch and int(c[-1]) - int(c[0]) == c.size - 1:  # consecutive: every step 1
            residual = np.diff(t) - 1 / self.rate_hz
        else:
            residual = np.diff(t) - np.diff(c) / self.rate_hz
        # A quarter frame, at least 1 ms: ordinary frames sit within microseconds of the counter
        # (the s/ns fields are exact); a PTP lock or a rate mismatch is far larger.
        tol = max(0.25 / self.rate_hz, 1e-3)
        stepped = np.abs(residual) > tol
        if not one_epoch:
            stepped &= np.diff(e) == 0
        for i in np.flatnonzero(stepped).tolist():
            step = ClockStep(int(c[i + 1]), float(residual[i]))
            self._steps_seen += 1
            if self._steps_seen <= 5:
                log.warning("scanner frame time stepped by %+.6f s at counter %d%s",
                            step.step_s, step.counter,
                            " (further steps not logged: is the rate right?)"
                            if self._steps_seen == 5 else "")
            self._pending_steps.append(step)

    def _block_time_base(self, frame_time: npt.NDArray[np.float64]) -> str:
        if frame_time.size and frame_time.min() >= 1e9 and self._time_base == "ptp":
            return "ptp"  # the usual block: every time finite (a NaN makes min NaN) and PTP
        finite = frame_time[np.isfinite(frame_time)]
        relative = finite < 1e9  # before 2001-09-09: a clock started at epoch 0 (no PTP time)
        base = "mixed" if relative.any() and not relative.all() else \
            ("relative" if relative.any() else "ptp")
        last = None if not finite.size else ("relative" if relative[-1] else "ptp")
        if last is not None and last != self._time_base:
            if last == "relative":
                log.warning("scanner frame times are relative to the scan start (PTP absent: "
                            "epoch 0)")
            elif self._time_base is not None:
                log.info("scanner frame times are now absolute PTP times")
            self._time_base = last
        return base
