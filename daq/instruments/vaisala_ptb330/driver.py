"""Vaisala PTB330-class barometer over RS-232 ASCII: the polled driver.

Responsibility: configure the barometer's output format, poll it (``SEND``), have its ASCII lines
decoded into static pressure (Pa), temperature (K) and air density whatever unit the instrument is
set to (:mod:`daq.instruments.vaisala_ptb330.decoder`), and turn every failure into a specific
:mod:`daq.errors` exception after a bounded, logged retry. Its settings are
:mod:`daq.instruments.vaisala_ptb330.settings`'. Not responsible for: opening the serial port's URL
(the caller builds the transport, with :data:`SERIAL_DEFAULTS` as line defaults), scheduling
acquisition threads, or recording (the driver only returns readings).

Wire format (docs/reference/wire_formats.md, "Barometer", manual facts cited inline):

- line settings 9600 baud, 7 data bits, even parity, 1 stop bit, XON/XOFF (a published PTB330
  integration); commands are ASCII terminated by a carriage return (``<cr>`` in the manuals);
- the driver sets the output format (``FORM``) to :data:`FORM_STRING`, which makes each reply a
  PTU300-style line (docs/reference/wire_formats.md, "Barometer", PTU300 p.103)::

      P=  1013.250 hPa    T= 21.34 'C <CR><LF>

  i.e. ``P=`` number pressure-unit ``T=`` number temperature-unit, CR LF. Field widths and
  padding are **[unverified]** (the manuals' ``x.y`` length modifier and the ``U6``/``U3``
  unit-field widths are not fixed by the facts we have), so the decoder accepts any spacing.
  The temperature quantity of the PTB330 is ``TP1`` (barometer module 1; PTB330 Table 13);
  a PTU300 calls it ``T``: subclass and override :attr:`VaisalaPtb330.FORM_STRING`;
- the pressure unit is read from every line (the instrument's ``UNIT`` can be changed on its display
  or serial port at any time: the "unit change" fault of docs/reference/wire_formats.md), and the
  value is converted with :data:`PRESSURE_UNITS_PA`; an unknown unit is a :class:`ProtocolError`,
  never a silently wrong number. ``mmH2O``/``inH2O`` are refused on purpose (their reference
  temperature is not stated in the line).

Temperature: ``TP1`` is the temperature of the pressure module, i.e. of the instrument, which
equals the air temperature only once the barometer is in thermal equilibrium with the tunnel air;
mount it in the tunnel hall away from heat sources.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Iterator, Mapping
from types import TracebackType
from typing import Any

from daq.errors import ProtocolError, TransportError, TransportTimeout
from daq.instruments.entry import DriverEntry
from daq.instruments.reading import PollSequence, Reading
from daq.instruments.vaisala_ptb330.decoder import (
    BarometerReading,
    Ptb330Line,
    Ptb330LineDecoder,
    reading_from_line,
)
from daq.instruments.vaisala_ptb330.settings import Ptb330Settings
from daq.transports.byte_transport import Transport

__all__ = ["DRIVER", "FORM_STRING", "SERIAL_DEFAULTS", "VaisalaPtb330"]

#: dtypes of the channels of :meth:`VaisalaPtb330.read`.
_DTYPES = {"pressure": "float64", "temperature": "float64", "density": "float64",
           "relative_humidity": "float64"}

logger = logging.getLogger(__name__)

#: Serial line defaults (docs/reference/wire_formats.md, "Barometer": "9600 baud, 7 data bits, even
#: parity, 1 stop bit, XON/XOFF"); the query of a ``serial://`` URL overrides them
#: (``open_transport(url,
#: **these)``).
SERIAL_DEFAULTS: Mapping[str, Any] = {
    "baudrate": 9600, "bytesize": 7, "parity": "E", "stopbits": 1, "xonxoff": True,
}

#: Output format the driver sets with ``FORM`` (modifiers from PTB330 Table 12 and the PTU300
#: ``FORM`` examples: ``"..."`` string constant, ``x.y`` length modifier, ``U6`` unit field of
#: 6 characters, ``#r #n`` CR LF). [unverified] exact field widths; the decoder ignores spacing.
FORM_STRING = '"P=" 6.3 P " " U6 "T=" 3.2 TP1 " " U3 #r #n'


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

    Each :meth:`read` (:meth:`measure`) sends ``SEND`` (or ``SEND aa``) and decodes one line. A
    garbled or partial line (:class:`ProtocolError`, with the bytes), no reply
    (:class:`TransportTimeout`) or a lost connection (:class:`TransportError`; the transport is
    reopened) is retried up to ``ATTEMPTS`` times in all, with a logged warning and exponential
    backoff; then the last error is raised.
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
        self._polls = PollSequence()
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
            self.measure()  # proves the format took effect
            self._polls = PollSequence()  # the check reading is not returned: polls from 1
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
        """Describe the channels of :meth:`read`: units, dtype, shape (one row per poll).

        ``pressure`` (static, Pa), ``temperature`` (of the barometer module, K) and
        ``density`` (dry air, kg/m^3), ``relative_humidity`` (a fraction, from a PTU300-class
        line's ``RH=`` field; a PTB330 has none); NaN where not available or implausible.
        """
        return {
            "pressure": {"units": "Pa", "dtype": "float64", "shape": ()},
            "temperature": {"units": "K", "dtype": "float64", "shape": ()},
            "density": {"units": "kg/m^3", "dtype": "float64", "shape": ()},
            "relative_humidity": {"units": "1", "dtype": "float64", "shape": ()},
        }

    # -- reading ------------------------------------------------------------------------------
    def read(self) -> Reading:
        """Poll one reading (:meth:`measure`): one row of :meth:`describe`'s channels.

        The counter is the poll number (a failed poll leaves a gap before the next reading);
        ``info`` keeps the line's ``status`` (why a value is NaN, empty when all are valid),
        ``pressure_unit`` and ``resolution_pa``. Raises as :meth:`measure`.
        """
        r = self.measure()
        return self._polls.reading(
            r.counter, r.values(), _DTYPES, host_time_ns=r.host_time_ns,
            info={"status": r.status, "pressure_unit": r.pressure_unit,
                  "resolution_pa": r.resolution_pa})

    def measure(self) -> BarometerReading:
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
        counter = self._polls.next()
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
        overruns its slot skips the missed slots rather than bursting. Errors of :meth:`measure`
        propagate.
        """
        interval = self.settings.poll_interval_s
        next_t = time.monotonic()
        done = 0
        while (count is None or done < count) and not (stop is not None and stop.is_set()):
            yield self.measure()
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


#: This driver's registry entry (collected by :mod:`daq.instruments.registry`).
DRIVER = DriverEntry(name="vaisala_ptb330", role="barometer", factory=VaisalaPtb330,
                    validate=Ptb330Settings.from_table, transport_defaults=SERIAL_DEFAULTS)
