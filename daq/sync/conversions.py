r"""Physical conversions of the sync view: heave and pitch, forces, wind speed, air density.

Responsibility (the synchronised view of docs/reference/file_format.md): pure numerical code used by
the run writer

- :func:`heave_pitch_from_lasers` (:class:`HeavePitch`): heave and pitch of the section from 2
  or 3 laser distances;
- :func:`sway_from_laser`: the sway of a section with three degrees of freedom from the sway
  laser's distance (and the pitch);
- :func:`forces_from_pressures`: lift and moment per unit span from the tap pressures;
- :func:`wind_speed` (:class:`WindSpeed`): wind speed from the Pitot dynamic pressure;
- :func:`air_density`: dry-air density from the barometer's pressure and temperature.

Not responsible for: reading devices, threads, queues or files (the acquisition engine feeds arrays
in and takes arrays out), nor putting the streams on one time base (:mod:`daq.sync.resample`).

Conventions: SI units.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from daq.instruments.vaisala_ptb330.decoder import PRESSURE_RANGE_PA, TEMPERATURE_RANGE_K
from ident.physics.air import R_DRY_AIR
from ident.physics.taps import TapLayout

__all__ = [
    "HeavePitch",
    "WindSpeed",
    "air_density",
    "forces_from_pressures",
    "heave_pitch_from_lasers",
    "sway_from_laser",
    "wind_speed",
]

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


class HeavePitch(NamedTuple):
    """Heave and pitch from the lasers.

    Attributes
    ----------
    h : ndarray, shape (n,)
        Heave, m, positive downward.
    alpha : ndarray, shape (n,)
        Pitch, rad, positive nose-up.
    check : ndarray, shape (n,)
        With 3 lasers: the third laser's reading minus what the first two predict at its
        position, m (0 for a rigid, correctly positioned set-up, up to noise). NaN with 2
        lasers or when a laser has no value.
    """

    h: FloatArray
    alpha: FloatArray
    check: FloatArray


def heave_pitch_from_lasers(distances_m: Any, x_positions_m: Any, standoff_m: Any) -> HeavePitch:
    r"""Heave and pitch of the section from 2 or 3 laser distances.

    Geometry: the lasers look down on the model from above, at chord positions ``x_i``
    (downstream positive, origin at the elastic axis); with h positive downward and alpha
    positive nose-up (the leading edge, at x < 0, moves up for alpha > 0) a laser reads
    ``d_i = standoff_i + h + x_i alpha`` (small angles: ``tan(alpha) - alpha`` is 0.08 % of
    alpha at 3 degrees).

    With 3 lasers, h and alpha are the least-squares solution (the noise of all three
    averaged); the check is the third laser's disagreement with the line through the first
    two, which reveals a mis-positioned or mis-mastered laser, a dirty target, or a model that
    twists or bends. A sample where one of three lasers has no value (NaN: out of range, dark
    target) is solved exactly from the other two; with fewer than two values it is NaN.

    Parameters
    ----------
    distances_m : array_like, shape (n, n_lasers)
        Laser readings, m, NaN where invalid; n_lasers is 2 or 3.
    x_positions_m : array_like, shape (n_lasers,)
        Chord position of each laser spot, m; distinct.
    standoff_m : float or array_like, shape (n_lasers,)
        Reading of each laser with the model at rest (h = alpha = 0), m.

    Returns
    -------
    HeavePitch
        ``(h, alpha, check)``.

    Examples
    --------
    >>> r = heave_pitch_from_lasers([[0.026, 0.024]], [-0.1, 0.1], 0.025)
    >>> float(r.h[0]), float(r.alpha[0])
    (0.0, -0.01)
    """
    d = np.asarray(distances_m, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] not in (2, 3):
        raise ValueError(f"distances_m must have shape (n, 2) or (n, 3), got {d.shape}")
    k = d.shape[1]
    x = np.asarray(x_positions_m, dtype=np.float64)
    if x.shape != (k,) or not np.all(np.isfinite(x)):
        raise ValueError(f"x_positions_m must be {k} finite positions, got {x_positions_m!r}")
    if np.unique(x).size != k:
        raise ValueError(f"laser positions must be distinct (a pair at one x cannot see pitch), "
                         f"got {x.tolist()}")
    s = np.broadcast_to(np.asarray(standoff_m, dtype=np.float64), (k,))
    if not np.all(np.isfinite(s)):
        raise ValueError(f"standoff_m must be finite, got {standoff_m!r}")
    y = d - s
    valid = np.isfinite(y)
    h = np.full(d.shape[0], np.nan)
    alpha = np.full(d.shape[0], np.nan)
    # Solve once per pattern of valid lasers (at most 2**3 patterns), vectorised over samples.
    patterns, inverse = np.unique(valid, axis=0, return_inverse=True)
    for p, pattern in enumerate(patterns):
        cols = np.flatnonzero(pattern)
        if cols.size < 2:
            continue
        rows = np.flatnonzero(inverse.ravel() == p)
        A = np.column_stack([np.ones(cols.size), x[cols]])
        sol = np.linalg.pinv(A) @ y[np.ix_(rows, cols)].T  # exact for 2 lasers, LS for 3
        h[rows], alpha[rows] = sol[0], sol[1]
    check = np.full(d.shape[0], np.nan)
    if k == 3:
        a12 = (y[:, 1] - y[:, 0]) / (x[1] - x[0])
        check = y[:, 2] - (y[:, 0] + (x[2] - x[0]) * a12)
    return HeavePitch(h, alpha, check)


def sway_from_laser(distance_m: Any, standoff_m: float, z_m: float, alpha: Any) -> FloatArray:
    r"""Sway ``p`` (m, positive downwind) from the sway laser's distance.

    Geometry (the simulated laser's, :mod:`simulators.devices.microepsilon_ild1420`): the laser
    sits downstream of the model looking upwind at its trailing face, the spot at height ``z``
    (positive down from the elastic axis). The face moves downwind by ``p - z alpha`` (a nose-up
    pitch takes a point below the axis upwind), towards the laser: ``d = standoff - (p - z
    alpha)``, so ``p = standoff - d + z alpha`` (small angles, as for heave and pitch).

    Parameters
    ----------
    distance_m : array_like, shape (n,)
        The sway laser's readings, m (NaN where invalid: p is NaN there).
    standoff_m : float
        Its reading with the model at rest, m.
    z_m : float
        Height of its spot below the elastic axis, m (0: no pitch correction).
    alpha : array_like, shape (n,)
        Pitch, rad (used only when ``z_m`` is not 0; NaN there makes p NaN).

    Examples
    --------
    >>> sway_from_laser([0.024, 0.026], 0.025, 0.0, [0.0, 0.0]).tolist()
    [0.001, -0.001]
    """
    d = np.asarray(distance_m, dtype=np.float64)
    p = float(standoff_m) - d
    if z_m != 0.0:
        p = p + float(z_m) * np.asarray(alpha, dtype=np.float64)
    return np.asarray(p, dtype=np.float64)


def forces_from_pressures(pressures: Any, taps: TapLayout) -> tuple[FloatArray, FloatArray]:
    """Lift and moment per unit span from tap pressures (``TapLayout.integrate``).

    Parameters
    ----------
    pressures : array_like, shape (n, n_taps)
        Tap pressures relative to the free-stream static pressure, Pa, in the layout's tap
        order (the scanner's first ``n_taps`` channels). A NaN tap makes that sample's forces
        NaN: a missing module is a marked gap, never a silently smaller force.
    taps : TapLayout
        Tap geometry of the section.

    Returns
    -------
    lift, moment : ndarray, shape (n,)
        N/m (positive downward) and N m/m (positive nose-up).
    """
    return taps.integrate(pressures)


class WindSpeed(NamedTuple):
    """Wind speed from the Pitot dynamic pressure.

    Attributes
    ----------
    speed : ndarray
        m/s; 0 where clipped, NaN where rejected or where the input was NaN.
    clipped : ndarray of bool
        Dynamic pressure in ``[-zero_tolerance_pa, 0)``: zero-offset noise, speed set to 0.
    rejected : ndarray of bool
        Dynamic pressure below ``-zero_tolerance_pa``: not noise (swapped Pitot lines, a zero
        taken with the wind on); speed NaN.
    """

    speed: FloatArray
    clipped: BoolArray
    rejected: BoolArray


def wind_speed(pitot_qd_pa: Any, rho: Any, *, zero_tolerance_pa: float = 5.0) -> WindSpeed:
    r"""Wind speed ``U = sqrt(2 qd / rho)`` from the Pitot dynamic pressure.

    At wind off the Pitot reads zero plus noise, half of it negative. Such a sample is clipped
    to 0 m/s and flagged rather than made NaN: NaN would mark every still-air record as lost
    data, while 0 is the true speed to within the noise (and a release's speed should come
    from its mean ``qd``, where the noise averages out, not from the mean of this channel). A
    value below ``-zero_tolerance_pa`` is not noise but a fault, so it is NaN and flagged: 0
    there would be a wrong number that looks right. The square root never sees a negative.

    Parameters
    ----------
    pitot_qd_pa : array_like
        Dynamic pressure, Pa.
    rho : float or array_like
        Air density, kg/m^3 (> 0; NaN gives NaN), broadcast against ``pitot_qd_pa``.
    zero_tolerance_pa : float
        Largest negative reading taken as zero-offset noise, Pa (>= 0). The default 5 Pa is
        5 standard deviations of the simulated scanner's noise and about the zero accuracy of
        a 1 psi MPS4264 module (0.06 % FS [unverified]).

    Examples
    --------
    >>> w = wind_speed([60.0, -1.0, -50.0], 1.2)
    >>> w.speed, w.clipped, w.rejected
    (array([10.,  0., nan]), array([False,  True, False]), array([False, False,  True]))
    """
    tol = float(zero_tolerance_pa)
    if not (math.isfinite(tol) and tol >= 0.0):
        raise ValueError(f"zero_tolerance_pa must be finite and >= 0, got {zero_tolerance_pa!r}")
    qd, r = np.broadcast_arrays(np.asarray(pitot_qd_pa, dtype=np.float64),
                                np.asarray(rho, dtype=np.float64))
    if np.any(r <= 0.0) or np.any(np.isinf(r)):
        raise ValueError(f"rho must be > 0 and finite (NaN allowed), got min {np.nanmin(r)!r}")
    with np.errstate(invalid="ignore"):
        clipped = (qd < 0.0) & (qd >= -tol)
        rejected = qd < -tol
    q = np.where(clipped, 0.0, np.where(rejected, np.nan, qd))
    speed = np.sqrt(2.0 * q / r)  # q >= 0 or NaN here
    return WindSpeed(speed, clipped, rejected)


def air_density(pressure_pa: Any, temperature_k: Any) -> FloatArray:
    r"""Dry-air density ``rho = p / (R_d T)``, R_d = 287.058 J/(kg K), as the barometer driver.

    Humidity is neglected (moist air is lighter: rho is overestimated by ~0.4 % at 20 degC and
    50 %RH; see :func:`daq.instruments.vaisala_ptb330.decoder.reading_from_line`); a rig config's
    ``[air]`` table makes the run writer use :func:`ident.physics.air.moist_air_density` instead.

    Parameters
    ----------
    pressure_pa : array_like
        Absolute pressure, Pa (NaN passes through).
    temperature_k : array_like
        Temperature, K (NaN passes through).

    Raises
    ------
    ValueError
        A value outside the barometer's plausible ranges (50-120 kPa, 233-353 K): most often
        hPa or degC passed by mistake.

    Examples
    --------
    >>> round(float(air_density(101325.0, 288.15)), 4)
    1.225
    """
    p = np.asarray(pressure_pa, dtype=np.float64)
    t = np.asarray(temperature_k, dtype=np.float64)
    for name, arr, (lo, hi), hint in (("pressure_pa", p, PRESSURE_RANGE_PA, "hPa?"),
                                      ("temperature_k", t, TEMPERATURE_RANGE_K, "degC?")):
        with np.errstate(invalid="ignore"):
            out = (arr < lo) | (arr > hi)
        if np.any(out):
            raise ValueError(f"{name} = {float(arr[out].ravel()[0])!r} is outside [{lo}, {hi}] "
                             f"({hint})")
    return np.asarray(p / (R_DRY_AIR * t), dtype=np.float64)
