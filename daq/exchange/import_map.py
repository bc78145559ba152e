"""The import map (``MAP.toml``): how a lab's file becomes a windrig run file.

Responsibility: :func:`parse_import_map` reads and checks a map into a frozen
:class:`ImportMap`: the source format, the rig config (the section and its taps), the model's
span (for forces given as totals), the time base, one entry per channel (the quantity, its
column, unit, linear scale from volts and sign), the pressure taps' columns, the wind (a
value, a property, a channel or a Pitot's dynamic pressure), the air density, the release
instants (a list, a trigger channel's edge, or found in the displacements) and the hold kept
before each. A number the map leaves to
the source (``{ property = "Name" }``: a TDMS property, which LabVIEW may write as a string
with a decimal comma, or a scalar of a MATLAB file) is a :class:`Value`, read per source by
:mod:`daq.exchange.importing` (:func:`parse_number` reads the strings). Every mistake is one
:class:`~daq.errors.UsageError` naming the map, the table and the key.

Units are converted to SI by :data:`UNITS` and the sign to windrig's conventions (h and lift
positive downward, alpha and moment nose-up, p and drag downwind): a channel with a direction
must state its ``sign``, since a lab's z-up data read as z-down flips the coupling and with it
the flutter speed; there is no silent default.

Not responsible for: reading files (:mod:`daq.exchange.sources`), or applying the map
(:mod:`daq.exchange.importing`).
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from daq.errors import UsageError

__all__ = ["FORMATS", "QUANTITIES", "UNITS", "ChannelSpec", "ImportMap", "ReleaseSpec",
           "TapsSpec", "TimeSpec", "Value", "WindSpec", "parse_import_map", "parse_number"]

#: Source formats, by the map's ``format`` or the file's extension.
FORMATS = {"csv": "csv", "txt": "csv", "mat": "mat", "tdms": "tdms"}

#: Units by kind: the factor that takes a value to SI. Totals (``N``, ``N m``) are divided by
#: the span as well (:data:`TOTALS`).
UNITS: dict[str, dict[str, float]] = {
    "length": {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6},
    "angle": {"rad": 1.0, "mrad": 1e-3, "deg": math.pi / 180.0},
    "force": {"N/m": 1.0, "kN/m": 1e3, "N": 1.0, "kN": 1e3},
    "moment": {"N m/m": 1.0, "Nm/m": 1.0, "N m": 1.0, "Nm": 1.0},
    "speed": {"m/s": 1.0, "km/h": 1.0 / 3.6},
    "density": {"kg/m^3": 1.0, "kg/m3": 1.0},
    "pressure": {"Pa": 1.0, "hPa": 100.0, "mbar": 100.0, "kPa": 1e3},
    "time": {"s": 1.0, "ms": 1e-3},
}
#: Units that are totals over the model's span (divided by ``span`` to give per unit span).
TOTALS = frozenset({"N", "kN", "N m", "Nm"})
#: Quantity -> (unit kind, its signs and their factors; empty: no direction).
QUANTITIES: dict[str, tuple[str, dict[str, float]]] = {
    "h": ("length", {"down": 1.0, "up": -1.0}),
    "alpha": ("angle", {"nose_up": 1.0, "nose_down": -1.0}),
    "lift": ("force", {"down": 1.0, "up": -1.0}),
    "moment": ("moment", {"nose_up": 1.0, "nose_down": -1.0}),
    "p": ("length", {"downwind": 1.0, "upwind": -1.0}),
    "drag": ("force", {"downwind": 1.0, "upwind": -1.0}),
    "U": ("speed", {}),
    "rho": ("density", {}),
    "pitot": ("pressure", {}),
}
#: The channels a map's ``[channels]`` may name (the wind's and density's go under [wind]).
MOTION_AND_FORCES = ("h", "alpha", "lift", "moment", "p", "drag")

_NUMBER = re.compile(r"^[+-]?(\d+([.,]\d*)?|[.,]\d+)([eE][+-]?\d+)?$")


def parse_number(value: Any, where: str) -> float:
    """Read a number from a map or a source's property: a number, or a string of one.

    LabVIEW writes numbers into TDMS properties as strings, in the locale of the PC, so
    ``"0,9"`` (a decimal comma) is read as 0.9. A string with both a comma and a point, or
    with thousands separators, is refused rather than guessed.

    Raises
    ------
    UsageError
        Naming ``where`` and the value, when it is not one finite number.
    """
    if isinstance(value, bool):
        raise UsageError(f"{where}: expected a number, got {value!r}")
    if isinstance(value, (int, float)) or (hasattr(value, "dtype") and
                                           getattr(value, "size", 0) == 1):
        x = float(value)
    elif isinstance(value, str) and _NUMBER.match(value.strip()):
        x = float(value.strip().replace(",", "."))
    else:
        raise UsageError(f"{where}: expected a number (a decimal comma is read as a point), "
                         f"got {value!r}")
    if not math.isfinite(x):
        raise UsageError(f"{where}: expected a finite number, got {value!r}")
    return x


@dataclass(frozen=True)
class Value:
    """A number of the map: given there, read from a source's property, or given per source.

    Attributes
    ----------
    number : float or None
        The number itself (in the unit its key states).
    prop : str or None
        The name of a property (TDMS: of the channel ``of``, else the group, else the file;
        MATLAB: a scalar variable) that holds it.
    of : str or None
        The column whose property it is (TDMS), or None.
    per_source : mapping or None
        A number per source name (``file`` or ``file:group``).
    where : str
        The map's key, for messages.
    """

    number: float | None = None
    prop: str | None = None
    of: str | None = None
    per_source: Mapping[str, float] | None = None
    where: str = ""


@dataclass(frozen=True)
class ChannelSpec:
    """One channel of the source and how it becomes a windrig quantity (SI, windrig's signs).

    ``SI = sign * factor * (scale * raw + offset)`` (``scale`` and ``offset`` for volts only;
    ``factor`` from :data:`UNITS`, divided by the span for a total).
    """

    quantity: str
    column: str
    unit: str
    sign: float = 1.0
    scale: Value | None = None
    offset: Value | None = None
    scaled_unit: str | None = None
    where: str = ""

    @property
    def si_unit(self) -> str:
        """The unit after any volts' scale (the one :data:`UNITS` converts)."""
        return self.scaled_unit if self.unit == "V" and self.scaled_unit else self.unit

    @property
    def total(self) -> bool:
        """Whether the channel is a total over the span (N, N m)."""
        return self.si_unit in TOTALS


@dataclass(frozen=True)
class TimeSpec:
    """The time base of a source.

    A column (in ``unit``), or a sampling rate (Hz), or a TDMS waveform's ``wf_increment``
    (``waveform``).
    """

    column: str | None = None
    unit: str = "s"
    rate: Value | None = None
    waveform: bool = False


@dataclass(frozen=True)
class WindSpec:
    """The wind speed and the air density of a source.

    The speed is a value, or a channel, or a Pitot channel (with rho); the density a value or a
    channel.
    """

    U: Value | None = None
    U_channel: ChannelSpec | None = None
    pitot: ChannelSpec | None = None
    rho: Value | None = None
    rho_channel: ChannelSpec | None = None


@dataclass(frozen=True)
class ReleaseSpec:
    """Where the releases are and what is kept around them.

    Attributes
    ----------
    times : tuple of float or None
        The release instants, s on the source's time base.
    column : str or None
        A trigger channel (the magnet's current or a digital line): a release at each crossing
        of ``threshold`` in the direction of ``edge``.
    detect : bool
        Found in h and alpha (:func:`ident.records.release_onset.find_releases`).
    hold : float
        Seconds kept before each release (the still hold).
    length : float or None
        Seconds of decay kept after each release (None: up to the next release's hold, or the
        end of the source).
    ends : tuple of float or None
        With ``times``: where each decay ends, s on the source's time base (its first sample
        not kept), instead of where the model is found still again: a run file exported by
        windrig keeps its decays row for row.
    """

    times: tuple[float, ...] | None = None
    column: str | None = None
    threshold: Value | None = None
    edge: str = "falling"
    detect: bool = False
    hold: float = 0.0
    length: float | None = None
    ends: tuple[float, ...] | None = None


@dataclass(frozen=True)
class TapsSpec:
    """The pressure taps' columns, in the rig config's tap order, and their unit.

    Attributes
    ----------
    columns : tuple of str or None
        The columns, listed.
    prefix : str or None
        Or every column whose name is the prefix and a number, in the order of the numbers
        (``P1, P2, ..., P62``).
    unit : str
        A unit of pressure (:data:`UNITS`).
    """

    columns: tuple[str, ...] | None = None
    prefix: str | None = None
    unit: str = "Pa"
    where: str = ""


@dataclass(frozen=True)
class ImportMap:
    """A parsed import map (see the module docstring and ``docs/guides/import_export.md``)."""

    path: Path
    text: str
    config: str
    format: str | None
    span: Value | None
    groups: tuple[str, ...]
    time: TimeSpec
    channels: dict[str, ChannelSpec] = field(default_factory=dict)
    wind: WindSpec = field(default_factory=WindSpec)
    releases: ReleaseSpec = field(default_factory=ReleaseSpec)
    taps: TapsSpec | None = None


def _keys(table: Any, where: str, required: set[str], optional: set[str]) -> None:
    if not isinstance(table, Mapping):
        raise UsageError(f"{where} must be a table, got {table!r}")
    unknown = sorted(set(table) - required - optional)
    missing = sorted(required - set(table))
    if unknown:
        raise UsageError(f"{where}: unknown key(s) {unknown}; allowed: "
                         f"{sorted(required | optional)}")
    if missing:
        raise UsageError(f"{where}: missing key(s) {missing}")


def _text(table: Mapping[str, Any], key: str, where: str) -> str:
    value = table[key]
    if not isinstance(value, str) or not value:
        raise UsageError(f"{where} {key} must be a non-empty string, got {value!r}")
    return value


def _value(raw: Any, where: str, *, positive: bool = False) -> Value:
    """Read a number, ``{ property = "Name" [, of = "column"] }`` or ``{ source = number }``."""
    if isinstance(raw, Mapping) and "property" in raw:
        _keys(raw, where, {"property"}, {"of"})
        return Value(prop=_text(raw, "property", where),
                     of=_text(raw, "of", where) if "of" in raw else None, where=where)
    if isinstance(raw, Mapping):
        if not raw:
            raise UsageError(f"{where}: an empty table; give a number, {{ property = \"Name\" "
                             "}} or a number per source")
        numbers = {str(k): parse_number(v, f"{where}.{k}") for k, v in raw.items()}
        return Value(per_source=numbers, where=where)
    x = parse_number(raw, where)
    if positive and x <= 0:
        raise UsageError(f"{where} = {x!r} must be > 0")
    return Value(number=x, where=where)


def _channel(name: str, raw: Any, where: str) -> ChannelSpec:
    kind, signs = QUANTITIES[name]
    optional = {"scale", "offset", "scaled_unit"} | ({"sign"} if not signs else set())
    _keys(raw, where, {"column", "unit"} | ({"sign"} if signs else set()), optional)
    unit = _text(raw, "unit", where)
    allowed = sorted(UNITS[kind]) + ["V"]
    if unit not in UNITS[kind] and unit != "V":
        raise UsageError(f"{where} unit = {unit!r} is not a unit of {name}; allowed: {allowed}")
    scaled = None
    if unit == "V":
        for key in ("scale", "scaled_unit"):
            if key not in raw:
                raise UsageError(f"{where}: a channel in volts needs {key} (scaled = scale * V "
                                 "+ offset, in scaled_unit)")
        scaled = _text(raw, "scaled_unit", where)
        if scaled not in UNITS[kind]:
            raise UsageError(f"{where} scaled_unit = {scaled!r} is not a unit of {name}; "
                             f"allowed: {sorted(UNITS[kind])}")
    elif "scale" in raw or "offset" in raw or "scaled_unit" in raw:
        raise UsageError(f"{where}: scale, offset and scaled_unit are for a channel in volts "
                         f"(unit = \"V\"), not {unit!r}")
    sign = 1.0
    if signs:
        text = raw["sign"]
        if not isinstance(text, str) or text not in signs:  # a list or table: not a key
            raise UsageError(f"{where} sign = {text!r}; allowed for {name}: {sorted(signs)} "
                             "(windrig's own is " + next(iter(signs)) + ")")
        sign = signs[text]
    return ChannelSpec(quantity=name, column=_text(raw, "column", where), unit=unit, sign=sign,
                       scale=_value(raw["scale"], f"{where} scale") if "scale" in raw else None,
                       offset=_value(raw["offset"], f"{where} offset") if "offset" in raw
                       else None, scaled_unit=scaled, where=where)


def _time(raw: Any, where: str) -> TimeSpec:
    if not isinstance(raw, Mapping) or sum(k in raw for k in ("column", "rate", "waveform")) != 1:
        raise UsageError(f"{where}: give exactly one of column (with unit), rate (Hz) or "
                         "waveform = true (a TDMS waveform's wf_increment)")
    if "column" in raw:
        _keys(raw, where, {"column", "unit"}, set())
        unit = _text(raw, "unit", where)
        if unit not in UNITS["time"]:
            raise UsageError(f"{where} unit = {unit!r}; allowed: {sorted(UNITS['time'])}")
        return TimeSpec(column=_text(raw, "column", where), unit=unit)
    if "rate" in raw:
        _keys(raw, where, {"rate"}, set())
        return TimeSpec(rate=_value(raw["rate"], f"{where} rate", positive=True))
    _keys(raw, where, {"waveform"}, set())
    if raw["waveform"] is not True:
        raise UsageError(f"{where} waveform must be true (or leave it out), got "
                         f"{raw['waveform']!r}")
    return TimeSpec(waveform=True)


def _wind(raw: Any, where: str) -> WindSpec:
    _keys(raw, where, {"rho"}, {"U", "pitot"})
    if ("U" in raw) == ("pitot" in raw):
        raise UsageError(f"{where}: give exactly one of U (a number, a property, a number per "
                         "source, or a channel table) or pitot (a channel of dynamic pressure)")
    U = U_channel = pitot = rho = rho_channel = None
    if "U" in raw:
        if isinstance(raw["U"], Mapping) and "column" in raw["U"]:
            U_channel = _channel("U", raw["U"], f"{where} U")
        else:
            U = _value(raw["U"], f"{where} U")
    else:
        pitot = _channel("pitot", raw["pitot"], f"{where} pitot")
    if isinstance(raw["rho"], Mapping) and "column" in raw["rho"]:
        rho_channel = _channel("rho", raw["rho"], f"{where} rho")
    else:
        rho = _value(raw["rho"], f"{where} rho (kg/m^3)", positive=True)
    return WindSpec(U=U, U_channel=U_channel, pitot=pitot, rho=rho, rho_channel=rho_channel)


def _releases(raw: Any, where: str) -> ReleaseSpec:
    modes = [k for k in ("times", "column", "detect") if k in raw] if isinstance(raw, Mapping) \
        else []
    if len(modes) != 1:
        raise UsageError(f"{where}: give exactly one of times (a list, s), column (a trigger "
                         "channel) or detect = true (found in h and alpha)")
    _keys(raw, where, {modes[0], "hold"},
          {"length"} | ({"threshold", "edge"} if modes[0] == "column" else set())
          | ({"ends"} if modes[0] == "times" else set()))
    hold = parse_number(raw["hold"], f"{where} hold")
    if hold < 0:
        raise UsageError(f"{where} hold = {hold!r} s must be >= 0")
    length = parse_number(raw["length"], f"{where} length") if "length" in raw else None
    if length is not None and length <= 0:
        raise UsageError(f"{where} length = {length!r} s must be > 0")
    spec = ReleaseSpec(hold=hold, length=length)
    if modes[0] == "times":
        times = raw["times"]
        if not isinstance(times, list) or not times:
            raise UsageError(f"{where} times must be a non-empty list of seconds")
        values = tuple(parse_number(t, f"{where} times[{i}]") for i, t in enumerate(times))
        if any(b <= a for a, b in zip(values, values[1:], strict=False)):
            raise UsageError(f"{where} times must increase, got {list(values)}")
        ends = None
        if "ends" in raw:
            if not isinstance(raw["ends"], list) or len(raw["ends"]) != len(values):
                raise UsageError(f"{where} ends must be a list of {len(values)} seconds, one "
                                 "per release time")
            ends = tuple(parse_number(e, f"{where} ends[{i}]") for i, e in enumerate(raw["ends"]))
            late = [i for i, (tr, e) in enumerate(zip(values, ends, strict=True)) if e <= tr]
            if late:
                raise UsageError(f"{where} ends[{late[0]}] = {ends[late[0]]!r} s is not after "
                                 f"its release time {values[late[0]]!r} s")
        return ReleaseSpec(times=values, hold=hold, length=length, ends=ends)
    if modes[0] == "column":
        edge = raw.get("edge", "falling")
        if edge not in ("falling", "rising"):
            raise UsageError(f"{where} edge = {edge!r}; allowed: ['falling', 'rising']")
        return ReleaseSpec(column=_text(raw, "column", where), edge=edge, hold=hold,
                           length=length,
                           threshold=(_value(raw["threshold"], f"{where} threshold")
                                      if "threshold" in raw else None))
    if raw["detect"] is not True:
        raise UsageError(f"{where} detect must be true, got {raw['detect']!r}")
    return ReleaseSpec(detect=True, hold=spec.hold, length=spec.length)


def _taps(raw: Any, where: str) -> TapsSpec:
    if not isinstance(raw, Mapping) or ("columns" in raw) == ("prefix" in raw):
        raise UsageError(f"{where}: give exactly one of columns (a list, in the rig config's "
                         "tap order) or prefix (columns named prefix1, prefix2, ...)")
    _keys(raw, where, {"unit"}, {"columns", "prefix"})
    unit = _text(raw, "unit", where)
    if unit not in UNITS["pressure"]:
        raise UsageError(f"{where} unit = {unit!r}; allowed: {sorted(UNITS['pressure'])}")
    if "prefix" in raw:
        return TapsSpec(prefix=_text(raw, "prefix", where), unit=unit, where=where)
    columns = raw["columns"]
    if not isinstance(columns, list) or not columns or not all(
            isinstance(c, str) and c for c in columns):
        raise UsageError(f"{where} columns must be a non-empty list of column names")
    return TapsSpec(columns=tuple(columns), unit=unit, where=where)


def parse_import_map(path: str | Path) -> ImportMap:
    """Read and check an import map.

    Parameters
    ----------
    path : str or Path
        The map, TOML (``docs/guides/import_export.md``).

    Returns
    -------
    ImportMap

    Raises
    ------
    UsageError
        The map cannot be read, is not TOML, or a key is unknown, missing or wrong (the
        message names the map, the table and the key).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise UsageError(f"cannot read the import map {path}: {exc.strerror or exc}") from exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise UsageError(f"{path}: not valid TOML: {exc}") from exc
    where = str(path)
    _keys(data, where, {"config", "time", "channels", "wind", "releases"},
          {"format", "span", "groups", "taps"})
    fmt = data.get("format")
    if fmt is not None and (not isinstance(fmt, str) or fmt not in set(FORMATS.values())):
        raise UsageError(f"{where} format = {fmt!r}; allowed: {sorted(set(FORMATS.values()))}")
    groups = data.get("groups", [])
    if not isinstance(groups, list) or not all(isinstance(g, str) and g for g in groups):
        raise UsageError(f"{where} groups must be a list of TDMS group names (or patterns)")
    channels_raw = data["channels"]
    _keys(channels_raw, f"{where} [channels]", {"h", "alpha"}, set(MOTION_AND_FORCES))
    channels = {name: _channel(name, spec, f"{where} [channels] {name}")
                for name, spec in channels_raw.items()}
    if ("lift" in channels) != ("moment" in channels):
        raise UsageError(f"{where} [channels]: give both lift and moment (E2RFC), or neither "
                         "(integrated from [taps], or the displacement-only route)")
    span = _value(data["span"], f"{where} span (m)", positive=True) if "span" in data else None
    return ImportMap(path=path, text=text, config=_text(data, "config", where), format=fmt,
                     span=span, groups=tuple(groups),
                     time=_time(data["time"], f"{where} [time]"), channels=channels,
                     wind=_wind(data["wind"], f"{where} [wind]"),
                     releases=_releases(data["releases"], f"{where} [releases]"),
                     taps=_taps(data["taps"], f"{where} [taps]") if "taps" in data else None)
