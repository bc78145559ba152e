"""Per-release regressors of the E2RFC least-squares problem.

For a release at wind speed U the normalised generalised force ``f~ = [L B, M] / (qd B^2)`` obeys
(``docs/conventions.md``, "In the time domain")::

    f~ = A1 q + A2 (B/U) q' + A3 (B/U)^2 q'' + sum_l A_{l+3} x_l,   x_l' = q' - (U/B) d_l x_l

All regressors are computed from the modal fit of the displacements (:mod:`ident.modal`), in
closed form: no noisy signal is ever differentiated, and the lag states start from zero at the
release instant t = 0 even when the record starts a little later.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from ident.modal import ModalFit, _exp, fit_modes, noise_std
from ident.release import Release
from ident.section import SectionModel

FloatArray = npt.NDArray[np.float64]

#: Rows per release kept for the held-out error and the precise lag-root search (every k-th
#: sample); the loose search of every start uses half of them (``"coarse"``): its roots are
#: converged again on these rows for the chosen structure (then moved by one Gauss-Newton step
#: on every sample). Halving the held-out error's rows too made its structure choice noisier.
SEARCH_ROWS = 1200


@dataclass(frozen=True, eq=False)
class PreparedRelease:
    """A release with its modal fit, fixed regressors and normalised forces.

    Attributes
    ----------
    release : Release
    fit : ModalFit
        Fit of ``q = [h/B, alpha]``.
    qd : float
        Dynamic pressure, Pa.
    fixed : ndarray, shape (n, 6)
        ``[q, (B/U) q', (B/U)^2 q'']`` (two columns each).
    force : ndarray, shape (n, 2)
        ``[L B, M] / (qd B^2)``.
    force_noise : ndarray, shape (2,)
        Noise estimate of each normalised force channel (sets its weight).
    """

    release: Release
    fit: ModalFit
    B: float
    qd: float
    fixed: FloatArray
    force: FloatArray
    force_noise: FloatArray
    _views: dict[str, RegressorView] = field(default_factory=dict, repr=False)

    @property
    def U(self) -> float:
        """Wind speed, m/s."""
        return self.release.U

    def view(self, which: str) -> RegressorView:
        """Return the regressors on a set of rows.

        ``"full"``: every sample; ``"search"``: the search subsample; ``"coarse"``: every other
        row of it.
        """
        if which not in self._views:
            step = self.search_rows().step
            rows = {"full": slice(None), "search": slice(None, None, step),
                    "coarse": slice(None, None, 2 * step)}[which]
            t = self.release.t[rows]
            self._views[which] = RegressorView(
                t=t,
                fixed=self.fixed[rows],
                force=self.force[rows],
                exponentials=_exp(np.outer(t, self.fit.poles)),
                fit=self.fit,
                rate=self.U / self.B,
            )
        return self._views[which]

    def search_rows(self) -> slice:
        """Every k-th row, so that the lag-root search sees about ``SEARCH_ROWS`` rows."""
        return slice(None, None, max(1, self.release.t.size // SEARCH_ROWS))


@dataclass(frozen=True, eq=False)
class RegressorView:
    """Fixed regressors, forces and the cached exponentials of the fit on a set of rows.

    The exponentials ``e^{p t}`` do not depend on the lag roots, so the many lag-state
    evaluations of the lag-root search reuse them.
    """

    t: FloatArray
    fixed: FloatArray
    force: FloatArray
    exponentials: npt.NDArray[np.complex128]
    fit: ModalFit
    rate: float  # U / B, 1/s

    def lag_columns(self, d: FloatArray) -> FloatArray:
        """Lag states ``x_l`` for lag roots ``d``, shape (n_rows, 2 m) (two columns per lag)."""
        if len(d) == 0:
            return np.zeros((self.t.size, 0))
        columns = []
        for d_l in d:
            mu = self.rate * d_l
            gained = (self.fit.poles / (self.fit.poles + mu))[:, None] * self.fit.amplitudes
            x = (self.exponentials @ gained).real
            x -= np.exp(np.maximum(-mu * self.t, -600.0))[:, None] * gained.sum(axis=0).real
            columns.append(x)
        return np.hstack(columns)

    def lag_derivatives(self, d: FloatArray) -> FloatArray:
        """Return the derivatives of :meth:`lag_columns` in ``log d``, shape (n_rows, 2 m).

        With ``g = p / (p + mu)`` (``mu = rate d``), ``x = Re[e^{pt} g C] - e^{-mu t} Re[sum g C]``
        and ``dg/dmu = -p / (p + mu)^2``; times ``dmu/dlog d = mu``.
        """
        if len(d) == 0:
            return np.zeros((self.t.size, 0))
        columns = []
        poles, amplitudes = self.fit.poles, self.fit.amplitudes
        for d_l in d:
            mu = self.rate * d_l
            gained = (poles / (poles + mu))[:, None] * amplitudes
            dgained = (-poles / (poles + mu) ** 2)[:, None] * amplitudes
            decay = np.exp(np.maximum(-mu * self.t, -600.0))[:, None]
            dx = ((self.exponentials @ dgained).real - decay * dgained.sum(axis=0).real
                  + self.t[:, None] * decay * gained.sum(axis=0).real)
            columns.append(mu * dx)
        return np.hstack(columns)


def prepare(release: Release, section: SectionModel) -> PreparedRelease:
    """Fit the modes of one release and build its fixed regressors and normalised forces."""
    B = section.B
    rho = section.rho if release.rho is None else release.rho
    qd = 0.5 * rho * release.U**2
    q = np.column_stack([release.h / B, release.alpha])
    fit = fit_modes(release.t, q)
    c = B / release.U
    t = release.t
    fixed = np.hstack([fit.evaluate(t) - fit.offset, c * fit.evaluate(t, 1),
                       c**2 * fit.evaluate(t, 2)])
    force = np.column_stack([release.lift * B, release.moment]) / (qd * B**2)
    scale = np.sqrt(np.mean((force - force.mean(axis=0)) ** 2, axis=0))
    noise = np.maximum(noise_std(force), 1e-6 * np.maximum(scale, 1e-300))
    return PreparedRelease(release=release, fit=fit, B=B, qd=qd, fixed=fixed, force=force,
                           force_noise=noise)
