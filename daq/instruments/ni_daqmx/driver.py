"""Drivers for analog inputs through NI-DAQmx: lasers with an analog output, scaled transducers.

Responsibility: :class:`NiDaqmxLaser` (a ``lasers`` driver: one channel of the task, scaled to a
distance, delivering what every laser delivers: ``distance``, ``error_code``, ``epoch``,
``triggered``, plus the raw ``volts``) and :class:`NiDaqmxAnalog` (an ``analog`` driver: named
scaled channels such as a Pitot transducer's dynamic pressure or a balance's forces, with
``error_code``, ``epoch``, ``triggered``). Both read their rows from the task their URL names,
shared with the other instruments on that device (:mod:`daq.instruments.ni_daqmx.task_group`):
the counter is the sample index, the device time the sample index over the rate (the DAQ's
sample clock is the device clock of the sync view), the trigger line flags ``triggered``.

Invalid readings (``error_code``, NaN in the scaled value): 1 the voltage is at the limit of the
task's input range (the ADC clipped), 2 it is outside the channel's ``valid_volts``, 3 (lasers)
the distance is outside the measuring range by more than 1 % of it. An analog instrument's
``error_code`` has bit ``j`` set when its channel ``j`` (settings order) is invalid.

Not responsible for: the URL (:mod:`daq.instruments.ni_daqmx.address`), the settings
(:mod:`daq.instruments.ni_daqmx.settings`), loading ``nidaqmx``
(:mod:`daq.instruments.ni_daqmx.runtime`).
Construction does no I/O: it imports the API and asks its runtime's version (a missing one is
a :class:`~daq.errors.DriverUnavailableError`); ``open()`` starts the task.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import TracebackType
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from daq.errors import ConfigError
from daq.instruments.entry import DriverEntry
from daq.instruments.ni_daqmx.address import TaskAddress
from daq.instruments.ni_daqmx.runtime import NiApi, load_api
from daq.instruments.ni_daqmx.settings import LinearScale, NiAnalogSettings, NiLaserSettings
from daq.instruments.ni_daqmx.task_group import Chunk, TaskGroup, task_group
from daq.instruments.reading import Reading

__all__ = ["ANALOG_DRIVER", "ERROR_CODES", "LASER_DRIVER", "NiDaqmxAnalog", "NiDaqmxLaser"]

#: What an ``error_code`` says (lasers; an analog instrument's is a bit per channel).
ERROR_CODES: Final = {1: "at the input range's limit (clipped)", 2: "outside valid_volts",
                      3: "distance outside the measuring range"}

FloatArray = npt.NDArray[np.float64]


class _NiInstrument:
    """What both drivers share: the task group, open/close, the rows of one read."""

    def __init__(self, address: TaskAddress, rate_hz: float, inputs: tuple[str, ...],
                 scales: tuple[LinearScale, ...]) -> None:
        if not isinstance(address, TaskAddress):
            raise TypeError(f"link must be a TaskAddress, got {type(address).__name__}")
        missing = [ch for ch in inputs if ch not in address.channels]
        if missing:
            raise ConfigError(f"url {address.url!r}: channel(s) {missing} are not among the "
                              f"task's {list(address.channels)}")
        for ch, scale in zip(inputs, scales, strict=True):
            valid = scale.valid_volts
            if valid is not None and not address.min_v <= valid[0] < valid[1] <= address.max_v:
                raise ConfigError(f"{ch} valid_volts = {list(valid)} is not inside "
                                  f"the task's input range [{address.min_v:g}, "
                                  f"{address.max_v:g}] V (url min=, max=)")
        self.address = address
        self.rate_hz = float(rate_hz)
        self.api: NiApi = load_api(address)
        self._group: TaskGroup = task_group(address, self.api)
        self._columns = [address.channels.index(ch) for ch in inputs]
        self._scales = scales
        self._inputs = inputs

    # -- properties -------------------------------------------------------------------------
    @property
    def is_open(self) -> bool:
        """Measure whether the instrument is open on a running task."""
        return self._group.is_open(id(self))

    @property
    def reconnects(self) -> int:
        """Measure the task's reconnections after the device was lost."""
        return self._group.reconnects

    @property
    def task_group(self) -> TaskGroup:
        """Measure the task this instrument shares (its faults' counts, its reconnect policy)."""
        return self._group

    @property
    def url(self) -> str:
        """Measure the task's URL."""
        return self.address.url

    # -- life cycle ---------------------------------------------------------------------------
    def open(self) -> None:
        """Start (or join) the task of the URL."""
        if not self.is_open:
            self._group.open(id(self), self.rate_hz)

    def close(self) -> None:
        """Leave the task (the last instrument stops it); idempotent."""
        self._group.close(id(self))

    def __enter__(self) -> Any:
        self.open()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def info(self) -> dict[str, str]:
        """Return the identity the device check shows: the inputs and the runtime's version."""
        return {"Name": f"{self.address.device}/{','.join(self._inputs)} via {self.api.name}",
                "Version": f"NI-DAQmx {self.api.driver_version}"}

    # -- reading ------------------------------------------------------------------------------
    def _rows(self, timeout_s: float) -> tuple[Chunk, FloatArray, npt.NDArray[np.int32]]:
        """Read the rows of this instrument's inputs: all chunks joined, volts, invalid codes."""
        chunks = self._group.read(id(self), timeout_s)
        joined = chunks[0] if len(chunks) == 1 else Chunk(
            volts=np.concatenate([c.volts for c in chunks]),
            triggered=np.concatenate([c.triggered for c in chunks]),
            index=np.concatenate([c.index for c in chunks]),
            counter=np.concatenate([c.counter for c in chunks]),
            host_time_ns=np.concatenate([c.host_time_ns for c in chunks]),
            epoch=chunks[-1].epoch, gaps=tuple(g for c in chunks for g in c.gaps))
        volts = joined.volts[:, self._columns]
        codes = np.zeros(volts.shape, dtype=np.int32)
        for j, scale in enumerate(self._scales):
            v = volts[:, j]
            lo, hi = scale.valid_volts or (-np.inf, np.inf)
            codes[:, j] = np.where((v <= self.address.min_v) | (v >= self.address.max_v), 1,
                                   np.where((v < lo) | (v > hi), 2, 0))
        return joined, volts, codes

    def _reading(self, joined: Chunk, channels: dict[str, Any]) -> Reading:
        return Reading(
            channels={**channels, "epoch": _epochs(joined), "triggered": joined.triggered},
            host_time_ns=joined.host_time_ns, counter=joined.counter,
            device_time=joined.index / self.rate_hz, gaps=joined.gaps,
            info={"epoch": joined.epoch, "reconnects": self._group.reconnects,
                  "overwritten": self._group.overwritten})


