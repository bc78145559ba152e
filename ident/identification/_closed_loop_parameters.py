"""The closed-loop fit's records and parameter vector.

Responsibility: the records the likelihood sees (each release and hold averaged over blocks,
:func:`records`), where every parameter sits in the vector ``theta`` with its bounds and step
limits (:class:`Layout`), and the search's start (:func:`initial`): the starting model's
coefficients, each wind speed's buffeting level and bandwidth and each release's noise from
the records themselves; and whether a shared buffeting filter's fitted exponents are those of
frozen gusts (:func:`exponent_warning`).

Not responsible for: the likelihood, its Fisher information or the search
(:mod:`ident.identification.closed_loop_ml`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ident.identification.channels import columns, coordinate_scales, force_channels
from ident.identification.innovations import ShapingFilter
from ident.identification.uncertainty import DISTINCT_U_RTOL, nearest_wind_speed
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.numerics.sampling import RATE_RTOL, decimation_factor
from ident.numerics.stats import white_noise_std
from ident.records.release import Release

__all__ = ["EXPONENT_TOLERANCE", "NOISE_FLOOR", "TARGET_FACTOR", "ZERO_START", "Layout",
           "Record", "block_size", "decimate", "exponent_warning",
           "initial", "log_lag_range", "noise_floor", "records", "with_lags"]

FloatArray = npt.NDArray[np.float64]

#: The records are decimated to at least this many times the highest still-air frequency: the
#: modes and the buffeting force's energy near them stay far inside the pass band, and the
#: likelihood costs a tenth of the full rate's at 500 Hz.
TARGET_FACTOR = 25.0

#: Least sensor-noise std of a channel, as a fraction of the channel's std over its release
#: (at the decimated rate). Lasers measure the motion to a few parts in 10^5 of its range, but
#: the sync view places them against the forces only to a few tenths of a millisecond (0.2 ms
#: is 0.5 % of the motion at 4 Hz): without a floor the likelihood trusted the displacements as
#: exact and fitted that misalignment (the simulated rig: -7.6 % with holds, -91 % without;
#: with the floor +0.6 and -2.7 %, docs/development/e2rfc_turbulence.md). Below the benchmark's own
#: noise.
NOISE_FLOOR = 5e-3

#: Least ratio L11 / L00 (and with sway L22 / L00) of a shaping filter's Cholesky factor (the
#: search's bound, and the floor a warm start writes): the moment's (drag's) own gust, never
#: quite none.
L11_RATIO_MIN = 1e-4
#: The exponents of the wind speed in a shared buffeting filter's frequencies and white-noise
#: level (:meth:`Layout.shaping`) where gusts of a fixed intensity and integral scale act
#: quasi-steadily: the force is ``rho U^2 B`` times the gust over ``U`` (``Iu U / U``), its
#: spectrum a function of the wavenumber ``f / U`` (Taylor's frozen turbulence), so its
#: frequencies scale as ``U`` and its low-frequency spectral density (``L L^T``) as
#: ``rho^2 U^3``. The search's start; the fit estimates both.
QUASI_STEADY_EXPONENTS = (1.0, 1.5)
#: A shared buffeting filter of two sections or more: its fitted exponents (frequencies as
#: ``U^a``, level as ``U^b``) are warned of when either lies further than this from gusts of
#: fixed intensity and scale (1 and 1.5) and further than three of its own standard deviations.
#: On the benchmark's tunnel rows (fourth-order filter): the plate 0.92-1.03 and 1.47-1.60 (1-3 %
#: turbulence, Davenport's admittance, eight releases per speed), the bluff deck 0.88-1.15 and
#: 1.28-1.66 (seeds 0-3 at 1 and 3 %, with and without holds). One section is not checked: it
#: cannot follow the gusts' spectral shape, and its exponents absorb that misfit (the same
#: deck releases: 0.44-0.56 and 1.84-2.03).
EXPONENT_TOLERANCE = 0.4
#: Start of each later section's zero, as ``tau w`` (:class:`ShapingFilter`): the likelihood
#: is even in it, so it cannot start at 0, where its derivative vanishes.
ZERO_START = 0.5


@dataclass
class Record:
    """One record's decimated channels and what it depends on."""

    y: FloatArray          # (n, n_y): h, alpha, lift, moment (, p, drag)
    fs: float              # decimated rate, Hz
    factor: int            # samples per block mean
    U: float
    rho: float
    group: int             # wind-speed index
    release: int           # release index (its noise parameters)
    held: bool             # a hold: the model does not move
    from_rest: bool = False  # starts at the release: the lag states are zero there


