"""What the run writer keeps per device: its clock map, timeline, triggers and counts.

Responsibility: :class:`DeviceState`, one per device of a run: its sample, gap and overflow
counts, and for a clocked device (the scanner, the lasers) its clock map onto the host clock
(:func:`new_clock_map`), its continuous host timeline, the trigger times it latched or flagged
and their pairing with the PLC's trigger pulses as clock anchors
(:meth:`DeviceState.anchor_triggers`, :meth:`DeviceState.pair_triggers`), and the state of a
device clock restart (rows held back until a fresh map settles). :func:`take_rows` cuts a block
at a restart gap; :data:`POLLED_DEFAULTS` names the raw channels of polled devices that do not
describe themselves; :func:`declare_device` declares a device's raw stream in the file and
builds its state; :class:`ClockObserver` is what the writer tells the sync view's times to
(a check against a simulated rig's truth).

Not responsible for: deciding when a device clock restarted, or the sync view and the file
(:class:`daq.recording.writer.RunWriter`, which owns the states); the clock-map numerics
(:mod:`daq.sync.clock_map`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from daq.acquisition.records import StreamBlock
from daq.config import RigConfig
from daq.recording.recorder_protocol import Recorder
from daq.sync.clock_map import ClockMap, trigger_times_from_flags, trigger_times_from_latch
from daq.sync.continuous_time import ContinuousTimeline
from daq.sync.resample import StreamSpec

__all__ = [
    "CLOCK_SETTLE_S",
    "CLOCK_WINDOW_S",
    "POLLED_DEFAULTS",
    "POLLED_RATE_HZ",
    "TRIGGER_PAIRING_S",
    "ClockObserver",
    "DeviceState",
    "RawRows",
    "ScannerRawRows",
    "TableRawRows",
    "declare_device",
    "laser_raw_rows",
    "new_clock_map",
    "take_rows",
    "view_streams",
]

FloatArray = npt.NDArray[np.float64]
#: No trigger time (a block without a new pulse).
_NONE: FloatArray = np.zeros(0)

#: Envelope window of the clock maps, s (see :class:`~daq.sync.clock_map.ClockMap`).
CLOCK_WINDOW_S = 0.5
#: How long into a file the clock maps take to settle, s: before, they rest on few windows and
#: anchors (the README's known limitation: lasers placed up to 1.5 ms late, a delay between
#: motion and forces of the order of the aerodynamic damping's phase at 4 Hz). Campaigns release
#: no earlier; a real fan's ramp and the wind's settling usually take longer anyway.
CLOCK_SETTLE_S = 6.0
#: A device trigger time is paired with the PLC trigger event within this distance, s.
TRIGGER_PAIRING_S = 0.05

#: Raw channels of the polled kinds when the driver does not describe itself.
POLLED_DEFAULTS: Mapping[str, tuple[tuple[str, str], ...]] = {
    "barometer": (("pressure", "Pa"), ("temperature", "K"), ("density", "kg/m^3")),
    "fan": (("speed", "rpm"), ("status_word", "1")),
    "plc": (("armed", "1"), ("released", "1"), ("trigger_count", "1")),
}
POLLED_RATE_HZ = {"barometer": 1.0, "fan": 10.0, "plc": 10.0}


class ClockObserver(Protocol):
    """Told the host times the sync view gives every clocked block (a clock-truth check)."""

    def observe(self, name: str, t_run: FloatArray, t_device: FloatArray, t0_s: float) -> None:
        """Take device ``name``'s samples: run times ``t_run`` (s), device times, run start."""


def new_clock_map(assumed_floor_s: float = 0.0) -> ClockMap:
    """Return a fresh clock map of the writer's windows (``assumed_floor_s``: a known floor)."""
    # 0.5 s windows (20 laser blocks, 25 scanner blocks each): a usable slope after ~1.5 s
    # (2 s windows leave a short run with a two-point slope); 600 windows span 5 min.
    return ClockMap(window_s=CLOCK_WINDOW_S, n_windows=600, assumed_floor_s=assumed_floor_s)


