"""The physical columns of the synchronised view, from the resampled device streams.

Responsibility: :func:`physical_columns` turns one :class:`~daq.sync.resample.SyncBlock` (the
lasers' distances and the scanner's tap and Pitot pressures on the sync time base) into the
columns of ``/entry/sync``: heave and pitch from two or three lasers (their ``x`` and
``standoff_mm``), lift and moment from the tap pressures (the rig's tap layout), the wind
speed from the Pitot with the air density in use. A column the rig has no device for is NaN.

Not responsible for: the conversions' numerics (:mod:`daq.sync.conversions`), resampling
(:mod:`daq.sync.resample`), or writing the rows (:class:`daq.recording.writer.RunWriter`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from daq.config import InstrumentConfig
from daq.sync.conversions import forces_from_pressures, heave_pitch_from_lasers, wind_speed
from daq.sync.resample import SyncBlock
from ident.taps import TapLayout

__all__ = ["SyncColumns", "physical_columns"]

FloatArray = npt.NDArray[np.float64]


class SyncColumns(NamedTuple):
    """The columns of one block of sync rows (SI units; see ``SYNC_COLUMNS`` of the layout)."""

    h: FloatArray
    alpha: FloatArray
    lift: FloatArray
    moment: FloatArray
    pressure: FloatArray
    U: FloatArray
    rho: FloatArray


def physical_columns(sb: SyncBlock, lasers: Sequence[InstrumentConfig], taps: TapLayout,
                     rho_now: float) -> SyncColumns:
    """Convert one block of resampled streams into the sync view's physical columns.

    Parameters
    ----------
    sb : SyncBlock
        Rows on the sync time base: ``laser.<name>`` distances (m), ``pressure`` (n, taps) and
        ``pitot`` (Pa) when the rig has a scanner.
    lasers : sequence of InstrumentConfig
        The lasers whose streams ``sb`` holds, in order (none, or two or more; the first three
        are used).
    taps : TapLayout
        The section's taps (coordinates, normals, tributary lengths).
    rho_now : float
        The air density in use, kg/m^3.
    """
    n = len(sb)
    nan = np.full(n, np.nan)
    h, alpha = nan, nan
    if lasers:
        d = np.column_stack([sb.values[f"laser.{inst.name}"] for inst in lasers])
        x = [float(inst.settings["x"]) for inst in lasers]
        s = [float(inst.settings["standoff_mm"]) * 1e-3 for inst in lasers]
        if d.shape[1] > 3:  # the conversion takes 2 or 3 lasers: the first three
            d, x, s = d[:, :3], x[:3], s[:3]
        hp = heave_pitch_from_lasers(d, x, s)
        h, alpha = hp.h, hp.alpha
    if "pressure" in sb.values:
        pressure = sb.values["pressure"]
        lift, moment = forces_from_pressures(pressure, taps)
        rho = np.full(n, rho_now)
        U = wind_speed(sb.values["pitot"], rho).speed
    else:
        pressure = np.full((n, taps.n_taps), np.nan)
        lift, moment, U, rho = nan, nan, nan, np.full(n, rho_now)
    return SyncColumns(h=h, alpha=alpha, lift=lift, moment=moment, pressure=pressure, U=U,
                       rho=rho)
