"""The steady-state Kalman predictor of a linear Gaussian state-space model, and its likelihood.

For ``x_{k+1} = Phi x_k + w_k``, ``y_k = C x_k + v_k`` (``w ~ N(0, Qd)``, ``v ~ N(0, R)``) the
steady-state predictor is ``x_{k+1} = Phi x_k + Kp e_k`` with the innovations
``e_k = y_k - C x_k``, ``Kp = Phi P C^T S^-1``, ``S = C P C^T + R`` and ``P`` the stabilising
solution of the discrete Riccati equation (:func:`riccati`). :class:`SteadyPredictor` runs it
in the modal coordinates of ``Phi - Kp C``, concentrates a record's constant offsets and
initial state out by least squares, and gives a nearby model's predictor and innovations to
first order (the Fisher information's derivatives, :mod:`ident.identification.closed_loop_ml`);
:func:`neg_log_likelihood` is ``-log L`` of the innovations.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.signal import lfilter

__all__ = ["RICCATI_ITERATIONS", "PredictorChange", "SteadyPredictor", "decorrelated",
           "neg_log_likelihood", "riccati"]

FloatArray = npt.NDArray[np.float64]

#: Most doubling steps of the Riccati solution (each squares the horizon: 60 is far beyond
#: what a stable, detectable model needs).
RICCATI_ITERATIONS = 60

#: Relative singular value below which a nuisance column (an offset or an initial state) is
#: taken as not moving the innovations: far below the columns' own conditioning (1e8 at most
#: measured) and far above round-off.
RANK_RTOL = 1e-11

LOG_2PI = math.log(2.0 * math.pi)


def neg_log_likelihood(e: FloatArray, S: FloatArray) -> float:
    """Return ``-log L`` of innovations ``e`` (n, m) of covariance ``S`` (m, m).

    ``n/2 (m log 2 pi + log det S) + 1/2 sum_k e_k^T S^-1 e_k``.
    """
    chol = np.linalg.cholesky(S)
    u = e @ np.linalg.inv(chol).T
    n = e.shape[0]
    return 0.5 * (n * (e.shape[1] * LOG_2PI + 2.0 * float(np.log(np.diag(chol)).sum()))
                  + float(np.sum(u * u)))


def riccati(Phi: FloatArray, C: FloatArray, Qd: FloatArray, R: FloatArray) -> FloatArray:
    """Steady predicted covariance ``P = Phi P Phi^T - Phi P C^T S^-1 C P Phi^T + Qd``.

    By the structure-preserving doubling algorithm (Chu, Fan, Lin, Wang 2004): the equation is
    ``X = A^T X (I + G X)^-1 A + H`` with ``A = Phi^T``, ``G = C^T R^-1 C``, ``H = Qd``, and the
    doubling converges quadratically, in a few dozen 12 x 12 solves (a fifth of the cost of
    the generalised Schur route for these sizes).

    Raises
    ------
    ValueError
        If the doubling does not converge (no stabilising solution: the model unstable and
        undetectable, or a singular ``R``).
    """
    A, G, H = Phi.T.copy(), C.T @ np.linalg.solve(R, C), Qd.copy()
    eye = np.eye(A.shape[0])
    for _ in range(RICCATI_ITERATIONS):
        W = eye + G @ H
        WA = np.linalg.solve(W, A)
        WG = np.linalg.solve(W, G)
        H_next = H + A.T @ H @ WA
        G = G + A @ WG @ A.T
        A = A @ WA
        if np.abs(H_next - H).max() <= 1e-13 * np.abs(H_next).max():
            return 0.5 * (H_next + H_next.T)
        H = H_next
        if not np.all(np.isfinite(H)):
            break
    raise ValueError("the steady-state Riccati equation has no stabilising solution here")


def decorrelated(Phi: FloatArray, Qd: FloatArray, C: FloatArray, R: FloatArray, M: FloatArray
                 ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Return the predictor's model with output noise uncorrelated with the process noise.

    For ``x_{k+1} = Phi x_k + w_k``, ``y_k = C x_k + u_k`` with ``E[w u^T] = M``, ``E[u u^T] =
    R``, the predictor's gain is ``(Phi P C^T + M) S^-1``. With ``G = M R^-1`` the model
    ``Phi - G C``, ``Qd - G M^T`` has uncorrelated noises, the same Riccati solution ``P`` and
    the same closed loop, and the gain is its own plus ``G``. Returns ``(Phi - G C, Qd - G M^T,
    G)``: the first two and ``C``, ``R`` make a :class:`SteadyPredictor` with
    ``feedthrough=G``.
    """
    if not np.any(M):  # uncorrelated already (samples rather than block means)
        return Phi, 0.5 * (Qd + Qd.T), np.zeros_like(M)
    G = np.asarray(np.linalg.solve(R, M.T).T, dtype=float)
    Qd_u = Qd - G @ M.T
    return Phi - G @ C, 0.5 * (Qd_u + Qd_u.T), G


