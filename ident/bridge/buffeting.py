"""Buffeting of a full bridge in the frequency domain: modal gust forces, response spectra, RMS.

Strip theory on the still-air modes (shared DESIGN, "Full-bridge flutter and buffeting"; signs of
``docs/reference/conventions.md``: h and L down, alpha and M nose-up, p and D downwind, gust ``w``
up).

**Gust forces per unit span.** At a deck node, the quasi-steady buffeting forces of
:func:`ident.physics.turbulence.buffeting_gain` (derived there from the relative wind; the same
linearisation as the self-excited quasi-steady terms of :mod:`ident.model.quasi_steady`)::

    L_b = qd B   [2 C_L u/U + (dC_L - C_D) w/U]
    M_b = qd B^2 [2 C_M u/U + dC_M w/U]
    D_b = qd B   [2 C_D u/U + (dC_D + C_L) w/U]

In short: the relative wind ``(U + u)`` downwind and ``w`` up has ``|V|^2 ~ U^2 (1 + 2 u/U)``
and meets the deck at a nose-up angle larger by ``phi = w/U``; lift and drag in wind axes
(``qd (1 + 2 u/U) B (C + dC phi)``) turned back by ``phi`` into the fixed axes (down and
downwind: ``L = L_w - D_w phi``, ``D = D_w + L_w phi``) give the lines above to first order;
i.e. ``[L_b B, M_b, D_b B] = (qd B^2 / U) g [u, w]`` with ``g = [[2 C_L, dC_L - C_D],
[2 C_M, dC_M], [2 C_D, dC_D + C_L]]``. (For a flat plate, ``C_* = 0``, ``dC_L = -2 pi``: an
upward gust ``w > 0`` lifts the plate, ``L_b < 0``, and pitches it nose-up, ``M_b > 0``.) The
admittance ``chi(f)`` multiplies the amplitude of each (the spectrum by ``chi^2``).

**On the modes.** With the generalised shapes ``Phi(x) = [h/B, alpha, p/B]`` per unit modal
coordinate (3 x n_modes) and strip widths ``w_k`` (trapezoid rule over the nodes), the modal
buffeting force is ``F = sum_k w_k Phi_k^T [L_b B, M_b, D_b B]_k`` (``h L + alpha M + p D``
integrated along the deck: :meth:`ident.bridge.model.BridgeModel.load_matrix`). u and w are
independent; each has the coherence
``exp(-C f |x_k - x_l| / U)`` between nodes, so the one-sided cross-spectral matrix of ``F`` is::

    S_F(f) = (qd B^2 / U)^2 chi(f)^2 sum_{c = u, w} S_c(f) P_c Coh_c(f) P_c^T,
    P_c[i, k] = w_k Phi_k[:, i] . g[:, c]

``P Coh P^T`` is evaluated in O(nodes) per frequency: the exponential coherence of sorted nodes
is a product of the neighbours' coherences, so ``Coh P^T`` is a forward and a backward recursion.

**Response.** The modal equations with the self-excited forces (Roger's form projected,
:class:`~ident.bridge.statespace.BridgeStateSpace`) give the transfer matrix at
``omega = 2 pi f``, ``K = B omega / U``::

    H(omega) = [-omega^2 M + i omega C + K_s - qd B^2 Qbar(iK)]^-1,
    Qbar(p) = sum_k w_k Phi_k^T Q(p) Phi_k

and ``S_xi = H S_F H^H``; the response at a node is ``r = B Phi_k[0] xi`` (h), ``Phi_k[1] xi``
(alpha), ``B Phi_k[2] xi`` (p). The RMS come from the modal covariance ``Re int S_xi df``. The
frequency grid is a logarithmic base grid plus points packed around every in-wind pole of the
state-space model (``f_d + gamma tan(theta)``, theta uniform, ``gamma`` the pole's half-power
half-width in Hz), so that lightly damped peaks are integrated accurately without a huge grid.

**Two routes to the same sums.** ``route="direct"`` evaluates the lines above at every
frequency of the grid (the reference: 107 s for 200 modes at 1000 nodes). The default
``route="eigen"`` (:mod:`ident.bridge.buffeting_eigen`) forms no matrix per frequency: ``H``
from one eigen decomposition of the state space, the products of poles in partial fractions,
the load matrix splined in frequency; on the same grid its RMS are within 1e-5 of the direct
route's (10.7 s, 1.9 s without spectra, on the same deck and host), and it is checked
against a direct inverse at the sharpest peaks before it is used.

Not responsible for: the time-domain simulation (:mod:`ident.bridge.buffeting_time`), reading
the wind file (:mod:`ident.bridge.wind`), plots (:mod:`daq.offline.bridge_plots`).

References
----------
A. G. Davenport, "Buffeting of a suspension bridge by storm winds", J. Struct. Div. ASCE 88, 1962.
R. H. Scanlan, "The action of flexible bridges under wind, II: buffeting theory", J. Sound Vib. 60,
1978. J. S. Bendat and A. G. Piersol, "Random Data", 4th ed., Wiley, 2010 (random error of a
variance estimate).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ident.bridge import buffeting_eigen as eigen_route
from ident.bridge.model import BridgeModel
from ident.bridge.statespace import BridgeStateSpace
from ident.model.quasi_steady import StaticCoefficients
from ident.numerics import validate as v
from ident.numerics.quadrature import trapezoid_weights
from ident.numerics.threads import single_threaded_blas
from ident.physics.turbulence import TurbulenceSpec, buffeting_gain

__all__ = [
    "BuffetingResponse",
    "eigen_mismatch",
    "frequency_domain",
    "frequency_grid",
    "gust_gain",
    "impedance",
    "modal_force_spectrum",
    "modal_gust_projection",
    "physical_shapes",
    "transfer_matrix",
]

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]

#: Bytes a frequency chunk may use for its largest temporary array.
_CHUNK_BYTES = 64 * 2**20
#: Points packed around each in-wind pole of the frequency grid.
_POLE_POINTS = 24


def gust_gain(static: StaticCoefficients) -> FloatArray:
    """Non-dimensional gains ``g`` with ``[L_b B, M_b, D_b B] = (qd B^2 / U) g [u, w]``.

    Shape (3, 2): rows L, M, D; columns u (downwind), w (upward). Windrig's signs (see the
    module docstring); the same matrix as :func:`ident.physics.turbulence.buffeting_gain` without
    the factor ``qd B^2 / U``.
    """
    # One linearisation for section and bridge: ident.physics.turbulence's gain at U = 1 m/s, B = 1
    # m, rho = 2 kg/m^3, where its factor qd B^2 / U is 1.
    return buffeting_gain(static, 1.0, 1.0, 2.0)


def _static(bridge: BridgeModel) -> StaticCoefficients:
    if bridge.static is None:
        raise ValueError(f"bridge {bridge.name!r} has no static coefficients (key static: C_D, "
                         f"C_L, C_M, dC_D, dC_L, dC_M): buffeting needs them")
    return bridge.static


def modal_gust_projection(bridge: BridgeModel) -> FloatArray:
    """Return ``P[c, i, k] = w_k Phi_k[:, i] . g[:, c]`` (m): node k's gust c on mode i.

    Shape (2, n_modes, nodes).

    Multiplied by ``qd B^2 / U`` and the gust (m/s) at node k it is the contribution of that
    node's strip to the modal force of mode i. Needs the bridge's static coefficients.
    """
    g = gust_gain(_static(bridge))
    per_span = g / np.array([bridge.B, 1.0, bridge.B])[:, None]  # [L, M, D] over qd B^2 / U
    return np.einsum("ika,ac->cik", bridge.load_matrix(), per_span)


def _coherent_quadratic(P: FloatArray, x: FloatArray, decay: FloatArray) -> FloatArray:
    """``P Coh(f) P^T`` for ``Coh_kl = exp(-decay(f) |x_k - x_l|)``, shape (nf, n, n).

    ``P`` is (n, nodes) with ``x`` increasing; ``decay`` (1/m) is ``C f / U`` at each frequency.
    The forward sum ``a_k = P_k + r_k a_{k-1}`` and the backward one (``r_k`` the coherence of
    neighbours) give ``(Coh P^T)_k`` without forming the nodes x nodes matrix.
    """
    n, nodes = P.shape
    nf = decay.size
    if nodes == 1 or not np.any(decay > 0.0):
        total = P.sum(axis=1)  # fully coherent (or one node): Coh is all ones
        return np.broadcast_to(np.outer(total, total), (nf, n, n)).copy()
    dx = np.diff(x)
    out = np.empty((nf, n, n))
    chunk = max(1, _CHUNK_BYTES // (8 * nodes * n))
    for start in range(0, nf, chunk):
        sl = slice(start, min(nf, start + chunk))
        r = np.exp(-decay[sl, None] * dx[None, :])  # (m, nodes - 1)
        Y = np.empty((r.shape[0], nodes, n))
        Y[:, 0] = P[:, 0]
        for k in range(1, nodes):
            Y[:, k] = P[:, k] + r[:, k - 1, None] * Y[:, k - 1]
        back = np.zeros((r.shape[0], n))
        for k in range(nodes - 2, -1, -1):
            back = r[:, k, None] * (P[:, k + 1] + back)
            Y[:, k] += back
        out[sl] = P @ Y  # (n, nodes) @ (m, nodes, n)
    return out


def modal_force_spectrum(bridge: BridgeModel, spec: TurbulenceSpec, U: float,
                         f: Any) -> FloatArray:
    """One-sided cross-spectral matrix of the modal buffeting forces, shape (nf, n, n).

    Parameters
    ----------
    bridge : BridgeModel
        Deck nodes, modes and static coefficients.
    spec : TurbulenceSpec
        Gust statistics, coherence and admittance.
    U : float
        Mean wind speed, m/s, > 0.
    f : array_like, shape (nf,)
        Frequencies, Hz, >= 0.

    Returns
    -------
    ndarray
        ``S_F(f)`` in (modal force)^2 per Hz (N^2 m^2 per Hz for shapes in m and rad); real:
        each gust is in phase with its force and the coherence is real.
    """
    U = v.positive("U", U)
    f_arr = np.atleast_1d(np.asarray(f, dtype=float))
    P = modal_gust_projection(bridge)
    S_u, S_w = spec.gust_spectra(f_arr, U)
    chi2 = spec.admittance_squared(f_arr, U, bridge.B)
    scale = (0.5 * bridge.rho * U**2 * bridge.B**2 / U) ** 2
    out = np.zeros((f_arr.size, bridge.n_modes, bridge.n_modes))
    for c, (S_c, C) in enumerate(((S_u, spec.Cuy), (S_w, spec.Cwy))):
        if not np.any(P[c]) or not np.any(S_c):
            continue  # no gain (e.g. u on a flat plate) or no turbulence of this kind
        quad = _coherent_quadratic(P[c], bridge.nodes_x, C * f_arr / U)
        out += (scale * S_c * chi2)[:, None, None] * quad
    return out


def impedance(ss: BridgeStateSpace, U: float, f: Any) -> ComplexArray:
    """``-omega^2 M + i omega C + K - qd B^2 Qbar(iK)`` at frequencies ``f`` (Hz), (nf, n, n).

    ``Qbar`` is the section's ``Q(iK)`` projected on the modes
    (:meth:`~ident.bridge.model.BridgeModel.modal_coefficients`), ``K = 2 pi f B / U``; at
    ``U = 0`` only the added mass ``-rho/2 B^4 A3`` is left of it.
    """
    U = v.finite("U", U)
    bridge, model = ss.bridge, ss.model
    omega = 2.0 * np.pi * np.atleast_1d(np.asarray(f, dtype=float))
    n, k = bridge.n_modes, model.n_dof
    if U <= 0.0:
        Z = (omega[:, None, None] ** 2 * (0.5 * bridge.rho * bridge.B**4 * ss.modal_A[2])
             ).astype(complex)
    else:
        # Qbar = sum_ij Q_ij G_ij as one product (nf, k^2) @ (k^2, n^2): BLAS, not einsum.
        Q = model.Q(1j * omega * bridge.B / U).reshape(omega.size, k * k)
        G = bridge.shape_integrals()[:k, :k].reshape(k * k, n * n)
        Z = (-0.5 * bridge.rho * U**2 * bridge.B**2 * (Q @ G)).reshape(omega.size, n, n)
    # The modal structure is diagonal: add it on the diagonal only.
    idx = np.arange(n)
    m, c, s = (np.diag(a) for a in (ss.mass, bridge.damping_matrix(),
                                     bridge.stiffness_matrix()))
    Z[:, idx, idx] += -omega[:, None] ** 2 * m + 1j * omega[:, None] * c + s
    return np.asarray(Z, dtype=complex)


def transfer_matrix(ss: BridgeStateSpace, U: float, f: Any) -> ComplexArray:
    """Aeroelastic transfer matrix ``H`` from modal force to modal coordinate, shape (nf, n, n).

    ``H = [-omega^2 M + i omega C + K - qd B^2 Qbar(iK)]^-1`` (:func:`impedance`); ``U >= 0``.
    """
    return np.asarray(np.linalg.inv(impedance(ss, U, f)), dtype=complex)


def frequency_grid(ss: BridgeStateSpace, U: float, *, f_max: float | None = None,
                   per_decade: int = 120, pole_points: int = _POLE_POINTS) -> FloatArray:
    """Frequencies (Hz, sorted, from 0) that resolve every resonance of the bridge at ``U``.

    A logarithmic grid from ``f_1 / 1000`` to ``f_max`` (default ten times the highest in-wind
    modal frequency) with ``per_decade`` points, plus ``pole_points`` points around each
    oscillatory pole ``-sigma + i omega_d`` of the state matrix, at
    ``omega_d / 2 pi + (sigma / 2 pi) tan(theta)`` with theta uniform in (-1.55, 1.55): a
    Lorentzian peak is then sampled evenly in its own angle, whatever its width (in theta a
    Lorentzian is constant, so few points integrate it). Against a 200 000-point grid the default
    RMS differ by at most 0.3 % on the IABSE deck and the tests' four-mode deck. The integrals
    are trapezoid sums in ``f``, not in theta, so a very lightly damped peak is overestimated:
    a single mode's RMS by up to 0.8 % at 0.6 % total damping, 2.5 % at 0.12 %
    (``docs/guides/buffeting.md``); ``pole_points=96`` keeps it under 0.4 %.
    """
    return _grid_from_poles(ss, ss.eigenvalues(U), f_max=f_max, per_decade=per_decade,
                            pole_points=pole_points)


def _grid_from_poles(ss: BridgeStateSpace, lam: ComplexArray, *, f_max: float | None = None,
                     per_decade: int = 120, pole_points: int = _POLE_POINTS) -> FloatArray:
    """:func:`frequency_grid` from the state matrix's eigenvalues ``lam`` (1/s) at ``U``."""
    osc = lam[lam.imag > 1e-9 * max(1.0, float(np.abs(lam).max()))]
    f_d = osc.imag / (2.0 * np.pi)
    gamma = np.maximum(-osc.real, 1e-6 * osc.imag) / (2.0 * np.pi)
    f_modes = ss.bridge.frequencies
    f_top = float(max(f_d.max(initial=0.0), f_modes.max()))
    f_hi = 10.0 * f_top if f_max is None else v.positive("f_max", f_max)
    f_lo = 1e-3 * float(f_modes.min())
    n_base = max(16, int(per_decade * np.log10(f_hi / f_lo)))
    theta = np.linspace(-1.55, 1.55, pole_points)
    packed = (f_d[:, None] + gamma[:, None] * np.tan(theta)[None, :]).ravel()
    grid = np.concatenate([[0.0], np.geomspace(f_lo, f_hi, n_base),
                           packed[(packed > 0.0) & (packed < f_hi)]])
    return np.unique(grid)


