"""Calibrations of a rig config: the tap wiring, the Pitot, the lasers, the air, the model's span.

Responsibility: the optional calibration keys of a rig config, validated into one frozen
:class:`Calibration` (:func:`parse_calibration`, called by :func:`daq.config.parse_rig_config`),
and what each calibration does to a reading. Every key is optional; without any, a rig behaves
as it did before calibrations existed (taps on scanner channels ``0 .. n_taps - 1``, no dead tap,
the Pitot read as the dynamic pressure, the lasers' readings as vertical distances, dry air).

The keys (docs/guides/calibration.md; each bad value is a ConfigError naming the key)::

    [section]   span = 0.9                       model span, m (per-unit-span forces to totals)
    [taps]      channels = [[module, channel], ...]   one per tap, in the layout's tap order
                dead = [i, j]                    tap indices left out of the forces
                source = "...", date = 2026-11-20     where the wiring comes from
    [tunnel.pitot]  factor = 1.02, offset_pa = 0.0    q_true = factor * q_pitot + offset_pa
                    (or fan_rpm = [...] with factor = [...]: interpolated on the fan speed)
                    source, date
    [air]       relative_humidity = 0.5 (or "barometer": its RH= field), co2_mole_fraction,
                source, date
    [[lasers]] then [lasers.calibration]  gain, offset_mm, angle_deg, source, date

Each calibration table may carry ``source`` (text) and ``date`` (ISO 8601, a TOML date or a
string); both go into the run file with the values (``/entry/calibration/<name>``).

Not responsible for: the section, the tap geometry, the instruments (:mod:`daq.config`), or
applying the calibrations to streams (:mod:`daq.recording.sync_view`, which calls the methods
here).
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from daq.errors import ConfigError
from daq.instruments import registry
from daq.validation import check_keys, number
from ident.physics.air import CO2_MOLE_FRACTION, R_DRY_AIR, moist_air_density
from ident.physics.taps import TapLayout

__all__ = ["AirCalibration", "Calibration", "LaserCalibration",
           "PitotCalibration", "TAP_KEYS", "TapWiring", "parse_calibration"]

FloatArray = npt.NDArray[np.float64]

#: Keys of ``[taps]`` read here (the rest describe the geometry, :meth:`TapLayout.from_table`).
TAP_KEYS = frozenset({"channels", "dead", "source", "date"})


@dataclass(frozen=True)
class TapWiring:
    """Which scanner channel each tap is on, and which taps are dead.

    Attributes
    ----------
    channels : tuple of int
        Global scanner channel (``channels_per_module * module + channel``) of each tap, in
        the layout's order.
    dead : tuple of int
        Taps left out of the forces (their pressures are still recorded), ascending.
    configured : bool
        ``[taps] channels`` was given (else the default ``0 .. n_taps - 1``).
    source, date : str
        Provenance of the wiring (``""`` if not given).
    channels_per_module : int
        Pressure channels per module of the rig's scanner, as its driver describes itself
        (0: the rig has no scanner).
    """

    channels: tuple[int, ...] = ()
    dead: tuple[int, ...] = ()
    configured: bool = False
    source: str = ""
    date: str = ""
    channels_per_module: int = 0

    def live_index(self, n_taps: int) -> npt.NDArray[np.intp]:
        """Return the indices of the live taps, ascending."""
        live = np.ones(n_taps, dtype=bool)
        live[list(self.dead)] = False
        return np.flatnonzero(live)


@dataclass(frozen=True)
class PitotCalibration:
    """Tunnel calibration of the Pitot: ``q_true = factor * q_pitot + offset_pa``.

    ``factor`` is one number, or (with ``fan_rpm``) a table interpolated linearly on the fan
    speed and held at its end values outside the table.
    """

    factor: tuple[float, ...] = (1.0,)
    offset_pa: float = 0.0
    fan_rpm: tuple[float, ...] = ()
    source: str = ""
    date: str = ""

    @property
    def needs_fan_speed(self) -> bool:
        """Measure whether the factor depends on the fan speed (a table)."""
        return bool(self.fan_rpm)

    def dynamic_pressure(self, q_pitot: Any, fan_rpm: float = math.nan) -> FloatArray:
        """Return the tunnel's dynamic pressure, Pa, from the Pitot's (Pa) at ``fan_rpm``.

        With a fan-speed table and no fan speed known yet (NaN), the result is NaN: a wind
        speed from an unknown factor would look right and be wrong.
        """
        q = np.asarray(q_pitot, dtype=np.float64)
        if self.fan_rpm:
            f = (float(np.interp(fan_rpm, self.fan_rpm, self.factor)) if math.isfinite(fan_rpm)
                 else math.nan)
        else:
            f = self.factor[0]
        return np.asarray(f * q + self.offset_pa, dtype=np.float64)


@dataclass(frozen=True)
class LaserCalibration:
    """A laser's calibration: ``distance = cos(angle) (gain * reading + offset_m)``.

    ``gain`` and ``offset_m`` correct the reading along the beam (against a reference); a beam
    tilted by ``angle_rad`` from the vertical reads the distance along itself, and the vertical
    distance is its projection. The spot's chord position ``x`` of the laser table is where the
    beam meets the model at rest (a tilt moves the spot by ``dz tan(angle)`` when the model
    moves by ``dz``: below 0.1 mm for 5 mm of heave at 1 degree, neglected).
    """

    gain: float = 1.0
    offset_m: float = 0.0
    angle_rad: float = 0.0
    source: str = ""
    date: str = ""

    def distance(self, reading_m: Any) -> FloatArray:
        """Vertical distance, m, from the laser's reading (m; NaN passes through)."""
        r = np.asarray(reading_m, dtype=np.float64)
        return np.asarray(math.cos(self.angle_rad) * (self.gain * r + self.offset_m),
                          dtype=np.float64)


