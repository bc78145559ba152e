"""Simulated Vaisala PTB330-class barometer: the RS-232 ASCII protocol over socket:// or a pty.

Responsibility: answer the barometer's serial commands from the manual facts
(``docs/reference/wire_formats.md``, "Barometer"), produce its measurement lines from the virtual
tunnel's air (pressure and temperature, plus the instrument's own slow drift and seeded noise), and
inject the barometer's faults (garbled or partial line, no reply, unit change:
``docs/reference/wire_formats.md``, "Faults the simulators inject"), keeping truth counters so tests
can tell what the simulator dropped from what a driver lost. Not responsible for: anything the
driver does (this module shares no code with ``daq``: it encodes the wire format with its own
implementation, which the HIL tests cross-check against the driver's), nor the electrical line (a
pty is always 8N1; ``socket://`` carries bytes only).

Behaviour (manual facts, with the simulator's own choices marked [sim]):

- commands end with CR (or LF) and are not case sensitive (PTB220 manual: "The commands are not
  case sensitive"); XON/XOFF bytes on input are flow control, not data, and are dropped;
- modes (``SMODE STOP|RUN|POLL|SEND``; ``POLLED`` is accepted too, as a published Hydromet
  integration spells it) take effect at ``RESET`` (PTU200: "give the RESET command to initialize the
  new sending mode"); STOP: every command works; RUN: lines are output every ``INTV`` and only ``S``
  (or ESC) is obeyed (DMT152/PTU300 ``R``/``S``); POLL: only ``SEND [aa]`` and ``OPEN aa`` are
  obeyed, and ``OPEN aa`` ... ``CLOSE`` gives temporary command access (PTB330 p.101);
- ``SEND [aa]`` outputs one line in the ``FORM`` format (PTB330 p.101: ``pressure = 1013.02
  hPa`` with the factory format); a bare ``SEND`` is answered in POLL mode too [sim];
- ``FORM`` accepts the modifiers of PTB330 Table 12 (``x.y``, quantities, ``U``/``U1..U9``,
  ``"text"``, ``#r #n #rn #t #NNN`` and their backslash forms, ``/`` for the default) and answers
  ``OK`` (PTU300 p.103); ``x.y`` prints x integer digits and y decimals [sim; unverified];
- ``UNIT [quantity] unit`` switches pressure (hPa, psi, inHg, torr, bar, mbar, mmHg, kPa, Pa,
  mmH2O, inH2O) or temperature ('C, 'F, K) units (PTB330 Table 13);
- reply texts of ``SMODE``, ``INTV``, ``ADDR``, ``UNIT`` follow the manuals' examples; there is
  no echo and no ``>`` prompt [sim: the POLL-mode behaviour, where echo is off].

Longer than 600 lines: the barometer's command set, its units and formats, its run and poll
modes and its faults act on one device state; one module keeps that state in one place.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import select
import socket
import threading
import tty
from collections.abc import Mapping
from dataclasses import dataclass
from types import TracebackType
from typing import Any

import numpy as np

from simulators.clock import DeviceClock
from simulators.virtual_tunnel import VirtualTunnel

__all__ = ["FAULTS", "SimVaisalaPtb330", "TruthLine"]

#: The barometer's faults (docs/reference/wire_formats.md, "Faults the simulators inject").
FAULTS = ("garbled", "partial", "no_reply", "unit_change")
_LINE_FAULTS = ("garbled", "partial", "no_reply")

# Pascals per unit, the simulator's own table (conventional mercury 13595.1 kg/m^3 and water
# 1000 kg/m^3 columns under standard gravity; avoirdupois pound-force per square inch).
_G = 9.80665
_PA_PER_UNIT: dict[str, float] = {
    "pa": 1.0, "hpa": 100.0, "mbar": 100.0, "kpa": 1.0e3, "bar": 1.0e5,
    "mmhg": 13595.1 * _G * 1e-3, "torr": 101325.0 / 760.0, "inhg": 13595.1 * _G * 0.0254,
    "psi": 4.4482216152605 / 0.0254**2, "mmh2o": 1000.0 * _G * 1e-3,
    "inh2o": 1000.0 * _G * 0.0254,
}
_UNIT_SPELLING = {"pa": "Pa", "hpa": "hPa", "mbar": "mbar", "kpa": "kPa", "bar": "bar",
                  "mmhg": "mmHg", "torr": "torr", "inhg": "inHg", "psi": "psi",
                  "mmh2o": "mmH2O", "inh2o": "inH2O"}
_DEFAULT_DECIMALS = {"Pa": 0, "hPa": 2, "mbar": 2, "kPa": 3, "bar": 5, "mmHg": 2, "torr": 2,
                     "inHg": 3, "psi": 3, "mmH2O": 0, "inH2O": 1}
_TEMPERATURE_SPELLING = {"'c": "'C", "c": "'C", "'f": "'F", "f": "'F", "k": "K"}
_PRESSURE_QUANTITIES = {"P", "P1", "P2", "P3"}
_TEMPERATURE_QUANTITIES = {"T", "TP1", "TP2", "TP3"}
_OTHER_QUANTITIES = {"MCTR", "ADDR", "SN"}

#: Factory output format: SEND gives ``pressure = 1013.02 hPa`` (PTB330 p.101).
DEFAULT_FORM = '"pressure = " P " " U #r #n'
_FORM_TOKEN = re.compile(r'\s*("[^"]*"|[#\\](?:rn|r|n|t|\d{1,3})|\d+\.\d+|[A-Za-z][A-Za-z0-9]*|/)',
                         re.IGNORECASE)
#: Characters a garbled line gets: none can be part of a valid number, unit or label.
_GARBAGE = b"?!$%&@~^|`"
_XON_XOFF = bytes([0x11, 0x13])
_ESC = 0x1B
_SERIAL_NUMBER = "S1234567"


@dataclass(frozen=True)
class TruthLine:
    """What the simulator produced for one measurement line (before faults).

    Attributes
    ----------
    counter : int
        Measurement counter (1, 2, ...; the ``MCTR`` quantity).
    t_true : float
        True time of the measurement, s.
    pressure_pa, temperature_k : float
        Measured values, including the simulated drift and noise, before rounding.
    pressure_unit : str
        Unit the line was printed in.
    fault : str
        ``""`` if delivered intact, else the fault applied (``garbled``, ``partial``,
        ``no_reply``), or ``undelivered`` if nobody was connected.
    """

    counter: int
    t_true: float
    pressure_pa: float
    temperature_k: float
    pressure_unit: str
    fault: str


def _compile_form(text: str) -> list[tuple[str, Any]]:
    """Compile a FORM string into (kind, value) items; raise ValueError if invalid."""
    items: list[tuple[str, Any]] = []
    pos = 0
    text = text.strip()
    while pos < len(text):
        match = _FORM_TOKEN.match(text, pos)
        if match is None:
            raise ValueError(f"cannot parse FORM at {text[pos:]!r}")
        token = match.group(1)
        pos = match.end()
        low = token.lower()
        if token.startswith('"'):
            items.append(("text", token[1:-1].encode("ascii", "replace")))
        elif token[0] in "#\\":
            code = low[1:]
            special = {"rn": b"\r\n", "r": b"\r", "n": b"\n", "t": b"\t"}
            items.append(("text", special[code] if code in special else bytes([int(code) % 256])))
        elif re.fullmatch(r"\d+\.\d+", token):
            x, y = token.split(".")
            items.append(("fmt", None if (int(x), int(y)) == (0, 0) else (int(x), int(y))))
        elif re.fullmatch(r"U\d?", token, re.IGNORECASE):
            items.append(("unit", int(token[1:]) if len(token) > 1 else None))
        elif token.upper() in _PRESSURE_QUANTITIES | _TEMPERATURE_QUANTITIES | _OTHER_QUANTITIES:
            items.append(("q", token.upper()))
        elif token == "/":
            raise ValueError("'/' must be used alone")
        else:
            raise ValueError(f"unknown quantity or modifier {token!r}")
    return items


class SimVaisalaPtb330:
    """A simulated PTB330-class barometer reading the virtual tunnel's air.

    Parameters
    ----------
    tunnel : VirtualTunnel
        Source of the true air state (``tunnel.air``) and of true time (``tunnel.clock``).
    address : int
        Device address (``ADDR``), 0..255.
    mode : str
        Serial mode at power-up: ``STOP``, ``RUN``, ``POLL`` or ``SEND``.
    interval_s : float
        RUN-mode output interval (``INTV``), device seconds.
    measurement_period_s : float
        Shortest output interval (the internal measurement cycle), device seconds.
    pressure_unit, temperature_unit : str
        Units at power-up (``hPa``, ``'C``...).
    noise_pa, noise_k : float
        Standard deviation of the measurement noise, Pa and K.
    drift_pa_per_h, drift_k_per_h : float
        Slow linear drift of the readings against the truth, per hour of device time.
    time_scale : float
        Speed-up of every device duration (``INTV``, measurement cycle): RUN lines come
        ``time_scale`` times faster than on the real instrument (tests only; 1 = real time).
    clock : DeviceClock, optional
        The instrument's clock (offset, drift) over the tunnel's true time.
    rng : numpy Generator, int or None
        Noise and fault randomness (seed for reproducible runs).
    faults : mapping, optional
        Probability per line of ``garbled``, ``partial``, ``no_reply`` (each in [0, 1]).
    relative_humidity : float, optional
        A PTU300-class instrument (same family, with a humidity probe): every measurement line
        ends with ``RH= 45.0 %RH`` for this fraction (0.45); default None, a PTB330 (no RH).
    """

    def __init__(
        self,
        tunnel: VirtualTunnel,
        *,
        address: int = 0,
        mode: str = "STOP",
        interval_s: float = 1.0,
        measurement_period_s: float = 1.0,
        pressure_unit: str = "hPa",
        temperature_unit: str = "'C",
        noise_pa: float = 2.0,
        noise_k: float = 0.02,
        drift_pa_per_h: float = 20.0,
        drift_k_per_h: float = 0.2,
        time_scale: float = 1.0,
        clock: DeviceClock | None = None,
        rng: np.random.Generator | int | None = None,
        faults: Mapping[str, float] | None = None,
        relative_humidity: float | None = None,
    ) -> None:
        if mode.upper() not in ("STOP", "RUN", "POLL", "POLLED", "SEND"):
            raise ValueError(f"mode must be STOP, RUN, POLL or SEND, got {mode!r}")
        if not 0 <= address <= 255:
            raise ValueError(f"address must be in [0, 255], got {address!r}")
        if not (time_scale > 0 and interval_s >= 0 and measurement_period_s > 0):
            raise ValueError("time_scale and measurement_period_s must be > 0, interval_s >= 0")
        if relative_humidity is not None and not 0.0 <= relative_humidity <= 1.0:
            raise ValueError(f"relative_humidity must be a fraction in [0, 1], "
                             f"got {relative_humidity!r}")
        self.relative_humidity = relative_humidity
        if noise_pa < 0 or noise_k < 0:
            raise ValueError(f"noise must be >= 0, got {noise_pa!r} Pa, {noise_k!r} K")
        self.tunnel = tunnel
        self.clock = clock if clock is not None else DeviceClock()
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self.noise_pa, self.noise_k = float(noise_pa), float(noise_k)
        self.drift_pa_per_h, self.drift_k_per_h = float(drift_pa_per_h), float(drift_k_per_h)
        self.time_scale = float(time_scale)
        self.measurement_period_s = float(measurement_period_s)
        self._probabilities = dict.fromkeys(_LINE_FAULTS, 0.0)
        for name, p in (faults or {}).items():
            if name not in _LINE_FAULTS:
                raise ValueError(f"unknown fault {name!r}; faults by probability: {_LINE_FAULTS}")
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"fault probability {name} = {p!r} is outside [0, 1]")
            self._probabilities[name] = float(p)
        self._lock = threading.Lock()
        self._address = int(address)
        self._smode = "POLL" if mode.upper() == "POLLED" else mode.upper()
        self._interval_s = float(interval_s)
        self._p_unit = self._pressure_unit(pressure_unit)
        self._t_unit = self._temperature_unit(temperature_unit)
        self._form_text = DEFAULT_FORM
        self._form = _compile_form(DEFAULT_FORM)
        self._scheduled: list[str] = []  # faults for the next lines, in order
        self._counter = 0
        self.truth: list[TruthLine] = []
        self._stats = {"lines": 0, "intact": 0, "garbled": 0, "partial": 0, "no_reply": 0,
                       "undelivered": 0, "commands": 0, "unit_changes": 0}
        # Serial-line state (set at power-up, i.e. start()).
        self._active = "STOP"
        self._running = False
        self._opened = False
        self._next_run_td = 0.0
        self._inbuf = bytearray()
        # I/O
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._listener: socket.socket | None = None
        self._client: socket.socket | None = None
        self._master: int | None = None
        self._slave: int | None = None
        self.url: str | None = None

    # -- units --------------------------------------------------------------------------------
    @staticmethod
    def _pressure_unit(unit: str) -> str:
        key = {"psia": "psi"}.get(unit.lower(), unit.lower())
        if key not in _PA_PER_UNIT:
            raise ValueError(f"unknown pressure unit {unit!r}; "
                             f"known: {sorted(_UNIT_SPELLING.values())}")
        return _UNIT_SPELLING[key]

    @staticmethod
    def _temperature_unit(unit: str) -> str:
        if unit.lower() not in _TEMPERATURE_SPELLING:
            raise ValueError(f"unknown temperature unit {unit!r}; known: 'C, 'F, K")
        return _TEMPERATURE_SPELLING[unit.lower()]

    # -- test interface -------------------------------------------------------------------------
    def inject(self, fault: str, count: int = 1, **params: Any) -> None:
        """Inject a fault (``docs/reference/wire_formats.md``, "Faults the simulators inject").

        Parameters
        ----------
        fault : str
            ``garbled``, ``partial`` or ``no_reply``: applied to the next ``count`` measurement
            lines (``SEND`` replies or RUN lines). ``unit_change``: switch units now, as an
            operator would on the display, with ``unit=`` (pressure) and/or
            ``temperature_unit=``; any unit the instrument knows, including ``mmH2O``.
        count : int
            Number of lines affected (line faults only), >= 1.
        """
        if fault not in FAULTS:
            raise ValueError(f"unknown fault {fault!r}; known: {FAULTS}")
        if fault == "unit_change":
            unknown = set(params) - {"unit", "temperature_unit"}
            if unknown or not params:
                raise TypeError(f"unit_change takes unit= and/or temperature_unit=, got {params}")
            with self._lock:
                if "unit" in params:
                    self._p_unit = self._pressure_unit(params["unit"])
                if "temperature_unit" in params:
                    self._t_unit = self._temperature_unit(params["temperature_unit"])
                self._stats["unit_changes"] += 1
            return
        if params:
            raise TypeError(f"{fault} takes no parameters, got {sorted(params)}")
        if count < 1:
            raise ValueError(f"count must be >= 1, got {count!r}")
        with self._lock:
            self._scheduled.extend([fault] * count)

    @property
    def stats(self) -> dict[str, int]:
        """Measure the truth counters: lines produced, intact, per fault, undelivered, commands."""
        with self._lock:
            return dict(self._stats)

    @property
    def pressure_unit(self) -> str:
        """Measure the current pressure unit."""
        with self._lock:
            return self._p_unit

    @property
    def form(self) -> str:
        """Measure the current output format string."""
        with self._lock:
            return self._form_text

    @property
    def running(self) -> bool:
        """Measure whether RUN-mode output is active."""
        with self._lock:
            return self._running

    def true_air(self, t_true: float) -> tuple[float, float]:
        """Return the instrument's noise-free (pressure Pa, temperature K) at true time ``t_true``.

        This is the tunnel's air plus the instrument's drift, i.e. the mean of its readings.
        """
        hours = self.clock.device_time(t_true) / 3600.0
        air = self.tunnel.air
        return (air.pressure_pa + self.drift_pa_per_h * hours,
                air.temperature_k + self.drift_k_per_h * hours)

    # -- life cycle -----------------------------------------------------------------------------
    def start(self, transport: str = "socket") -> str:
        """Power up and serve on 127.0.0.1 (``socket``) or a pty pair (``pty``); return the URL.

        The pty URL states the line a pty really has, 8N1 (Linux ptys ignore the character size
        and parity; some kernels even refuse to set them), overriding the 7E1 default of a
        driver: ``serial:///dev/pts/N?bytesize=8&parity=N``.
        """
        if self._thread is not None:
            raise RuntimeError("simulator already started")
        if transport == "socket":
            listener = socket.create_server(("127.0.0.1", 0))
            listener.setblocking(False)
            self._listener = listener
            self.url = f"socket://127.0.0.1:{listener.getsockname()[1]}"
        elif transport == "pty":
            master, slave = os.openpty()
            tty.setraw(slave)  # no echo or line editing before a driver configures the port
            os.set_blocking(master, False)
            self._master, self._slave = master, slave
            self.url = f"serial://{os.ttyname(slave)}?bytesize=8&parity=N"
        else:
            raise ValueError(f"transport must be 'socket' or 'pty', got {transport!r}")
        self._power_up()
        self._stop.clear()
        self._thread = threading.Thread(target=self._serve, name=f"SimVaisalaPtb330-{transport}",
                                        daemon=True)
        self._thread.start()
        return self.url

    def stop(self) -> None:
        """Stop serving and release the port; idempotent."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        for sock in (self._client, self._listener):
            if sock is not None:
                sock.close()
        self._client = self._listener = None
        for fd in (self._master, self._slave):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = None

    def __enter__(self) -> SimVaisalaPtb330:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.stop()

    def _power_up(self) -> None:
        with self._lock:
            self._active = self._smode
            self._opened = False
            self._running = self._active == "RUN"
            self._next_run_td = self._device_now()
        if self._active == "STOP":
            self._reply("PTB330 / 1.01")  # type and version after power-up (PTB220 manual)
        elif self._active == "SEND":
            self._measurement_line()  # one message after power-up (PTB220 "SEND mode")

    # -- I/O loop ---------------------------------------------------------------------------
    def _device_now(self) -> float:
        return self.clock.device_time(self.tunnel.clock.now())

    def _serve(self) -> None:
        while not self._stop.is_set():
            sources: list[Any] = []
            if self._listener is not None:
                sources.append(self._listener)
            if self._client is not None:
                sources.append(self._client)
            if self._master is not None:
                sources.append(self._master)
            timeout = 0.05
            with self._lock:
                if self._running:
                    period = self._run_period_s()
                    timeout = min(timeout, max(0.0, self._next_run_td - self._device_now()))
                    timeout = min(timeout, period / 4)
            readable, _, _ = select.select(sources, [], [], timeout)
            for source in readable:
                if source is self._listener:
                    self._accept()
                else:
                    self._receive(source)
            self._run_output()

    def _accept(self) -> None:
        assert self._listener is not None
        try:
            conn, _ = self._listener.accept()
        except BlockingIOError:
            return
        if self._client is not None:
            self._client.close()  # one peer per serial line: the newest wins
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._client = conn

    def _receive(self, source: Any) -> None:
        try:
            if self._master is not None and source is self._master:
                data = os.read(self._master, 4096)
            else:
                data = source.recv(4096)
        except BlockingIOError:
            return
        except OSError:
            data = b""
        if not data:
            if source is self._client:
                self._client.close()
                self._client = None
            return
        for byte in data:
            if byte in _XON_XOFF:
                continue
            if byte == _ESC:
                self._stop_run()
                continue
            if byte in (0x0D, 0x0A):
                line = bytes(self._inbuf).decode("ascii", "replace").strip()
                self._inbuf.clear()
                if line:
                    self._command(line)
            elif len(self._inbuf) < 512:
                self._inbuf.append(byte)

    def _write(self, data: bytes) -> bool:
        try:
            if self._client is not None:
                self._client.sendall(data)
                return True
            if self._master is not None:
                os.write(self._master, data)
                return True
        except OSError:
            if self._client is not None:
                self._client.close()
                self._client = None
        return False

    def _reply(self, text: str) -> None:
        self._write(text.encode("ascii", "replace") + b"\r\n")

    # -- commands -------------------------------------------------------------------------------
    def _address_matches(self, arg: str, *, allow_empty: bool) -> bool:
        if not arg:
            return allow_empty
        try:
            return int(arg) == self._address
        except ValueError:
            return False

    def _stop_run(self) -> None:
        with self._lock:
            if self._running:
                self._running = False
                self._active = "STOP" if self._active == "RUN" else self._active

    def _command(self, line: str) -> None:
        with self._lock:
            self._stats["commands"] += 1
            running, active, opened = self._running, self._active, self._opened
        word, _, arg = line.partition(" ")
        word, arg = word.upper(), arg.strip()
        if running:  # RUN output: only S is obeyed (DMT152, PTU300)
            if word == "S":
                self._stop_run()
            return
        if active == "POLL" and not opened:  # POLL: only SEND [aa] and OPEN aa (PTB330 p.101)
            if word == "SEND" and self._address_matches(arg, allow_empty=True):
                self._measurement_line()
            elif word == "OPEN" and self._address_matches(arg, allow_empty=False):
                with self._lock:
                    self._opened = True
                self._reply(f"PTB330: {self._address} line opened for operator commands")
            return
        handler = {
            "SEND": self._cmd_send, "R": self._cmd_r, "S": lambda a: None,
            "SMODE": self._cmd_smode, "INTV": self._cmd_intv, "FORM": self._cmd_form,
            "UNIT": self._cmd_unit, "ADDR": self._cmd_addr, "RESET": lambda a: self._power_up(),
            "OPEN": lambda a: self._reply(f"PTB330: {self._address} line opened for operator "
                                          "commands"),
            "CLOSE": self._cmd_close,
        }.get(word)
        if handler is None:
            self._reply("Unknown command")  # [sim] reply text
        else:
            handler(arg)

    def _cmd_send(self, arg: str) -> None:
        if self._address_matches(arg, allow_empty=True):
            self._measurement_line()

    def _cmd_r(self, arg: str) -> None:
        with self._lock:
            self._running = True
            self._next_run_td = self._device_now()

    def _cmd_close(self, arg: str) -> None:
        with self._lock:
            self._opened = False
        self._reply("line closed")

    def _cmd_smode(self, arg: str) -> None:
        mode = arg.upper()
        if mode == "POLLED":
            mode = "POLL"
        if mode:
            if mode not in ("STOP", "RUN", "POLL", "SEND"):
                self._reply("Invalid mode")  # [sim] reply text
                return
            with self._lock:
                self._smode = mode
        self._reply(f"Serial mode : {self._smode}")

    def _cmd_intv(self, arg: str) -> None:
        parts = arg.split()
        if parts:
            try:
                n = int(parts[0])
                scale = {"S": 1.0, "MIN": 60.0, "H": 3600.0}[parts[1].upper() if len(parts) > 1
                                                              else "S"]
            except (ValueError, KeyError):
                self._reply("Invalid interval")  # [sim] reply text
                return
            if not 0 <= n <= 255:  # INTV n: 0 ... 255 (DMT152, HMP228)
                self._reply("Invalid interval")
                return
            with self._lock:
                self._interval_s = n * scale
        self._reply(f"Output interval: {self._interval_s:g} s")

    def _cmd_form(self, arg: str) -> None:
        if not arg:
            self._reply(f"Output format  : {self._form_text}")
            return
        text = DEFAULT_FORM if arg == "/" else arg
        try:
            items = _compile_form(text)
        except ValueError as exc:
            self._reply(f"Invalid format: {exc}")  # [sim] reply text
            return
        with self._lock:
            self._form_text, self._form = text, items
        self._reply("OK")

    def _cmd_unit(self, arg: str) -> None:
        parts = arg.split()
        try:
            if len(parts) == 1:
                try:
                    unit = self._pressure_unit(parts[0])
                    with self._lock:
                        self._p_unit = unit
                except ValueError:
                    t_unit = self._temperature_unit(parts[0])
                    with self._lock:
                        self._t_unit = t_unit
            elif len(parts) == 2:
                quantity = parts[0].upper()
                if quantity in _PRESSURE_QUANTITIES:
                    unit = self._pressure_unit(parts[1])
                    with self._lock:
                        self._p_unit = unit
                elif quantity in _TEMPERATURE_QUANTITIES:
                    t_unit = self._temperature_unit(parts[1])
                    with self._lock:
                        self._t_unit = t_unit
                else:
                    raise ValueError(quantity)
            elif parts:
                raise ValueError(arg)
        except ValueError:
            self._reply("Invalid unit")  # [sim] reply text
            return
        with self._lock:
            p_unit, t_unit = self._p_unit, self._t_unit
        for quantity in ("P", "P1"):
            self._reply(f"{quantity:<6}: {p_unit}")
        self._reply(f"{'TP1':<6}: {t_unit}")

    def _cmd_addr(self, arg: str) -> None:
        if arg:
            try:
                address = int(arg)
            except ValueError:
                address = -1
            if not 0 <= address <= 255:
                self._reply("Invalid address")  # [sim] reply text
                return
            with self._lock:
                self._address = address
        self._reply(f"Address : {self._address}")

    # -- measurement lines ----------------------------------------------------------------------
    def _run_period_s(self) -> float:
        return max(self._interval_s, self.measurement_period_s) / self.time_scale

    def _run_output(self) -> None:
        with self._lock:
            if not self._running:
                return
            now = self._device_now()
            if now < self._next_run_td:
                return
            period = self._run_period_s()
            # Keep the cadence; after a long stall resume at once rather than burst.
            self._next_run_td = max(self._next_run_td + period, now)
        self._measurement_line()

    def _measurement_line(self) -> None:
        t_true = self.tunnel.clock.now()
        p_mean, t_mean = self.true_air(t_true)
        with self._lock:
            pressure = p_mean + self.noise_pa * float(self.rng.standard_normal())
            temperature = t_mean + self.noise_k * float(self.rng.standard_normal())
            self._counter += 1
            counter = self._counter
            p_unit, t_unit, form = self._p_unit, self._t_unit, self._form
            fault = self._scheduled.pop(0) if self._scheduled else ""
            if not fault:
                for name in _LINE_FAULTS:
                    if self._probabilities[name] and self.rng.random() < self._probabilities[name]:
                        fault = name
                        break
            line = self._render(form, pressure, temperature, p_unit, t_unit, counter)
            if self.relative_humidity is not None:  # a PTU300's factory form ends with RH
                text = line.rstrip(b"\r\n")
                line = (text + f" RH= {100.0 * self.relative_humidity:5.1f} %RH".encode()
                        + line[len(text):])
            if fault == "garbled":
                body = bytearray(line.rstrip(b"\r\n"))
                n = int(self.rng.integers(1, 4))
                for index in self.rng.choice(len(body), size=min(n, len(body)), replace=False):
                    body[int(index)] = _GARBAGE[int(self.rng.integers(len(_GARBAGE)))]
                line = bytes(body) + line[len(body):]
            elif fault == "partial":
                body_len = len(line.rstrip(b"\r\n"))
                line = line[: int(self.rng.integers(1, max(body_len, 2)))]
            elif fault == "no_reply":
                line = b""
            # Record before writing: a driver may act on the line before this thread resumes.
            self._stats["lines"] += 1
            self._stats[fault if fault else "intact"] += 1
            self.truth.append(TruthLine(counter, t_true, pressure, temperature, p_unit, fault))
            index = len(self.truth) - 1
        if line and not self._write(line):
            with self._lock:
                self._stats[fault if fault else "intact"] -= 1
                self._stats["undelivered"] += 1
                self.truth[index] = TruthLine(counter, t_true, pressure, temperature, p_unit,
                                              "undelivered")

    def _render(self, form: list[tuple[str, Any]], pressure: float, temperature: float,
                p_unit: str, t_unit: str, counter: int) -> bytes:
        out = bytearray()
        number_format: tuple[int, int] | None = None
        last_unit = ""
        for kind, value in form:
            if kind == "text":
                out += value
            elif kind == "fmt":
                number_format = value
            elif kind == "unit":
                out += (last_unit if value is None else last_unit[:value].ljust(value)).encode()
            elif value in _PRESSURE_QUANTITIES:
                shown = pressure / _PA_PER_UNIT[p_unit.lower()]
                out += self._number(shown, number_format, _DEFAULT_DECIMALS[p_unit])
                last_unit = p_unit
            elif value in _TEMPERATURE_QUANTITIES:
                celsius = temperature - 273.15
                shown = (celsius if t_unit == "'C" else celsius * 9.0 / 5.0 + 32.0
                         if t_unit == "'F" else temperature)
                out += self._number(shown, number_format, 2)
                last_unit = t_unit
            elif value == "MCTR":
                out += str(counter).encode()
            elif value == "ADDR":
                out += f"{self._address:>3}".encode()
            elif value == "SN":
                out += _SERIAL_NUMBER.encode()
        return bytes(out)

    @staticmethod
    def _number(value: float, number_format: tuple[int, int] | None, decimals: int) -> bytes:
        if not math.isfinite(value):
            return b"******"
        if number_format is None:
            return f"{value:.{decimals}f}".encode()
        digits, places = number_format
        width = digits + (places + 1 if places else 0)
        return f"{value:{width}.{places}f}".encode()
