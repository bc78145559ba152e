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

Longer than 600 lines: one device's check is one flow (open, identify, read, judge, close) and
the judges of the six roles write into its findings; apart, they would share its private state.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from daq.acquisition.drivers import ROLE_KINDS
from daq.config import InstrumentConfig, RigConfig
from daq.errors import DaqError, DeviceCheckError
from daq.instruments.build import build_driver
from daq.instruments.reading import Reading

__all__ = ["CheckLimits", "CheckResult", "check_rig", "failure_lines", "format_table",
           "require_devices_ok"]

log = logging.getLogger(__name__)

#: Frame times above this are on an absolute (PTP) base, s (2001-09-09; the scanner driver's own
#: rule for its ``time_base``).
_ABSOLUTE_TIME_S = 1e9


@dataclass(frozen=True)
class CheckLimits:
    """Thresholds of the plausibility checks.

    Attributes
    ----------
    zero_tolerance_pa : float
        Wind off, the median ``|p|`` over the taps and the Pitot's ``|p|`` must be below this, Pa.
        50 Pa lies above the zero offsets a scanner keeps between two CALZs (tens of Pa; the
        simulated scanner's are 10 Pa rms) and below the dynamic pressure of a test wind
        (q = 50 Pa at 9 m/s).
    rate_tolerance : float
        Measured rate of a clocked device (counter over device time) against its configured
        rate, relative. 2 %: a wrong setting is off by a factor, a healthy device by ppm.
    clock_rate_tolerance : float
        Device time advanced over host time during the window, relative. 10 %: the least
        latency of each half of a 0.5 s window is known to a few ms on a busy host (a few %);
        a stuck clock or one in the wrong unit is off by 100 % or more.
    laser_valid_fraction : float
        Fewest valid laser samples (no error value), fraction. A laser on its target at rest
        gives no error values; a few are allowed (a dust grain).
    pressure_range_pa : (float, float)
        A laboratory's air pressure, Pa: the PTB330's 500 to 1100 hPa range.
    temperature_range_k : (float, float)
        A laboratory's air temperature, K (-10 to 50 degC).
    fan_stopped_rpm : float
        The fan is stopped when ``|actual speed|`` is below this, rpm.
    """

    zero_tolerance_pa: float = 50.0
    rate_tolerance: float = 0.02
    clock_rate_tolerance: float = 0.10
    laser_valid_fraction: float = 0.99
    pressure_range_pa: tuple[float, float] = (50_000.0, 110_000.0)
    temperature_range_k: tuple[float, float] = (263.15, 323.15)
    fan_stopped_rpm: float = 5.0


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


@dataclass
class _Findings:
    """What one device's check collects as it goes (turned into a :class:`CheckResult`)."""

    reachable: bool = False
    identity: str = ""
    rate_hz: float | None = None
    nominal_rate_hz: float | None = None
    poll_s: float | None = None
    clock: str = ""
    readings: str = ""
    problems: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


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
        self.found = _Findings()
        self.driver: Any = None
        self._lock = threading.Lock()
        self._abandoned: str | None = None
        self._start = time.monotonic()
        self._elapsed = 0.0
        self.thread = threading.Thread(target=self._run, name=f"windrig-check-{inst.name}",
                                       daemon=True)

    def abandon(self, timeout_s: float) -> None:
        """Give up on a device that did not finish in time: say so, close its driver."""
        with self._lock:
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
        try:
            try:
                self.driver.open()
            except Exception as exc:
                if self._abandoned is None:  # else: closed under it, "no answer" says why
                    self._failed("unreachable", exc)
                return self._done()
            found.reachable = True
            INSPECT[self.kind](self, self.driver, found)
        except Exception as exc:
            if self._abandoned is None:
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
        self.found.problems.append(f"{what}: {_failure(exc)}")

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
                readings.append(read(min(left, 0.2)))
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
            readings.append(read())
            trips.append(time.monotonic() - sent)
            wait = start + (i + 1) * self.window_s / n - time.monotonic()
            if i + 1 < n and wait > 0:
                time.sleep(wait)
        self.found.poll_s = float(np.median(trips)) if trips else None
        return readings


