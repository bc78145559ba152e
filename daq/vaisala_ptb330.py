"""Vaisala PTB330-class barometer over RS-232 ASCII: settings, line decoder and polled driver.

Responsibility: configure the barometer's output format, poll it (``SEND``), decode its ASCII
lines into static pressure (Pa) and temperature (K) whatever unit the instrument is set to, derive
the air density, and turn every failure into a specific :mod:`daq.errors` exception after a
bounded, logged retry. Not responsible for: opening the serial port's URL (the caller builds the
transport, with :data:`SERIAL_DEFAULTS` as line defaults), scheduling acquisition threads, or
recording (the driver only returns readings).

Wire format (DEVICES.md A.3 "Barometer / T / RH", manual facts cited inline):

- line settings 9600 baud, 7 data bits, even parity, 1 stop bit, XON/XOFF (the PTB330 integration
  in DEVICES.md A.3); commands are ASCII terminated by a carriage return (``<cr>`` in the manuals);
- the driver sets the output format (``FORM``) to :data:`FORM_STRING`, which makes each reply a
  PTU300-style line (DEVICES.md A.3, PTU300 p.103)::

      P=  1013.250 hPa    T= 21.34 'C <CR><LF>

  i.e. ``P=`` number pressure-unit ``T=`` number temperature-unit, CR LF. Field widths and
  padding are **[unverified]** (the manuals' ``x.y`` length modifier and the ``U6``/``U3``
  unit-field widths are not fixed by the facts we have), so the decoder accepts any spacing.
  The temperature quantity of the PTB330 is ``TP1`` (barometer module 1; PTB330 Table 13);
  a PTU300 calls it ``T``: subclass and override :attr:`VaisalaPtb330.FORM_STRING`;
- the pressure unit is read from every line (the instrument's ``UNIT`` can be changed on its
  display or serial port at any time: the DEVICES.md A.5 fault "unit change"), and the value is
  converted with :data:`PRESSURE_UNITS_PA`; an unknown unit is a :class:`ProtocolError`, never a
  silently wrong number. ``mmH2O``/``inH2O`` are refused on purpose (their reference temperature
  is not stated in the line).

Temperature: ``TP1`` is the temperature of the pressure module, i.e. of the instrument, which
equals the air temperature only once the barometer is in thermal equilibrium with the tunnel air;
mount it in the tunnel hall away from heat sources.
"""

from __future__ import annotations

import logging
import math
import re
import threading
import time
from collections import deque
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from types import TracebackType
from typing import Any

from daq.config import check_keys, number
from daq.errors import ConfigError, ProtocolError, TransportError, TransportTimeout
from daq.registry import DriverEntry, register
from daq.transport import Transport

__all__ = [
    "FORM_STRING",
    "PRESSURE_RANGE_PA",
    "PRESSURE_UNITS_PA",
    "R_DRY_AIR",
    "SERIAL_DEFAULTS",
    "TEMPERATURE_RANGE_K",
    "BarometerReading",
    "Ptb330BadLine",
    "Ptb330Line",
    "Ptb330LineDecoder",
    "Ptb330Settings",
    "VaisalaPtb330",
    "parse_line",
    "reading_from_line",
]

logger = logging.getLogger(__name__)

#: Serial line defaults (DEVICES.md A.3: "9600 baud, 7 data bits, even parity, 1 stop bit,
#: XON/XOFF"); the query of a ``serial://`` URL overrides them (``open_transport(url, **these)``).
SERIAL_DEFAULTS: Mapping[str, Any] = {
    "baudrate": 9600, "bytesize": 7, "parity": "E", "stopbits": 1, "xonxoff": True,
}

#: Output format the driver sets with ``FORM`` (modifiers from PTB330 Table 12 and the PTU300
#: ``FORM`` examples: ``"..."`` string constant, ``x.y`` length modifier, ``U6`` unit field of
#: 6 characters, ``#r #n`` CR LF). [unverified] exact field widths; the decoder ignores spacing.
FORM_STRING = '"P=" 6.3 P " " U6 "T=" 3.2 TP1 " " U3 #r #n'

#: Gas constant of dry air, J/(kg K).
R_DRY_AIR = 287.058

