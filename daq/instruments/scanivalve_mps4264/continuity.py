"""One stream across the scanner's scans: counters and frame times continued over a restart.

Responsibility: :class:`ScanContinuity` turns the blocks of successive scans
(:class:`~daq.instruments.scanivalve_mps4264.blocks.ScanBlock`, whose counter and frame time
start again with every ``SCAN``) into one stream of
:class:`~daq.instruments.reading.Reading`: the counters of a new scan continue after the last
one delivered, behind a ``"restart"`` gap, and so do its frame times where they started again
at 0; it also keeps the last ``RECENT_S`` of pressure rows (the zero a CALZ removes). The
driver (:class:`~daq.instruments.scanivalve_mps4264.driver.ScanivalveMps4264`) tells it of
every new scan (:meth:`ScanContinuity.restarted`) and of the measured standstill of a pause
(:meth:`ScanContinuity.note_pause`). Pure bookkeeping: no I/O.

How a restart's gap is measured. A new scan restarts the driver's counter unwrapping (and the
device's frame counter), so after a restart the counters are shifted to continue after the last
one delivered, with a ``(last, -1)`` restart gap: the stream's counter stays increasing.

A restart after a pause of the engine's own (a CALZ: ``restarted(measure=True)``) is measured
instead where the device clock allows it: with absolute (PTP) frame times on both sides the gap
is the number of frame periods the scan stood still, ``(last, n)``, and the counter continues
after it. With frame times relative to the scan start (PTP absent) the new scan's clock starts
again at 0 and the length is unknown (-1); its frame times are then continued on the previous
scan's base with the host-measured time from STOP to SCAN (the only measure of it there is;
off by less than a frame period plus half the two commands' durations), so that the clock map
of the stream stays valid.

Not responsible for: reading frames or commanding scans (the driver), or mapping the device
clock onto the host clock (:mod:`daq.sync`, through the run writer).
"""

from __future__ import annotations

import logging
import math
from collections import deque

import numpy as np
import numpy.typing as npt

from daq.instruments.reading import Gap, Reading
from daq.instruments.scanivalve_mps4264.blocks import ScanBlock

__all__ = ["ScanContinuity"]

log = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]


