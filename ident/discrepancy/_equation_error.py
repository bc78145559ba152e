"""Equation-error fits of the discrepancy workflow's candidate effects (private to it).

With the structure known (the section model: ``Ms``, ``Cs``, ``Ks``) and the self-excited forces
measured (integrated pressures), each free decay must satisfy the structural equation
``Ms q'' + Cs q' + Ks q = f``. What the linear model misses shows as the residual
``r = Ms q'' + Cs q' + Ks q - f``, and every candidate effect predicts it as a term that is
*linear in the effect's parameters* (to first order for a delay and for crosstalk):

============================  ===============================================================
coulomb_friction               ``[-F_h sgn(h') B, -M_a sgn(alpha')]`` (``tanh`` of a small band)
quadratic_damping              ``[-c2_h |h'| h' B, -c2_a |alpha'| alpha']``
cubic_stiffness                ``[-k3_h h^3 B, -k3_a alpha^3]``
static_unbalance               ``-S [B alpha'', h'']`` (the off-diagonal ``S B`` of ``Ms``)
channel_delay                  ``tau f'`` (forces recorded ``tau`` late: ``f(t) = f_rec(t + tau)``)
tubing_distortion              ``a1 f' + a2 f''``, measured force (``1/H = 1 + a1 s + a2 s^2``)
sensor_crosstalk               ``a L([alpha/B, 0]) + b L([0, h])``, ``L(x) = Ms x'' + Cs x' + Ks x``
============================  ===============================================================

so each is a linear least-squares fit. Vortex shedding adds a force the pressures measure, so it
leaves the structural equation satisfied; it shows instead as a spectral line in the forces
above the motion's band whose frequency is proportional to the wind speed (``St U / D``). Its
family of residuals is the forces' high-pass part, fitted with a sine and cosine per release (a
phase of its own) at ``k U`` Hz, ``k`` found by a scan.

Derivatives come from the signals low-passed (zero phase, 4th-order Butterworth at
``LOWPASS_FACTOR`` times the highest modal frequency) and then differentiated by a quintic
Savitzky-Golay filter. The filter is linear, so it commutes with the structural equation; a
nonlinear regressor does not commute with it, so it is computed over the whole decay and
low-passed again the same way (:meth:`DecaySignals.band_limited`): the residual holds only the
low-passed nonlinear force, and a regressor's harmonics above the band would bias its
coefficient low (a friction beside a 6 Hz floor: 37 % low before, 16 % after); the
first and last ``EDGE_S`` seconds of each decay (the filter's transients, and the jump of
acceleration at the release) are not used. Each candidate is scored by its held-out residual:
five contiguous time blocks of every release, each predicted from a fit to the other four.

Not responsible for: choosing among the candidates, refitting the aerodynamic model or
simulating (:mod:`ident.discrepancy.workflow`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.signal import butter, savgol_filter, sosfiltfilt

from ident.model.section import SectionModel
from ident.numerics.stats import autocorrelation_inflation
from ident.records.release import Release

FloatArray = npt.NDArray[np.float64]

#: The low-pass cut-off, as a multiple of the highest structural frequency.
LOWPASS_FACTOR = 2.5
#: Seconds dropped at each end of a decay (filter transients, the release's acceleration jump).
EDGE_S = 0.4
#: Savitzky-Golay window (samples) and order of the derivatives of the low-passed signals.
SG_WINDOW, SG_ORDER = 9, 5
#: Held-out folds: chunks of ``FOLD_CHUNK_S`` of every release, dealt round-robin to the folds
#: (every fold spans all amplitudes, and a chunk is much longer than the filters' memory).
N_FOLDS = 5
FOLD_CHUNK_S = 0.25
#: Velocity band of the smoothed sign of the friction candidate, m/s and rad/s (as the effect).
FRICTION_BAND = (1e-4, 1e-3)
#: ... widened to this many times the filtered velocity's noise: where the model sticks, a
#: sharp sign of noise would add regressor variance uncorrelated with the friction force and
#: bias the fitted force low (by ~30 % at twice the noise, in tests on simulated decays).
FRICTION_NOISE_BANDS = 8.0
#: Shedding frequencies scanned, as Hz per m/s of wind (St/D; St 0.05-0.25 for D 0.01-0.1 m).
VORTEX_K_RANGE = (0.5, 25.0)


@dataclass(frozen=True)
class DecaySignals:
    """One decay, filtered and differentiated, trimmed of its edges.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Time from the release, s.
    q, q1, q2 : ndarray, shape (n, 2)
        ``[h/B, alpha]`` and its first and second time derivatives.
    f, f1, f2 : ndarray, shape (n, 2)
        Generalised forces ``[L B, M]`` (N m/m) and their first and second time derivatives.
    f_high : ndarray, shape (n, 2)
        The forces' part above the low-pass band (the vortex candidate's residual).
    U, qd : float
        Wind speed (m/s) and dynamic pressure (Pa).
    v_noise : ndarray, shape (2,)
        Noise of the filtered velocities ``[h', alpha']``, m/s and rad/s (from the raw signals'
        noise above the low-pass band).
    chunk : int
        Samples per held-out chunk (``FOLD_CHUNK_S``).
    """

    t: FloatArray
    q: FloatArray
    q1: FloatArray
    q2: FloatArray
    f: FloatArray
    f1: FloatArray
    f2: FloatArray
    f_high: FloatArray
    U: float
    qd: float
    v_noise: FloatArray
    chunk: int
    q_full: FloatArray | None = None
    q1_full: FloatArray | None = None
    q2_full: FloatArray | None = None
    rho: float = 1.2
    keep: npt.NDArray[np.bool_] | None = None
    sos: FloatArray | None = None

    def band_limited(self, columns: FloatArray) -> FloatArray:
        """Low-pass ``columns`` (rows of the whole decay) as the signals were, then trim.

        A nonlinear function of the low-passed motion has harmonics above the band (a
        friction force flipping with a 6 Hz floor motion: a square wave) that the residual,
        low-passed, does not hold; left in, they bias the fitted coefficient low.
        """
        assert self.sos is not None and self.keep is not None
        return np.asarray(sosfiltfilt(self.sos, columns, axis=0)[self.keep], dtype=float)


def passband_gain(signals: DecaySignals, frequency_hz: float) -> float:
    """Return the gain of the signals' zero-phase low-pass at ``frequency_hz`` (0-1).

    A sine through the forward and backward pass comes out scaled by ``|H(f)|^2``, unshifted.
    """
    from scipy.signal import sosfreqz

    assert signals.sos is not None
    fs = 1.0 / float(np.median(np.diff(signals.t)))
    _, h = sosfreqz(signals.sos, worN=[frequency_hz], fs=fs)
    return float(abs(h[0]) ** 2)


def decay_signals(release: Release, section: SectionModel) -> DecaySignals:
    """Filter and differentiate one release (see the module docstring)."""
    fs = release.fs
    cutoff = min(LOWPASS_FACTOR * max(section.fh, section.fa), 0.4 * fs)
    sos = butter(4, cutoff, fs=fs, output="sos")
    dt = 1.0 / fs
    B = section.B
    raw_q = np.column_stack([release.h / B, release.alpha])
    raw_f = np.column_stack([release.lift * B, release.moment])

    def smooth(x: FloatArray, order: int) -> FloatArray:
        low = sosfiltfilt(sos, x, axis=0)
        return np.asarray(savgol_filter(low, SG_WINDOW, SG_ORDER, deriv=order, delta=dt,
                                        axis=0, mode="interp"), dtype=float)

    keep = (release.t >= release.t[0] + EDGE_S) & (release.t <= release.t[-1] - EDGE_S)
    f_low = sosfiltfilt(sos, raw_f, axis=0)
    # White noise above the band, scaled to the whole band, then through the filter and one
    # derivative: sigma_v = sigma 2 pi sqrt(fc^3 / (3 fs/2)).
    above = (raw_q - sosfiltfilt(sos, raw_q, axis=0))[keep]
    sigma = np.std(above, axis=0) * math.sqrt(0.5 * fs / (0.5 * fs - cutoff))
    v_noise = sigma * 2 * math.pi * math.sqrt(cutoff**3 / (1.5 * fs)) * np.array([B, 1.0])
    rho = section.rho if release.rho is None else release.rho
    return DecaySignals(
        t=release.t[keep], q=smooth(raw_q, 0)[keep], q1=smooth(raw_q, 1)[keep],
        q2=smooth(raw_q, 2)[keep], f=smooth(raw_f, 0)[keep], f1=smooth(raw_f, 1)[keep],
        f2=smooth(raw_f, 2)[keep],
        f_high=(raw_f - f_low)[keep], U=release.U, qd=0.5 * rho * release.U**2,
        v_noise=v_noise, chunk=max(1, int(round(FOLD_CHUNK_S * fs))),
        q_full=smooth(raw_q, 0), q1_full=smooth(raw_q, 1), q2_full=smooth(raw_q, 2), keep=keep,
        sos=sos, rho=rho)


def structural_residual(sig: DecaySignals, section: SectionModel) -> FloatArray:
    """Return ``Ms q'' + Cs q' + Ks q - f`` (N m/m), shape (n, 2)."""
    return _operator(section, sig.q, sig.q1, sig.q2) - sig.f


