"""What the simulated scanner did: the frames produced, sent and dropped, per module.

Responsibility: :class:`SimTruth`, the truth counters a test reads to prove that no frame was
lost that the simulator did not drop (with the reason), and :class:`FrameRuns`, the frame
counters kept as runs so that a long gapless scan costs constant memory.

Not responsible for: producing or sending the frames
(:mod:`simulators.devices.scanivalve_mps4264.scanner`,
:mod:`simulators.devices.scanivalve_mps4264.servers`), which fill it in under the scanner's lock.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

__all__ = ["FrameRuns", "SimTruth"]


class FrameRuns:
    """Frame counters kept as runs ``[scan id, first, last]``: constant memory while gapless."""

    def __init__(self) -> None:
        self.runs: list[list[int]] = []

    def add(self, scan_id: int, counter: int) -> None:
        """Record one frame."""
        if self.runs and self.runs[-1][0] == scan_id and self.runs[-1][2] + 1 == counter:
            self.runs[-1][2] = counter
        else:
            self.runs.append([scan_id, counter, counter])

    def counters(self, scan_id: int) -> npt.NDArray[np.int64]:
        """Counters recorded for ``scan_id``, in the order recorded."""
        parts = [np.arange(first, last + 1) for s, first, last in self.runs if s == scan_id]
        return np.concatenate(parts).astype(np.int64) if parts else np.zeros(0, np.int64)

    def __len__(self) -> int:
        return sum(last - first + 1 for _, first, last in self.runs)


@dataclass
class SimTruth:
    """What the simulator did, per module: frames produced, sent and dropped.

    A scan id starts at 1 with the first ``SCAN`` and increases at every ``SCAN`` and at every
    restart after a ``tcp_reset``. ``produced`` and ``sent`` (bytes handed to the client's
    connection) are :class:`FrameRuns`; ``dropped`` holds ``(scan id, counter, reason)`` with
    reasons ``"fault"`` (``drop_frames``), ``"overrun"`` (buffer full), ``"reset"`` (lost in a
    TCP reset) and ``"superseded"`` (unsent at the next ``SCAN``). ``calz_wind_speeds`` lists
    the wind speed (m/s) at every CALZ.
    """

    produced: list[FrameRuns] = field(default_factory=list)
    sent: list[FrameRuns] = field(default_factory=list)
    dropped: list[list[tuple[int, int, str]]] = field(default_factory=list)
    calz_wind_speeds: list[float] = field(default_factory=list)

    def sent_counters(self, module: int, scan_id: int) -> npt.NDArray[np.int64]:
        """Counters of the frames of ``scan_id`` whose bytes went to a client, in order."""
        return self.sent[module].counters(scan_id)

    def dropped_counters(self, module: int, scan_id: int,
                         reason: str | None = None) -> npt.NDArray[np.int64]:
        """Counters of the frames of ``scan_id`` dropped (for ``reason``, or any), sorted."""
        return np.array(sorted(c for s, c, r in self.dropped[module]
                               if s == scan_id and (reason is None or r == reason)), np.int64)
