"""The driver contract of each role, as checks a driver's own tests run (docs/guides/drivers.md).

Responsibility: what windrig's engine, device check, recorder, console and campaigns rely on,
written once as data (:data:`ROLE_CHANNELS`, :data:`ROLE_METHODS`) and checked by plain
functions that return a list of problems (empty: the contract holds), so that a test can assert
on them and a report can print them:

- :func:`entry_problems`: the registry entry (role, callables, its name);
- :func:`construction_problems`: construction does no I/O (a transport whose every use fails
  the check), a misspelt keyword is a ``TypeError``, the role's methods exist, a polled
  driver keeps its validated settings as ``settings`` (where the engine reads its poll
  period), ``describe()`` has the role's channels with their units, dtypes and ranks, and
  every channel has units;
- :func:`reading_problems`: one reading against ``describe()`` and the role (shapes, dtypes,
  host times, counters, device times for the clocked roles, gaps inside the reading);
- :func:`sequence_problems`: consecutive readings: counters go on, and every jump of the
  counter is a reported :class:`~daq.instruments.reading.Gap`;

and :func:`check_driver`, which opens a driver on a live transport (its simulator's, or the
device's for a hardware test), reads it as the engine does and raises ``AssertionError``
listing every problem.

Not responsible for: a device's own protocol (the driver's tests, with scripted exchanges from
:mod:`daq.testing.exchange` or a simulator).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from daq.errors import TransportTimeout
from daq.instruments.build import POLLED_ROLES, poll_settings_problem
from daq.instruments.entry import ROLES, DriverEntry
from daq.instruments.reading import Reading, describe_mismatches
from daq.transports.byte_transport import TransportBase

__all__ = ["CLOCKED_ROLES", "ROLE_CHANNELS", "ROLE_METHODS", "ChannelRule", "check_driver",
           "construction_problems", "entry_problems", "read_as_engine", "reading_problems",
           "sequence_problems"]


@dataclass(frozen=True)
class ChannelRule:
    """What a role requires of one channel of ``describe()`` and ``read()``.

    Attributes
    ----------
    units : str
        The units it must be in (SI, or ``"1"`` for counts and flags).
    dtype : str
        Its numpy dtype.
    ndim : int
        Dimensions of one row: 0 a scalar, 1 a vector (its length is the driver's to say).
    """

    units: str
    dtype: str
    ndim: int = 0


#: The channels every driver of a role must deliver (it may deliver more).
ROLE_CHANNELS: Mapping[str, Mapping[str, ChannelRule]] = {
    "scanner": {
        "pressure": ChannelRule("Pa", "float64", 1),  # every channel of every module
        "pitot": ChannelRule("Pa", "float64"),
        "trigger_time": ChannelRule("s", "float64"),  # NaN when no trigger input
        "module_status": ChannelRule("1", "int8", 1),  # one per module, 0 = OK
    },
    "lasers": {
        "distance": ChannelRule("m", "float64"),
        "error_code": ChannelRule("1", "int32"),  # 0 = valid
        "triggered": ChannelRule("1", "bool"),  # False throughout without a trigger input
    },
    "fan": {
        "speed": ChannelRule("rpm", "float64"),  # the actual speed, physical units
        "status_word": ChannelRule("1", "uint16"),  # the drive's own bits (recorded as is)
    },
    "plc": {
        "armed": ChannelRule("1", "bool"),
        "released": ChannelRule("1", "bool"),
        "trigger_count": ChannelRule("1", "uint16"),
    },
    "barometer": {
        "pressure": ChannelRule("Pa", "float64"),
        "temperature": ChannelRule("K", "float64"),
        "density": ChannelRule("kg/m^3", "float64"),
    },
    # Besides these, one float64 channel per configured input, named and in SI units as the
    # rig config says (an input named ``pitot`` in Pa gives the wind speed without a scanner).
    "analog": {
        "error_code": ChannelRule("1", "int32"),  # bit j set: input j invalid (its value NaN)
        "triggered": ChannelRule("1", "bool"),
    },
}

#: The roles whose readings carry the device's own clock (``device_time``).
CLOCKED_ROLES = ("scanner", "lasers", "analog")

#: The methods and attributes each role's users call (the engine, the device check, the
#: console, the campaigns, CALZ): docs/guides/drivers.md says who calls each and when.
ROLE_METHODS: Mapping[str, tuple[str, ...]] = {
    "scanner": ("open", "close", "describe", "read", "start", "stop", "recover", "drain",
                "note_pause", "recent_pressure_mean", "scan", "status", "serial_numbers", "rate_hz",
                "calz", "check_calz_allowed"),
    "lasers": ("open", "close", "describe", "read", "info"),
    "fan": ("open", "close", "describe", "read", "set_speed", "start", "stop", "coast",
            "wait_for_speed", "status", "max_rpm"),
    "plc": ("open", "close", "describe", "read", "arm", "disarm", "release", "trigger_pulse"),
    "barometer": ("open", "close", "describe", "read"),
    "analog": ("open", "close", "describe", "read", "info"),
}


def entry_problems(entry: Any, name: str | None = None) -> list[str]:
    """Return how a registry entry breaks the contract (empty: it does not).

    Parameters
    ----------
    entry : DriverEntry
        The object a ``windrig.drivers`` entry point names.
    name : str, optional
        The entry point's name, which must be the entry's.
    """
    if not isinstance(entry, DriverEntry):
        return [f"a {type(entry).__name__}, not a daq.instruments.entry.DriverEntry"]
    out = []
    if entry.role not in ROLES:
        out.append(f"role {entry.role!r} is not one of {list(ROLES)}")
    if name is not None and entry.name != name:
        out.append(f"entry names driver {entry.name!r}, its entry point {name!r}")
    for attr in ("factory", "validate"):
        if not callable(getattr(entry, attr)):
            out.append(f"{attr} is not callable")
    return out


class _Untouchable(TransportBase):
    """A transport any use of which is recorded: construction must not touch it."""

    url = "untouchable://"

    def __init__(self) -> None:
        self.used: list[str] = []

    @property
    def is_open(self) -> bool:
        """Measure whether the transport is open (never)."""
        return False

    def open(self) -> None:
        """Record the call."""
        self.used.append("open")

    def close(self) -> None:
        """Record the call."""
        self.used.append("close")

    def write(self, data: bytes) -> None:
        """Record the call."""
        self.used.append(f"write {data!r}")

    def read(self, max_bytes: int, timeout_s: float) -> bytes:
        """Record the call."""
        self.used.append("read")
        return b""


def construction_problems(entry: DriverEntry, settings: Mapping[str, Any], *,
                          link: Any = None, **extra: Any) -> list[str]:
    """Build a driver from its entry without I/O; return how it breaks the contract.

    Checks that the settings validate, that construction touches no transport, that an
    unknown keyword is a ``TypeError``, that the role's methods exist (:data:`ROLE_METHODS`),
    that a polled driver's ``settings`` attribute is the object ``validate`` returned (the
    engine reads ``settings.poll_interval_s`` there), and that ``describe()`` holds the role's
    channels (:data:`ROLE_CHANNELS`) with units.

    Parameters
    ----------
    entry : DriverEntry
        The driver's entry.
    settings : mapping
        An instrument table of a rig config, as TOML gives it (without ``driver``, ``url`` and
        ``name``): the raw mapping, which the entry's ``validate`` turns into settings.
    link : object, optional
        What to build it on (default: a byte transport that records any use; a Modbus driver
        passes a :class:`~daq.transports.scripted.ScriptedBus` with an empty script).
    extra
        Keyword arguments of the factory (a fan's ``limit_rpm``).
    """
    out = entry_problems(entry)
    if out:
        return out
    validated = entry.validate(settings, f"driver {entry.name!r}")
    transport = _Untouchable() if link is None else link
    driver = entry.factory(transport, validated, **extra)
    if isinstance(transport, _Untouchable) and transport.used:
        out.append(f"construction used the transport: {transport.used}")
    try:
        entry.factory(_Untouchable(), validated, no_such_option=1, **extra)
        out.append("an unknown keyword (no_such_option) was accepted, not a TypeError")
    except TypeError:
        pass
    missing = [m for m in ROLE_METHODS[entry.role] if not hasattr(driver, m)]
    if missing:
        out.append(f"missing the {entry.role} role's methods {missing}")
    if entry.role in POLLED_ROLES and getattr(driver, "settings", None) is not validated:
        out.append(poll_settings_problem(entry.role, driver, validated) or (
            f"a polled ({entry.role}) driver keeps the object validate() returned as its "
            "`settings` attribute (the engine reads settings.poll_interval_s there); "
            f"{type(driver).__name__}.settings is "
            f"{type(getattr(driver, 'settings', None)).__name__}"))
    out += describe_problems(driver.describe(), entry.role)
    return out


def describe_problems(described: Mapping[str, Mapping[str, Any]], role: str) -> list[str]:
    """Return how a ``describe()`` breaks its role's channel rules (and any channel's units)."""
    out = []
    for name, rule in ROLE_CHANNELS[role].items():
        info = described.get(name)
        if info is None:
            out.append(f"missing channel {name!r} of the {role} role")
            continue
        if str(info.get("units")) != rule.units:
            out.append(f"{name}: units {info.get('units')!r}, the {role} role's are "
                       f"{rule.units!r}")
        if np.dtype(info.get("dtype", "float64")) != np.dtype(rule.dtype):
            out.append(f"{name}: dtype {info.get('dtype')}, the {role} role's is {rule.dtype}")
        if len(tuple(info.get("shape", ()))) != rule.ndim:
            out.append(f"{name}: shape {tuple(info.get('shape', ()))}, the {role} role's rows "
                       f"have {rule.ndim} dimension(s)")
    out += [f"{name}: no units" for name, info in described.items() if "units" not in info]
    if role == "scanner" and not out:
        modules = tuple(described["module_status"]["shape"])[0]
        channels = tuple(described["pressure"]["shape"])[0]
        if modules < 1 or channels % modules:
            out.append(f"pressure has {channels} channels for {modules} module(s): not a "
                       "whole number per module")
    return out


def reading_problems(described: Mapping[str, Mapping[str, Any]], reading: Any,
                     role: str) -> list[str]:
    """Return how one reading breaks the contract of ``describe()`` and of its role."""
    if not isinstance(reading, Reading):
        return [f"read() returned a {type(reading).__name__}, not a Reading"]
    if len(reading) < 1:
        return ["an empty reading (read() returns at least one row, or raises a timeout)"]
    out = [f"not as described: {p}" for p in describe_mismatches(described, reading)]
    clocked = role in CLOCKED_ROLES
    if clocked and reading.device_time is None:
        out.append(f"no device_time: a {role} reading carries the device's own clock")
    if not clocked and reading.device_time is not None:
        out.append(f"device_time given: a {role} is polled, its rows have host times only")
    counter = np.asarray(reading.counter)
    if counter.size > 1 and np.any(np.diff(counter) < 1):
        out.append("counter does not increase within the reading")
    if np.any(np.diff(np.asarray(reading.host_time_ns)) < 0):
        out.append("host_time_ns goes back within the reading")
    if reading.device_time is not None and np.any(np.diff(reading.device_time) <= 0):
        out.append("device_time does not increase within the reading")
    out += _unreported(counter, reading.gaps, inside_only=True)
    return out


def sequence_problems(readings: Sequence[Reading]) -> list[str]:
    """Return the counter jumps between and within readings that no reported gap covers."""
    if not readings:
        return ["no readings"]
    out: list[str] = []
    for before, after in zip(readings, readings[1:], strict=False):
        last, first = int(before.counter[-1]), int(after.counter[0])
        if first <= last:
            out.append(f"counter goes back: {first} after {last}")
        elif first > last + 1:
            reported = sum(g.length for g in after.gaps if g.after_counter == last)
            if reported != first - last - 1:
                out.append(f"{first - last - 1} row(s) missing after counter {last} but "
                           f"{reported} reported as a gap")
    return out


def _unreported(counter: np.ndarray, gaps: Sequence[Any], *, inside_only: bool) -> list[str]:
    out = []
    for i in np.flatnonzero(np.diff(counter) > 1):
        last, missing = int(counter[i]), int(counter[i + 1] - counter[i] - 1)
        reported = sum(g.length for g in gaps if g.after_counter == last)
        if reported != missing:
            out.append(f"{missing} row(s) missing after counter {last} but {reported} "
                       "reported as a gap")
    return out


def read_as_engine(driver: Any, role: str, n: int = 3, timeout_s: float = 2.0,
                   ) -> list[Reading]:
    """Read ``n`` readings from an open driver as the engine does; return them.

    A scanner is started first (``start()``: configure and scan) and stopped after; a
    streaming role reads with ``read(timeout_s=...)`` (a timeout is retried until
    ``timeout_s`` has passed once per reading); a polled role calls ``read()``.
    """
    readings: list[Reading] = []
    if role == "scanner":
        driver.start()
    try:
        while len(readings) < n:
            if role in CLOCKED_ROLES:
                try:
                    readings.append(driver.read(timeout_s=timeout_s))
                except TransportTimeout as exc:
                    raise AssertionError(f"no {role} data within {timeout_s:g} s") from exc
            else:
                readings.append(driver.read())
    finally:
        if role == "scanner":
            driver.stop()
    return readings


def check_driver(entry: DriverEntry, settings: Mapping[str, Any], link: Any, *, n: int = 3,
                 timeout_s: float = 2.0, **extra: Any) -> list[Reading]:
    """Open a driver on a live transport, read it as the engine does, assert the contract.

    Parameters
    ----------
    entry : DriverEntry
        The driver's entry.
    settings : mapping
        An instrument table of a rig config, for the device behind ``link``, as TOML gives it
        (the raw mapping, not the validated settings object).
    link : Transport or RegisterBus
        A transport (or bus) to a running simulator or to the device, not yet open: e.g.
        ``open_transport(url, **entry.transport_defaults)``
        (:func:`daq.transports.byte_transport.open_transport`).
    n : int
        Readings to take (consecutive ones are checked against each other).
    timeout_s : float
        Longest wait for one streaming reading, s.
    extra
        Keyword arguments of the factory (a fan's ``limit_rpm``).

    Returns
    -------
    list of Reading
        The readings (for checks of the driver's own).

    Raises
    ------
    AssertionError
        Listing every problem of :func:`construction_problems`, :func:`reading_problems` and
        :func:`sequence_problems`.
    """
    problems = construction_problems(entry, settings, **extra)
    driver = entry.factory(link, entry.validate(settings, f"driver {entry.name!r}"), **extra)
    driver.open()
    try:
        described = driver.describe()
        readings = read_as_engine(driver, entry.role, n, timeout_s)
    finally:
        driver.close()
    for i, reading in enumerate(readings):
        problems += [f"reading {i}: {p}" for p in reading_problems(described, reading,
                                                                     entry.role)]
    problems += sequence_problems(readings)
    if problems:
        raise AssertionError(f"driver {entry.name!r} breaks the {entry.role} contract:\n  "
                             + "\n  ".join(problems))
    return readings