@dataclass(frozen=True, eq=False)
class BuffetingResponse:
    """RMS buffeting response along the deck at one mean wind speed.

    Attributes
    ----------
    U : float
        Mean wind speed, m/s.
    x : ndarray, shape (nodes,)
        Deck nodes, m.
    rms_h, rms_alpha, rms_p : ndarray, shape (nodes,)
        RMS heave (m), pitch (rad) and sway (m) at the nodes.
    method : str
        ``"frequency"`` or ``"time"``.
    f : ndarray, shape (nf,)
        Frequencies of :attr:`spectra`, Hz (frequency domain; empty for a time record without
        spectra).
    spectrum_nodes : ndarray of int
        Node indices whose one-sided response spectra are in :attr:`spectra`.
    spectra : dict of str to ndarray
        ``"h"`` (m^2/Hz), ``"alpha"`` (rad^2/Hz), ``"p"`` (m^2/Hz): shape (nf, len(spectrum_nodes)).
    correlation_time : dict of str to ndarray
        Frequency domain only: ``T_c = int S^2 df / (int S df)^2`` (s) of each component at the
        spectrum nodes; a record of length T estimates the RMS with relative standard deviation
        ``0.5 sqrt(T_c / T)`` (:meth:`rms_relative_std`).
    duration : float
        Time domain only: length of the record the RMS come from, s (0 for the frequency domain).
    rms_modal : ndarray, shape (n_modes,)
        RMS of each modal (generalised) coordinate, in the unit its mode's shapes are scaled by
        (the square roots of the modal covariance's diagonal): the response mode by mode, which
        no node's h, alpha or p shows alone where modes share a node.
    modal_spectra : ndarray, shape (nf, n_modes)
        Frequency domain only: each modal coordinate's one-sided auto-spectrum (unit^2/Hz).
    modal_correlation_time : ndarray, shape (n_modes,)
        Frequency domain only: ``T_c`` (s) of each modal coordinate
        (:meth:`rms_modal_relative_std`).
    route : str
        Frequency domain only: how the response was computed, ``"eigen"`` (one eigen
        decomposition, :mod:`ident.bridge.buffeting_eigen`) or ``"direct"`` (one inverse per
        frequency); empty for the time domain.
    """

    U: float
    x: FloatArray
    rms_h: FloatArray
    rms_alpha: FloatArray
    rms_p: FloatArray
    method: str
    f: FloatArray = field(default_factory=lambda: np.zeros(0))
    spectrum_nodes: npt.NDArray[np.int64] = field(
        default_factory=lambda: np.zeros(0, dtype=np.int64))
    spectra: dict[str, FloatArray] = field(default_factory=dict)
    correlation_time: dict[str, FloatArray] = field(default_factory=dict)
    duration: float = 0.0
    rms_modal: FloatArray = field(default_factory=lambda: np.zeros(0))
    modal_spectra: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    modal_correlation_time: FloatArray = field(default_factory=lambda: np.zeros(0))
    route: str = ""

    def rms_relative_std(self, duration: float) -> dict[str, FloatArray]:
        """Relative standard deviation of an RMS estimated from a record of ``duration`` s.

        For a zero-mean Gaussian response, the variance estimated from a record of length T
        (or one period of a periodic Gaussian-coefficient simulation) has variance
        ``(1/T) int S(f)^2 df`` (one-sided S; Bendat and Piersol's ``2/T int R^2 dtau``), so the
        RMS has relative standard deviation ``0.5 sqrt(T_c / T)`` with the correlation time
        ``T_c`` of :attr:`correlation_time`. Valid for T much longer than ``T_c``.

        Returns
        -------
        dict
            ``"h"``, ``"alpha"``, ``"p"``: arrays over :attr:`spectrum_nodes` (NaN where the
            response is zero).
        """
        T = v.positive("duration", duration)
        return {k: 0.5 * np.sqrt(tc / T) for k, tc in self.correlation_time.items()}

    def rms_modal_relative_std(self, duration: float) -> FloatArray:
        """Relative standard deviation of each modal RMS from a record of ``duration`` s.

        The same estimate as :meth:`rms_relative_std`, ``0.5 sqrt(T_c / T)``, with each modal
        coordinate's correlation time (:attr:`modal_correlation_time`); shape (n_modes,), NaN
        for a mode the wind does not move.
        """
        T = v.positive("duration", duration)
        return np.asarray(0.5 * np.sqrt(self.modal_correlation_time / T), dtype=float)

    def to_dict(self) -> dict[str, Any]:
        """Return ``{"U", "x", "rms_h", "rms_alpha", "rms_p"}`` as DESIGN's JSON (m/s, m, rad)."""
        return {"U": float(self.U), "x": self.x.tolist(), "rms_h": self.rms_h.tolist(),
                "rms_alpha": self.rms_alpha.tolist(), "rms_p": self.rms_p.tolist()}