def declare_device(rec: Recorder, config: RigConfig, name: str, kind: str,
                   describe: Mapping[str, Mapping[str, Any]]) -> DeviceState:
    """Declare a device's raw stream in the run file; return its state, clocked or not.

    The raw stream's layout is the file format's (docs/reference/file_format.md), per role: so this
    is where the writer asks what kind of device it records. A laser records ``distance`` (m)
    with its ``error_code`` and ``triggered`` flags, a scanner its taps and Pitot (Pa, float32)
    with the trigger time, an analog device (clocked) and a polled device the scalar channels
    their ``describe()`` names.

    Parameters
    ----------
    rec : Recorder
        The run file, declaring.
    config : RigConfig
        The rig config (the lasers' and the scanner's rates, the taps).
    name, kind : str
        The device and its engine kind.
    describe : mapping
        The driver's ``describe()`` (channel -> units, dtype, shape).
    """
    if kind == "laser":
        lasers = {inst.name: inst for inst in config.by_role("lasers")}
        rate = float(lasers[name].settings["rate_hz"]) if name in lasers else 4000.0
        rec.add_stream(name, ["distance"], "m", rate, "float64",
                       extra={"error_code": "int32", "triggered": "bool"})
        return DeviceState(name, kind, ["distance"], rate, new_clock_map(),
                           ContinuousTimeline(1.0 / rate), raw_rows=laser_raw_rows)
    if kind == "analog":
        # Scaled analog inputs (a Pitot transducer, a balance): a clocked stream of scalar
        # channels, with their flags, mapped onto the host clock as a laser's.
        rate = float(config.instrument(name).settings["rate_hz"])
        pairs = [(k, str(v.get("units", "") or "1")) for k, v in describe.items()
                 if tuple(v.get("shape", ())) == ()]
        channels = [k for k, _ in pairs]
        rec.add_stream(name, channels, [u for _, u in pairs], rate, "float64")
        return DeviceState(name, kind, channels, rate, new_clock_map(),
                           ContinuousTimeline(1.0 / rate), raw_rows=TableRawRows(tuple(channels)))
    if kind == "scanner":
        rate = float(config.instrument(name).settings["rate_hz"])
        n_taps = config.taps.n_taps
        channels = [*(f"tap{i:03d}" for i in range(n_taps)), "pitot"]
        rec.add_stream(name, channels, "Pa", rate, "float32", extra={"trigger_time": "float64"})
        return DeviceState(name, kind, channels, rate, new_clock_map(),
                           ContinuousTimeline(1.0 / rate),
                           raw_rows=ScannerRawRows(config.calibration.tap_channels(n_taps),
                                                   "float32"))
    pairs = [(k, str(v.get("units", "") or "1")) for k, v in describe.items()
             if tuple(v.get("shape", ())) == ()]
    if not pairs:
        pairs = list(POLLED_DEFAULTS.get(kind, (("value", "1"),)))
    channels = [k for k, _ in pairs]
    rate = POLLED_RATE_HZ.get(kind, 1.0)
    rec.add_stream(name, channels, [u for _, u in pairs], rate, "float64")
    return DeviceState(name, kind, channels, rate, raw_rows=TableRawRows(tuple(channels)))


def view_streams(dev: DeviceState, describe: Mapping[str, Any], scanner: str | None,
                 n_taps: int, *, laser: bool, taken: Sequence[StreamSpec] = ()
                 ) -> list[StreamSpec]:
    """Return a device's streams in the sync view, and set its ``view`` (None: not in it).

    A configured laser gives ``laser.<name>`` (its distance, boxcar-averaged), the rig's
    scanner ``pressure`` (taps) and ``pitot``; on a rig without a scanner, the first ``analog``
    device with a ``pitot`` channel (Pa, a Pitot transducer) gives ``pitot``, hence U.
    ``taken``: the streams other devices gave already.
    """
    period = 1.0 / dev.rate_hz
    if dev.kind == "laser" and laser:
        dev.view = f"laser.{dev.name}"
        return [StreamSpec(dev.view, period, "boxcar")]
    if dev.kind == "scanner" and dev.name == scanner:
        dev.view = "pressure"
        return [StreamSpec("pressure", period, "linear", n_taps),
                StreamSpec("pitot", period, "linear")]
    if (dev.kind == "analog" and scanner is None and "pitot" in describe
            and all(s.name != "pitot" for s in taken)):
        dev.view = "pitot"
        return [StreamSpec("pitot", period, "linear")]
    return []