@dataclass(frozen=True)
class AirCalibration:
    """How the air density is computed from the barometer's pressure and temperature.

    ``relative_humidity`` None: dry air, ``p / (R_d T)`` (the default, as before). A fraction:
    moist air by CIPM-2007 (:func:`ident.physics.air.moist_air_density`) at that fixed humidity.
    ``from_barometer``: moist air at the humidity each barometer reading carries (a
    PTU300-class instrument's ``RH=`` field); a reading without one has no density (NaN: the
    run keeps the last density, as for any failed barometer reading).
    """

    relative_humidity: float | None = None
    co2_mole_fraction: float = CO2_MOLE_FRACTION
    from_barometer: bool = False
    source: str = ""
    date: str = ""

    @property
    def humid(self) -> bool:
        """Measure whether the density is that of humid air (a fixed or a measured humidity)."""
        return self.from_barometer or self.relative_humidity is not None

    def density(self, pressure_pa: float, temperature_k: float,
                measured_rh: float = math.nan) -> float:
        """Return the air density, kg/m^3 (NaN if an input it needs is NaN).

        ``measured_rh`` is the barometer's relative humidity (a fraction), used with
        ``from_barometer``.
        """
        rh = measured_rh if self.from_barometer else self.relative_humidity
        if rh is None:
            return float(pressure_pa / (R_DRY_AIR * temperature_k))
        if math.isnan(rh):
            return math.nan
        return float(moist_air_density(pressure_pa, temperature_k, rh, self.co2_mole_fraction))