def _default_spectrum_nodes(n_nodes: int, count: int = 25) -> npt.NDArray[np.int64]:
    if n_nodes <= count:
        return np.arange(n_nodes)
    return np.unique(np.round(np.linspace(0, n_nodes - 1, count)).astype(np.int64))


@single_threaded_blas
def frequency_domain(ss: BridgeStateSpace, spec: TurbulenceSpec, U: float, *,
                     f: Any | None = None,
                     spectrum_nodes: Sequence[int] | None = None,
                     route: str = "eigen", spectra: bool = True) -> BuffetingResponse:
    """Buffeting response of the bridge at mean speed ``U`` in the frequency domain.

    Parameters
    ----------
    ss : BridgeStateSpace
        The bridge (modes, structure, static coefficients) with the section's self-excited
        forces projected on its modes.
    spec : TurbulenceSpec
        The wind (:func:`ident.bridge.wind.read_wind`).
    U : float
        Mean wind speed, m/s, > 0; below the flutter speed (above it there is no stationary
        response and a ``ValueError`` says so).
    f : array_like, optional
        Frequency grid, Hz (default :func:`frequency_grid`); integrals by the trapezoid rule.
    spectrum_nodes : sequence of int, optional
        Nodes whose response spectra to keep (default: all nodes up to 25, else 25 spread
        along the deck).
    route : {"eigen", "direct"}
        ``"eigen"`` (default): one eigen decomposition of the state space and the load
        matrices splined in frequency (:mod:`ident.bridge.buffeting_eigen`; RMS within a few
        1e-6 of the direct route), falling back to ``"direct"`` if its certificate fails;
        ``"direct"``: an inverse and the exact load matrix at every frequency (the reference).
        :attr:`BuffetingResponse.route` says which one ran.
    spectra : bool
        Compute the response spectra (modal and at ``spectrum_nodes``) and their correlation
        times (default). Without them (``False``) only the RMS and the modal RMS are returned,
        several times faster on the eigen route; ``spectra``, ``correlation_time``,
        ``modal_spectra`` and ``modal_correlation_time`` are then empty.

    Returns
    -------
    BuffetingResponse
        RMS at every node, spectra and correlation times at ``spectrum_nodes``.

    Notes
    -----
    BLAS runs single-threaded here (:mod:`ident.numerics.threads`): the many small matrix products
    per frequency ran 10 to 40 times slower with OpenBLAS's threads on the shared two-core host.
    """
    U = v.positive("U", U)
    if route not in ("eigen", "direct"):
        raise ValueError(f"route must be 'eigen' or 'direct', got {route!r}")
    bridge = ss.bridge
    _static(bridge)
    if route == "eigen":
        lam, vec = ss.eig(U)
    else:
        lam, vec = ss.eigenvalues(U), None
    if np.any(lam.real >= 0.0):
        raise ValueError(f"U = {U:g} m/s is at or above the flutter speed (an eigenvalue has "
                         f"real part {float(lam.real.max()):.3g} 1/s >= 0): no stationary "
                         f"buffeting response")
    f_arr = _grid_from_poles(ss, lam) if f is None else np.asarray(f, dtype=float)
    if f_arr.ndim != 1 or f_arr.size < 2 or np.any(np.diff(f_arr) <= 0.0) or f_arr[0] < 0.0:
        raise ValueError("f must be an increasing 1-D grid of at least 2 frequencies >= 0 Hz")
    nodes = (_default_spectrum_nodes(bridge.n_nodes) if spectrum_nodes is None
             else np.asarray(spectrum_nodes, dtype=np.int64))
    n = bridge.n_modes
    # Response components at the chosen nodes: rows of the physical shapes (m or rad per unit
    # modal coordinate).
    phys = physical_shapes(bridge)  # (nodes, 3, n)
    sel_rows = np.ascontiguousarray(phys[nodes].reshape(-1, n))  # (s 3, n): node-major rows
    weights = trapezoid_weights(f_arr)
    result = None
    if vec is not None:
        result = _eigen_route(ss, spec, U, lam, vec, f_arr, weights,
                              sel_rows if spectra else None)
    if result is not None:
        cov, modal_spectra, node_spectra = result
        used = "eigen"
    else:
        cov, modal_spectra, node_spectra = _direct_route(ss, spec, U, f_arr, weights, sel_rows)
        used = "direct"
    variance = np.einsum("kai,ij,kaj->ka", phys, cov, phys)
    rms = np.sqrt(np.maximum(variance, 0.0))
    names = ("h", "alpha", "p")
    common: dict[str, Any] = {
        "U": U, "x": np.array(bridge.nodes_x), "rms_h": rms[:, 0], "rms_alpha": rms[:, 1],
        "rms_p": rms[:, 2], "method": "frequency", "f": f_arr, "spectrum_nodes": nodes,
        "rms_modal": np.sqrt(np.maximum(np.diag(cov), 0.0)), "route": used}
    if not spectra or node_spectra is None or modal_spectra is None:
        return BuffetingResponse(**common)
    # (nf, 3 s) node-major rows to (nf, 3, s).
    spec_nodes = node_spectra.reshape(-1, nodes.size, 3).transpose(0, 2, 1)
    total = np.einsum("f,fas->as", weights, spec_nodes)
    square = np.einsum("f,fas->as", weights, spec_nodes**2)
    modal_total = weights @ modal_spectra
    modal_square = weights @ modal_spectra**2
    with np.errstate(invalid="ignore", divide="ignore"):
        t_c = np.where(total > 0.0, square / total**2, np.nan)
        t_c_modal = np.where(modal_total > 0.0, modal_square / modal_total**2, np.nan)
    return BuffetingResponse(
        **common,
        spectra={name: spec_nodes[:, a, :] for a, name in enumerate(names)},
        correlation_time={name: t_c[a] for a, name in enumerate(names)},
        modal_spectra=modal_spectra, modal_correlation_time=t_c_modal)


