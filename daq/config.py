"""Rig configurations: TOML files in rig_configs/, parsed and validated into frozen objects.

The simulated rigs windrig ships are package data (``daq/rig_configs/*.toml``, installed with
the wheel; the repository's ``rig_configs`` is a link to that folder): :data:`SHIPPED_CONFIGS`,
and :func:`load_rig_config` also takes a shipped config's bare name (``sim_flat_plate``).

A rig config describes one tunnel set-up: the section model (structure and pressure taps), the
safety limits, the tunnel calibration, the instruments (each a ``driver`` name, a transport
``url`` and driver-specific settings) and, for simulated rigs, the virtual tunnel's truth. Every
table rejects unknown keys and names missing ones; every number is range-checked; each error is a
:class:`~daq.errors.ConfigError` whose message names the key (``[section] m``) and the allowed
range. Instrument settings are validated by the settings class each driver registers
(:mod:`daq.instruments.registry`), so a driver owns its own keys.

The TOML text is kept verbatim (it goes into every HDF5 file as ``/entry/config``).
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from daq.calibration import TAP_KEYS, Calibration, parse_calibration
from daq.errors import ConfigError
from daq.instruments import registry
from daq.instruments.entry import ROLES as ENTRY_ROLES
from daq.tubing_config import parse_tubing, split_tubing
from daq.validation import check_keys, number
from ident.model.flat_plate import jones_model
from ident.model.quasi_steady import StaticCoefficients
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.physics.taps import TapLayout
from ident.physics.tubing import TubingGroup
from ident.physics.turbulence import TurbulenceSpec

__all__ = [
    "InstrumentConfig",
    "is_sway_laser",
    "Limits",
    "RigConfig",
    "SHIPPED_CONFIGS",
    "SimulationConfig",
    "load_rig_config",
    "parse_rig_config",
    "shipped_config",
]

#: Instrument roles a rig may have (docs/guides/drivers.md: what each role's driver delivers).
ROLES = ENTRY_ROLES
#: Roles a rig may have several of: arrays of tables (``[[lasers]]``, ``[[analog]]``).
MULTIPLE = ("lasers", "analog")


@dataclass(frozen=True)
class Limits:
    """Safety limits of the rig.

    Attributes
    ----------
    max_wind_speed : float
        Highest wind speed the operator may request, m/s.
    max_fan_rpm : float
        Highest fan speed reference the drive may ever be sent, rpm.
    """

    max_wind_speed: float
    max_fan_rpm: float


@dataclass(frozen=True)
class InstrumentConfig:
    """One instrument: its driver name, transport URL and driver-specific settings."""

    role: str
    name: str
    driver: str
    url: str
    settings: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class SimulationConfig:
    """Truth of the virtual tunnel for a simulated rig.

    Attributes
    ----------
    aerodynamics : str
        ``"flat_plate_jones"`` (the closed-form flat plate) or ``"rfc"`` (coefficients given).
    rfc : dict or None
        ``{"A": ..., "d": ...}`` when ``aerodynamics = "rfc"``.
    hold_h, hold_alpha : float
        Hold position of the electromagnet, m and rad.
    hold_p : float
        Sway of the hold position, m (``hold_p``, a 3-DOF rig only; default 0).
    pressure_pa, temperature_c : float
        Ambient air.
    devices : dict
        Per-instrument simulation settings (clock offset and drift, noise, faults), by name.
    static : StaticCoefficients or None
        ``[simulation.static]``: the section's static coefficients (``C_D, C_L, C_M`` and their
        slopes per radian, lift positive downward): the mean wind load, and the buffeting
        forces with turbulence.
    turbulence : TurbulenceSpec or None
        ``[simulation.turbulence]``: oncoming turbulence (``Iu, Iw`` intensities as fractions,
        ``Lux, Lwx`` length scales in m, ``Cuy, Cwy`` span-wise coherence decays, ``admittance``
        ``"none"`` or ``"davenport"`` with ``decay``); needs ``static``.
    span : float or None
        The section model's span, m (``[simulation.turbulence] span``, else ``[section] span``;
        the two must agree when both are given: the span-wise coherence
        of the gusts averages the buffeting over it).
    turbulence_seed : int
        Seed of the gust field (``[simulation.turbulence] seed``, default 0).
    tubing : bool
        ``[simulation] tubing = true``: the simulated scanner sees the tap pressures through
        the config's ``[[taps.tubing]]`` (default false: perfect tubing).
    """

    aerodynamics: str
    rfc: Mapping[str, Any] | None
    hold_h: float
    hold_alpha: float
    pressure_pa: float
    temperature_c: float
    devices: Mapping[str, Mapping[str, Any]]
    static: StaticCoefficients | None = None
    turbulence: TurbulenceSpec | None = None
    span: float | None = None
    turbulence_seed: int = 0
    tubing: bool = False
    hold_p: float = 0.0


@dataclass(frozen=True)
class RigConfig:
    """A validated rig configuration (see the module docstring).

    ``calibration`` holds the optional calibrations (tap wiring and dead taps, Pitot, lasers,
    humid air, span; :mod:`daq.calibration`, docs/guides/calibration.md): the defaults change
    nothing.
    """

    name: str
    section: SectionModel
    depth: float
    taps: TapLayout
    limits: Limits
    wind_per_rpm: float
    instruments: tuple[InstrumentConfig, ...]
    simulation: SimulationConfig | None
    text: str = field(repr=False)
    source: str = ""
    #: ``[[taps.tubing]]`` (:mod:`daq.tubing_config`): the pneumatic tubing per group of taps.
    tubing: tuple[TubingGroup, ...] = ()
    calibration: Calibration = field(default_factory=Calibration)

    def instrument(self, name: str) -> InstrumentConfig:
        """Return the instrument called ``name`` (``scanner``, ``fan``, a laser's name, ...)."""
        for inst in self.instruments:
            if inst.name == name:
                return inst
        raise ConfigError(f"{self.source}: no instrument named {name!r}; have "
                          f"{[i.name for i in self.instruments]}")

    def aerodynamic_model(self) -> RationalFunctionModel:
        """Return the simulated truth's aerodynamic model (simulated rigs only)."""
        if self.simulation is None:
            raise ConfigError(f"{self.source}: not a simulated rig (no [simulation] table)")
        if self.simulation.aerodynamics == "flat_plate_jones":
            return jones_model()
        assert self.simulation.rfc is not None  # checked when parsed
        return RationalFunctionModel.from_dict(dict(self.simulation.rfc))

    def by_role(self, role: str) -> list[InstrumentConfig]:
        """Return every instrument of a role (``lasers`` and ``analog`` may have several)."""
        return [inst for inst in self.instruments if inst.role == role]

    @property
    def sway_laser(self) -> InstrumentConfig | None:
        """The laser that gives the sway p (``axis = "sway"``): a 3-DOF rig's; None on 2-DOF."""
        found = [inst for inst in self.by_role("lasers") if is_sway_laser(inst)]
        return found[0] if found else None

    @property
    def heave_pitch_lasers(self) -> list[InstrumentConfig]:
        """The lasers looking down at the model (h and alpha), in config order."""
        return [inst for inst in self.by_role("lasers") if not is_sway_laser(inst)]


def is_sway_laser(inst: InstrumentConfig) -> bool:
    """Whether an instrument is a laser measuring the sway (``axis = "sway"``)."""
    return inst.role == "lasers" and inst.settings.get("axis", "vertical") == "sway"


#: The folder of the rig configs shipped inside the package (found without a source checkout).
SHIPPED_CONFIGS = Path(__file__).resolve().parent / "rig_configs"


def shipped_config(name: str) -> Path:
    """Return the path of a shipped rig config by name (``"sim_flat_plate"``, ``.toml`` optional).

    Raises
    ------
    ConfigError
        If no shipped config has that name (the message lists those that do).
    """
    path = SHIPPED_CONFIGS / (name if name.endswith(".toml") else f"{name}.toml")
    if not path.is_file():
        names = sorted(p.stem for p in SHIPPED_CONFIGS.glob("*.toml"))
        raise ConfigError(f"no shipped rig config {name!r}; shipped: {', '.join(names)}")
    return path


def load_rig_config(path: str | Path) -> RigConfig:
    """Read and validate a rig config file.

    A bare name with no such file in the working directory (``sim_flat_plate``, no folder) is
    looked up among the shipped configs (:func:`shipped_config`).
    """
    path = Path(path)
    if not path.exists() and path.parent == Path(".") and \
            (SHIPPED_CONFIGS / f"{path.stem}.toml").is_file():
        path = shipped_config(path.name)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        hint = ""
        if path.parent == Path(".") and not path.exists():
            names = sorted(p.stem for p in SHIPPED_CONFIGS.glob("*.toml"))
            hint = f" (shipped configs, by name: {', '.join(names)})"
        raise ConfigError(f"cannot read rig config {path}: {exc.strerror or exc}{hint}") from exc
    return parse_rig_config(text, source=str(path))


def parse_rig_config(text: str, source: str = "<string>") -> RigConfig:
    """Validate the TOML ``text`` of a rig config; ``source`` names it in error messages."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: not valid TOML: {exc}") from exc
    check_keys(data, source, {"rig", "section", "taps", "limits", "tunnel"},
               set(ROLES) | {"simulation", "air"})
    check_keys(data["rig"], f"{source} [rig]", {"name"}, {"description"})
    section, depth = _section(data["section"], f"{source} [section]")
    taps_table, tubing_tables = split_tubing(data["taps"], source)
    try:
        # The wiring keys (channels, dead taps) are the calibration's (daq.calibration).
        taps = TapLayout.from_table({k: v for k, v in taps_table.items() if k not in TAP_KEYS})
    except (ValueError, TypeError, AttributeError) as exc:
        raise ConfigError(f"{source} [taps]: {exc}") from exc
    tubing = parse_tubing(tubing_tables, taps.n_taps, source,
                          Path(source).parent if source != "<string>" else None)
    check_keys(data["limits"], f"{source} [limits]", {"max_wind_speed", "max_fan_rpm"})
    limits = Limits(
        max_wind_speed=number(data["limits"], "max_wind_speed", f"{source} [limits]",
                              lo=0.0, hi=100.0, lo_open=True),
        max_fan_rpm=number(data["limits"], "max_fan_rpm", f"{source} [limits]",
                           lo=0.0, hi=100000.0, lo_open=True),
    )
    check_keys(data["tunnel"], f"{source} [tunnel]", {"wind_per_rpm"}, {"pitot"})
    wind_per_rpm = number(data["tunnel"], "wind_per_rpm", f"{source} [tunnel]", lo=0.0,
                          hi=10.0, lo_open=True)
    if limits.max_fan_rpm * wind_per_rpm < limits.max_wind_speed:
        raise ConfigError(
            f"{source} [limits]: max_wind_speed {limits.max_wind_speed} m/s cannot be reached "
            f"below max_fan_rpm {limits.max_fan_rpm} at {wind_per_rpm} (m/s)/rpm"
        )
    instruments = _instruments(data, source)
    _check_fan_full_scale(limits, instruments, source)
    _check_sway(section, instruments, source)
    simulation = (_simulation(data["simulation"], f"{source} [simulation]", instruments,
                              data["section"])
                  if "simulation" in data else None)
    if simulation is not None:
        _check_hold_in_range(simulation, instruments, source)
    if simulation is not None and simulation.tubing and not tubing:
        raise ConfigError(f"{source} [simulation] tubing = true needs [[taps.tubing]] tables")
    return RigConfig(name=str(data["rig"]["name"]), section=section, depth=depth, taps=taps,
                     limits=limits, wind_per_rpm=wind_per_rpm, instruments=instruments,
                     simulation=simulation, text=text, source=source, tubing=tubing,
                     calibration=parse_calibration(data, source, taps, instruments))


def _section(table: Mapping[str, Any], where: str) -> tuple[SectionModel, float]:
    fields_ = {"B", "m", "I", "fh", "fa", "zeta_h", "zeta_a"}
    sway = {"fp", "zeta_p", "m_p"}  # the lateral spring: a section with fp has 3 DOF
    check_keys(table, where, fields_ | {"depth"}, {"S", "span"} | sway)  # span: daq.calibration
    values = {key: number(table, key, where) for key in fields_ | ({"S"} & set(table))}
    for key in sorted(sway & set(table) - {"fp"}):
        if "fp" not in table:
            raise ConfigError(f"{where} {key} needs fp (the sway spring's frequency, Hz): a "
                              "section without fp has two degrees of freedom")
    if "fp" in table:
        values["fp"] = number(table, "fp", where, lo=0.0, hi=1000.0, lo_open=True)
        values["zeta_p"] = number(table, "zeta_p", where, lo=0.0, hi=0.5, default=0.0)
        if "m_p" in table:
            values["m_p"] = number(table, "m_p", where, lo=0.0, hi=1e5, lo_open=True)
    try:
        section = SectionModel(**values)
    except ValueError as exc:
        raise ConfigError(f"{where}: {exc}") from exc
    depth = number(table, "depth", where, lo=0.0, hi=section.B, lo_open=True)
    return section, depth


def _check_fan_full_scale(limits: Limits, instruments: tuple[InstrumentConfig, ...],
                          source: str) -> None:
    """Refuse a ``max_fan_rpm`` above the fan drive's own full-scale speed (``max_rpm``).

    Parameters
    ----------
    limits : Limits
        The rig's limits; ``max_fan_rpm`` in rpm.
    instruments : tuple of InstrumentConfig
        The validated instruments; a fan whose settings give ``max_rpm`` (rpm, the speed at
        full-scale reference, as the ``abb_acs580`` driver's do) is checked, a plugin drive
        without that key is left to its driver.
    source : str
        The config's name, for the message.

    Raises
    ------
    ConfigError
        Naming both keys: every front end (a campaign's plan check, the console's set-point
        range) lets the operator ask for up to ``max_fan_rpm``, which the drive would then
        refuse halfway through a test instead of the config being refused before it starts.
    """
    for inst in instruments:
        full_scale = inst.settings.get("max_rpm") if inst.role == "fan" else None
        if isinstance(full_scale, (int, float)) and limits.max_fan_rpm > full_scale:
            raise ConfigError(
                f"{source} [limits] max_fan_rpm = {limits.max_fan_rpm:g} is above [fan] max_rpm "
                f"= {full_scale:g}, the drive's full-scale speed (rpm), which it can never "
                f"be sent; allowed: max_fan_rpm <= {full_scale:g}")


def _check_hold_in_range(simulation: SimulationConfig,
                         instruments: tuple[InstrumentConfig, ...], source: str) -> None:
    """Refuse a simulated hold that puts a laser's spot beyond its measuring range.

    A vertical laser at chord position ``x`` (m) reads ``standoff + 1000 (h + x alpha)`` mm, a
    sway laser at height ``z`` reads ``standoff - 1000 (p - z alpha)`` mm; a release swings
    the model about its rest position to about the hold's displacement on the other side, so
    both ``standoff -+ deviation`` must lie in ``0..range_mm``. Without this check the
    simulated model was held where every laser reads an error value: the device check failed
    on the lasers without naming the hold, and with ``--skip-check`` no release was usable.

    Parameters
    ----------
    simulation : SimulationConfig
        Its ``hold_h`` (m), ``hold_alpha`` (rad) and ``hold_p`` (m).
    instruments : tuple of InstrumentConfig
        Lasers with ``range_mm`` and ``standoff_mm`` (mm) and ``x`` or ``z`` (m) are checked.
    source : str
        The config's name, for the message.

    Raises
    ------
    ConfigError
        Naming the hold keys, the laser and its range.
    """
    for inst in instruments:
        settings = inst.settings
        if inst.role != "lasers" or not all(isinstance(settings.get(key), (int, float))
                                             for key in ("range_mm", "standoff_mm")):
            continue
        if is_sway_laser(inst):
            keys = "hold_p, hold_alpha"
            deviation = simulation.hold_p - float(settings.get("z", 0.0)) * simulation.hold_alpha
        else:
            keys = "hold_h, hold_alpha"
            deviation = simulation.hold_h + float(settings.get("x", 0.0)) * simulation.hold_alpha
        swing_mm = 1000.0 * abs(deviation)
        range_mm, standoff_mm = float(settings["range_mm"]), float(settings["standoff_mm"])
        room_mm = min(standoff_mm, range_mm - standoff_mm)
        if swing_mm > room_mm:
            raise ConfigError(
                f"{source} [simulation] {keys}: the hold moves {inst.name}'s reading "
                f"{swing_mm:.3g} mm from its standoff {standoff_mm:g} mm, and the decay as far "
                f"the other way, beyond its measuring range 0..{range_mm:g} mm; allowed: at "
                f"most {room_mm:g} mm")


def _check_sway(section: SectionModel, instruments: tuple[InstrumentConfig, ...],
                source: str) -> None:
    """Check that a rig is 3-DOF exactly when its section has fp, with one sway laser for p."""
    sway = [inst.name for inst in instruments if is_sway_laser(inst)]
    if section.n_dof == 3 and not sway:
        raise ConfigError(f"{source} [section] fp = {section.fp:g} Hz makes the rig 3-DOF: it "
                          "needs a sway laser ([[lasers]] with axis = \"sway\") to measure p")
    if sway and section.n_dof == 2:
        raise ConfigError(f"{source} [[lasers]] {sway[0]!r} axis = \"sway\" needs the sway "
                          "spring in [section] (fp, Hz): a section without fp has 2 DOF")
    if len(sway) > 1:
        raise ConfigError(f"{source} [[lasers]]: one sway laser (axis = \"sway\") gives p, "
                          f"got {len(sway)}: {sway}")


def _instruments(data: Mapping[str, Any], source: str) -> tuple[InstrumentConfig, ...]:
    out: list[InstrumentConfig] = []
    for role in ROLES:
        if role not in data:
            continue
        tables = data[role] if role in MULTIPLE else [data[role]]
        if role in MULTIPLE and not isinstance(tables, list):
            raise ConfigError(f"{source}: {role} must be an array of tables ([[{role}]])")
        for index, table in enumerate(tables):
            where = (f"{source} [{role}]" if role not in MULTIPLE
                     else f"{source} [[{role}]] #{index}")
            if not isinstance(table, Mapping):
                raise ConfigError(f"{where} must be a table")
            for key in ("driver", "url"):
                if key not in table:
                    raise ConfigError(f"{where}: missing required key {key!r}")
            name = str(table.get("name", role))
            # A laser's [lasers.calibration] belongs to daq.calibration, not to the driver.
            settings = {k: v for k, v in table.items()
                        if k not in ("driver", "url", "name", "calibration")}
            registry.validate_settings(str(table["driver"]), role, settings, where)
            out.append(InstrumentConfig(role=role, name=name, driver=str(table["driver"]),
                                        url=str(table["url"]), settings=settings))
    names = [inst.name for inst in out]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise ConfigError(f"{source}: instrument names must be unique; repeated: {repeated}")
    return tuple(out)


def _simulation(table: Mapping[str, Any], where: str, instruments: tuple[InstrumentConfig, ...],
                section: Mapping[str, Any]) -> SimulationConfig:
    check_keys(table, where, {"aerodynamics", "hold_h", "hold_alpha"},
               {"rfc", "pressure_pa", "temperature_c", "devices", "static", "turbulence",
                "tubing", "hold_p"})
    if "hold_p" in table and "fp" not in section:
        raise ConfigError(f"{where} hold_p needs the sway spring in [section] (fp, Hz): a "
                          "section without fp has two degrees of freedom")
    aerodynamics = table["aerodynamics"]
    if aerodynamics not in ("flat_plate_jones", "rfc"):
        raise ConfigError(f"{where} aerodynamics must be 'flat_plate_jones' or 'rfc', "
                          f"got {aerodynamics!r}")
    if (aerodynamics == "rfc") != ("rfc" in table):
        raise ConfigError(f"{where}: an [simulation.rfc] table is required exactly when "
                          "aerodynamics = 'rfc'")
    if "rfc" in table:
        check_keys(table["rfc"], _subtable(where, "rfc"), {"A", "d"})
        try:
            RationalFunctionModel.from_dict(dict(table["rfc"]))
        except (ValueError, TypeError) as exc:
            raise ConfigError(f"{_subtable(where, 'rfc')}: {exc}") from exc
    devices = table.get("devices", {})
    check_keys(devices, _subtable(where, "devices"), set(), {inst.name for inst in instruments})
    static = _static(table["static"], _subtable(where, "static")) if "static" in table else None
    turbulence, span, seed = None, None, 0
    if "turbulence" in table:
        if static is None:
            raise ConfigError(f"{_subtable(where, 'turbulence')} needs a [simulation.static] "
                              "table: the buffeting forces come from the static coefficients")
        turbulence, span, seed = _turbulence(table["turbulence"],
                                             _subtable(where, "turbulence"), section)
    return SimulationConfig(
        aerodynamics=aerodynamics,
        rfc=table.get("rfc"),
        hold_h=number(table, "hold_h", where, lo=-0.05, hi=0.05),
        hold_alpha=number(table, "hold_alpha", where, lo=-0.2, hi=0.2),
        pressure_pa=number(table, "pressure_pa", where, lo=50000.0, hi=120000.0,
                           default=101325.0),
        temperature_c=number(table, "temperature_c", where, lo=-30.0, hi=60.0, default=20.0),
        devices=devices,
        static=static,
        turbulence=turbulence,
        span=span,
        turbulence_seed=seed,
        tubing=_flag(table, "tubing", where),
        hold_p=number(table, "hold_p", where, lo=-0.05, hi=0.05, default=0.0),
    )


def _flag(table: Mapping[str, Any], key: str, where: str) -> bool:
    value = table.get(key, False)
    if not isinstance(value, bool):
        raise ConfigError(f"{where} {key} must be true or false, got {value!r}")
    return value


def _subtable(where: str, name: str) -> str:
    """Name a sub-table in messages: ``file [simulation]`` -> ``file [simulation.name]``."""
    return f"{where[:-1]}.{name}]" if where.endswith("]") else f"{where}.{name}"


def _static(table: Mapping[str, Any], where: str) -> StaticCoefficients:
    """Read the static coefficients: six numbers, the slopes per radian (|value| <= 20)."""
    names = ("C_D", "C_L", "C_M", "dC_D", "dC_L", "dC_M")
    check_keys(table, where, set(names))
    return StaticCoefficients(**{name: number(table, name, where, lo=-20.0, hi=20.0)
                                 for name in names})


def _turbulence(table: Mapping[str, Any], where: str,
                section: Mapping[str, Any]) -> tuple[TurbulenceSpec, float, int]:
    """Read the turbulence spec, the model's span (m) and the gust field's seed."""
    check_keys(table, where, {"Iu", "Iw", "Lux", "Lwx"},
               {"Cuy", "Cwy", "admittance", "decay", "seed", "span", "skewness", "kurtosis"})
    admittance = table.get("admittance", "none")
    if admittance not in ("none", "davenport"):
        raise ConfigError(f"{where} admittance must be 'none' or 'davenport', got {admittance!r}")
    seed = table.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"{where} seed must be an integer >= 0, got {seed!r}")
    spec = TurbulenceSpec(
        Iu=number(table, "Iu", where, lo=0.0, hi=0.5),
        Iw=number(table, "Iw", where, lo=0.0, hi=0.5),
        Lux=number(table, "Lux", where, lo=0.0, hi=100.0, lo_open=True),
        Lwx=number(table, "Lwx", where, lo=0.0, hi=100.0, lo_open=True),
        Cuy=number(table, "Cuy", where, lo=0.0, hi=100.0, default=10.0),
        Cwy=number(table, "Cwy", where, lo=0.0, hi=100.0, default=8.0),
        admittance=admittance,
        decay=number(table, "decay", where, lo=0.0, hi=100.0, lo_open=True, default=7.0),
        skewness=number(table, "skewness", where, lo=-1.0, hi=1.0, default=0.0),
        kurtosis=number(table, "kurtosis", where, lo=3.0, hi=8.0, default=3.0),
    )
    if "span" not in table and "span" not in section:
        raise ConfigError(f"{where}: missing required key(s) ['span'] (the model's span, m; "
                          "or give [section] span)")
    span = (number(table, "span", where, lo=0.0, hi=20.0, lo_open=True) if "span" in table else
            number(section, "span", f"{where[:where.rfind('[')]}[section]", lo=0.0, hi=20.0,
                   lo_open=True))
    return spec, span, int(seed)
