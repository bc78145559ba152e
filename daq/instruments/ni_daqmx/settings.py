"""Settings of the NI-DAQmx drivers: a laser's ``[[lasers]]`` table, an ``[[analog]]`` table.

Responsibility: :class:`LinearScale` (a channel's ``value = offset + gain * volts`` in a named
unit, validated: a known unit, finite numbers, a gain that is not zero, the valid voltage span
inside the task's range), :class:`NiLaserSettings` (a laser with an analog output: its channel
and scale, and the keys every laser has: measuring range, rate, position and standoff, axis) and
:class:`NiAnalogSettings` (named scaled channels: a Pitot transducer, a balance). Each check
raises one :class:`~daq.errors.ConfigError` naming the table and the key.

Not responsible for: the task's URL (:mod:`daq.instruments.ni_daqmx.address`), reading
(:mod:`daq.instruments.ni_daqmx.driver`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from daq.errors import ConfigError
from daq.validation import check_keys, number

__all__ = ["LENGTH_UNITS", "MAX_RATE_HZ", "RESERVED_NAMES", "UNITS", "LinearScale",
           "NiAnalogChannel", "NiAnalogSettings", "NiLaserSettings"]

#: A unit a scale may give -> (its SI unit, the factor to it).
UNITS: Final[Mapping[str, tuple[str, float]]] = {
    "V": ("V", 1.0), "mV": ("V", 1e-3),
    "m": ("m", 1.0), "mm": ("m", 1e-3), "um": ("m", 1e-6),
    "Pa": ("Pa", 1.0), "hPa": ("Pa", 100.0), "kPa": ("Pa", 1e3),
    "N": ("N", 1.0), "kN": ("N", 1e3), "N m": ("N m", 1.0),
    "m/s": ("m/s", 1.0), "rad": ("rad", 1.0), "deg": ("rad", math.pi / 180.0),
}

#: Units of a laser's distance.
LENGTH_UNITS: Final = ("m", "mm", "um")

#: Highest sample rate accepted, Hz (per channel; multifunction DAQs reach 250 kS/s to a few MS/s
#: aggregate: the device refuses what it cannot do when the task starts).
MAX_RATE_HZ: Final = 100_000.0

#: Channel names an ``[[analog]]`` table may not use: the reading's own channels.
RESERVED_NAMES: Final = frozenset({"error_code", "epoch", "triggered"})

_CHANNEL = re.compile(r"ai\d+$")
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*$")
FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class LinearScale:
    """A channel's linear scale: ``value = offset + gain * volts``, in ``units``.

    Attributes
    ----------
    gain : float
        Units per volt (not zero).
    offset : float
        Value at 0 V, in ``units``.
    units : str
        A key of :data:`UNITS`; values are delivered in its SI unit.
    valid_volts : (float, float) or None
        Voltages outside this span are not valid readings (a laser's output with no target, a
        transducer beyond its range); None: the task's input range.
    """

    gain: float
    offset: float
    units: str
    valid_volts: tuple[float, float] | None = None

    @classmethod
    def from_table(cls, table: Mapping[str, Any], where: str, *,
                   units: Sequence[str] | None = None,
                   extra: set[str] = frozenset()) -> LinearScale:  # type: ignore[assignment]
        """Validate ``{gain, offset, units[, valid_volts]}`` (plus the ``extra`` keys, unread)."""
        check_keys(table, where, {"gain", "offset", "units"}, {"valid_volts"} | set(extra))
        allowed = list(UNITS) if units is None else list(units)
        unit = table["units"]
        if unit not in allowed:
            raise ConfigError(f"{where} units = {unit!r} is not one of {allowed}")
        gain = number(table, "gain", where, lo=-1e9, hi=1e9)
        if gain == 0.0:
            raise ConfigError(f"{where} gain = 0: a scale must change with the voltage")
        offset = number(table, "offset", where, lo=-1e9, hi=1e9)
        valid = None
        if "valid_volts" in table:
            span = table["valid_volts"]
            ok = (isinstance(span, (list, tuple)) and len(span) == 2
                  and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                          and math.isfinite(v) for v in span) and span[0] < span[1])
            if not ok:
                raise ConfigError(f"{where} valid_volts = {span!r} must be [low, high], two "
                                  "finite voltages, low < high")
            valid = (float(span[0]), float(span[1]))
        return cls(gain=gain, offset=offset, units=str(unit), valid_volts=valid)

    @property
    def si_units(self) -> str:
        """Measure the SI unit the scaled values are delivered in."""
        return UNITS[self.units][0]

    def apply(self, volts: FloatArray) -> FloatArray:
        """Return ``offset + gain * volts`` in the SI unit (NaN stays NaN)."""
        factor = UNITS[self.units][1]
        return (self.offset + self.gain * np.asarray(volts, dtype=np.float64)) * factor

    def volts_of(self, value_si: FloatArray) -> FloatArray:
        """Return the voltage that reads ``value_si`` (the inverse; a simulated sensor's output)."""
        factor = UNITS[self.units][1]
        return (np.asarray(value_si, dtype=np.float64) / factor - self.offset) / self.gain


def _channel(table: Mapping[str, Any], where: str) -> str:
    channel = table["channel"]
    if not isinstance(channel, str) or not _CHANNEL.match(channel):
        raise ConfigError(f"{where} channel = {channel!r} is not an analog input such as 'ai0'")
    return channel


def _rate(table: Mapping[str, Any], where: str) -> float:
    return number(table, "rate_hz", where, lo=0.0, hi=MAX_RATE_HZ, lo_open=True)


@dataclass(frozen=True)
class NiLaserSettings:
    """A laser with an analog output read on one NI-DAQmx channel (a ``[[lasers]]`` table).

    Attributes
    ----------
    channel : str
        The task's analog input the laser's output is wired to (``ai0``; one of the URL's).
    scale : LinearScale
        Distance from volts, in a length unit (e.g. an ILD1420-50's 0-10 V over 50 mm:
        ``gain = 5.0``, ``offset = 0``, ``units = "mm"``).
    range_mm : float
        The laser's measuring range, mm (the distances a valid reading lies in).
    rate_hz : float
        The task's sample rate, Hz (every instrument of one task gives the same).
    x, z, standoff_mm, axis
        Where the laser looks, as every laser of the rig config (docs/guides/calibration.md): chord
        position ``x`` (m, vertical laser), spot height ``z`` (m, sway laser), the reading at
        rest (mm) and ``vertical`` or ``sway``.
    """

    channel: str
    scale: LinearScale
    range_mm: float
    rate_hz: float
    x: float = 0.0
    standoff_mm: float = 0.0
    axis: str = "vertical"
    z: float = 0.0

    @classmethod
    def from_table(cls, table: Mapping[str, Any], where: str) -> NiLaserSettings:
        """Validate a ``[[lasers]]`` table of the ``ni_daqmx_laser`` driver."""
        axis = table.get("axis", "vertical")
        if axis not in ("vertical", "sway"):
            raise ConfigError(f"{where} axis = {axis!r} is not one of ['vertical', 'sway']")
        place = "x" if axis == "vertical" else "z"
        check_keys(table, where, {"channel", "scale", "range_mm", "rate_hz", "standoff_mm"}
                   | ({"x"} if axis == "vertical" else set()), {"axis", place})
        range_mm = number(table, "range_mm", where, lo=0.0, hi=10_000.0, lo_open=True)
        scale_table = table["scale"]
        if not isinstance(scale_table, Mapping):
            raise ConfigError(f"{where} scale must be a table {{gain, offset, units}}")
        return cls(
            channel=_channel(table, where),
            scale=LinearScale.from_table(scale_table, f"{where} scale", units=LENGTH_UNITS),
            range_mm=range_mm,
            rate_hz=_rate(table, where),
            x=number(table, "x", where, lo=-1.0, hi=1.0, default=0.0),
            standoff_mm=number(table, "standoff_mm", where, lo=0.0, hi=range_mm),
            axis=str(axis),
            z=number(table, "z", where, lo=-1.0, hi=1.0, default=0.0),
        )


@dataclass(frozen=True)
class NiAnalogChannel:
    """One named channel of an ``[[analog]]`` instrument: its input and its scale."""

    name: str
    channel: str
    scale: LinearScale


@dataclass(frozen=True)
class NiAnalogSettings:
    """Scaled analog inputs read on one NI-DAQmx task (an ``[[analog]]`` table).

    Attributes
    ----------
    rate_hz : float
        The task's sample rate, Hz.
    channels : tuple of NiAnalogChannel
        ``[[analog.channels]]``: each a ``name`` (the reading's channel; ``pitot`` in Pa gives
        the wind speed of a rig without a scanner), the task's ``channel`` and its scale
        (``gain``, ``offset``, ``units``, optional ``valid_volts``).
    """

    rate_hz: float
    channels: tuple[NiAnalogChannel, ...]

    @classmethod
    def from_table(cls, table: Mapping[str, Any], where: str) -> NiAnalogSettings:
        """Validate an ``[[analog]]`` table of the ``ni_daqmx_analog`` driver."""
        check_keys(table, where, {"rate_hz", "channels"})
        tables = table["channels"]
        if not isinstance(tables, list) or not 1 <= len(tables) <= 31:
            raise ConfigError(f"{where} channels must be an array of 1 to 31 tables "
                              "([[analog.channels]]; error_code has a bit per channel)")
        channels: list[NiAnalogChannel] = []
        for i, sub in enumerate(tables):
            at = f"{where} channels #{i}"
            if not isinstance(sub, Mapping):
                raise ConfigError(f"{at} must be a table")
            check_keys(sub, at, {"name", "channel", "gain", "offset", "units"}, {"valid_volts"})
            name = sub["name"]
            if not isinstance(name, str) or not _NAME.match(name) or name in RESERVED_NAMES:
                raise ConfigError(f"{at} name = {name!r} must be an identifier other than "
                                  f"{sorted(RESERVED_NAMES)}")
            channels.append(NiAnalogChannel(
                name=name, channel=_channel(sub, at),
                scale=LinearScale.from_table(sub, at, extra={"name", "channel"})))
        for attr in ("name", "channel"):
            values = [getattr(c, attr) for c in channels]
            repeated = sorted({v for v in values if values.count(v) > 1})
            if repeated:
                raise ConfigError(f"{where} channels: {attr} {repeated} given twice")
        pitot = [c for c in channels if c.name == "pitot"]
        if pitot and pitot[0].scale.si_units != "Pa":
            raise ConfigError(f"{where} channels: 'pitot' gives the dynamic pressure: its units "
                              f"must be a pressure (Pa, hPa, kPa), got {pitot[0].scale.units!r}")
        return cls(rate_hz=_rate(table, where), channels=tuple(channels))