@dataclass(frozen=True)
class Calibration:
    """Every calibration of a rig (see the module docstring); the defaults change nothing."""

    taps: TapWiring = field(default_factory=TapWiring)
    pitot: PitotCalibration = field(default_factory=PitotCalibration)
    lasers: Mapping[str, LaserCalibration] = field(default_factory=dict)
    air: AirCalibration = field(default_factory=AirCalibration)
    span: float | None = None

    def tap_channels(self, n_taps: int) -> tuple[int, ...]:
        """Return the scanner channel of each tap (the default wiring when none was configured)."""
        return self.taps.channels if self.taps.channels else tuple(range(n_taps))

    def laser(self, name: str) -> LaserCalibration:
        """Return the calibration of laser ``name`` (identity if none was configured)."""
        return self.lasers.get(name, LaserCalibration())

    def live_taps(self, layout: TapLayout) -> tuple[TapLayout, npt.NDArray[np.intp]]:
        """Return the layout of the live taps (:meth:`TapLayout.without`) and their indices."""
        index = self.taps.live_index(layout.n_taps)
        return (layout.without(self.taps.dead) if self.taps.dead else layout), index

    def records(self, n_taps: int) -> dict[str, tuple[dict[str, Any], dict[str, str]]]:
        """Return what goes into the run file: ``name -> (values, attrs)`` per calibration.

        Values are numbers or arrays in SI units (names with their unit); attrs are
        ``source`` and ``date`` (``""`` when the config gave none) and ``configured``
        (``"yes"``, or ``"no"``: the default, which changes nothing).
        """
        channels = np.asarray(self.tap_channels(n_taps), dtype=np.int64)
        per_module = self.taps.channels_per_module or max(int(channels.max(initial=0)) + 1, 1)
        live = np.ones(n_taps, dtype=bool)
        live[list(self.taps.dead)] = False
        out: dict[str, tuple[dict[str, Any], dict[str, str]]] = {
            "taps": ({"scanner_module": channels // per_module,
                      "scanner_channel": channels % per_module,
                      "dead": np.asarray(self.taps.dead, dtype=np.int64), "live": live},
                     _attrs(self.taps.source, self.taps.date,
                            self.taps.configured or bool(self.taps.dead))),
        }
        p = self.pitot
        pitot: dict[str, Any] = {"offset_pa": p.offset_pa}
        if p.fan_rpm:
            pitot.update(fan_rpm=np.asarray(p.fan_rpm), factor=np.asarray(p.factor))
        else:
            pitot["factor"] = p.factor[0]
        out["pitot"] = (pitot, _attrs(p.source, p.date, p != PitotCalibration()))
        a = self.air
        out["air"] = ({"relative_humidity": math.nan if a.relative_humidity is None
                       else a.relative_humidity, "co2_mole_fraction": a.co2_mole_fraction,
                       "humidity_from": "barometer" if a.from_barometer
                       else "config" if a.relative_humidity is not None else "none",
                       "formula": "CIPM-2007 (Picard et al., Metrologia 45 (2008) 149)"
                       if a.humid else "dry air p/(R_d T)"},
                      _attrs(a.source, a.date, a.humid))
        for name, cal in sorted(self.lasers.items()):
            out[f"laser_{name}"] = ({"gain": cal.gain, "offset_m": cal.offset_m,
                                     "angle_rad": cal.angle_rad},
                                    _attrs(cal.source, cal.date, True))
        if self.span is not None:
            out["section"] = ({"span_m": self.span}, _attrs("", "", True))
        return out


def _attrs(source: str, date: str, configured: bool) -> dict[str, str]:
    return {"source": source, "date": date, "configured": "yes" if configured else "no"}


def parse_calibration(data: Mapping[str, Any], source: str, taps: TapLayout,
                      instruments: Sequence[Any]) -> Calibration:
    """Validate the calibration keys of a parsed rig config (the TOML ``data``).

    Parameters
    ----------
    data : mapping
        The whole parsed TOML.
    source : str
        The config's name, for messages.
    taps : TapLayout
        The tap geometry (``[taps]`` without :data:`TAP_KEYS`).
    instruments : sequence of daq.config.InstrumentConfig
        The validated instruments (the scanner's modules and Pitot channel, the lasers' tables).

    Raises
    ------
    ConfigError
        Naming the key, the value and what is allowed.
    """
    wiring = _tap_wiring(data["taps"], f"{source} [taps]", taps, instruments)
    tunnel = data["tunnel"]
    pitot = (_pitot(tunnel["pitot"], f"{source} [tunnel.pitot]", instruments)
             if "pitot" in tunnel else PitotCalibration())
    air = (_air(data["air"], f"{source} [air]", instruments) if "air" in data
           else AirCalibration())
    lasers = {}
    raw_lasers = data.get("lasers", [])
    for index, table in enumerate(raw_lasers if isinstance(raw_lasers, list) else []):
        if isinstance(table, Mapping) and "calibration" in table:
            name = str(table.get("name", "lasers"))
            lasers[name] = _laser(table["calibration"],
                                  f"{source} [[lasers]] #{index} ({name}) [lasers.calibration]",
                                  table)
    span = None
    if "span" in data["section"]:
        span = number(data["section"], "span", f"{source} [section]", lo=0.0, hi=20.0,
                      lo_open=True)
        turbulence = data.get("simulation", {}).get("turbulence", {})
        sim_span = turbulence.get("span") if isinstance(turbulence, Mapping) else None
        if isinstance(sim_span, (int, float)) and not math.isclose(float(sim_span), span,
                                                                    rel_tol=1e-9):
            raise ConfigError(f"{source} [section] span = {span!r} m disagrees with "
                              f"[simulation.turbulence] span = {sim_span!r} m: the simulated "
                              "model is the rig's model, give them the same value")
    return Calibration(taps=wiring, pitot=pitot, lasers=lasers, air=air, span=span)


