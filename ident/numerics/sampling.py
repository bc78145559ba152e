"""Whole-number decimation factors of sampling rates that are not exactly round.

A rate read from a record's time stamps is the mean of its steps, and a recorder that puts its
channels on a synchronised time base gives rates such as 499.9999999999999 Hz for a nominal
500 Hz: the floor of ``fs / rate`` then falls one short of the factor the nominal rate gives
(4 instead of 5). Two records of one campaign decimated by different factors would then be
treated as if they had one rate. :func:`decimation_factor` takes a ratio within
:data:`RATE_RTOL` of a whole number as that number.
"""

from __future__ import annotations

import math

__all__ = ["RATE_RTOL", "decimation_factor"]

#: Relative tolerance of a rate against the whole multiple it is meant to be: far above the
#: rounding of a mean time step (1e-15) and a synchronised clock's drift over a run (about
#: 1e-7 for 0.1 ppm), far below the step between two whole factors.
RATE_RTOL = 1e-6


def decimation_factor(fs: float, least_rate: float) -> int:
    """Return the largest whole factor ``k >= 1`` with ``fs / k >= least_rate`` (up to rounding).

    Parameters
    ----------
    fs : float
        Sampling rate, Hz, > 0.
    least_rate : float
        The least rate the decimated record may have, Hz, > 0.

    Returns
    -------
    int

    Examples
    --------
    >>> decimation_factor(500.0, 100.0), decimation_factor(499.9999999999999, 100.0)
    (5, 5)
    >>> decimation_factor(499.0, 100.0), decimation_factor(80.0, 100.0)
    (4, 1)
    """
    if not (fs > 0 and least_rate > 0 and math.isfinite(fs) and math.isfinite(least_rate)):
        raise ValueError(f"fs and least_rate must be finite and > 0, got {fs!r} and "
                         f"{least_rate!r}")
    return max(1, math.floor(fs / least_rate * (1.0 + RATE_RTOL)))