def eigen_mismatch(ss: BridgeStateSpace, spec: TurbulenceSpec, U: float, lam: ComplexArray,
                   vec: ComplexArray, f: FloatArray) -> float:
    """Return the eigen route's certificate: its modal spectra against the direct inverse's.

    At the three least damped poles' frequencies (the sharpest peaks, where an inaccurate
    decomposition shows first) and the median of the grid ``f`` (Hz): the largest relative
    difference of ``diag(H S_F H^H)`` (each mode against its own spectrum) with the eigen
    route's ``H`` (:func:`ident.bridge.buffeting_eigen.transfer_matrix`; ``lam``, ``vec`` from
    ``ss.eig(U)``) and with :func:`transfer_matrix`, the exact ``S_F`` in both.
    """
    osc = lam[lam.imag > 0.0]
    sharp = osc[np.argsort(-osc.real / np.abs(osc))[:3]]
    f_check = np.concatenate([sharp.imag / (2.0 * np.pi), [float(np.median(f))]])
    S_F = modal_force_spectrum(ss.bridge, spec, U, f_check)
    spectra = []
    for H in (transfer_matrix(ss, U, f_check),
              eigen_route.transfer_matrix(ss, lam, vec, f_check)):
        spectra.append(np.einsum("fij,fjk,fik->fi", H, S_F, H.conj()).real)
    direct, eigen = spectra
    floor = 1e-12 * np.max(direct, axis=1, keepdims=True)  # modes the wind does not move
    with np.errstate(invalid="ignore"):
        mismatch = np.abs(eigen - direct) / np.maximum(direct, floor)
    return float(np.nanmax(mismatch)) if np.any(direct > 0.0) else 0.0