def _operator(section: SectionModel, x: FloatArray, x1: FloatArray, x2: FloatArray) -> FloatArray:
    """``L(x) = Ms x'' + Cs x' + Ks x`` for rows of x, shape (n, 2)."""
    return np.asarray(x2 @ section.mass_matrix().T + x1 @ section.damping_matrix().T
                      + x @ section.stiffness_matrix().T, dtype=float)


#: Regressor builders of the structural candidates: (signals, section) -> columns, each (n, 2).
def _diagonal(sig: DecaySignals, heave: FloatArray, pitch: FloatArray) -> list[FloatArray]:
    """Columns ``[heave, 0]`` and ``[0, pitch]`` (whole decay), band-limited and trimmed."""
    zero = np.zeros(heave.size)
    return [sig.band_limited(np.column_stack([heave, zero])),
            sig.band_limited(np.column_stack([zero, pitch]))]


def _friction(sig: DecaySignals, section: SectionModel) -> list[FloatArray]:
    assert sig.q1_full is not None
    B = section.B
    # The sign of a noisy velocity: see FRICTION_NOISE_BANDS.
    band_h = max(FRICTION_BAND[0], FRICTION_NOISE_BANDS * float(sig.v_noise[0]))
    band_a = max(FRICTION_BAND[1], FRICTION_NOISE_BANDS * float(sig.v_noise[1]))
    return _diagonal(sig, -np.tanh(sig.q1_full[:, 0] * B / band_h) * B,
                     -np.tanh(sig.q1_full[:, 1] / band_a))