def _epochs(joined: Chunk) -> npt.NDArray[np.int32]:
    """Epoch of each row: the last chunk's, less one per sample-index restart after the row."""
    restarts = np.flatnonzero(joined.index[1:] < joined.index[:-1]) + 1
    out = np.full(len(joined), joined.epoch, dtype=np.int32)
    for k in restarts[::-1]:
        out[:k] -= 1
    return out


class NiDaqmxLaser(_NiInstrument):
    """A laser with an analog output, read on one channel of an NI-DAQmx task.

    Parameters
    ----------
    address : TaskAddress
        The task (``nidaqmx://Dev1/ai0:2?trigger=port0/line0``), built from the URL.
    settings : NiLaserSettings
        Its channel, scale, measuring range and rate.
    """

    def __init__(self, address: TaskAddress, settings: NiLaserSettings) -> None:
        if not isinstance(settings, NiLaserSettings):
            raise TypeError(f"settings must be NiLaserSettings, got {type(settings).__name__}")
        self._settings = settings
        super().__init__(address, settings.rate_hz, (settings.channel,), (settings.scale,))

    @property
    def settings(self) -> NiLaserSettings:
        """Measure the settings this driver was built with (read-only)."""
        return self._settings

    def describe(self) -> dict[str, dict[str, Any]]:
        """Return channel -> {units, dtype, shape} of :meth:`read` (the lasers' channels)."""
        return {
            "distance": {"units": "m", "dtype": "float64", "shape": ()},
            "error_code": {"units": "1", "dtype": "int32", "shape": ()},
            "epoch": {"units": "1", "dtype": "int32", "shape": ()},
            "triggered": {"units": "1", "dtype": "bool", "shape": ()},
            "volts": {"units": "V", "dtype": "float64", "shape": ()},
        }

    def read(self, timeout_s: float = 1.0) -> Reading:
        """Return the rows read since the last call (at least one; ~20 ms of them).

        Raises
        ------
        TransportTimeout
            No sample within ``timeout_s`` s.
        TransportError
            Not open, or the device was lost and did not come back.
        """
        joined, volts, codes = self._rows(timeout_s)
        s = self._settings
        v = volts[:, 0]
        distance = s.scale.apply(v)
        code = codes[:, 0]
        margin = 0.01 * s.range_mm * 1e-3  # as a laser's own range reserve: 1 % each side
        outside = (distance < -margin) | (distance > s.range_mm * 1e-3 + margin)
        code = np.where((code == 0) & outside, 3, code).astype(np.int32)
        distance = np.where(code == 0, distance, np.nan)
        return self._reading(joined, {"distance": distance, "error_code": code, "volts": v})


