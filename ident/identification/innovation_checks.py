"""Whether a fit's innovations, pooled over its records, are white.

Each record's own check (:attr:`~ident.identification.closed_loop_ml.ClosedLoopFit.whiteness`)
has the power of one record. A model that misses part of every record a little (one shaping
section following a gust spectrum 10-25 % off) leaves each record's autocorrelations at their
chance level; pooled over all the records, they are not. :func:`pooled_portmanteau` is Ljung
and Box's statistic with the lagged products of every record summed before dividing by their
power; :func:`portmanteau_limit` its limit; :func:`portmanteau_warning` what the fit says
above it.

References
----------
G. M. Ljung and G. E. P. Box, "On a measure of lack of fit in time series models",
*Biometrika* 65 (1978) 297-303.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
import scipy.stats

__all__ = ["CHANNELS", "PORTMANTEAU_LAGS", "PORTMANTEAU_LEVEL", "pooled_portmanteau",
           "portmanteau_limit", "portmanteau_warning"]

FloatArray = npt.NDArray[np.float64]

#: Lags of the pooled portmanteau statistic (:func:`pooled_portmanteau`).
PORTMANTEAU_LAGS = 20
#: Chance of the pooled portmanteau statistic exceeding its limit on any of the four channels
#: when the model is right (split evenly between them; the limit is then 50). Measured
#: (plate, Iw 1 %, no holds, seeds 0-2): with one section per force the statistic of heave,
#: pitch and lift was 44-59 over 3 speeds x 2 releases and 99-206 over 3 x 8; with two
#: sections on exact block means 12-31 on every channel (chance: 20 on average), that model
#: 167-170 (3 x 2) and 575-598 (3 x 8) higher in log L for 24 more parameters and four more
#: initial states per record.
PORTMANTEAU_LEVEL = 1e-3
#: The channels of a record, in their order (with sway, then ``sway, drag``).
CHANNELS = ("heave", "pitch", "lift", "moment", "sway", "drag")


def pooled_portmanteau(innovations: Sequence[FloatArray], covariances: Sequence[FloatArray],
                       lags: int = PORTMANTEAU_LAGS) -> FloatArray:
    """Return the portmanteau statistic per channel of innovations pooled over records.

    Parameters
    ----------
    innovations : sequence of ndarray, shape (n_r, n_y)
        Each record's innovations, in its channels' units.
    covariances : sequence of ndarray, shape (n_y, n_y)
        Their covariances (each record's are standardised by its own).
    lags : int, optional
        Lags 1 to ``lags`` are summed.

    Returns
    -------
    ndarray, shape (n_y,)
        ``N sum_l rho_l^2`` with ``rho_l`` the autocorrelation at lag ``l`` of the standardised
        innovations, products summed over every record before dividing by their power, and
        ``N`` the samples of every record: chi-square with ``lags`` degrees of freedom for
        white innovations.
    """
    n_y = innovations[0].shape[1]
    products, power, samples = np.zeros((lags, n_y)), np.zeros(n_y), 0
    for e, S in zip(innovations, covariances, strict=True):
        u = e @ np.linalg.inv(np.linalg.cholesky(S)).T
        u = u - u.mean(axis=0)
        for lag in range(1, lags + 1):
            products[lag - 1] += np.sum(u[lag:] * u[:-lag], axis=0)
        power += np.sum(u * u, axis=0)
        samples += e.shape[0]
    return np.asarray(samples * np.sum((products / power) ** 2, axis=0), dtype=float)


def portmanteau_limit(n_channels: int = 4) -> float:
    """Return the pooled portmanteau statistic's limit (:data:`PORTMANTEAU_LEVEL`).

    The level is shared by the ``n_channels`` channels (four; six with sway).
    """
    return float(scipy.stats.chi2.isf(PORTMANTEAU_LEVEL / n_channels, PORTMANTEAU_LAGS))


def portmanteau_warning(portmanteau: FloatArray, n_records: int,
                         shaping_sections: int, *, n_holds: int) -> list[str]:
    """Return the warning of innovations not white pooled over the records (or none).

    ``n_holds``: how many of the records are holds before a release. Without any, the
    buffeting spectrum is learnt from the motion alone, and a gust spectrum that the filter
    does not follow pulls the flutter speed most (docs/development/e2rfc_turbulence.md): the
    warning then says that holds are the remedy too.
    """
    limit = portmanteau_limit(len(portmanteau))
    if not np.any(portmanteau > limit):
        return []
    named = zip(CHANNELS[:len(portmanteau)], portmanteau, strict=True)
    channels = ", ".join(f"{name} {q:.0f}" for name, q in named if q > limit)
    remedy = ("; one section per force follows a gust spectrum too loosely: the fourth-order "
              "buffeting model (closed_loop_buffeting='fourth-order', "
              "--closed-loop-buffeting fourth-order) removes most of that bias at about twice "
              "the time" if shaping_sections == 1 else "")
    if n_holds == 0:
        remedy += ("; without a hold in the wind before each release the buffeting spectrum "
                   "is learnt from the motion alone, and a spectrum the filter does not follow "
                   "then pulls the flutter speed most, mostly upwards: record holds")
    return [f"the innovations pooled over the {n_records} records are not white (portmanteau "
            f"statistic over lags 1-{PORTMANTEAU_LAGS}: {channels}; chance stays below "
            f"{limit:.0f}): the model misses part of the data, which biases the estimate "
            f"beyond what its Fisher deviation says{remedy}"]