def _quadratic(sig: DecaySignals, section: SectionModel) -> list[FloatArray]:
    assert sig.q1_full is not None
    B = section.B
    h1, a1 = sig.q1_full[:, 0] * B, sig.q1_full[:, 1]
    return _diagonal(sig, -np.abs(h1) * h1 * B, -np.abs(a1) * a1)


def _cubic(sig: DecaySignals, section: SectionModel) -> list[FloatArray]:
    assert sig.q_full is not None
    B = section.B
    return _diagonal(sig, -(sig.q_full[:, 0] * B) ** 3 * B, -sig.q_full[:, 1] ** 3)


def _unbalance(sig: DecaySignals, section: SectionModel) -> list[FloatArray]:
    B = section.B
    return [-np.column_stack([B * sig.q2[:, 1], sig.q2[:, 0] * B])]


def _delay(sig: DecaySignals, section: SectionModel) -> list[FloatArray]:
    return [sig.f1.copy()]


def _tubing(sig: DecaySignals, section: SectionModel) -> list[FloatArray]:
    # The true force is the measured one through 1 / H = 1 + a1 s + a2 s^2 (exact for a
    # second-order tube), so the residual is a1 f' + a2 f'' of the measured force.
    return [sig.f1.copy(), sig.f2.copy()]


def _crosstalk(sig: DecaySignals, section: SectionModel) -> list[FloatArray]:
    B = section.B

    def only(column: int, scale: float, x: FloatArray) -> FloatArray:
        out = np.zeros_like(x)
        out[:, 1 - column] = scale * x[:, column]
        return out

    # h_measured = h + a alpha: q_h picks up (a/B) alpha; alpha_measured = alpha + b h.
    cols = []
    for source, target_scale in ((1, 1.0 / B), (0, B)):
        x = [only(source, target_scale, d) for d in (sig.q, sig.q1, sig.q2)]
        cols.append(_operator(section, *x))
    return cols


def _viscous(sig: DecaySignals, section: SectionModel) -> list[FloatArray]:
    # Linear in the motion, so it commutes with the filter: the filtered velocity serves.
    B = section.B
    zero = np.zeros(sig.t.size)
    return [np.column_stack([-sig.q1[:, 0] * B * B, zero]),
            np.column_stack([zero, -sig.q1[:, 1]])]


