"""The buffeting response by the eigen decomposition of the modal state space (the fast route).

:func:`ident.bridge.buffeting.frequency_domain` integrates ``S_xi = H S_F H^H`` over a grid of
thousands of frequencies (a few hundred base points plus 24 around every in-wind pole). Done
frequency by frequency (its ``route="direct"``), each point costs the modal force matrix
``P Coh(f) P^T`` (``n^2`` times the nodes), an ``n x n`` complex inverse and four ``n x n``
products: 107 s for 200 modes at 1000 nodes, 54 % of it in the force matrix, 22 % in the
inverses, 17 % in the products. This module gives the same trapezoid sums on the same grid
without any per-frequency matrix work:

**The transfer matrix from one eigen decomposition.** The modal state space at ``U``
(:class:`~ident.bridge.statespace.BridgeStateSpace`: modal coordinates, velocities and lag
states, ``N = n (2 + lags)`` states) has ``S = V diag(lambda) V^-1``, so
``H(omega) = W diag(u(omega)) L`` with ``W`` the modal-coordinate rows of ``V``, ``L = V^-1 E``
and ``u_a = 1 / (i omega - lambda_a)``. Roger's lags make ``H`` rational; the state space holds
all of it, so this is exact (no modal truncation).

**The product of two poles in partial fractions.** ``u_a conj(u_b) = -(u_a + conj(u_b)) /
(lambda_a + conj(lambda_b))`` (exact; the denominator is not zero below flutter, where every
``Re lambda < 0``). With ``G(f) = L S_F(f) L^H`` the integrated response is then
``cov = Re W X W^H``, ``X = -(Y + Y^H) / (lambda_a + conj(lambda_b))``,
``Y = sum_f w_f diag(u(f)) G(f)``: the poles enter through one ``N``-vector per frequency.

**The load matrix is smooth in frequency.** ``S_F(f) = sum_c s_c(f) Q_c(f)`` with the scalar
spectra ``s_c`` (gust spectrum, admittance, ``(qd B^2/U)^2``) and ``Q_c(f) = P_c Coh_c(f)
P_c^T`` (``_coherent_quadratic`` of :mod:`ident.bridge.buffeting`), which depends on ``f`` only
through the coherence's decay ``C f / U``. Written ``S_F(f) = s(f) M(f)`` with
``s = s_u + s_w`` taken exactly at every frequency and ``M = sum_c (s_c / s) Q_c`` (the ratio
of the two von Karman spectra is smooth, the admittance and the factor cancel), ``M`` is
smooth over decades, unlike the transfer matrix's peaks: it is evaluated on a coarse grid
uniform in ``log(f + f_0)`` (``f_0`` the lowest positive frequency; 8 points a decade) and
interpolated by a cubic spline (``scipy.interpolate.make_interp_spline``), whose B-spline
coefficients ``C_m`` and local basis ``B_m(f)`` (four non-zero at each frequency) give
``Y = sum_m diag(k_m) L C_m L^H`` with ``k_m = sum_f w_f s(f) B_m(f) u(f)``: one spline for
both gusts. Measured: the spline of one gust's ``Q_c`` against the exact one (largest error
over the largest entry) on a 24-mode deck of 120 nodes: 7.6e-6 at 8 points a decade, 9e-7 at
14; the RMS of the 200-mode benchmark deck (1000 nodes, both gusts) within 1e-5 of the
direct route at 8 (modal RMS 2.2e-5), 1.2e-6 at 14. Gusts whose ``Q_c`` is constant (full
coherence, ``C = 0``, or a single node) keep one exact coefficient each: no spline error.

**Spectra only where asked.** A row ``r`` of responses (a modal coordinate, or h, alpha, p at
a spectrum node: ``r = R W``) has the one-sided spectrum ``S_r(f) = -2 Re sum_a u_a(f)
E[a, r](f)``, ``E(f) = W_r^T o ((G(f) / (lambda_a + conj(lambda_b))) W_r^H)``, interpolated as
``M``: per coefficient two ``N x N`` products, per frequency an ``N``-vector product. They are
most of this route's time (the reason for the spline's 8 points a decade, :data:`PER_DECADE`);
``spectra=False`` skips them.

**A certificate.** The eigen decomposition of a non-normal state matrix can be ill conditioned
(clusters of lag eigenvalues: the condition number of ``V`` is 2e11 on the 200-mode benchmark
deck, where the route is still within 3e-6). :func:`transfer_matrix` gives ``H`` at a few
frequencies, and the caller compares the modal spectra it gives with the direct inverse's at
the sharpest peaks, falling back to the direct route when they differ.

Not responsible for: the frequency grid, the gust projection and the direct route
(:mod:`ident.bridge.buffeting`), the time domain (:mod:`ident.bridge.buffeting_time`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.interpolate import BSpline, make_interp_spline

from ident.bridge.statespace import BridgeStateSpace

__all__ = ["EigenResponse", "LoadBasis", "constant_basis", "eigen_response", "load_basis",
           "transfer_matrix"]

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]

#: Coarse points a decade of ``f + f_0`` for the spline of the load matrix. The spectra cost
#: in proportion (two ``N x N`` products per coefficient), the RMS error falls as its fourth
#: power. Measured on the 200-mode benchmark deck against the direct route, at 8 a decade: RMS
#: within 1e-5 (modal RMS 2.2e-5), node spectra within 6e-5 of their peak, modal spectra
#: 2.6e-4, correlation times 6e-5 (at 14 a decade: RMS 1.2e-6, modal spectra 2.5e-5, and
#: the spectra 1.7 times as long to compute).
PER_DECADE = 8.0


@dataclass(frozen=True, eq=False)
class LoadBasis:
    """``Q_c(f) = sum_m design[f, m] coefs[m]`` for one gust component ``c``.

    Attributes
    ----------
    coefs : ndarray, shape (M, n, n)
        B-spline coefficients (m^2; symmetric, real).
    design : ndarray, shape (nf, M)
        The basis at the fine frequencies (four non-zero a row; one column of ones for a
        constant ``Q_c``).
    """

    coefs: FloatArray
    design: FloatArray

    def support(self, m: int) -> slice:
        """Rows (frequencies) where basis function ``m`` is not zero (an interval)."""
        rows = np.flatnonzero(self.design[:, m])
        return slice(0, 0) if rows.size == 0 else slice(int(rows[0]), int(rows[-1]) + 1)


def load_basis(matrix: Callable[[FloatArray], FloatArray], f: FloatArray,
               per_decade: float = PER_DECADE) -> LoadBasis:
    """Spline a smooth matrix function of frequency ``matrix(f)`` over the fine grid ``f`` (Hz).

    Parameters
    ----------
    matrix : callable
        ``matrix(f_coarse)`` returns the matrices (J, n, n) at frequencies ``f_coarse`` (Hz).
    f : ndarray, shape (nf,)
        The fine grid, Hz, increasing, ``>= 0``.
    per_decade : float
        Coarse points a decade of ``f + f_0``.
    """
    # log(f + f0): finite at f = 0, logarithmic above f0; the coherence is analytic in its
    # decay C f / U, so the load matrix is smooth in this variable over the whole grid.
    f0 = float(f[f > 0.0].min())
    t = np.log(f + f0)
    J = max(8, int(np.ceil(per_decade * (t[-1] - t[0]) / np.log(10.0)))) + 1
    t_coarse = np.linspace(t[0], t[-1], J)
    spline = make_interp_spline(t_coarse, matrix(np.exp(t_coarse) - f0), k=3)
    design = BSpline.design_matrix(np.clip(t, t_coarse[0], t_coarse[-1]), spline.t, 3)
    return LoadBasis(coefs=np.asarray(spline.c), design=design.toarray())


def constant_basis(matrix: FloatArray, nf: int) -> LoadBasis:
    """One exact coefficient for a load matrix that does not depend on frequency."""
    return LoadBasis(coefs=np.asarray(matrix)[None], design=np.ones((nf, 1)))


@dataclass(frozen=True, eq=False)
class EigenResponse:
    """What the eigen route returns: the modal covariance and the asked spectra.

    Attributes
    ----------
    cov : ndarray, shape (n_modes, n_modes)
        ``Re sum_f w_f S_xi(f)``, modal coordinate units squared.
    spectra : ndarray, shape (nf, R) or None
        One-sided spectra of the asked rows (``rows @ eta``), units^2/Hz; None if none asked.
    """

    cov: FloatArray
    spectra: FloatArray | None


def _pole_factor(f: FloatArray, lam: ComplexArray) -> ComplexArray:
    """``u[f, a] = 1 / (i 2 pi f - lambda_a)``, s."""
    return np.asarray(1.0 / (2j * np.pi * f[:, None] - lam[None, :]), dtype=complex)


def eigen_response(ss: BridgeStateSpace, lam: ComplexArray, vec: ComplexArray,
                   f: FloatArray, weights: FloatArray,
                   loads: list[tuple[FloatArray, LoadBasis]], rows: FloatArray | None = None
                   ) -> EigenResponse:
    """Integrated modal covariance (and spectra of ``rows``) by the eigen route.

    Parameters
    ----------
    ss : BridgeStateSpace
        The modal state space (its input matrix ``E``).
    lam, vec : ndarray
        Eigenvalues (1/s) and right eigenvectors (columns) of ``ss.matrix(U)``, all stable.
    f, weights : ndarray, shape (nf,)
        Frequencies (Hz) and their trapezoid weights (Hz).
    loads : list of (ndarray, LoadBasis)
        ``S_F(f) = sum s(f) M(f)`` over the list: each scalar spectrum ``s`` at ``f`` (modal
        force^2 per Hz per unit ``M``) and the spline of its matrix ``M``.
    rows : ndarray, shape (R, n_modes), optional
        Responses per unit modal coordinate whose spectra to return (with the same spline as
        the covariance, so that they integrate to it to rounding).
    """
    n = ss.n_modes
    W = vec[:n]  # (n, N): modal coordinates of the eigenvectors
    L = np.linalg.solve(vec, ss.input_matrix())  # (N, n)
    L_stacked = np.concatenate([L.real, L.imag])  # real BLAS for the products with real C_m
    N = lam.size
    # 1 / (lambda_a + conj(lambda_b)): not zero, all Re lambda < 0 (checked by the caller).
    pair_inv = 1.0 / (lam[:, None] + np.conj(lam)[None, :])

    def l_times(coef: FloatArray) -> ComplexArray:
        LC_stacked = L_stacked @ coef
        return np.asarray(LC_stacked[:N] + 1j * LC_stacked[N:])  # L C_m, (N, n)

    T = np.zeros((N, n), dtype=complex)
    for s_c, basis in loads:
        ws = weights * s_c
        for m in range(basis.coefs.shape[0]):
            sl = basis.support(m)
            k = (ws[sl] * basis.design[sl, m]) @ _pole_factor(f[sl], lam)  # (N,)
            T += k[:, None] * l_times(basis.coefs[m])
    Y = T @ L.conj().T
    X = -(Y + Y.conj().T) * pair_inv
    cov = np.asarray(((W @ X) @ W.conj().T).real, dtype=float)
    if rows is None:
        return EigenResponse(cov=0.5 * (cov + cov.T), spectra=None)
    W_rows = rows @ W  # (R, N)
    W_rows_H = np.ascontiguousarray(W_rows.conj().T)
    L_H = np.ascontiguousarray(L.conj().T)
    spectra = np.zeros((f.size, rows.shape[0]))
    for s_c, basis in loads:
        for m in range(basis.coefs.shape[0]):
            sl = basis.support(m)
            # E = W_r^T o ((G / (lambda_a + conj lambda_b)) W_r^H), G = L C_m L^H.
            G = (l_times(basis.coefs[m]) @ L_H) * pair_inv
            E = W_rows.T * (G @ W_rows_H)  # (N, R)
            spectra[sl] += -2.0 * ((s_c[sl] * basis.design[sl, m])[:, None]
                                   * (_pole_factor(f[sl], lam) @ E)).real
    return EigenResponse(cov=0.5 * (cov + cov.T), spectra=spectra)


def transfer_matrix(ss: BridgeStateSpace, lam: ComplexArray, vec: ComplexArray,
                    f: FloatArray) -> ComplexArray:
    """Return the eigen route's ``H = W diag(u) V^-1 E`` at frequencies ``f`` (Hz), (nf, n, n).

    For its certificate: the caller compares the spectra it gives with the direct inverse's at
    the sharpest peaks.
    """
    n = ss.n_modes
    L = np.linalg.solve(vec, ss.input_matrix())
    u = _pole_factor(f, lam)
    return np.stack([(vec[:n] * u[j]) @ L for j in range(f.size)])
