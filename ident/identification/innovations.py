"""The exact Gaussian likelihood of a release in turbulence, from a Kalman filter's innovations.

A section model released in turbulent flow is a linear system driven by coloured noise: the
self-excited forces (Roger's form, :mod:`ident.model.statespace`) close the loop, the buffeting
generalised force ``f_b = [L_b B, M_b]`` (N m/m) drives it, and the four recorded channels see
it through sensor noise. This module writes that as one discrete-time state-space model per wind
speed (:class:`ReleaseModel`) and evaluates the exact log-likelihood of a record by the
innovations of a Kalman filter (:func:`kalman_filter`, :func:`log_likelihood`). It is the
foundation of a closed-loop maximum-likelihood estimator; it holds no optimiser.

The continuous model. With ``Meff = Ms - rho/2 B^4 A3`` (structural plus added mass) and
``Ma = rho/2 B^4 A3``, the equations of motion ``Ms q'' + Cs q' + Ks q = f_se + f_b`` with the
self-excited force ``f_se = Kae q + Cae q' + Ma q'' + sum_l G_l x_l`` give::

    z' = A z + E f_b,                 E = [0; Meff^-1; 0]          (f_b enters the q'' rows)
    f_se = F z + Ma Meff^-1 f_b       (F = force_matrix(): its added-mass part uses A's q'' rows)

so that the recorded force, self-excited plus buffeting, is::

    f_se + f_b = F z + (I + Ma Meff^-1) f_b = F z + Ms Meff^-1 f_b.

The buffeting force is the output of a :class:`ShapingFilter`, ``x_b' = A_b x_b + B_b w``,
``f_b = C_b x_b`` with ``w`` unit-intensity continuous white noise (``E[w(t) w(s)^T] = I
delta(t - s)``). The augmented state ``x = [z, x_b]`` obeys ``x' = Ac x + G w`` with
``Ac = [[A, E C_b], [0, A_b]]`` and ``G = [0; B_b]``, and the outputs ``y = C x + v`` are
``[h, alpha, lift, moment]`` = ``[B q_h, alpha, (F z + Ms Meff^-1 C_b x_b)_0 / B,
(F z + Ms Meff^-1 C_b x_b)_1]`` (m, rad, N/m, N m/m) with sensor noise ``v ~ N(0, R)``,
``R = diag(sigma^2)``. With sway (three degrees of freedom) ``q = [h/B, alpha, p/B]``, the
buffeting force is ``[L_b B, M_b, D_b B]`` and the outputs gain ``[B q_p, (.)_2 / B]`` (m,
N/m): sway and drag.

The exact discretisation at the sampling interval ``T = 1/fs``: ``Phi = expm(Ac T)`` and
``Qd = int_0^T expm(Ac s) G G^T expm(Ac s)^T ds``, both from one matrix exponential (Van Loan
1978): ``expm([[-Ac, G G^T], [0, Ac^T]] T) = [[., Phi^-1 Qd], [0, Phi^T]]``. No hold is implied:
the process noise is continuous white noise, not a sampled one.

Timing (measured on the shared 2-core machine under load): a 20 s record at 500 Hz with the
Jones plate (12 states) is filtered in 0.09-0.21 s: the covariance recursion settles in 800-1000
samples, after which the gain is held and the rest runs as one vectorised pass; the full
recursion on every sample (``steady_tol=0``) takes 0.7-1.1 s. Building a model (one 24 x 24
matrix exponential) takes 7 ms.

References
----------
C. F. Van Loan, "Computing integrals involving the matrix exponential", IEEE Trans. Automatic
Control 23(3), 1978.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
import scipy.linalg

from ident.identification.channels import (
    coordinate_scales,
    displacement_channels,
    force_channels,
)
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.model.statespace import AeroelasticSystem
from ident.numerics import validate as v

__all__ = ["InnovationsResult", "ReleaseModel", "ShapingFilter", "block_means", "discretise",
           "kalman_filter", "log_likelihood"]

FloatArray = npt.NDArray[np.float64]

LOG_2PI = math.log(2.0 * math.pi)

@dataclass(frozen=True, eq=False)
class ShapingFilter:
    """The buffeting force ``[L B, M]`` as white noise through second-order sections per force.

    With one section (the default form), force ``i`` obeys ``f_i'' + 2 zeta_i w_i f_i' +
    w_i^2 f_i = w_i^2 (L xi)_i``, ``w_i = 2 pi f_i`` and ``xi`` unit-intensity white noise: unit
    gain at 0 Hz, so ``L L^T`` is the two-sided spectral density of the force at low
    frequency, (N m/m)^2/Hz; its spectrum falls as ``f^-4``. With ``S`` sections in cascade,
    section ``j`` of force ``i`` has the transfer ``w_ij^2 (1 + tau_ij s) / (s^2 + 2 zeta_ij
    w_ij s + w_ij^2)`` (unit gain at 0 Hz, a zero at ``-1 / tau_ij``): two sections follow a
    span-averaged von Karman force's slower fall around the corner (about ``f^-8/3``) to within
    a few per cent from 0 to 25 Hz, where one is 10-25 % low near 2-4 Hz.

    With sway (three degrees of freedom) the drag ``D B`` is a third force with its own
    sections, after the moment; the forces' correlations are all in ``L``.

    Mixed after the sections (``mixed_after``), row ``i`` is instead the filter of an
    independent source ``s_i`` (unit white noise through its sections) and the forces are
    ``L s``: source 0 drives every force, source 1 the moment (and drag), source 2 the drag
    alone. This is quasi-steady buffeting's own form, each force a fixed mix of gusts that
    have spectra of their own: the forces' coherence then changes with frequency (a drag
    driven mostly by along-wind gusts, the lift by vertical ones), where filtering each
    force after the mix holds it constant.

    Parameters
    ----------
    frequencies : array_like, shape (n_f,) or (n_f, S)
        Natural frequencies of each force's sections, Hz, > 0 (lift first); ``n_f`` is 2
        (lift, moment) or 3 (and drag).
    damping : array_like, same shape
        Damping ratios of the sections, > 0 (a stationary force needs a stable filter).
    L : array_like, shape (n_f, n_f)
        Lower-triangular Cholesky factor of the white noise's intensity, N m/m s^0.5. Its
        off-diagonal entries set the forces' correlations; zero is allowed (no buffeting).
    zeros : array_like, same shape as ``frequencies``, optional
        Time constants ``tau`` of the sections' zeros, s, finite. Default: none (all 0).
    mixed_after : bool, optional
        Mix independent sources' filters into the forces by ``L`` (above) rather than filter
        each force of the mixed white noise. Default False.

    Raises
    ------
    ValueError
        On a non-positive or non-finite frequency or damping ratio, shapes that do not match,
        or an ``L`` that is not a finite lower-triangular ``n_f`` x ``n_f`` matrix.
    """

    frequencies: Any
    damping: Any
    L: Any
    zeros: Any = None
    mixed_after: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.mixed_after, bool):
            raise ValueError(f"mixed_after must be True or False, got {self.mixed_after!r}")
        f = v.positive_array("frequencies", self.frequencies)
        z = v.positive_array("damping", self.damping)
        tau = np.zeros_like(f) if self.zeros is None else v.finite_array("zeros", self.zeros)
        L = v.finite_array("L", self.L, ndim=2)
        n_f = f.shape[0] if f.ndim else 0
        if (f.ndim not in (1, 2) or n_f not in (2, 3) or z.shape != f.shape
                or tau.shape != f.shape):
            raise ValueError(f"frequencies, damping and zeros need one row per force (lift, "
                             f"moment, and drag with sway) and one column per section, got "
                             f"shapes {f.shape}, {z.shape} and {tau.shape}")
        if L.shape != (n_f, n_f) or np.any(np.triu(L, 1) != 0.0):
            raise ValueError(f"L must be a lower-triangular {n_f}x{n_f} matrix (one row per "
                             f"force), got {L.tolist()}")
        for name, arr in (("frequencies", f), ("damping", z), ("zeros", tau), ("L", L)):
            arr = arr.reshape(n_f, -1) if name != "L" else arr
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)

    @property
    def n_forces(self) -> int:
        """Number of forces: 2 (lift, moment) or 3 (and drag)."""
        return int(self.frequencies.shape[0])

    @property
    def n_states(self) -> int:
        """Number of states: two per section per force."""
        return int(2 * self.n_forces * self.frequencies.shape[1])

    def matrices(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Return ``(A_b, B_b, C_b)``: ``x_b' = A_b x_b + B_b xi``, ``[L B, M] = C_b x_b``.

        The state is, per force, each section's output and its rate (N m/m and N m/(m s)),
        lift's sections first; shapes (n, n), (n, n_f), (n_f, n) with ``n`` :attr:`n_states`
        and ``n_f`` :attr:`n_forces` (with drag, ``[L B, M, D B] = C_b x_b``); ``A_b`` in
        1/s, ``B_b`` in N m/m s^-1.5. Mixed after the sections (:attr:`mixed_after`) the
        state is per source (s^-0.5 and s^-1.5, source 0's first), ``B_b`` in s^-2, and
        ``C_b`` carries ``L``.
        """
        n_sections, n_f = self.frequencies.shape[1], self.n_forces
        n = self.n_states
        w = 2.0 * math.pi * self.frequencies
        A_b, B0, C_b = np.zeros((n, n)), np.zeros((n, n_f)), np.zeros((n_f, n))
        for i in range(n_f):
            for j in range(n_sections):
                a = 2 * (i * n_sections + j)  # this section's output; a + 1 its rate
                A_b[a, a + 1] = 1.0
                A_b[a + 1, a] = -w[i, j] ** 2
                A_b[a + 1, a + 1] = -2.0 * self.damping[i, j] * w[i, j]
                if j == 0:
                    B0[a + 1, i] = w[i, j] ** 2
                else:  # driven by the previous section's output through its zero
                    A_b[a + 1, a - 2] = w[i, j] ** 2
                    A_b[a + 1, a - 1] = w[i, j] ** 2 * self.zeros[i, j - 1]
            last = 2 * (i * n_sections + n_sections - 1)
            C_b[i, last], C_b[i, last + 1] = 1.0, self.zeros[i, -1]
        if self.mixed_after:
            return A_b, B0, np.asarray(self.L) @ C_b
        return A_b, B0 @ np.asarray(self.L), C_b

    def stationary_covariance(self) -> FloatArray:
        """Covariance of the state ``x_b`` in its stationary distribution, (n_states, n_states).

        The solution of the Lyapunov equation ``A_b P + P A_b^T + B_b B_b^T = 0``.
        """
        A_b, B_b, _ = self.matrices()
        P = scipy.linalg.solve_continuous_lyapunov(A_b, -B_b @ B_b.T)
        return np.asarray(0.5 * (P + P.T), dtype=float)

    def spectrum(self, f: Any) -> npt.NDArray[np.complex128]:
        """Two-sided cross-spectral density of ``[L B, M]`` (and ``D B``) at ``f`` (Hz).

        ``S(f) = H(i 2 pi f) H(i 2 pi f)^H`` with ``H(s) = C_b (s I - A_b)^-1 B_b``; shape
        (len(f), n_f, n_f), (N m/m)^2/Hz. Its integral over all f is ``C_b P C_b^T``.
        """
        A_b, B_b, C_b = self.matrices()
        s = 2j * math.pi * np.atleast_1d(v.finite_array("f", f))
        H = C_b @ np.linalg.solve(s[:, None, None] * np.eye(A_b.shape[0]) - A_b, B_b)
        return np.asarray(H @ np.conj(np.swapaxes(H, 1, 2)), dtype=complex)


