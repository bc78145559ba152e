"""The check of a rig before a test: every configured device contacted, read and judged.

Responsibility: :func:`check_rig` builds every instrument's driver of a rig config
(:func:`daq.instruments.build.build_driver`), and checks each device on a thread of its own, so
that one unreachable or silent device neither stops nor delays the others: open it (reachable),
ask its identity where its protocol gives one (the scanner's state and module serial numbers,
the lasers' ``GETINFO``; the fan drive, the PLC and the barometer as windrig drives them give
none), read it for a short window, measure its rate (on the device's own clock where it has
one) and its clock against the host's, judge a few readings for a wind-off rig at rest, close
it. Each device gives one :class:`CheckResult`; :func:`format_table` prints them as one table,
:func:`failure_lines` one line per failing device. ``windrig check``, ``windrig acquire`` and
the live console run it before anything starts (:func:`require_devices_ok`).

The plausibility rules (:class:`CheckLimits`, every threshold with its reason):

- scanner: every module present, tap and Pitot pressures near zero (the wind is off), frame
  rate as configured;
- lasers: valid distances (no error values) inside the measuring range, rate as configured;
- barometer: pressure and temperature of a laboratory (the PTB330's range is 500 to 1100 hPa);
- fan drive: in remote (fieldbus) control, not tripped, stopped;
- PLC: its inputs readable and consistent (armed with RELEASED set means the armature left an
  energised magnet);
- analog inputs (a Pitot transducer, a balance): valid readings (inside the input range and
  the channels' ``valid_volts``), rate as configured.

A device's clock is reported as its time base and its rate against the host's: device time
advanced over host time during the window (a stuck clock, or one in the wrong unit, is off by
far more than :attr:`CheckLimits.clock_rate_tolerance`). A PTP-locked scanner's frame times
are compared with the host's UTC too (a note, not a failure: the synchronisation fits every
clock's offset from the trigger anchors, whatever it is).

Not responsible for: starting simulators (the command line passes a simulated rig's URLs in, as
for a recording), or deciding what to do about a failure (the callers).

What each kind of device is read for and judged by (its rate, its clock, its readings) is
:mod:`daq.acquisition.device_inspections`, with the thresholds (:class:`CheckLimits`); this
module runs the checks and reports them.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from daq.acquisition.device_inspections import INSPECT, CheckLimits, Findings
from daq.acquisition.drivers import ROLE_KINDS
from daq.config import InstrumentConfig, RigConfig
from daq.errors import DaqError, DeviceCheckError, PluginError
from daq.instruments.build import build_driver
from daq.instruments.reading import Reading, ReadingContract

__all__ = ["CheckLimits", "CheckResult", "check_rig", "failure_lines", "format_table",
           "require_devices_ok"]

log = logging.getLogger(__name__)

@dataclass(frozen=True)
class CheckResult:
    """What the check found on one device.

    Attributes
    ----------
    device, driver, url, kind : str
        The instrument's name, driver, transport URL and engine kind (``scanner``, ``laser``,
        ``fan``, ``plc``, ``barometer``).
    reachable : bool
        The driver opened (the device answered).
    identity : str
        Identity and firmware as the protocol gives them ("" when it gives none).
    rate_hz : float or None
        Measured rate, Hz: samples per second of the device's own clock (scanner, lasers).
    nominal_rate_hz : float or None
        The configured rate, Hz (clocked devices).
    poll_s : float or None
        Median round trip of one poll, s (the polled devices: fan, PLC, barometer).
    clock : str
        The device's time base and its time against the host's ("" for devices without a
        clock).
    readings : str
        A summary of what was read (pressures, distances, p and T, speed, PLC state).
    problems : tuple of str
        Why the device fails the check (empty: it passes).
    notes : tuple of str
        Facts worth knowing that do not fail the check.
    elapsed_s : float
        Time the device's check took, s.
    """

    device: str
    driver: str
    url: str
    kind: str
    reachable: bool = False
    identity: str = ""
    rate_hz: float | None = None
    nominal_rate_hz: float | None = None
    poll_s: float | None = None
    clock: str = ""
    readings: str = ""
    problems: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    elapsed_s: float = 0.0

    @property
    def ok(self) -> bool:
        """Tell whether the device passed (no problems)."""
        return not self.problems

    def to_dict(self) -> dict[str, Any]:
        """Return the result as JSON-ready values (``ok`` included)."""
        out = dataclasses.asdict(self)
        out["problems"], out["notes"] = list(self.problems), list(self.notes)
        out["ok"] = self.ok
        return out


def check_rig(config: RigConfig, *, timeout_s: float = 2.0, window_s: float = 0.5,
              limits: CheckLimits | None = None,
              only: Sequence[str] | None = None) -> list[CheckResult]:
    """Check every device of a rig (each on its own thread); return one result per device.

    Parameters
    ----------
    config : RigConfig
        The rig; its URLs must be real (a simulated rig's filled in by whoever started it).
    timeout_s : float
        Longest time one device's check may take, s (> ``window_s``): a device that has not
        finished by then is reported as not answering, and its driver is closed under it.
    window_s : float
        How long each device is read, s.
    limits : CheckLimits, optional
        Thresholds of the plausibility checks.
    only : sequence of str, optional
        Check only these instruments (by name).

    Returns
    -------
    list of CheckResult
        In the config's order.
    """
    if not (math.isfinite(window_s) and window_s > 0 and math.isfinite(timeout_s)
            and timeout_s > window_s):
        raise ValueError(f"need 0 < window_s < timeout_s, got window_s = {window_s!r}, "
                         f"timeout_s = {timeout_s!r}")
    limits = CheckLimits() if limits is None else limits
    instruments = [inst for inst in config.instruments if only is None or inst.name in only]
    if only is not None:
        unknown = sorted(set(only) - {inst.name for inst in instruments})
        if unknown:
            raise ValueError(f"no instrument named {unknown}; have "
                             f"{[inst.name for inst in config.instruments]}")
    checks = [_DeviceCheck(inst, config, limits, window_s) for inst in instruments]
    deadline = time.monotonic() + timeout_s
    for check in checks:
        check.thread.start()
    for check in checks:
        check.thread.join(max(deadline - time.monotonic(), 0.0))
    for check in checks:
        if check.thread.is_alive():
            check.abandon(timeout_s)
    for check in checks:  # closing the driver unblocks a read; give it a moment to end
        check.thread.join(1.0)
    return [check.result() for check in checks]


def require_devices_ok(config: RigConfig, **options: Any) -> list[CheckResult]:
    """Run :func:`check_rig`; raise if any device fails, naming every failing one.

    Returns
    -------
    list of CheckResult
        Every device's result (all passed).

    Raises
    ------
    DeviceCheckError
        One line per failing device (:func:`failure_lines`).
    """
    results = check_rig(config, **options)
    failed = failure_lines(results)
    if failed:
        raise DeviceCheckError(f"{config.source}: device check failed for "
                               f"{len(failed)} of {len(results)} device(s):\n"
                               + "\n".join(failed))
    return results


def failure_lines(results: Sequence[CheckResult]) -> list[str]:
    """Return one line per failing device: its name, URL and every reason."""
    return [f"{r.device} ({r.url}): {'; '.join(r.problems)}" for r in results if not r.ok]


def format_table(results: Sequence[CheckResult]) -> str:
    """Return the results as a text table, one row per device, and the notes under it."""
    header = ("device", "driver", "url", "reachable", "identity", "rate", "clock", "readings",
              "check")
    rows = [header]
    for r in results:
        rate = "" if r.rate_hz is None else f"{r.rate_hz:.1f} Hz"
        if r.nominal_rate_hz is not None and r.rate_hz is not None:
            rate += f" (of {r.nominal_rate_hz:g})"
        if r.poll_s is not None:
            rate = f"poll {r.poll_s * 1e3:.1f} ms"
        rows.append((r.device, r.driver, r.url, "yes" if r.reachable else "NO",
                     r.identity or "-", rate or "-", r.clock or "-", r.readings or "-",
                     "OK" if r.ok else "FAIL"))
    widths = [max(len(row[i]) for row in rows) for i in range(len(header))]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip()
             for row in rows]
    for r in results:
        lines += [f"note: {r.device}: {note}" for note in r.notes]
    return "\n".join(lines)


class _DeviceCheck:
    """One device's check, on a thread of its own (see :func:`check_rig`)."""

    def __init__(self, inst: InstrumentConfig, config: RigConfig, limits: CheckLimits,
                 window_s: float) -> None:
        self.inst = inst
        self.kind = ROLE_KINDS[inst.role]
        self.config = config
        self.limits = limits
        self.window_s = window_s
        self.found = Findings()
        self.driver: Any = None
        self._contract: ReadingContract  # once the driver is built (_run)
        self._lock = threading.Lock()
        self._abandoned: str | None = None
        self._gave_up = False  # the device's own thread ended its check on an exception
        self._start = time.monotonic()
        self._elapsed = 0.0
        self.thread = threading.Thread(target=self._run, name=f"windrig-check-{inst.name}",
                                       daemon=True)

    def abandon(self, timeout_s: float) -> None:
        """Give up on a device that did not finish in time: say so, close its driver."""
        with self._lock:
            # The driver's own timeout may have fired a moment before ours (a scanner's command
            # timeout is 2 s, the check's default too): then its failure says why already, and a
            # second line for the same silence would only confuse.
            if not self._gave_up:
                self._abandoned = f"no answer within {timeout_s:g} s"
            self._elapsed = time.monotonic() - self._start
        driver = self.driver
        if driver is not None:
            try:
                driver.close()
            except Exception:  # the check has failed already; closing is best effort
                log.debug("closing %s after its timeout failed", self.inst.name, exc_info=True)

    def result(self) -> CheckResult:
        with self._lock:
            values = dataclasses.asdict(self.found)  # every finding, by the same field names
            abandoned = [] if self._abandoned is None else [self._abandoned]
            values["problems"] = tuple(values["problems"] + abandoned)
            values["notes"] = tuple(values["notes"])
            elapsed = self._elapsed
        return CheckResult(device=self.inst.name, driver=self.inst.driver, url=self.inst.url,
                           kind=self.kind, elapsed_s=elapsed, **values)

    # -- the device's thread ---------------------------------------------------------------------
    def _run(self) -> None:
        # Every exception of a device's check fails that device, whatever its type: a driver
        # (a plugin's above all) may raise anything, and a check that let an AttributeError
        # escape its thread used to print a traceback and then count the device as OK. The
        # exception is not swallowed: it becomes the device's problem (type and message, one
        # line), and its traceback goes to the log at DEBUG (``windrig --debug check``).
        found = self.found
        try:
            self.driver = build_driver(self.inst, self.config.limits)
        except Exception as exc:
            self._failed("cannot build the driver", exc)
            return self._done()
        self._contract = ReadingContract(self.driver)
        try:
            try:
                self.driver.open()
            except Exception as exc:
                # A device that accepts the connection and stays silent is there but mute.
                self._failed("no answer" if isinstance(exc, TimeoutError) else "unreachable",
                             exc)
                return self._done()
            found.reachable = True
            INSPECT[self.kind](self, self.driver, found)
        except Exception as exc:
            self._failed("check failed", exc)
        finally:
            try:
                self.driver.close()
            except Exception as exc:  # the readings are in; a failed close is worth a note
                log.debug("closing %s failed", self.inst.name, exc_info=True)
                found.notes.append(f"closing failed: {_failure(exc)}")
            self._done()

    def _failed(self, what: str, exc: Exception) -> None:
        """Record ``exc`` as this device's problem (one line), its traceback in the log."""
        log.debug("device check of %s: %s", self.inst.name, what, exc_info=exc)
        with self._lock:
            if self._abandoned is None:  # else: closed under it, "no answer within" says why
                self.found.problems.append(f"{what}: {_failure(exc)}")
                self._gave_up = True

    def _done(self) -> None:
        with self._lock:
            if self._abandoned is None:
                self._elapsed = time.monotonic() - self._start

    def stream(self, read: Callable[[float], Reading]) -> list[Reading]:
        """Read a streaming device for ``window_s``; return its readings."""
        readings: list[Reading] = []
        end = time.monotonic() + self.window_s
        while (left := end - time.monotonic()) > 0 and self._abandoned is None:
            try:
                readings.append(self._checked(read(min(left, 0.2))))
            except TimeoutError:  # TransportTimeout: nothing within the slice, go on
                continue
        return readings

    def polls(self, read: Callable[[], Reading], n: int = 3) -> list[Reading]:
        """Poll a device ``n`` times over ``window_s``; measure the median round trip."""
        readings: list[Reading] = []
        trips: list[float] = []
        start = time.monotonic()
        for i in range(n):
            if self._abandoned is not None:
                break
            sent = time.monotonic()
            readings.append(self._checked(read()))
            trips.append(time.monotonic() - sent)
            wait = start + (i + 1) * self.window_s / n - time.monotonic()
            if i + 1 < n and wait > 0:
                time.sleep(wait)
        self.found.poll_s = float(np.median(trips)) if trips else None
        return readings

    def _checked(self, reading: Reading) -> Reading:
        """Return ``reading`` if the engine would record it, else raise what breaks it.

        The engine checks every reading the same way (:class:`ReadingContract`) and stops
        reading a device whose driver breaks the contract; the check says so before a run,
        rather than judge a reading of the wrong shape (the first of two values read as the
        pressure).

        Raises
        ------
        PluginError
            The reading differs from the driver's ``describe()``, or its counter goes back.
        """
        breach = self._contract.breach(reading)
        if breach is not None:
            raise PluginError(breach)
        return reading


def _why(exc: BaseException) -> str:
    """One line for an exception: its message, or its type when it has none."""
    text = " ".join(str(exc).split())
    return text or type(exc).__name__


def _failure(exc: BaseException) -> str:
    """One line for an exception: ``KeyError: 'pressure'``, or a windrig error's own message.

    The type is said for every exception that is not windrig's own: a ``KeyError``'s message
    alone is a bare key, and an unexpected type (``AttributeError`` from a driver) is itself the
    news. A :class:`~daq.errors.DaqError` carries a message written for the operator (it names
    the device and what to do); its type would only be noise.
    """
    text = " ".join(str(exc).split())
    if isinstance(exc, DaqError) and text:
        return text
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__
