"""Zeroing the pressure scanner (CALZ) during a run: the engine's pause of the scan, step by step.

Responsibility: the procedure :meth:`daq.acquisition.engine.Acquisition.calz` runs once it holds
its CALZ lock and has checked that it runs: the driver's wind-off rule applied before anything
is touched (:func:`refuse_unsafe_calz`), then the pause itself (:func:`run_calz`): park the
scanner's reader between two reads, STOP, deliver the frames still in flight, measure the zero
the CALZ will remove, CALZ, restart the scan (:func:`restart_scan`, retried while the scanner
still zeroes), resume the reader; every failure posted as a ``"calz_failed"`` event
(:func:`post_calz_failed`), success as a ``"calz"`` event and a :class:`CalzResult`.

Not responsible for: when a CALZ is allowed (the driver refuses a nonzero wind; the console's
interlocks, :mod:`daq.console.interlocks`, ask for the fan stopped and the wind settled), the
reader's own parking (:mod:`daq.acquisition.reader`), or the scanner's protocol and the gap it
marks over the pause (the driver, :mod:`daq.instruments.scanivalve_mps4264.continuity`).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from daq.acquisition.reader import DeviceReader
from daq.acquisition.records import (
    Event,
    FloatArray,
)
from daq.errors import CalzError, DaqError

if TYPE_CHECKING:
    pass

__all__ = ["RESTART_WAIT_S", "CalzResult", "offsets_summary", "post_calz_failed",
           "refuse_unsafe_calz", "restart_scan", "run_calz"]

log = logging.getLogger(__name__)
#: After a CALZ that timed out the scanner may still be zeroing: how long a restart of the scan
#: keeps trying, s (the manual: a CALZ takes "under 10 seconds").
RESTART_WAIT_S = 10.0


@dataclass(frozen=True, eq=False)
class CalzResult:
    """What :meth:`Acquisition.calz` did: the pause of the scan and the zero it removed.

    Attributes
    ----------
    device : str
        The scanner.
    wind_speed_now : float
        The wind speed the caller vouched for, m/s (0: the driver refuses anything else).
    stop_ns, stopped_ns : int
        Host ``time.monotonic_ns()`` just before STOP was sent and once it was acknowledged:
        the scanner stopped in between.
    restart_ns, restarted_ns : int
        The same for the new scan: before the (successful) restart began and once SCAN was
        acknowledged.
    pause_s : float
        How long the scanner did not scan, s: from the middle of the STOP command to the
        middle of the restart, each known to within half its duration (a few ms; the bounds
        are ``(restart_ns - stopped_ns)`` and ``(restarted_ns - stop_ns)``).
    calz_s : float
        Time from CALZ to READY, s.
    offsets_before_pa : ndarray of float64, (channels,)
        Mean pressure per channel over the last frames before STOP (``frames_averaged`` of
        them), Pa. Wind-off (as a CALZ must be) this is the zero error the CALZ removed; NaN
        for a channel without a frame.
    frames_averaged : int
        Frames in that mean.
    event : Event
        The ``"calz"`` event posted.
    """

    device: str
    wind_speed_now: float
    stop_ns: int
    stopped_ns: int
    restart_ns: int
    restarted_ns: int
    pause_s: float
    calz_s: float
    offsets_before_pa: FloatArray
    frames_averaged: int
    event: Event

    def summary(self) -> dict[str, float | int]:
        """Zero-offset figures for an event or a status line (Pa): RMS, max and where."""
        return offsets_summary(self.offsets_before_pa, self.frames_averaged)


def offsets_summary(offsets: FloatArray, frames: int) -> dict[str, float | int]:
    """Zero-offset figures of a CALZ (Pa): mean, RMS, largest and its channel, frames averaged."""
    finite = np.isfinite(offsets)
    if not finite.any():
        return {"frames_averaged": frames, "channels": 0}
    abs_off = np.where(finite, np.abs(offsets), -1.0)
    worst = int(np.argmax(abs_off))
    return {"frames_averaged": frames, "channels": int(finite.sum()),
            "offset_mean_pa": float(np.mean(offsets[finite])),
            "offset_rms_pa": float(np.sqrt(np.mean(offsets[finite] ** 2))),
            "offset_max_abs_pa": float(abs_off[worst]), "offset_max_channel": worst}


def refuse_unsafe_calz(name: str, driver: Any, wind_speed_now: float,
                       post_event: Callable[[Event], None]) -> None:
    """Apply the driver's wind-off rule before the scan is touched (a refusal costs no data)."""
    check = getattr(driver, "check_calz_allowed", None)
    if not callable(check):
        return  # the driver's calz() still applies its rule, after STOP
    try:
        check(wind_speed_now=wind_speed_now)
    except DaqError as exc:
        post_event(Event(
            kind="calz_failed", host_time_ns=time.monotonic_ns(), device=name,
            text=f"CALZ refused, the scan goes on: {exc}",
            data={"stage": "refused", "error": type(exc).__name__,
                  "wind_speed_now": wind_speed_now, "scan_interrupted": False}))
        raise

