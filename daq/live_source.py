"""The live console's data source: a rig acquired now, synchronised into a ring buffer.

Responsibility: :class:`LiveSource` (a :class:`~daq.source.DataSource`) starts a rig (the
simulated one in a child process, :func:`daq.rig_process.start_rig_process`, or the real
instruments of a config), runs the acquisition engine over its drivers and feeds the console's
:class:`~daq.ring_buffer.RingBuffer` with the rows of the synchronised view. The sync view is the
recording pipeline's own: a :class:`~daq.pipeline.RunWriter` runs as the engine's subscriber,
writing into a :class:`RingRecorder` instead of an HDF5 file (the writer only needs the
recorder's methods), so the live view and a recorded file hold the same rows by construction.
The GUI thread polls :meth:`LiveSource.snapshot` (the ring's copy) and :meth:`LiveSource.health`
(built from :meth:`Acquisition.stats` and what the subscriber kept under a lock); nothing is
pushed to the GUI from the acquisition threads (STYLE.md, "Threads and GUI").

Not responsible for: drawing (:mod:`daq.live`), the sync numerics (:mod:`daq.sync` through
:class:`~daq.pipeline.RunWriter`), recording to a file (a later part), or the operator controls
(:mod:`daq.controls`, which use :attr:`LiveSource.acq`).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np
import numpy.typing as npt

from daq.config import RigConfig
from daq.recorder import RunRecorder
from daq.ring_buffer import RingBuffer
from daq.source import DeviceHealth, SourceInfo, sync_columns

__all__ = ["STALL_S", "LiveSource", "RingRecorder"]

log = logging.getLogger(__name__)

#: A device whose last block is older than this is stalled, s (the barometer polls at 1 Hz).
STALL_S = 3.0
#: A device fault keeps the alarm raised this long, s (the last fault stays in the table).
FAULT_ALARM_S = 10.0
#: Sample rates in the health panel are averaged over this long, s.
RATE_WINDOW_S = 2.0
#: How often the subscriber copies the writer's clock fits for the GUI, s.
CLOCK_FIT_INTERVAL_S = 0.5
#: The live source keeps this many of the engine's latest events (:meth:`LiveSource.events`).
EVENTS_KEPT = 1000
#: Sync rows are handed to the ring this often, s (the writer's batching interval).
WRITE_INTERVAL_S = 0.05
#: The ring holds at least this much history, s: a whole free decay must still be there when
#: the releases table cuts it (:mod:`daq.live_ident`).
MIN_HISTORY_S = 30.0


class RingRecorder:
    """What :class:`~daq.pipeline.RunWriter` writes into, for a live view: no file.

    It offers the :class:`~daq.recorder.RunRecorder` methods the writer calls. The sync rows go
    to ``ring`` (columns of :func:`daq.source.sync_columns`); of the raw streams only the last
    fan speed is kept (``fan_rpm``); everything else is dropped. Called on the engine's
    dispatcher thread; the ring is thread-safe, and ``fan_rpm`` is one float (atomic).

    Parameters
    ----------
    ring : RingBuffer
        The console's buffer.
    fan_devices : sequence of str
        Names of the fan drives whose ``speed`` channel is the fan state.
    plc_devices : sequence of str
        Names of the PLCs whose ``armed`` channel is the release state.
    """

    def __init__(self, ring: RingBuffer, fan_devices: Sequence[str] = (),
                 plc_devices: Sequence[str] = ()) -> None:
        self.ring = ring
        self._fans = set(fan_devices)
        self._plcs = set(plc_devices)
        self._channels: dict[str, list[str]] = {}
        self._state = "new"
        #: Last fan speed read, rpm (NaN before the first reading).
        self.fan_rpm = math.nan
        #: Last PLC ARM coil read: (host ``monotonic_ns`` of the reading, armed); None before.
        self.plc_armed: tuple[int, bool] | None = None

    @property
    def state(self) -> str:
        """Measure the phase, as ``RunRecorder.state``."""
        return self._state

    def open(self) -> None:
        """Start declaring streams (nothing to create)."""
        self._state = "declaring"

    def start(self, t0_host_ns: int | None = None) -> None:
        """Start taking rows."""
        self._state = "recording"

    def close(self) -> None:
        """Stop (the ring keeps its rows)."""
        self._state = "closed"

    def add_stream(self, device: str, channels: Sequence[str], units: Any, rate_hz: float,
                   dtype: Any, *, extra: Mapping[str, Any] | None = None) -> None:
        """Remember a stream's channel names."""
        self._channels[device] = list(channels)

    def add_sync(self, tap_names: Sequence[str], **_: Any) -> None:
        """Declare the sync view (the ring already has its columns)."""

    def append_raw(self, device: str, host_time_ns: Any, device_time: Any, counter: Any,
                   values: Any, *, extra: Mapping[str, Any] | None = None) -> None:
        """Keep the last fan speed and PLC ARM state; drop the other raw samples."""
        channels = self._channels.get(device, ())
        if device in self._fans and "speed" in channels:
            table = np.asarray(values, dtype=np.float64)
            if table.ndim == 2 and table.shape[0]:
                self.fan_rpm = float(table[-1, channels.index("speed")])
        elif device in self._plcs and "armed" in channels:
            table = np.asarray(values, dtype=np.float64)
            hosts = np.asarray(host_time_ns, dtype=np.int64)
            if table.ndim == 2 and table.shape[0] and hosts.size:
                # one tuple, swapped whole (atomic for the GUI thread that reads it)
                self.plc_armed = (int(hosts[-1]), bool(table[-1, channels.index("armed")]))

    def append_sync(self, time: Any, *, h: Any, alpha: Any, lift: Any, moment: Any,
                    pressure: Any, U: Any, rho: Any) -> None:
        """Append sync rows to the ring."""
        self.ring.append({"time": time, "h": h, "alpha": alpha, "lift": lift, "moment": moment,
                          "U": U, "rho": rho, "pressure": pressure})

    def add_gap(self, *args: Any, **kwargs: Any) -> None:
        """Ignore (gaps are counted by the engine's stats)."""

    def add_event(self, *args: Any, **kwargs: Any) -> None:
        """Ignore (faults reach the health panel through :class:`_HealthTap`)."""

    def add_release(self, **kwargs: Any) -> None:
        """Ignore (the live releases come from the writer's ``release_hook``)."""

    def set_sync_attrs(self, **kwargs: Any) -> None:
        """Ignore."""

    def add_metadata(self, name: str, value: Any) -> None:
        """Ignore."""


