"""Heave-pitch coupling that exists at zero wind and the model lacks.

Responsibility: :func:`zero_wind_coupling` measures, in every release, how much each mode of the
decay moves the other degree of freedom (the mode shape's ratio, mass-normalised so that heave
and pitch count by their kinetic energy), subtracts what the model predicts at that wind speed
(the eigenvectors of :class:`~ident.model.statespace.AeroelasticSystem`), and extrapolates the
difference to zero wind along the dynamic pressure ``qd = rho U^2 / 2``.

Why: the aerodynamic coupling of heave and pitch grows with the dynamic pressure and vanishes in
still air, and the model's share of it is subtracted; what is left at ``qd = 0`` is coupling the
structure or the sensors put there. A static unbalance (a mass matrix with ``S B`` off the
diagonal) or crosstalk between the laser channels makes it in phase with the motion (the real
part), and large; a model that merely misfits the forces leaves it near zero or in quadrature.
Releases need wind (E2RFC needs ``U > 0``), so zero wind is reached by extrapolation: a straight
line through the releases' ``(qd, coupling)``, its intercept and standard error.

Not responsible for: naming the effect (:mod:`ident.discrepancy.workflow`, which reports this as one
of its looks), or the modal fit itself (:func:`ident.identification.modal.fit_modes`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from ident.errors import IdentError
from ident.identification.modal import fit_modes
from ident.model.conventions import name_modes
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.model.statespace import AeroelasticSystem
from ident.records.release import Release

__all__ = ["COUPLING_FLOOR", "COUPLING_SIGMAS", "ZeroWindCoupling", "coupling_verdict",
           "zero_wind_coupling"]

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]

#: In-phase coupling below this (a mode moving the other degree of freedom by 0.5 % of its own
#: mass-normalised amplitude) is not reported as significant, whatever its standard error: with
#: six releases the straight line's error is itself uncertain.
COUPLING_FLOOR = 0.005
#: ... and it must be this many standard errors from zero.
COUPLING_SIGMAS = 3.0


@dataclass(frozen=True)
class ZeroWindCoupling:
    """One mode's coupling at zero wind that the model does not explain.

    Attributes
    ----------
    mode : str
        ``"heave"`` (the pitch the heave-dominated mode carries) or ``"pitch"`` (the heave the
        pitch-dominated mode carries).
    in_phase, in_phase_std : float
        Real part of the mass-normalised coupling at ``qd = 0`` (measured minus model), and its
        standard error (dimensionless: the other degree of freedom's amplitude over the mode's
        own, each times the square root of its mass term).
    quadrature, quadrature_std : float
        The imaginary part, likewise.
    qd : ndarray
        Dynamic pressure of each release used, Pa.
    per_release : ndarray, complex
        Each release's measured minus model coupling.
    """

    mode: str
    in_phase: float
    in_phase_std: float
    quadrature: float
    quadrature_std: float
    qd: FloatArray = field(repr=False)
    per_release: ComplexArray = field(repr=False)

    @property
    def significant(self) -> bool:
        """Tell whether the in-phase part is clear of zero (:data:`COUPLING_FLOOR`, sigmas)."""
        return (abs(self.in_phase) > COUPLING_FLOOR
                and abs(self.in_phase) > COUPLING_SIGMAS * self.in_phase_std)

    def text(self) -> str:
        """Return one line: the mode, both parts with their errors, and the verdict."""
        verdict = "SIGNIFICANT" if self.significant else "not significant"
        return (f"{self.mode} mode: in phase {self.in_phase:+.4f} +- {self.in_phase_std:.4f}, "
                f"quadrature {self.quadrature:+.4f} +- {self.quadrature_std:.4f} ({verdict})")


def _mode_shapes(release: Release, section: SectionModel) -> tuple[ComplexArray, ComplexArray]:
    """Return the decay's two poles (heave-, pitch-dominated) and mass-normalised shapes."""
    x = np.column_stack([release.h / section.B, release.alpha])
    fit = fit_modes(release.t, x, n_modes=2)
    if fit.modes.size < 2:
        raise IdentError(f"found {fit.modes.size} oscillatory mode(s), need 2")
    order = list(name_modes(fit.mode_shapes(), section.mass_matrix()))
    shapes = fit.mode_shapes() * np.sqrt(np.diag(section.mass_matrix()))
    return fit.modes[order], shapes[order]


