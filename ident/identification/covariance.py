"""An identified model's parameter covariance as a file carries it, and samples drawn from it.

E2RFC estimates the entries of ``A`` it fits and the logarithms of the lag roots ``d``
(:class:`~ident.identification.results.E2RFCDiagnostics`: ``covariance`` and
``parameter_index``). ``windrig identify --json`` writes them as ``model_covariance``
(:meth:`ModelCovariance.to_dict`) so that a later analysis (the full bridge's flutter speed,
:mod:`ident.bridge.uncertainty`) can carry the section's measurement noise further without the
run files. The parameters, in order: ``A[k, i, j]`` for each ``(k, i, j)`` of
``parameter_index`` (the entries not listed were not fitted: zero, and certain), then
``log(d_l)`` for every lag (non-dimensional; ``d`` itself must stay positive, which a normal
distribution of ``log d`` keeps).

Not responsible for: estimating the covariance (:mod:`ident.identification.e2rfc`), what the
flutter speed's std is made of (:mod:`ident.identification.uncertainty`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from ident.model.rfc import RationalFunctionModel

if TYPE_CHECKING:  # annotations only: results does not import this module, no cycle
    from ident.identification.results import IdentifiedModel

__all__ = ["ModelCovariance"]

FloatArray = npt.NDArray[np.float64]

#: Relative asymmetry of a read covariance accepted as round-off (JSON keeps 17 digits; a
#: matrix written by another tool may have been symmetrised less carefully).
_SYMMETRY_RTOL = 1e-8
#: Most negative eigenvalue, relative to the largest, accepted as round-off of a positive
#: semi-definite matrix (a least-squares covariance of a nearly collinear fit).
_PSD_RTOL = 1e-9


@dataclass(frozen=True, eq=False)
class ModelCovariance:
    """Covariance of a rational-function model's fitted parameters (module docstring).

    Attributes
    ----------
    parameter_index : tuple of (int, int, int)
        ``(k, i, j)`` of ``A[k, i, j]`` for each of the first ``len(parameter_index)``
        parameters.
    n_lags : int
        The lag roots' ``log d`` parameters that follow.
    matrix : ndarray, shape (p, p)
        Symmetric, positive semi-definite; units: those of ``A`` (non-dimensional) and of
        ``log d`` (non-dimensional).
    """

    parameter_index: tuple[tuple[int, int, int], ...]
    n_lags: int
    matrix: FloatArray

    def __post_init__(self) -> None:
        p = len(self.parameter_index) + self.n_lags
        matrix = np.asarray(self.matrix, dtype=float)
        if matrix.shape != (p, p):
            raise ValueError(f"the covariance must be {p} x {p} ({len(self.parameter_index)} "
                             f"coefficients and {self.n_lags} lag roots), got shape "
                             f"{matrix.shape}")
        if not np.all(np.isfinite(matrix)):
            raise ValueError("the covariance holds a value that is not finite")
        scale = float(np.max(np.abs(matrix))) if matrix.size else 0.0
        if np.max(np.abs(matrix - matrix.T), initial=0.0) > _SYMMETRY_RTOL * scale:
            raise ValueError("the covariance is not symmetric")
        if matrix.size and float(np.linalg.eigvalsh(matrix).min()) < -_PSD_RTOL * scale:
            raise ValueError("the covariance is not positive semi-definite (a negative "
                             "variance)")
        object.__setattr__(self, "matrix", 0.5 * (matrix + matrix.T))

    @classmethod
    def of(cls, model: IdentifiedModel) -> ModelCovariance:
        """Return an E2RFC model's covariance (its diagnostics', :meth:`from_estimate`)."""
        diagnostics = model.diagnostics
        return cls.from_estimate(tuple(diagnostics.parameter_index), model.n_lags,
                                 diagnostics.covariance)

    @classmethod
    def from_estimate(cls, parameter_index: tuple[tuple[int, int, int], ...], n_lags: int,
                      matrix: FloatArray) -> ModelCovariance:
        """Return an estimated covariance symmetrised, its negative eigenvalues set to zero.

        E2RFC's covariance is a pseudo-inverse of ``J^T J`` (positive semi-definite), which
        round-off leaves slightly asymmetric and, for an ill-conditioned fit, with eigenvalues
        of about ``-eps cond``; what a file carries must pass :meth:`from_dict`'s checks, which
        stay strict for a matrix a user gives.
        """
        matrix = np.asarray(matrix, dtype=float)
        matrix = 0.5 * (matrix + matrix.T)
        if matrix.size and np.all(np.isfinite(matrix)):
            values, vectors = np.linalg.eigh(matrix)
            if values.min() < 0.0:
                matrix = (vectors * np.clip(values, 0.0, None)) @ vectors.T
                matrix = 0.5 * (matrix + matrix.T)
        return cls(parameter_index, n_lags, matrix)

    @property
    def size(self) -> int:
        """Number of parameters ``p``."""
        return len(self.parameter_index) + self.n_lags

    def check_model(self, model: RationalFunctionModel, where: str = "") -> None:
        """Raise ``ValueError`` unless ``model`` has every indexed entry and exactly the lags."""
        if model.n_lags != self.n_lags:
            raise ValueError(f"{where}the covariance has {self.n_lags} lag root(s), the model "
                             f"{model.n_lags}")
        shape = model.A.shape
        for k, i, j in self.parameter_index:
            if not (0 <= k < shape[0] and 0 <= i < shape[1] and 0 <= j < shape[2]):
                raise ValueError(f"{where}the covariance names A[{k}, {i}, {j}], which a model "
                                 f"of shape {list(shape)} does not have")

    def parameters(self, model: RationalFunctionModel) -> FloatArray:
        """Return ``model``'s parameter vector: the indexed ``A`` entries, then ``log d``."""
        return np.concatenate([[model.A[k, i, j] for k, i, j in self.parameter_index],
                               np.log(model.d)])

    def model_at(self, model: RationalFunctionModel, theta: FloatArray) -> RationalFunctionModel:
        """Return ``model`` with the parameters ``theta`` (the unindexed entries kept)."""
        A = model.A.copy()
        n = len(self.parameter_index)
        for value, (k, i, j) in zip(theta[:n], self.parameter_index, strict=True):
            A[k, i, j] = value
        return RationalFunctionModel(A, np.exp(theta[n:]))

    def sample(self, model: RationalFunctionModel, n: int,
               rng: np.random.Generator) -> list[RationalFunctionModel]:
        """Draw ``n`` models from the normal distribution about ``model``.

        Drawn through the symmetric square root of the covariance (its eigenvectors), which a
        semi-definite matrix has and a Cholesky factor may not.
        """
        values, vectors = np.linalg.eigh(self.matrix)
        root = vectors * np.sqrt(np.clip(values, 0.0, None))
        theta0 = self.parameters(model)
        draws = theta0 + rng.standard_normal((n, self.size)) @ root.T
        return [self.model_at(model, theta) for theta in draws]

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form: ``parameters`` (names), ``index``, ``n_lags``, ``matrix``."""
        names = [f"A{k + 1}[{i},{j}]" for k, i, j in self.parameter_index]
        names += [f"log d{l + 1}" for l in range(self.n_lags)]  # noqa: E741 - lag index
        return {"parameters": names, "index": [list(t) for t in self.parameter_index],
                "n_lags": self.n_lags, "matrix": self.matrix.tolist(),
                "units": "A entries non-dimensional; lag roots as log(d), non-dimensional"}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ModelCovariance:
        """Build from :meth:`to_dict` output; a wrong shape or value raises ``ValueError``."""
        missing = {"index", "n_lags", "matrix"} - set(data)
        if missing:
            raise ValueError(f"the covariance is missing key(s) {sorted(missing)}")
        try:
            index = tuple((int(k), int(i), int(j)) for k, i, j in data["index"])
            n_lags = int(data["n_lags"])
            matrix = np.asarray(data["matrix"], dtype=float)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"the covariance's index, n_lags or matrix is malformed ({exc})"
                             ) from exc
        return cls(index, n_lags, matrix)
