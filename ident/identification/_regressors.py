"""Per-release regressors of the E2RFC least-squares problem.

For a release at wind speed U the normalised generalised force ``f~ = [L B, M(, D B)] / (qd B^2)``
obeys (``docs/reference/conventions.md``, "In the time domain"; n = 2 or 3 degrees of freedom)::

    f~ = A1 q + A2 (B/U) q' + A3 (B/U)^2 q'' + sum_l A_{l+3} x_l,   x_l' = q' - (U/B) d_l x_l

All regressors are computed from the modal fit of the displacements
(:mod:`ident.identification.modal`), in closed form: no noisy signal is ever differentiated, and the
lag states start from zero at the release instant t = 0 even when the record starts a little later.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import numpy.typing as npt

from ident.identification.modal import (
    ModalFit,
    _exponentials,
    _fit_modes_and_exponentials,
    noise_std,
)
from ident.model.section import SectionModel
from ident.records.release import Release

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
        Fit of ``q = [h/B, alpha(, p/B)]`` with as many modes as degrees of freedom.
    qd : float
        Dynamic pressure, Pa.
    fixed : ndarray, shape (n, 3 n_dof)
        ``[q, (B/U) q', (B/U)^2 q'']`` (``n_dof`` columns each).
    force : ndarray, shape (n, n_dof)
        ``[L B, M(, D B)] / (qd B^2)``.
    force_noise : ndarray, shape (n_dof,)
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
    #: ``e^{p t}`` of the fit's poles at every sample (n, n_poles), when :func:`prepare` has
    #: computed them for the fixed regressors: the views take their rows instead of computing
    #: the exponentials again.
    exponentials: npt.NDArray[np.complex128] | None = field(default=None, repr=False)

    @property
    def U(self) -> float:
        """Wind speed, m/s."""
        return self.release.U

    @property
    def n_dof(self) -> int:
        """Degrees of freedom (force channels) of the release: 2 or 3."""
        return int(self.force.shape[1])

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
            exponentials = (_exponentials(t, self.fit.poles) if self.exponentials is None
                            else self.exponentials[rows])
            self._views[which] = RegressorView(
                t=t,
                fixed=self.fixed[rows],
                force=self.force[rows],
                exponentials=exponentials,
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
    #: The last lag roots' ``_lag_terms``: the search asks for the columns, then (at the same
    #: roots, when it accepts them) for their derivatives, which reuse them.
    _terms: dict[bytes, tuple[FloatArray, npt.NDArray[np.complex128], FloatArray]] = field(
        default_factory=dict, repr=False, compare=False)

    @property
    def n_dof(self) -> int:
        """Degrees of freedom: columns of ``q`` (one lag state per lag and coordinate)."""
        return int(self.fit.amplitudes.shape[1])

    def lag_columns(self, d: FloatArray) -> FloatArray:
        """Lag states ``x_l`` for lag roots ``d``, shape (n_rows, n_dof m) (n_dof per lag).

        Every lag in one product: ``x_l = Re[e^{pt} g_l C] - e^{-mu_l t} Re[sum g_l C]`` with
        ``g_l = p / (p + mu_l)`` (``mu_l = rate d_l``).
        """
        if len(d) == 0:
            return np.zeros((self.t.size, 0))
        mu, gained, decay = self._lag_terms(d)
        # Each lag's decay multiplies its n_dof columns: broadcast over (rows, lag, coordinate)
        # rather than repeating the decays into a new array.
        shape = (self.t.size, mu.size, self.n_dof)
        columns = decay[:, :, None] * gained.sum(axis=0).real.reshape(shape[1:])
        np.subtract(self._real_product(gained).reshape(shape), columns, out=columns)
        return columns.reshape(self.t.size, -1)

    def lag_derivatives(self, d: FloatArray) -> FloatArray:
        """Return the derivatives of :meth:`lag_columns` in ``log d``, shape (n_rows, n_dof m).

        With ``g = p / (p + mu)`` (``mu = rate d``), ``x = Re[e^{pt} g C] - e^{-mu t} Re[sum g C]``
        and ``dg/dmu = -p / (p + mu)^2``; times ``dmu/dlog d = mu``.
        """
        if len(d) == 0:
            return np.zeros((self.t.size, 0))
        mu, gained, decay = self._lag_terms(d)
        poles = self.fit.poles[:, None]
        dgain = -poles / (poles + mu) ** 2  # (n_poles, m)
        dgained = (dgain[:, :, None] * self.fit.amplitudes[:, None, :]).reshape(poles.size, -1)
        shape = (self.t.size, mu.size, self.n_dof)
        per_lag = (mu.size, self.n_dof)
        dx = decay[:, :, None] * dgained.sum(axis=0).real.reshape(per_lag)
        np.subtract(self._real_product(dgained).reshape(shape), dx, out=dx)
        dx += (self.t[:, None] * decay)[:, :, None] * gained.sum(axis=0).real.reshape(per_lag)
        dx *= mu[:, None]
        return dx.reshape(self.t.size, -1)

    def _real_product(self, G: npt.NDArray[np.complex128]) -> FloatArray:
        """``Re(exponentials @ G)`` for ``G`` of shape (n_poles, c), as one real product."""
        design, kept, imaginary = self._real_design
        return np.asarray(design @ np.concatenate([G[kept].real, G[imaginary].imag]),
                          dtype=float)

    @cached_property
    def _real_design(self) -> tuple[FloatArray, npt.NDArray[np.intp], npt.NDArray[np.intp]]:
        """Real columns whose products give ``Re(exponentials @ G)``; the rows of ``G`` they take.

        ``Re(e G) = Re(e) Re(G) - Im(e) Im(G)``, and a conjugate pair (conjugate amplitudes:
        a real signal) gives twice the upper pole's real part: its conjugate needs no columns.
        So ``[2 Re e_upper, Re e_real, -2 Im e_upper]`` times ``[Re G_upper; Re G_real;
        Im G_upper]``: as many columns as poles, in a real product a quarter of the complex
        one's work. Poles without their conjugate pair keep both of their columns.
        """
        poles, amplitudes, E = self.fit.poles, self.fit.amplitudes, self.exponentials
        upper = np.flatnonzero(poles.imag > 0)
        lower = np.flatnonzero(poles.imag < 0)
        partners = [np.flatnonzero((poles == poles[u].conjugate())
                                   & np.all(amplitudes == amplitudes[u].conjugate(), axis=1))
                    for u in upper]
        # Every lower pole the conjugate partner of exactly one upper pole.
        paired = (all(p.size == 1 for p in partners)
                  and len({int(p[0]) for p in partners}) == lower.size == upper.size)
        if paired:  # each upper pole stands for its pair: twice its real part
            kept = np.concatenate([upper, np.flatnonzero(poles.imag == 0)])
            imaginary, factor = upper, 2.0
        else:
            kept = np.arange(poles.size)
            imaginary, factor = np.flatnonzero(poles.imag != 0), 1.0
        real_factor = np.where(poles[kept].imag != 0, factor, 1.0)
        design = np.hstack([E[:, kept].real * real_factor, -factor * E[:, imaginary].imag])
        return np.ascontiguousarray(design), kept, imaginary

    def _lag_terms(self, d: FloatArray) -> tuple[FloatArray, npt.NDArray[np.complex128],
                                                FloatArray]:
        """Return ``mu`` (m,), ``g_l C`` (n_poles, n_dof m) and ``e^{-mu t}`` (n_rows, m)."""
        d = np.asarray(d, dtype=float)
        key = d.tobytes()
        if key not in self._terms:
            mu = self.rate * d
            poles = self.fit.poles[:, None]
            gain = poles / (poles + mu)  # (n_poles, m)
            gained = (gain[:, :, None] * self.fit.amplitudes[:, None, :]).reshape(poles.size, -1)
            decay = np.exp(np.maximum(-np.outer(self.t, mu), -600.0))
            self._terms.clear()
            self._terms[key] = (mu, gained, decay)
        return self._terms[key]


def prepare(release: Release, section: SectionModel) -> PreparedRelease:
    """Fit the modes of one release and build its fixed regressors and normalised forces.

    A release with sway (three degrees of freedom) is fitted with three modes: the coordinates
    share the poles, and every mode must be in the decay (released from a displacement that
    excites it) for the force regression to see it.
    """
    B = section.B
    rho = section.rho if release.rho is None else release.rho
    qd = 0.5 * rho * release.U**2
    q = release.coordinates(B)
    fit, exponentials = _fit_modes_and_exponentials(release.t, q, n_modes=release.n_dof)
    assert exponentials is not None  # asked for (the default)
    c = B / release.U
    # q - offset, q' and q'' of the fit (ModalFit.evaluate) from one set of exponentials.
    p = fit.poles[:, None]
    fixed = (exponentials @ np.hstack([fit.amplitudes, c * p * fit.amplitudes,
                                       c**2 * p**2 * fit.amplitudes])).real
    force = release.generalised_forces(B) / (qd * B**2)
    scale = np.sqrt(np.mean((force - force.mean(axis=0)) ** 2, axis=0))
    noise = np.maximum(noise_std(force), 1e-6 * np.maximum(scale, 1e-300))
    return PreparedRelease(release=release, fit=fit, B=B, qd=qd, fixed=fixed, force=force,
                           force_noise=noise, exponentials=exponentials)