# -- per kind ------------------------------------------------------------------------------------
def _clocked(check: _DeviceCheck, readings: list[Reading], nominal_hz: float,
             found: _Findings, read: Callable[[float], Reading] | None = None) -> None:
    """Rate on the device's clock, and the device clock against the host's.

    A clock ratio out of tolerance is measured once more on a second window (``read``, the
    device's streaming read) before it counts: a clock that is wrong is wrong again, while a
    host busy through one half of a window (a loaded test machine measured 1.24) is not.
    """
    found.nominal_rate_hz = float(nominal_hz)
    if not readings:
        found.problems.append(f"no data within {check.window_s:g} s")
        return
    counter = np.concatenate([r.counter for r in readings])
    host, device = _times(readings)
    if counter.size < 3 or device.size != counter.size:
        found.problems.append(f"only {counter.size} sample(s) in {check.window_s:g} s")
        return
    span = float(device[-1] - device[0])
    if not span > 0:
        found.problems.append(f"device clock does not advance ({device[0]!r} s throughout)")
        return
    found.rate_hz = float(counter[-1] - counter[0]) / span
    off = abs(found.rate_hz / nominal_hz - 1.0)
    if off > check.limits.rate_tolerance:
        found.problems.append(f"rate {found.rate_hz:.1f} Hz, configured {nominal_hz:g} Hz")
    ratio = _clock_ratio(host, device)
    tolerance = check.limits.clock_rate_tolerance
    if not abs(ratio - 1.0) <= tolerance and read is not None:
        first, ratio = ratio, _restreamed_ratio(check, read)
        if abs(ratio - 1.0) <= tolerance:
            found.notes.append(f"its clock ran at {first:.3f} x the host's over the first "
                               f"window and {ratio:.4f} x over a second: the host was busy")
    if not abs(ratio - 1.0) <= tolerance:
        found.problems.append(f"device clock runs at {ratio:.3f} x the host's")
    base = str(readings[-1].info.get("time_base", ""))
    if base == "ptp" or (not base and device[-1] > _ABSOLUTE_TIME_S):
        wall = time.time() - (time.monotonic() - host)
        offset = float(np.median(device - wall))
        found.clock = f"ptp, {_span(offset)} vs host UTC, rate x{ratio:.4f}"
        if abs(offset) > 1.0:
            found.notes.append(f"its PTP time is {_span(offset)} from the host's UTC (the "
                               "synchronisation fits the offset; PTP grandmaster not on UTC?)")
    elif base == "relative":
        found.clock = f"relative to the scan start (no PTP), rate x{ratio:.4f}"
        found.notes.append("frame times start at 0 with the scan: no PTP time")
    else:
        found.clock = f"free-running, t = {device[-1]:.3f} s, rate x{ratio:.4f}"


def _streaming_read(driver: Any) -> Callable[[float], Reading]:
    """Return ``read(timeout_s)`` of a streaming driver."""
    return lambda timeout_s: driver.read(timeout_s=timeout_s)


def _times(readings: list[Reading]) -> tuple[np.ndarray, np.ndarray]:
    """Return the host times (s) of every sample and the device times of those that have one."""
    host = np.concatenate([r.host_time_ns for r in readings]) * 1e-9
    device = np.concatenate([r.device_time for r in readings if r.device_time is not None])
    return host, device


def _restreamed_ratio(check: _DeviceCheck, read: Callable[[float], Reading]) -> float:
    """Return the clock ratio over a second window (nan without enough samples)."""
    readings = [r for r in check.stream(read) if r.device_time is not None]
    if sum(r.counter.size for r in readings) < 3:
        return float("nan")
    return _clock_ratio(*_times(readings))


