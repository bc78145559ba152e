"""The flutter derivatives of an identified model as a printed table, and its degrees of freedom.

Responsibility: :func:`derivative_rows` and :func:`format_derivative_table` give the flutter
derivatives of a rational-function model (``H1*..A4*``, or with sway all 18 ``H1*..H6*,
A1*..A6*, P1*..P6*`` in the order of :func:`ident.model.conventions.derivative_names`, Scanlan's
signs of ``docs/conventions.md``) at a few reduced frequencies spanning what the releases
measured, one line per derivative; ``windrig identify`` prints it for a run of three degrees of
freedom. :func:`check_model_dof` refuses a model with fewer degrees of freedom than its
section, such as an identification that ignored the sway.

Not responsible for: identifying the model (:mod:`ident.identification.e2rfc`) or the command line
(:mod:`daq.offline.flutter_commands`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from ident.errors import IdentError
from ident.model.conventions import derivative_names
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel

__all__ = ["TABLE_POINTS", "check_model_dof", "derivative_rows", "format_derivative_table"]

#: Reduced frequencies printed, evenly spread over the span the releases cover.
TABLE_POINTS = 5


def derivative_rows(model: RationalFunctionModel,
                    K_span: npt.ArrayLike) -> tuple[npt.NDArray[np.float64], dict[str, Any]]:
    """Return the printed reduced frequencies and each derivative's values there.

    Parameters
    ----------
    model : RationalFunctionModel
        2 or 3 degrees of freedom.
    K_span : array_like
        Reduced frequencies ``B omega / U`` the releases cover (their minimum and maximum
        bound the table).

    Returns
    -------
    K : ndarray, shape (TABLE_POINTS,)
    values : dict of str to ndarray
        ``derivative_names(model.n_dof)`` in order, each of shape ``K.shape``.
    """
    span = np.asarray(K_span, dtype=float)
    K = np.linspace(float(np.min(span)), float(np.max(span)), TABLE_POINTS)
    derivatives = model.flutter_derivatives(K)
    return K, {name: np.asarray(derivatives[name], dtype=float)
               for name in derivative_names(model.n_dof)}


def format_derivative_table(model: RationalFunctionModel, K_span: npt.ArrayLike) -> list[str]:
    """Return the table's lines: a header of K and 1/K, then one line per derivative.

    Examples
    --------
    >>> from ident.model.flat_plate import jones_model
    >>> lines = format_derivative_table(jones_model(), [0.5, 1.0])
    >>> len(lines), lines[2].split()[0]
    (10, 'H1*')
    """
    K, values = derivative_rows(model, K_span)
    lines = ["flutter derivatives (Scanlan's signs, docs/conventions.md):",
             f"{'K':>8}" + "".join(f"{k:>11.4f}" for k in K)]
    lines[1] += "   (1/K " + ", ".join(f"{1.0 / k:.3g}" for k in K) + ")"
    lines.extend(f"{name + '*':>8}" + "".join(f"{v:>11.4g}" for v in column)
                 for name, column in values.items())
    return lines


def check_model_dof(model: RationalFunctionModel, section: SectionModel) -> None:
    """Raise IdentError when the model has fewer degrees of freedom than the section.

    A 2-DOF model of a section with sway (``fp``) leaves out the drag and the sway forces: its
    flutter speed would be that of another structure.
    """
    if model.n_dof != section.n_dof:
        raise IdentError(
            f"the identified model has {model.n_dof} degrees of freedom, the section "
            f"{section.n_dof} (fp = {section.fp} Hz): E2RFC did not identify the sway and drag "
            "terms; a 3-DOF campaign needs E2RFC in 3x3")