def _model_shapes(section: SectionModel, model: RationalFunctionModel, U: float,
                  poles: ComplexArray) -> ComplexArray:
    """Return the model's mass-normalised shapes of the modes nearest ``poles`` at ``U``."""
    lam, vectors = np.linalg.eig(AeroelasticSystem(section, model, U).matrix())
    oscillatory = np.flatnonzero(lam.imag > 0)
    weights = np.sqrt(np.diag(section.mass_matrix()))
    out = np.empty((poles.size, 2), dtype=complex)
    for i, p in enumerate(poles):
        j = oscillatory[np.argmin(np.abs(lam[oscillatory] - p))]
        out[i] = vectors[:2, j] * weights
    return out


def _intercept(qd: FloatArray, y: FloatArray) -> tuple[float, float]:
    """Return the intercept of a straight line through ``(qd, y)`` and its standard error."""
    design = np.column_stack([np.ones_like(qd), qd / np.max(qd)])  # scaled: well conditioned
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    resid = y - design @ coef
    dof = qd.size - 2
    variance = float(resid @ resid) / dof if dof > 0 else math.inf
    cov = variance * np.linalg.inv(design.T @ design)
    return float(coef[0]), math.sqrt(max(float(cov[0, 0]), 0.0))


def zero_wind_coupling(releases: Sequence[Release], section: SectionModel,
                       model: RationalFunctionModel) -> tuple[ZeroWindCoupling, ...]:
    """Return the heave and pitch modes' coupling at zero wind that ``model`` lacks.

    Parameters
    ----------
    releases : sequence of Release
        Free decays at two or more wind speeds.
    section : SectionModel
        The structure as known (the model's mass matrix, its modes at each wind speed).
    model : RationalFunctionModel
        The aerodynamic model whose coupling is subtracted.

    Returns
    -------
    tuple of ZeroWindCoupling
        ``(heave, pitch)``; empty when fewer than three releases could be fitted with two modes
        or they are at fewer than two wind speeds (no line to extrapolate along).
    """
    qd, couplings = [], []
    for r in releases:
        try:
            poles, shapes = _mode_shapes(r, section)
        except IdentError:
            continue  # too short or one mode only: this release says nothing about coupling
        rho = section.rho if r.rho is None else r.rho
        predicted = _model_shapes(section.replace(rho=rho), model, r.U, poles)
        heave = shapes[0, 1] / shapes[0, 0] - predicted[0, 1] / predicted[0, 0]
        pitch = shapes[1, 0] / shapes[1, 1] - predicted[1, 0] / predicted[1, 1]
        qd.append(0.5 * rho * r.U ** 2)
        couplings.append((heave, pitch))
    q = np.asarray(qd, dtype=float)
    if q.size < 3 or np.ptp(q) <= 1e-9 * np.max(q):
        return ()
    c = np.asarray(couplings, dtype=complex)
    out = []
    for j, mode in enumerate(("heave", "pitch")):
        re, re_std = _intercept(q, c[:, j].real)
        im, im_std = _intercept(q, c[:, j].imag)
        out.append(ZeroWindCoupling(mode=mode, in_phase=re, in_phase_std=re_std, quadrature=im,
                                    quadrature_std=im_std, qd=q, per_release=c[:, j]))
    return tuple(out)


def coupling_verdict(couplings: Sequence[ZeroWindCoupling]) -> str:
    """Return one line saying what the zero-wind coupling of both modes shows.

    Both modes must carry significant in-phase coupling for it to count: a static unbalance
    and laser crosstalk couple both (measured on the simulated campaigns: 10-20 standard
    errors), whereas a model misfitting the forces (a channel delay, vortex forcing absorbed by
    E2RFC) can make one mode's coupling significant by itself.
    """
    if not couplings:
        return "not estimated (needs three or more releases at two or more wind speeds)"
    if all(c.significant for c in couplings):
        return ("in-phase coupling in both modes that the model lacks: the structure or the "
                "sensors couple heave and pitch (as a static unbalance or crosstalk would)")
    return "no in-phase coupling in both modes beyond the model's"
