r"""Driver for the Micro-Epsilon optoNCDT ILD1420-class laser displacement sensor (RS-422).

Responsibility: :class:`MicroEpsilonIld1420` talks the sensor's ASCII command set
(``GETOUTINFO_RS422``, ``MASTERMV``, ``OUTPUT``, ``GETINFO``), reads its binary stream (commands
and stream share the line: the stream bytes around a reply are kept), and reconnects with a
bounded backoff when the line drops. The pieces without I/O are the package's other modules: the
``[[lasers]]`` table (:class:`~daq.instruments.microepsilon_ild1420.settings.Ild1420Settings`),
the 3-byte words into samples
(:class:`~daq.instruments.microepsilon_ild1420.decoder.Ild1420Decoder`), and the unwrapping of
the 18-bit counter and the 32-bit timestamp with its gaps and restarts
(:class:`~daq.instruments.microepsilon_ild1420.sequencer.Ild1420Sequencer`).

Not responsible for: opening ports (the transport is injected, see
:mod:`daq.transports.byte_transport`; :meth:`Ild1420Settings.line` gives its serial settings),
converting distances into heave and pitch (the acquisition does that with the ``x`` and
``standoff_mm`` settings), mapping the device clock onto the host clock (the synchronisation), or
threads and queues (the acquisition runs one reader thread per sensor).

Manual facts (docs/reference/wire_formats.md, "Laser displacement sensors") and the choices made
beyond them:

- 921.6 kBd 8N1 by default; one value is three bytes ``L = 00 D5..D0``, ``M = 01 D11..D6``,
  ``H = 1 f D17..D12``; ``f = 0`` for the first value of a block (the distance), 1 for the
  additional values. A block is the distance followed by the additional values in the order the
  sensor reports with ``GETOUTINFO_RS422`` (the ``output`` setting).
- Distance without mastering: 16 bits, ``d[mm] = (102 x / 65520 - 1) MR / 100``; with mastering:
  18 bits, ``d[mm] = (102 x / 65520 - 51) MR / 100``. Error values 262075..262082 replace the
  distance; they decode to NaN and the value is kept per sample as ``error_code``.
- Counter 18 bits (wraps at 262144); timestamp two 16-bit words, ``t[ms] = (65536 y + x) / 100``;
  [unverified] the low word ``x`` is sent before the high word ``y``. Status 18 bits, bit 15 =
  "value triggered". Exposure ``ET[us] = x / 10``; intensity ``I[%] = 100 x / 65472``.
- ASCII commands; "after processing a command always a return and a prompt (``->``) is returned",
  errors ``Exxx <text>`` before the prompt, warnings ``Wxxx`` (Micro-Epsilon ILD1320/1420 manual,
  A 3.1). [unverified] framing used here: the host sends ``<command>\r\n``; the sensor echoes
  ``<command>\r\n`` (ECHO ON), then reply lines each ending ``\r\n``, then ``->``; the reply
  sits between two binary blocks; the output names of ``GETOUTINFO_RS422`` are ``DIST1``,
  ``COUNTER``, ``TIMESTAMP``, ``STATE``, ``SHUTTER``, ``INTENSITY``.
- ``MASTERMV`` waits up to 2 s for the next value, else replies ``E104 Timeout``. [unverified] the
  first block after the reply of a successful ``MASTERMV`` is the first mastered one.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Iterator
from types import TracebackType
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from daq.errors import ConfigError, DeviceError, ProtocolError, TransportError, TransportTimeout
from daq.instruments.entry import DriverEntry
from daq.instruments.microepsilon_ild1420.decoder import (
    STATUS_TRIGGERED,
    Ild1420Decoder,
    Ild1420Samples,
)
from daq.instruments.microepsilon_ild1420.sequencer import Ild1420Sequencer
from daq.instruments.microepsilon_ild1420.settings import Ild1420Settings
from daq.instruments.reading import Reading
from daq.transports.byte_transport import Transport

__all__ = ["DRIVER", "OUTPUT_NAMES", "MicroEpsilonIld1420"]

log = logging.getLogger(__name__)


#: Names of the values in GETOUTINFO_RS422 replies [unverified].
OUTPUT_NAMES: Final = {"distance": "DIST1", "counter": "COUNTER", "timestamp": "TIMESTAMP",
                       "status": "STATE", "exposure": "SHUTTER", "intensity": "INTENSITY"}


IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


# ------------------------------------------------------------------------------------------------
# Driver
# ------------------------------------------------------------------------------------------------
class MicroEpsilonIld1420:
    """An ILD1420 laser on a serial line: ASCII commands and the binary stream.

    Parameters
    ----------
    transport : Transport
        A closed transport (e.g. ``open_transport(url, **settings.line())``); the driver opens it.
    settings : Ild1420Settings
        Measuring range, rate, output layout and geometry.
    command_timeout_s : float
        Longest wait for a command's reply, s (MASTERMV alone may take 2 s).
    reconnect_attempts : int
        Reopen attempts after the line fails, before giving up with TransportError.
    reconnect_backoff_s : float
        First wait before reopening, s; doubled after each failed attempt.

    Notes
    -----
    ``open()`` ends mastering (``MASTERMV NONE``: the acquisition relies on absolute distances),
    checks that ``GETOUTINFO_RS422`` matches ``settings.output`` and selects ``OUTPUT RS422``.
    Commands may be sent while the sensor streams: the stream bytes around the reply are kept and
    decoded, nothing is lost. Not thread-safe: send commands from the thread that reads.
    """

    #: Time a read keeps collecting data after its first sample, s: a block spans about this
    #: long (80 samples at 4 kHz) instead of the few samples one serial read gives, so that
    #: everything downstream (engine queue, synchronisation, recording, live view) runs per
    #: block at ~50 blocks/s rather than per read at ~350 reads/s, which saturated one core.
    DRAIN_S = 0.02

    def __init__(self, transport: Transport, settings: Ild1420Settings, *,
                 command_timeout_s: float = 3.0, reconnect_attempts: int = 5,
                 reconnect_backoff_s: float = 0.1) -> None:
        if not isinstance(settings, Ild1420Settings):
            raise TypeError(f"settings must be Ild1420Settings, got {type(settings).__name__}")
        if command_timeout_s <= 0 or reconnect_attempts < 0 or reconnect_backoff_s < 0:
            raise ValueError("command_timeout_s must be > 0, reconnect_attempts and "
                             "reconnect_backoff_s >= 0")
        self._transport = transport
        self._settings = settings
        self.command_timeout_s = float(command_timeout_s)
        self.reconnect_attempts = int(reconnect_attempts)
        self.reconnect_backoff_s = float(reconnect_backoff_s)
        self._decoder = Ild1420Decoder(settings.output, range_mm=settings.range_mm)
        self._sequencer = Ild1420Sequencer(settings.rate_hz)
        self._backlog: list[tuple[Ild1420Samples, IntArray]] = []
        self._backlog_size = 0
        self._skipped_reported = 0
        self._open = False
        #: Reconnections made so far.
        self.reconnects = 0

    # -- properties -------------------------------------------------------------------------
    @property
    def settings(self) -> Ild1420Settings:
        """Measure the settings this driver was built with (read-only)."""
        return self._settings

    @property
    def is_open(self) -> bool:
        """Measure whether the driver has opened its transport."""
        return self._open

    @property
    def mastered(self) -> bool:
        """Measure whether the sensor is mastered (18-bit distances shifted by the master)."""
        return self._decoder.mastered

    @property
    def bytes_skipped(self) -> int:
        """Measure the bytes discarded while resynchronising, since construction."""
        return self._decoder.bytes_skipped

    @property
    def decoder(self) -> Ild1420Decoder:
        """Measure the decoder's counters (``bytes_skipped``, ``resyncs``, ``blocks_decoded``)."""
        return self._decoder

    # -- life cycle ---------------------------------------------------------------------------
    def open(self) -> None:
        """Open the transport, end mastering, check the output layout, select RS422 output."""
        if self._open:
            return
        self._transport.open()
        self._open = True
        try:
            self.unmaster()
            reported = self.output_info()
            expected = ("distance", *self._settings.output)
            if reported != expected:
                raise ConfigError(
                    f"{self._transport.url}: the sensor sends {list(reported)} per block but the "
                    f"rig config says output = {list(self._settings.output)} (after the distance)"
                )
            self.set_output("RS422")
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Close the transport; idempotent."""
        self._open = False
        self._transport.close()

    def __enter__(self) -> MicroEpsilonIld1420:
        self.open()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def describe(self) -> dict[str, dict[str, Any]]:
        """Return channel -> {units, dtype, shape} (shape of one sample) of :meth:`read`.

        ``distance`` (m, NaN on error), ``error_code`` (0 = valid, else the sensor's error
        value, see :data:`~daq.instruments.microepsilon_ild1420.decoder.ERROR_CODES`),
        ``epoch`` (restarts of the sensor seen so far), ``triggered`` (status bit 15),
        ``status`` (raw status bits); plus ``exposure`` (s) and ``intensity`` (%) when
        selected. The counter and the device time are the reading's own fields.
        """
        out: dict[str, dict[str, Any]] = {
            "distance": {"units": "m", "dtype": "float64", "shape": ()},
            "error_code": {"units": "1", "dtype": "int32", "shape": ()},
            "epoch": {"units": "1", "dtype": "int32", "shape": ()},
            "triggered": {"units": "1", "dtype": "bool", "shape": ()},
            "status": {"units": "1", "dtype": "int64", "shape": ()},
        }
        if "exposure" in self._settings.output:
            out["exposure"] = {"units": "s", "dtype": "float64", "shape": ()}
        if "intensity" in self._settings.output:
            out["intensity"] = {"units": "%", "dtype": "float64", "shape": ()}
        return out

    # -- ASCII commands -----------------------------------------------------------------------
    def command(self, text: str, timeout_s: float | None = None) -> list[str]:
        """Send one ASCII command; return its reply lines (without echo and prompt).

        Raises
        ------
        DeviceError
            The sensor answered ``Exxx <text>`` (e.g. ``E104 Timeout``).
        TransportTimeout
            No echo and prompt within ``timeout_s`` (default ``command_timeout_s``).
        """
        if not self._open:
            raise TransportError(f"{self._transport.url}: not open")
        if not text or any(c in text for c in "\r\n") or not text.isascii():
            raise ValueError(f"a command is one line of ASCII, got {text!r}")
        timeout = self.command_timeout_s if timeout_s is None else float(timeout_s)
        echo = text.encode("ascii") + b"\r\n"
        self._transport.write(echo)
        deadline = time.monotonic() + timeout
        buf = bytearray()
        start = -1
        while True:
            if start < 0:
                start = buf.find(echo)
                if start < 0 and len(buf) >= len(echo):
                    # Stream bytes before the echo: decode them now, keep the tail that may be
                    # the echo's beginning.
                    cut = len(buf) - len(echo) + 1
                    self._ingest(bytes(buf[:cut]), time.monotonic_ns())
                    del buf[:cut]
                elif start > 0:
                    self._ingest(bytes(buf[:start]), time.monotonic_ns())
                    del buf[:start]
                    start = 0
            if start >= 0:
                prompt = buf.find(b"->", len(echo))
                if prompt >= 0:
                    break
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TransportTimeout(
                    f"{self._transport.url}: no reply to {text!r} within {timeout:g} s "
                    f"(last bytes {bytes(buf[-64:]).hex(' ')})")
            try:
                buf += self._transport.read(65536, remaining)
            except TransportTimeout:
                continue  # the deadline check above raises, naming the command
        reply = bytes(buf[len(echo):prompt])
        rest = bytes(buf[prompt + 2:])
        lines = [line.strip() for line in reply.decode("ascii", "replace").split("\r\n")]
        lines = [line for line in lines if line]
        for line in lines:
            if _is_code(line, "E"):
                if rest:
                    self._ingest(rest, time.monotonic_ns())
                raise DeviceError(f"{self._transport.url}: {text!r} failed: {line}")
            if _is_code(line, "W"):
                log.warning("%s: %r: sensor warning %s", self._transport.url, text, line)
        self._after_reply(text)
        if rest:
            self._ingest(rest, time.monotonic_ns())
        return [line for line in lines if not _is_code(line, "W")]

    def _after_reply(self, text: str) -> None:
        """Track state that changes the decoding (mastering) once a command succeeded."""
        words = text.upper().split()
        if words[:1] == ["MASTERMV"] and len(words) >= 2:
            self._decoder.mastered = words[1] == "MASTER"

    def output_info(self) -> tuple[str, ...]:
        """Return the values per block the sensor reports (``GETOUTINFO_RS422``), in order."""
        lines = self.command("GETOUTINFO_RS422")
        tokens = " ".join(lines).split()
        if tokens[:1] == ["GETOUTINFO_RS422"]:
            tokens = tokens[1:]
        names = {v: k for k, v in OUTPUT_NAMES.items()}
        unknown = [t for t in tokens if t not in names]
        if unknown or not tokens:
            raise ProtocolError(f"{self._transport.url}: GETOUTINFO_RS422 reply {lines!r} has "
                                f"unknown or no output names {unknown}")
        return tuple(names[t] for t in tokens)

    def set_output(self, interface: str) -> None:
        """Select the measurement output: ``RS422``, ``NONE`` or ``ANALOG`` (``OUTPUT``)."""
        if interface not in ("RS422", "NONE", "ANALOG"):
            raise ValueError(f"interface must be RS422, NONE or ANALOG, got {interface!r}")
        self.command(f"OUTPUT {interface}")

    def master(self, master_value_mm: float) -> None:
        """Master the next value to ``master_value_mm`` (``MASTERMV MASTER``), mm in [0, 2 MR].

        Afterwards distances are 18-bit values relative to the master. Raises
        DeviceError (``E104 Timeout``) when no value comes within 2 s.
        """
        mv = float(master_value_mm)
        if not (math.isfinite(mv) and 0.0 <= mv <= 2.0 * self._settings.range_mm):
            raise ValueError(f"master value {mv!r} mm is outside [0, "
                             f"{2 * self._settings.range_mm}]")
        self.command(f"MASTERMV MASTER {mv:.6f}")

    def unmaster(self) -> None:
        """End mastering (``MASTERMV NONE``): absolute 16-bit distances again."""
        self.command("MASTERMV NONE")

    def info(self) -> dict[str, str]:
        """Return the sensor information of ``GETINFO`` as ``{field: value}``."""
        out: dict[str, str] = {}
        for line in self.command("GETINFO"):
            key, sep, value = line.partition(":")
            if sep:
                out[key.strip()] = value.strip()
        return out

    # -- stream -------------------------------------------------------------------------------
    def read(self, timeout_s: float = 1.0, *, max_samples: int = 100_000) -> Reading:
        """Return the samples received so far (at least one), waiting up to ``timeout_s`` (s).

        The reading's channels are those of :meth:`describe`; its counter is the unwrapped
        sample counter, its device time the unwrapped timestamp (s, restarting with the
        sensor), its host times those of the read that completed each sample (ns), its gaps
        the counter jumps and the sensor's restarts, and ``info["bytes_skipped"]`` the bytes
        the decoder discarded meanwhile (resynchronisations).

        After the first sample it keeps reading, waiting for more, for :attr:`DRAIN_S` and up
        to ``max_samples`` (one read's worth more at most). A failed line is reopened (bounded
        attempts with backoff, logged); after a reopen the first step is checked for a sensor
        restart.

        Raises
        ------
        TransportTimeout
            Nothing decodable arrived within ``timeout_s`` (sensor quiet, output off, stalled).
        TransportError
            The line failed and did not come back after ``reconnect_attempts`` attempts.
        """
        if not self._open:
            raise TransportError(f"{self._transport.url}: not open")
        deadline = time.monotonic() + timeout_s
        while self._backlog_size == 0:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TransportTimeout(f"{self._transport.url}: no ILD1420 block within "
                                       f"{timeout_s:g} s")
            self._receive(remaining)  # on a timeout the deadline check raises, naming the sensor
        # Keep collecting for DRAIN_S after the first sample (waiting for what is still coming)
        # and up to max_samples; each read is decoded and stamped with its own arrival time, so
        # the clock fit keeps a tight host time for the last sample of every read.
        drain_end = time.monotonic() + self.DRAIN_S
        while self._backlog_size < max_samples:
            remaining = drain_end - time.monotonic()
            if remaining <= 0 or not self._receive(remaining):
                break
        return self._build_block()

    def _receive(self, timeout_s: float) -> bool:
        """Read and decode what arrives within ``timeout_s`` (s), stamped with its arrival.

        Returns False when nothing came: a timeout, or a failed line that was reopened.
        """
        try:
            data = self._transport.read(65536, timeout_s)
        except TransportTimeout:
            return False
        except TransportError as exc:
            self._reconnect(exc)
            return False
        self._ingest(data, time.monotonic_ns())
        return True

    def _reconnect(self, cause: TransportError) -> None:
        url = self._transport.url
        log.warning("%s: line failed (%s); reopening", url, cause)
        delay = self.reconnect_backoff_s
        last: TransportError = cause
        for attempt in range(1, self.reconnect_attempts + 1):
            time.sleep(delay)
            delay *= 2
            try:
                self._transport.close()
                self._transport.open()
            except TransportError as exc:
                last = exc
                log.warning("%s: reopen attempt %d of %d failed: %s", url, attempt,
                            self.reconnect_attempts, exc)
                continue
            dropped = self._decoder.reset()
            self._sequencer.expect_discontinuity()
            self.reconnects += 1
            log.warning("%s: reopened after %d attempt(s); %d bytes of a cut block dropped",
                        url, attempt, dropped)
            return
        self._open = False
        self._transport.close()
        raise TransportError(f"{url}: the ILD1420 did not come back after "
                             f"{self.reconnect_attempts} reopen attempts") from last

    def _ingest(self, data: bytes, host_ns: int) -> None:
        samples = self._decoder.feed(data)
        if len(samples):
            self._backlog.append((samples, np.full(len(samples), host_ns, dtype=np.int64)))
            self._backlog_size += len(samples)

    def _build_block(self) -> Reading:
        parts, self._backlog, self._backlog_size = self._backlog, [], 0
        if len(parts) == 1:  # one transport read held the block: nothing to join
            samples, host_ns = parts[0]
        else:
            samples = Ild1420Samples.concatenate([p for p, _ in parts])
            host_ns = np.concatenate([h for _, h in parts])
        assert samples.counter is not None and samples.timestamp is not None
        assert samples.status is not None  # required by the settings
        counter, device_time, epoch, gaps = self._sequencer.process(
            samples.counter, samples.timestamp, host_ns)
        channels: dict[str, npt.NDArray[Any]] = {
            "distance": samples.distance_mm * 1e-3,
            "error_code": samples.error_code,
            "epoch": epoch,
            "triggered": (samples.status & STATUS_TRIGGERED) != 0,
            "status": samples.status,
        }
        if samples.exposure is not None:
            channels["exposure"] = samples.exposure * 1e-7  # ET[us] = x / 10
        if samples.intensity is not None:
            channels["intensity"] = samples.intensity * (100.0 / 65472.0)
        skipped = self._decoder.bytes_skipped - self._skipped_reported
        self._skipped_reported = self._decoder.bytes_skipped
        for gap in gaps:
            log.info("%s: %d sample(s) missing after counter %d%s", self._transport.url,
                     gap.length, gap.after_counter, "" if gap.exact else " (estimated)")
        return Reading(channels=channels, host_time_ns=host_ns, counter=counter,
                       device_time=device_time, gaps=tuple(gaps),
                       info={"bytes_skipped": skipped})

    def blocks(self, timeout_s: float = 1.0) -> Iterator[Reading]:
        """Yield readings until the transport times out or fails (for simple readers)."""
        while True:
            yield self.read(timeout_s)


def _is_code(line: str, letter: str) -> bool:
    """Whether a reply line is an error (``E``) or warning (``W``) message: letter + digits."""
    head = line.split(" ", 1)[0]
    return len(head) > 1 and head[0] == letter and head[1:].isdigit()


def _build(transport: Transport, settings: Ild1420Settings) -> MicroEpsilonIld1420:
    return MicroEpsilonIld1420(transport, settings)


#: This driver's registry entry (collected by :mod:`daq.instruments.registry`).
DRIVER = DriverEntry(name="microepsilon_ild1420", role="lasers", factory=_build,
                    validate=Ild1420Settings.from_table)