def _provenance(table: Mapping[str, Any], where: str) -> tuple[str, str]:
    """``source`` (text) and ``date`` (ISO 8601) of a calibration table, ``""`` if absent."""
    src = table.get("source", "")
    if not isinstance(src, str):
        raise ConfigError(f"{where} source must be a text (where the calibration comes from), "
                          f"got {src!r}")
    date = table.get("date", "")
    if isinstance(date, (dt.date, dt.datetime)):
        return src, date.isoformat()
    if isinstance(date, dt.time) or not isinstance(date, str):
        raise ConfigError(f"{where} date must be an ISO 8601 date such as 2026-11-20, "
                          f"got {date!r}")
    if date:
        try:
            dt.datetime.fromisoformat(date)
        except ValueError:
            raise ConfigError(f"{where} date = {date!r} is not an ISO 8601 date "
                              "(e.g. 2026-11-20 or 2026-11-20T09:30:00Z)") from None
    return src, date


def _int_list(value: Any, key: str, where: str) -> list[Any]:
    if not isinstance(value, list):
        raise ConfigError(f"{where} {key} must be an array, got {value!r}")
    return value


def _is_int(x: Any) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _tap_wiring(table: Mapping[str, Any], where: str, taps: TapLayout,
                instruments: Sequence[Any]) -> TapWiring:
    n = taps.n_taps
    scanners = [inst for inst in instruments if inst.role == "scanner"]
    src, date = _provenance(table, where)
    channels: tuple[int, ...] = ()
    # How wide the scanner is comes from its driver's describe(), never from a constant.
    per_module, modules = ((0, 0) if not scanners else registry.scanner_layout(
        scanners[0].driver, scanners[0].settings, f"{where[:where.rfind('[')]}[scanner]"))
    if "channels" in table:
        if not scanners:
            raise ConfigError(f"{where} channels: the rig has no [scanner] to wire taps to")
        pitot = int(scanners[0].settings["pitot_channel"])
        pairs = _int_list(table["channels"], "channels", where)
        if len(pairs) != n:
            raise ConfigError(f"{where} channels must list one [module, channel] per tap: "
                              f"{n} taps, got {len(pairs)} entries")
        out = []
        for i, pair in enumerate(pairs):
            if not (isinstance(pair, list) and len(pair) == 2 and all(map(_is_int, pair))):
                raise ConfigError(f"{where} channels: entry {i} must be [module, channel] "
                                  f"(two integers), got {pair!r}")
            module, channel = pair
            if not (0 <= module < modules and 0 <= channel < per_module):
                raise ConfigError(f"{where} channels: tap {i} = [{module}, {channel}] is outside "
                                  f"the scanner: module in [0, {modules - 1}] ([scanner] "
                                  f"modules = {modules}), channel in [0, "
                                  f"{per_module - 1}]")
            out.append(per_module * module + channel)
        seen: dict[int, int] = {}
        for i, ch in enumerate(out):
            if ch == pitot:
                raise ConfigError(f"{where} channels: tap {i} is on the Pitot's channel "
                                  f"([scanner] pitot_channel = {pitot}, module "
                                  f"{pitot // per_module} channel "
                                  f"{pitot % per_module})")
            if ch in seen:
                raise ConfigError(f"{where} channels: taps {seen[ch]} and {i} share module "
                                  f"{ch // per_module} channel "
                                  f"{ch % per_module}; each channel holds one tap")
            seen[ch] = i
        channels = tuple(out)
    else:
        for inst in scanners[:1]:  # the default wiring: taps on 0 .. n-1, the Pitot above them
            total = per_module * modules
            pitot = int(inst.settings["pitot_channel"])
            if n + 1 > total:
                raise ConfigError(f"{where[:where.rfind('[')]}[scanner] modules: {n} taps plus "
                                  f"the Pitot need {n + 1} channels, "
                                  f"{inst.settings['modules']} module(s) have {total}")
            if pitot < n:
                raise ConfigError(f"{where[:where.rfind('[')]}[scanner] pitot_channel = {pitot} "
                                  f"is a tap's channel; taps use channels 0..{n - 1} (or map "
                                  "them with [taps] channels)")
    dead: tuple[int, ...] = ()
    if "dead" in table:
        items = _int_list(table["dead"], "dead", where)
        if not all(map(_is_int, items)) or any(not 0 <= i < n for i in items):
            raise ConfigError(f"{where} dead must list tap indices in [0, {n - 1}], "
                              f"got {items!r}")
        if len(set(items)) != len(items):
            raise ConfigError(f"{where} dead lists a tap twice: {items!r}")
        dead = tuple(sorted(items))
        try:
            taps.without(dead)
        except ValueError as exc:
            raise ConfigError(f"{where} dead = {items!r}: {exc}") from exc
    return TapWiring(channels=channels, dead=dead, configured="channels" in table,
                     source=src, date=date, channels_per_module=per_module)