class Layout:
    """Where each parameter sits in the vector ``theta``."""

    def __init__(self, n_dof: int, n_lags: int, with_A3: bool, n_groups: int,
                 n_releases: int, sections: int = 1,
                 scaled: FloatArray | None = None, mixed_after: bool = False) -> None:
        terms = ([0, 1, 2] if with_A3 else [0, 1]) + [3 + m for m in range(n_lags)]
        self.index = tuple((k, i, j) for i in range(n_dof) for k in terms for j in range(n_dof))
        self.n_A, self.n_lags, self.n_dof = len(self.index), n_lags, n_dof
        self.n_aero = self.n_A + n_lags
        self.sections = sections
        #: The shaping filters' sources mixed into the forces after their sections
        #: (:class:`ShapingFilter`'s ``mixed_after``).
        self.mixed_after = mixed_after
        #: Channels of a record (``[h, alpha, lift, moment]``, with sway ``[.., p, drag]``).
        self.n_y = 2 * n_dof
        #: Entries of the shaping filter's Cholesky factor, in :meth:`shaping`'s order.
        self.L_entries = tuple((i, j) for i in range(n_dof) for j in range(i + 1))
        #: Parameters of a wind speed's shaping filter (:meth:`shaping`).
        self.n_shaping = (len(self.L_entries) + 2 * n_dof * sections
                          + (n_dof * sections if sections > 1 else 0))
        self.shaping0 = self.n_aero
        #: Per wind speed, ``log(U / U_ref)`` and ``log(rho / rho_ref)`` of one filter shared by
        #: every speed (:meth:`shaping`); None: a filter per speed.
        self.scaled = None if scaled is None else np.asarray(scaled, dtype=float)
        #: Shaping parameters in ``theta``: a block per speed, or one shared block and its two
        #: scaling exponents.
        self.n_groups = n_groups
        self.n_shaping_blocks = n_groups if scaled is None else 1
        self.shaping_size = (self.n_shaping * n_groups if scaled is None
                             else self.n_shaping + 2)
        self.noise0 = self.shaping0 + self.shaping_size
        #: Where a shared filter's two exponents sit in ``theta`` (:meth:`shaping`); None with a
        #: filter per speed.
        self.exponents = (None if scaled is None
                          else slice(self.shaping0 + self.n_shaping, self.noise0))
        self.size = self.noise0 + self.n_y * n_releases
        #: log of each channel's least noise std (:data:`NOISE_FLOOR`; :func:`noise_floor`).
        self.noise_floor = np.full(self.n_y * n_releases, -np.inf)
        #: log of the least and largest lag root (``d``, reduced; :func:`log_lag_range`).
        self.log_lag_range = (-math.inf, math.inf)

    def model(self, theta: FloatArray) -> RationalFunctionModel:
        """Return the rational-function model of ``theta``'s aerodynamic part."""
        A = np.zeros((3 + self.n_lags, self.n_dof, self.n_dof))
        for value, (k, i, j) in zip(theta[:self.n_A], self.index, strict=True):
            A[k, i, j] = value
        return RationalFunctionModel(A, np.exp(theta[self.n_A:self.n_aero]))

    def shaping(self, theta: FloatArray, group: int) -> ShapingFilter:
        """``[log f (2 S), log zeta (2 S), log L00, L10 / L00, log(L11 / L00), tau w (2 S)]``.

        With sway (three forces) ``3 S`` frequencies, damping ratios and zeros, and after
        ``log(L11 / L00)`` the drag's row ``L20 / L00, L21 / L00, log(L22 / L00)``.
        ``S`` sections per force, lift's first; the zeros (``tau w``, :class:`ShapingFilter`)
        only with more than one section: with one, the likelihood drove a zero to nothing
        (docs/development/e2rfc_turbulence.md). ``L11`` in log: the likelihood depends on its
        square, so it is flat in ``L11`` at 0 (a lift and moment that are one gust's) and
        Fisher scoring would stall there.

        With one filter shared by the speeds (:attr:`scaled`), the block is that filter's at
        the reference speed and density, followed by two exponents ``a`` and ``b``: at speed
        ``U`` the frequencies are the block's times ``(U / U_ref)^a`` and ``L`` its times
        ``(rho / rho_ref) (U / U_ref)^b``; damping, zeros (as ``tau w``) and the lift-moment
        correlation are the block's.
        """
        p = self._block(theta, group)
        n, k, n_L = self.n_dof, self.n_dof * self.sections, len(self.L_entries)
        f = np.exp(p[0:k]).reshape(n, self.sections)
        L00 = math.exp(p[2 * k])
        L = np.zeros((n, n))
        for value, (i, j) in zip(p[2 * k:2 * k + n_L], self.L_entries, strict=True):
            L[i, j] = L00 * (math.exp(value) if i == j else value)
        L[0, 0] = L00
        zeros = (p[2 * k + n_L:3 * k + n_L].reshape(n, self.sections) / (2.0 * math.pi * f)
                 if self.sections > 1 else None)
        return ShapingFilter(f, np.exp(p[k:2 * k]).reshape(n, self.sections), L, zeros,
                             self.mixed_after)

    def _block(self, theta: FloatArray, group: int) -> FloatArray:
        """Return wind speed ``group``'s shaping parameters (:meth:`shaping`'s layout)."""
        if self.scaled is None:
            return theta[self.shaping0 + self.n_shaping * group:
                         self.shaping0 + self.n_shaping * (group + 1)]
        p = theta[self.shaping0:self.shaping0 + self.n_shaping].copy()
        a, b = theta[self.exponents]
        log_U, log_rho = self.scaled[group]
        k = self.n_dof * self.sections
        p[0:k] += a * log_U
        p[2 * k] += b * log_U + log_rho
        return p

    def shaping_offset(self, group: int) -> int:
        """Return where wind speed ``group``'s shaping block starts in ``theta``."""
        return self.shaping0 + (0 if self.scaled is not None else self.n_shaping * group)

    def set_shaping(self, theta: FloatArray, group: int, shaping: ShapingFilter) -> None:
        """Write ``shaping`` into ``theta`` as wind speed ``group``'s filter, in place.

        The inverse of :meth:`shaping`; the filter's sections must number :attr:`sections`.
        With a shared filter, its block is set so that speed ``group``'s filter is
        ``shaping`` at the exponents already in ``theta``.
        """
        f, zeta, L = shaping.frequencies, shaping.damping, shaping.L
        if f.shape != (self.n_dof, self.sections):
            raise ValueError(f"a shaping filter of {f.shape[1]} section(s) per force cannot "
                             f"start one of {self.sections}")
        p0, k, n_L = self.shaping_offset(group), self.n_dof * self.sections, len(self.L_entries)
        a = b = log_U = log_rho = 0.0
        if self.scaled is not None:
            a, b = theta[self.exponents]
            log_U, log_rho = self.scaled[group]
        theta[p0:p0 + k] = np.log(f).ravel() - a * log_U
        theta[p0 + k:p0 + 2 * k] = np.log(zeta).ravel()
        for at, (i, j) in enumerate(self.L_entries, start=p0 + 2 * k):
            theta[at] = (L[i, j] / L[0, 0] if i != j
                         else math.log(max(abs(L[i, i]) / L[0, 0], L11_RATIO_MIN)))
        theta[p0 + 2 * k] = math.log(L[0, 0]) - b * log_U - log_rho
        if self.sections > 1:
            theta[p0 + 2 * k + n_L:p0 + 3 * k + n_L] = (shaping.zeros * 2.0 * math.pi
                                                        * f).ravel()

    def step_limits(self, theta: FloatArray) -> FloatArray:
        """Return the largest move of each parameter in one step.

        A factor e in the logarithms and in the lift-moment ratio, half the coefficients' RMS
        (or the entry, if larger) in ``A``.
        """
        limit = np.ones(self.size)
        A = theta[:self.n_A]
        limit[:self.n_A] = np.maximum(0.5 * np.abs(A), 0.5 * math.sqrt(float(np.mean(A**2))))
        return limit

    def bounds(self, theta: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return the lower and upper bounds of the parameters.

        The lag roots within :attr:`log_lag_range` (E2RFC's own: a factor 20 beyond the reduced
        frequencies the releases cover), ``L11 / L00`` at least :data:`L11_RATIO_MIN` (its
        log), each noise at least a thousandth of its starting value and at least its
        :data:`NOISE_FLOOR`; the rest unbounded.
        """
        lower, upper = np.full(self.size, -np.inf), np.full(self.size, np.inf)
        lower[self.n_A:self.n_aero], upper[self.n_A:self.n_aero] = self.log_lag_range
        diagonal = [2 * self.n_dof * self.sections + at
                    for at, (i, j) in enumerate(self.L_entries) if i == j and i > 0]
        lower[[self.shaping_offset(g) + d for g in range(self.n_shaping_blocks)
               for d in diagonal]] = math.log(L11_RATIO_MIN)
        lower[self.noise0:] = np.maximum(theta[self.noise0:] - math.log(1e3), self.noise_floor)
        return lower, upper

    def noise(self, theta: FloatArray, release: int) -> FloatArray:
        """Return a release's noise standard deviations (m, rad, N/m, N m/m; m, N/m)."""
        at = self.noise0 + self.n_y * release
        return np.exp(theta[at:at + self.n_y])

    def affecting(self, record: Record) -> list[int]:
        """Return the parameters a record's likelihood depends on."""
        aero = [] if record.held else list(range(self.n_aero))
        p0 = self.shaping_offset(record.group)
        shaping = list(range(p0, p0 + (self.n_shaping if self.scaled is None
                                       else self.shaping_size)))
        noise = list(range(self.noise0 + self.n_y * record.release,
                           self.noise0 + self.n_y * (record.release + 1)))
        return aero + shaping + noise


def with_lags(model: RationalFunctionModel, n_lags: int) -> RationalFunctionModel:
    """Return ``model`` with ``n_lags`` lags: missing ones added with zero coefficients."""
    if n_lags == model.n_lags:
        return model
    n_dof = model.n_dof
    A = np.zeros((3 + n_lags, n_dof, n_dof))
    keep = min(n_lags, model.n_lags)
    A[:3 + keep] = model.A[:3 + keep]
    spread = np.geomspace(0.1, 1.0, n_lags) if n_lags else np.zeros(0)
    d = np.concatenate([model.d[:keep], spread[keep:]])
    return RationalFunctionModel(A, d)


def block_size(fs: float, f_max: float) -> int:
    """Decimation factor: the rate stays at least TARGET_FACTOR times ``f_max``."""
    return decimation_factor(fs, TARGET_FACTOR * f_max)


def decimate(y: FloatArray, factor: int) -> FloatArray:
    """Means of consecutive blocks of ``factor`` samples.

    Block means of white sensor noise stay white (a low-pass filter would colour it near the
    new Nyquist frequency, which the model's white sensor noise cannot follow); on the signals
    they act as a delay of half a block, the same on every channel, and a gain within 0.3 % of
    one at the still-air modes (a block is at most 1/:data:`TARGET_FACTOR` of their periods).
    """
    n = y.shape[0] // factor
    return np.asarray(y[: n * factor].reshape(n, factor, y.shape[1]).mean(axis=1), dtype=float)


def records(releases: Sequence[Release], section: SectionModel, speeds: list[float],
             f_max: float, use_holds: bool, window: tuple[float, float] | None = None
             ) -> list[Record]:
    """Decimated records of every release (within ``window``) and (when used) hold.

    Each record keeps its own decimated rate (releases may be recorded at different rates);
    rates within :data:`~ident.numerics.sampling.RATE_RTOL` of one already seen are taken as
    that one, so that records whose time stamps differ by rounding share one discretisation.
    """
    records: list[Record] = []
    rates: list[float] = []
    for index, r in enumerate(releases):
        group = nearest_wind_speed(r.U, speeds)
        rho = section.rho if r.rho is None else r.rho
        factor = block_size(r.fs, f_max)
        fs = r.fs / factor
        fs = next((seen for seen in rates if abs(fs - seen) <= RATE_RTOL * seen), fs)
        rates.append(fs)
        y = columns(r)
        t = r.t
        if window is not None:
            kept = (r.t >= window[0]) & (r.t < window[1])
            y, t = y[kept], r.t[kept]
            if y.shape[0] < 50 * factor:
                raise ValueError(f"the window {window} s leaves {y.shape[0]} samples of a "
                                 f"release; at least {50 * factor} are needed")
        # A release starts from rest (Release's contract): its lag states, driven by the
        # velocity, are zero at t = 0. A block mean taken as the state's sample stands half a
        # block later, when they are at most (2 pi / 50)^2 / 2 = 0.8 % of the released
        # displacement (a block is 1/TARGET_FACTOR of the fastest mode's period). A window
        # that starts later knows nothing of them.
        from_rest = bool(t[0] < factor / r.fs)
        records.append(Record(decimate(y, factor), fs, factor, r.U, rho, group, index,
                              False, from_rest))
        if use_holds and r.hold is not None and r.hold.t.size > 50 * factor:
            hold = columns(r.hold)
            records.append(Record(decimate(hold, factor), fs, factor, r.U, rho, group, index,
                                   True))
    return records


def log_lag_range(section: SectionModel, speeds: list[float]) -> tuple[float, float]:
    """Return the log of E2RFC's range of lag roots: 20 times beyond the reduced frequencies.

    The still-air frequencies at the highest and lowest wind speed bound the reduced
    frequencies ``K = 2 pi f B / U``. Far outside them a lag is a constant or a derivative term
    that the other coefficients already hold; a fit sent there (a root of 175 where the data
    cover 0.3-1.6, friction in 1 % turbulence) had a stiff state that made its Fisher
    information meaningless (a flutter-speed std of 0.004 %).
    """
    f = [section.fh, section.fa] + ([section.fp] if section.fp is not None else [])
    K_lo = 2.0 * math.pi * min(f) * section.B / max(speeds)
    K_hi = 2.0 * math.pi * max(f) * section.B / min(speeds)
    return math.log(K_lo / 20.0), math.log(20.0 * K_hi)


def noise_floor(records: list[Record], n_releases: int) -> FloatArray:
    """Return the log of each release's least channel noise std (:data:`NOISE_FLOOR`)."""
    n_y = records[0].y.shape[1]
    floor = np.empty(n_y * n_releases)
    for r in range(n_releases):
        released = np.vstack([rec.y for rec in records if rec.release == r and not rec.held])
        floor[n_y * r: n_y * (r + 1)] = np.log(np.maximum(
            NOISE_FLOOR * np.std(released, axis=0), 1e-300))
    return floor


def initial(records: list[Record], layout: Layout, start: RationalFunctionModel,
             section: SectionModel, f_max: float) -> FloatArray:
    """Return the start: ``start``'s coefficients, shaping and noise from the records."""
    theta = np.zeros(layout.size)
    A = start.A
    theta[:layout.n_A] = [A[k, i, j] if k < A.shape[0] else 0.0 for k, i, j in layout.index]
    theta[layout.n_A:layout.n_aero] = np.log(np.maximum(start.d, 1e-6))
    present = sorted({rec.group for rec in records})
    for r in range(1 + max(rec.release for rec in records)):
        own = [rec for rec in records if rec.release == r]
        y = np.vstack([rec.y for rec in own])
        # Noise from third differences (the signals' part is small at 25 x f_max).
        std = white_noise_std(np.vstack([rec.y for rec in own if not rec.held]))
        at = slice(layout.n_y * r, layout.n_y * (r + 1))
        theta[layout.noise0:][at] = np.maximum(np.log(
            np.maximum(std, 1e-12 * np.maximum(np.std(y, axis=0), 1e-300))),
            layout.noise_floor[at])
    blocks = np.zeros((layout.n_groups, layout.n_shaping))
    for g in present:
        own = [rec for rec in records if rec.group == g]
        # The buffeting force's level and bandwidth from a hold (force alone) or else the
        # second half of the releases (mostly random response).
        pieces = ([rec.y for rec in own if rec.held]
                  or [rec.y[rec.y.shape[0] // 2:] for rec in own])
        force = (np.vstack([p - p.mean(axis=0) for p in pieces])[:, force_channels(layout.n_dof)]
                 * coordinate_scales(layout.n_dof, section.B))
        fs = float(np.mean([rec.fs for rec in own]))  # a start: rates differ by little if at all
        rate = np.std(np.diff(force, axis=0), axis=0) * fs / np.maximum(
            np.std(force, axis=0), 1e-300)
        fc = np.clip(rate / (2.0 * math.pi), 0.5 * f_max, 5.0 * f_max)
        # Later sections an octave apart above the first, each with a zero an octave above
        # its own natural frequency.
        S, n = layout.sections, layout.n_dof
        f = fc[:, None] * 2.0 ** np.arange(S)[None, :]
        zeros = ZERO_START / (2.0 * math.pi * f) if S > 1 else None
        base = ShapingFilter(f, np.full((n, S), 0.7), np.eye(n), zeros)
        P = base.stationary_covariance()
        _, _, C_b = base.matrices()
        unit = np.sqrt(np.diag(C_b @ P @ C_b.T))
        if layout.mixed_after:  # forces L s, independent sources of variance unit^2
            cov = np.cov(force.T)
            L = np.linalg.cholesky(cov + 1e-9 * np.trace(cov) * np.eye(n)) / unit[None, :]
        else:
            cov = np.cov(force.T) / np.outer(unit, unit)
            L = np.linalg.cholesky(cov + 1e-9 * np.trace(cov) * np.eye(n))
        k, n_L = n * S, len(layout.L_entries)
        blocks[g, :k] = np.log(f).ravel()
        blocks[g, k:2 * k] = math.log(0.7)
        for column, (i, j) in enumerate(layout.L_entries, start=2 * k):
            blocks[g, column] = (L[i, j] / L[0, 0] if i != j
                                 else math.log(max(L[i, i] / L[0, 0], 1e-3)))
        blocks[g, 2 * k] = math.log(L[0, 0])
        if S > 1:
            blocks[g, 2 * k + n_L:3 * k + n_L] = ZERO_START
    if layout.scaled is None:
        theta[layout.shaping0:layout.noise0] = blocks.ravel()
        return theta
    # One filter for every speed: each speed's start scaled back to the reference by the
    # quasi-steady exponents, and averaged.
    a, b = QUASI_STEADY_EXPONENTS
    k = layout.n_dof * layout.sections
    blocks[:, :k] -= a * layout.scaled[:, :1]
    blocks[:, 2 * k] -= b * layout.scaled[:, 0] + layout.scaled[:, 1]
    theta[layout.shaping0:layout.shaping0 + layout.n_shaping] = blocks[present].mean(axis=0)
    theta[layout.exponents] = a, b
    return theta


def warm_nuisance(theta: FloatArray, layout: Layout, speeds: Sequence[float],
                  shaping: Sequence[tuple[float, ShapingFilter]],
                  noise: Sequence[FloatArray],
                  exponents: tuple[float, float] | None = None) -> None:
    """Start the shaping filters and noise from another fit's, in place.

    ``shaping`` holds (wind speed, filter) pairs of a fit of a superset of the releases: each
    of ``speeds`` takes the filter of the same speed (nearest, within the speeds' tolerance),
    else keeps its start. ``noise`` holds each release's four noise stds there, in this fit's
    order; each is kept above its floor. Near the other fit's maximum, the nuisance starts
    near this one's: the refit without the top speed then takes a few scoring steps where a
    start from the records' own statistics took about fifteen. With one filter shared by the
    speeds (:attr:`Layout.scaled`), ``exponents`` (the other fit's, when it shared one too)
    start its two exponents, and the filter of the speed nearest the reference its block.
    """
    if len(noise) != (layout.size - layout.noise0) // layout.n_y:
        raise ValueError(f"{len(noise)} releases' noise for a fit of "
                         f"{(layout.size - layout.noise0) // layout.n_y}")
    known = [U for U, _ in shaping]
    groups: Sequence[int] = range(len(speeds))
    if layout.scaled is not None:
        if exponents is not None:
            theta[layout.exponents] = exponents
        groups = [int(np.argmin(np.abs(layout.scaled[:, 0])))]
    for group in groups:
        U = speeds[group]
        nearest = nearest_wind_speed(U, known) if known else -1
        if nearest >= 0 and abs(known[nearest] - U) <= DISTINCT_U_RTOL * U:
            layout.set_shaping(theta, group, shaping[nearest][1])
    for release, std in enumerate(noise):
        at = slice(layout.n_y * release, layout.n_y * (release + 1))
        theta[layout.noise0:][at] = np.maximum(
            np.log(np.maximum(np.asarray(std, dtype=float), 1e-300)), layout.noise_floor[at])


def exponent_warning(exponents: tuple[float, float], std: tuple[float, float]) -> list[str]:
    """Warn of a shared buffeting filter that does not scale as frozen gusts do (or nothing).

    Gusts of fixed intensity and integral scale carried past the deck at ``U`` (Taylor) give a
    buffeting force whose spectrum is ``rho^2 U^3`` times a function of ``f / U``, whatever the
    admittance and span coherence: corners as ``U^1``, level as ``U^1.5``. A filter of two
    sections or more whose fitted exponents lie far from these (:data:`EXPONENT_TOLERANCE`, and
    three of their std) means turbulence that changes with the fan speed, or releases whose
    wind speed or air density is wrong.

    Parameters
    ----------
    exponents : (float, float)
        The fitted exponents of ``U`` in the filter's frequencies and its white-noise level.
    std : (float, float)
        Their standard deviations (inverse Fisher information).
    """
    far = [abs(value - expected) > max(EXPONENT_TOLERANCE, 3.0 * spread)
           for value, expected, spread in zip(exponents, QUASI_STEADY_EXPONENTS, std,
                                              strict=True)]
    if not any(far):
        return []
    (a, b), (sa, sb) = exponents, std
    return [f"the buffeting filter shared by the wind speeds scales as U^{a:.2f} (std {sa:.2f}) "
            f"in frequency and U^{b:.2f} (std {sb:.2f}) in level, where gusts of fixed "
            "intensity and scale give U^1 and U^1.5: the turbulence changes with the wind speed "
            "(an active grid, a generator at fixed frequencies), or a release's wind speed or "
            "air density is wrong; if the buffeting follows no power law of U, "
            "closed_loop_buffeting='fourth-order-per-speed' fits a filter per speed"]

