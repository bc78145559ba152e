"""E2RFC's instrumental-variable problem for releases in turbulent flow (private to ident.e2rfc).

Why: in turbulence the measured force is ``F = F_se(x_det + x_rand) + F_b``: the buffeting force
``F_b`` drives a random response ``x_rand`` that is narrow-band at the modal frequencies and
stationary, while the release's deterministic decay ``x_det`` dies out. Regressed on the modal
fit of the displacements (:mod:`ident._e2rfc_problem`, the smooth-flow estimator), the error is
``F_se(x_rand) + F_b``: it is large exactly in the modal band the decay's information lives in,
and it is correlated with the regressors (the modal fit of a decay that turns into a random
response follows part of it), so the coefficients are biased and the lag-root search wanders.

What: the regressors are built from the MEASURED motion, so that ``F_se(x_rand)`` is explained
and the error is the buffeting force alone; the instruments are the same columns built from the
modal fit's deterministic decay (noise-free, and independent of the turbulence to first order:
the turbulence is independent of the release). For fixed lag roots the coefficients of each
force channel are the just-identified instrumental-variable solution ``(Z' W X)^-1 Z' W y``
(``W`` the channels' noise weights, per-release intercepts profiled out by demeaning); the lag
roots minimise the weighted residual ``y - X beta(d)`` (variable projection with the IV solve
inside; the Jacobian by central differences, one to three lag roots). The regressors ``X`` carry
the displacement noise; the instruments do not, so IV is consistent with noisy regressors too.

The measured displacements and the forces are low-passed by the same zero-phase Butterworth
filter (cutoff ``CUTOFF_FACTOR`` times the release's highest modal frequency) before ``q'`` and
``q''`` are taken by central differences: the model is linear and time-invariant, so filtering
both sides keeps it exact while the differentiated noise stays bounded. Before the release the
model is held at rest, so the records are padded with their first values (no filter transient
at the informative start); the last ``EDGE_PERIODS`` periods of the cut-off frequency are
dropped (the backward pass's transient). Lag states of the measured motion are integrated by
the exact recursion for piecewise-linear ``q``, from the modal fit's lag state at the first
sample.

Structure selection is the smooth-flow estimator's: five-fold held-out error (interleaved
one-period blocks), each fold's coefficients the IV solve on the other folds. The parameter
covariance is the Gauss-Newton one of the instruments' design with the IV residual's variance
and its autocorrelation inflation; in turbulence E2RFC reports the release-to-release scatter
(jackknife) as the statistical uncertainty instead (:mod:`ident.e2rfc`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.signal import butter, lfilter, sosfiltfilt

from ident._e2rfc_problem import MAX_CONDITION, N_FOLDS, FinalFit, Problem
from ident._lsq import bounded_lm
from ident._regressors import PreparedRelease, RegressorView
from ident._selection import Candidate
from ident._stats import autocorrelation_inflation
from ident.modal import ModalFit, _exp
from ident.rfc import RationalFunctionModel
from ident.section import SectionModel
from ident.statespace import AeroelasticSystem

__all__ = ["CUTOFF_FACTOR", "EDGE_PERIODS", "IVProblem", "deterministic_decay"]

FloatArray = npt.NDArray[np.float64]

#: Low-pass cutoff of the measured motion and forces, times the release's highest modal
#: frequency: far enough above the modes that their band is flat, low enough that the twice
#: differentiated displacement noise stays small.
CUTOFF_FACTOR = 4.0
#: Periods of the cutoff frequency dropped at the end of each record (filter transient).
EDGE_PERIODS = 3.0
#: Butterworth order of that filter.
FILTER_ORDER = 4


@dataclass(frozen=True, eq=False)
class _IVRows:
    """One release's instruments, measured regressors and filtered forces on a set of rows."""

    instruments: RegressorView  # modal fit: fixed columns and lag columns
    measured: FloatArray  # (n, 6): filtered [q, c q', c^2 q'']
    force: FloatArray  # (n, 2): filtered normalised forces
    rows: npt.NDArray[np.intp]


