"""Settings of the Micro-Epsilon ILD1420-class laser driver: the ``[[lasers]]`` table, validated.

Responsibility: :class:`Ild1420Settings` (measuring range, rate, output values, what the laser
looks at (``axis``: down at the model for heave and pitch, or along the wind for sway), position
and standoff of the laser on the model, line settings) with the ranges the sensor family
allows, and the line budget check (the values of a block must fit the baud rate). Each check
raises a :class:`~daq.errors.ConfigError` naming the key.

Not responsible for: the bytes on the line (:mod:`daq.instruments.microepsilon_ild1420.decoder`)
or talking to the sensor (:mod:`daq.instruments.microepsilon_ild1420.driver`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

from daq.errors import ConfigError
from daq.validation import check_keys, number

__all__ = ["AXES", "BAUDRATE_RANGE", "BITS_PER_VALUE", "DEFAULT_BAUDRATE", "DEFAULT_OUTPUT",
           "MAX_RATE_HZ", "RANGES_MM", "REQUIRED_OUTPUT", "WORDS_PER_VALUE", "Ild1420Settings"]

#: Measuring ranges of the ILD1420 family, mm (docs/reference/wire_formats.md, "Laser
#: displacement").
RANGES_MM: Final = (10, 25, 50, 100, 200, 500)


#: What a laser looks at: ``vertical`` (down at the model at chord position ``x``: heave and
#: pitch) or ``sway`` (along the wind at the model's face at height ``z``: the lateral motion of
#: a rig with three degrees of freedom).
AXES: Final = ("vertical", "sway")


#: Highest measuring rate, Hz ("The maximum measuring rate is 4 kHz").
MAX_RATE_HZ: Final = 4000.0


#: Factory baud rate.
DEFAULT_BAUDRATE: Final = 921600


#: Baud rates accepted [unverified: the manual lists 9.6 kBd ... 1 MBd; only the bounds are used].
BAUDRATE_RANGE: Final = (9600, 1000000)


#: Line bits per value: 3 bytes x (start + 8 data + stop) (8N1; the ILD2300 sizing rule).
BITS_PER_VALUE: Final = 33


#: Default additional values, in block order.
DEFAULT_OUTPUT: Final = ("counter", "timestamp", "status")


#: Additional values the stream contract needs (gaps, device time, trigger flag).
REQUIRED_OUTPUT: Final = frozenset(DEFAULT_OUTPUT)


#: Words per additional value (the timestamp is two 16-bit words).
WORDS_PER_VALUE: Final = {"counter": 1, "timestamp": 2, "status": 1, "exposure": 1, "intensity": 1}


@dataclass(frozen=True)
class Ild1420Settings:
    """Validated settings of one ILD1420 laser (a ``[[lasers]]`` table without driver/url/name).

    Attributes
    ----------
    range_mm : int
        Measuring range MR, mm: one of 10, 25, 50, 100, 200, 500.
    rate_hz : float
        Measuring rate, Hz, in (0, 4000].
    x : float
        Chord position of the laser spot, m, in [-1, 1], positive downstream of the elastic axis
        (a ``vertical`` laser; a sway laser has none: 0).
    standoff_mm : float
        Distance reading at the model's rest position, mm, within [0, MR].
    baudrate : int
        RS-422 baud rate, in [9600, 1000000]; default 921600.
    output : tuple of str
        Additional values in block order; must contain ``counter``, ``timestamp`` and ``status``,
        may add ``exposure`` and ``intensity``. ``33 bits x values x rate_hz`` must fit in
        ``baudrate`` (else the sensor sends 262075).
    axis : {"vertical", "sway"}
        ``vertical`` (default): the laser looks down at the model and reads
        ``standoff + h + x alpha``. ``sway``: it sits downstream of the model, looking upwind
        at its trailing face, and reads ``standoff - (p - z alpha)`` (p positive downwind).
    z : float
        A sway laser's spot height, m, in [-1, 1], positive downward from the elastic axis (a
        pitch nose-up moves a face point at height z upwind by ``z alpha``); 0 for a vertical
        laser.
    """

    range_mm: int
    rate_hz: float
    x: float
    standoff_mm: float
    baudrate: int = DEFAULT_BAUDRATE
    output: tuple[str, ...] = DEFAULT_OUTPUT
    axis: str = "vertical"
    z: float = 0.0

    def __post_init__(self) -> None:
        _validate_settings(where="ILD1420 settings", range_mm=self.range_mm,
                           rate_hz=self.rate_hz, x=self.x, standoff_mm=self.standoff_mm,
                           baudrate=self.baudrate, output=self.output)
        _validate_axis("ILD1420 settings", self.axis, self.x, self.z)

    @classmethod
    def from_table(cls, table: Mapping[str, Any], where: str) -> Ild1420Settings:
        """Validate a rig-config table; raise ConfigError naming the key and its allowed range."""
        axis = table.get("axis", "vertical")
        if axis not in AXES:
            raise ConfigError(f"{where} axis = {axis!r} is not one of {list(AXES)}")
        # A vertical laser is placed along the chord (x), a sway laser in height (z).
        place = "x" if axis == "vertical" else "z"
        check_keys(table, where, {"range_mm", "rate_hz", "standoff_mm"} | (
            {"x"} if axis == "vertical" else set()), {"baudrate", "output", "axis", place})
        range_mm = table["range_mm"]
        if (isinstance(range_mm, bool) or not isinstance(range_mm, (int, float))
                or range_mm not in RANGES_MM):
            raise ConfigError(f"{where} range_mm = {range_mm!r} is not one of {list(RANGES_MM)}")
        baudrate = table.get("baudrate", DEFAULT_BAUDRATE)
        if isinstance(baudrate, bool) or not isinstance(baudrate, int):
            raise ConfigError(f"{where} baudrate must be an integer, got {baudrate!r}")
        output = table.get("output", list(DEFAULT_OUTPUT))
        if not isinstance(output, (list, tuple)) or not all(isinstance(o, str) for o in output):
            raise ConfigError(f"{where} output must be a list of names, got {output!r}")
        settings: dict[str, Any] = {
            "range_mm": int(range_mm),
            "rate_hz": number(table, "rate_hz", where, lo=0.0, hi=MAX_RATE_HZ, lo_open=True),
            "x": number(table, "x", where, lo=-1.0, hi=1.0, default=0.0),
            "standoff_mm": number(table, "standoff_mm", where, lo=0.0, hi=float(range_mm)),
            "baudrate": baudrate,
            "output": tuple(output),
            "axis": str(axis),
            "z": number(table, "z", where, lo=-1.0, hi=1.0, default=0.0),
        }
        _validate_settings(where=where, **{k: v for k, v in settings.items()
                                           if k not in ("axis", "z")})
        return cls(**settings)

    @property
    def values_per_block(self) -> int:
        """Measure the number of 3-byte values in one block (distance plus additional values)."""
        return 1 + sum(WORDS_PER_VALUE[name] for name in self.output)

    @property
    def bits_per_second(self) -> float:
        """Measure the line load the settings need, bit/s (33 bits per value, 8N1)."""
        return BITS_PER_VALUE * self.values_per_block * self.rate_hz

    def line(self) -> dict[str, Any]:
        """Return the serial settings (8N1) for ``open_transport``."""
        return {"baudrate": self.baudrate, "bytesize": 8, "parity": "N", "stopbits": 1}


def _validate_axis(where: str, axis: Any, x: Any, z: Any) -> None:
    """Check what the laser looks at and where its spot is."""
    if axis not in AXES:
        raise ConfigError(f"{where} axis = {axis!r} is not one of {list(AXES)}")
    if not (isinstance(z, (int, float)) and -1.0 <= z <= 1.0):
        raise ConfigError(f"{where} z = {z!r} m is outside [-1, 1]")
    if axis == "vertical" and z != 0.0:
        raise ConfigError(f"{where} z = {z!r}: only a sway laser has a spot height z")
    if axis == "sway" and x != 0.0:
        raise ConfigError(f"{where} x = {x!r}: a sway laser has no chord position x")


def _validate_settings(*, where: str, range_mm: Any, rate_hz: Any, x: Any, standoff_mm: Any,
                       baudrate: Any, output: Any) -> None:
    """Check every setting (shared by ``from_table`` and direct construction)."""
    if isinstance(range_mm, bool) or range_mm not in RANGES_MM:
        raise ConfigError(f"{where} range_mm = {range_mm!r} is not one of {list(RANGES_MM)}")
    if not (isinstance(rate_hz, (int, float)) and 0.0 < rate_hz <= MAX_RATE_HZ):
        raise ConfigError(f"{where} rate_hz = {rate_hz!r} is outside (0, {MAX_RATE_HZ}]")
    if not (isinstance(x, (int, float)) and -1.0 <= x <= 1.0):
        raise ConfigError(f"{where} x = {x!r} m is outside [-1, 1]")
    if not (isinstance(standoff_mm, (int, float)) and 0.0 <= standoff_mm <= range_mm):
        raise ConfigError(f"{where} standoff_mm = {standoff_mm!r} is outside the measuring "
                          f"range [0, {range_mm}]")
    lo, hi = BAUDRATE_RANGE
    if isinstance(baudrate, bool) or not isinstance(baudrate, int) or not lo <= baudrate <= hi:
        raise ConfigError(f"{where} baudrate = {baudrate!r} is outside [{lo}, {hi}] (integer)")
    if not isinstance(output, tuple) or not all(isinstance(o, str) for o in output):
        raise ConfigError(f"{where} output must be a tuple of names, got {output!r}")
    unknown = [o for o in output if o not in WORDS_PER_VALUE]
    if unknown:
        raise ConfigError(f"{where} output: unknown value(s) {unknown}; allowed: "
                          f"{sorted(WORDS_PER_VALUE)}")
    if len(set(output)) != len(output):
        raise ConfigError(f"{where} output = {list(output)} names a value twice")
    missing = sorted(REQUIRED_OUTPUT - set(output))
    if missing:
        raise ConfigError(f"{where} output = {list(output)} lacks {missing}: the stream needs "
                          "the counter (gaps), the timestamp (device time) and the status "
                          "(trigger flag)")
    values = 1 + sum(WORDS_PER_VALUE[name] for name in output)
    needed = BITS_PER_VALUE * values * rate_hz
    if needed > baudrate:
        raise ConfigError(
            f"{where} baudrate = {baudrate} is too low for rate_hz = {rate_hz:g} with {values} "
            f"values per block: 33 bits x {values} x {rate_hz:g} Hz = {needed:.0f} bit/s "
            f"(the sensor would send 262075, 'data amount too big for the selected baud rate')"
        )