@dataclass(frozen=True, eq=False)
class ReleaseModel:
    """A section released in turbulence, discretised exactly at ``fs``.

    With two degrees of freedom the channels are ``[h, alpha, lift, moment]``; with sway,
    ``[h, alpha, lift, moment, p, drag]`` (the order of a 3-DOF release's channels; the
    shaping filter then of three forces).

    Parameters
    ----------
    section : SectionModel
        The structure (two or three degrees of freedom).
    model : RationalFunctionModel
        The self-excited forces (a 3-DOF model acts on a 2-DOF section through its heave-pitch
        block).
    U : float
        Mean wind speed, m/s, >= 0.
    fs : float
        Sampling rate, Hz, > 0.
    shaping : ShapingFilter
        The buffeting force.
    noise_std : array_like, shape (2 n_dof,)
        Sensor-noise standard deviations of ``h`` (m), ``alpha`` (rad), ``lift`` (N/m) and
        ``moment`` (N m/m) (and ``p``, m, and ``drag``, N/m), each >= 0 (the filter needs the
        innovation covariance to be positive definite: zero only where the state is
        uncertain).
    rho : float, optional
        Air density, kg/m^3; replaces the section's own when given.

    Attributes
    ----------
    Phi, Qd : ndarray, shape (n_x, n_x)
        Transition matrix and process-noise covariance over one sample.
    C : ndarray, shape (2 n_dof, n_x)
        Output matrix; ``R`` (2 n_dof, 2 n_dof): sensor-noise covariance.
    """

    section: SectionModel
    model: RationalFunctionModel
    U: float
    fs: float
    shaping: ShapingFilter
    noise_std: Any
    rho: float | None = None
    Phi: FloatArray = field(init=False, repr=False)
    Qd: FloatArray = field(init=False, repr=False)
    C: FloatArray = field(init=False, repr=False)
    R: FloatArray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        section = self.section
        if self.rho is not None and self.rho != section.rho:  # a copy costs the fit's loop
            section = section.replace(rho=v.positive("rho", self.rho))
        if self.shaping.n_forces != section.n_dof:
            raise ValueError(f"the shaping filter has {self.shaping.n_forces} forces for a "
                             f"section of {section.n_dof} degrees of freedom")
        object.__setattr__(self, "section", section)
        object.__setattr__(self, "fs", v.positive("fs", self.fs))
        std = v.finite_array("noise_std", self.noise_std, ndim=1)
        n_y = 2 * section.n_dof
        if std.shape != (n_y,) or np.any(std < 0.0):
            raise ValueError(f"noise_std must be {n_y} values >= 0 (h m, alpha rad, lift N/m, "
                             f"moment N m/m{', p m, drag N/m' if n_y == 6 else ''}), got "
                             f"{std.tolist()}")
        object.__setattr__(self, "noise_std", std)
        object.__setattr__(self, "U", AeroelasticSystem(section, self.model, self.U).U)
        Ac, G, C = self.continuous_matrices()
        Phi, Qd = discretise(Ac, G, 1.0 / self.fs)
        object.__setattr__(self, "Phi", Phi)
        object.__setattr__(self, "Qd", Qd)
        object.__setattr__(self, "C", C)
        object.__setattr__(self, "R", np.diag(std**2))

    def continuous_matrices(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Return ``(Ac, G, C)`` of the continuous system ``x' = Ac x + G w``, ``y = C x + v``.

        The state is ``[q, q', lag states, x_b]`` (module docstring); ``w`` unit white noise.
        """
        system = AeroelasticSystem(self.section, self.model, self.U)
        A_b, B_b, C_b = self.shaping.matrices()
        A = system.matrix()
        F = system.force_matrix(A)
        nz, nb, k = system.n_states, A_b.shape[0], system.n_dof
        Meff_inv = np.linalg.inv(system.effective_mass())
        Ac = np.zeros((nz + nb, nz + nb))
        Ac[:nz, :nz] = A
        Ac[k : 2 * k, nz:] = Meff_inv @ C_b  # the buffeting force in the q'' rows
        Ac[nz:, nz:] = A_b
        G = np.zeros((nz + nb, k))
        G[nz:] = B_b
        # Recorded force = self-excited (its added mass sees the buffeting-driven q'') + buffeting.
        force = np.hstack([F, self.section.mass_matrix() @ Meff_inv @ C_b])
        scale = coordinate_scales(k, self.section.B)
        C = np.zeros((2 * k, nz + nb))
        C[displacement_channels(k), :k] = np.diag(scale)
        C[force_channels(k)] = force / scale[:, None]
        return Ac, G, C

    @property
    def n_states(self) -> int:
        """Number of states: the aeroelastic ones and the shaping filter's."""
        return int(self.Phi.shape[0])

    def initial_state(self, h0: float, alpha0: float, p0: float = 0.0) -> FloatArray:
        """Mean state at a release from rest at ``h0`` (m), ``alpha0`` (rad) (and ``p0``, m).

        The lag states and ``x_b`` are zero.
        """
        x0 = np.zeros(self.n_states)
        x0[0] = v.finite("h0", h0) / self.section.B
        x0[1] = v.finite("alpha0", alpha0)
        if self.section.n_dof == 3:
            x0[2] = v.finite("p0", p0) / self.section.B
        return x0

    def initial_covariance(self, extra: Any = None) -> FloatArray:
        """Covariance of the state at the release, shape (n_x, n_x).

        The shaping filter's states in their stationary distribution, the structure's known
        exactly, plus ``extra`` (n_x, n_x) when given (e.g. the release position known only to
        the sensor noise: ``(sigma_h / B)^2`` and ``sigma_alpha^2`` on the first two diagonals).
        """
        P0 = np.zeros((self.n_states, self.n_states))
        P_b = self.shaping.stationary_covariance()
        P0[-P_b.shape[0]:, -P_b.shape[0]:] = P_b
        if extra is not None:
            P0 = P0 + _covariance("extra", extra, self.n_states)
        return P0

    def sample(self, x0: Any, P0: Any, n: int, rng: np.random.Generator) -> FloatArray:
        """Draw a record ``y`` (n, 2 n_dof) from the discrete model, ``x(0) ~ N(x0, P0)``."""
        x = rng.multivariate_normal(_vector("x0", x0, self.n_states),
                                    _covariance("P0", P0, self.n_states), method="eigh")
        w = rng.multivariate_normal(np.zeros(self.n_states), self.Qd, size=n, method="eigh")
        n_y = self.C.shape[0]
        y = np.empty((n, n_y))
        for k in range(n):
            y[k] = self.C @ x
            x = self.Phi @ x + w[k]
        return y + rng.standard_normal((n, n_y)) * self.noise_std


def discretise(Ac: FloatArray, G: FloatArray, T: float) -> tuple[FloatArray, FloatArray]:
    """Return ``(Phi, Qd)`` of ``x' = Ac x + G w`` (``w`` unit white noise) over ``T`` s.

    Van Loan: one matrix exponential gives the transition ``Phi = expm(Ac T)`` and the exact
    process-noise covariance ``Qd`` over the interval (symmetrised).
    """
    n = Ac.shape[0]
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n], M[:n, n:], M[n:, n:] = -Ac, G @ G.T, Ac.T
    E = scipy.linalg.expm(M * T)
    Phi = E[n:, n:].T
    Qd = Phi @ E[:n, n:]
    return Phi, 0.5 * (Qd + Qd.T)


def block_means(Phi: FloatArray, Qd: FloatArray, C: FloatArray, m: int
                ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Return the exact model of the means of blocks of ``m`` samples.

    With ``x_{j+1} = Phi x_j + w_j`` (``w ~ N(0, Qd)``) on the fine grid and the block mean
    ``s_k = 1/m sum_{j<m} x_{km+j}``, the block-rate model is

        x_{k+1} = Phi^m x_k + w_k,      mean of C x over block k = H x_k + C eta_k,

    with ``H = C Gamma``, ``Gamma = 1/m sum_{j<m} Phi^j``, and ``eta_k`` the process noise
    averaged within the block, which is correlated with ``w_k``: ``eta_k = 1/m sum_{i<m-1}
    Psi_i w_{km+i}``, ``Psi_i = sum_{l <= m-2-i} Phi^l``. Treating a block mean as a sample
    of the state (``H = C``, no ``eta``) misplaces the buffeting-driven part of every channel
    by a fraction of a block, the more so the broader its spectrum.

    Returns
    -------
    Phi_m, Qd_m : ndarray, shape (n_x, n_x)
        Transition and process-noise covariance over one block.
    H : ndarray, shape (n_y, n_x)
        Output matrix of the block means.
    R_eta : ndarray, shape (n_y, n_y)
        Covariance of ``C eta_k`` (add the block-mean sensor noise's for the output noise).
    M : ndarray, shape (n_x, n_y)
        Cross-covariance ``E[w_k (C eta_k)^T]``.
    """
    n = Phi.shape[0]
    if m == 1:  # samples as they are (the fit's default): nothing to average
        return Phi, 0.5 * (Qd + Qd.T), C, np.zeros((C.shape[0],) * 2), np.zeros((n, C.shape[0]))
    powers = np.empty((m, n, n))  # Phi^0 .. Phi^(m-1)
    powers[0] = np.eye(n)
    for j in range(1, m):
        powers[j] = Phi @ powers[j - 1]
    partial = np.cumsum(powers, axis=0)  # partial[j] = sum of Phi^0 .. Phi^j
    Gamma = partial[-1] / m
    Phi_m = Phi @ powers[-1]
    Qd_m, eta, cross = np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n))
    for i in range(m):
        to_end = powers[m - 1 - i]  # Phi^(m-1-i): w_i's part of x_{k+1}
        Qd_m += to_end @ Qd @ to_end.T
        if i < m - 1:
            Psi = partial[m - 2 - i] / m  # w_i's part of the block mean
            eta += Psi @ Qd @ Psi.T
            cross += to_end @ Qd @ Psi.T
    return (Phi_m, 0.5 * (Qd_m + Qd_m.T), C @ Gamma, C @ (0.5 * (eta + eta.T)) @ C.T,
            cross @ C.T)


@dataclass(frozen=True, eq=False)
class InnovationsResult:
    """What the Kalman filter gives a record.

    Attributes
    ----------
    log_likelihood : float
        Exact Gaussian log-likelihood of the observed samples.
    innovations : ndarray, shape (n, n_y)
        ``e_k = y_k - C x_{k|k-1}`` in the channels' units; NaN where a sample is missing.
    standardized : ndarray, shape (n, n_y)
        ``chol(S_k)^-1 e_k`` over the observed channels (white, unit variance if the model is
        right: for a whiteness check); NaN where missing.
    predictions : ndarray, shape (n, n_y)
        One-step predictions ``C x_{k|k-1}`` of every channel.
    """

    log_likelihood: float
    innovations: FloatArray
    standardized: FloatArray
    predictions: FloatArray


def kalman_filter(model: ReleaseModel, y: Any, x0: Any, P0: Any = None, *,
                  steady_tol: float = 1e-14) -> InnovationsResult:
    """Run the Kalman filter over a record and return its innovations and log-likelihood.

    ``log L = sum_k -1/2 (m_k log 2 pi + log det S_k + e_k^T S_k^-1 e_k)`` with ``m_k`` the
    channels observed at sample ``k``; ``S_k`` is factored by Cholesky and the covariance is
    updated in Joseph form, so it stays symmetric positive semi-definite. The covariance does
    not depend on the data: once its prediction changes by less than ``steady_tol`` (relative,
    max norm) over a fully observed sample, the gain is held (the steady-state filter) until a
    sample with a missing channel, and the record's stretch is filtered in one vectorised pass.

    Parameters
    ----------
    model : ReleaseModel
        The discrete model; ``y`` is on its sample grid.
    y : array_like, shape (n, n_y)
        ``[h, alpha, lift, moment]`` (m, rad, N/m, N m/m), with sway then ``[p, drag]`` (m,
        N/m); the first row at the release. NaN marks
        a missing sample: that channel's update is skipped at that sample.
    x0 : array_like, shape (n_x,)
        Mean state at the first sample (:meth:`ReleaseModel.initial_state`).
    P0 : array_like, shape (n_x, n_x), optional
        Its covariance; default :meth:`ReleaseModel.initial_covariance` (the shaping filter
        stationary, the release position exact).
    steady_tol : float, optional
        Relative change of the predicted covariance below which the gain is held; 0 never holds
        it. At the default 1e-14 the log-likelihood of a 20 s record at 500 Hz moves by 1e-10 to
        4e-10 against the full recursion (5e-8 with a burst of missing samples mid-record), of
        about 2e5.

    Returns
    -------
    InnovationsResult

    Raises
    ------
    ValueError
        On a ``y`` of the wrong shape or with infinite values, a non-finite ``x0`` or ``P0``, or an
        innovation covariance that is not positive definite (zero sensor noise on a channel the
        state determines exactly).
    """
    y_arr = np.asarray(y, dtype=float)
    n_y = model.C.shape[0]
    if y_arr.ndim != 2 or y_arr.shape[1] != n_y or y_arr.shape[0] < 1:
        names = "h, alpha, lift, moment" + (", p, drag" if n_y == 6 else "")
        raise ValueError(f"y must have shape (n, {n_y}) ({names}), got {y_arr.shape}")
    if np.any(np.isinf(y_arr)):
        raise ValueError("y contains infinite values (NaN marks a missing sample; inf is an error)")
    steady_tol = v.finite("steady_tol", steady_tol)
    n_x = model.n_states
    x = _vector("x0", x0, n_x).copy()
    P = model.initial_covariance() if P0 is None else _covariance("P0", P0, n_x)
    Phi, Qd, C, R = model.Phi, model.Qd, model.C, model.R
    observed = ~np.isnan(y_arr)
    full_rows = observed.all(axis=1)
    n = y_arr.shape[0]
    innovations = np.full((n, n_y), np.nan)
    standardized = np.full((n, n_y), np.nan)
    predictions = np.empty((n, n_y))
    eye = np.eye(n_x)
    log_l = 0.0
    held: tuple[FloatArray, FloatArray, float] | None = None  # gain, chol(S)^-1, log det S
    k = 0
    while k < n:
        if held is not None and full_rows[k]:
            stop = k + int(np.argmin(full_rows[k:])) if not full_rows[k:].all() else n
            x, log_l_part = _steady_stretch(model, y_arr[k:stop], x, held,
                                            predictions[k:stop], innovations[k:stop],
                                            standardized[k:stop])
            log_l += log_l_part
            k = stop
            continue
        predictions[k] = C @ x
        rows = observed[k]
        P_pred = P
        if rows.any():
            full = bool(full_rows[k])
            H = C if full else C[rows]
            R_k = R if full else R[np.ix_(rows, rows)]
            e = y_arr[k, rows] - predictions[k, rows]
            PHt = P @ H.T
            try:
                chol = np.linalg.cholesky(H @ PHt + R_k)
            except np.linalg.LinAlgError as exc:
                raise ValueError(
                    f"the innovation covariance at sample {k} is not positive definite: give "
                    "sensor noise > 0 on channels the state determines exactly") from exc
            # Plain numpy on these 4x4 blocks: scipy's wrappers cost more than the algebra here.
            chol_inv = np.linalg.inv(chol)
            u = chol_inv @ e
            log_det = 2.0 * float(np.log(np.diag(chol)).sum())
            log_l -= 0.5 * (e.size * LOG_2PI + log_det + float(u @ u))
            innovations[k, rows], standardized[k, rows] = e, u
            # K = P H^T S^-1 through the factor; Joseph form keeps P symmetric and PSD.
            K = PHt @ (chol_inv.T @ chol_inv)
            x = x + K @ e
            IKH = eye - K @ H
            P = IKH @ P @ IKH.T + K @ R_k @ K.T
        x = Phi @ x
        P = Phi @ P @ Phi.T + Qd
        held = None
        if full_rows[k] and steady_tol > 0.0:
            if np.abs(P - P_pred).max() <= steady_tol * np.abs(P).max():
                held = (K, chol_inv, log_det)
        k += 1
    return InnovationsResult(log_l, innovations, standardized, predictions)


def _steady_stretch(model: ReleaseModel, y: FloatArray, x: FloatArray,
                    held: tuple[FloatArray, FloatArray, float], predictions: FloatArray,
                    innovations: FloatArray, standardized: FloatArray) -> tuple[FloatArray, float]:
    """Filter fully observed samples with a held gain; fill the output slices in place.

    Returns the predicted state after the stretch and the stretch's log-likelihood.
    """
    K, chol_inv, log_det = held
    Phi, C = model.Phi, model.C
    # The one-step predictor x+ = Phi (I - K C) x + Phi K y: a loop of two small products.
    A_cl, B_cl = Phi - Phi @ K @ C, Phi @ K
    drive = y @ B_cl.T
    states = np.empty((y.shape[0], x.size))
    for i in range(y.shape[0]):
        states[i] = x
        x = A_cl @ x + drive[i]
    predictions[:] = states @ C.T
    innovations[:] = y - predictions
    standardized[:] = innovations @ chol_inv.T
    log_l = -0.5 * (y.shape[0] * (4 * LOG_2PI + log_det) + float(np.sum(standardized**2)))
    return x, log_l


def log_likelihood(model: ReleaseModel, y: Any, x0: Any, P0: Any = None) -> float:
    """Exact Gaussian log-likelihood of a record (:func:`kalman_filter`'s, alone)."""
    return kalman_filter(model, y, x0, P0).log_likelihood


def _vector(name: str, value: Any, n: int) -> FloatArray:
    """Check a state vector: finite, shape (n,)."""
    arr = v.finite_array(name, value, ndim=1)
    if arr.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},) (the model's states), got {arr.shape}")
    return arr


def _covariance(name: str, value: Any, n: int) -> FloatArray:
    """Check a state covariance: finite, symmetric, shape (n, n)."""
    arr = v.finite_array(name, value, ndim=2)
    if arr.shape != (n, n):
        raise ValueError(f"{name} must have shape ({n}, {n}) (the model's states), got "
                         f"{arr.shape}")
    if not np.allclose(arr, arr.T, rtol=1e-12, atol=0.0):
        raise ValueError(f"{name} must be symmetric")
    return arr
