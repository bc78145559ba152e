"""Test helpers: scripted byte exchanges for driver tests, and run files written from releases.

``expected_exchange([(sent, reply), ...])`` yields an open :class:`ScriptedTransport`; the driver
under test writes to it and reads from it. Every write must match the next expected ``sent``
bytes exactly (a mismatch fails at once, showing both in hex), after which ``reply`` becomes
readable; on exit every pair must have been consumed. A pair with ``sent = b""`` is unsolicited
data (a stream) that is readable as soon as the previous pair is done. Modelled on pymeasure's
``expected_protocol`` (STYLE.md, "Tests").

``write_release_run(path, config, releases)`` writes :class:`~ident.release.Release` objects
(e.g. simulated ones) back to back into a run file with the acquisition's own recorder, for the
tests and benchmarks of the file readers (identify, diagnose, reprocess).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from daq.errors import TransportError, TransportTimeout
from daq.transport import _TransportBase

__all__ = ["ScriptedTransport", "expected_exchange", "write_release_run"]


class ScriptedTransport(_TransportBase):
    """A transport that plays a fixed script of (expected write, reply) pairs."""

    def __init__(self, exchanges: Sequence[tuple[bytes, bytes]],
                 url: str = "scripted://") -> None:
        self.url = url
        self._script = [(bytes(s), bytes(r)) for s, r in exchanges]
        self._next = 0
        self._pending = bytearray()  # bytes written towards the next expected `sent`
        self._readable = bytearray()
        self._open = False
        self._release_unsolicited()

    @property
    def is_open(self) -> bool:
        """Measure whether the transport is open."""
        return self._open

    def open(self) -> None:
        """Open (no I/O)."""
        self._open = True

    def close(self) -> None:
        """Close; idempotent."""
        self._open = False

    def _release_unsolicited(self) -> None:
        while self._next < len(self._script) and self._script[self._next][0] == b"":
            self._readable += self._script[self._next][1]
            self._next += 1

    def write(self, data: bytes) -> None:
        """Check ``data`` against the script; queue the reply once a `sent` is complete."""
        if not self._open:
            raise TransportError(f"{self.url}: not open")
        for byte in data:
            if self._next >= len(self._script):
                raise AssertionError(f"unexpected write after the script ended: {data.hex(' ')}")
            expected = self._script[self._next][0]
            self._pending.append(byte)
            if not expected.startswith(bytes(self._pending)):
                raise AssertionError(
                    f"exchange {self._next}: expected {expected!r} ({expected.hex(' ')}), "
                    f"got {bytes(self._pending)!r} ({bytes(self._pending).hex(' ')})"
                )
            if bytes(self._pending) == expected:
                self._readable += self._script[self._next][1]
                self._pending.clear()
                self._next += 1
                self._release_unsolicited()

    def read(self, max_bytes: int, timeout_s: float) -> bytes:
        """Return scripted reply bytes; none left is a timeout (without waiting)."""
        if not self._open:
            raise TransportError(f"{self.url}: not open")
        if not self._readable:
            raise TransportTimeout(f"{self.url}: no scripted data left to read")
        out = bytes(self._readable[:max_bytes])
        del self._readable[:max_bytes]
        return out

    def reset_input(self) -> None:
        """Discard readable bytes."""
        self._readable.clear()

    def assert_complete(self) -> None:
        """Fail unless every exchange happened and every reply byte was read."""
        if self._next < len(self._script) or self._pending:
            raise AssertionError(
                f"script incomplete: {self._next} of {len(self._script)} exchanges done; "
                f"next expected {self._script[self._next][0]!r}" if self._next < len(self._script)
                else f"partial write {bytes(self._pending)!r} at the end"
            )
        if self._readable:
            raise AssertionError(f"reply bytes never read: {bytes(self._readable)!r}")


@contextmanager
def expected_exchange(exchanges: Sequence[tuple[bytes, bytes]]) -> Iterator[ScriptedTransport]:
    """Yield an open scripted transport and check on exit that the script was played fully."""
    transport = ScriptedTransport(exchanges)
    transport.open()
    yield transport
    transport.assert_complete()


def write_release_run(path: str | Path, config: Any, releases: Sequence[Any]) -> None:
    """Write releases back to back into a run file (the DESIGN.md layout, via RunRecorder).

    Parameters
    ----------
    path : str or Path
        The run file to create.
    config : RigConfig
        Stored verbatim (its section and rig name are the file's).
    releases : sequence of Release or SimulatedRelease
        One row of ``/entry/releases`` each; the sync view holds their samples one after the
        other on one time base (the tap pressures are zero: not simulated here), U constant
        and the release's air density (1.2 kg/m^3 when it has none). Samples before a
        release's ``t = 0`` (a simulated hold, ``pre_s``) are written before its release row's
        start; its ``h0``/``alpha0`` are the release's own when it has them, else the samples
        at ``t = 0``.
    """
    from daq.recorder import RunRecorder

    rec = RunRecorder(path, config_text=config.text, rig_name=config.name, min_free_bytes=0,
                      reserve_bytes=0)
    rec.open()
    n_taps = config.taps.n_taps
    rec.add_sync([f"tap{i:03d}" for i in range(n_taps)])
    rec.start()
    rows, t0 = 0, 0.0
    for r in releases:
        t = t0 - float(r.t[0]) + r.t  # the release's first sample (held or free) at t0
        n = t.size
        first = int(np.searchsorted(r.t, 0.0))  # the release instant, t = 0
        rho = 1.2 if r.rho is None else float(r.rho)
        rec.append_sync(t, h=r.h, alpha=r.alpha, lift=r.lift, moment=r.moment,
                        pressure=np.zeros((n, n_taps), dtype=np.float32), U=np.full(n, r.U),
                        rho=np.full(n, rho))
        rec.add_release(release_time=float(t[first]), start_index=rows + first,
                        stop_index=rows + n, U=r.U,
                        h0=float(getattr(r, "h0", r.h[first])),
                        alpha0=float(getattr(r, "alpha0", r.alpha[first])))
        rows += n
        t0 = float(t[-1]) + float(r.t[1] - r.t[0])
    rec.close()