@dataclass(frozen=True)
class CandidateSpec:
    """A structural candidate: its parameters (names, units) and regressor builder."""

    name: str
    parameters: tuple[str, ...]
    units: tuple[str, ...]
    regressors: Callable[[DecaySignals, SectionModel], list[FloatArray]]


STRUCTURAL_CANDIDATES: tuple[CandidateSpec, ...] = (
    CandidateSpec("coulomb_friction", ("force_h", "moment_a"), ("N/m", "N m/m"), _friction),
    CandidateSpec("quadratic_damping", ("c2_h", "c2_a"), ("N s^2/m^3", "N m s^2/m"),
                  _quadratic),
    CandidateSpec("cubic_stiffness", ("k3_h", "k3_a"), ("N/m^4", "N m/m"), _cubic),
    CandidateSpec("channel_delay", ("delay_s",), ("s",), _delay),
    CandidateSpec("static_unbalance", ("S",), ("kg m/m",), _unbalance),
    CandidateSpec("sensor_crosstalk", ("h_from_alpha", "alpha_from_h"), ("m/rad", "rad/m"),
                  _crosstalk),
    # Fitted as 1 / H = 1 + a1 s + a2 s^2; reported as frequency_hz and damping
    # (ident.discrepancy.effect_selection converts).
    CandidateSpec("tubing_distortion", ("a1", "a2"), ("s", "s^2"), _tubing),
)
#: Not a named effect: the reference friction and drag (named by how their damping changes
#: with the amplitude) are judged against, a linear damping the section's still-air damping
#: misses (a wrong ``Cs``, outside the library): ``[-c_h h' B, -c_a alpha']``, N m/m.
LINEAR_DAMPING = CandidateSpec("linear_damping", ("c_h", "c_a"), ("N s/m^2", "N m s/m"),
                               _viscous)


@dataclass(frozen=True)
class LinearFit:
    """A candidate fitted by linear least squares on one residual family.

    Attributes
    ----------
    theta, std : ndarray, shape (p,)
        Parameters and their standard deviations (the least-squares covariance, inflated for
        the residual's autocorrelation).
    cv_ratio : float
        Held-out residual sum of squares with the candidate over that without it (< 1: the
        candidate predicts residual it was not fitted to).
    cv_ratio_se : float
        Standard error of ``cv_ratio`` (from the chunks' paired improvements).
    """

    theta: FloatArray
    std: FloatArray
    cv_ratio: float
    cv_ratio_se: float