def take_rows(block: StreamBlock, lo: int, hi: int) -> StreamBlock:
    """Rows ``lo:hi`` of a block (every value holds one row per sample), without its gaps."""
    return StreamBlock(
        device=block.device, kind=block.kind, seq=block.seq,
        host_time_ns=block.host_time_ns[lo:hi],
        device_time=None if block.device_time is None else block.device_time[lo:hi],
        counter=block.counter[lo:hi],
        values={k: np.asarray(v)[lo:hi] for k, v in block.values.items()},
        gaps=(), info=block.info, overflow_samples=0)


#: A block's values -> its raw stream's rows: the ``values`` table and the extra columns.
RawRows = Callable[[Mapping[str, npt.NDArray[Any]], int],
                   tuple[npt.NDArray[Any], dict[str, npt.NDArray[Any]]]]


def laser_raw_rows(values: Mapping[str, npt.NDArray[Any]], n: int,
                   ) -> tuple[npt.NDArray[Any], dict[str, npt.NDArray[Any]]]:
    """Return a laser's raw rows: ``distance`` (m), its ``error_code`` and ``triggered`` flags."""
    extra = {"error_code": values["error_code"] if "error_code" in values
             else np.zeros(n, np.int32),
             "triggered": values["triggered"] if "triggered" in values else np.zeros(n, bool)}
    return values["distance"], extra


class ScannerRawRows:
    """A scanner's raw rows: the taps' pressures and the Pitot's (Pa), trigger times.

    Parameters
    ----------
    taps : int or sequence of int
        The scanner channel of each tap, in the layout's tap order (the rig config's wiring,
        :meth:`daq.calibration.Calibration.tap_channels`); an int ``n``: channels ``0 .. n - 1``.
        The other channels of the scanner are not recorded.
    dtype : str
        dtype of the raw stream's values: the table is built in it (one conversion, half the
        bytes to batch for float32).
    """

    def __init__(self, taps: int | Sequence[int], dtype: str = "float64") -> None:
        cols = list(range(taps)) if isinstance(taps, int) else [int(c) for c in taps]
        self.n_taps = len(cols)
        # The default wiring is a slice (a view, no gather); a mapped one gathers its columns.
        self.columns: slice | npt.NDArray[np.intp] = (
            slice(0, self.n_taps) if cols == list(range(self.n_taps))
            else np.asarray(cols, dtype=np.intp))
        self.dtype = np.dtype(dtype)

    def __call__(self, values: Mapping[str, npt.NDArray[Any]], n: int,
                 ) -> tuple[npt.NDArray[Any], dict[str, npt.NDArray[Any]]]:
        """Return the ``(n, n_taps + 1)`` table and the ``trigger_time`` column (s)."""
        table = np.empty((n, self.n_taps + 1), self.dtype)
        table[:, :self.n_taps] = values["pressure"][:, self.columns]
        table[:, self.n_taps] = values["pitot"]
        trigger = values["trigger_time"] if "trigger_time" in values else np.full(n, np.nan)
        return table, {"trigger_time": trigger}


class TableRawRows:
    """A polled device's raw rows: its scalar channels side by side, as float64 (NaN if absent).

    Parameters
    ----------
    channels : tuple of str
        The columns, in order.
    """

    def __init__(self, channels: tuple[str, ...]) -> None:
        self.channels = channels

    def __call__(self, values: Mapping[str, npt.NDArray[Any]], n: int,
                 ) -> tuple[npt.NDArray[Any], dict[str, npt.NDArray[Any]]]:
        """Return the ``(n, channels)`` table and no extra column."""
        table = np.full((n, len(self.channels)), np.nan)
        for j, c in enumerate(self.channels):
            if c in values:
                table[:, j] = np.asarray(values[c], dtype=np.float64).reshape(n)
        return table, {}