class _IVRelease:
    """A prepared release's filtered measured motion and forces, with views on row sets."""

    def __init__(self, p: PreparedRelease, search_step: int, instrument: ModalFit) -> None:
        self.p = p
        self.instrument = instrument
        r = p.release
        fs = 1.0 / r.dt
        f_top = float(p.fit.frequencies.max()) if p.fit.frequencies.size else fs / 40.0
        cutoff = min(CUTOFF_FACTOR * f_top, 0.4 * fs)
        sos = butter(FILTER_ORDER, cutoff / (fs / 2.0), output="sos")
        pad = int(math.ceil(EDGE_PERIODS * fs / cutoff)) * 2
        q = np.column_stack([r.h / p.B, r.alpha])
        q_start = p.fit.evaluate(r.t[:1])[0]
        force = p.force
        force_start = force[: max(3, int(0.01 * fs))].mean(axis=0)

        def filtered(x: FloatArray, start: FloatArray) -> FloatArray:
            # Padded before the release with the held value, at the end by reflection (those
            # samples are dropped anyway).
            padded = np.vstack([np.repeat(start[None, :], pad, axis=0), x])
            return np.asarray(sosfiltfilt(sos, padded, axis=0, padtype="odd")[pad:], dtype=float)

        qf = filtered(q, q_start)
        c = p.B / p.U
        dq = np.gradient(qf, r.dt, axis=0)
        ddq = np.gradient(dq, r.dt, axis=0)
        self.q = qf
        self.measured = np.hstack([qf - q_start, c * dq, c**2 * ddq])
        self.force = filtered(force, force_start)
        self.dt = r.dt
        self.t = r.t
        edge = int(math.ceil(EDGE_PERIODS * fs / cutoff))
        interior = np.arange(0, r.t.size - edge)
        self.row_sets = {"full": interior, "search": interior[::search_step],
                         "coarse": interior[::2 * search_step]}
        self._views: dict[str, _IVRows] = {}
        self._lag_cache: dict[bytes, FloatArray] = {}

    def view(self, which: str) -> _IVRows:
        if which not in self._views:
            rows = self.row_sets[which]
            p = self.p
            t = self.t[rows]
            fit = self.instrument
            exponentials = _exp(np.outer(t, fit.poles))
            c = p.B / p.U
            poles = fit.poles[:, None]
            fixed = (exponentials @ np.hstack([fit.amplitudes, c * poles * fit.amplitudes,
                                               c**2 * poles**2 * fit.amplitudes])).real
            instruments = RegressorView(t=t, fixed=fixed, force=p.force[rows],
                                        exponentials=exponentials, fit=fit, rate=p.U / p.B)
            self._views[which] = _IVRows(instruments, self.measured[rows], self.force[rows],
                                         rows)
        return self._views[which]

    def measured_lags(self, d: FloatArray) -> FloatArray:
        """Lag states of the filtered measured motion at every sample, shape (n, 2 m)."""
        key = np.asarray(d, dtype=float).tobytes()
        if key in self._lag_cache:
            return self._lag_cache[key]
        rate = self.p.U / self.p.B
        columns = []
        for d_l in d:
            mu = rate * float(d_l)
            a = math.exp(-mu * self.dt)
            g = (1.0 - a) / (mu * self.dt)
            x0 = self.p.fit.lag_state(self.t[:1], mu)[0]
            # x_n = a x_{n-1} + g (q_n - q_{n-1}): exact for piecewise-linear q; x(t0) = x0.
            dq = np.vstack([np.zeros((1, 2)), np.diff(self.q, axis=0)])
            x = lfilter([g], [1.0, -a], dq, axis=0)
            x += np.exp(-mu * (self.t - self.t[0]))[:, None] * x0
            columns.append(x)
        out = np.hstack(columns) if columns else np.zeros((self.t.size, 0))
        if len(self._lag_cache) > 8:
            self._lag_cache.clear()
        self._lag_cache[key] = out
        return out