def _chunk_labels(n: int, chunk: int, offset: int) -> npt.NDArray[np.intp]:
    """Chunk number of each row: ``chunk`` rows each, numbered from ``offset``."""
    return np.asarray(np.arange(n) // max(chunk, 1) + offset, dtype=np.intp)


def chunk_ids(y: Sequence[FloatArray], chunks: Sequence[int]) -> tuple[npt.NDArray[np.intp],
                                                                         npt.NDArray[np.intp]]:
    """Return each row's chunk number and held-out fold (see :func:`fit_linear`)."""
    labels, offset = [], 0
    for i, (yi, chunk) in enumerate(zip(y, chunks, strict=True)):
        lab = _chunk_labels(len(yi), chunk, offset)
        labels.append((lab, (lab - offset + i) % N_FOLDS))
        offset = int(lab[-1]) + 1
    return (np.concatenate([lab for lab, _ in labels]),
            np.concatenate([f for _, f in labels]))


def held_out_sse(y: Sequence[FloatArray], X: Sequence[FloatArray],
                 chunks: Sequence[int]) -> FloatArray:
    """Return every row's squared held-out error of ``y = X theta`` (no columns: ``y^2``)."""
    Y, Xall = np.concatenate(y), np.vstack(X)
    if Xall.shape[1] == 0:
        return np.asarray(Y**2, dtype=float)
    _, fold = chunk_ids(y, chunks)
    held_sse = np.zeros(Y.size)
    for k in range(N_FOLDS):
        test = fold == k
        th_k, *_ = np.linalg.lstsq(Xall[~test], Y[~test], rcond=None)
        held_sse[test] = (Y[test] - Xall[test] @ th_k) ** 2
    return held_sse


def compare_held_out(before: FloatArray, after: FloatArray,
                     chunk_id: npt.NDArray[np.intp]) -> tuple[float, float]:
    """Return the held-out ratio ``sum after / sum before`` and its standard error.

    The standard error comes from the chunks' paired improvements (many nearly independent
    chunks, not five folds).
    """
    n_chunks = int(chunk_id.max()) + 1
    gain = np.bincount(chunk_id, weights=before - after, minlength=n_chunks)
    total = float(before.sum())
    ratio = 1.0 - float(gain.sum()) / total
    se = math.sqrt(n_chunks) * float(np.std(gain, ddof=1)) / total
    return ratio, se


def fit_linear(y: Sequence[FloatArray], X: Sequence[FloatArray],
               chunks: Sequence[int]) -> LinearFit:
    """Fit ``y = X theta`` over releases; score by held-out error (module docstring).

    The chunks of release ``i`` are dealt to the folds from fold ``i`` on, so that the starts
    of the decays (their largest amplitudes) are spread over the folds. The standard error of
    the held-out ratio comes from the chunks' paired improvements (many nearly independent
    chunks, not five folds).

    Parameters
    ----------
    y : sequence of ndarray, shape (n_i,)
        Whitened residual of each release.
    X : sequence of ndarray, shape (n_i, p)
        The candidate's whitened regressors, same rows.
    chunks : sequence of int
        Rows per fold chunk, per release.
    """
    Y, Xall = np.concatenate(y), np.vstack(X)
    # Unit-norm columns: they span ten orders of magnitude (h^3 beside a friction's sign), past
    # what pinv of the normal matrix resolves (a cubic spring beside friction: std 2e-14).
    norms = np.linalg.norm(Xall, axis=0)
    norms[norms == 0.0] = 1.0
    Xs = Xall / norms
    theta_s, *_ = np.linalg.lstsq(Xs, Y, rcond=None)
    theta = theta_s / norms
    chunk_id, _ = chunk_ids(y, chunks)
    ratio, se = compare_held_out(np.asarray(Y**2, dtype=float), held_out_sse(y, X, chunks),
                                 chunk_id)
    residuals = [yi - Xi @ theta for yi, Xi in zip(y, X, strict=True)]
    dof = max(Y.size - theta.size, 1)
    sigma2 = float(sum(float(r @ r) for r in residuals)) / dof
    sigma2 *= autocorrelation_inflation([r[:, None] for r in residuals])
    cov = sigma2 * np.linalg.pinv(Xs.T @ Xs) / np.outer(norms, norms)
    return LinearFit(theta=np.asarray(theta, dtype=float),
                     std=np.sqrt(np.maximum(np.diag(cov), 0.0)), cv_ratio=ratio, cv_ratio_se=se)


@dataclass(frozen=True)
class StructuralProblem:
    """The whitened structural residual of all decays and every candidate's regressors.

    Attributes
    ----------
    y : list of ndarray, shape (2 n_i,)
        Per release, the residual ``Ms q'' + Cs q' + Ks q - f`` with each equation (heave,
        pitch) divided by its RMS over all releases (so that neither dominates by its units).
    X : dict of str to list of ndarray, shape (2 n_i, p)
        Per candidate name, per release, its regressors whitened alike (and those of
        :data:`LINEAR_DAMPING`, the reference of the damping candidates).
    chunks : list of int
        Rows per held-out chunk, per release.
    scale : ndarray, shape (2,)
        The whitening of the heave and pitch equations, N m/m.
    t : list of ndarray
        Per release, the time of its rows, s (each row is both equations).
    """

    y: list[FloatArray]
    X: dict[str, list[FloatArray]]
    chunks: list[int]
    scale: FloatArray
    t: list[FloatArray]

    def design(self, names: Sequence[str]) -> list[FloatArray]:
        """Per release, the columns of the candidates ``names`` side by side (a joint fit)."""
        return [np.column_stack([self.X[name][i] for name in names]) if names
                else np.zeros((yi.size, 0)) for i, yi in enumerate(self.y)]


def structural_problem(signals: Sequence[DecaySignals], section: SectionModel,
                       specs: Sequence[CandidateSpec] = STRUCTURAL_CANDIDATES
                       ) -> StructuralProblem:
    """Build the whitened residuals and the candidates' (and :data:`LINEAR_DAMPING`'s) columns."""
    residuals = [structural_residual(sig, section) for sig in signals]
    scale = np.sqrt(np.mean(np.vstack(residuals) ** 2, axis=0))
    scale[scale == 0.0] = 1.0
    y = [(r / scale).ravel() for r in residuals]
    X = {spec.name: [np.column_stack([(c / scale).ravel() for c in spec.regressors(sig, section)])
                     for sig in signals] for spec in (*specs, LINEAR_DAMPING)}
    return StructuralProblem(y=y, X=X, chunks=[2 * sig.chunk for sig in signals], scale=scale,
                             t=[sig.t for sig in signals])


def beside_linear_damping(problem: StructuralProblem, base: Sequence[str], name: str,
                          section: SectionModel) -> tuple[float, float, FloatArray]:
    """Score a damping candidate beside a linear damping of the structure (:data:`LINEAR_DAMPING`).

    Parameters
    ----------
    problem : StructuralProblem
        The structural residuals and columns.
    base : sequence of str
        The structural effects already chosen (fitted in both fits).
    name : str
        The candidate.
    section : SectionModel
        The structure (its still-air modes turn the damping into damping ratios).

    Returns
    -------
    ratio, se : float
        Held-out residual with ``name`` over that without it, both beside ``base`` and the
        linear damping, and its standard error.
    zeta : ndarray, shape (4,)
        The linear damping fitted beside ``base`` as the damping ratios it adds,
        ``c_h / (2 m w_h)``, ``c_a / (2 I w_a)`` (``c_h`` N s/m^2, ``c_a`` N m s/m), and their
        standard deviations.
    """
    ids, _ = chunk_ids(problem.y, problem.chunks)
    columns = [*base, LINEAR_DAMPING.name]
    without = held_out_sse(problem.y, problem.design(columns), problem.chunks)
    ratio, se = compare_held_out(without, held_out_sse(
        problem.y, problem.design([*columns, name]), problem.chunks), ids)
    fit = fit_linear(problem.y, problem.design(columns), problem.chunks)
    to_zeta = 1.0 / np.array([2 * section.m * 2 * math.pi * section.fh,
                              2 * section.I * 2 * math.pi * section.fa])
    zeta = np.concatenate([fit.theta[-2:] * to_zeta, fit.std[-2:] * to_zeta])
    return ratio, se, zeta


@dataclass(frozen=True)
class VortexFit:
    """The vortex candidate: a line at ``k U`` Hz in the forces, a phase per release.

    Attributes
    ----------
    k, k_std : float
        Shedding frequency per wind speed, Hz per m/s (``St / D``), and its standard deviation.
    cl, cm : float
        Median over the releases of the lift and moment coefficient amplitudes
        (``L = qd B cl sin(...)``, ``M = qd B^2 cm sin(...)``).
    cl_std, cm_std : float
        Their spread over the releases (standard deviation).
    phase : float
        Median phase of the moment relative to the lift, rad.
    amplitudes : ndarray, shape (n_releases, 4)
        Per release, the generalised lift ``L B`` (sine, cosine) and moment (sine, cosine)
        amplitudes of the line, N m/m, with ``t`` from the release.
    fit : LinearFit
        The amplitude fit at ``k`` (its ``cv_ratio`` scores the candidate).
    """

    k: float
    k_std: float
    cl: float
    cm: float
    cl_std: float
    cm_std: float
    phase: float
    amplitudes: FloatArray
    fit: LinearFit


def fit_vortex(signals: Sequence[DecaySignals], section: SectionModel) -> VortexFit:
    """Find the shedding line in the forces' high-pass part and fit it (module docstring)."""
    scale = np.sqrt(np.mean(np.vstack([s.f_high for s in signals]) ** 2, axis=0))
    scale[scale == 0.0] = 1.0
    y = [(s.f_high / scale).ravel() for s in signals]
    fs = 1.0 / float(np.median(np.diff(signals[0].t)))
    k_max = min(VORTEX_K_RANGE[1], 0.45 * fs / max(s.U for s in signals))
    # Coarse scan: the summed periodograms (zero-padded FFTs) of the force residuals, each
    # release's frequency axis divided by its wind speed, on a grid finer than the spectral
    # resolution of the shortest decay at the highest wind speed.
    duration = min(float(s.t[-1] - s.t[0]) for s in signals)
    step = 0.25 / (duration * max(s.U for s in signals))
    grid = np.arange(VORTEX_K_RANGE[0], k_max, step)
    power = np.zeros(grid.size)
    for s, yi in zip(signals, y, strict=True):
        e = yi.reshape(-1, 2)
        n_fft = 1 << int(math.ceil(math.log2(8 * e.shape[0])))
        spectrum = np.sum(np.abs(np.fft.rfft(e, n=n_fft, axis=0)) ** 2, axis=1) / e.shape[0]
        k_axis = np.fft.rfftfreq(n_fft, d=1.0 / fs) / s.U
        power += np.interp(grid, k_axis, spectrum)
    k0 = float(grid[int(np.argmax(power))])
    k = _refine_k(signals, y, scale, section, k0, step)
    fit = fit_linear(y, _vortex_design(signals, scale, section, k),
                     [2 * sig.chunk for sig in signals])
    amps = fit.theta.reshape(len(signals), 4)  # N m/m: y and columns are whitened alike
    qdB2 = np.array([s.qd * section.B**2 for s in signals])
    cl = np.hypot(amps[:, 0], amps[:, 1]) / qdB2
    cm = np.hypot(amps[:, 2], amps[:, 3]) / qdB2
    phase = np.angle((amps[:, 2] + 1j * amps[:, 3]) / (amps[:, 0] + 1j * amps[:, 1]))
    k_std = _k_std(signals, y, scale, section, k, step)
    return VortexFit(k=k, k_std=k_std, cl=float(np.median(cl)), cm=float(np.median(cm)),
                     cl_std=float(np.std(cl, ddof=1)) if cl.size > 1 else math.nan,
                     cm_std=float(np.std(cm, ddof=1)) if cm.size > 1 else math.nan,
                     phase=float(np.median(phase)), amplitudes=amps, fit=fit)


def _vortex_columns(s: DecaySignals, scale: FloatArray, section: SectionModel,
                    k: float) -> FloatArray:
    """Sine and cosine columns of lift and moment at ``k U`` Hz, whitened, shape (2n, 4)."""
    w = 2 * math.pi * k * s.U
    sn, cs = np.sin(w * s.t), np.cos(w * s.t)
    zero = np.zeros(s.t.size)
    cols = [np.column_stack([sn, zero]), np.column_stack([cs, zero]),
            np.column_stack([zero, sn]), np.column_stack([zero, cs])]
    return np.column_stack([(c / scale).ravel() for c in cols])


def _vortex_design(signals: Sequence[DecaySignals], scale: FloatArray, section: SectionModel,
                   k: float) -> list[FloatArray]:
    """Per release, its four columns in its own block of a block-diagonal design."""
    n = len(signals)
    out = []
    for i, s in enumerate(signals):
        block = np.zeros((2 * s.t.size, 4 * n))
        block[:, 4 * i:4 * i + 4] = _vortex_columns(s, scale, section, k)
        out.append(block)
    return out


def _vortex_rss(signals: Sequence[DecaySignals], y: Sequence[FloatArray], scale: FloatArray,
                section: SectionModel, k: float) -> float:
    total = 0.0
    for s, yi in zip(signals, y, strict=True):
        X = _vortex_columns(s, scale, section, k)
        theta, *_ = np.linalg.lstsq(X, yi, rcond=None)
        total += float(np.sum((yi - X @ theta) ** 2))
    return total


def _refine_k(signals: Sequence[DecaySignals], y: Sequence[FloatArray], scale: FloatArray,
              section: SectionModel, k0: float, step: float) -> float:
    from scipy.optimize import minimize_scalar

    res = minimize_scalar(lambda k: _vortex_rss(signals, y, scale, section, k),
                          bounds=(k0 - 2 * step, k0 + 2 * step), method="bounded",
                          options={"xatol": step * 1e-4})
    return float(res.x)


def _k_std(signals: Sequence[DecaySignals], y: Sequence[FloatArray], scale: FloatArray,
           section: SectionModel, k: float, step: float) -> float:
    """Return the standard deviation of k from the curvature of the residual sum of squares."""
    h = step * 0.05
    r0 = _vortex_rss(signals, y, scale, section, k)
    rp = _vortex_rss(signals, y, scale, section, k + h)
    rm = _vortex_rss(signals, y, scale, section, k - h)
    curvature = (rp - 2 * r0 + rm) / h**2
    n = sum(yi.size for yi in y)
    sigma2 = r0 / max(n - 4 * len(signals) - 1, 1)
    return math.sqrt(2 * sigma2 / curvature) if curvature > 0 else math.inf