class _HealthTap:
    """The engine subscriber: the run writer, plus the faults and clock fits for the GUI."""

    def __init__(self, writer: Any) -> None:
        self.writer = writer
        self._lock = threading.Lock()
        self._last_fault: dict[str, tuple[float, str]] = {}
        self._fits: dict[str, dict[str, float]] = {}
        self._next_fit = 0.0
        self._events: deque[Any] = deque(maxlen=EVENTS_KEPT)

    def __call__(self, name: str, doc: Any) -> None:
        if name == "event":
            with self._lock:
                self._events.append(doc)
        if name == "event" and getattr(doc, "kind", "") == "fault":
            device = str(getattr(doc, "device", None) or "?")
            text = f"{getattr(doc, 'error', 'fault')}: {getattr(doc, 'text', '')}"
            with self._lock:
                self._last_fault[device] = (time.monotonic(), text[:200])
        self.writer(name, doc)
        now = time.monotonic()
        if now >= self._next_fit:
            self._next_fit = now + CLOCK_FIT_INTERVAL_S
            fits = self.writer.clock_fits()
            with self._lock:
                self._fits = fits

    def events(self) -> list[Any]:
        with self._lock:
            return list(self._events)

    def read(self) -> tuple[dict[str, tuple[float, str]], dict[str, dict[str, float]]]:
        with self._lock:
            return dict(self._last_fault), dict(self._fits)


