"""Operator commands on the rig's devices, each recorded as an event of the run.

Responsibility: what each operator command does to its driver and the
:class:`~daq.acquisition.records.Event` it posts: release and arm the model, disarm, pulse the
trigger line (the PLC); set the fan's speed reference, start it and stop it (the fan drive); an
operator's marker. A refused or failed command posts a ``"<command>_failed"`` event (its
``data["error"]`` names the exception) before the error is raised again, so the run records
what was asked as well as what was done. The event kinds are those of
:data:`~daq.acquisition.records.SYSTEM_EVENT_KINDS` (an operator's marker may not use them).

Not responsible for: finding the device and checking that the engine runs (the engine's
methods, :class:`~daq.acquisition.engine.Acquisition`, which call these), the CALZ
(:mod:`daq.acquisition.calz`), or whether a command is allowed in the operator's current state
(the drivers' own safety checks, and the console's :mod:`daq.console.interlocks`).

Times: every event carries a host ``time.monotonic_ns()``; where the device's action falls
between the request and the acknowledgement, both are kept (the event's time is stated per
command below).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from daq.acquisition.records import SYSTEM_EVENT_KINDS, Event
from daq.errors import DaqError

__all__ = ["arm", "disarm", "manual_hold", "manual_release", "marker", "release",
           "set_fan_speed", "start_fan", "stop_fan", "trigger"]

PostEvent = Callable[[Event], None]


def _failed(post_event: PostEvent, kind: str, name: str, requested_ns: int, exc: DaqError,
            **data: Any) -> None:
    post_event(Event(kind=kind, host_time_ns=requested_ns, device=name, text=str(exc),
                     data={"error": type(exc).__name__, **data}))


def _command(name: str, post_event: PostEvent | None, action: Callable[[], object], *, kind: str,
             text: str, data: dict[str, Any] | None = None, failed: str | None = None,
             failed_data: dict[str, Any] | None = None) -> Event:
    """Run ``action`` (a driver call); post its event at the request, or the failure's.

    The event's ``data`` gets ``acknowledged_ns`` (when the call returned). A
    :class:`~daq.errors.DaqError` posts ``failed`` (default ``"<kind>_failed"``) and is raised
    again. Nothing is posted when ``post_event`` is None.
    """
    requested = time.monotonic_ns()
    try:
        action()
    except DaqError as exc:
        if post_event is not None:
            _failed(post_event, failed or f"{kind}_failed", name, requested, exc,
                    **(failed_data or {}))
        raise
    event = Event(kind=kind, host_time_ns=requested, device=name, text=text,
                  data={**(data or {}), "acknowledged_ns": time.monotonic_ns()})
    if post_event is not None:
        post_event(event)
    return event


def marker(kind: str, text: str, device: str | None = None) -> Event:
    """Return a marker event of ``device`` (time: now); refuse an empty or reserved ``kind``."""
    if not isinstance(kind, str) or not kind.strip():
        raise ValueError(f"a marker kind is a non-empty string, got {kind!r}")
    if kind in SYSTEM_EVENT_KINDS:
        raise ValueError(f"marker kind {kind!r} is reserved for the engine's own events "
                         f"{sorted(SYSTEM_EVENT_KINDS)}")
    return Event(kind=kind, host_time_ns=time.monotonic_ns(), text=str(text), device=device)


def release(name: str, driver: Any, post_event: PostEvent) -> Event:
    """Release the model; post ``"release"`` at the PLC's acknowledgement of the RELEASE coil."""
    requested = time.monotonic_ns()
    try:
        timing = driver.release()
    except DaqError as exc:
        _failed(post_event, "release_failed", name, requested, exc)
        raise
    command = int(getattr(timing, "command_ns", requested))
    confirmed = int(getattr(timing, "confirmed_ns", command))
    round_trip = int(getattr(timing, "round_trip_ns", 0))
    event = Event(kind="release", host_time_ns=command, device=name, text="model released",
                  data={"requested_ns": requested, "command_ns": command,
                        "confirmed_ns": confirmed, "delay_s": (confirmed - command) * 1e-9,
                        "round_trip_s": round_trip * 1e-9})
    post_event(event)
    return event


def manual_release(post_event: PostEvent, text: str = "") -> Event:
    """Record the operator's word that the model was let go by hand; post ``"manual_release"``.

    The event's time is the key press (or button), some time *after* the release: the release
    instant itself is found in the lasers' signals by the run writer
    (:mod:`daq.recording.releases`, :func:`ident.records.release_onset.locate_release`).
    """
    event = Event(kind="manual_release", host_time_ns=time.monotonic_ns(),
                  text=text or "operator: model released by hand")
    post_event(event)
    return event


def manual_hold(post_event: PostEvent, text: str = "") -> Event:
    """Record the operator's word that the model is caught and held; post ``"manual_hold"``.

    Like an ``"arm"``, it ends the free decay of the last release: at the start of the still
    hold before the key press, found in the lasers' signals by the run writer.
    """
    event = Event(kind="manual_hold", host_time_ns=time.monotonic_ns(),
                  text=text or "operator: model caught and held by hand")
    post_event(event)
    return event


def arm(name: str, driver: Any, post_event: PostEvent) -> Event:
    """Arm the PLC; post ``"arm"`` at the request (the decay is surely free before it)."""
    return _command(name, post_event, driver.arm, kind="arm", text="release armed")


def disarm(name: str, driver: Any, post_event: PostEvent) -> Event:
    """Disarm the PLC (magnet off, no release permitted); post ``"disarm"`` at the request."""
    return _command(name, post_event, driver.disarm, kind="disarm", text="release disarmed")


def trigger(name: str, driver: Any, post_event: PostEvent) -> Event:
    """Pulse the trigger line; post ``"trigger"`` at the rising edge's time."""
    t_ns = int(driver.trigger_pulse())
    round_trip = int(getattr(driver, "last_trigger_round_trip_ns", 0))
    event = Event(kind="trigger", host_time_ns=t_ns, device=name, text="trigger pulse",
                  data={"round_trip_s": round_trip * 1e-9})
    post_event(event)
    return event


def set_fan_speed(name: str, driver: Any, rpm: float, post_event: PostEvent) -> Event:
    """Send the fan's speed reference; post ``"fan_speed"`` at the request, with ``rpm``."""
    return _command(name, post_event, lambda: driver.set_speed(rpm), kind="fan_speed",
                    text=f"fan speed reference {rpm:g} rpm", data={"rpm": rpm},
                    failed="fan_failed", failed_data={"command": "set_speed", "rpm": rpm})


def start_fan(name: str, driver: Any, post_event: PostEvent) -> Event:
    """Run the fan at its reference; post ``"fan_start"`` at the request."""
    return _command(name, post_event, driver.start, kind="fan_start", text="fan started",
                    failed="fan_failed", failed_data={"command": "start"})


def stop_fan(name: str, driver: Any, post_event: PostEvent | None) -> Event:
    """Stop the fan (ramp stop); post ``"fan_stop"`` at the request unless ``post_event`` is None.

    The engine stops the fan even when it records nothing (not running): a stop must never be
    refused for want of a place to record it.
    """
    return _command(name, post_event, driver.stop, kind="fan_stop", text="fan stopped",
                    failed="fan_failed", failed_data={"command": "stop"})
