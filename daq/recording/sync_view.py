"""The physical columns of the synchronised view, from the resampled device streams.

Responsibility: :func:`physical_columns` turns one :class:`~daq.sync.resample.SyncBlock` (the
lasers' distances and the scanner's tap and Pitot pressures on the sync time base) into the
columns of ``/entry/sync``: heave and pitch from two or three lasers (their ``x`` and
``standoff_mm``, each reading through its calibration), lift and moment from the live taps'
pressures (the rig's tap layout without its dead taps), the wind speed from the Pitot through
the tunnel calibration with the air density in use. A column the rig has no device for is NaN.
A rig with three degrees of freedom (``[section] fp``) adds the sway ``p`` from its sway laser
(``axis = "sway"``) and the drag from the taps' pressures (NaN when the taps' outline has no
faces across the wind, :attr:`ident.physics.taps.TapLayout.carries_drag`); a 2-DOF rig has neither.
The calibrations are the rig config's (:class:`daq.calibration.Calibration`).

Not responsible for: the conversions' numerics (:mod:`daq.sync.conversions`), resampling
(:mod:`daq.sync.resample`), or writing the rows (:class:`daq.recording.writer.RunWriter`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from daq.calibration import Calibration
from daq.config import InstrumentConfig, RigConfig, is_sway_laser
from daq.sync.conversions import (
    forces_from_pressures,
    heave_pitch_from_lasers,
    sway_from_laser,
    wind_speed,
)
from daq.sync.resample import SyncBlock

__all__ = ["SyncColumns", "physical_columns", "polled_conditions", "tap_columns"]

FloatArray = npt.NDArray[np.float64]


class SyncColumns(NamedTuple):
    """The columns of one block of sync rows (SI units; see ``SYNC_COLUMNS`` of the layout).

    ``p`` (m) and ``drag`` (N/m): a 3-DOF rig's (``SWAY_COLUMNS``), None on a 2-DOF one.
    """

    h: FloatArray
    alpha: FloatArray
    lift: FloatArray
    moment: FloatArray
    pressure: FloatArray
    U: FloatArray
    rho: FloatArray
    p: FloatArray | None = None
    drag: FloatArray | None = None

    def sway(self) -> dict[str, FloatArray]:
        """Return ``{"p": ..., "drag": ...}`` of a 3-DOF rig, ``{}`` of a 2-DOF one."""
        if self.p is None or self.drag is None:
            return {}
        return {"p": self.p, "drag": self.drag}


def physical_columns(sb: SyncBlock, lasers: Sequence[InstrumentConfig], config: RigConfig,
                     rho_now: float, fan_rpm: float = math.nan) -> SyncColumns:
    """Convert one block of resampled streams into the sync view's physical columns.

    Parameters
    ----------
    sb : SyncBlock
        Rows on the sync time base: ``laser.<name>`` distances (m), ``pressure`` (n, taps)
        when the rig has a scanner, ``pitot`` (Pa) from the scanner or an analog transducer.
    lasers : sequence of InstrumentConfig
        The lasers whose streams ``sb`` holds, in order: the vertical ones (none, or two or
        more; the first three are used) and a 3-DOF rig's sway laser.
    config : RigConfig
        The rig: its taps (coordinates, normals, tributary lengths) and its calibrations (dead
        taps, Pitot, lasers).
    rho_now : float
        The air density in use, kg/m^3.
    fan_rpm : float
        The fan speed now, rpm (a Pitot factor tabulated on it; without a scanner, the wind
        speed: times wind_per_rpm; NaN: unknown).
    """
    taps, cal = config.taps, config.calibration
    n = len(sb)
    nan = np.full(n, np.nan)
    h, alpha = nan, nan
    sway_lasers = [inst for inst in lasers if is_sway_laser(inst)]
    lasers = [inst for inst in lasers if not is_sway_laser(inst)]
    if len(lasers) >= 2:
        d = np.column_stack([cal.laser(inst.name).distance(sb.values[f"laser.{inst.name}"])
                             for inst in lasers])
        x = [float(inst.settings["x"]) for inst in lasers]
        s = [float(inst.settings["standoff_mm"]) * 1e-3 for inst in lasers]
        if d.shape[1] > 3:  # the conversion takes 2 or 3 lasers: the first three
            d, x, s = d[:, :3], x[:3], s[:3]
        hp = heave_pitch_from_lasers(d, x, s)
        h, alpha = hp.h, hp.alpha
    rho = np.full(n, rho_now)
    if "pressure" in sb.values:
        pressure = sb.values["pressure"]
        if cal.taps.dead:
            live_taps, live = cal.live_taps(taps)
            lift, moment = forces_from_pressures(pressure[:, live], live_taps)
        else:
            lift, moment = forces_from_pressures(pressure, taps)
    else:
        pressure = np.full((n, taps.n_taps), np.nan)
        lift, moment = nan, nan
    if "pitot" in sb.values:
        # The scanner's Pitot, or (a rig without a scanner) an analog Pitot transducer's.
        U = wind_speed(cal.pitot.dynamic_pressure(sb.values["pitot"], fan_rpm), rho).speed
    else:
        # No Pitot at all (a rig without taps): the wind is the fan's actual speed times the
        # tunnel's calibration, [tunnel] wind_per_rpm (NaN until the drive reports one).
        U = np.full(n, fan_rpm * config.wind_per_rpm if math.isfinite(fan_rpm) else np.nan)
    p = drag = None
    if config.section.n_dof == 3:
        p, drag = _sway_columns(sb, sway_lasers, config, alpha, pressure)
    return SyncColumns(h=h, alpha=alpha, lift=lift, moment=moment, pressure=pressure, U=U,
                       rho=rho, p=p, drag=drag)


def _sway_columns(sb: SyncBlock, sway_lasers: Sequence[InstrumentConfig], config: RigConfig,
                  alpha: FloatArray, pressure: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Return a 3-DOF rig's sway (m) and drag (N/m) columns (NaN without their device)."""
    n = len(sb)
    p = np.full(n, np.nan)
    if sway_lasers:
        inst = sway_lasers[0]
        distance = config.calibration.laser(inst.name).distance(sb.values[f"laser.{inst.name}"])
        p = sway_from_laser(distance, float(inst.settings["standoff_mm"]) * 1e-3,
                            float(inst.settings.get("z", 0.0)), alpha)
    taps, cal = config.taps, config.calibration
    drag = np.full(n, np.nan)
    if "pressure" in sb.values and taps.carries_drag:
        if cal.taps.dead:
            live_taps, live = cal.live_taps(taps)
            if live_taps.carries_drag:
                drag = live_taps.integrate_drag(pressure[:, live])
        else:
            drag = taps.integrate_drag(pressure)
    return p, drag


