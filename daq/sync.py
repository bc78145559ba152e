"""Synchronisation of the device streams onto the host clock, and the synchronised view.

The module the rest of the code imports; it re-exports the public names of the modules that do
the work, one job each:

- :mod:`daq.clock_map`: :class:`ClockMap` (one device clock mapped onto the host clock) and the
  trigger times that anchor it (:func:`trigger_times_from_flags`,
  :func:`trigger_times_from_latch`);
- :mod:`daq.counters`: counter unwrapping and gaps (:class:`CounterUnwrapper`,
  :func:`unwrap_counter`, :func:`find_gaps`, :class:`Gap`, :class:`CounterStep`,
  :class:`Unwrapped`);
- :mod:`daq.resample`: the sync view's uniform time base (:class:`Resampler`, :func:`resample`,
  :class:`StreamSpec`, :class:`SyncBlock`);
- :mod:`daq.conversions`: the sync view's physical conversions (:func:`heave_pitch_from_lasers`,
  :func:`forces_from_pressures`, :func:`wind_speed`, :func:`air_density`, :class:`HeavePitch`,
  :class:`WindSpeed`);
- :mod:`daq._sync_common`: :class:`SyncError` and the argument checks the modules share.
"""

from __future__ import annotations

from daq._sync_common import SyncError
from daq.clock_map import ClockMap, trigger_times_from_flags, trigger_times_from_latch
from daq.conversions import (
    HeavePitch,
    WindSpeed,
    air_density,
    forces_from_pressures,
    heave_pitch_from_lasers,
    wind_speed,
)
from daq.counters import CounterStep, CounterUnwrapper, Gap, Unwrapped, find_gaps, unwrap_counter
from daq.resample import Resampler, StreamSpec, SyncBlock, resample

__all__ = [
    "ClockMap",
    "CounterStep",
    "CounterUnwrapper",
    "Gap",
    "HeavePitch",
    "Resampler",
    "StreamSpec",
    "SyncBlock",
    "SyncError",
    "Unwrapped",
    "WindSpeed",
    "air_density",
    "find_gaps",
    "forces_from_pressures",
    "heave_pitch_from_lasers",
    "resample",
    "trigger_times_from_flags",
    "trigger_times_from_latch",
    "unwrap_counter",
    "wind_speed",
]
