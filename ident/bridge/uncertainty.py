"""The section test's uncertainty carried to the bridge's flutter speed: delta method, Monte Carlo.

**From an identified model** (``windrig identify --json`` with its ``model_covariance``,
:class:`~ident.identification.covariance.ModelCovariance`: the fitted ``A`` entries and the lag
roots' ``log d``, jointly normal):

- *delta method* (:func:`delta_method`): the gradient of the bridge's flutter speed with respect
  to the section parameters, analytic from the flutter point of the modal rational eigenproblem
  ``T(lambda, U) v = 0`` (:class:`~ident.bridge.fast_flutter.ModalRationalProblem`). With the
  left and right null vectors ``w, v`` of ``T(i omega_F, U_F)``, a parameter change moves the
  critical eigenvalue by ``d lambda = -w^H (dT/d theta) v / (w^H dT/d lambda v)``, and the flutter
  speed by ``-Re(d lambda / d theta) / Re(d lambda / dU)``. ``T`` is linear in every ``A`` entry
  (through the mode-shape integrals ``G_ij``) and rational in each lag root, so every ``dT/d
  theta`` is exact. Chosen over finite differences through the fast route: one flutter point
  and ``p`` contractions of ``n x n`` matrices instead of ``2 p`` whole analyses (each following
  every branch from still air), and no step size to tune against the route's own tolerance
  (the tests check it against central differences of the route);
  ``std = sqrt(g^T C g)``.
- *Monte Carlo* (:func:`sample_models`, :func:`flutter_speeds`): ``N`` parameter vectors drawn
  from the covariance, each model through :func:`ident.bridge.fast_flutter.analyze`. The
  samples are drawn here, from one seed, before any task runs, so the result is the same
  whichever machine (or how many) analyses them; :func:`flutter_speeds` is the task: module
  level, plain arguments (the bridge, models, numbers), no file paths, so it pickles to any
  Dask worker.

**From a flutter-derivative table with std columns**: Monte Carlo only (:func:`sample_tables`,
:func:`table_flutter_speeds`): each tabulated derivative drawn independently, normal with its
std (a table carries no correlations, so none are assumed), each sampled table Roger-fitted
with one structure (lags and ``A3``: the one the evidence picks most often on the first
:data:`STRUCTURE_PROBES` samples, :func:`noisy_structure`; choosing it anew per sample would
mix the structure search's jumps into the noise, and costs ten times the fit) and through the
fast route. No delta method: the fit
has ``rows x derivatives`` inputs and a nonlinear lag search, and its linearisation would need
as many fits as the Monte Carlo itself.

:func:`summarise` puts the two together with their warnings (the stds disagree by more than
:data:`AGREEMENT`, samples without flutter in the searched range, failed samples).

Not responsible for: running the tasks (serially or on Dask: :mod:`daq.offline.bridge_uncertainty`),
the section's other uncertainty parts (structure, extrapolation: scaled there, not propagated).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ident.bridge import fast_flutter
from ident.bridge.aero import aero_from_model
from ident.bridge.model import BridgeModel
from ident.errors import IdentError
from ident.identification.covariance import ModelCovariance
from ident.model.rfc import RationalFunctionModel
from ident.tables.fd_table import FlutterDerivativeTable
from ident.tables.roger_table import fit_table

__all__ = ["AGREEMENT", "QUANTILES", "DeltaMethod", "SampleOutcome", "Uncertainty",
           "delta_method", "flutter_speeds", "sample_models", "sample_tables", "search_top",
           "summarise", "table_flutter_speeds", "noisy_structure"]

FloatArray = npt.NDArray[np.float64]

#: Relative difference of the delta-method and Monte Carlo stds above which a warning says
#: the flutter speed is not linear enough in the parameters over their spread.
AGREEMENT = 0.10
#: Quantiles of the Monte Carlo distribution reported (2 std either side, 1 std, median).
QUANTILES = (0.025, 0.16, 0.5, 0.84, 0.975)
#: How far above the nominal flutter speed the samples are searched, in delta-method stds
#: (at least to the nominal search's top): a sample beyond it is counted as not fluttering.
SEARCH_STDS = 6.0
#: Sampled tables whose structure search picks the Monte Carlo's one structure.
STRUCTURE_PROBES = 3


@dataclass(frozen=True)
class DeltaMethod:
    """The delta method's result (module docstring).

    Attributes
    ----------
    speed, frequency : float
        The nominal flutter speed (m/s) and frequency (Hz), fast route.
    gradient : ndarray, shape (p,)
        ``dU_F / d theta``, m/s per unit parameter (``A`` entries, then ``log d``).
    std : float
        ``sqrt(g^T C g)``, m/s.
    parameters : list of str
        Names of the parameters (the covariance's).
    """

    speed: float
    frequency: float
    gradient: FloatArray
    std: float
    parameters: list[str]


@dataclass(frozen=True)
class SampleOutcome:
    """One Monte Carlo sample through the fast route: flutter speed (m/s), frequency (Hz)."""

    speed: float | None
    frequency: float | None
    error: str | None = None


def _parameter_derivatives(problem: fast_flutter.ModalRationalProblem, bridge: BridgeModel,
                           covariance: ModelCovariance, lam: complex, U: float
                           ) -> list[npt.NDArray[np.complex128]]:
    """``dT / d theta`` at ``(lambda, U)`` for every parameter (module docstring), N/m."""
    half_rho, B = 0.5 * bridge.rho, bridge.B
    G = bridge.shape_integrals()
    out = []
    for k, i, j in covariance.parameter_index:
        scale: complex
        if k == 0:  # A1: -U^2 rho/2 B^2 G_ij
            scale = -(U**2) * half_rho * B**2
        elif k == 1:  # A2: -U lambda rho/2 B^3 G_ij
            scale = -U * lam * half_rho * B**3
        elif k == 2:  # A3, in the effective mass: -lambda^2 rho/2 B^4 G_ij
            scale = -(lam**2) * half_rho * B**4
        else:  # A_(l+3): -U^2 lambda / (lambda + a_l U) rho/2 B^2 G_ij
            a = problem.a[k - 3]
            scale = -(U**2) * lam / (lam + a * U) * half_rho * B**2
        out.append(scale * G[i, j])
    for a, A in zip(problem.a[:covariance.n_lags], problem.lags, strict=False):
        # d/d log d_l of -U^2 lambda / (lambda + a_l U) A_l, with da_l / dlog d_l = a_l.
        out.append(a * U**3 * lam / (lam + a * U) ** 2 * A)
    return out


def delta_method(bridge: BridgeModel, model: RationalFunctionModel,
                 covariance: ModelCovariance, U_max: float | None = None) -> DeltaMethod | None:
    """Flutter speed and its std by the delta method (module docstring).

    Parameters
    ----------
    bridge : BridgeModel
    model : RationalFunctionModel
        The section's model the covariance belongs to (2 or 3 DOF); completed with the bridge's
        quasi-steady sway terms as :func:`ident.bridge.aero.aero_from_model` does (the
        covariance's parameters are the section's, the first entries of the completed model).
    covariance : ModelCovariance
    U_max : float, optional
        Top of the search, m/s.

    Returns
    -------
    DeltaMethod or None
        None when the nominal model does not flutter below ``U_max``.

    Raises
    ------
    ValueError
        The covariance does not fit the model, or the critical eigenvalue does not cross the
        imaginary axis at the flutter point (a tangency: no first-order sensitivity).
    """
    covariance.check_model(model)
    full = aero_from_model(bridge, model).model
    nominal = fast_flutter.analyze(bridge, full, U_max=U_max)
    if nominal.speed is None or nominal.frequency is None:
        return None
    U, omega = nominal.speed, 2.0 * math.pi * nominal.frequency
    problem = fast_flutter.ModalRationalProblem(bridge, full)
    lam = 1j * omega
    # The null vectors of T at the flutter point: its smallest singular pair (T is singular
    # there to Newton's 1e-13; the next singular value is of the order of T itself).
    left, _, right_h = np.linalg.svd(problem.T(lam, U))
    w, v = left[:, -1], right_h[-1].conj()
    denominator = w.conj() @ problem.dT_dlam(lam, U) @ v
    slope = -(w.conj() @ problem.dT_dU(lam, U) @ v) / denominator
    if not slope.real > 0.0:
        raise ValueError(f"at the flutter point ({U:.6g} m/s) the critical eigenvalue does not "
                         "cross into the right half plane: no first-order sensitivity")
    gradient = np.array([
        (w.conj() @ dT @ v / denominator).real / slope.real  # -Re(dlam) / Re(dlam/dU)
        for dT in _parameter_derivatives(problem, bridge, covariance, lam, U)])
    variance = float(gradient @ covariance.matrix @ gradient)
    return DeltaMethod(speed=U, frequency=nominal.frequency, gradient=gradient,
                       std=math.sqrt(max(variance, 0.0)),
                       parameters=list(covariance.to_dict()["parameters"]))


def sample_models(bridge: BridgeModel, model: RationalFunctionModel,
                  covariance: ModelCovariance, n: int, seed: int = 0
                  ) -> list[RationalFunctionModel]:
    """Draw ``n`` section models and complete each for the bridge (sway terms); see module."""
    covariance.check_model(model)
    rng = np.random.default_rng(seed)
    return [aero_from_model(bridge, m).model for m in covariance.sample(model, n, rng)]


def flutter_speeds(bridge: BridgeModel, models: Sequence[RationalFunctionModel],
                   U_max: float) -> list[SampleOutcome]:
    """Flutter speed of every model through the fast route (a Monte Carlo task).

    A sample the route cannot analyse (a branch lost, a failed certification, no still-air
    modes) is returned with its error, named, and counted as failed by :func:`summarise`.
    """
    out = []
    for model in models:
        try:
            result = fast_flutter.analyze(bridge, model, U_max=U_max)
        except (IdentError, ValueError) as exc:  # reported per sample, counted in "failed"
            out.append(SampleOutcome(None, None, f"{type(exc).__name__}: {exc}"))
            continue
        out.append(SampleOutcome(result.speed, result.frequency))
    return out


def sample_tables(table: FlutterDerivativeTable, n: int, seed: int = 0
                  ) -> list[FlutterDerivativeTable]:
    """Draw ``n`` tables: each derivative with a std column normal about its value.

    Raises
    ------
    ValueError
        When the table has no std column.
    """
    if not table.std:
        raise ValueError(f"{table.source}: no std column (H1_std, ...): nothing to sample")
    rng = np.random.default_rng(seed)
    names = sorted(table.std)
    out = []
    for _ in range(n):
        values = dict(table.values)
        for name in names:
            values[name] = table.values[name] + table.std[name] * rng.standard_normal(
                table.K.size)
        out.append(FlutterDerivativeTable(table.K, values, filled=table.filled,
                                          source=table.source))
    return out


def noisy_structure(tables: Sequence[FlutterDerivativeTable]) -> tuple[int, bool]:
    """Return the Roger structure ``(n_lags, with_A3)`` the evidence picks on sampled tables.

    The most frequent choice of :func:`ident.tables.roger_table.fit_table` over ``tables``
    (ties: the fewer lags). A table's own values may be smooth enough to support more lags than
    its stated std does: the example deck's noise-free table picks 3 lags, its samples at a 3 %
    std 1 or 2, and 3 lags fitted to such samples were ill-conditioned in half of them.
    """
    chosen = []
    for table in tables:
        model = fit_table(table).model
        chosen.append((model.n_lags, bool(np.any(model.A[2] != 0.0))))
    return min(set(chosen), key=lambda c: (-chosen.count(c), c[0]))


def table_flutter_speeds(bridge: BridgeModel, tables: Sequence[FlutterDerivativeTable],
                         n_lags: int, with_A3: bool, U_max: float) -> list[SampleOutcome]:
    """Roger-fit every table with the given structure, then the fast route (a task).

    A fit that flutters at a reduced frequency above the table's range (below the wind speeds
    the table covers: the fit's extrapolation, which the table does not show) is a failed
    sample, named so, as the bridge's routes would not take that fit either.
    """
    out = []
    for table in tables:
        try:
            fit = fit_table(table, n_lags=n_lags, with_A3=with_A3)
            model = aero_from_model(bridge, fit.model).model
        except (IdentError, ValueError) as exc:  # reported per sample, counted in "failed"
            out.append(SampleOutcome(None, None, f"fit: {type(exc).__name__}: {exc}"))
            continue
        outcome = flutter_speeds(bridge, [model], U_max)[0]
        if outcome.speed is not None and outcome.frequency is not None:
            K = 2.0 * math.pi * outcome.frequency * bridge.B / outcome.speed
            if K > table.K[-1]:
                outcome = SampleOutcome(None, None, (
                    f"the fit flutters below the table's range (K = {K:.3g} above its "
                    f"{table.K[-1]:.3g})"))
        out.append(outcome)
    return out


def search_top(U_max: float, delta: DeltaMethod | None) -> float:
    """Top of the samples' search, m/s: ``U_max``, or ``SEARCH_STDS`` delta stds above U_F."""
    if delta is None:
        return U_max
    return max(U_max, delta.speed + SEARCH_STDS * delta.std)


@dataclass(frozen=True)
class Uncertainty:
    """The bridge's flutter speed's uncertainty: the JSON's ``uncertainty`` (:meth:`to_dict`).

    Attributes
    ----------
    source : str
        ``"model covariance"`` or ``"table std columns"``.
    speed : float or None
        Nominal flutter speed, m/s.
    delta : DeltaMethod or None
    outcomes : list of SampleOutcome
    U_max : float
        Top of the samples' search, m/s.
    seed : int
    warnings : list of str
    """

    source: str
    speed: float | None
    delta: DeltaMethod | None
    outcomes: list[SampleOutcome]
    U_max: float
    seed: int
    warnings: list[str] = field(default_factory=list)

    @property
    def speeds(self) -> FloatArray:
        """Flutter speeds of the samples that flutter below ``U_max``, m/s."""
        return np.array([o.speed for o in self.outcomes if o.speed is not None], dtype=float)

    @property
    def mc_std(self) -> float | None:
        """Sample std (``ddof = 1``) of :attr:`speeds`, m/s (None below two)."""
        s = self.speeds
        return float(np.std(s, ddof=1)) if s.size >= 2 else None

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form (units in ``units``)."""
        s = self.speeds
        failed = [o.error for o in self.outcomes if o.error is not None]
        no_flutter = sum(o.error is None and o.speed is None for o in self.outcomes)
        mc: dict[str, Any] = {
            "n": len(self.outcomes), "fluttering": int(s.size), "no_flutter": no_flutter,
            "failed": len(failed), "failures": sorted(set(failed))[:5],
            "mean": float(s.mean()) if s.size else None, "std": self.mc_std,
            "quantiles": ({f"{q:g}": float(x) for q, x in zip(QUANTILES, np.quantile(s, QUANTILES),
                                                                strict=True)}
                          if s.size else None),
            "seed": self.seed, "U_max": self.U_max}
        out: dict[str, Any] = {
            "source": self.source, "flutter_speed": self.speed, "monte_carlo": mc,
            "delta_std": None if self.delta is None else self.delta.std,
            "units": {"flutter_speed": "m/s", "delta_std": "m/s", "mean": "m/s", "std": "m/s",
                      "quantiles": "m/s", "U_max": "m/s", "gradient": "m/s per parameter"},
            "warnings": list(self.warnings)}
        if self.delta is not None:
            out["gradient"] = dict(zip(self.delta.parameters, self.delta.gradient.tolist(),
                                       strict=True))
            mc_std = self.mc_std
            out["std_ratio"] = None if mc_std is None or self.delta.std == 0.0 else (
                self.delta.std / mc_std)
        return out


def summarise(source: str, speed: float | None, delta: DeltaMethod | None,
              outcomes: list[SampleOutcome], U_max: float, seed: int) -> Uncertainty:
    """Collect the two estimates and say what a reader must know (module docstring)."""
    warnings: list[str] = []
    result = Uncertainty(source, speed, delta, outcomes, U_max, seed, warnings)
    n = len(outcomes)
    failed = sum(o.error is not None for o in outcomes)
    no_flutter = sum(o.error is None and o.speed is None for o in outcomes)
    if failed:
        warnings.append(f"{failed} of {n} samples could not be analysed by the fast route (see "
                        "monte_carlo.failures): the distribution leaves them out")
    if no_flutter:
        warnings.append(f"{no_flutter} of {n} samples do not flutter below {U_max:.4g} m/s: the "
                        "Monte Carlo mean and std leave them out and understate the spread")
    mc_std = result.mc_std
    if delta is not None and mc_std is not None and mc_std > 0.0:
        ratio = delta.std / mc_std
        if abs(ratio - 1.0) > AGREEMENT:
            warnings.append(
                f"the delta-method std ({delta.std:.4g} m/s) and the Monte Carlo std "
                f"({mc_std:.4g} m/s, {n} samples) differ by {100 * (ratio - 1):+.0f} %: the "
                "flutter speed is not linear in the section parameters over their spread "
                "(or the samples are too few); the Monte Carlo distribution is the one to use")
    if mc_std is not None and n < 100:
        warnings.append(f"only {n} samples: the Monte Carlo std itself is uncertain by about "
                        f"{100 / math.sqrt(2 * (n - 1)):.0f} %")
    return result
