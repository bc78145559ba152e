"""What the device check reads of each kind of device, and how it judges it.

One function per kind (scanner, laser, barometer, fan drive, PLC, analog inputs), run on the
device's own check thread once its driver is open (:data:`INSPECT`): it asks the device's
identity where the protocol gives one, reads it for the check's window, and writes what it
found into the check's :class:`Findings`; the clocked kinds also measure their rate on the
device's clock and that clock against the host's (:func:`_clocked`), all judged by the
thresholds of :class:`CheckLimits`. Running the checks and reporting them is
:mod:`daq.acquisition.device_check`, which re-exports :class:`CheckLimits`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from daq.config import InstrumentConfig, RigConfig
from daq.instruments.reading import Reading

__all__ = ["INSPECT", "CheckLimits", "DeviceSession", "Findings"]

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



@dataclass
class Findings:
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

class DeviceSession(Protocol):
    """What an inspection needs of the device's check (``device_check._DeviceCheck``)."""

    inst: InstrumentConfig
    config: RigConfig
    limits: CheckLimits
    window_s: float

    def stream(self, read: Callable[[float], Reading]) -> list[Reading]:
        """Read a streaming device for the window; return its readings."""
        ...

    def polls(self, read: Callable[[], Reading], n: int = 3) -> list[Reading]:
        """Poll a device ``n`` times over the window (its round trip into the findings)."""
        ...


def _clocked(check: DeviceSession, readings: list[Reading], nominal_hz: float,
             found: Findings, read: Callable[[float], Reading] | None = None) -> None:
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


def _restreamed_ratio(check: DeviceSession, read: Callable[[float], Reading]) -> float:
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


def _scanner(check: DeviceSession, driver: Any, found: Findings) -> None:
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


def _laser(check: DeviceSession, driver: Any, found: Findings) -> None:
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


def _barometer(check: DeviceSession, driver: Any, found: Findings) -> None:
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


def _fan(check: DeviceSession, driver: Any, found: Findings) -> None:
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


def _plc(check: DeviceSession, driver: Any, found: Findings) -> None:
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


def _analog(check: DeviceSession, driver: Any, found: Findings) -> None:
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
INSPECT: Mapping[str, Callable[[DeviceSession, Any, Findings], None]] = {
    "scanner": _scanner, "laser": _laser, "barometer": _barometer, "fan": _fan, "plc": _plc,
    "analog": _analog}


def _span(seconds: float) -> str:
    """Format a signed duration in the unit that reads best: ``+1.2 ms``, ``-329.4 d``."""
    size = abs(seconds)
    for unit, scale in (("d", 86400.0), ("h", 3600.0), ("s", 1.0), ("ms", 1e-3)):
        if size >= scale:
            return f"{seconds / scale:+.1f} {unit}"
    return f"{seconds * 1e6:+.0f} us"