class IVProblem:
    """The stacked instrumental-variable problem over all releases (module docstring).

    Offers the interface :mod:`ident.e2rfc` uses of :class:`ident._e2rfc_problem.Problem`:
    ``starts``, ``candidate``, ``polished``, ``refit``, ``final`` and ``K_range``.
    """

    def __init__(self, prepared: list[PreparedRelease], instruments: list[ModalFit]) -> None:
        self.base = Problem(prepared)
        self.prepared = prepared
        self.K_range = self.base.K_range
        self.weights = self.base.weights
        self.releases = [_IVRelease(p, max(1, p.search_rows().step or 1), z)
                         for p, z in zip(prepared, instruments, strict=True)]
        self._fold_rows = [self._folds(r) for r in self.releases]

    # -- the IV solve ------------------------------------------------------------------------
    def _blocks(self, d: FloatArray, with_A3: bool, which: str
                ) -> list[tuple[FloatArray, FloatArray, FloatArray]]:
        """Per release: instruments (n, k), measured regressors (n, k), forces (n, 2)."""
        out = []
        n_fixed = 6 if with_A3 else 4
        for r in self.releases:
            v = r.view(which)
            Z = np.hstack([v.instruments.fixed[:, :n_fixed], v.instruments.lag_columns(d)])
            X = np.hstack([v.measured[:, :n_fixed], r.measured_lags(d)[v.rows]])
            out.append((Z, X, v.force))
        return out

    def _solve(self, blocks: list[tuple[FloatArray, FloatArray, FloatArray]]
               ) -> tuple[FloatArray, list[FloatArray]]:
        """IV coefficients (k, 2) and weighted residuals per release (intercepts profiled)."""
        k = blocks[0][0].shape[1]
        centred = [(Z - Z.mean(axis=0), X - X.mean(axis=0), y - y.mean(axis=0))
                   for Z, X, y in blocks]
        coef = np.empty((k, 2))
        for i in range(2):
            G = np.zeros((k, k))
            b = np.zeros(k)
            for (Z, X, y), w in zip(centred, self.weights, strict=True):
                G += w[i] ** 2 * (Z.T @ X)
                b += w[i] ** 2 * (Z.T @ y[:, i])
            coef[:, i] = _scaled_solve(G, b)
        residuals = [w * (y - X @ coef) for (_, X, y), w in zip(centred, self.weights,
                                                                 strict=True)]
        return coef, residuals

    def _residual(self, theta: FloatArray, with_A3: bool, which: str) -> FloatArray:
        _, residuals = self._solve(self._blocks(np.exp(theta), with_A3, which))
        stacked = np.vstack(residuals)
        return np.concatenate([stacked[:, 0], stacked[:, 1]])

    # -- lag-root search ---------------------------------------------------------------------
    def starts(self, n_lags: int, previous: FloatArray | None) -> list[FloatArray]:
        """Start values of the lag-root search (the smooth-flow problem's)."""
        return self.base.starts(n_lags, previous)

    def search(self, n_lags: int, with_A3: bool, starts: list[FloatArray], *, loose: bool
               ) -> FloatArray:
        """Lag roots minimising the weighted IV residual, from the best of several starts."""
        if n_lags == 0:
            return np.zeros(0)
        K_lo, K_hi = self.K_range
        lo, hi = math.log(K_lo / 20.0), math.log(20.0 * K_hi)

        def solve(theta0: FloatArray, which: str, tol: float, nfev: int):  # type: ignore[no-untyped-def]
            def residual(theta: FloatArray) -> FloatArray:
                return self._residual(theta, with_A3, which)

            def jacobian(theta: FloatArray) -> FloatArray:
                h = 1e-5
                columns = []
                for j in range(theta.size):
                    up, down = theta.copy(), theta.copy()
                    up[j] += h
                    down[j] -= h
                    columns.append((residual(up) - residual(down)) / (2 * h))
                return np.column_stack(columns)

            return bounded_lm(residual, jacobian, np.clip(theta0, lo + 1e-6, hi - 1e-6),
                              (np.full(theta0.size, lo), np.full(theta0.size, hi)),
                              xtol=tol, ftol=1e-2 * tol, max_nfev=nfev)

        best = min((solve(np.log(start), "coarse", 1e-3, 20) for start in starts),
                   key=lambda sol: sol.cost)
        theta = best.x
        if not loose:
            theta = solve(theta, "search", 1e-6, 30).x
        return np.sort(np.exp(theta))

    # -- structures --------------------------------------------------------------------------
    def candidate(self, n_lags: int, with_A3: bool, starts: list[FloatArray], *, score: bool
                  ) -> tuple[Candidate, FloatArray | None]:
        """Search the lag roots of one structure and (if ``score``) its held-out error."""
        k = 2 * ((6 if with_A3 else 4) + 2 * n_lags) + n_lags
        d = self.search(n_lags, with_A3, starts, loose=score)
        if n_lags and np.min(np.diff(np.concatenate([[0.0], d]))) <= 1e-6 * d.max():
            return Candidate(n_lags, with_A3, tuple(d), math.inf, math.inf, k,
                             "lag roots merged: fewer lags describe the data"), None
        cond = self.base.condition(d, with_A3)
        if cond > MAX_CONDITION:
            return Candidate(n_lags, with_A3, tuple(d), math.inf, math.inf, k,
                             f"rank deficient (condition number {cond:.2g})"), None
        if not score:
            return Candidate(n_lags, with_A3, tuple(d), math.nan, math.nan, k), d
        errors = self._cross_validate(d, with_A3)
        return Candidate(n_lags, with_A3, tuple(d), float(errors.mean()),
                         float(errors.std(ddof=1) / math.sqrt(errors.size)), k), d

    def polished(self, candidate: Candidate) -> Candidate:
        """Return the candidate with its lag roots searched again at full precision."""
        import dataclasses

        d = self.search(candidate.n_lags, candidate.with_A3, [np.array(candidate.d)],
                        loose=False)
        return dataclasses.replace(candidate, d=tuple(float(x) for x in d))

    def refit(self, n_lags: int, with_A3: bool, starts: list[FloatArray]) -> FinalFit | None:
        """Fit a structure from near-converged starts, loosely (the uncertainty's refits)."""
        d = self.search(n_lags, with_A3, starts, loose=True)
        if n_lags and np.min(np.diff(np.concatenate([[0.0], d]))) <= 1e-6 * d.max():
            return None
        if self.base.condition(d, with_A3) > MAX_CONDITION:
            return None
        return self.final(Candidate(n_lags, with_A3, tuple(d), math.nan, math.nan, 0))

    def _cross_validate(self, d: FloatArray, with_A3: bool) -> FloatArray:
        """Held-out weighted mean squared force error per fold (IV solve on the other folds)."""
        blocks = self._blocks(d, with_A3, "search")
        errors = np.empty(N_FOLDS)
        for fold in range(N_FOLDS):
            train, held = [], []
            for (Z, X, y), folds in zip(blocks, self._fold_rows, strict=True):
                keep = np.ones(Z.shape[0], dtype=bool)
                keep[folds[fold]] = False
                train.append((Z[keep], X[keep], y[keep]))
                held.append((X[~keep], y[~keep], X[keep].mean(axis=0), y[keep].mean(axis=0)))
            coef, _ = self._solve(train)
            sq, n = 0.0, 0
            for (X, y, x_mean, y_mean), w in zip(held, self.weights, strict=True):
                e = w * ((y - y_mean) - (X - x_mean) @ coef)
                sq += float(np.sum(e**2))
                n += e.size
            errors[fold] = sq / max(n, 1)
        return errors

    @staticmethod
    def _folds(r: _IVRelease) -> list[npt.NDArray[np.intp]]:
        """Folds of interleaved one-period blocks of the search rows (as the smooth problem)."""
        t = r.t[r.row_sets["search"]]
        period = 1.0 / float(r.p.fit.frequencies.min())
        labels = (np.floor((t - t[0]) / period).astype(int)) % N_FOLDS
        return [np.flatnonzero(labels == k) for k in range(N_FOLDS)]

    def final(self, chosen: Candidate) -> FinalFit:
        """Fit the chosen structure on every sample; return the model's arrays and statistics."""
        d = np.array(chosen.d)
        condition = self.base.condition(d, chosen.with_A3)
        coef, residuals = self._solve(self._blocks(d, chosen.with_A3, "full"))
        terms = [0, 1, 2] if chosen.with_A3 else [0, 1]
        terms += [3 + l for l in range(d.size)]
        A = np.zeros((3 + d.size, 2, 2))
        index: list[tuple[int, int, int]] = []
        for i in range(2):
            for col, (term, j) in enumerate((t, j) for t in terms for j in range(2)):
                A[term, i, j] = coef[col, i]
                index.append((term, i, j))
        release_residuals = np.array([
            np.sqrt(np.mean((res / w) ** 2, axis=0))
            / np.sqrt(np.mean((r.view("full").force - r.view("full").force.mean(axis=0)) ** 2,
                              axis=0))
            for res, w, r in zip(residuals, self.weights, self.releases, strict=True)
        ])
        inflation = autocorrelation_inflation(residuals)
        covariance = self.base._covariance(d, chosen.with_A3, coef, residuals, inflation)
        return FinalFit(A=A, d=d, with_A3=chosen.with_A3, covariance=covariance,
                        parameter_index=tuple(index), release_residuals=release_residuals,
                        condition_number=condition, residual_inflation=inflation)