class ScanContinuity:
    """Counters and frame times of successive scans as one stream (see the module docstring)."""

    #: Frames kept for :meth:`recent_pressure_mean`: the last this many seconds of them.
    RECENT_S = 0.5
    _MAX_RECENT_ROWS = 4096

    def __init__(self) -> None:
        self._offset = 0
        self._last: int | None = None
        self._restarted = False
        self._measure_gap = False  # the next restart follows a pause of ours: measure its gap
        self._time_shift = 0.0  # s added to frame times (a relative base continued)
        self._last_time = math.nan  # last finite frame time delivered (shifted), s
        self._last_host_ns = 0  # its host arrival time, ns
        self._last_base: str | None = None  # time base of the block that held it
        self._pause_s: float | None = None  # STOP to SCAN of the last pause, host-measured, s
        self._recent: deque[FloatArray] = deque()  # pressure rows of the last RECENT_S
        self._recent_rows = 0

    def restarted(self, *, measure: bool) -> None:
        """Note a new scan: its first block continues the stream.

        Parameters
        ----------
        measure : bool
            The scan follows a pause the caller made (STOP, CALZ, SCAN): measure the gap from
            the frame times (module docstring). False (a recovery) keeps a measurement asked
            for by a restart that failed before its first frame: the gap is still the pause's.
        """
        self._restarted = True
        if measure:
            self._measure_gap = True
            self._pause_s = None

    def note_pause(self, pause_s: float) -> None:
        """Take the host-measured time from STOP to SCAN of the last pause, s."""
        self._pause_s = float(pause_s)

    def reading(self, block: ScanBlock, rate_hz: float) -> Reading:
        """Return a block of the current scan as a reading of the continued stream.

        Parameters
        ----------
        block : ScanBlock
            The frames of one read.
        rate_hz : float
            The scanner's frame rate, Hz (to count the frames of a measured pause).
        """
        gaps = list(block.gaps)
        counter = block.counter
        n = len(block)
        if self._restarted and n:
            self._restarted = False
            if self._last is not None:
                length = self._restart_gap(block, rate_hz)
                self._offset = self._last + 1 + max(length, 0) - int(counter[0])
                gaps = [g for g in gaps if g.after_counter >= int(counter[0]) - 1 or g.length < 0]
                gaps.insert(0, Gap(self._last - self._offset, length, "restart"))
        if self._offset:
            counter = counter + self._offset
            gaps = [Gap(g.after_counter + self._offset, g.length, g.kind) for g in gaps]
        frame_time = block.frame_time
        if self._time_shift:
            frame_time = frame_time + self._time_shift
        if n:
            self._last = int(counter[-1])
            self._remember(block, frame_time, rate_hz)
        return Reading(
            channels={"pressure": block.pressure, "pitot": block.pitot,
                      "temperature": block.temperature, "trigger_time": block.trigger_time,
                      "module_status": block.module_status},
            host_time_ns=block.host_time_ns, counter=counter, device_time=frame_time,
            gaps=tuple(gaps),
            info={"time_base": block.time_base, "clock_steps": block.clock_steps})

    def _restart_gap(self, block: ScanBlock, rate_hz: float) -> int:
        """Length of the gap before the first block of a restarted scan (-1: unknown).

        Also sets the frame-time shift of the new scan (see the module docstring).
        """
        measure, self._measure_gap = self._measure_gap, False
        if not measure:  # a restart of the recovery: as it always was
            self._time_shift = 0.0
            return -1
        finite = np.flatnonzero(np.isfinite(block.frame_time))
        if finite.size == 0 or not math.isfinite(self._last_time):
            return -1
        first = int(finite[0])
        t_first = float(block.frame_time[first])
        if block.time_base == "ptp":
            self._time_shift = 0.0  # absolute times continue by themselves
            if self._last_base != "ptp":
                return -1
            # Frames the scanner would have sent at its rate while it stood still; the new
            # scan's frames are not on the old frame grid, hence the rounding.
            n = round((t_first - self._last_time) * rate_hz) - 1 if rate_hz > 0 else -1
            return n if n >= 1 else -1
        pause_s = self._pause_s
        if pause_s is not None:
            # Relative frame time 0 is the SCAN; the last frame preceded STOP by less than a
            # period: on the old base, the new scan starts the pause after that frame.
            self._time_shift = self._last_time + pause_s
        else:  # the pause's length was not told: the arrival times are all there is
            pause_s = (int(block.host_time_ns[first]) - self._last_host_ns) * 1e-9
            self._time_shift = self._last_time + pause_s - t_first
        log.warning("scanner: frame times restarted at 0 with the scan (PTP absent): continued "
                    "on the previous base with the host-measured pause, %.3f s", pause_s)
        return -1

    def _remember(self, block: ScanBlock, frame_time: FloatArray, rate_hz: float) -> None:
        """Keep the last frame time and the last ``RECENT_S`` of pressure rows."""
        last = frame_time.size - 1
        if last >= 0 and not math.isfinite(frame_time[last]):  # else the usual: the last row
            finite = np.flatnonzero(np.isfinite(frame_time))
            last = int(finite[-1]) if finite.size else -1
        if last >= 0:
            self._last_time = float(frame_time[last])
            self._last_host_ns = int(block.host_time_ns[last])
            self._last_base = block.time_base
        keep = self._keep_rows(rate_hz)
        self._recent.append(block.pressure)
        self._recent_rows += len(block)
        while self._recent_rows - len(self._recent[0]) >= keep:
            self._recent_rows -= len(self._recent.popleft())

    def _keep_rows(self, rate_hz: float) -> int:
        return min(max(math.ceil(self.RECENT_S * (rate_hz or 0.0)), 1), self._MAX_RECENT_ROWS)

    def recent_pressure_mean(self, rate_hz: float) -> tuple[FloatArray, int]:
        """Mean pressure per channel over the last ``RECENT_S`` of frames read, Pa, and rows.

        NaN rows (a missing module) are left out per channel; an empty history gives an empty
        array and 0. ``rate_hz``: the frame rate, Hz.
        """
        if not self._recent:
            return np.zeros(0), 0
        rows = np.concatenate(list(self._recent))
        rows = rows[-self._keep_rows(rate_hz):]
        with np.errstate(invalid="ignore"):
            counted = np.isfinite(rows).sum(axis=0)
            mean = np.where(counted > 0, np.nansum(rows, axis=0) / np.maximum(counted, 1),
                            np.nan)
        return mean, int(rows.shape[0])
