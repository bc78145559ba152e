"""The sync view on the final clock maps: each clocked stream mapped again at the run's end.

Responsibility: :func:`refine_sync_view` rebuilds the rows of ``/entry/sync`` that come from
clocked devices (the lasers' ``h``, ``alpha``, ``p``; the scanner's ``pressure``, ``lift``,
``moment``, ``drag``, ``U``) from the raw streams, with every device time mapped by the device's
final clock map, and overwrites them in place.

Why: during the run each block is mapped with the clock map as fitted so far
(:mod:`daq.sync.continuous_time`), and early in a run that map rests on a few envelope windows
and anchors. Measured on the simulated campaign's files (two cores, loaded): the lasers' rows of
a file's first 6 s were placed up to 1.5 ms later than the final maps put them (0.1-0.3 ms
after), so a file's first release carried a motion-to-force delay of ~1.5 ms (a 3-5 % phase
error of the aerodynamic damping at 4 Hz) and a modal-fit residual 2.5-7 times its noise, where
each laser alone, on its own device clock, fits to the noise. The final map has seen the whole
run: the streams it places agree with each other to its residual.

What is not refined (the online rows stay, and ``/entry/sync`` says why in its attribute
``time_base_note``): a run whose device clock restarted (the epochs' maps differ and the
online view marks the break), a run longer than a clock map's fitted span
(:data:`MAX_SPAN_S`: the final map is local to the run's end), a recorder that is not a run
file (the console's ring). ``rho`` is kept (the barometer is polled, not clocked), and ``U``
is computed again with it and the fan speed of its time, as while recording.

Not responsible for: the maps (:class:`~daq.sync.clock_map.ClockMap`), the resampling
(:func:`daq.sync.resample.resample`, the same numbers as the online resampler) or the
conversions (:func:`daq.recording.sync_view.physical_columns`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
import numpy.typing as npt

from daq.config import InstrumentConfig, RigConfig
from daq.recording.devices import CLOCK_WINDOW_S, DeviceState, new_clock_map
from daq.recording.recorder import RunRecorder
from daq.recording.sync_view import physical_columns
from daq.sync.conversions import wind_speed
from daq.sync.resample import StreamSpec, SyncBlock, resample

__all__ = ["MAX_SPAN_S", "refine_sync_view"]

FloatArray = npt.NDArray[np.float64]

#: Longest run refined, s: the span a clock map fits (its envelope windows,
#: :func:`daq.recording.devices.new_clock_map`); over a longer run the final map is an
#: extrapolation at the run's start.
MAX_SPAN_S = CLOCK_WINDOW_S * new_clock_map().n_windows


def refine_sync_view(rec: RunRecorder, devices: Mapping[str, DeviceState],
                     streams: Sequence[StreamSpec], *, rate_hz: float, t0_ns: int,
                     lasers: Sequence[InstrumentConfig], config: RigConfig) -> str:
    """Map the clocked streams again with their final maps and overwrite the sync rows.

    Parameters
    ----------
    rec : RunRecorder
        The run file, still recording (every raw block and sync row written).
    devices : mapping of str to DeviceState
        The writer's devices, with their final clock maps.
    streams : sequence of StreamSpec
        The sync view's streams (the online resampler's).
    rate_hz : float
        The sync rate, Hz (sync row ``k`` at ``k / rate_hz`` s).
    t0_ns : int
        Host time of the run's time 0, ns (the polled fan's rows are on it).
    lasers : sequence of InstrumentConfig
        The lasers of the view, in the writer's order.
    config : RigConfig
        The rig (tap layout, calibrations).

    Returns
    -------
    str
        What was done, for ``/entry/sync``'s ``time_base_note``: starts with ``"final clock
        maps"`` when the rows were refined.
    """
    n_rows = rec.sync_rows
    viewed = [dev for dev in devices.values() if dev.view is not None]
    if n_rows == 0 or not viewed or not streams:
        return "online clock maps: no clocked stream in the sync view"
    if any(dev.clock_restarts for dev in viewed):
        return "online clock maps: a device clock restarted during the run"
    if n_rows / rate_hz > MAX_SPAN_S:
        return (f"online clock maps: the run ({n_rows / rate_hz:.0f} s) is longer than a clock "
                f"map's span ({MAX_SPAN_S:.0f} s)")
    data: dict[str, tuple[FloatArray, FloatArray]] = {}
    for dev in viewed:
        if dev.clock is None or not dev.clock.ready:
            return f"online clock maps: {dev.name} has no clock map"
        raw = rec.read_raw(dev.name)
        t_dev = np.asarray(raw["device_time"], dtype=np.float64)
        rows = np.flatnonzero(np.isfinite(t_dev))
        t = dev.clock.to_host(t_dev[rows])
        # Increasing times only, as online (a device time going back is dropped there too).
        if t.size:
            keep = np.concatenate(([True], t[1:] > np.maximum.accumulate(t)[:-1]))
            rows, t = rows[keep], t[keep]
        value = np.asarray(raw["value"], dtype=np.float64)[rows]
        if dev.view == "pressure":
            n_taps = value.shape[1] - 1  # the taps in the layout's order, then the Pitot
            data["pressure"] = (t, value[:, :n_taps])
            data["pitot"] = (t, value[:, n_taps])
        else:
            code = np.asarray(raw["error_code"])[rows] if "error_code" in raw else None
            d = value[:, 0]
            data[str(dev.view)] = (t, d if code is None else np.where(code != 0, np.nan, d))
    block = resample(streams, data, rate_hz=rate_hz, t_start=0.0)
    n = min(len(block), n_rows)
    if n == 0:
        return "online clock maps: the raw streams give no sync row"
    first = SyncBlock(block.index[:n], block.time[:n],
                      {k: v[:n] for k, v in block.values.items()})
    cols = physical_columns(first, lasers, config, 1.2)  # the density: U is redone below
    out: dict[str, FloatArray] = {}
    if any(s.name.startswith("laser.") for s in streams):
        out.update(h=cols.h, alpha=cols.alpha)
        if cols.p is not None:
            out["p"] = cols.p
    if "pressure" in data:
        out.update(pressure=cols.pressure, lift=cols.lift, moment=cols.moment,
                   U=_wind_speed(rec, devices, first, config, t0_ns))
        if cols.drag is not None:
            out["drag"] = cols.drag
    rec.rewrite_sync(0, out)
    return (f"final clock maps: rows 0-{n - 1} of {n_rows} mapped again at the run's end"
            + ("" if n == n_rows else " (the rest as recorded)"))


def _wind_speed(rec: RunRecorder, devices: Mapping[str, DeviceState], rows: SyncBlock,
                config: RigConfig, t0_ns: int) -> FloatArray:
    """``U`` of the rows from their Pitot pressure, as the writer computes it while recording.

    With the air density each row was written with (``rho``: the barometer's of its time) and
    the fan speed polled last before it (a Pitot factor tabulated on the fan speed).
    """
    rho = rec.read_sync("rho")[:len(rows)]
    rho = np.where(np.isfinite(rho) & (rho > 0), rho, np.nan)
    pitot = config.calibration.pitot
    rpm = np.full(len(rows), math.nan)
    fans = [dev for dev in devices.values() if dev.kind == "fan" and "speed" in dev.channels]
    if pitot.fan_rpm and fans:
        raw = rec.read_raw(fans[0].name)
        t = (np.asarray(raw["host_time_ns"], dtype=np.int64) - t0_ns) * 1e-9
        speed = np.asarray(raw["value"], dtype=np.float64)[:, fans[0].channels.index("speed")]
        t, speed = t[np.isfinite(speed)], speed[np.isfinite(speed)]
        last = np.searchsorted(t, rows.time, side="right") - 1
        rpm = np.where(last >= 0, speed[np.maximum(last, 0)], math.nan)
    q = np.full(len(rows), math.nan)
    for value in np.unique(rpm):  # one factor per fan speed (NaN: the factor's own rule)
        at = np.isnan(rpm) if math.isnan(value) else rpm == value
        q[at] = pitot.dynamic_pressure(rows.values["pitot"][at], float(value))
    return np.asarray(wind_speed(q, rho).speed, dtype=np.float64)