class LiveSource:
    """A rig acquired live, as a console data source (see the module docstring).

    Parameters
    ----------
    config : RigConfig
        The rig. With ``simulate`` its simulated instruments are started in a child process;
        without, its URLs must be real.
    simulate : bool
        Start the simulated rig of the config.
    window_s : float
        Length of the history kept for the views, s, > 0.
    fan_rpm : float, optional
        Start the fan at this speed once the engine runs (within the config's limits; the
        driver refuses more); it is stopped again on :meth:`close`. None: leave the fan alone.
    sync_pulse_interval_s : float or None
        Pulse the PLC's trigger line this often, s (clock anchors, as ``record_run``).

    Notes
    -----
    The constructor does no I/O; :meth:`open` starts everything, :meth:`close` stops the
    engine, then the rig (idempotent). With ``simulate`` the scanner is zeroed (CALZ) before
    the engine starts: the simulated tunnel starts wind-off.
    """

    def __init__(self, config: RigConfig, *, simulate: bool = True, window_s: float = 20.0,
                 fan_rpm: float | None = None,
                 sync_pulse_interval_s: float | None = 0.5) -> None:
        if not (isinstance(window_s, (int, float)) and 0 < window_s < math.inf):
            raise ValueError(f"window_s = {window_s!r} must be a number of seconds > 0")
        if fan_rpm is not None and not (math.isfinite(fan_rpm) and fan_rpm >= 0):
            raise ValueError(f"fan_rpm = {fan_rpm!r} must be a number of rpm >= 0")
        self.config = config
        self.simulate = bool(simulate)
        self.window_s = float(window_s)
        self.fan_rpm = fan_rpm
        self._pulse_s = sync_pulse_interval_s
        self._rig: Any = None
        self._acq: Any = None
        self._pulser: Any = None
        self._tap: _HealthTap | None = None
        self._writer: Any = None
        self._recorder: RingRecorder | None = None
        self._ring: RingBuffer | None = None
        self._info: SourceInfo | None = None
        self._fan_started = False
        self._started_ns = 0
        self._closed = False
        self._error: str | None = None
        self._seen_rows = 0
        self._counts: deque[tuple[float, dict[str, int]]] = deque()  # (host s, samples)
        self._decay_lock = threading.Lock()
        self._decays: list[tuple[float, float | None]] = []  # (release s, caught s or None)

    # -- life cycle ------------------------------------------------------------------------------
    def open(self) -> None:
        """Start the rig (simulated: in its own process), the drivers and the engine.

        Raises
        ------
        DaqError, RuntimeError, TimeoutError
            A device did not open, or the simulated rig did not start; everything already
            started is stopped again.
        """
        if self._acq is not None or self._closed:
            return
        from daq.acquisition import Acquisition, drivers_from_config
        from daq.pipeline import RunWriter, start_sync_pulses

        try:
            live = self.config
            if self.simulate:
                from daq.rig_process import start_rig_process

                self._rig = start_rig_process(self.config)
                live = self._rig.config
            scanners = live.by_role("scanner")
            rate = float(scanners[0].settings["rate_hz"]) if scanners else 500.0
            history_s = max(self.window_s, MIN_HISTORY_S)
            self._ring = RingBuffer(int(math.ceil(history_s * rate)) + 2,
                                    *sync_columns(live.taps.n_taps))
            self._recorder = RingRecorder(self._ring, [i.name for i in live.by_role("fan")],
                                          [i.name for i in live.by_role("plc")])
            writer = RunWriter(Path("live"), live, write_interval_s=WRITE_INTERVAL_S,
                               release_hook=self._on_decay)
            writer.recorder = cast(RunRecorder, self._recorder)  # duck-typed: no file
            self._writer = writer
            self._tap = _HealthTap(writer)
            drivers = drivers_from_config(live)
            if self.simulate:
                for kind, driver in drivers.values():
                    if kind == "scanner":
                        driver.open()  # idempotent: the engine's open() keeps this connection
                        driver.calz(wind_speed_now=0.0)
            self._acq = Acquisition(drivers, subscribers=[self._tap],
                                    metadata={"rig": live.name, "mode": "live console"})
            self._acq.start()
            self._started_ns = time.monotonic_ns()
            self._pulser = start_sync_pulses(self._acq, drivers, self._pulse_s)
            if self.fan_rpm is not None and "fan" in self._acq.drivers:
                fan = self._acq.drivers["fan"]
                fan.set_speed(self.fan_rpm)
                fan.start()
                self._fan_started = True
            self._info = SourceInfo(label="live", config=live, rate_hz=rate, duration_s=None)
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Stop the fan (if this source started it), the engine and the rig (idempotent)."""
        self._closed = True
        pulser, self._pulser = self._pulser, None
        if pulser is not None:
            pulser.stop()
        acq, self._acq = self._acq, None
        if acq is not None:
            if self._fan_started:
                try:
                    acq.drivers["fan"].stop()
                except Exception:  # stopping anyway: the engine and rig close below
                    log.exception("stopping the fan failed")
            try:
                summary = acq.stop("console closed")
                if summary.get("threads_alive"):
                    log.error("threads still alive after stop: %s", summary["threads_alive"])
            except Exception:
                log.exception("stopping the acquisition failed")
        rig, self._rig = self._rig, None
        if rig is not None:
            rig.close()

    def __enter__(self) -> LiveSource:
        """Start the rig and the engine."""
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        """Stop everything."""
        self.close()

    # -- the DataSource protocol -----------------------------------------------------------------
    @property
    def info(self) -> SourceInfo:
        """Describe the live rig (after :meth:`open`)."""
        if self._info is None:
            raise RuntimeError("LiveSource.info: call open() first")
        return self._info

    @property
    def total_rows(self) -> int:
        """Count sync rows synchronised so far."""
        return 0 if self._ring is None else self._ring.total_rows

    @property
    def error(self) -> str | None:
        """Describe the failure that stopped the sync view, if any."""
        if self._error is None and self._writer is not None and self._writer.error is not None:
            self._error = f"sync view failed: {self._writer.error}"
        return self._error

    @property
    def running(self) -> bool:
        """Tell whether the engine runs."""
        return self._acq is not None and bool(self._acq.running)

    @property
    def acq(self) -> Any:
        """The acquisition engine (:class:`~daq.acquisition.Acquisition`); None when stopped.

        For operator commands (:mod:`daq.controls`): its ``drivers``, ``arm``, ``release``,
        ``mark``.
        """
        return self._acq

    def events(self, kind: str | None = None) -> list[Any]:
        """Return the engine's latest events (:class:`~daq.acquisition.Event`), oldest first.

        Parameters
        ----------
        kind : str, optional
            Only those of this kind (``"release"``, ``"arm"``, ``"note"``, ...).

        Returns
        -------
        list of Event
            At most :data:`EVENTS_KEPT`; empty before :meth:`open`.
        """
        events = [] if self._tap is None else self._tap.events()
        return [e for e in events if kind is None or getattr(e, "kind", None) == kind]

    def decays(self) -> list[tuple[float, float | None]]:
        """Return the free decays seen so far, oldest first.

        Returns
        -------
        list of (float, float or None)
            ``(release, caught)``: the release instant and, once the model was armed again, the
            time of the decay's last row, s from the run start (the sync view's ``time``);
            ``caught`` is None while the decay goes on. The same instants as the releases
            table of a recorded run (:class:`~daq.pipeline.RunWriter`).
        """
        with self._decay_lock:
            return list(self._decays)

    def _on_decay(self, what: str, t: float) -> None:
        """Note a decay's start or end (the run writer's release hook, dispatcher thread)."""
        with self._decay_lock:
            if what == "release":
                self._decays.append((t, None))
            elif what == "caught" and self._decays and self._decays[-1][1] is None:
                self._decays[-1] = (self._decays[-1][0], t)

    @property
    def plc_armed(self) -> tuple[int, bool] | None:
        """The PLC's ARM coil as last read: (host ``monotonic_ns``, armed); None before."""
        return None if self._recorder is None else self._recorder.plc_armed

    @property
    def fan_speed_rpm(self) -> float:
        """Measure the fan speed last read, rpm (NaN without a fan or before a reading)."""
        return math.nan if self._recorder is None else self._recorder.fan_rpm

    def poll(self) -> int:
        """Return the rows synchronised since the last poll (the engine runs by itself)."""
        total = self.total_rows
        new, self._seen_rows = total - self._seen_rows, total
        return new

    def snapshot(self, last: int | None = None,
                 columns: Sequence[str] | None = None) -> dict[str, npt.NDArray[Any]]:
        """Return copies of the most recent sync rows, oldest first (``RingBuffer.snapshot``)."""
        if self._ring is None:
            raise RuntimeError("LiveSource.snapshot: call open() first")
        return self._ring.snapshot(last, columns)

    def status(self) -> str:
        """Return the status line: rig, rows, seconds shown, fan speed, errors."""
        if self.error is not None:
            return f"error: {self.error}"
        if self._info is None:
            return "live: not started"
        state = "running" if self.running else "stopped"
        fan = self.fan_speed_rpm
        fan_text = "" if math.isnan(fan) else f", fan {fan:.0f} rpm"
        return (f"live {self._info.config.name}: {state}, {self.total_rows} sync rows at "
                f"{self._info.rate_hz:g} Hz{fan_text}")

    # -- health ----------------------------------------------------------------------------------
    def health(self, now_ns: int | None = None) -> list[DeviceHealth]:
        """Return every device's health: rate, gaps, overflows, faults, clock fit, alarm.

        Parameters
        ----------
        now_ns : int, optional
            Host ``time.monotonic_ns()`` now (a seam for tests).

        Returns
        -------
        list of DeviceHealth
            One per device, in the engine's order; empty before :meth:`open`. The rate is the
            samples read per second over the last :data:`RATE_WINDOW_S` of calls (since the
            start at first).
        """
        if self._acq is None or self._tap is None:
            return []
        now_ns = time.monotonic_ns() if now_ns is None else now_ns
        stats = self._acq.stats()
        faults, fits = self._tap.read()
        counts = {name: s.samples for name, s in stats.items()}
        # The rate over the last RATE_WINDOW_S (the 1 Hz barometer is lumpy over less).
        now_s = now_ns * 1e-9
        history = self._counts
        if not history:
            history.append((self._started_ns * 1e-9, dict.fromkeys(counts, 0)))
        while len(history) > 1 and history[1][0] <= now_s - RATE_WINDOW_S:
            history.popleft()
        t_old, old = history[0]
        dt = now_s - t_old
        rates = {n: (c - old.get(n, 0)) / dt if dt > 0 else 0.0 for n, c in counts.items()}
        if now_s > history[-1][0]:
            history.append((now_s, counts))
        out = []
        for name, s in stats.items():
            last_ns = self._started_ns if s.last_arrival_ns is None else s.last_arrival_ns
            age = (now_ns - last_ns) * 1e-9
            fault = faults.get(name)
            alarm = None
            if s.failed is not None or not s.running:
                alarm = f"reader stopped: {s.failed or 'not running'}"
            elif age > STALL_S:
                alarm = ("no data yet" if s.last_arrival_ns is None
                         else f"stalled: no data for {age:.1f} s")
            elif fault is not None and now_ns * 1e-9 - fault[0] < FAULT_ALARM_S:
                alarm = f"fault: {fault[1]}"
            out.append(DeviceHealth(
                device=name, kind=s.kind, rate_hz=rates[name], gaps=s.gaps,
                overflow_samples=s.overflow_samples, faults=s.faults,
                last_fault=None if fault is None else fault[1], clock_fit=fits.get(name),
                alarm=alarm))
        return out