def tap_columns(calibration: Calibration, n_taps: int) -> slice | npt.NDArray[np.intp]:
    """Return the taps' scanner columns, in tap order: a slice for the default wiring (a view)."""
    channels = list(calibration.tap_channels(n_taps))
    if channels == list(range(n_taps)):
        return slice(0, n_taps)
    return np.asarray(channels, dtype=np.intp)


def polled_conditions(kind: str, values: Mapping[str, Any], config: RigConfig,
                      fan_rpm: float) -> tuple[float, float]:
    """Return the fan speed (rpm) and air density (kg/m^3) a polled device's block tells.

    Parameters
    ----------
    kind : str
        The device's engine kind (``"fan"``: its ``speed`` is the fan speed).
    values : mapping
        The block's channels (a barometer's carry ``density``, ``pressure``, ``temperature``).
    config : RigConfig
        The rig; its ``[air]`` calibration decides the density: the driver's dry-air
        ``density``, or with a configured humidity (``[air] relative_humidity``, a fraction or
        the barometer's own ``relative_humidity``) moist air by CIPM-2007 from the row's
        pressure and temperature (NaN without the humidity).
    fan_rpm : float
        The fan speed known so far, rpm (returned unless the block has a finite one).

    Returns
    -------
    fan_rpm, rho : float
        The fan speed now, and the block's air density (NaN when it has none).
    """
    air = config.calibration.air
    if kind == "fan" and "speed" in values:
        speed = float(np.asarray(values["speed"], dtype=np.float64)[-1])
        fan_rpm = speed if math.isfinite(speed) else fan_rpm
    if "density" not in values:
        return fan_rpm, math.nan
    if not air.humid or "temperature" not in values:
        return fan_rpm, float(values["density"][-1])
    rh = (float(values["relative_humidity"][-1]) if "relative_humidity" in values
          else math.nan)
    return fan_rpm, air.density(float(values["pressure"][-1]), float(values["temperature"][-1]),
                                rh)