def _clock_ratio(host: np.ndarray, device: np.ndarray) -> float:
    """Return device time advanced over host time, from the lower envelope of the latency.

    A sample arrives at the host some latency after the device stamped it; the least latency
    of each half of the window is the one least disturbed (a backlog at the start of a scan,
    a busy host), so the drift is the change of that least latency between the two halves.
    """
    lag = (host - host[0]) - (device - device[0])
    half = device.size // 2
    first, second = int(np.argmin(lag[:half])), half + int(np.argmin(lag[half:]))
    span = float(device[second] - device[first])
    if not span > 0:
        return float("nan")
    return 1.0 / (1.0 + float(lag[second] - lag[first]) / span)


def _scanner(check: _DeviceCheck, driver: Any, found: _Findings) -> None:
    state = driver.status()
    driver.start()
    try:
        readings = check.stream(_streaming_read(driver))
    finally:
        driver.stop()
    serials = [s for s in driver.serial_numbers if s is not None]
    found.identity = f"state {state}" + (f", S/N {', '.join(map(str, serials))}"
                                         if serials else "")
    _clocked(check, readings, float(check.inst.settings["rate_hz"]), found)
    if not readings:
        return
    pressure = np.concatenate([r.channels["pressure"] for r in readings])
    pitot = np.concatenate([r.channels["pitot"] for r in readings])
    status = np.concatenate([r.channels["module_status"] for r in readings])
    missing = sorted({int(k) for k in np.nonzero((status != 0).any(axis=0))[0]})
    if missing:
        found.problems.append(f"module(s) {missing} missing or on the calibration valve")
    n_taps = check.config.taps.n_taps
    taps = np.nanmean(pressure[:, :n_taps], axis=0) if n_taps else np.zeros(0)
    median = float(np.nanmedian(np.abs(taps))) if taps.size else 0.0
    largest = float(np.nanmax(np.abs(taps))) if taps.size else 0.0
    p_pitot = float(np.nanmean(pitot))
    found.readings = (f"taps median |p| {median:.1f} Pa (largest {largest:.1f}), Pitot "
                      f"{p_pitot:+.1f} Pa")
    tol = check.limits.zero_tolerance_pa
    if not (median <= tol and abs(p_pitot) <= tol):
        found.problems.append(f"pressures not near zero with the wind off (taps median |p| "
                              f"{median:.1f} Pa, Pitot {p_pitot:+.1f} Pa, allowed {tol:g} Pa): "
                              "wind on, or zero offsets large (CALZ)")


def _laser(check: _DeviceCheck, driver: Any, found: _Findings) -> None:
    info = driver.info()
    found.identity = ", ".join(
        f"{key.lower()} {info[key]}" for key in ("Name", "Serial", "Version") if key in info)
    read = _streaming_read(driver)
    readings = check.stream(read)
    _clocked(check, readings, float(check.inst.settings["rate_hz"]), found, read)
    if not readings:
        return
    distance = np.concatenate([r.channels["distance"] for r in readings])
    codes = np.concatenate([r.channels["error_code"] for r in readings])
    valid = (codes == 0) & np.isfinite(distance)
    fraction = float(valid.mean())
    range_m = float(check.inst.settings["range_mm"]) * 1e-3
    if not valid.any():
        found.readings = f"no valid distance (error values {sorted(set(codes.tolist()))[:3]})"
        found.problems.append(f"out of range: {found.readings}")
        return
    d = float(np.median(distance[valid]))
    found.readings = f"distance {d * 1e3:.2f} mm of {range_m * 1e3:g} mm, {fraction:.1%} valid"
    if fraction < check.limits.laser_valid_fraction:
        found.problems.append(f"only {fraction:.1%} of the distances valid (error values "
                              f"{sorted(set(codes[~valid].tolist()))[:3]})")
    if not 0.0 <= d <= range_m:
        found.problems.append(f"distance {d * 1e3:.2f} mm outside the measuring range "
                              f"0..{range_m * 1e3:g} mm")