#: Pascals per unit of every pressure unit the decoder accepts (PTB330 Table 13 lists hPa, psi,
#: inHg, torr, bar, mbar, mmHg, kPa, Pa, mmH2O, inH2O; the water columns are refused, see the
#: module docstring). mmHg and inHg are the conventional units (13.5951 g/cm^3, g_n), psi the
#: pound-force per square inch; 'psia' is how the PTB200 names it (DEVICES.md A.3).
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


# ------------------------------------------------------------------------------------------
# Pure decoding
# ------------------------------------------------------------------------------------------
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
        %RH if the line carries it (a PTU300's ``RH=`` field), else NaN; not used for density.
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


# ------------------------------------------------------------------------------------------
# Readings
# ------------------------------------------------------------------------------------------
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
        :func:`reading_from_line`).
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

    @property
    def ok(self) -> bool:
        """Measure whether all values are valid (``status`` is empty)."""
        return not self.status

    def values(self) -> dict[str, float]:
        """Return the channels of :meth:`VaisalaPtb330.describe` with their values."""
        return {"pressure": self.pressure_pa, "temperature": self.temperature_k,
                "density": self.density_kg_m3}


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
    rho = p / (R_DRY_AIR * t)  # NaN propagates
    return BarometerReading(
        pressure_pa=p, temperature_k=t, density_kg_m3=rho, host_time_ns=host_time_ns,
        counter=counter, status="; ".join(problems),
        pressure_unit=line.pressure_unit, resolution_pa=line.resolution_pa, raw=line.raw,
    )


# ------------------------------------------------------------------------------------------
# Settings
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Ptb330Settings:
    """Driver settings of a ``[barometer]`` table with ``driver = "vaisala_ptb330"``.

    Attributes
    ----------
    poll_interval_s : float
        Period of :meth:`VaisalaPtb330.poll`, s, in [0.1, 60]; default 1.0.
    timeout_s : float
        Longest wait for one reply line, s, in [0.05, 30]; default 2.0.
    address : int or None
        Device address for ``SEND aa`` / ``OPEN aa`` (POLL mode on a shared line), 0..255
        (PTB330 manual p.101, ``OPEN [aa]``); None (default) sends a bare ``SEND``.
    """

    poll_interval_s: float = 1.0
    timeout_s: float = 2.0
    address: int | None = None

    def __post_init__(self) -> None:
        where = "vaisala_ptb330 settings"
        number({"poll_interval_s": self.poll_interval_s}, "poll_interval_s", where,
               lo=0.1, hi=60.0)
        number({"timeout_s": self.timeout_s}, "timeout_s", where, lo=0.05, hi=30.0)
        _check_address(self.address, where)

    @classmethod
    def from_table(cls, table: Mapping[str, Any], where: str) -> Ptb330Settings:
        """Validate a rig-config table (without driver/url/name) or raise ConfigError."""
        check_keys(table, where, set(), {"poll_interval_s", "timeout_s", "address"})
        address = table.get("address")
        _check_address(address, where)
        return cls(
            poll_interval_s=number(table, "poll_interval_s", where, lo=0.1, hi=60.0,
                                   default=1.0),
            timeout_s=number(table, "timeout_s", where, lo=0.05, hi=30.0, default=2.0),
            address=address,
        )


def _check_address(address: object, where: str) -> None:
    if address is None:
        return
    if isinstance(address, bool) or not isinstance(address, int) or not 0 <= address <= 255:
        raise ConfigError(f"{where} address = {address!r} must be an integer in [0, 255]")


