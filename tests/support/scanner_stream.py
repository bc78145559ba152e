"""A synthetic pressure-scanner stream with PLC trigger pulses, as the run writer receives it.

Exact clocks: every frame reaches the host ``LATENCY_S`` late, the PLC's pulses are at known host
times and their trigger events carry the command's round trip with the pulse at its midpoint
(legs alike). The callers build the frames' true and device times, counters and latched trigger
times; :func:`scanner_run_docs` cuts them into the writer's blocks and events.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from daq.acquisition.records import Event, StreamBlock
from daq.instruments.reading import Gap

#: Every frame arrives this late, s; off the sync grid, so no sync row is a sample.
LATENCY_S = 1.0003e-3
#: The PLC's trigger pulses (clock anchors), every 0.5 s from 0.25 s.
PULSE_S = 0.5
#: A PTP frame time's epoch, s.
PTP_EPOCH_S = 1_767_225_600.0
#: The run's time 0 on the host clock, ns.
T0_NS = 10_000_000_000
#: Frames per block.
BLOCK = 10


def ns(t: Any) -> Any:
    """Host time stamps (ns) of times ``t`` (s from the run start)."""
    return (T0_NS + np.round(np.asarray(t) * 1e9)).astype(np.int64)


def scanner_run_docs(true: np.ndarray, device: np.ndarray, counter: np.ndarray,
                     pressure: np.ndarray, trigger_time: np.ndarray, arrival: np.ndarray,
                     pulses: np.ndarray, *, round_trip_s: float = 4e-4,
                     restart_at: int | None = None) -> list[tuple[str, Any]]:
    """Start, scanner blocks of BLOCK frames, the pulses' trigger events, stop, in arrival order.

    Parameters
    ----------
    true, device : ndarray
        The frames' true times (s from the run start) and device times, s.
    counter : ndarray
        Their frame counters.
    pressure : ndarray, shape (n, 64)
        Their pressures, Pa (column 63 is the Pitot's).
    trigger_time : ndarray
        The scanner's latched last trigger time at each frame, s on its clock (NaN: none yet).
    arrival : ndarray
        Each frame's host arrival time, s from the run start (a block arrives with its last).
    pulses : ndarray
        The PLC's trigger pulses, host s from the run start; each event reaches the writer when
        the reply came back, half the round trip later.
    round_trip_s : float
        The pulse commands' round trip, s.
    restart_at : int or None
        Frame index after which the driver reports a restart gap.
    """
    items: list[tuple[float, str, Any]] = []
    for seq, lo in enumerate(range(0, true.size, BLOCK)):
        sl = slice(lo, lo + BLOCK)
        restart = restart_at is not None and lo <= restart_at < lo + BLOCK
        items.append((float(arrival[sl][-1]), "block", StreamBlock(
            device="scanner", kind="scanner", seq=seq, host_time_ns=ns(arrival[sl]),
            device_time=device[sl], counter=counter[sl],
            values={"pressure": pressure[sl], "pitot": pressure[sl, 63],
                    "trigger_time": trigger_time[sl]},
            gaps=(Gap(restart_at, -1, "restart"),) if restart else ())))
    for t in pulses:
        items.append((float(t) + 0.5 * round_trip_s, "event", Event(
            kind="trigger", host_time_ns=int(ns(t)), device="plc", text="trigger pulse",
            data={"round_trip_s": round_trip_s})))
    items.sort(key=lambda item: item[0])
    docs: list[tuple[str, Any]] = [("start", {"host_time_ns": T0_NS, "devices": {
        "scanner": {"kind": "scanner", "describe": {}}}})]
    docs += [(name, doc) for _, name, doc in items]
    docs.append(("stop", {"reason": "duration", "duration_s": float(true[-1])}))
    return docs