@dataclass
class DeviceState:
    """What the writer knows of one device: counts, clock map, timeline, triggers, restarts."""

    name: str
    kind: str
    channels: list[str]
    rate_hz: float
    clock: ClockMap | None = None
    timeline: ContinuousTimeline | None = None  # continuous host times across clock refits
    samples: int = 0
    gaps: int = 0
    overflow_samples: int = 0
    last_trigger: float = -math.inf  # scanner: last latched trigger time taken
    pending_triggers: list[float] = field(default_factory=list)  # device times not yet paired
    trigger_channel: bool = False  # its blocks carry trigger times (latch or flags)
    trigger_times: int = 0  # trigger times it reported in the file
    last_device_time: float = math.nan  # newest finite device time mapped, s
    last_host: float = -math.inf  # host time (run s) of the newest sample pushed to the view
    restart_pending: bool = False  # a restart gap was seen; its first timed sample decides
    break_pending: bool = False  # the clock restarted: mark the break in the view (_push)
    clock_restarts: int = 0  # clock maps started afresh after a device clock restart
    settle_until: float = math.nan  # device time up to which a new epoch's rows are held back
    settle_host_until: float = math.nan  # and the host time (run s) up to which they are
    held: list[tuple[StreamBlock, FloatArray, npt.NDArray[np.bool_] | None]] = field(
        default_factory=list)  # rows of the new epoch waiting for its map to settle
    raw_rows: RawRows | None = None  # the block's values -> the raw stream's rows
    view: str | None = None  # its stream in the sync view ("pressure", "laser.<name>") if any

    def anchor_triggers(self, block: StreamBlock, t_dev: FloatArray,
                        trigger_events: Collection[tuple[float, float]]) -> None:
        """Take the trigger times a block reveals (latched or flagged); pair those it can.

        A ``trigger_time`` channel is a latch (the scanner's last trigger time on its clock, s);
        a ``triggered`` channel flags the samples a trigger marked (the lasers).
        """
        values = block.values
        if "trigger_time" in values:
            latched = np.asarray(values["trigger_time"])
            # Most blocks hold no new pulse: one comparison tells (NaN compares False).
            if not (latched > self.last_trigger).any():
                found = _NONE
            else:
                found = trigger_times_from_latch(latched, self.last_trigger)
            if found.size:
                self.last_trigger = float(found[-1])
        elif "triggered" in values:
            flags = np.asarray(values["triggered"])
            if not flags.any():  # most blocks hold no flagged sample
                found = _NONE
            else:
                ok = np.isfinite(t_dev)
                found = trigger_times_from_flags(t_dev[ok], flags[ok], 1.0 / self.rate_hz)
        else:
            return
        self.trigger_channel = True
        if found.size:
            self.trigger_times += found.size
            self.pending_triggers.extend(float(t) for t in found)
            del self.pending_triggers[:-32]
        self.pair_triggers(trigger_events)

    def pair_triggers(self, trigger_events: Collection[tuple[float, float]]) -> None:
        """Give the clock map an anchor per trigger time that matches a PLC trigger event.

        ``trigger_events``: the PLC's trigger pulses as (host time, s from the run start; its
        uncertainty, s: half the pulse command's round trip).
        """
        if (not self.pending_triggers or self.clock is None or not self.clock.ready
                or not trigger_events):
            return
        pulses = np.array(list(trigger_events), dtype=np.float64).reshape(-1, 2)
        events, uncertainty = pulses[:, 0], pulses[:, 1]
        left: list[float] = []
        for td in self.pending_triggers:
            predicted = self.clock.to_host(td)
            k = int(np.argmin(np.abs(events - predicted)))
            if abs(events[k] - predicted) <= TRIGGER_PAIRING_S:
                self.clock.add_anchor(td, float(events[k]), float(uncertainty[k]))
            elif predicted > events[-1]:
                left.append(td)  # its PLC event may still come
        self.pending_triggers = left

    def clock_fit(self) -> dict[str, float] | None:
        """Return the clock fit: offset (s), drift (ppm), residual (s), anchors, pairs; or None."""
        cm = self.clock
        if cm is None or not cm.ready:
            return None
        return {"offset_s": cm.offset_s, "drift_ppm": cm.drift_ppm, "residual_s": cm.residual_s,
                "latency_floor_s": cm.latency_floor_s, "anchors": float(cm.n_anchors),
                "anchor_uncertainty_s": cm.anchor_uncertainty_s,
                "pairs": float(cm.n_pairs)}
