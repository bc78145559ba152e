"""Measurement noise keyed to the release and the sample, not to the order of drawing.

A simulated instrument samples in real time, so how many samples it has drawn before a release
depends on thread timing (when the campaign released, how long the analysis between speeds
took). Noise drawn as one continuous stream therefore falls differently on every decay, and a
fixed seed does not give a fixed run. :class:`KeyedNoise` draws the noise of a sample from the
sample's place instead: the *epoch* (the number of releases the tunnel has made before the
sample: 0 before the first, n from the n-th release on) and the sample's index on the
instrument's own grid counted from that release (``round((tau - tau_release) * rate)`` in
device time ``tau``, so that a drifting clock still counts its own samples one by one). The
noise of epoch n is a stream of standard normals in chunks, chunk c drawn from
``numpy.random.default_rng([key, n, c])``; the instrument's ``key`` comes from its seed. The
same seed thus gives the same noise on the same samples of every decay, whatever the timing.

What is left to timing: where the instrument's grid falls relative to the release (a fraction
of a sample period: the decay is sampled a little earlier or later, the noise values are the
same), and which held samples a CALZ or a hold window averages. Outside the simulators, the
release time a recording takes (the host's time of the PLC's acknowledgement, measured 2-23
ms after the simulated magnet let go on a loaded two-core host) moves each decay's time origin
from run to run, and E2RFC's fit with it; keyed noise does not remove that.

Not responsible for: the noise level (each instrument scales the standard normals) or the
physics (:mod:`simulators.virtual_tunnel`).
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np
import numpy.typing as npt

from simulators.clock import DeviceClock

__all__ = ["KeyedNoise", "key_from", "sample_keys"]

FloatArray = npt.NDArray[np.float64]

#: Chunks of one stream kept in memory (a batch of samples rarely spans more than two).
_CHUNKS_KEPT = 8
#: Sample indices wrap here (2**40 samples: 8.7 years at 4 kHz).
_INDEX_WRAP = 1 << 40


def key_from(rng: np.random.Generator) -> int:
    """Return a stream key drawn from an instrument's generator (deterministic for a seed)."""
    return int(rng.integers(0, 2**63 - 1))


class KeyedNoise:
    """Standard normal noise of ``width`` channels keyed by (epoch, sample index).

    Parameters
    ----------
    key : int
        Key of the instrument's streams (from its seed, :func:`key_from`).
    width : int
        Channels per sample.
    chunk : int
        Samples per drawn chunk (a second or so of the instrument's rate).
    """

    def __init__(self, key: int, width: int, chunk: int) -> None:
        if width < 1 or chunk < 1:
            raise ValueError(f"width and chunk must be >= 1, got {width!r}, {chunk!r}")
        self.key, self.width, self.chunk = int(key), int(width), int(chunk)
        self._cache: OrderedDict[tuple[int, int], FloatArray] = OrderedDict()

    def _chunk(self, epoch: int, c: int) -> FloatArray:
        got = self._cache.get((epoch, c))
        if got is None:
            got = np.random.default_rng([self.key, epoch, c]).standard_normal(
                (self.chunk, self.width))
            self._cache[(epoch, c)] = got
            while len(self._cache) > _CHUNKS_KEPT:
                self._cache.popitem(last=False)
        return got

    def normal(self, epoch: npt.NDArray[np.int64], index: npt.NDArray[np.int64]) -> FloatArray:
        """Return the standard normals of samples ``(epoch[i], index[i])``, shape (n, width).

        ``index`` must be >= 0 (samples count from their epoch's release on).
        """
        epoch = np.asarray(epoch, dtype=np.int64)
        index = np.asarray(index, dtype=np.int64)
        out = np.empty((index.size, self.width))
        if index.size and int(index.min()) < 0:
            raise ValueError(f"sample indices must be >= 0, got {int(index.min())}")
        c_all = index // self.chunk
        if index.size and epoch[0] == epoch[-1] and c_all[0] == c_all[-1]:
            # One epoch, one chunk (a batch nearly always: the indices increase): no grouping.
            e, c = int(epoch[0]), int(c_all[0])
            if np.all(epoch == e) and np.all(c_all == c):
                return self._chunk(e, c)[index - c * self.chunk]
        for e, c in sorted(set(zip(epoch.tolist(), c_all.tolist(), strict=True))):
            sel = (epoch == e) & (c_all == c)
            out[sel] = self._chunk(e, c)[index[sel] - c * self.chunk]
        return out

    def sampled(self, release_times: list[float], t_true: FloatArray, device_time: FloatArray,
                clock: DeviceClock, rate_hz: float) -> FloatArray:
        """Return the standard normals of samples at true times ``t_true``, shape (n, width).

        ``release_times`` are the tunnel's (true s); ``device_time`` the samples' times on
        the instrument's ``clock``, whose grid runs at ``rate_hz``.
        """
        releases = np.asarray(release_times, dtype=float)
        epoch, index = sample_keys(releases.tolist(), np.asarray(t_true, dtype=float),
                                   np.asarray(device_time, dtype=float),
                                   np.asarray(clock.device_time(releases)), rate_hz)  # type: ignore[arg-type]
        return self.normal(epoch, index)


def sample_keys(release_times: list[float], t_true: FloatArray, device_time: FloatArray,
                device_time_of_release: FloatArray, rate_hz: float
                ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Return each sample's (epoch, index since its epoch's release).

    Parameters
    ----------
    release_times : list of float
        True times of the tunnel's releases so far, s (increasing).
    t_true : array
        True times of the samples, s.
    device_time : array
        The samples' device times, s.
    device_time_of_release : array
        Device time of each release in ``release_times`` (same length), s.
    rate_hz : float
        The instrument's sampling rate on its own clock, Hz.
    """
    epoch = np.searchsorted(np.asarray(release_times, dtype=float), t_true, side="right")
    # Epoch 0 counts from the device's time 0 (before any release: the samples only need keys
    # of their own, the held model's noise is not part of a decay).
    origin = np.concatenate([[0.0], np.asarray(device_time_of_release, dtype=float)])[epoch]
    index = np.rint((device_time - origin) * rate_hz).astype(np.int64)
    # Within a decay the index is >= 0; epoch 0's may be negative (a device clock behind the
    # tunnel's): wrapped, still one index per sample.
    return epoch.astype(np.int64), index % _INDEX_WRAP
