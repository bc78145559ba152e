"""Trigger pulses every half second during a run: the anchors of the device clock maps.

Responsibility: :func:`start_sync_pulses` starts a :class:`SyncPulses` thread that asks the
engine (:meth:`daq.acquisition.engine.Acquisition.trigger`) to pulse the PLC's trigger line
every ``interval_s``; each pulse is recorded by the engine as a ``"trigger"`` event, which the
run writer pairs with the trigger times the scanner latches and the lasers flag (clock anchors,
:class:`daq.sync.clock_map.ClockMap`). A failed pulse is counted and logged; the run goes on.

Not responsible for: the pairing (:class:`daq.recording.writer.RunWriter`) or the PLC's protocol
(:mod:`daq.instruments.modbus_plc.driver`).
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Mapping
from typing import Any

from daq.errors import DaqError

__all__ = ["SYNC_PULSE_INTERVAL_S", "SyncPulses", "start_sync_pulses"]

log = logging.getLogger(__name__)

#: Default interval of the trigger pulses a run sends as clock anchors, s.
SYNC_PULSE_INTERVAL_S = 0.5


class SyncPulses:
    """A thread pulsing the PLC's trigger line every ``interval_s`` (clock-map anchors).

    Start it with :func:`start_sync_pulses`; :meth:`stop` ends it. ``failures`` counts the
    pulses that failed (each logged; the PLC's own fault reporting covers the link).
    """

    def __init__(self, acq: Any, interval_s: float) -> None:
        self._acq = acq
        self._interval_s = interval_s
        self._stop = threading.Event()
        self.failures = 0
        self._thread = threading.Thread(target=self._run, name="windrig-sync-pulses",
                                        daemon=True)

    def start(self) -> None:
        """Start pulsing."""
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self._interval_s):
            try:
                self._acq.trigger()
            except DaqError as exc:  # the PLC's own fault reporting covers the link
                self.failures += 1
                log.warning("sync pulse failed (%d so far): %s", self.failures, exc)

    def stop(self) -> None:
        """Stop pulsing and join the thread."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0 + self._interval_s)


def start_sync_pulses(acq: Any, drivers: Mapping[str, tuple[str, Any]],
                      interval_s: float | None) -> SyncPulses | None:
    """Pulse the PLC's trigger line every ``interval_s`` while ``acq`` runs.

    Parameters
    ----------
    acq : Acquisition
        The running engine (its :meth:`~daq.acquisition.engine.Acquisition.trigger` is called).
    drivers : mapping
        The engine's ``name -> (kind, driver)``: without a ``"plc"`` there is nothing to pulse.
    interval_s : float or None
        Interval, s (> 0); None: no pulses.

    Returns
    -------
    SyncPulses or None
        The running pulser (call ``stop()``), or None when there is none.
    """
    if interval_s is None or not any(kind == "plc" for kind, _ in drivers.values()):
        return None
    if not (math.isfinite(interval_s) and interval_s > 0):
        raise ValueError(f"sync_pulse_interval_s must be > 0 s or None, got {interval_s!r}")
    pulser = SyncPulses(acq, float(interval_s))
    pulser.start()
    return pulser
