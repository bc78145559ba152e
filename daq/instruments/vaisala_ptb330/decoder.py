"""The PTB330-class barometer's ASCII lines: parsed into pressure and temperature (pure, no I/O).

Responsibility: :func:`parse_line` and :class:`Ptb330LineDecoder` turn the barometer's reply
lines (``P=  1013.250 hPa    T= 21.34 'C``, any spacing) into :class:`Ptb330Line` values, with the
pressure unit read from every line and converted (:data:`PRESSURE_UNITS_PA`) and a malformed
line kept as :class:`Ptb330BadLine`; :func:`reading_from_line` derives the air density into a
:class:`BarometerReading` (the ideal gas law with :data:`ident.physics.air.R_DRY_AIR`), with the
plausible ranges (:data:`PRESSURE_RANGE_PA`, :data:`TEMPERATURE_RANGE_K`).

Not responsible for: polling the instrument or recovering its line
(:mod:`daq.instruments.vaisala_ptb330.driver`). The wire format is described in
``docs/reference/wire_formats.md``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass

from daq.errors import ProtocolError
from ident.physics.air import R_DRY_AIR

__all__ = ["MAX_LINE_BYTES", "PRESSURE_RANGE_PA", "PRESSURE_UNITS_PA", "TEMPERATURE_RANGE_K",
           "BarometerReading", "Ptb330BadLine", "Ptb330Line", "Ptb330LineDecoder", "parse_line",
           "reading_from_line"]


#: Pascals per unit of every pressure unit the decoder accepts (PTB330 Table 13 lists hPa, psi,
#: inHg, torr, bar, mbar, mmHg, kPa, Pa, mmH2O, inH2O; the water columns are refused, see the module
#: docstring). mmHg and inHg are the conventional units (13.5951 g/cm^3, g_n), psi the pound-force
#: per square inch; 'psia' is how the PTB200 names it (docs/reference/wire_formats.md, "Barometer").
PRESSURE_UNITS_PA: Mapping[str, float] = {
    "Pa": 1.0,
    "hPa": 100.0,
    "mbar": 100.0,
    "kPa": 1000.0,
    "bar": 100000.0,
    "mmHg": 133.322387415,
    "torr": 101325.0 / 760.0,
    "inHg": 25.4 * 133.322387415,
    "psi": 0.45359237 * 9.80665 / 0.0254**2,
    "psia": 0.45359237 * 9.80665 / 0.0254**2,
}


#: Temperature units of the barometer's temperature quantities (PTB330 Table 13: Celsius,
#: Fahrenheit or Kelvin; written 'C and 'F on the 7-bit line, PTU300 p.103).
_TEMPERATURE_UNITS = {"'C", "'F", "K"}


#: Plausible static pressure in a wind-tunnel hall, Pa (the rig-config range of
#: ``[simulation] pressure_pa``).
PRESSURE_RANGE_PA = (50_000.0, 120_000.0)


#: Plausible air temperature, K (-40..80 degC).
TEMPERATURE_RANGE_K = (233.15, 353.15)


#: Longest line the decoder buffers before discarding it as garbage, bytes.
MAX_LINE_BYTES = 256


_NUMBER = rb"[-+]?(?:\d+\.?\d*|\.\d+)|\*+"


_LINE_RE = re.compile(
    rb"P=[ \t]*(?P<p>" + _NUMBER + rb")[ \t]*(?P<pu>[^\s\d.*+-]\S*)[ \t]+"
    rb"T=[ \t]*(?P<t>" + _NUMBER + rb")[ \t]*(?P<tu>[^\s\d.*+-]\S*)"
    # A PTU300 (same family) appends relative humidity in its factory format (PTU300 p.103).
    rb"(?:[ \t]+RH=[ \t]*(?P<rh>" + _NUMBER + rb")[ \t]*%RH)?[ \t]*"
)


@dataclass(frozen=True)
class Ptb330Line:
    """One decoded data line.

    Attributes
    ----------
    pressure_pa : float
        Static pressure, Pa; NaN when the instrument sent ``*`` characters (value not available).
    temperature_k : float
        Temperature, K; NaN when not available.
    pressure_unit, temperature_unit : str
        Units as the line gave them (``hPa``, ``'C``, ...).
    resolution_pa : float
        Half a unit of the last printed pressure digit, Pa (the rounding error of the line).
    raw : bytes
        The line as received, without its terminator.
    relative_humidity : float
        %RH if the line carries it (a PTU300's ``RH=`` field), else NaN.
    """

    pressure_pa: float
    temperature_k: float
    pressure_unit: str
    temperature_unit: str
    resolution_pa: float
    raw: bytes
    relative_humidity: float = math.nan


@dataclass(frozen=True)
class Ptb330BadLine:
    """A line that is not a valid data line (garbled, truncated, unknown unit)."""

    raw: bytes
    reason: str

    def error(self) -> ProtocolError:
        """Return the ProtocolError describing this line (bytes in hex and as text)."""
        return ProtocolError(f"{self.reason}: {self.raw!r} ({self.raw.hex(' ')})")


def _decimals(text: bytes) -> int:
    dot = text.find(b".")
    return 0 if dot < 0 else len(text) - dot - 1


def parse_line(line: bytes) -> Ptb330Line | Ptb330BadLine:
    """Decode one line (without CR LF) of the format :data:`FORM_STRING` produces.

    Leading prompt characters (``>``) and spacing are tolerated; anything else that does not
    match, or an unknown unit, gives a :class:`Ptb330BadLine` naming the reason.
    """
    text = line.strip().lstrip(b">").strip()
    match = _LINE_RE.fullmatch(text)
    if match is None:
        return Ptb330BadLine(line, "not a 'P= <p> <unit> T= <t> <unit>' line")
    p_unit = match["pu"].decode("ascii", "replace")
    t_unit = match["tu"].decode("ascii", "replace")
    factor = PRESSURE_UNITS_PA.get(p_unit)
    if factor is None:
        return Ptb330BadLine(line, f"unknown pressure unit {p_unit!r}; known: "
                                   f"{sorted(PRESSURE_UNITS_PA)}")
    if t_unit not in _TEMPERATURE_UNITS:
        return Ptb330BadLine(line, f"unknown temperature unit {t_unit!r}; known: "
                                   f"{sorted(_TEMPERATURE_UNITS)}")
    p_text, t_text = match["p"], match["t"]
    # '*' characters: the quantity is not available (PTB330 Table 12, "quantity").
    pressure = math.nan if p_text.startswith(b"*") else float(p_text) * factor
    if t_text.startswith(b"*"):
        temperature = math.nan
    else:
        t = float(t_text)
        temperature = (t + 273.15 if t_unit == "'C"
                       else (t - 32.0) * 5.0 / 9.0 + 273.15 if t_unit == "'F" else t)
    resolution = 0.5 * 10.0 ** -_decimals(p_text) * factor
    rh_text = match["rh"]
    rh = math.nan if rh_text is None or rh_text.startswith(b"*") else float(rh_text)
    return Ptb330Line(pressure, temperature, p_unit, t_unit, resolution, bytes(line), rh)


class Ptb330LineDecoder:
    """Split a byte stream into lines and decode them; never raises, never blocks.

    Feed it whatever the transport returned (RUN-mode streams or ``SEND`` replies); it returns the
    complete lines decoded so far, as :class:`Ptb330Line` or :class:`Ptb330BadLine`. Lines end at
    LF (a preceding CR is dropped). Empty lines and prompts are skipped. Bytes before the last
    ``P=`` of a line are a truncated line (the partial-line fault) or noise: the decoder
    resynchronises on that ``P=``, reports the fragment as bad, and decodes the rest. Bytes
    that never reach an LF within :data:`MAX_LINE_BYTES` are dropped and counted.

    Attributes
    ----------
    lines_ok, lines_bad : int
        Counts of decoded and rejected lines.
    bytes_skipped : int
        Bytes dropped: rejected lines, fragments before a resynchronisation, overlong garbage.
    """

    def __init__(self) -> None:
        self._buffer = bytearray()
        self.lines_ok = 0
        self.lines_bad = 0
        self.bytes_skipped = 0

    @property
    def pending(self) -> bytes:
        """Measure the bytes received after the last line end (a partial line), as bytes."""
        return bytes(self._buffer)

    def reset(self) -> None:
        """Drop the partial line (after the transport's input was discarded)."""
        self.bytes_skipped += len(self._buffer)
        self._buffer.clear()

    def feed(self, data: bytes) -> list[Ptb330Line | Ptb330BadLine]:
        """Add received bytes; return every line they complete, in order."""
        self._buffer += data
        out: list[Ptb330Line | Ptb330BadLine] = []
        start = 0
        buf = self._buffer
        while True:
            end = buf.find(b"\n", start)
            if end < 0:
                break
            line = bytes(buf[start:end])
            start = end + 1
            if line.endswith(b"\r"):
                line = line[:-1]
            if not line.strip(b" \t\r>"):
                continue  # an empty line or a bare prompt
            self._decode_into(line, out)
        del buf[:start]
        if len(buf) > MAX_LINE_BYTES:  # no line end in sight: garbage, drop it
            out.append(Ptb330BadLine(bytes(buf), f"no line end within {MAX_LINE_BYTES} bytes"))
            self.lines_bad += 1
            self.bytes_skipped += len(buf)
            buf.clear()
        return out

    def _decode_into(self, line: bytes, out: list[Ptb330Line | Ptb330BadLine]) -> None:
        # A valid line holds 'P=' only at its start: bytes before the last 'P=' are the rest
        # of a truncated line (or noise), and what follows it is a whole line.
        cut = line.rfind(b"P=")
        if cut > 0:
            fragment, line = line[:cut], line[cut:]
            out.append(Ptb330BadLine(fragment, "truncated line (resynchronised on the next 'P=')"))
            self.lines_bad += 1
            self.bytes_skipped += len(fragment)
        decoded = parse_line(line)
        if isinstance(decoded, Ptb330BadLine):
            self.lines_bad += 1
            self.bytes_skipped += len(line) + 2
        else:
            self.lines_ok += 1
        out.append(decoded)


@dataclass(frozen=True)
class BarometerReading:
    """One barometer reading, stamped on the host clock.

    Attributes
    ----------
    pressure_pa : float
        Static pressure, Pa (NaN if not available or implausible, see ``status``).
    temperature_k : float
        Temperature of the barometer module, K (NaN likewise).
    density_kg_m3 : float
        Dry-air density ``p / (R T)``, kg/m^3 (NaN unless both inputs are valid). Humidity is
        neglected, which overestimates rho by ~0.4 % at 20 degC and 50 %RH (see
        :func:`reading_from_line`; the run writer uses moist air when the rig config has an
        ``[air] relative_humidity``, :mod:`daq.calibration`).
    host_time_ns : int
        ``time.monotonic_ns()`` when the line's last byte arrived.
    counter : int
        Poll number of the driver (each ``read`` uses one, failed or not: a jump is a gap).
    status : str
        Empty when every value is valid, else why a value is NaN (with the reported value).
    pressure_unit : str
        Pressure unit of the line.
    resolution_pa : float
        Rounding error of the printed pressure, Pa.
    raw : bytes
        The line as received.
    relative_humidity : float
        Relative humidity as a fraction (0.5 = 50 %RH) when the line carries it (a PTU300-class
        instrument's ``RH=`` field), else NaN (a PTB330 reports none).
    """

    pressure_pa: float
    temperature_k: float
    density_kg_m3: float
    host_time_ns: int
    counter: int
    status: str
    pressure_unit: str
    resolution_pa: float
    raw: bytes
    relative_humidity: float = math.nan

    @property
    def ok(self) -> bool:
        """Measure whether all values are valid (``status`` is empty)."""
        return not self.status

    def values(self) -> dict[str, float]:
        """Return the channels of :meth:`VaisalaPtb330.describe` with their values."""
        return {"pressure": self.pressure_pa, "temperature": self.temperature_k,
                "density": self.density_kg_m3, "relative_humidity": self.relative_humidity}


def reading_from_line(line: Ptb330Line, host_time_ns: int, counter: int) -> BarometerReading:
    """Check a decoded line for plausibility and derive the density.

    A value outside :data:`PRESSURE_RANGE_PA` / :data:`TEMPERATURE_RANGE_K` is well-formed but
    implausible (a failed sensor, or a unit table the decoder does not share with the device): it
    becomes NaN, the density too, and ``status`` keeps the reported value and the reason. Such a
    reading is returned, not raised: it belongs in the raw record, and a poll loop must not stop
    for it; a NaN cannot enter the dynamic pressure unnoticed.

    The density is that of dry air, ``rho = p / (R_d T)`` with R_d = 287.058 J/(kg K). Humidity
    is neglected: moist air is lighter by about ``0.378 e / p`` (e the water-vapour pressure),
    i.e. rho is overestimated by ~0.4 % at 20 degC and 50 %RH, ~0.7 % at 25 degC and 60 %RH, and
    ~1.1 % at 30 degC and 70 %RH.
    """
    p, t = line.pressure_pa, line.temperature_k
    problems = []
    if math.isnan(p):
        problems.append("pressure not available (device sent '*')")
    elif not PRESSURE_RANGE_PA[0] <= p <= PRESSURE_RANGE_PA[1]:
        problems.append(f"pressure {p:.6g} Pa outside {PRESSURE_RANGE_PA} Pa")
        p = math.nan
    if math.isnan(t):
        problems.append("temperature not available (device sent '*')")
    elif not TEMPERATURE_RANGE_K[0] <= t <= TEMPERATURE_RANGE_K[1]:
        problems.append(f"temperature {t:.6g} K outside {TEMPERATURE_RANGE_K} K")
        t = math.nan
    rh = line.relative_humidity / 100.0  # NaN when the line has none
    if not math.isnan(rh) and not 0.0 <= rh <= 1.0:
        problems.append(f"relative humidity {line.relative_humidity:.6g} %RH outside [0, 100]")
        rh = math.nan
    rho = p / (R_DRY_AIR * t)  # NaN propagates
    return BarometerReading(
        pressure_pa=p, temperature_k=t, density_kg_m3=rho, host_time_ns=host_time_ns,
        counter=counter, status="; ".join(problems),
        pressure_unit=line.pressure_unit, resolution_pa=line.resolution_pa, raw=line.raw,
        relative_humidity=rh,
    )
