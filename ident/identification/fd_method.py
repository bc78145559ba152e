"""The indirect peer route: flutter derivatives from displacement-only decays, then Roger's fit.

This module is responsible for the classical method windrig compares E2RFC with. It takes the same
inputs as :func:`ident.identification.e2rfc.identify` (so that both run on one data set) but uses
only the displacements of each release:

1. Each free decay ``q = [h/B, alpha]`` is fitted with two damped modes
   (:func:`ident.identification.modal.fit_modes`). Their poles ``lambda_k`` and complex mode shapes
   ``phi_k`` rebuild the first-order system ``x' = S x``, ``x = [q, q']``, as ``S = Psi diag(lambda)
   Psi^-1`` with ``Psi = [[phi, conj(phi)], [lambda phi, conj(lambda phi)]]``.
   With the known structural mass ``Ms``, the effective stiffness and damping are
   ``K_eff = -Ms S[2:4, 0:2]`` and ``C_eff = -Ms S[2:4, 2:4]``.
2. Their differences from the still-air values, ``dK = K_0 - K_eff`` and ``dC = C_0 - C_eff``, are
   the aerodynamic stiffness and damping. Read as harmonic forces they give the flutter
   derivatives, ``qd B^2 Q(iK) = dK + i omega dC`` column by column: the heave column (H1, H4, A1,
   A4) at the reduced frequency ``K_h`` of the heave-dominated mode, the pitch column (H2, H3, A2,
   A3) at ``K_a`` of the pitch-dominated mode (Sarkar, Jones and Scanlan 1994).
3. Roger's rational function is fitted to that table, entry by entry because the two columns are
   known at different ``K``; the lag roots are searched by variable projection and the structure
   (number of lags, added mass) chosen by leave-one-wind-speed-out error.

Known weaknesses, which this module reproduces rather than hides (they are what the comparison
with E2RFC is about): it needs many wind speeds (fewer than 3 are refused); and it is only
approximately right even on noise-free data, because (a) each decaying mode holds both degrees of
freedom at one frequency while the classical reading assigns each column to one mode's frequency,
(b) the motion decays instead of being harmonic, so the forces are sampled at ``p = K(-zeta + i)``
rather than ``p = iK`` and any curvature of ``Q(p)`` (lags, added mass) turns into errors of order
``zeta``, and (c) with measured still-air decays, the still-air added mass is absorbed into
``K_0`` and ``C_0`` and is missing from the derivatives. On the flat plate (a) and (b) amount to a
few % on H1, H3, A2, A3 at moderate wind speeds and grow to 10-20 % on H1 and A2 near flutter,
where the modes are strongly coupled; the small derivatives (H2, H4, A1, A4) are much worse in
relative terms.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ident.errors import InsufficientDataError, NonUniformSamplingError, RankDeficiencyError
from ident.identification.modal import ModalFit, fit_modes
from ident.identification.results import RANDOM_RESPONSE_LIMIT
from ident.model.conventions import (
    FLUTTER_DERIVATIVE_NAMES,
    Q_from_flutter_derivatives,
    flutter_derivatives_from_Q,
    name_modes,
)
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel, proportion_warnings
from ident.numerics import validate as v
from ident.numerics.selection import Candidate
from ident.numerics.threads import single_threaded_blas
from ident.records import decay_checks, plausibility
from ident.records.release import SAMPLING_RTOL, Release
from ident.tables.roger_table import RogerProblem, select_structure

__all__ = [
    "Candidate",
    "FDDiagnostics",
    "FDIdentifiedModel",
    "DecayDerivativeTable",
    "flutter_derivatives",
    "identify",
]

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]

#: Wind speeds closer than this (relative) count as one wind speed (as in
#: :mod:`ident.identification.e2rfc`).
DISTINCT_U_RTOL = 0.02
#: Fewest distinct wind speeds :func:`identify` accepts: a Roger fit with lags needs a table.
MIN_WIND_SPEEDS = 3
#: Largest imaginary part of the rebuilt system matrix, relative to its largest entry. ``S`` is
#: real by construction (conjugate pairs); a larger imaginary part means nearly parallel mode
#: shapes, i.e. an ill-conditioned ``Psi``.
MAX_IMAGINARY_S = 1e-6
#: Largest condition number of an entry's column-scaled Roger design accepted as determined. A
#: table identified this way is uncertain by ~1e-3 (noise-free, model bias) to 1e-2 relative; a
#: larger condition number turns that into coefficients of opposite sign that cancel (typically
#: two lag roots that nearly coincide), meaningless although they still evaluate to the data.
MAX_CONDITION = 1e4

#: Flutter derivatives of the heave column (measured at K_h) and of the pitch column (at K_a).
HEAVE_COLUMN: tuple[str, ...] = ("H1", "H4", "A1", "A4")
PITCH_COLUMN: tuple[str, ...] = ("H2", "H3", "A2", "A3")


# -------------------------------------------------------------------------------------------------
# Flutter derivatives from free decays


@dataclass(frozen=True, eq=False)
class DecayDerivativeTable:
    """Flutter derivatives identified from free decays, one row per wind speed.

    Attributes
    ----------
    U : ndarray, shape (n,)
        Wind speed of each row (mean over its releases), m/s, increasing.
    K_h, K_a : ndarray, shape (n,)
        Reduced frequencies ``B omega / U`` of the heave- and pitch-dominated modes (mean over the
        row's releases). The heave column (H1, H4, A1, A4) holds at ``K_h``, the pitch column
        (H2, H3, A2, A3) at ``K_a``.
    derivatives : dict of str to ndarray, shape (n,)
        ``H1..H4, A1..A4`` (Scanlan notation, non-dimensional), mean over the row's releases.
    spread : dict of str to ndarray, shape (n,)
        Sample standard deviation (ddof=1) of each derivative over the row's releases; NaN where a
        row has one release. It includes the effect of the (up to 2 %) differences in U within a
        row, since the derivatives depend on K.
    n_releases : ndarray of int, shape (n,)
        Releases averaged in each row.
    modal_fits : tuple of tuple of ModalFit
        Per row, the modal fit of each release's ``[h/B, alpha]``.
    K_0, C_0 : ndarray, shape (2, 2)
        Still-air stiffness (N m/m) and damping (N m s/m) the aerodynamic parts are taken from.
    warnings : tuple of str
        The section's proportions unlike a section model's
        (:func:`ident.model.section.proportion_warnings`), its still-air frequencies far from
        what the decays ring at (:func:`ident.records.decay_checks.check_frequencies`), and its
        damping ratios far above what they decay at
        (:func:`ident.records.decay_checks.check_damping`).
    """

    U: FloatArray
    K_h: FloatArray
    K_a: FloatArray
    derivatives: dict[str, FloatArray]
    spread: dict[str, FloatArray]
    n_releases: npt.NDArray[np.int64]
    modal_fits: tuple[tuple[ModalFit, ...], ...] = field(repr=False)
    K_0: FloatArray = field(repr=False)
    C_0: FloatArray = field(repr=False)
    warnings: tuple[str, ...] = ()

    def Q_entries(self) -> tuple[FloatArray, ComplexArray]:
        """Return the table as samples of ``Q(iK)``, each entry at the K it was measured at.

        Returns
        -------
        K : ndarray, shape (n, 2, 2)
            ``K[:, i, 0] = K_h`` (heave column), ``K[:, i, 1] = K_a`` (pitch column).
        Q : ndarray, shape (n, 2, 2), complex
            ``Q[:, i, j]`` is ``Q_ij(i K[:, i, j])`` (non-dimensional).
        """
        K = np.empty((self.U.size, 2, 2))
        K[:, :, 0] = self.K_h[:, None]
        K[:, :, 1] = self.K_a[:, None]
        Q = np.empty((self.U.size, 2, 2), dtype=complex)
        Q[:, :, 0] = Q_from_flutter_derivatives(self.K_h, self.derivatives)[:, :, 0]
        Q[:, :, 1] = Q_from_flutter_derivatives(self.K_a, self.derivatives)[:, :, 1]
        return K, Q


@dataclass(frozen=True)
class _ModalSystem:
    """Effective structural matrices of one decay and its two modes (heave-, pitch-dominated)."""

    K_eff: FloatArray
    C_eff: FloatArray
    lam_h: complex
    lam_a: complex
    fit: ModalFit


@single_threaded_blas
def flutter_derivatives(
    releases: Sequence[Release],
    section: SectionModel,
    still_air: Sequence[tuple[Any, Any, Any]] | None = None,
) -> DecayDerivativeTable:
    """Identify flutter derivatives from the displacements of free decays at several wind speeds.

    Releases whose wind speeds agree within 2 % form one row of the table: each is identified on
    its own and the row holds the mean and spread of their derivatives. The forces of the releases
    are not used.

    Parameters
    ----------
    releases : sequence of Release
        Wind-on free decays (only ``t``, ``h``, ``alpha``, ``U`` and ``rho`` are used).
    section : SectionModel
        The structure: its mass matrix (known, e.g. weighed), width ``B`` and, for releases without
        one, air density.
    still_air : sequence of (t, h, alpha), optional
        Still-air free decays (s, m, rad; uniformly sampled). None: take the still-air stiffness
        and damping from ``section``. Given: identify them from these decays like the wind-on
        ones (mean over the decays); the still-air added mass is then part of the reference and
        drops out of the derivatives.

    Returns
    -------
    DecayDerivativeTable

    Raises
    ------
    InsufficientDataError
        No releases, or a decay in which two oscillatory modes cannot be found.
    RankDeficiencyError
        A decay whose two mode shapes are nearly parallel (the system matrix is not determined).
    PlausibilityError
        The section's still-air frequencies look like rad/s, or fh and fa swapped: what the
        decays ring at says so (:func:`ident.records.decay_checks.check_frequencies`); or,
        without ``still_air``, its damping ratios look given in per cent
        (:func:`ident.records.decay_checks.check_damping`).
    TypeError
        If ``releases`` holds something other than :class:`Release` objects.

    References
    ----------
    P. P. Sarkar, N. P. Jones and R. H. Scanlan, "Identification of aeroelastic parameters of
    flexible bridges", Journal of Engineering Mechanics 120 (1994) 1718-1742.
    R. H. Scanlan and J. J. Tomko, "Airfoil and bridge deck flutter derivatives", Journal of the
    Engineering Mechanics Division 97 (1971) 1717-1737.

    Examples
    --------
    >>> import numpy as np
    >>> from ident import SectionModel
    >>> from ident.model import flat_plate
    >>> from simulators import simulate_release
    >>> s = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)
    >>> truth = flat_plate.jones_model()
    >>> sims = [simulate_release(s, truth, U, 0.004, 0.02, duration=10.0, fs=200.0)
    ...         for U in (4.0, 6.0)]
    >>> table = flutter_derivatives([Release.from_simulation(r) for r in sims], s)
    >>> exact = truth.flutter_derivatives(table.K_a)["A3"]
    >>> bool(np.allclose(table.derivatives["A3"], exact, rtol=0.01))
    True
    """
    releases = _check_releases(releases)
    if not releases:
        raise InsufficientDataError("no releases given: flutter derivatives need wind-on decays")
    K_0, C_0 = _still_air_reference(still_air, section)
    groups = _group_by_speed(releases)
    rows = [_group_row(group, section, K_0, C_0) for group in groups]
    speeds = [row["U"] for row in rows for _ in row["frequencies"]]
    warnings = proportion_warnings(section)
    warnings += decay_checks.check_frequencies(
        section, speeds, [f for row in rows for f in row["frequencies"]])
    if still_air is None:  # the section's damping is the reference the decays are read from
        warnings += decay_checks.check_damping(
            section, speeds, [z for row in rows for z in row["damping"]])
    names = FLUTTER_DERIVATIVE_NAMES
    return DecayDerivativeTable(
        U=np.array([row["U"] for row in rows]),
        K_h=np.array([row["K_h"] for row in rows]),
        K_a=np.array([row["K_a"] for row in rows]),
        derivatives={n: np.array([row["mean"][n] for row in rows]) for n in names},
        spread={n: np.array([row["std"][n] for row in rows]) for n in names},
        n_releases=np.array([len(group) for group in groups], dtype=np.int64),
        modal_fits=tuple(row["fits"] for row in rows),
        K_0=K_0,
        C_0=C_0,
        warnings=tuple(warnings),
    )


def _check_releases(releases: Sequence[Release]) -> list[Release]:
    out = list(releases)
    for r in out:
        if not isinstance(r, Release):
            raise TypeError(f"releases must be ident.Release objects, got {type(r).__name__}")
        plausibility.check_channels(r, ("h", "alpha", "p"))
    return out


def _group_by_speed(releases: list[Release]) -> list[list[Release]]:
    """Releases grouped by wind speed (within ``DISTINCT_U_RTOL`` of a group's slowest), by U."""
    groups: list[list[Release]] = []
    for r in sorted(releases, key=lambda r: r.U):
        if groups and r.U <= groups[-1][0].U * (1 + DISTINCT_U_RTOL):
            groups[-1].append(r)
        else:
            groups.append([r])
    return groups


def _group_row(
    group: list[Release], section: SectionModel, K_0: FloatArray, C_0: FloatArray
) -> dict[str, Any]:
    """Identify each release of one wind speed; return the mean and spread of its derivatives."""
    per_release = []
    for r in group:
        try:
            system = _modal_system(r.t, r.h, r.alpha, section)
        except InsufficientDataError as err:
            raise type(err)(f"release at U = {r.U:.4g} m/s: {err}") from err
        rho = section.rho if r.rho is None else r.rho
        per_release.append((system, _release_derivatives(system, K_0, C_0, r.U, rho, section.B)))
    fds = {n: np.array([fd[n] for _, (fd, _, _) in per_release]) for n in FLUTTER_DERIVATIVE_NAMES}
    # The still-air checks read decays only: a buffeted release's modal fit does not name them.
    decays = [system for system, _ in per_release
              if system.fit.random_response <= RANDOM_RESPONSE_LIMIT]
    return {
        "U": float(np.mean([r.U for r in group])),
        "K_h": float(np.mean([K_h for _, (_, K_h, _) in per_release])),
        "K_a": float(np.mean([K_a for _, (_, _, K_a) in per_release])),
        "mean": {n: float(x.mean()) for n, x in fds.items()},
        "std": {n: float(x.std(ddof=1)) if x.size > 1 else math.nan for n, x in fds.items()},
        "fits": tuple(system.fit for system, _ in per_release),
        "frequencies": [(abs(s.lam_h.imag) / (2 * math.pi), abs(s.lam_a.imag) / (2 * math.pi))
                        for s in decays],
        "damping": [(-s.lam_h.real / abs(s.lam_h), -s.lam_a.real / abs(s.lam_a))
                    for s in decays],
    }


def _release_derivatives(
    system: _ModalSystem, K_0: FloatArray, C_0: FloatArray, U: float, rho: float, B: float
) -> tuple[dict[str, float], float, float]:
    """Flutter derivatives of one decay, with the reduced frequencies of its two columns.

    The aerodynamic stiffness ``dK`` and damping ``dC`` are read as harmonic forces at the
    frequency of the mode that dominates each column: ``qd B^2 Q = dK + i omega dC``. This is
    Scanlan's definition (e.g. ``H1 = dC[0, 0] U / (qd B^3 K_h)``) written through
    :mod:`ident.model.conventions`, so the sign and scaling conventions live in one place.
    """
    dK = K_0 - system.K_eff
    dC = C_0 - system.C_eff
    qd_B2 = 0.5 * rho * U**2 * B**2
    omega_h, omega_a = system.lam_h.imag, system.lam_a.imag
    K_h, K_a = B * omega_h / U, B * omega_a / U
    Q_h = np.asarray((dK + 1j * omega_h * dC) / qd_B2, dtype=complex)[None]
    Q_a = np.asarray((dK + 1j * omega_a * dC) / qd_B2, dtype=complex)[None]
    at_h = flutter_derivatives_from_Q([K_h], Q_h)
    at_a = flutter_derivatives_from_Q([K_a], Q_a)
    fd = {n: float(at_h[n][0]) for n in HEAVE_COLUMN} | {n: float(at_a[n][0]) for n in PITCH_COLUMN}
    return fd, K_h, K_a


def _modal_system(t: Any, h: Any, alpha: Any, section: SectionModel) -> _ModalSystem:
    """Fit two modes to one decay and rebuild its effective stiffness and damping matrices."""
    q = np.column_stack([np.asarray(h, dtype=float) / section.B, np.asarray(alpha, dtype=float)])
    fit = fit_modes(np.asarray(t, dtype=float), q, n_modes=2)
    lam = fit.modes
    phi = fit.mode_shapes()  # (2 modes, 2 coordinates); any complex scale per mode is fine
    S = _system_matrix(lam, phi)
    Ms = section.mass_matrix()
    heave, pitch = name_modes(phi, Ms)
    return _ModalSystem(
        K_eff=-Ms @ S[2:4, 0:2],
        C_eff=-Ms @ S[2:4, 2:4],
        lam_h=complex(lam[heave]),
        lam_a=complex(lam[pitch]),
        fit=fit,
    )


def _system_matrix(lam: ComplexArray, phi: ComplexArray) -> FloatArray:
    """Real first-order system matrix ``S`` (4 x 4, 1/s) with the given modes of ``q``.

    ``S = Psi diag(lambda, conj(lambda)) Psi^-1``, the columns of ``Psi`` being the state vectors
    ``[phi_k, lambda_k phi_k]`` of the four eigenvalues.

    Raises
    ------
    RankDeficiencyError
        If ``S`` is not real to ``MAX_IMAGINARY_S``: the mode shapes are nearly parallel.
    """
    states = np.vstack([phi.T, lam * phi.T])  # (4, 2): one column per mode
    Psi = np.hstack([states, states.conj()])
    eigenvalues = np.concatenate([lam, lam.conj()])
    cond = np.linalg.cond(Psi)
    S = Psi @ np.diag(eigenvalues) @ np.linalg.inv(Psi)
    if not np.isfinite(cond) or np.abs(S.imag).max() > MAX_IMAGINARY_S * np.abs(S.real).max():
        raise RankDeficiencyError(
            f"the two identified mode shapes are nearly parallel (condition number {cond:.3g}): "
            "the decay does not determine the stiffness and damping matrices"
        )
    return np.asarray(S.real, dtype=float)


def _still_air_reference(
    still_air: Sequence[tuple[Any, Any, Any]] | None, section: SectionModel
) -> tuple[FloatArray, FloatArray]:
    """Still-air stiffness and damping: the section's, or the mean identified from decays."""
    if still_air is None:
        return section.stiffness_matrix(), section.damping_matrix()
    decays = list(still_air)
    if not decays:
        raise InsufficientDataError("still_air is empty: give still-air decays or None")
    systems = []
    for n, decay in enumerate(decays):
        t, h, alpha = _check_decay(n, decay)
        try:
            systems.append(_modal_system(t, h, alpha, section))
        except InsufficientDataError as err:
            raise type(err)(f"still-air decay {n}: {err}") from err
    K_0 = np.mean([s.K_eff for s in systems], axis=0)
    C_0 = np.mean([s.C_eff for s in systems], axis=0)
    return K_0, C_0


def _check_decay(n: int, decay: Any) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Validate one still-air decay ``(t, h, alpha)``: 1-D, equal lengths, finite, uniform t."""
    try:
        t, h, alpha = decay
    except (TypeError, ValueError):
        raise TypeError(f"still_air[{n}] must be a (t, h, alpha) triple of arrays") from None
    arrays = [v.finite_array(f"still_air[{n}].{name}", x, ndim=1)
              for name, x in (("t", t), ("h", h), ("alpha", alpha))]
    if len({a.size for a in arrays}) != 1:
        raise ValueError(f"still_air[{n}]: t, h and alpha must have equal lengths")
    steps = np.diff(arrays[0])
    if steps.size == 0 or np.any(steps <= 0.0):
        raise NonUniformSamplingError(f"still_air[{n}].t must be strictly increasing")
    if float(np.abs(steps - steps.mean()).max()) > SAMPLING_RTOL * float(steps.mean()):
        raise NonUniformSamplingError(
            f"still_air[{n}].t is not uniformly sampled (tolerance {SAMPLING_RTOL:g} of the "
            "step): resample first"
        )
    return arrays[0], arrays[1], arrays[2]


# -------------------------------------------------------------------------------------------------
# Roger fit of the table


@dataclass(frozen=True, eq=False)
class FDDiagnostics:
    """What the Roger fit of a flutter-derivative table found besides the coefficients.

    Attributes
    ----------
    n_lags, with_A3 :
        The chosen structure.
    reason : str
        Why it was chosen (or "given by the caller").
    candidates : tuple of Candidate
        Every structure tried, with its held-out error: leave-one-wind-speed-out mean squared
        error of the held-out ``Q`` entries, each relative to its RMS over the table.
    relative_residual : ndarray, shape (2, 2)
        RMS fit residual of each entry of ``Q`` relative to that entry's RMS over the table.
    """

    n_lags: int
    with_A3: bool
    reason: str
    candidates: tuple[Candidate, ...]
    relative_residual: FloatArray


class FDIdentifiedModel(RationalFunctionModel):
    """A :class:`RationalFunctionModel` from the flutter-derivative route, with its table.

    Attributes
    ----------
    table : DecayDerivativeTable
        The flutter derivatives it was fitted to.
    diagnostics : FDDiagnostics
        Chosen structure and the candidates tried.
    """

    __slots__ = ("table", "diagnostics")

    def __init__(
        self, A: FloatArray, d: FloatArray, table: DecayDerivativeTable,
        diagnostics: FDDiagnostics,
    ) -> None:
        super().__init__(A, d)
        self.table = table
        self.diagnostics = diagnostics


@single_threaded_blas
def identify(
    releases: Sequence[Release],
    section: SectionModel,
    n_lags: int | None = None,
    with_A3: bool | None = None,
    still_air: Sequence[tuple[Any, Any, Any]] | None = None,
) -> FDIdentifiedModel:
    """Identify the rational-function model through flutter derivatives (the classical route).

    Flutter derivatives from the displacement decays (:func:`flutter_derivatives`), then a Roger
    least-squares fit of the table with lag roots found by variable projection. Takes the same
    data as :func:`ident.identification.e2rfc.identify`, for side-by-side comparison.

    Parameters
    ----------
    releases : sequence of Release
        Wind-on free decays at three or more (in practice many) wind speeds; forces are ignored.
    section : SectionModel
        The structure (mass matrix, width, and the air density where a release has none).
    n_lags : int, optional
        Number of lag terms (0 to 3); None chooses by leave-one-wind-speed-out error.
    with_A3 : bool, optional
        Fit the added-mass matrix A3; None chooses likewise.
    still_air : sequence of (t, h, alpha), optional
        Still-air decays for the reference stiffness and damping (see
        :func:`flutter_derivatives`); None uses the section's matrices.

    Returns
    -------
    FDIdentifiedModel
        A :class:`RationalFunctionModel` with ``.table`` (the flutter derivatives) and
        ``.diagnostics`` (:class:`FDDiagnostics`).

    Raises
    ------
    RankDeficiencyError
        Releases at fewer than three wind speeds, or a table that cannot determine the requested
        structure.
    PlausibilityError
        The section's still-air frequencies look like rad/s, or swapped
        (:func:`flutter_derivatives`).
    ValueError
        ``n_lags`` outside 0..3.

    References
    ----------
    K. L. Roger, "Airplane math modeling methods for active control design", AGARD CP-228, 1977.
    X. Chen, M. Matsumoto and A. Kareem, "Time domain flutter and buffeting response analysis of
    bridges", Journal of Engineering Mechanics 126 (2000) 7-16.
    P. P. Sarkar, N. P. Jones and R. H. Scanlan, Journal of Engineering Mechanics 120 (1994).

    Examples
    --------
    >>> import numpy as np
    >>> from ident import SectionModel
    >>> from ident.model import flat_plate, flutter
    >>> from simulators import simulate_release
    >>> s = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)
    >>> truth = flat_plate.jones_model()
    >>> sims = [simulate_release(s, truth, U, 0.004, 0.02, duration=10.0, fs=200.0)
    ...         for U in (4.0, 5.0, 6.0, 7.0, 8.0)]
    >>> model = identify([Release.from_simulation(r) for r in sims], s, n_lags=1, with_A3=True)
    >>> model.n_lags, model.table.U.size
    (1, 5)
    >>> speed = flutter.analyze(s, model).speed
    >>> bool(abs(speed / flutter.analyze(s, truth).speed - 1) < 0.05)
    True
    >>> identify([Release.from_simulation(r) for r in sims[:2]], s)
    Traceback (most recent call last):
    ...
    ident.errors.RankDeficiencyError: releases at 2 wind speed(s) ...
    """
    releases = _check_releases(releases)
    if n_lags is not None and (
        isinstance(n_lags, bool) or not isinstance(n_lags, int) or not 0 <= n_lags <= 3
    ):
        raise ValueError(f"n_lags must be an integer in 0..3 or None, got {n_lags!r}")
    _check_wind_speeds(releases)  # before the modal fits: refuse cheaply
    table = flutter_derivatives(releases, section, still_air)
    problem = RogerProblem(*table.Q_entries(), max_condition=MAX_CONDITION,
                           row_name="wind speeds")
    model, chosen, reason, candidates = select_structure(problem, n_lags, with_A3)
    diagnostics = FDDiagnostics(
        n_lags=chosen.n_lags,
        with_A3=chosen.with_A3,
        reason=reason,
        candidates=candidates,
        relative_residual=problem.relative_residual(model),
    )
    return FDIdentifiedModel(model.A, model.d, table, diagnostics)


def _check_wind_speeds(releases: list[Release]) -> None:
    if not releases:
        raise RankDeficiencyError(
            f"no releases given: the flutter-derivative route needs releases at "
            f"{MIN_WIND_SPEEDS} or more (in practice many) wind speeds"
        )
    n_speeds = len(_group_by_speed(releases))
    if n_speeds < MIN_WIND_SPEEDS:
        raise RankDeficiencyError(
            f"releases at {n_speeds} wind speed(s) cannot determine a rational function model by "
            f"the flutter-derivative route: it needs a table over {MIN_WIND_SPEEDS} or more wind "
            "speeds (in practice many), one row per speed; this is the method's known weakness "
            "(E2RFC, ident.identification.e2rfc.identify, works from two)"
        )
