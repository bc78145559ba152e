"""Choosing a rational-function structure (number of lags, added mass) by held-out error.

Shared by E2RFC (:mod:`ident.identification.e2rfc`) and the flutter-derivative route
(:mod:`ident.identification.fd_method`): both score every candidate structure by a held-out error
with a standard error, then keep the simplest structure whose error is within one standard error of
the best (the one-standard-error rule of Hastie, Tibshirani and Friedman), which guards against
fitting noise with extra lags.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Candidate", "select_one_se", "structure_label", "within_one_se"]


@dataclass(frozen=True)
class Candidate:
    """One model structure tried during selection.

    Attributes
    ----------
    n_lags : int
    with_A3 : bool
    d : tuple of float
        Lag roots found for this structure (non-dimensional).
    cv_error : float
        Held-out error; its scale is the caller's (see the identifying module). NaN for a
        structure given by the caller (not scored).
    cv_se : float
        Standard error of ``cv_error`` over the folds.
    n_params : int
        Parameters fitted (coefficients and lag roots).
    note : str
        Why the structure was skipped, when it was (empty otherwise).
    """

    n_lags: int
    with_A3: bool
    d: tuple[float, ...]
    cv_error: float
    cv_se: float
    n_params: int
    note: str = ""

    @property
    def label(self) -> str:
        """Short description, e.g. ``n_lags=2, A3=fitted``."""
        return structure_label(self.n_lags, self.with_A3)


def structure_label(n_lags: int, with_A3: bool) -> str:
    """Short description of a structure, e.g. ``n_lags=2, A3=fitted``."""
    return f"n_lags={n_lags}, A3={'fitted' if with_A3 else 'zero'}"


def select_one_se(usable: list[Candidate], *, given: bool) -> tuple[Candidate, str]:
    """Choose a structure by the one-standard-error rule; return it and the reason in words.

    Parameters
    ----------
    usable : list of Candidate
        Scored candidates (none skipped); not empty.
    given : bool
        The caller fixed the structure: return the first candidate as "given by the caller".
    """
    if given:
        return usable[0], "given by the caller"
    best = min(usable, key=lambda c: c.cv_error)
    simple = min(within_one_se(usable), key=lambda c: c.n_params)
    reason = (
        f"{simple.label}: the simplest structure whose held-out error ({simple.cv_error:.4g}) is "
        f"within one standard error of the best ({best.cv_error:.4g} +/- {best.cv_se:.2g}, "
        f"{best.label})"
    )
    return simple, reason


def within_one_se(usable: list[Candidate]) -> list[Candidate]:
    """Return the scored candidates whose held-out error is within one standard error of the best.

    The data do not tell these structures apart: the one-standard-error rule picks the simplest
    of them, and the spread of what they predict is an uncertainty of the model's structure
    that the chosen structure's parameter covariance does not hold.

    Parameters
    ----------
    usable : list of Candidate
        Scored candidates (none skipped); not empty.

    Returns
    -------
    list of Candidate
        In the order given.
    """
    best = min(usable, key=lambda c: c.cv_error)
    threshold = best.cv_error + best.cv_se
    return [c for c in usable if c.cv_error <= threshold]