#: Largest relative difference of the modal spectra by the eigen route's ``H`` and by the direct
#: inverse at the certificate's frequencies; measured 1e-12 on small decks and 2e-8 on the
#: 200-mode benchmark deck (its eigenvectors' condition number 2e11), against the 1e-3 asked of
#: the RMS.
_EIGEN_TOLERANCE = 1e-5


def _eigen_route(ss: BridgeStateSpace, spec: TurbulenceSpec, U: float, lam: ComplexArray,
                 vec: ComplexArray, f: FloatArray, weights: FloatArray,
                 sel_rows: FloatArray | None
                 ) -> tuple[FloatArray, FloatArray | None, FloatArray | None] | None:
    """Covariance, modal and node spectra by :mod:`ident.bridge.buffeting_eigen`.

    None when its certificate fails (the caller then takes the direct route).
    """
    bridge = ss.bridge
    if eigen_mismatch(ss, spec, U, lam, vec, f) > _EIGEN_TOLERANCE:
        return None
    P = modal_gust_projection(bridge)
    chi2 = spec.admittance_squared(f, U, bridge.B)
    scale = (0.5 * bridge.rho * U**2 * bridge.B**2 / U) ** 2
    decays = (spec.Cuy / U, spec.Cwy / U)  # the coherence's decay per Hz, s/m
    S_fine = spec.gust_spectra(f, U)
    active = [c for c in (0, 1) if np.any(P[c]) and np.any(S_fine[c])]  # gain and turbulence
    x = bridge.nodes_x
    loads: list[tuple[FloatArray, eigen_route.LoadBasis]] = []
    if bridge.n_nodes == 1 or all(decays[c] == 0.0 for c in active):
        # Fully coherent: each gust's load matrix is constant, one exact coefficient each.
        for c in active:
            Q = _coherent_quadratic(P[c], x, np.zeros(1))[0]
            loads.append((scale * chi2 * S_fine[c], eigen_route.constant_basis(Q, f.size)))
    elif active:
        def matrix(f_coarse: FloatArray) -> FloatArray:
            # M = sum_c (s_c / s) Q_c: the admittance and the factor cancel in the ratio.
            S = spec.gust_spectra(f_coarse, U)
            total = sum(S[c] for c in active)
            with np.errstate(invalid="ignore", divide="ignore"):
                ratios = [np.where(total > 0.0, S[c] / total, 0.0) for c in active]
            return np.asarray(sum(r[:, None, None] * _coherent_quadratic(P[c], x,
                                                                          decays[c] * f_coarse)
                                  for r, c in zip(ratios, active, strict=True)))

        s_total = np.asarray(scale * chi2 * sum(S_fine[c] for c in active), dtype=float)
        loads.append((s_total, eigen_route.load_basis(matrix, f)))
    n = bridge.n_modes
    rows = None if sel_rows is None else np.concatenate([np.eye(n), sel_rows])
    out = eigen_route.eigen_response(ss, lam, vec, f, weights, loads, rows)
    if out.spectra is None:
        return out.cov, None, None
    return out.cov, out.spectra[:, :n], out.spectra[:, n:]