def _barometer(check: _DeviceCheck, driver: Any, found: _Findings) -> None:
    readings = check.polls(driver.read)
    p = float(np.median([r.channels["pressure"][0] for r in readings]))
    t = float(np.median([r.channels["temperature"][0] for r in readings]))
    rho = float(np.median([r.channels["density"][0] for r in readings]))
    found.readings = f"p {p / 100:.2f} hPa, T {t - 273.15:.2f} degC, rho {rho:.4f} kg/m^3"
    (p_lo, p_hi), (t_lo, t_hi) = check.limits.pressure_range_pa, check.limits.temperature_range_k
    if not p_lo <= p <= p_hi:
        found.problems.append(f"pressure {p / 100:.2f} hPa outside {p_lo / 100:g}.."
                              f"{p_hi / 100:g} hPa")
    if not t_lo <= t <= t_hi:
        found.problems.append(f"temperature {t - 273.15:.2f} degC outside "
                              f"{t_lo - 273.15:g}..{t_hi - 273.15:g} degC")


def _fan(check: _DeviceCheck, driver: Any, found: _Findings) -> None:
    readings = check.polls(driver.read)
    speed = float(readings[-1].channels["speed"][0])
    # The drive's own status (the fan role's ``status()``, docs/guides/drivers.md): what its bits
    # mean is the driver's business (an ABB drive's differ from a PROFIdrive one's).
    status = driver.status()
    word = int(status.word)
    found.readings = (f"{speed:.0f} rpm, SW {word:#06x} "
                      f"({', '.join(status.active()) or 'no bits'})")
    if status.tripped:
        found.problems.append(f"drive tripped (SW {status.word:#06x}): reset it")
    if not status.remote:
        found.problems.append("drive not in remote (fieldbus) control: windrig cannot command it")
    if abs(speed) > check.limits.fan_stopped_rpm:
        found.problems.append(f"fan running at {speed:.0f} rpm: a check expects the wind off "
                              "(stop the fan, or skip the check)")


def _plc(check: _DeviceCheck, driver: Any, found: _Findings) -> None:
    readings = check.polls(driver.read)
    last = readings[-1].channels
    armed, released = bool(last["armed"][0]), bool(last["released"][0])
    count = int(last["trigger_count"][0])
    found.readings = (("armed (magnet on)" if armed else "disarmed")
                      + (", RELEASED set" if released else ", model held" if armed else "")
                      + f", trigger count {count}")
    if armed and released:
        found.problems.append("armed but RELEASED set: the armature is off an energised magnet "
                              "(limit switch, or model not caught)")


def _analog(check: _DeviceCheck, driver: Any, found: _Findings) -> None:
    info = driver.info()
    found.identity = ", ".join(f"{key.lower()} {info[key]}" for key in ("Name", "Version")
                               if key in info)
    read = _streaming_read(driver)
    readings = check.stream(read)
    _clocked(check, readings, float(check.inst.settings["rate_hz"]), found, read)
    if not readings:
        return
    described = driver.describe()
    names = [k for k in described if k not in ("error_code", "epoch", "triggered")]
    codes = np.concatenate([r.channels["error_code"] for r in readings])
    parts = []
    for j, name in enumerate(names):
        values = np.concatenate([r.channels[name] for r in readings])
        valid = ((codes >> j) & 1) == 0
        fraction = float(valid.mean())
        mean = float(np.mean(values[valid])) if valid.any() else float("nan")
        parts.append(f"{name} {mean:.4g} {described[name]['units']}")
        if fraction < check.limits.laser_valid_fraction:
            found.problems.append(f"{name}: only {fraction:.1%} of the readings valid (the "
                                  "input at its range's limit or outside valid_volts)")
    found.readings = ", ".join(parts)


#: The inspection of each kind of device, after its driver opened.
INSPECT: Mapping[str, Callable[[_DeviceCheck, Any, _Findings], None]] = {
    "scanner": _scanner, "laser": _laser, "barometer": _barometer, "fan": _fan, "plc": _plc,
    "analog": _analog}


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


def _span(seconds: float) -> str:
    """Format a signed duration in the unit that reads best: ``+1.2 ms``, ``-329.4 d``."""
    size = abs(seconds)
    for unit, scale in (("d", 86400.0), ("h", 3600.0), ("s", 1.0), ("ms", 1e-3)):
        if size >= scale:
            return f"{seconds / scale:+.1f} {unit}"
    return f"{seconds * 1e6:+.0f} us"
