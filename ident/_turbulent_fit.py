"""E2RFC's turbulence branch: refined instrumental variables with the holds' noise model.

In turbulent flow the measured force is the self-excited force of the whole motion (the
release's decay plus the random response the buffeting drives) plus the buffeting force. E2RFC's
regressors come from a modal fit of the decay, which cannot follow the random response, and its
least squares takes the buffeting for white noise: both bias it (docs/e2rfc_turbulence.md).
This module fits the same rational-function model another way, measured in
``benchmarks/turbulent_gls_experiment.py``:

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
motion) carry a 1-6 % error floor that E2RFC's modal-fit regressors do not, so :mod:`ident.e2rfc`
calls this only when its releases hold a random response and each carries a hold of at least
:data:`MIN_HOLD_S`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares
from scipy.signal import butter, lfilter, savgol_filter, sosfiltfilt

from ident._selection import Candidate, select_one_se
from ident.release import Release
from ident.section import SectionModel

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
    """What the branch returns to :func:`ident.e2rfc.identify`.

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
        self.decim = max(1, min(int(round(fs / TARGET_FS)), int(fs // (4.0 * fc))))
        q = release.coordinates(B)
        f = release.generalised_forces(B) / (qd * B**2)
        qf = sosfiltfilt(self.sos, q, axis=0)
        ff = sosfiltfilt(self.sos, f, axis=0)
        window = int(round(SG_WINDOW_S * fs)) | 1
        qdot = savgol_filter(qf, window, 3, deriv=1, delta=release.dt, axis=0)
        qdd = savgol_filter(qf, window, 3, deriv=2, delta=release.dt, axis=0)
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
