"""What the operator console reads: the data-source contract shared by replay and live.

Responsibility: name the columns of the synchronised view as the console sees them (the same names,
units and row shapes as ``/entry/sync`` of a run file, docs/reference/file_format.md), and state the
:class:`DataSource` protocol that the console's GUI timer polls. A source is *polled* from the GUI
thread: :meth:`DataSource.poll` moves it forward, :meth:`DataSource.snapshot` hands out copies
shaped like :meth:`daq.console.ring_buffer.RingBuffer.snapshot`. Nothing is ever pushed to the GUI
from another thread (docs/reference/architecture.md, "Design rules").

Implementations: :class:`daq.console.replay.ReplaySource` (a recorded run played back in time),
:class:`daq.console.live_source.LiveSource` (a rig acquired now; its ``poll`` only reports how far
``total_rows`` moved) and :class:`daq.console.process_source.ProcessLiveSource` (the same in a
process of its own). A live source is also a :class:`HealthSource`: it reports
:class:`DeviceHealth` per device, which the window shows in its health panel.

Not responsible for: reading files (``daq.console.replay``), acquisition, or drawing
(``daq.console.window``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol, Self, runtime_checkable

import numpy as np
import numpy.typing as npt

from daq.config import RigConfig
from daq.console.ring_buffer import Column, RingBuffer

__all__ = ["SWAY_SCALARS", "SYNC_SCALARS", "DataSource", "DeviceHealth", "HealthSource",
           "RingSource", "SourceInfo", "sync_columns"]

#: Scalar columns of the synchronised view and their units (``pressure`` is the one 2-D column).
SYNC_SCALARS: dict[str, str] = {
    "time": "s", "h": "m", "alpha": "rad", "lift": "N/m", "moment": "N m/m", "U": "m/s",
    "rho": "kg/m^3",
}
#: The scalar columns a rig with three degrees of freedom adds (``/entry/sync`` of its files).
SWAY_SCALARS: dict[str, str] = {"p": "m", "drag": "N/m"}


def sync_columns(n_taps: int, sway: bool = False) -> tuple[Column, ...]:
    """Return the ring-buffer columns of the synchronised view.

    Parameters
    ----------
    n_taps : int
        Number of pressure taps (the width of the ``pressure`` column), >= 0.
    sway : bool
        A 3-DOF rig's view: the :data:`SWAY_SCALARS` ``p`` (m) and ``drag`` (N/m) too, before
        ``pressure``.

    Returns
    -------
    tuple of Column
        ``time`` (s), ``h`` (m), ``alpha`` (rad), ``lift`` (N/m), ``moment`` (N m/m), ``U``
        (m/s), ``rho`` (kg/m^3) as float64 scalars, and ``pressure`` (Pa) as float32 rows of
        ``n_taps`` values (the storage type of the run file: 7 digits, far below scanner noise).

    Examples
    --------
    >>> [c.name for c in sync_columns(4)][-1], sync_columns(4)[-1].shape
    ('pressure', (4,))
    """
    return (*(Column(name) for name in SYNC_SCALARS),
            *(Column(name) for name in (SWAY_SCALARS if sway else ())),
            Column("pressure", np.float32, (n_taps,)))


@dataclass(frozen=True)
class SourceInfo:
    """Static description of a source, known once it is open.

    Attributes
    ----------
    label : str
        Shown in the status line (a file name, or "live").
    config : RigConfig
        The rig config (tap geometry for the pressure view, limits for later controls).
    rate_hz : float
        Row rate of the synchronised view, Hz.
    duration_s : float or None
        Length of a recorded run, s; ``None`` for a live source.
    """

    label: str
    config: RigConfig
    rate_hz: float
    duration_s: float | None


class DataSource(Protocol):
    """What the console polls (GUI thread only)."""

    @property
    def info(self) -> SourceInfo:
        """Describe the source (valid after it is opened)."""
        ...

    @property
    def total_rows(self) -> int:
        """Count rows made available so far (a poller redraws when it changes)."""
        ...

    @property
    def error(self) -> str | None:
        """Describe the error that stopped the source, or ``None``."""
        ...

    def poll(self) -> int:
        """Bring in what is due now and return the number of new rows."""
        ...

    def snapshot(self, last: int | None = None,
                 columns: Sequence[str] | None = None) -> dict[str, npt.NDArray[Any]]:
        """Return copies of the most recent rows, oldest first (see ``RingBuffer.snapshot``)."""
        ...

    def status(self) -> str:
        """Return one line for the status bar (position, speed, end of file, errors)."""
        ...

    def close(self) -> None:
        """Release the source's resources (idempotent)."""
        ...


class RingSource:
    """What the replay and live sources share: the rows shown are a ring buffer's.

    A subclass sets ``_ring`` (the :class:`~daq.console.ring_buffer.RingBuffer` of
    :func:`sync_columns`) and ``_info`` in its ``open()`` (None before) and defines
    ``open()`` and ``close()``; this class gives the context manager, :attr:`info`,
    :attr:`total_rows` and :meth:`snapshot`.
    """

    _ring: RingBuffer | None
    _info: SourceInfo | None

    def open(self) -> None:
        """Open the source (subclasses)."""
        raise NotImplementedError

    def close(self) -> None:
        """Release the source's resources (subclasses)."""
        raise NotImplementedError

    def __enter__(self) -> Self:
        """Open the source."""
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        """Close the source."""
        self.close()

    @property
    def info(self) -> SourceInfo:
        """Describe the source (after :meth:`open`)."""
        if self._info is None:
            raise RuntimeError(f"{type(self).__name__}.info: call open() first")
        return self._info

    @property
    def total_rows(self) -> int:
        """Count rows made available so far."""
        return 0 if self._ring is None else self._ring.total_rows

    def snapshot(self, last: int | None = None,
                 columns: Sequence[str] | None = None) -> dict[str, npt.NDArray[Any]]:
        """Return copies of the most recent rows, oldest first (``RingBuffer.snapshot``)."""
        if self._ring is None:
            raise RuntimeError(f"{type(self).__name__}.snapshot: call open() first")
        return self._ring.snapshot(last, columns)


@dataclass(frozen=True)
class DeviceHealth:
    """The health of one device of a live rig, as the console's health panel shows it.

    Attributes
    ----------
    device, kind : str
        Instrument name and engine kind.
    rate_hz : float
        Samples read per second, recently.
    gaps : int
        Gaps the device's stream reported.
    overflow_samples : int
        Samples dropped because the engine's queue was full.
    faults : int
        Driver faults so far (stalls and reconnects included).
    last_fault : str or None
        The last fault's text.
    clock_fit : dict or None
        The device clock's fit onto the host clock (``offset_s``, ``drift_ppm``,
        ``residual_s``, ...; see ``RunWriter.clock_fits``), None for an unclocked device or
        before the fit is ready.
    alarm : str or None
        Why the device needs the operator's attention now (faulted, stalled, reader stopped),
        or None.
    """

    device: str
    kind: str
    rate_hz: float
    gaps: int
    overflow_samples: int
    faults: int
    last_fault: str | None
    clock_fit: dict[str, float] | None
    alarm: str | None


@runtime_checkable
class HealthSource(Protocol):
    """A source that reports device health (a live rig); polled from the GUI thread."""

    def health(self) -> list[DeviceHealth]:
        """Return every device's health now."""
        ...

    @property
    def fan_speed_rpm(self) -> float:
        """Measure the fan speed last read, rpm (NaN when unknown)."""
        ...
