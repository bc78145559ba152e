"""What the Scanivalve MPS4264-class driver returns: scan blocks, their gaps and clock steps.

Responsibility: the immutable results of
:meth:`~daq.instruments.scanivalve_mps4264.driver.ScanivalveMps4264.read_block`: :class:`ScanBlock`
(the frames of one read merged over modules, one row per frame number; gaps are
:class:`~daq.instruments.reading.Gap` of kind ``"missing"`` or ``"restart"``), the
:class:`ClockStep` records it carries, and the ``module_status`` codes of its rows
(:data:`STATUS_OK`, :data:`STATUS_MISSING`, :data:`STATUS_VALVE_CAL`). Not responsible for:
producing them (:mod:`daq.instruments.scanivalve_mps4264.merge` and the driver) or mapping their
device times onto the host clock (:mod:`daq.sync`, through the run writer). No I/O: frozen
dataclasses only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from daq.instruments.reading import Gap

__all__ = [
    "STATUS_MISSING",
    "STATUS_OK",
    "STATUS_VALVE_CAL",
    "ClockStep",
    "ScanBlock",
]

#: ``module_status`` codes of a :class:`ScanBlock` row.
STATUS_OK = 0
#: The module sent no packet for this frame number (pressures and temperatures NaN).
STATUS_MISSING = 1
#: The module's calibration valve was in the Cal position (``valve_status`` 1): pressures NaN.
STATUS_VALVE_CAL = 2


@dataclass(frozen=True)
class ClockStep:
    """A jump of the frame time against the counter (e.g. when PTP locks).

    Attributes
    ----------
    counter : int
        Unwrapped counter of the first frame after the step.
    step_s : float
        Frame time minus the time the counter and rate predict, s.
    """

    counter: int
    step_s: float


@dataclass(frozen=True, eq=False)
class ScanBlock:
    """Frames read in one call, merged over modules (one row per frame number).

    Attributes
    ----------
    counter : ndarray of int64, (n,)
        Unwrapped frame counter (continues across device-counter wraps and restarts).
    frame_time : ndarray of float64, (n,)
        Device frame time, s (PTP absolute, or relative to the scan start: see ``time_base``).
    trigger_time : ndarray of float64, (n,)
        Last external trigger on the frame-time base, s; NaN when none (or 0x6D packets).
    host_time_ns : ndarray of int64, (n,)
        Host ``time.monotonic_ns()`` when the frame's last module packet arrived (the return of
        the read that delivered its last byte), ns.
    pressure : ndarray of float64, (n, 64 * modules)
        Pa; NaN where ``module_status`` is not ``STATUS_OK``.
    pitot : ndarray of float64, (n,)
        Dynamic pressure of the Pitot channel, Pa (a copy of that pressure column).
    temperature : ndarray of float64, (n, 8 * modules)
        Module temperatures, degC; NaN for missing modules.
    module_status : ndarray of int8, (n, modules)
        ``STATUS_OK``, ``STATUS_MISSING`` or ``STATUS_VALVE_CAL`` per module: the reason of NaN.
    gaps : tuple of Gap
        Counter gaps and restarts before or inside this block.
    clock_steps : tuple of ClockStep
        Frame-time jumps detected before or inside this block.
    time_base : str
        ``"ptp"``, ``"relative"`` (frame times < 1e9 s: PTP absent, epoch 0) or ``"mixed"``.
    """

    counter: npt.NDArray[np.int64]
    frame_time: npt.NDArray[np.float64]
    trigger_time: npt.NDArray[np.float64]
    host_time_ns: npt.NDArray[np.int64]
    pressure: npt.NDArray[np.float64]
    pitot: npt.NDArray[np.float64]
    temperature: npt.NDArray[np.float64]
    module_status: npt.NDArray[np.int8]
    gaps: tuple[Gap, ...] = ()
    clock_steps: tuple[ClockStep, ...] = ()
    time_base: str = "ptp"

    def __len__(self) -> int:
        return int(self.counter.size)
