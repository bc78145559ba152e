"""E2RFC's turbulence branch: refined instrumental variables with the holds' noise model.

In turbulent flow the measured force is the self-excited force of the whole motion (the
release's decay plus the random response the buffeting drives) plus the buffeting force. E2RFC's
regressors come from a modal fit of the decay, which cannot follow the random response, and its
least squares takes the buffeting for white noise: both bias it
(docs/guides/turbulence.md). This module fits the same rational-function model another
way, measured in ``benchmarks/turbulent_gls_experiment.py``:

- *Regressors from the measured motion*: ``q`` low-passed (zero phase) at :data:`FC_FACTOR`
  times the highest still-air frequency, ``q'`` and ``q''`` by a Savitzky-Golay filter, lag
  states by filtering ``q'`` through ``1 / (s + d U / B)`` from rest at the release, all
  decimated to about :data:`TARGET_FS`; the force low-passed alike. The self-excited force of
  the random response is then in the regressors, not in the residual.
- *A noise model from the hold*: while the model is held in the wind before the release it
  does not move, so its measured force is buffeting plus noise alone. An AR model of it (order
  by BIC up to :data:`AR_MAX_ORDER`, after the same filter and decimation), per release and
  force channel, is fixed and whitens both sides of the regression. Iterated from the fit's own
  residual instead it does not converge: the first fits' residuals hold mis-fitted self-excited
  force.
- *Refined IV*: even whitened, ``q'`` and ``q''`` respond at once to the force of the last
  sampling interval (and the zero-phase filter adds a little of the future), so least squares
  stays biased (-58 % on the flutter speed with the true lag roots and noise model). Two-stage
  least squares with the whitened regressors delayed by :data:`IV_DELAYS_S` as instruments is
  nearly consistent (-0.5 % in the same oracle test).
- *Lag roots* by a bounded search of the whitened residual of the IV coefficients (the
  prediction error), from roots spread over the reduced frequencies.
- *Structure* (one or two lags, A3 as the caller offers) by held-out error over releases: each
  release left out in turn is predicted by the model fitted on the others (whitened by its own
  hold's noise model), with the one-standard-error rule. Those refits are the jackknife the
  uncertainty needs, so the choice costs nothing extra. A structure whose fit on all releases
  the data contradict outright (the caller's test: E2RFC's is a flutter speed below a wind
  speed at which a release decayed) is not scored: refined IV sometimes lands on a model that
  flutters at a few per cent of the true speed (1 to 3 of 16 seeds per benchmark row), and
  another structure of the same releases then does not.

Only a turbulence branch: in smooth flow these regressors (filtered, differentiated measured
motion; :data:`MOTION` offers a Kalman smoother instead, measured and not the default) carry a
1-6 % error floor that E2RFC's modal-fit regressors do not, so :mod:`ident.identification.e2rfc`
calls this only when its releases hold a random response and each carries a hold of at least
:data:`MIN_HOLD_S`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.linalg import expm, solve_discrete_are
from scipy.optimize import least_squares
from scipy.signal import butter, lfilter, savgol_filter, sosfiltfilt

from ident.model.section import SectionModel
from ident.numerics.sampling import decimation_factor
from ident.numerics.selection import Candidate, select_one_se
from ident.numerics.stats import white_noise_std
from ident.records.release import Release

__all__ = ["MIN_HOLD_S", "TurbulentFit", "TurbulentResult", "fit_turbulent", "holds_suffice"]

FloatArray = npt.NDArray[np.float64]

#: Shortest hold before every release for the branch, s. Measured (plate Iw 1 %, 8 seeds): a
#: 10 s hold gives a 2.6-3.1 % median flutter-speed error, a 3 s hold 6.6-7.9 % with 2 of 8
#: fits without flutter: an AR model of a short hold misses the buffeting's low frequencies.
MIN_HOLD_S = 10.0
#: Low-pass cut-off of motion and force, as a multiple of the highest still-air frequency.
FC_FACTOR = 3.0
#: Order of the Butterworth low-pass (applied forward and backward).
FILTER_ORDER = 4
#: Rate the regression runs at, Hz (about: the decimation is a whole number of samples); 50 Hz
#: holds 3 f_max of these sections and keeps the AR models short.
TARGET_FS = 50.0
#: Delays of the instruments, s (6, 10 and 14 samples at 50 Hz): beyond the reach of the
#: zero-phase filters and the 0.1 s Savitzky-Golay window, while the narrow-band regressors
#: stay strongly correlated with their own past.
IV_DELAYS_S = (0.12, 0.20, 0.28)
#: Savitzky-Golay window for q' and q'', s (cubic).
SG_WINDOW_S = 0.1
#: Samples cut at each end of a release (filter and Savitzky-Golay edges), s.
EDGE_S = 0.2
#: Largest order of a hold's AR noise model.
AR_MAX_ORDER = 20
#: Bounds of the lag-root search (non-dimensional d).
D_BOUNDS = (1e-3, 20.0)
#: Lag counts the branch chooses among.
LAG_OPTIONS = (1, 2)
#: How the regressors' motion is estimated: ``"filter"`` low-passes the measured displacements
#: and differentiates them (Savitzky-Golay); ``"smoother"`` takes ``q``, ``q'`` from a Kalman
#: (RTS) smoother of the known structure driven by the measured force (:func:`smoothed_motion`)
#: and ``q''`` from its equation of motion; ``"smoother-sg"`` the smoother's ``q``, ``q'`` with
#: the filter's ``q''``. Measured (docs/development/e2rfc_turbulence.md): the smoother's motion is
#: 5-20 times closer to the truth and removes most of the smooth-flow floor, but the branch in
#: turbulence is worse with it (plate Iw 1 % median 11 % against 2.6 %), so the filter stays.
MOTION = "filter"


@dataclass(frozen=True)
class TurbulentFit:
    """One structure fitted by refined IV.

    Attributes
    ----------
    A : ndarray, shape (3 + n_lags, n_dof, n_dof)
        Roger coefficients (``A[2]`` zero when A3 is not fitted).
    d : ndarray, shape (n_lags,)
    with_A3 : bool
    covariance : ndarray
        Of the ``A`` entries (``parameter_index``) then ``log d`` (zero: the lag roots'
        uncertainty is left to the jackknife); two-stage least squares with the lag roots
        fixed, from the whitened residual's variance.
    parameter_index : tuple of (int, int, int)
    release_residuals : ndarray, shape (n_releases, n_dof)
        RMS force residual of each release and channel relative to that channel's RMS (the
        low-passed, decimated signals).
    """

    A: FloatArray
    d: FloatArray
    with_A3: bool
    covariance: FloatArray
    parameter_index: tuple[tuple[int, int, int], ...]
    release_residuals: FloatArray


@dataclass(frozen=True)
class TurbulentResult:
    """What the branch returns to :func:`ident.identification.e2rfc.identify`.

    Attributes
    ----------
    chosen : TurbulentFit
    leave_one_out : tuple of TurbulentFit
        The chosen structure fitted with each release left out in turn (the jackknife).
    alternatives : tuple of TurbulentFit
        The other structures within one standard error of the best held-out error.
    reduced : TurbulentFit or None
        The chosen structure without the releases at the highest wind speed (three or more
        speeds; for the extrapolation part).
    candidates : tuple of Candidate
        Every structure tried, with its held-out error (mean whitened squared prediction error
        of a left-out release; 1 = the hold's innovation level) and standard error.
    reason : str
        Why the chosen structure was chosen.
    contradicted : bool
        Whether ``admissible`` rejected every structure tried (all were scored then).
    """

    chosen: TurbulentFit
    leave_one_out: tuple[TurbulentFit, ...]
    alternatives: tuple[TurbulentFit, ...]
    reduced: TurbulentFit | None
    candidates: tuple[Candidate, ...]
    reason: str
    contradicted: bool = False


def holds_suffice(releases: Sequence[Release]) -> bool:
    """Whether every release carries a hold of at least :data:`MIN_HOLD_S`."""
    return all(r.hold is not None and r.hold.duration >= MIN_HOLD_S - 1e-9 for r in releases)


class _Signals:
    """A release's low-passed, decimated regressors and force, and its hold's noise model."""

    def __init__(self, release: Release, section: SectionModel) -> None:
        if release.hold is None:
            raise ValueError("the turbulence branch needs a hold before every release")
        B = section.B
        rho = section.rho if release.rho is None else release.rho
        qd = 0.5 * rho * release.U**2
        fs = release.fs
        f_max = max(section.fh, section.fa, section.fp or 0.0)
        # The cut-off below the recorded rate's Nyquist frequency; the decimated rate at least
        # 4 times the cut-off, so that the low-passed signals do not alias (at 500 Hz and the
        # benchmark's sections: 50 Hz for a 12 Hz cut-off).
        fc = min(FC_FACTOR * f_max, 0.45 * fs)
        self.sos = butter(FILTER_ORDER, fc / (fs / 2), output="sos")
        self.decim = max(1, min(int(round(fs / TARGET_FS)), decimation_factor(fs, 4.0 * fc)))
        q = release.coordinates(B)
        forces = release.generalised_forces(B)
        f = forces / (qd * B**2)
        window = int(round(SG_WINDOW_S * fs)) | 1
        if MOTION == "filter":
            qf = sosfiltfilt(self.sos, q, axis=0)
            qdot = savgol_filter(qf, window, 3, deriv=1, delta=release.dt, axis=0)
            qdd = savgol_filter(qf, window, 3, deriv=2, delta=release.dt, axis=0)
        elif MOTION in ("smoother", "smoother-sg"):
            # The same zero-phase low-pass as the force's: a linear filter on both sides keeps
            # the model's relation between them.
            q_s, qdot_s, qdd_s = smoothed_motion(q, forces, section, release.dt)
            qf = sosfiltfilt(self.sos, q_s, axis=0)
            qdot = sosfiltfilt(self.sos, qdot_s, axis=0)
            if MOTION == "smoother":
                qdd = sosfiltfilt(self.sos, qdd_s, axis=0)
            else:  # q'' as "filter" makes it: free of the tap noise the smoother's q'' carries
                qdd = savgol_filter(sosfiltfilt(self.sos, q, axis=0), window, 3, deriv=2,
                                    delta=release.dt, axis=0)
        else:
            raise ValueError(f"MOTION must be 'filter', 'smoother' or 'smoother-sg', got "
                             f"{MOTION!r}")
        ff = sosfiltfilt(self.sos, f, axis=0)
        c = B / release.U
        edge = int(round(EDGE_S * fs))
        self.rows = slice(edge, q.shape[0] - edge, self.decim)
        self.U, self.B, self.dt = release.U, B, release.dt
        self.qdot = qdot
        self.fixed = np.hstack([qf, c * qdot, c**2 * qdd])[self.rows]
        self.force = ff[self.rows]
        self.n_dof = q.shape[1]
        # Each normalised force channel's white-noise level (first differences at the full
        # rate), so that the channels weigh alike in the lag-root search.
        self.weight = 1.0 / (np.std(np.diff(f, axis=0), axis=0) / math.sqrt(2.0))
        held = release.hold.generalised_forces(B) / (qd * B**2)
        held = sosfiltfilt(self.sos, held, axis=0)[::self.decim]
        self.ar = [ar_fit(held[:, i], AR_MAX_ORDER) for i in range(self.n_dof)]

    def lags(self, d: FloatArray) -> FloatArray:
        """Lag states ``x_l`` of ``x' = q' - d U / B x`` from rest, at the regression's rows."""
        columns = []
        for d_l in d:
            a = math.exp(-self.U / self.B * d_l * self.dt)
            # Trapezoidal on q' (exact enough at the recorded rate, 10 times the regression's).
            x = lfilter([self.dt / 2, self.dt / 2], [1.0, -a], self.qdot, axis=0)
            columns.append(x[self.rows])
        return np.hstack(columns) if columns else np.zeros((self.force.shape[0], 0))

    def design(self, d: FloatArray, with_A3: bool) -> FloatArray:
        fixed = self.fixed if with_A3 else self.fixed[:, :2 * self.n_dof]
        return np.hstack([fixed, self.lags(d)])

    def whitened(self, X: FloatArray, channel: int) -> tuple[FloatArray, FloatArray]:
        """Whitened, weighted regressors and force of one channel (means removed first)."""
        a = self.ar[channel]
        Z = np.column_stack([X, self.force[:, channel]])
        Z = Z - Z.mean(axis=0)  # the means: static forces and the hold's offset
        Zw = lfilter(a, [1.0], Z, axis=0)[a.size - 1:] * self.weight[channel]
        return Zw[:, :-1], Zw[:, -1]


def smoothed_motion(q: FloatArray, forces: FloatArray, section: SectionModel, dt: float
                    ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Estimate a release's motion by a Kalman (RTS) smoother of the structure and its force.

    The measured generalised force is the whole aerodynamic force (self-excited plus
    buffeting) plus white tap noise, and drives the known structure:
    ``M q'' + C q' + K q = f - n_f``. So the state ``[q, q']`` follows from the force (with
    the tap noise as process noise) and the lasers (measurement noise); the smoother's
    ``q'`` integrates the force instead of differentiating noisy displacements, and
    ``q'' = M^-1 (f - C q' - K q)``.

    Parameters
    ----------
    q : ndarray, shape (n, n_dof)
        Measured coordinates ``[h/B, alpha(, p/B)]`` (1, rad), from the release (at rest).
    forces : ndarray, shape (n, n_dof)
        Measured generalised forces ``[L B, M(, D B)]``, N m/m.
    section : SectionModel
        The structure (``M``, ``C``, ``K`` for ``q``).
    dt : float
        Sampling interval, s.

    Returns
    -------
    q, q', q'' : ndarray, shape (n, n_dof)
        Smoothed coordinates (1, rad), their rates (1/s, rad/s) and accelerations (1/s^2,
        rad/s^2).
    """
    n, n_dof = q.shape
    M, C, K = section.mass_matrix(), section.damping_matrix(), section.stiffness_matrix()
    Minv = np.linalg.inv(M)
    eye, zero = np.eye(n_dof), np.zeros((n_dof, n_dof))
    Ac = np.block([[zero, eye], [-Minv @ K, -Minv @ C]])
    Bc = np.vstack([zero, Minv])
    # A constant force the record does not show (a zero offset of the taps or the lasers, a
    # static load the lasers' zero already holds): the record's mean of M q'' + C q' + K q - f,
    # with mean q'' ~ 0 (the release starts and ends near rest: an error of M v_end / T) and
    # mean q' = (q_end - q_0) / T.
    T = dt * (n - 1)
    offset = K @ q.mean(axis=0) + C @ (q[-1] - q[0]) / T - forces.mean(axis=0)
    u = forces + offset
    # First-order hold on the force (piecewise linear between samples): a zero-order hold
    # would delay it by half a sample, a phase error of the order of the aerodynamic damping.
    ns = 2 * n_dof
    big = np.zeros((ns + 2 * n_dof, ns + 2 * n_dof))
    big[:ns, :ns] = Ac * dt
    big[:ns, ns:ns + n_dof] = Bc * dt
    big[ns:ns + n_dof, ns + n_dof:] = eye
    phi = expm(big)
    A, G1, G2 = phi[:ns, :ns], phi[:ns, ns:ns + n_dof], phi[:ns, ns + n_dof:]
    G0 = G1 - G2  # x[k+1] = A x[k] + G0 u[k] + G2 u[k+1]
    # White-noise levels from third differences (20 sigma^2 for white noise; the motion's and
    # the buffeting's own share is (2 pi f dt)^3 small at these rates).
    sig_f = white_noise_std(forces)
    sig_q = white_noise_std(q)
    S_f = np.diag(sig_f**2)
    Q = G0 @ S_f @ G0.T + G2 @ S_f @ G2.T
    R = np.diag(np.maximum(sig_q, 1e-12 * np.max(np.abs(q)) + 1e-300) ** 2)
    H = np.hstack([eye, zero])
    # Steady-state gains: the smoother's own start-up is short next to the edges cut. Q is
    # singular (the force enters through n_dof columns); a negligible floor keeps the Riccati
    # solver well posed.
    P_pred = solve_discrete_are(A.T, H.T, Q + 1e-30 * np.eye(ns), R)
    gain = P_pred @ H.T @ np.linalg.inv(H @ P_pred @ H.T + R)
    P_filt = (np.eye(ns) - gain @ H) @ P_pred
    J = P_filt @ A.T @ np.linalg.inv(P_pred)
    drive = u[:-1] @ G0.T + u[1:] @ G2.T
    # Forward: x_pred[k+1] = (A - A gain H) x_pred[k] + A gain y[k] + drive[k], from rest.
    x0 = np.concatenate([q[0], np.zeros(n_dof)])
    x_pred = _recursion(A - A @ gain @ H, q[:-1] @ (A @ gain).T + drive, x0)
    x_filt = x_pred + (q - x_pred[:, :n_dof]) @ gain.T
    # Backward (RTS): x_s[k] = J x_s[k+1] + x_filt[k] - J x_pred[k+1], from x_s[-1] = x_filt[-1].
    inputs = x_filt[:-1] - x_pred[1:] @ J.T
    x_s = _recursion(J, inputs[::-1], x_filt[-1])[::-1]
    q_s, v_s = x_s[:, :n_dof], x_s[:, n_dof:]
    a_s = (u - v_s @ C.T - q_s @ K.T) @ Minv.T
    return q_s, v_s, a_s


def _recursion(F: FloatArray, g: FloatArray, x0: FloatArray) -> FloatArray:
    """Return ``x`` with ``x[0] = x0``, ``x[k+1] = F x[k] + g[k]``, shape (len(g) + 1, n).

    By the eigenvectors of ``F``: each modal coordinate is a first-order recursion that
    :func:`scipy.signal.lfilter` runs in compiled code (a Python loop over 10^4 samples costs
    about 50 ms a pass). A defective ``F`` (ill-conditioned eigenvectors) takes the loop.
    """
    lam, V = np.linalg.eig(F)
    if np.linalg.cond(V) < 1e8:
        z0 = np.linalg.solve(V, x0.astype(complex))
        gz = np.linalg.solve(V, g.T.astype(complex)).T
        z = np.empty((g.shape[0] + 1, lam.size), dtype=complex)
        z[0] = z0
        for i, root in enumerate(lam):
            z[1:, i], _ = lfilter([1.0], [1.0, -root], gz[:, i], zi=[root * z0[i]])
        return np.real(z @ V.T)
    x = np.empty((g.shape[0] + 1, x0.size))
    x[0] = x0
    for k in range(g.shape[0]):
        x[k + 1] = F @ x[k] + g[k]
    return x


def ar_fit(e: FloatArray, p_max: int) -> FloatArray:
    """Return AR coefficients ``[1, a1, ..., ap]`` (the whitening filter) of a signal.

    Least squares for each order up to ``p_max``; the order by the Bayesian information
    criterion (order 0: white).
    """
    e = np.asarray(e, dtype=float) - float(np.mean(e))
    n = e.size
    best = (n * math.log(max(float(e @ e) / n, 1e-300)), np.array([1.0]))
    for p in range(1, min(p_max, n // 4) + 1):
        X = np.column_stack([e[p - k - 1:n - k - 1] for k in range(p)])
        y = e[p:]
        coef, *_ = np.linalg.lstsq(X, y, rcond=None)
        r = y - X @ coef
        bic = y.size * math.log(max(float(r @ r) / y.size, 1e-300)) + p * math.log(y.size)
        if bic < best[0]:
            best = (bic, np.concatenate([[1.0], -coef]))
    return best[1]


def _delays(signals: Sequence[_Signals]) -> tuple[int, ...]:
    rate = 1.0 / (signals[0].dt * signals[0].decim)
    return tuple(max(1, int(round(s * rate))) for s in IV_DELAYS_S)


def _iv_solve(signals: Sequence[_Signals], Xs: Sequence[FloatArray], delays: tuple[int, ...]
              ) -> tuple[FloatArray, list[FloatArray], list[FloatArray]]:
    """Two-stage least squares per force channel.

    Returns the coefficients (k, n_dof), each channel's whitened residual of them (what the
    lag-root search minimises) and each channel's covariance of its coefficients.
    """
    k = Xs[0].shape[1]
    n_dof = signals[0].n_dof
    K = max(delays)
    coef = np.empty((k, n_dof))
    residuals, covariances = [], []
    for i in range(n_dof):
        rows_X, rows_y, rows_Z = [], [], []
        for s, X in zip(signals, Xs, strict=True):
            Xw, yw = s.whitened(X, i)
            n = Xw.shape[0]
            rows_X.append(Xw[K:])
            rows_y.append(yw[K:])
            rows_Z.append(np.hstack([Xw[K - L:n - L] for L in delays]))
        X = np.vstack(rows_X)
        y = np.concatenate(rows_y)
        Q, _ = np.linalg.qr(np.vstack(rows_Z))
        Xp = Q @ (Q.T @ X)
        sol, *_ = np.linalg.lstsq(Xp, y, rcond=None)
        coef[:, i] = sol
        r = y - X @ sol
        residuals.append(r)
        sigma2 = float(r @ r) / max(r.size - k, 1)
        covariances.append(sigma2 * np.linalg.pinv(Xp.T @ Xp))
    return coef, residuals, covariances


def _fit(signals: Sequence[_Signals], n_lags: int, with_A3: bool, d0: FloatArray
         ) -> TurbulentFit:
    """Fit one structure: lag roots by the whitened IV residual, then the coefficients."""
    delays = _delays(signals)
    d = np.clip(np.asarray(d0, dtype=float), *D_BOUNDS)
    if n_lags:
        def residual(log_d: FloatArray) -> FloatArray:
            Xs = [s.design(np.exp(log_d), with_A3) for s in signals]
            return np.concatenate(_iv_solve(signals, Xs, delays)[1])

        lo, hi = np.log(D_BOUNDS[0]), np.log(D_BOUNDS[1])
        found = least_squares(residual, np.clip(np.log(d), lo + 1e-9, hi - 1e-9), method="trf",
                              x_scale=1.0, bounds=(lo, hi))
        d = np.sort(np.exp(found.x))
    Xs = [s.design(d, with_A3) for s in signals]
    coef, _, covariances = _iv_solve(signals, Xs, delays)
    n_dof = signals[0].n_dof
    terms = ([0, 1, 2] if with_A3 else [0, 1]) + [3 + m for m in range(n_lags)]
    columns = [(term, j) for term in terms for j in range(n_dof)]
    A = np.zeros((3 + n_lags, n_dof, n_dof))
    index = []
    for i in range(n_dof):
        for col, (term, j) in enumerate(columns):
            A[term, i, j] = coef[col, i]
            index.append((term, i, j))
    k = len(columns)
    covariance = np.zeros((n_dof * k + n_lags, n_dof * k + n_lags))
    for i, block in enumerate(covariances):
        covariance[i * k:(i + 1) * k, i * k:(i + 1) * k] = block
    residuals = np.array([
        np.sqrt(np.mean((s.force - X @ coef - (s.force - X @ coef).mean(axis=0)) ** 2, axis=0))
        / np.maximum(np.std(s.force, axis=0), 1e-300) for s, X in zip(signals, Xs, strict=True)])
    return TurbulentFit(A=A, d=d, with_A3=with_A3, covariance=covariance,
                        parameter_index=tuple(index), release_residuals=residuals)


def _prediction_error(s: _Signals, fit: TurbulentFit) -> float:
    """Mean whitened, weighted squared error of a model's prediction of one release's force."""
    X = s.design(fit.d, fit.with_A3)
    n_dof = s.n_dof
    terms = ([0, 1, 2] if fit.with_A3 else [0, 1]) + [3 + m for m in range(fit.d.size)]
    total = 0.0
    for i in range(n_dof):
        coef = np.array([fit.A[term, i, j] for term in terms for j in range(n_dof)])
        Xw, yw = s.whitened(X, i)
        e = yw - Xw @ coef
        total += float(np.mean(e**2))
    return total / n_dof


def _starts(n_lags: int) -> FloatArray:
    """Lag roots to start the search from: spread geometrically over 0.1-1 (the experiment's)."""
    return np.geomspace(0.1, 1.0, n_lags) if n_lags else np.zeros(0)


def fit_turbulent(releases: Sequence[Release], section: SectionModel, *,
                  a3_options: Sequence[bool] = (True, False), n_lags: int | None = None,
                  reduced_below: float | None = None,
                  admissible: Callable[[TurbulentFit], bool] | None = None) -> TurbulentResult:
    """Fit the rational-function model by refined IV with each release's hold as noise model.

    Every structure (lags in :data:`LAG_OPTIONS` or ``n_lags``, A3 in ``a3_options``) is fitted
    on all releases first; those ``admissible`` rejects (E2RFC's: a model that flutters below a
    wind speed at which a release decayed, which the data contradict) are dropped unless all
    are; the rest are scored by leave-one-release-out prediction error and chosen by the
    one-standard-error rule.

    Parameters
    ----------
    releases : sequence of Release
        Each with a hold (:func:`holds_suffice`); at two or more wind speeds.
    section : SectionModel
    a3_options : sequence of bool
        Whether the added-mass matrix A3 is fitted, per structure tried.
    n_lags : int, optional
        The number of lags; None chooses among :data:`LAG_OPTIONS` by held-out error.
    reduced_below : float, optional
        Fit the chosen structure again on the releases below this wind speed, m/s (E2RFC's
        highest distinct speed, with three or more: the extrapolation part); None: not.
    admissible : callable, optional
        Whether a structure fitted on all releases agrees with what the data say outright.

    Returns
    -------
    TurbulentResult
    """
    signals = [_Signals(r, section) for r in releases]
    options = LAG_OPTIONS if n_lags is None else (n_lags,)
    fulls = [_fit(signals, m, a3, _starts(m)) for m in options for a3 in a3_options]
    kept = [f for f in fulls if admissible is None or admissible(f)]
    rejected = len(fulls) - len(kept)
    contradicted = not kept
    if contradicted:  # every structure contradicted: score them all (the interval says so)
        kept, rejected = fulls, 0
    given = n_lags is not None and len(a3_options) == 1
    scored = []
    for full in kept:
        # Leave each release out in turn, from the full fit's roots: the refits are both the
        # held-out error of the structure and its jackknife.
        refits, errors = [], []
        for j in range(len(signals)):
            others = signals[:j] + signals[j + 1:]
            refit = _fit(others, full.d.size, full.with_A3, full.d)
            refits.append(refit)
            errors.append(_prediction_error(signals[j], refit))
        err = np.array(errors)
        finite = bool(np.all(np.isfinite(err)))
        candidate = Candidate(
            n_lags=full.d.size, with_A3=full.with_A3, d=tuple(float(x) for x in full.d),
            cv_error=float(err.mean()) if finite else math.inf,
            cv_se=float(err.std(ddof=1) / math.sqrt(err.size)) if finite else 0.0,
            n_params=full.covariance.shape[0])
        scored.append((candidate, full, tuple(refits)))
    candidates = [c for c, _, _ in scored]
    chosen_candidate, reason = select_one_se(candidates, given=given)
    best = min(candidates, key=lambda c: c.cv_error)
    threshold = best.cv_error + best.cv_se
    chosen = next(item for item in scored if item[0] is chosen_candidate)
    alternatives = tuple(full for c, full, _ in scored
                         if c is not chosen_candidate and c.cv_error <= threshold)
    if rejected:
        reason += (f"; {rejected} of {len(fulls)} structures left out: they flutter below a "
                   "wind speed at which a release decayed")
    reduced = None
    if reduced_below is not None:
        below = [s for s in signals if s.U < reduced_below]
        if below:
            reduced = _fit(below, chosen[1].d.size, chosen[1].with_A3, chosen[1].d)
    return TurbulentResult(chosen=chosen[1], leave_one_out=chosen[2], alternatives=alternatives,
                           reduced=reduced, candidates=tuple(candidates),
                           reason=f"refined IV with the holds' noise model: {reason}",
                           contradicted=contradicted)