def _direct_route(ss: BridgeStateSpace, spec: TurbulenceSpec, U: float, f_arr: FloatArray,
                  weights: FloatArray, sel_rows: FloatArray
                  ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Covariance, modal and node spectra (nf, 3 s) with an inverse at every frequency."""
    bridge = ss.bridge
    n = bridge.n_modes
    cov = np.zeros((n, n))
    spectra = np.zeros((f_arr.size, sel_rows.shape[0]))
    modal_spectra = np.zeros((f_arr.size, n))
    chunk = max(1, _CHUNK_BYTES // (16 * n * max(n, bridge.n_nodes)))
    for start in range(0, f_arr.size, chunk):
        sl = slice(start, min(f_arr.size, start + chunk))
        S_F = modal_force_spectrum(bridge, spec, U, f_arr[sl])  # real, symmetric
        H = transfer_matrix(ss, U, f_arr[sl])
        # Real arithmetic: Re(H S_F H^H) = Hr S_F Hr^T + Hi S_F Hi^T for a real S_F (half the
        # work of complex products); contiguous operands for numpy's stacked BLAS matmul.
        Hr, Hi = np.ascontiguousarray(H.real), np.ascontiguousarray(H.imag)
        HrT = np.ascontiguousarray(np.swapaxes(Hr, -1, -2))
        HiT = np.ascontiguousarray(np.swapaxes(Hi, -1, -2))
        S_xi = (Hr @ S_F) @ HrT + (Hi @ S_F) @ HiT  # modal response spectra, (m, n, n)
        cov += np.tensordot(weights[sl], S_xi, axes=1)
        modal_spectra[sl] = np.diagonal(S_xi, axis1=-2, axis2=-1)
        # Response at the chosen nodes per unit modal force, (m, 3 s, n), and its spectrum.
        Rr, Ri = sel_rows @ Hr, sel_rows @ Hi
        spectra[sl] = np.sum((Rr @ S_F) * Rr + (Ri @ S_F) * Ri, axis=-1)
    return cov, modal_spectra, spectra


def physical_shapes(bridge: BridgeModel) -> FloatArray:
    """Return the shapes ``[h, alpha, p]`` at the nodes (m, rad, m per unit modal coordinate).

    Shape (nodes, 3, n_modes).
    """
    return bridge.shapes() * np.array([bridge.B, 1.0, bridge.B])[None, :, None]
