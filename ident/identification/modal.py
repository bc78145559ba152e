"""Modal identification of free decays: a sum of damped exponentials fitted to several channels.

A linear free decay is exactly a sum of exponentials ``e^{p t}`` at the eigenvalues of its system:
the structural modes (complex pairs) and, in the wind, the aerodynamic lag poles (real). This
module fits that form to the measured displacements, which serves three purposes: modal
frequencies and damping for operators and for the flutter-derivative method; and a noise-free,
analytically differentiable model of the displacements from which E2RFC builds its regressors
(velocities, accelerations and lag states) without differentiating noisy data.

Method: the poles are first located by a matrix pencil on block-averaged data, then refined by
variable projection (for fixed poles the amplitudes are linear) with a nonlinear least-squares
solver. Block averaging of ``e^{p t}`` has an exact closed form, so averaging reduces noise and
cost without the edge effects of a filter. The number of real poles (0 to 3) is chosen by BIC.

Longer than 600 lines: the pencil, the variable-projection fit (its Jacobian in closed form)
and the order search share the block-averaged basis and its caches; split across modules they
would pass those caches through private interfaces. The release-level helpers at the end
(:func:`fit_release_modes`, :func:`release_modes`) are thin; the naming of modes by their
kinetic energy is :func:`ident.model.conventions.name_modes`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from scipy.linalg import eigh
from scipy.optimize import least_squares

from ident.errors import InsufficientDataError
from ident.model.conventions import name_modes
from ident.numerics.lsq import bounded_lm
from ident.numerics.threads import single_threaded_blas

if TYPE_CHECKING:  # only the type: a section's B and mass matrix are read
    from ident.model.section import SectionModel

__all__ = ["ModalFit", "ReleaseModes", "fit_modes", "fit_release_modes",
           "noise_std", "release_modes"]

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]

#: Block-averaged samples per period of the fastest mode used for the fit.
_SAMPLES_PER_PERIOD = 6
#: The poles are searched with :func:`ident.numerics.lsq.bounded_lm` first, and again with scipy's
#: ``least_squares`` when the fit's block-averaged residual is more than this many times the
#: white noise: a decay fits down to the noise (about 1), a random response (turbulence, 20 and
#: more) does not, and its fit has many local optima, in which the two solvers' different paths
#: end differently (scipy's is the one the fit was validated with).
FAST_SEARCH_LIMIT = 3.0


@dataclass(frozen=True, eq=False)
class ModalFit:
    """A multichannel sum of exponentials ``x(t) = offset + Re(sum_k e^{p_k t} C_k)``.

    Attributes
    ----------
    poles : ndarray, complex, shape (n_poles,)
        Every pole, complex ones together with their conjugates, 1/s.
    amplitudes : ndarray, complex, shape (n_poles, n_channels)
        Conjugate-symmetric amplitudes (so that the sum is real).
    offset : ndarray, shape (n_channels,)
        Constant part (static equilibrium), in channel units.
    noise : ndarray, shape (n_channels,)
        Estimated standard deviation of the measurement noise, channel units.
    residual_rms : ndarray, shape (n_channels,)
        RMS of data minus fit, channel units.
    """

    poles: ComplexArray
    amplitudes: ComplexArray
    offset: FloatArray
    noise: FloatArray
    residual_rms: FloatArray

    @property
    def modes(self) -> ComplexArray:
        """Oscillatory poles with positive imaginary part, sorted by frequency, 1/s."""
        osc = self.poles[self.poles.imag > 0]
        return osc[np.argsort(osc.imag)]

    @property
    def frequencies(self) -> FloatArray:
        """Damped frequencies of the oscillatory modes, Hz."""
        return np.asarray(self.modes.imag / (2 * math.pi), dtype=float)

    @property
    def damping(self) -> FloatArray:
        """Damping ratios ``-Re(p)/|p|`` of the oscillatory modes."""
        modes = self.modes
        return np.asarray(-modes.real / np.abs(modes), dtype=float)

    @property
    def random_response(self) -> float:
        """The residual rms over the white measurement noise, larger channel.

        About 1 for a decay fitted to its noise; 10-60 for a random response (turbulence).
        """
        scale = np.maximum(self.noise, 1e-9 * np.maximum(self.residual_rms, 1e-300))
        return (float(np.max(self.residual_rms / scale)) if np.any(self.residual_rms > 0)
                else 0.0)

    @property
    def real_poles(self) -> FloatArray:
        """Non-oscillatory poles (aerodynamic lags, overdamped motion), 1/s."""
        return np.asarray(self.poles[self.poles.imag == 0].real, dtype=float)

    def mode_shapes(self) -> ComplexArray:
        """Complex amplitude of each oscillatory mode per channel, shape (n_modes, n_channels)."""
        order = [int(np.flatnonzero(self.poles == p)[0]) for p in self.modes]
        return self.amplitudes[order]

    def evaluate(self, t: FloatArray, derivative: int = 0) -> FloatArray:
        """Evaluate the fit (or its ``derivative``-th time derivative) at times ``t``, (n, ch)."""
        E = _exponentials(t, self.poles)
        out = (E @ (self.poles[:, None] ** derivative * self.amplitudes)).real
        if derivative == 0:
            out = out + self.offset
        return np.asarray(out, dtype=float)

    def lag_state(self, t: FloatArray, mu: float) -> FloatArray:
        """State x with ``x' = x_fit' - mu x`` and ``x(0) = 0``, at times ``t`` (n, ch).

        Exact for the fitted exponentials: each ``C e^{pt}`` contributes
        ``C p (e^{pt} - e^{-mu t}) / (p + mu)``.
        """
        p = self.poles
        E = _exp(np.outer(t, p)) - np.exp(np.maximum(-mu * t, -600.0))[:, None]
        gain = p / (p + mu)
        return np.asarray((E @ (gain[:, None] * self.amplitudes)).real, dtype=float)


def noise_std(x: FloatArray) -> FloatArray:
    """Robust estimate of white measurement noise per column from second differences.

    For a smooth signal sampled far above its bandwidth the second difference is almost pure noise
    with variance ``6 sigma^2``; the median absolute deviation keeps transients from dominating.
    """
    d2 = np.diff(x, n=2, axis=0)
    mad = np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0)
    return np.asarray(1.4826 * mad / math.sqrt(6.0), dtype=float)


def _exp(arg: ComplexArray) -> ComplexArray:
    """``exp`` with the real part clamped at -600: no denormal numbers (which are very slow)."""
    return np.exp(np.maximum(arg.real, -600.0) + 1j * arg.imag)


def _exponentials(t: FloatArray, poles: ComplexArray) -> ComplexArray:
    """``_exp(np.outer(t, poles))``, computing each conjugate pair's exponential once.

    A fit's poles come in conjugate pairs and real poles: ``e^{conj(p) t}`` is the conjugate of
    ``e^{p t}`` (the same numbers: the sine is odd), and a real pole's exponential needs no
    sine and cosine. For the regressors of a 30 s release at 500 Hz this is most of the cost of
    preparing it.
    """
    t = np.asarray(t, dtype=float)
    out = np.empty((t.size, poles.size), dtype=complex)
    done = np.zeros(poles.size, dtype=bool)
    real = poles.imag == 0
    out[:, real] = np.exp(np.maximum(np.outer(t, poles[real].real), -600.0))
    done[real] = True
    upper = np.flatnonzero(poles.imag > 0)
    out[:, upper] = _exp(np.outer(t, poles[upper]))
    done[upper] = True
    for j in np.flatnonzero(~done):
        match = upper[poles[upper] == poles[j].conjugate()]
        out[:, j] = out[:, match[0]].conj() if match.size else _exp(t * poles[j])
    return out


def _block_average(t: FloatArray, x: FloatArray, block: int) -> tuple[FloatArray, FloatArray]:
    n = (t.size // block) * block
    tb = t[:n].reshape(-1, block)[:, 0]  # start of each block
    xb = x[:n].reshape(-1, block, x.shape[1]).mean(axis=1)
    return tb, xb


def _block_gain(poles: ComplexArray, block: int, dt: float) -> tuple[ComplexArray, ComplexArray]:
    """Gain ``g(p)`` of averaging ``e^{p t}`` over ``block`` samples, and ``dg/dp``.

    ``g = (1 - z^N) / (N (1 - z))`` with ``z = e^{p dt}``; at ``z = 1`` (p = 0) ``g = 1``.
    """
    if block == 1:
        return np.ones_like(poles), np.zeros_like(poles)
    N = block
    z = np.exp(poles * dt)
    near_one = np.abs(z - 1) < 1e-9
    zs = np.where(near_one, 0.5, z)  # placeholder where the closed form is 0/0
    g = (1 - zs**N) / (N * (1 - zs))
    dg_dz = (-N * zs ** (N - 1) * (1 - zs) + (1 - zs**N)) / (N * (1 - zs) ** 2)
    g = np.where(near_one, 1.0, g)
    # Near z = 1: g ~ 1 + (N - 1) (z - 1) / 2, so dg/dz -> (N - 1) / 2.
    dg_dz = np.where(near_one, (N - 1) / 2, dg_dz)
    return np.asarray(g, dtype=complex), np.asarray(dg_dz * z * dt, dtype=complex)


def _basis(tb: FloatArray, poles: ComplexArray, block: int, dt: float) -> ComplexArray:
    """Block averages of ``e^{p t}`` over ``block`` samples starting at ``tb`` (exact).

    ``tb`` is uniform from 0 here, so ``e^{p tb_k} = z^k`` with ``z = e^{p dtb}``: a running
    product is several times faster than complex exponentials and accurate to ~k eps.
    """
    g, _ = _block_gain(poles, block, dt)
    z = _exp(poles * (tb[1] - tb[0]))
    steps = np.broadcast_to(z, (tb.size, poles.size)).copy()
    steps[0] = 1.0
    return np.cumprod(steps, axis=0) * g


def _poles_from_params(theta: FloatArray, n_complex: int) -> ComplexArray:
    """Parameters ``[Re p_1, Im p_1, ..., sigma_1, ...]`` to the full pole list with conjugates."""
    pairs = theta[: 2 * n_complex].reshape(-1, 2)
    upper = pairs[:, 0] + 1j * pairs[:, 1]
    reals = theta[2 * n_complex :].astype(complex)
    return np.concatenate([upper, upper.conj(), reals, [0.0 + 0.0j]])


def _real_design(basis: ComplexArray, n_complex: int) -> FloatArray:
    """Real columns spanning the same signals: Re/Im for each complex pair, the rest as is."""
    upper = basis[:, :n_complex]
    rest = basis[:, 2 * n_complex :]
    return np.column_stack([upper.real, upper.imag, rest.real])


def _distinct_design(
    tb: FloatArray, poles: ComplexArray, n_modes: int, block: int, dt: float
) -> tuple[ComplexArray, ComplexArray, FloatArray]:
    """``_real_design(_basis(tb, poles, ...))`` without computing the conjugates' columns.

    The conjugate poles give the same real design, so only the distinct exponentials (upper
    complex poles, real poles, the offset) are computed; ``_basis`` works column by column, so
    these are exactly the columns ``_real_design`` would pick. Returns the distinct poles,
    their basis and the design.
    """
    distinct = np.concatenate([poles[:n_modes], poles[2 * n_modes:]])
    basis = _basis(tb, distinct, block, dt)
    design = np.column_stack([basis[:, :n_modes].real, basis[:, :n_modes].imag,
                              basis[:, n_modes:].real])
    return distinct, basis, design


def _solve_amplitudes(design: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    return np.asarray(coef, dtype=float), np.asarray(y - design @ coef, dtype=float)


def _to_complex_amplitudes(
    coef: FloatArray, n_complex: int, n_real: int
) -> tuple[ComplexArray, FloatArray]:
    """Real coefficients (columns of ``_real_design``) to conjugate-symmetric amplitudes."""
    a, b = coef[:n_complex], coef[n_complex : 2 * n_complex]
    c = (a - 1j * b) / 2  # a Re(e) + b Im(e) = 2 Re(c e) with c = (a - ib)/2
    reals = coef[2 * n_complex : 2 * n_complex + n_real].astype(complex)
    offset = coef[-1]
    return np.concatenate([c, c.conj(), reals]), np.asarray(offset, dtype=float)


def _pencil(xb: FloatArray, order: int, dtb: float) -> ComplexArray:
    """Matrix-pencil poles (1/s) of multichannel data at interval ``dtb``."""
    n = xb.shape[0]
    L = max(order + 1, min(n // 3, 120))
    rows = n - L
    H = np.vstack([np.lib.stride_tricks.sliding_window_view(xb[:, c], L + 1)[:rows]
                   for c in range(xb.shape[1])])
    # The leading right singular vectors of H, as the leading eigenvectors of H^T H (only
    # those are computed; the SVD's left vectors, unused, cost most of its time). Squaring
    # costs accuracy only in directions eps^0.5 below the largest, far below the noise floor
    # that separates the signal's subspace here.
    _, vectors = eigh(H.T @ H, subset_by_index=[H.shape[1] - order, H.shape[1] - 1])
    V = vectors[:, ::-1]
    z = np.linalg.eigvals(np.linalg.pinv(V[:-1]) @ V[1:])
    return np.asarray(np.log(z.astype(complex)) / dtb, dtype=complex)


@single_threaded_blas
def fit_modes(
    t: FloatArray,
    x: FloatArray,
    *,
    n_modes: int = 2,
    max_real_poles: int = 3,
    weights: FloatArray | None = None,
) -> ModalFit:
    """Fit ``n_modes`` damped oscillations, up to ``max_real_poles`` real poles and an offset.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Uniform sample times, s.
    x : ndarray, shape (n, n_channels)
        Signals (one column per channel); all channels share the poles.
    n_modes : int
        Number of oscillatory modes (complex pole pairs).
    max_real_poles : int
        Largest number of real poles tried; the number used is chosen by BIC.
    weights : ndarray, shape (n_channels,), optional
        Channel weights (default: the inverse of each channel's noise estimate).

    Returns
    -------
    ModalFit

    Raises
    ------
    InsufficientDataError
        If the record is too short for the model.

    References
    ----------
    Y. Hua and T. K. Sarkar, "Matrix pencil method for estimating parameters of exponentially
    damped/undamped sinusoids in noise", IEEE Trans. ASSP 38 (1990).
    G. H. Golub and V. Pereyra, "Separable nonlinear least squares: the variable projection
    method and its applications", Inverse Problems 19 (2003).

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(4000) / 200.0
    >>> x = np.exp(-0.3 * t) * np.cos(2 * np.pi * 2.0 * t)
    >>> fit = fit_modes(t, x[:, None], n_modes=1, max_real_poles=0)
    >>> round(float(fit.frequencies[0]), 6), round(float(fit.damping[0]), 6)
    (2.0, 0.023866)
    """
    return _fit_modes_and_exponentials(t, x, n_modes=n_modes, max_real_poles=max_real_poles,
                                       weights=weights, exponentials=False)[0]


@single_threaded_blas
def _fit_modes_and_exponentials(
    t: FloatArray,
    x: FloatArray,
    *,
    n_modes: int = 2,
    max_real_poles: int = 3,
    weights: FloatArray | None = None,
    exponentials: bool = True,
) -> tuple[ModalFit, ComplexArray | None]:
    """Fit as :func:`fit_modes`; also return ``e^{p t}`` of the fit's poles at ``t``, (n, n_poles).

    The exponentials are the amplitude fit's own basis (a running product over the uniform
    samples, relative error ~1e-12 after 10^4 samples): E2RFC's regressors reuse them instead
    of computing 10^5 complex exponentials again. ``exponentials=False`` returns None instead
    (:func:`fit_modes`, whose callers do not use them).
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    if x.ndim != 2 or x.shape[0] != t.size:
        raise ValueError(f"x must have shape (len(t), n_channels), got {x.shape}")
    dt = float((t[-1] - t[0]) / (t.size - 1))
    noise = noise_std(x)
    scale = np.sqrt(np.mean((x - x.mean(axis=0)) ** 2, axis=0))
    if np.any(scale == 0.0):
        raise InsufficientDataError("a channel is constant: no decay to fit")
    if weights is None:
        weights = 1.0 / np.maximum(noise, 1e-6 * scale)
    y = x * weights

    # Block size: about _SAMPLES_PER_PERIOD averaged samples per period of the fastest mode.
    spectrum = np.abs(np.fft.rfft(y - y.mean(axis=0), axis=0)).sum(axis=1)
    freqs = np.fft.rfftfreq(t.size, dt)
    # The peak of an oscillation the record holds at least four periods of: a slow drift (or
    # the low-frequency part of a random response) must not set a block longer than the modes.
    usable = freqs >= 4.0 / max(float(t[-1] - t[0]), dt)
    usable[0] = False
    f_peak = float(freqs[usable][np.argmax(spectrum[usable])]) if usable.any() else float(
        freqs[1:][np.argmax(spectrum[1:])])
    block = max(1, int(1.0 / (2.0 * f_peak * _SAMPLES_PER_PERIOD * dt)))
    # A short record gets shorter blocks rather than too few of them (more averaged samples per
    # period only help the pencil); a record that had enough blocks keeps its block size.
    needed = 8 * (2 * n_modes + max_real_poles + 1)
    block = max(1, min(block, t.size // needed))
    tb, yb = _block_average(t - t[0], y, block)
    if tb.size < needed:
        raise InsufficientDataError(f"{t.size} samples are too few for {n_modes} modes")

    dtb = block * dt
    duration = float(t[-1] - t[0])
    bounds = _bounds(n_modes, dtb, duration)
    pencil = _pencil(yb[: min(yb.shape[0], 400)], 2 * n_modes + max_real_poles + 3, dtb)
    osc, reals = _strongest_poles(tb, yb, block, dt, pencil)
    if osc.size < n_modes:
        raise InsufficientDataError(
            f"found {osc.size} of {n_modes} oscillatory modes in the data: too noisy or too short"
        )
    # The fast search first; where it leaves more than noise (a random response, whose fit has
    # many local optima), scipy's search, which the fit was validated with, decides.
    search = (tb, yb, block, dt, n_modes, max_real_poles, osc, reals, bounds, duration)
    theta, rss = _search_poles(*search, fast=True)
    if math.sqrt(rss * block / yb.size) > FAST_SEARCH_LIMIT:
        theta, rss = _search_poles(*search, fast=False)
    n_real = theta.size - 2 * n_modes

    # Amplitudes on the full-rate data (block = 1), with the refined poles.
    poles = _poles_from_params(theta, n_modes)
    _, basis, design = _distinct_design(t - t[0], poles, n_modes, 1, dt)
    coef, resid = _solve_amplitudes(design, y)
    amplitudes, offset = _to_complex_amplitudes(coef, n_modes, n_real)
    # Undo the channel weights and shift the time origin back to t[0].
    amplitudes = amplitudes / weights * np.exp(-poles[:-1] * t[0])[:, None]
    fit = ModalFit(
        poles=poles[:-1],
        amplitudes=amplitudes,
        offset=offset / weights,
        noise=noise,
        residual_rms=np.sqrt(np.mean(resid**2, axis=0)) / weights,
    )
    if not exponentials:
        return fit, None
    # e^{p t} of every pole from the distinct ones' e^{p (t - t[0])} (the offset's column last).
    upper = basis[:, :n_modes] * np.exp(poles[:n_modes] * t[0])
    reals = basis[:, n_modes:-1] * np.exp(poles[2 * n_modes:-1] * t[0])
    return fit, np.hstack([upper, upper.conj(), reals])


def _search_poles(
    tb: FloatArray, yb: FloatArray, block: int, dt: float, n_modes: int, max_real_poles: int,
    osc: ComplexArray, reals: FloatArray, bounds: tuple[FloatArray, FloatArray],
    duration: float, *, fast: bool,
) -> tuple[FloatArray, float]:
    """Refined pole parameters and residual sum: the modes, then real poles while BIC improves.

    Each new real pole starts from the pencil's real poles or from a grid of decay rates
    across the record: scipy's search (``fast=False``) refines from each of three grid points
    and keeps the best; the fast search refines from the best of a finer grid only
    (:func:`_scanned_start`), one refinement instead of three. The order search uses loose
    tolerances (it only compares orders); the chosen order is then polished to full precision.
    ``duration``: of the record, s; ``fast``: see :func:`_refine`.
    """
    dtb = block * dt
    theta, rss = _refine(tb, yb, block, dt, n_modes, 0, _complex_params(osc[:n_modes]), bounds,
                         loose=True, fast=fast)
    bic = _bic(rss, yb, n_modes, 0)
    grid = -np.geomspace(3.0 / duration, 0.3 / dtb, 3)
    unused = [r for r in reals if bounds[0][-1] < r < bounds[1][-1]]
    for n_real in range(1, max_real_poles + 1):
        starts = unused[:1] or list(grid)  # the pencil's next real pole when it found one
        if fast and not unused:
            starts = [_scanned_start(tb, yb, block, dt, n_modes, theta, grid)]
        trials = [
            _refine(tb, yb, block, dt, n_modes, n_real, np.append(theta, start), bounds,
                    loose=True, fast=fast)
            for start in starts
        ]
        theta_new, rss_new = min(trials, key=lambda trial: trial[1])
        bic_new = _bic(rss_new, yb, n_modes, n_real)
        if bic_new >= bic:
            break
        theta, rss, bic = theta_new, rss_new, bic_new
        unused = unused[1:]
    n_real = theta.size - 2 * n_modes
    return _refine(tb, yb, block, dt, n_modes, n_real, theta, bounds, loose=False, fast=fast)


#: Grid points per factor of 10 of the decay rate in the fast search's scan for a new real
#: pole's start (:func:`_scanned_start`).
_SCAN_PER_DECADE = 4


def _scanned_start(tb: FloatArray, yb: FloatArray, block: int, dt: float, n_modes: int,
                   theta: FloatArray, grid: FloatArray) -> float:
    """Return the start of a new real pole: the best of a grid, the other poles held.

    The residual of the fit with the poles found so far and one real pole more is evaluated
    (a rank-one update of the current fit's projection) at ``_SCAN_PER_DECADE`` points per
    decade over the span of ``grid`` (decay rates, 1/s, negative); the search then refines
    from the best point alone.
    Measured on the benchmark's decays (500 Hz, 20-30 s): where the three grid starts were each
    refined, their optima agreed to the noise, and the scan's point lies in the same basin, at a
    third of the cost.
    """
    lo, hi = float(np.min(-grid)), float(np.max(-grid))
    points = -np.geomspace(lo, hi, max(3, int(math.ceil(_SCAN_PER_DECADE
                                                            * math.log10(hi / lo))) + 1))
    # One column more than the current fit: the new residual sum is the current one less the
    # residual's projection on the column's part orthogonal to the current design (a rank-one
    # update of the projection), for every point at once instead of one solve each.
    resid, (_, _, Q, _) = _varpro_residual(tb, yb, block, dt, n_modes, theta)
    resid = resid.reshape(yb.shape, order="F")
    columns = _basis(tb, points.astype(complex), block, dt).real
    orthogonal = columns - Q @ (Q.T @ columns)
    norms = np.sum(orthogonal**2, axis=0)
    explained = np.sum((orthogonal.T @ resid) ** 2, axis=1) / np.where(norms > 0.0, norms, 1.0)
    # A column inside the current design's span (to round-off) explains nothing new.
    explained[norms <= 1e-12 * np.sum(columns**2, axis=0)] = 0.0
    return float(points[int(np.argmax(explained))])


def _bounds(n_modes: int, dtb: float, duration: float) -> tuple[FloatArray, FloatArray]:
    """Parameter bounds for ``n_modes`` complex pairs followed by (up to 3) real poles.

    Oscillations lie below the Nyquist rate of the averaged data and grow by at most 5 e-folds
    over the record; real poles decay slower than one per averaged sample and faster than 0.05
    e-folds over the record (slower ones are indistinguishable from the offset).
    """
    nyquist = math.pi / dtb
    lo_c = [-0.5 * nyquist, 1e-3]  # damping ratio up to ~0.45 at Nyquist, any below
    hi_c = [5.0 / duration, 0.95 * nyquist]
    lo = np.array(lo_c * n_modes + [-1.0 / dtb] * 3)
    hi = np.array(hi_c * n_modes + [-0.05 / duration] * 3)
    return lo, hi


def _bic(rss: float, yb: FloatArray, n_modes: int, n_real: int) -> float:
    """Bayesian information criterion of a fit with ``n_modes`` pairs and ``n_real`` real poles."""
    k = 2 * n_modes + n_real + yb.shape[1] * (2 * n_modes + n_real + 1)
    return yb.size * math.log(max(rss, 1e-300) / yb.size) + k * math.log(yb.size)


def _complex_params(osc: ComplexArray) -> FloatArray:
    osc = np.sort_complex(osc)
    return np.column_stack([osc.real, osc.imag]).ravel()


def _strongest_poles(
    tb: FloatArray, yb: FloatArray, block: int, dt: float, pencil: ComplexArray
) -> tuple[ComplexArray, FloatArray]:
    """Pencil poles ordered by the energy they carry in the data (noise poles carry little).

    Returns the oscillatory poles (Im > 0) and the real poles, each strongest first.
    """
    z = pencil[np.isfinite(pencil) & (pencil.real < 0.5 * np.abs(pencil.imag) + 10.0)]
    z = z[z.imag >= -1e-6 * np.abs(z)]  # one of each conjugate pair
    z = np.where(np.abs(z.imag) <= 1e-6 * np.abs(z), z.real + 0j, z)
    full = np.concatenate([z, z[z.imag > 0].conj(), [0.0 + 0.0j]])
    basis = _basis(tb, full, block, dt)
    coef, *_ = np.linalg.lstsq(basis, yb.astype(complex), rcond=None)
    energy = np.linalg.norm(basis, axis=0)[: z.size] * np.linalg.norm(coef[: z.size], axis=1)
    order = np.argsort(-energy)
    z = z[order]
    return z[z.imag > 0], np.asarray(z[z.imag == 0].real, dtype=float)


def _refine(
    tb: FloatArray, yb: FloatArray, block: int, dt: float, n_modes: int, n_real: int,
    theta0: FloatArray, bounds: tuple[FloatArray, FloatArray], *, loose: bool,
    fast: bool = False,
) -> tuple[FloatArray, float]:
    """Variable-projection refinement of the poles; returns parameters and residual sum.

    ``loose`` stops at a relative cost change of 1e-6 (enough to compare model orders).
    ``fast`` searches with :func:`ident.numerics.lsq.bounded_lm` instead of scipy's trust-region
    reflective ``least_squares`` (same tolerances; a fraction of the bookkeeping per call).

    The Jacobian is Kaufman's approximation ``-P_perp (dD/dtheta) c`` with the derivative of each
    exponential column taken in closed form through its (holomorphic) pole derivative.
    """
    k = theta0.size
    lo, hi = bounds[0][:k], bounds[1][:k]
    # Start values come from the pencil and from grids, and may sit on or beyond a bound (a noise
    # pole growing faster than allowed, say): the solver needs a strictly feasible start.
    margin = 1e-6 * (hi - lo)
    theta0 = np.clip(theta0, lo + margin, hi - margin)
    # The solvers ask for the Jacobian right after the residual at the points they accept; the
    # residual's factorisation is kept for it.
    last: list[tuple[FloatArray, tuple[ComplexArray, ComplexArray, FloatArray, FloatArray]]] = []

    def residual(theta: FloatArray) -> FloatArray:
        resid, parts = _varpro_residual(tb, yb, block, dt, n_modes, theta)
        last[:] = [(theta.copy(), parts)]
        return resid

    def jacobian(theta: FloatArray) -> FloatArray:
        if not last or not np.array_equal(last[0][0], theta):
            residual(theta)
        return _varpro_jacobian(tb, yb, block, dt, n_modes, theta, last[0][1])

    # A well-posed fit converges in ~15 evaluations; a pole the data cannot support wanders,
    # and the BIC rejects it anyway, so its search is cut short.
    xtol, ftol, max_nfev = (1e-6, 1e-6, 20) if loose else (1e-10, 1e-12, 60)
    if fast:
        sol = bounded_lm(residual, jacobian, theta0, (lo, hi), xtol=xtol, ftol=ftol,
                         max_nfev=max_nfev)
    else:
        sol = least_squares(residual, theta0, jac=jacobian, bounds=(lo, hi), x_scale="jac",
                            xtol=xtol, ftol=ftol, max_nfev=max_nfev)
    return sol.x, float(np.sum(sol.fun**2))


def _varpro_residual(
    tb: FloatArray, yb: FloatArray, block: int, dt: float, n_modes: int, theta: FloatArray
) -> tuple[FloatArray, tuple[ComplexArray, ComplexArray, FloatArray, FloatArray]]:
    """Residual (flattened channel by channel) at pole parameters, and what the Jacobian reuses.

    The solver asks for the Jacobian only at the points it accepts, so it is a separate step
    (:func:`_varpro_jacobian`) on the distinct poles, their basis, ``Q`` and the amplitudes.
    """
    poles = _poles_from_params(theta, n_modes)
    distinct, basis, design = _distinct_design(tb, poles, n_modes, block, dt)
    Q, R = np.linalg.qr(design)
    coef = np.linalg.solve(R, Q.T @ yb)
    resid = yb - design @ coef
    return resid.ravel(order="F"), (distinct, basis, Q, coef)


def _varpro_jacobian(
    tb: FloatArray, yb: FloatArray, block: int, dt: float, n_modes: int, theta: FloatArray,
    parts: tuple[ComplexArray, ComplexArray, FloatArray, FloatArray],
) -> FloatArray:
    """Kaufman's Jacobian ``-P_perp (dD/dtheta) c`` of :func:`_varpro_residual`'s residual."""
    distinct, basis, Q, coef = parts
    n_real = theta.size - 2 * n_modes
    n_b, n_ch = yb.shape
    # Pole derivative of each distinct exponential column (upper complex poles, then reals).
    # d/dp of g(p) e^{p t} = (t g + g') e^{p t}: reuses the exponentials of the basis. The
    # arrays are laid out (column, channel, sample): the sample axis innermost keeps numpy's
    # loops long (the columns and channels are a handful; with them innermost, broadcasting
    # cost most of the Jacobian's time).
    g, dg = _block_gain(distinct[:-1], block, dt)
    d_basis = basis[:, :-1].T * (tb[None, :] + (dg / g)[:, None])  # (n_poles, n_b)
    real, imag = d_basis.real[:, None, :], d_basis.imag[:, None, :]
    c_re, c_im = coef[:n_modes, :, None], coef[n_modes:2 * n_modes, :, None]  # Re(E_j), Im(E_j)
    # d/dRe(p) of (c_re Re E + c_im Im E), and d/dIm(p) (the derivative times i), interleaved
    # per mode; then the real poles: every column's model derivative, shape (k, n_ch, n_b).
    V = np.empty((theta.size, n_ch, n_b))
    V[0:2 * n_modes:2] = real[:n_modes] * c_re + imag[:n_modes] * c_im
    V[1:2 * n_modes:2] = real[:n_modes] * c_im - imag[:n_modes] * c_re
    V[2 * n_modes:] = real[n_modes:] * coef[2 * n_modes:2 * n_modes + n_real, :, None]
    rows = V.reshape(theta.size * n_ch, n_b)
    projected = (rows - (rows @ Q) @ Q.T).reshape(theta.size, n_ch * n_b)
    return np.asarray(-projected.T)


# -- one release's heave and pitch modes (the console's releases table, reprocessing) ----------
@dataclass(frozen=True)
class ReleaseModes:
    """Frequency and damping of the heave and pitch (and sway) modes of one decay.

    Attributes
    ----------
    f_h, f_a : float
        Frequencies of the heave- and pitch-dominated modes, Hz.
    zeta_h, zeta_a : float
        Their damping ratios (1 = critical).
    f_p, zeta_p : float or None
        The sway-dominated mode's, with three degrees of freedom (else None).
    """

    f_h: float
    zeta_h: float
    f_a: float
    zeta_a: float
    f_p: float | None = None
    zeta_p: float | None = None


def fit_release_modes(t: FloatArray, h: FloatArray, alpha: FloatArray,
                      section: SectionModel) -> ReleaseModes:
    """Fit the two modes of one free decay and name them heave and pitch.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Uniform sample times, s.
    h, alpha : ndarray, shape (n,)
        Heave (m) and pitch (rad).
    section : SectionModel
        Its mass matrix names the modes: the heave-dominated mode is the one whose kinetic
        energy is most in heave (``m B^2 |phi_h/B|^2`` against ``I |phi_alpha|^2``).

    Returns
    -------
    ReleaseModes

    Raises
    ------
    InsufficientDataError
        The decay is too short, or two oscillatory modes are not found in it.
    """
    x = np.column_stack([np.asarray(h, dtype=float) / section.B, np.asarray(alpha, dtype=float)])
    return release_modes(fit_modes(np.asarray(t, dtype=float), x, n_modes=2), section)


def release_modes(fit: ModalFit, section: SectionModel) -> ReleaseModes:
    """Name the modes of a decay's modal fit heave and pitch (and sway).

    The fit is of ``[h/B, alpha]``, or of ``[h/B, alpha, p/B]`` on a section with sway.

    Raises
    ------
    InsufficientDataError
        The fit holds fewer oscillatory modes than the section has degrees of freedom.
    ValueError
        The fit's coordinates are not the section's.
    """
    n = section.n_dof
    if fit.amplitudes.shape[1] != n:
        raise ValueError(f"a fit of {fit.amplitudes.shape[1]} coordinates cannot name the modes "
                         f"of a section with {n} degrees of freedom")
    if fit.frequencies.size < n:
        names = "heave and pitch" if n == 2 else "heave, pitch and sway"
        raise InsufficientDataError(f"found {fit.frequencies.size} oscillatory mode(s) in the "
                                    f"decay, need {n} ({names})")
    named = name_modes(fit.mode_shapes(), section.mass_matrix())
    f, z = fit.frequencies, fit.damping
    j_h, j_a = named[:2]
    sway = {} if n == 2 else {"f_p": float(f[named[2]]), "zeta_p": float(z[named[2]])}
    return ReleaseModes(f_h=float(f[j_h]), zeta_h=float(z[j_h]), f_a=float(f[j_a]),
                        zeta_a=float(z[j_a]), **sway)