# ------------------------------------------------------------------------------------------
# Driver
# ------------------------------------------------------------------------------------------
class VaisalaPtb330:
    """Polled driver of a Vaisala PTB330-class barometer.

    Parameters
    ----------
    transport : Transport
        A serial transport, created (not opened) by the caller, e.g.
        ``open_transport(url, **SERIAL_DEFAULTS)``.
    settings : Ptb330Settings, optional
        Defaults to ``Ptb330Settings()``.

    Notes
    -----
    :meth:`open` brings the instrument to a known state, whatever it was doing, with commands
    from the manuals (each followed by a short wait for its reply, which is discarded: the reply
    texts are [unverified]):

    1. ``S`` stops a RUN-mode output (Vaisala PTU300/DMT152 ``R``/``S``; [unverified] on the
       PTB330, harmless otherwise); its reply, if any, is collected with the next command's;
    2. ``OPEN aa`` when an address is set (a POLL-mode unit accepts commands only once opened,
       PTB330 p.101);
    3. ``FORM`` :data:`FORM_STRING` (PTB330 Table 12);
    4. ``CLOSE`` when an address is set (back to POLL mode, PTB330 p.101);
    5. a first ``SEND [aa]`` whose reply must decode: otherwise the instrument did not adopt the
       format (e.g. a POLL-mode unit without ``address``) and :class:`ProtocolError` says so.

    Each :meth:`read` sends ``SEND`` (or ``SEND aa``) and decodes one line. A garbled or partial
    line (:class:`ProtocolError`, with the bytes), no reply (:class:`TransportTimeout`) or a lost
    connection (:class:`TransportError`; the transport is reopened) is retried up to
    ``ATTEMPTS`` times in all, with a logged warning and exponential backoff; then the last
    error is raised.
    """

    #: Output format set by :meth:`open`; subclasses may override it (e.g. ``T`` on a PTU300).
    FORM_STRING: str = FORM_STRING
    #: Attempts per read (first try + retries).
    ATTEMPTS: int = 3
    #: Backoff before retry k (k = 1, 2, ...) is ``BACKOFF_S * 2**(k-1)``, s.
    BACKOFF_S: float = 0.05
    #: Longest wait for a configuration command's reply, s; then a quiet gap ends the reply.
    COMMAND_WAIT_S: float = 0.1
    QUIET_S: float = 0.03

    def __init__(self, transport: Transport, settings: Ptb330Settings | None = None) -> None:
        if settings is None:
            settings = Ptb330Settings()
        if not isinstance(settings, Ptb330Settings):
            raise TypeError(f"settings must be Ptb330Settings, got {type(settings).__name__}")
        self._transport = transport
        self.settings = settings
        self._decoder = Ptb330LineDecoder()
        self._counter = 0
        self._stats = {"reads": 0, "retries": 0, "timeouts": 0, "protocol_errors": 0,
                       "reconnects": 0}
        self._bad_lines: deque[bytes] = deque(maxlen=16)
        self._opened = False

    # -- life cycle ---------------------------------------------------------------------------
    def open(self) -> None:
        """Open the transport, set the output format and check one reading; idempotent."""
        if self._opened:
            return
        if not self._transport.is_open:
            self._transport.open()
        try:
            self._configure()
            self._opened = True
            self.read()  # proves the format took effect
            self._counter = 0  # the check reading is not returned: polls count from 1
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Close the transport; idempotent."""
        self._opened = False
        self._transport.close()

    def __enter__(self) -> VaisalaPtb330:
        self.open()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def _configure(self) -> None:
        self._transport.reset_input()
        self._command("S", wait=False)
        if self.settings.address is not None:
            self._command(f"OPEN {self.settings.address}")
        self._command(f"FORM {self.FORM_STRING}")
        if self.settings.address is not None:
            self._command("CLOSE")
        self._decoder.reset()

    def _command(self, text: str, *, wait: bool = True) -> bytes:
        """Send a configuration command; return (and log) whatever reply came back."""
        self._transport.write(text.encode("ascii") + b"\r")
        reply = bytearray()
        if not wait:
            return b""
        deadline = time.monotonic() + self.COMMAND_WAIT_S
        while True:
            window = self.QUIET_S if reply.endswith(b"\n") else deadline - time.monotonic()
            if window <= 0:
                break
            try:
                reply += self._transport.read(256, window)
            except TransportTimeout:
                break
        logger.debug("%s: %s -> %r", self._transport.url, text, bytes(reply))
        return bytes(reply)

    # -- properties ---------------------------------------------------------------------------
    @property
    def is_open(self) -> bool:
        """Measure whether the driver is open (configured, transport open)."""
        return self._opened and self._transport.is_open

    @property
    def stats(self) -> dict[str, int]:
        """Measure the driver's counters: reads, retries, timeouts, protocol errors, reconnects."""
        return dict(self._stats)

    @property
    def bad_lines(self) -> list[bytes]:
        """Measure the last (up to 16) rejected lines, as received."""
        return list(self._bad_lines)

    def describe(self) -> dict[str, dict[str, Any]]:
        """Describe the channels of :meth:`BarometerReading.values`: units, dtype, shape."""
        return {
            "pressure": {"units": "Pa", "dtype": "float64", "shape": ()},
            "temperature": {"units": "K", "dtype": "float64", "shape": ()},
            "density": {"units": "kg/m^3", "dtype": "float64", "shape": ()},
        }

    # -- reading ------------------------------------------------------------------------------
    def read(self) -> BarometerReading:
        """Poll one reading (``SEND``), retrying garbled, partial or missing replies.

        Raises
        ------
        ProtocolError
            Every attempt got a line that does not decode (the message holds its bytes).
        TransportTimeout
            No reply to any attempt.
        TransportError
            The transport failed and could not be reopened.
        """
        if not self._opened:
            raise TransportError(f"{self._transport.url}: barometer not open")
        self._counter += 1
        counter = self._counter
        last: Exception | None = None
        for attempt in range(1, self.ATTEMPTS + 1):
            if attempt > 1:
                delay = self.BACKOFF_S * 2 ** (attempt - 2)
                logger.warning("barometer read attempt %d of %d after: %s (backoff %.3g s)",
                               attempt, self.ATTEMPTS, last, delay)
                self._stats["retries"] += 1
                time.sleep(delay)
                try:
                    self._recover(last)
                except TransportError as exc:
                    last = exc
                    continue
            try:
                line, host_ns = self._poll_once()
            except TransportTimeout as exc:
                self._stats["timeouts"] += 1
                last = exc
            except ProtocolError as exc:
                self._stats["protocol_errors"] += 1
                last = exc
            except TransportError as exc:
                last = exc
            else:
                self._stats["reads"] += 1
                return reading_from_line(line, host_ns, counter)
        assert last is not None
        note = f" (after {self.ATTEMPTS} attempts)"
        if isinstance(last, TransportTimeout):
            raise TransportTimeout(f"{last}{note}") from last
        if isinstance(last, ProtocolError):
            raise ProtocolError(f"{last}{note}") from last
        raise TransportError(f"{last}{note}") from last

    def _recover(self, error: Exception | None) -> None:
        if isinstance(error, TransportError) and not isinstance(error, TransportTimeout):
            self._stats["reconnects"] += 1
            self._transport.close()
            self._transport.open()
        else:
            self._transport.reset_input()
        self._decoder.reset()

    def _poll_once(self) -> tuple[Ptb330Line, int]:
        address = self.settings.address
        command = "SEND" if address is None else f"SEND {address}"
        self._transport.write(command.encode("ascii") + b"\r")
        deadline = time.monotonic() + self.settings.timeout_s
        while True:
            try:
                data = self._transport.read(256, max(deadline - time.monotonic(), 0.0))
            except TransportTimeout as exc:
                pending = self._decoder.pending
                if pending:
                    self._bad_lines.append(pending)
                    raise ProtocolError(
                        f"{self._transport.url}: partial line, no line end within "
                        f"{self.settings.timeout_s:g} s: {pending!r} ({pending.hex(' ')})"
                    ) from exc
                raise TransportTimeout(f"{self._transport.url}: no reply to {command!r} "
                                       f"within {self.settings.timeout_s:g} s") from exc
            host_ns = time.monotonic_ns()
            for item in self._decoder.feed(data):
                if isinstance(item, Ptb330Line):
                    return item, host_ns
                if item.raw.strip().upper() == command.encode("ascii"):
                    continue  # the instrument's echo of our command
                self._bad_lines.append(item.raw)
                raise ProtocolError(f"{self._transport.url}: {item.error()}")

    def poll(self, stop: threading.Event | None = None,
             count: int | None = None) -> Iterator[BarometerReading]:
        """Yield readings every ``poll_interval_s`` until ``stop`` is set or ``count`` are done.

        The schedule is kept on absolute deadlines (no accumulated sleep error); a read that
        overruns its slot skips the missed slots rather than bursting. Errors of :meth:`read`
        propagate.
        """
        interval = self.settings.poll_interval_s
        next_t = time.monotonic()
        done = 0
        while (count is None or done < count) and not (stop is not None and stop.is_set()):
            yield self.read()
            done += 1
            if count is not None and done >= count:
                return
            now = time.monotonic()
            next_t += interval
            if next_t < now:
                next_t += math.ceil((now - next_t) / interval) * interval
            wait = next_t - now
            if stop is not None:
                if stop.wait(wait):
                    return
            else:
                time.sleep(wait)


register(DriverEntry(name="vaisala_ptb330", role="barometer", factory=VaisalaPtb330,
                     validate=Ptb330Settings.from_table, transport_defaults=SERIAL_DEFAULTS))