def _pitot(table: Mapping[str, Any], where: str,
           instruments: Sequence[Any]) -> PitotCalibration:
    check_keys(table, where, set(), {"factor", "offset_pa", "fan_rpm", "source", "date"})
    src, date = _provenance(table, where)
    offset = number(table, "offset_pa", where, lo=-200.0, hi=200.0, default=0.0)
    if "fan_rpm" not in table:
        factor = number(table, "factor", where, lo=0.5, hi=2.0, default=1.0)
        return PitotCalibration(factor=(factor,), offset_pa=offset, source=src, date=date)
    if not any(inst.role == "fan" for inst in instruments):
        raise ConfigError(f"{where} fan_rpm: a factor table on the fan speed needs a [fan]")
    rpm = _int_list(table["fan_rpm"], "fan_rpm", where)
    factors = _int_list(table.get("factor"), "factor", where) if "factor" in table else None
    if factors is None or len(factors) != len(rpm) or len(rpm) < 2:
        raise ConfigError(f"{where} factor must be an array as long as fan_rpm (at least 2 "
                          f"points), got factor = {table.get('factor')!r} for fan_rpm = {rpm!r}")
    rpm_values = [number({"fan_rpm": r}, "fan_rpm", where, lo=0.0, hi=100000.0) for r in rpm]
    if any(b <= a for a, b in zip(rpm_values, rpm_values[1:], strict=False)):
        raise ConfigError(f"{where} fan_rpm must increase strictly, got {rpm!r}")
    f_values = [number({"factor": f}, "factor", where, lo=0.5, hi=2.0) for f in factors]
    return PitotCalibration(factor=tuple(f_values), offset_pa=offset, fan_rpm=tuple(rpm_values),
                            source=src, date=date)


def _air(table: Mapping[str, Any], where: str, instruments: Sequence[Any]) -> AirCalibration:
    check_keys(table, where, set(), {"relative_humidity", "co2_mole_fraction", "source", "date"})
    src, date = _provenance(table, where)
    co2 = number(table, "co2_mole_fraction", where, lo=0.0, hi=0.01, default=CO2_MOLE_FRACTION)
    value = table.get("relative_humidity")
    if isinstance(value, str):
        if value != "barometer":
            raise ConfigError(f"{where} relative_humidity must be a fraction in [0, 1] (0.5 = "
                              f"50 %RH) or \"barometer\", got {value!r}")
        if not any(inst.role == "barometer" for inst in instruments):
            raise ConfigError(f"{where} relative_humidity = \"barometer\" needs a [barometer] "
                              "that reports humidity (a PTU300-class RH= field)")
        return AirCalibration(co2_mole_fraction=co2, from_barometer=True, source=src, date=date)
    rh = (number(table, "relative_humidity", where, lo=0.0, hi=1.0)
          if "relative_humidity" in table else None)
    return AirCalibration(relative_humidity=rh, co2_mole_fraction=co2, source=src, date=date)


def _laser(table: Any, where: str, laser: Mapping[str, Any]) -> LaserCalibration:
    check_keys(table, where, set(), {"gain", "offset_mm", "angle_deg", "source", "date"})
    src, date = _provenance(table, where)
    range_mm = laser.get("range_mm", 1000.0)
    limit = float(range_mm) if isinstance(range_mm, (int, float)) else 1000.0
    return LaserCalibration(
        gain=number(table, "gain", where, lo=0.5, hi=2.0, default=1.0),
        offset_m=1e-3 * number(table, "offset_mm", where, lo=-limit, hi=limit, default=0.0),
        angle_rad=math.radians(number(table, "angle_deg", where, lo=-45.0, hi=45.0,
                                      default=0.0)),
        source=src, date=date)