def run_calz(name: str, reader: DeviceReader, wind_speed_now: float, timeout_s: float, *,
             join_timeout_s: float, post_event: Callable[[Event], None]) -> CalzResult:
    """Park the reader, STOP, drain, CALZ, restart the scan, resume: the steps of calz()."""
    driver = reader.driver
    if not reader.pause(join_timeout_s):
        reader.resume()
        why = (f"the reader of {name!r} did not pause within {join_timeout_s:g} s "
               "(stuck in a read or a reconnect?)")
        post_calz_failed(post_event, name, "pause", why, time.monotonic_ns(), restarted=None)
        raise CalzError(f"CALZ of {name!r} not started: {why}; nothing was interrupted, "
                        "the scan goes on")
    stage = "stop"
    failure: DaqError | None = None
    calz_s = math.nan
    offsets, frames = np.zeros(0), 0
    stop_ns = stopped_ns = time.monotonic_ns()
    try:
        try:
            driver.stop()
            stopped_ns = time.monotonic_ns()
            # Frames sent before STOP are data like any other: deliver them, so that the
            # gap is only the time the scanner stood still.
            rate = float(getattr(driver, "rate_hz", 0.0) or 0.0)
            reader.drain(max(0.05, 5.0 / rate) if rate > 0 else 0.2)
            offsets, frames = reader.recent_pressure_mean()
            stage = "calz"
            took = driver.calz(wind_speed_now=wind_speed_now, timeout_s=timeout_s)
            calz_s = float(took) if isinstance(took, (int, float)) else math.nan
            stage = "restart"
        except DaqError as exc:
            failure = exc
        finally:  # also on a bug or Ctrl-C: the scan must run again if at all possible
            restart_error, restart_ns = restart_scan(name, reader)
            restarted_ns = time.monotonic_ns()
            # Each end of the standstill is known to within half its command's duration.
            pause_s = ((restart_ns + restarted_ns) - (stop_ns + stopped_ns)) * 0.5e-9
            reader.note_pause(pause_s)
    finally:
        reader.resume()
    if restart_error is not None:
        reader.report_fault(restart_error)
        if failure is None:
            stage, failure = "restart", restart_error
    if failure is not None:
        post_calz_failed(post_event, name, stage, failure, stop_ns, restarted=restart_error is None,
                          pause_s=pause_s)
        state = (f"the scan was restarted after {pause_s:.2f} s" if restart_error is None
                 else f"the scan could NOT be restarted ({restart_error}); the reader's "
                 "recovery retries")
        raise CalzError(f"CALZ of {name!r} failed at {stage}: {failure}; {state}") \
            from failure
    summary = offsets_summary(offsets, frames)
    event = Event(kind="calz", host_time_ns=stop_ns, device=name,
                  text=f"scanner zeroed (CALZ, wind {wind_speed_now:g} m/s); scan paused "
                       f"{pause_s:.3f} s",
                  data={"pause_s": pause_s, "calz_s": calz_s, "stop_ns": stop_ns,
                        "stopped_ns": stopped_ns, "restart_ns": restart_ns,
                        "restarted_ns": restarted_ns, "wind_speed_now": wind_speed_now,
                        **summary, "offsets_before_pa": offsets.copy()})
    post_event(event)
    log.info("%s: CALZ done; scan paused %.3f s; zero removed: %s", name, pause_s, summary)
    return CalzResult(device=name, wind_speed_now=wind_speed_now, stop_ns=stop_ns,
                      stopped_ns=stopped_ns, restart_ns=restart_ns,
                      restarted_ns=restarted_ns, pause_s=pause_s, calz_s=calz_s,
                      offsets_before_pa=offsets, frames_averaged=frames, event=event)

def restart_scan(name: str, reader: DeviceReader) -> tuple[DaqError | None, int]:
    """Start the scan again after a pause; return the error when it could not be.

    A refused SCAN is retried while the scanner still zeroes (a CALZ that timed out),
    for at most ``RESTART_WAIT_S``; a scanner found scanning already (STOP had failed)
    counts as restarted: it streams to the fresh data connections. Also returns the host
    time (ns) at which the last attempt began.
    """
    end = time.monotonic() + RESTART_WAIT_S
    while True:
        began = time.monotonic_ns()
        try:
            reader.restart_after_pause()
            return None, began
        except DaqError as exc:
            error = exc
        try:
            state = reader.driver.status()
        except DaqError as exc:
            log.error("%s: scan not restarted (%s); status failed too: %s", name, error, exc)
            return error, began
        if state == "SCAN":
            return None, began
        if state != "CALZ" or time.monotonic() >= end:
            log.error("%s: scan not restarted (state %s): %s", name, state, error)
            return error, began
        time.sleep(0.1)


def post_calz_failed(post_event: Callable[[Event], None], name: str, stage: str,
                     error: BaseException | str, at_ns: int, *, restarted: bool | None,
                     pause_s: float = 0.0) -> None:
    """Log a failed CALZ and post its ``"calz_failed"`` event (the stage, the error, the scan)."""
    log.error("%s: CALZ failed at %s: %s", name, stage, error)
    post_event(Event(
        kind="calz_failed", host_time_ns=at_ns, device=name,
        text=f"CALZ failed at {stage}: {error}",
        data={"stage": stage,
              "error": "timeout" if isinstance(error, str) else type(error).__name__,
              "scan_interrupted": restarted is not None, "scan_restarted": restarted,
              "pause_s": pause_s}))