def _scaled_solve(G: FloatArray, b: FloatArray) -> FloatArray:
    """Solve ``G x = b`` with columns and rows scaled to unit diagonal magnitude (lstsq)."""
    row = np.sqrt(np.abs(np.einsum("ij,ij->i", G, G)))
    col = np.sqrt(np.abs(np.einsum("ij,ij->j", G, G)))
    row[row == 0.0] = 1.0
    col[col == 0.0] = 1.0
    scaled, *_ = np.linalg.lstsq(G / np.outer(row, col), b / row, rcond=None)
    return np.asarray(scaled / col, dtype=float)


def deterministic_decay(section: SectionModel, model: RationalFunctionModel,
                        p: PreparedRelease) -> ModalFit:
    """The free decay ``model`` predicts for a release, as a sum of exponentials (instruments).

    From rest at the release's initial displacement (the modal fit's value at the first sample,
    about its equilibrium): ``z(t) = V e^{Lambda t} V^-1 z0`` of the aeroelastic state matrix at
    the release's wind speed. It depends on the release's initial condition and the model only,
    not on the buffeting that follows the release. Poles the model puts in the right half-plane
    (a poor first model above its own flutter speed) are reflected into the left one so that the
    instruments stay bounded.
    """
    system = AeroelasticSystem(section, model, p.U)
    values, vectors = np.linalg.eig(system.matrix())
    fit = p.fit
    r = p.release
    start = max(3, int(round(0.01 / r.dt)))  # about 10 ms: the hold, averaged over its noise
    q0 = np.array([r.h[:start].mean() / p.B, r.alpha[:start].mean()]) - fit.offset
    z0 = np.zeros(system.n_states)
    z0[:2] = q0
    weights = np.linalg.solve(vectors, z0.astype(complex))
    amplitudes = (vectors[:2, :] * weights).T  # (n_poles, 2)
    # The oscillatory modes only: the lag modes' share of the displacement is small, and a real
    # pole at exactly a trial lag root's -U d / B would make the lag columns 0/0.
    keep = values.imag != 0.0
    values, amplitudes = values[keep], amplitudes[keep]
    poles = np.where(values.real > 0.0, -values.real + 1j * values.imag, values)
    # The decay from t = 0; the record's first sample is at t[0] (about 0).
    zero = np.zeros(2)
    return ModalFit(poles=np.asarray(poles, dtype=complex),
                    amplitudes=np.asarray(amplitudes, dtype=complex), offset=fit.offset.copy(),
                    noise=zero + fit.noise, residual_rms=zero + fit.residual_rms)