class NiDaqmxAnalog(_NiInstrument):
    """Scaled analog inputs (a Pitot transducer, a balance) on channels of an NI-DAQmx task.

    Parameters
    ----------
    address : TaskAddress
        The task, built from the URL.
    settings : NiAnalogSettings
        Its named channels with their scales, and the rate.
    """

    def __init__(self, address: TaskAddress, settings: NiAnalogSettings) -> None:
        if not isinstance(settings, NiAnalogSettings):
            raise TypeError(f"settings must be NiAnalogSettings, got {type(settings).__name__}")
        self._settings = settings
        super().__init__(address, settings.rate_hz, tuple(c.channel for c in settings.channels),
                         tuple(c.scale for c in settings.channels))

    @property
    def settings(self) -> NiAnalogSettings:
        """Measure the settings this driver was built with (read-only)."""
        return self._settings

    def describe(self) -> dict[str, dict[str, Any]]:
        """Return channel -> {units, dtype, shape}: each named channel (SI), then the flags."""
        out: dict[str, dict[str, Any]] = {
            c.name: {"units": c.scale.si_units, "dtype": "float64", "shape": ()}
            for c in self._settings.channels}
        out["error_code"] = {"units": "1", "dtype": "int32", "shape": ()}
        out["epoch"] = {"units": "1", "dtype": "int32", "shape": ()}
        out["triggered"] = {"units": "1", "dtype": "bool", "shape": ()}
        return out

    def read(self, timeout_s: float = 1.0) -> Reading:
        """Return the rows read since the last call (see :meth:`NiDaqmxLaser.read`)."""
        joined, volts, codes = self._rows(timeout_s)
        channels: dict[str, Any] = {}
        bits = np.zeros(len(joined), dtype=np.int32)
        for j, c in enumerate(self._settings.channels):
            bad = codes[:, j] != 0
            channels[c.name] = np.where(bad, np.nan, c.scale.apply(volts[:, j]))
            bits |= np.where(bad, np.int32(1 << j), np.int32(0)).astype(np.int32)
        channels["error_code"] = bits
        return self._reading(joined, channels)


def _laser(link: TaskAddress, settings: NiLaserSettings) -> NiDaqmxLaser:
    return NiDaqmxLaser(link, settings)


def _analog(link: TaskAddress, settings: NiAnalogSettings) -> NiDaqmxAnalog:
    return NiDaqmxAnalog(link, settings)


def _validate(cls: Any) -> Any:
    def validate(table: Mapping[str, Any], where: str) -> Any:
        return cls.from_table(table, where)
    return validate


#: The laser driver's registry entry (collected by :mod:`daq.instruments.registry`).
LASER_DRIVER = DriverEntry(name="ni_daqmx_laser", role="lasers", factory=_laser,
                           validate=_validate(NiLaserSettings), link=TaskAddress.parse)
#: The analog driver's registry entry.
ANALOG_DRIVER = DriverEntry(name="ni_daqmx_analog", role="analog", factory=_analog,
                            validate=_validate(NiAnalogSettings), link=TaskAddress.parse)