@dataclass(frozen=True)
class PredictorChange:
    """A nearby predictor, to first order (:meth:`SteadyPredictor.change`).

    Attributes
    ----------
    P, S : ndarray
        Its Riccati solution and innovation covariance.
    closed_loop, gain, C : ndarray
        The changes of the closed loop ``Phi - Kp C``, of the gain (with any feedthrough) and
        of the output matrix.
    """

    P: FloatArray
    S: FloatArray
    closed_loop: FloatArray
    gain: FloatArray
    C: FloatArray


class SteadyPredictor:
    """The steady-state Kalman predictor of one model, in modal coordinates.

    Parameters
    ----------
    Phi, Qd : ndarray, shape (n_x, n_x)
        Transition matrix and process-noise covariance per sample.
    C : ndarray, shape (n_y, n_x)
        Output matrix.
    R : ndarray, shape (n_y, n_y)
        Measurement-noise covariance (positive definite).
    P : ndarray, shape (n_x, n_x), optional
        The Riccati solution, when known (:meth:`perturbed`); else solved by :func:`riccati`.
    feedthrough : ndarray, shape (n_x, n_y), optional
        Added to the gain: for output noise correlated with the process noise
        (:func:`decorrelated`), whose ``Phi`` and ``Qd`` are then the decorrelated ones.

    Raises
    ------
    ValueError
        If the Riccati equation has no stabilising solution, or the predictor is unstable.
    """

    def __init__(self, Phi: FloatArray, Qd: FloatArray, C: FloatArray, R: FloatArray,
                 P: FloatArray | None = None, feedthrough: FloatArray | None = None) -> None:
        self.Phi, self.Qd, self.C, self.R = Phi, Qd, C, R
        self.feedthrough = feedthrough
        self.P = riccati(Phi, C, Qd, R) if P is None else P
        self.S = C @ self.P @ C.T + R
        self.Kp = Phi @ self.P @ C.T @ np.linalg.inv(self.S)
        self.closed_loop = Phi - self.Kp @ C
        self.lam, self.V = np.linalg.eig(self.closed_loop)
        if np.max(np.abs(self.lam)) >= 1.0:
            raise ValueError("the predictor is unstable")
        self.V_inv = np.linalg.inv(self.V)
        self.gain = self.Kp if feedthrough is None else self.Kp + feedthrough
        self.drive = self.V_inv @ self.gain
        self.CV = C @ self.V
        self.n_x, self.n_y = Phi.shape[0], C.shape[0]
        # The matrix is real, so its complex modes come in conjugate pairs (LAPACK returns
        # them adjacent, with conjugate vectors): the recursion of the one with positive
        # imaginary part, doubled, stands for both.
        self.run = np.flatnonzero(self.lam.imag >= 0.0)
        self.doubling = np.where(self.lam[self.run].imag > 0.0, 2.0, 1.0)
        self.CV_run = self.CV[:, self.run] * self.doubling

    def change(self, Phi: FloatArray, Qd: FloatArray, C: FloatArray, R: FloatArray,
               feedthrough: FloatArray | None = None) -> PredictorChange:
        """Return how the predictor changes for nearby matrices, to first order.

        The change ``dP`` of the Riccati solution solves the Stein equation
        ``dP = Phi_c dP Phi_c^T + M`` with ``Phi_c = Phi - Kp C`` (this predictor's, already
        diagonalised: ``dP_ij`` is ``M_ij / (1 - lam_i conj(lam_j))`` in its modal
        coordinates) and

            M = dPhi P Phi_c^T + Phi_c P dPhi^T - Phi_c P dC^T Kp^T - Kp dC P Phi_c^T
                + dQd + Kp dR Kp^T.

        For a forward difference this is as exact as solving the Riccati equation again (its
        error is of the second order in the step, like the difference's own), at a tenth of
        the cost; the nearby predictor is neither diagonalised nor checked for stability (its
        innovations' change comes from this one's filter, :meth:`innovation_changes`).
        """
        return self.changes(Phi[None], Qd[None], C[None], R[None],
                            None if feedthrough is None else feedthrough[None])[0]

    def changes(self, Phi: FloatArray, Qd: FloatArray, C: FloatArray, R: FloatArray,
                feedthrough: FloatArray | None = None) -> list[PredictorChange]:
        """:meth:`change` for many nearby models at once: each argument stacked on a first axis.

        One batched product per step instead of one per model: a fit takes a change for
        every parameter it perturbs at every iteration.
        """
        dPhi, dC = Phi - self.Phi, C - self.C
        Pc = self.P @ self.closed_loop.T
        dPhi_Pc = dPhi @ Pc
        Kp_dC_Pc = self.Kp @ dC @ Pc
        M = (dPhi_Pc + dPhi_Pc.transpose(0, 2, 1) - Kp_dC_Pc.transpose(0, 2, 1) - Kp_dC_Pc
             + (Qd - self.Qd) + self.Kp @ (R - self.R) @ self.Kp.T)
        M_modal = self.V_inv @ M @ self.V_inv.conj().T
        Y = M_modal / (1.0 - self.lam[:, None] * self.lam.conj()[None, :])
        dP = (self.V @ Y @ self.V.conj().T).real
        P = self.P + 0.5 * (dP + dP.transpose(0, 2, 1))
        CT = C.transpose(0, 2, 1)
        S = C @ P @ CT + R
        Kp = Phi @ P @ CT @ np.linalg.inv(S)
        gain = Kp if feedthrough is None else Kp + feedthrough
        closed_loop = (Phi - Kp @ C) - self.closed_loop
        d_gain = gain - self.gain
        return [PredictorChange(P=P[i], S=S[i], closed_loop=closed_loop[i], gain=d_gain[i],
                                C=dC[i]) for i in range(Phi.shape[0])]

    def innovations(self, y: FloatArray, nuisance: FloatArray | None = None) -> FloatArray:
        """Innovations of ``y`` (n, n_y) less offsets ``nuisance[:n_y]``, from ``nuisance[n_y:]``.

        ``x_{k+1} = Phi x_k + Kp e_k`` in modal coordinates ``z = V^-1 x``: one first-order
        recursion per real mode or conjugate pair, run by scipy's lfilter in C.
        """
        u, z = self._modal_states(y, nuisance)
        return np.asarray(u - (z @ self.CV_run.T).real, dtype=float)

    def innovation_changes(self, y: FloatArray, nuisance: FloatArray,
                           changes: Sequence[PredictorChange]) -> FloatArray:
        """Return the first-order changes of the innovations for each change, nuisance held.

        With ``x_{k+1} = Phi_c x_k + K u_k`` and ``e_k = u_k - C x_k`` (``u`` the record less
        its offsets, ``K`` the gain, ``Phi_c`` the closed loop), a change moves the states by
        ``dx_{k+1} = Phi_c dx_k + dPhi_c x_k + dK u_k`` (``dx_0 = 0``: the initial state is
        held) and the innovations by ``de_k = -dC x_k - C dx_k``. Every change runs through
        this predictor's own modes, so all of them take one filter pass per mode rather than
        one predictor each.

        Parameters
        ----------
        y : ndarray, shape (n, n_y)
            The record, in its channels' units.
        nuisance : ndarray, shape (n_y + n_x,)
            Its offsets and initial state (:meth:`concentrated`), held.
        changes : sequence of PredictorChange
            From :meth:`change`.

        Returns
        -------
        ndarray, shape (len(changes), n, n_y)
            The innovations' changes, in the channels' units.
        """
        u, z = self._modal_states(y, nuisance)
        x = (z @ (self.V[:, self.run] * self.doubling).T).real  # (n, n_x)
        n, n_p = y.shape[0], len(changes)
        project = self.V_inv[self.run]  # (n_run, n_x): into the run modes
        # The modal inputs of every change: (mode, change, signal), the signals being the
        # states then the channels, stacked with time contiguous.
        inputs = np.stack([np.hstack([project @ c.closed_loop, project @ c.gain])
                           for c in changes], axis=1)
        signals = np.ascontiguousarray(np.hstack([x[:-1], u[:-1]]).T)
        n_s = signals.shape[0]
        roots = self.lam[self.run]
        C_dx = np.zeros((self.n_y * n_p, n))
        # The filter is linear, so each mode filters the few signals rather than the many
        # changes' inputs, and one product per group sums over modes and signals: C dz of
        # change p is the sum over modes and signals of CV inputs times the filtered signal.
        real = roots.imag == 0.0
        if np.any(real):
            filtered = np.stack([lfilter([1.0], [1.0, -root.real], signals, axis=-1)
                                 for root in roots[real]])
            weights = self._weights(real, inputs)
            C_dx[:, 1:] += np.ascontiguousarray(weights.real) @ filtered.reshape(-1, n - 1)
        if not np.all(real):
            # A complex mode z+ = r z + s driven by real s is, with w = s / (1 - 2 Re(r) q^-1
            # + |r|^2 q^-2) (one real filter, a fifth of a complex one's cost),
            # z+ = w - conj(r) w-: so Re(W z+) = Re(W) w - (Re(r) Re(W) + Im(r) Im(W)) w-.
            complex_roots = roots[~real]
            filtered = np.stack([lfilter([1.0], [1.0, -2.0 * r.real, abs(r) ** 2], signals,
                                         axis=-1) for r in complex_roots])
            weights = self._weights(~real, inputs).reshape(self.n_y * n_p, -1, n_s)
            lagged = -(complex_roots.real[:, None] * weights.real
                       + complex_roots.imag[:, None] * weights.imag)
            both = np.vstack([weights.real.reshape(self.n_y * n_p, -1),
                              lagged.reshape(self.n_y * n_p, -1)]) @ filtered.reshape(-1, n - 1)
            C_dx[:, 1:] += both[:self.n_y * n_p]
            C_dx[:, 2:] += both[self.n_y * n_p:, :-1]
        C_dx = C_dx.reshape(self.n_y, n_p, n)
        d_C = np.stack([c.C for c in changes], axis=1).reshape(self.n_y * n_p, -1)
        de = -(d_C @ x.T).reshape(self.n_y, n_p, n) - C_dx
        return np.ascontiguousarray(np.moveaxis(de, 0, -1))

    def _weights(self, modes: npt.NDArray[np.bool_], inputs: np.ndarray) -> np.ndarray:
        """Return ``CV`` times the modal inputs: rows (channel, change), columns (mode, signal).

        ``modes`` picks run modes; ``inputs`` is (run mode, change, signal).
        """
        n_p = inputs.shape[1]
        return (self.CV_run[:, modes][:, None, :, None]
                * inputs[modes].transpose(1, 0, 2)[None]).reshape(self.n_y * n_p, -1)

    def _modal_states(self, y: FloatArray, nuisance: FloatArray | None
                      ) -> tuple[FloatArray, FloatArray]:
        """Return ``u`` (the record less its offsets) and the modal states ``z`` (run modes)."""
        n_y = self.n_y
        offsets = np.zeros(n_y) if nuisance is None else nuisance[:n_y]
        z0 = (np.zeros(self.n_x, dtype=complex) if nuisance is None
              else self.V_inv @ nuisance[n_y:])
        u = y - offsets
        beta = u[:-1] @ self.drive[self.run].T
        z = np.empty((y.shape[0], self.run.size), dtype=complex)
        z[0] = z0[self.run]
        for column, m in enumerate(self.run):
            root = self.lam[m]
            if root.imag == 0.0:  # a real mode: real arithmetic, half the work
                root, drive, start = root.real, beta[:, column].real, z0[m].real
            else:
                drive, start = beta[:, column], z0[m]
            z[1:, column] = lfilter([1.0], [1.0, -root], drive, zi=[root * start])[0]
        return u, z

    def concentrated(self, y: FloatArray, at_zero: Sequence[int] = ()
                     ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Innovations with the offsets and the initial state at their GLS estimates.

        Returns the innovations (n, n_y), the whitened nuisance columns (n_y n, n_y + n_x less
        ``at_zero``) and the estimates ``[offsets (n_y), initial state (n_x)]``, the entries
        ``at_zero`` of the initial state held at zero (known, not estimated: no column). The
        columns: a unit initial state along axis j gives ``C A^k e_j = CV lam^k V^-1 e_j``; a
        unit offset on channel c gives ``1_c - CV g_k V^-1 Kp 1_c``, ``g_k = (1 - lam^k) / (1 -
        lam)`` (``|lam| < 1``).
        """
        n, n_y = y.shape[0], self.n_y
        e = self.innovations(y)
        W = np.linalg.inv(np.linalg.cholesky(self.S))
        CVw = W @ self.CV
        # lam^k by a running product: a tenth of the cost of complex powers (which take
        # exp(k log lam), as inexact by k rounding errors) and exact at lam = 0.
        powers = np.empty((n, self.lam.size), dtype=complex)
        powers[0], powers[1:] = 1.0, self.lam
        np.cumprod(powers, axis=0, out=powers)
        geometric = (1.0 - powers) / (1.0 - self.lam)[None, :]
        m = self.lam.size
        initial = ((powers[:, None, :] * CVw[None]).reshape(n_y * n, m) @ self.V_inv).real
        offsets = (np.tile(W, (n, 1))
                   - ((geometric[:, None, :] * CVw[None]).reshape(n_y * n, m) @ self.drive).real)
        free = np.setdiff1d(np.arange(self.n_x), np.asarray(at_zero, dtype=int))
        columns = np.hstack([offsets, initial[:, free]])
        ew = (e @ W.T).reshape(n_y * n)
        # Least squares on the columns themselves, not on their normal equations: the initial
        # states of lightly damped modes and the offsets are nearly collinear (the columns'
        # condition number reaches 1e8), and the normal equations' square of it lies beyond
        # double precision, where a rank cut-off made -log L jump by about 1 between
        # neighbouring parameter values. The cut-off left here drops only columns that are
        # zero to round-off (a lag state whose coefficients are zero moves no output).
        estimate = np.linalg.lstsq(columns, ew, rcond=RANK_RTOL)[0]
        e = ((ew - columns @ estimate).reshape(n, n_y)) @ np.linalg.inv(W).T
        nuisance = np.zeros(n_y + self.n_x)
        nuisance[:n_y], nuisance[n_y + free] = estimate[:n_y], estimate[n_y:]
        return e, columns, nuisance
