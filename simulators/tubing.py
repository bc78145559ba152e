"""Pneumatic tubing in the virtual tunnel: tap pressures as the scanner's transducers see them.

The tubes (:mod:`ident.physics.tubing`) are linear and time-invariant, and so is the map from the
tunnel's physical channels to the tap pressures (``p = A [lift, moment, qd]``: the pressures
that integrate to the forces plus the mean field of the dynamic pressure). So the pressure
behind tap ``i``'s tube is ``A_i`` applied to the channels convolved with that tube's impulse
response, a causal FIR filter::

    p_i(t) = A_i sum_k h_k [lift, moment, qd](t - k dt)

The impulse response ``h`` is the inverse FFT of ``H(f)`` on a grid of step :data:`FIR_DT_S`,
``H`` kept exactly up to :data:`FIR_EXACT_HZ` and rolled off to zero at ``1 / (2 dt)`` (the
tunnel's channels hold nothing up there; a sharp edge would ring). Its roll-off is zero-phase,
so the response reaches a millisecond or so before ``t = 0``; that part (under 1e-3 of it) is
dropped to keep the filter causal. It is cut where its tail holds less than :data:`FIR_TAIL`
of its absolute sum and scaled to ``sum h = H(0) = 1`` (a steady pressure passes unchanged).

The filter has no state of its own: it evaluates the tunnel's channels at the past times it
needs, so an instrument may ask for any times, in any blocks, and every ask gives the same
answer (a sample during a hold after a re-arm sees the held model for the whole memory of the
tube, tens of ms, where the real tube still carried the decay's last pressures).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from ident.physics.tubing import TableResponse, Tube, TubingSet

__all__ = ["FIR_DT_S", "FIR_TAIL", "TubingFilter", "impulse_response"]

FloatArray = npt.NDArray[np.float64]

#: Time step of the tubes' impulse responses, s (a 2 kHz filter: the channels are splines
#: through 1 kHz samples, with nothing near 1 kHz for the filter to alias).
FIR_DT_S = 5e-4
#: Highest frequency at which the filter's response is exactly the tube's, Hz (the scanner's
#: Nyquist frequency at 500 Hz; the tunnel's channels hold nothing near it).
FIR_EXACT_HZ = 250.0
#: Fraction of the impulse response's absolute sum that its cut tail may hold.
FIR_TAIL = 1e-5
#: Longest impulse response kept, s (a tube of tens of metres rings for longer: refused).
FIR_MAX_S = 2.0


def impulse_response(model: Tube | TableResponse, tubing: TubingSet,
                     dt: float = FIR_DT_S) -> FloatArray:
    """Discrete impulse response (sums to 1) of one tube, on a time step ``dt`` (s).

    Raises
    ------
    ValueError
        If the response is unknown below ``1 / (2 dt)`` (a table ending early) or does not die
        out within :data:`FIR_MAX_S`.
    """
    n = 1 << int(math.ceil(math.log2(2.0 * FIR_MAX_S / dt)))
    freqs = np.fft.rfftfreq(n, dt)
    H = model.response(freqs, tubing.air)
    if np.any(np.isnan(H)):
        raise ValueError(f"the tubing's response is unknown below {0.5 / dt:g} Hz (a table "
                         "ending early); the simulated scanner cannot apply it")
    # Rolled off smoothly above FIR_EXACT_HZ: a sharp band edge at the Nyquist frequency, where
    # a tube still passes a few per cent, would ring for seconds.
    x = np.clip((freqs - FIR_EXACT_HZ) / (freqs[-1] - FIR_EXACT_HZ), 0.0, 1.0)
    h = np.fft.irfft(H * 0.5 * (1.0 + np.cos(np.pi * x)), n)[: n // 2]  # t >= 0: causal
    tail = np.cumsum(np.abs(h[::-1]))[::-1]  # absolute sum from each sample on
    keep = int(np.searchsorted(-tail, -FIR_TAIL * tail[0]))
    if tail[-1] > FIR_TAIL * tail[0]:
        raise ValueError(f"the tubing's impulse response lasts longer than {FIR_MAX_S} s")
    h = h[:max(keep, 1)]
    return np.asarray(h / h.sum(), dtype=float)  # the cut tail's share back on the steady part


class TubingFilter:
    """Tap pressures behind their tubes, from a function of the tunnel's channels.

    Parameters
    ----------
    tubing : TubingSet
        Which taps have which tube.
    to_pressures : ndarray, shape (n_taps, 3)
        ``A`` with ``p = A [lift, moment, qd]`` (Pa per N/m, per N m/m, per Pa).
    dt : float
        Time step of the impulse responses, s.
    """

    def __init__(self, tubing: TubingSet, to_pressures: FloatArray,
                 dt: float = FIR_DT_S) -> None:
        if to_pressures.shape != (tubing.n_taps, 3):
            raise ValueError(f"to_pressures must have shape ({tubing.n_taps}, 3), got "
                             f"{to_pressures.shape}")
        self.tubing = tubing
        self.dt = float(dt)
        self._A = np.asarray(to_pressures, dtype=float)
        self._groups = [(tubing.members(i), impulse_response(g.model, tubing, dt))
                        for i, g in enumerate(tubing.groups)]

    @property
    def memory_s(self) -> float:
        """How far back the longest impulse response reaches, s."""
        return max(h.size for _, h in self._groups) * self.dt if self._groups else 0.0

    def pressures(self, t: FloatArray,
                  channels: Callable[[FloatArray], FloatArray]) -> FloatArray:
        """Tap pressures at the transducers at true times ``t``, Pa, shape (len(t), n_taps).

        ``channels(times)`` returns ``[lift, moment, qd]`` at any times (shape (len, 3)).
        """
        t = np.asarray(t, dtype=float)
        p = channels(t) @ self._A.T  # taps without tubing
        for members, h in self._groups:
            lags = np.arange(h.size) * self.dt
            times = (t[:, None] - lags[None, :]).ravel()
            unique, inverse = np.unique(times, return_inverse=True)
            values = channels(unique)[inverse].reshape(t.size, h.size, 3)
            p[:, members] = np.einsum("k,nkc->nc", h, values) @ self._A[members].T
        return np.asarray(p, dtype=float)
