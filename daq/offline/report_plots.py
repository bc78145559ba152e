"""The two report plots every campaign page shares: flutter derivatives and the flutter diagram.

``windrig demo``, ``windrig campaign`` and ``windrig reprocess`` each draw them from their own
data (a live analysis, a campaign's outcome, a cached summary); the drawing is here once so that
the three pages look alike and a change of style happens in one place.

Matplotlib is imported inside the functions, after choosing the non-interactive ``Agg`` backend:
importing :mod:`daq` never loads a GUI toolkit, and plots can be written on a headless host.

Not responsible for: which curves to draw or where the files go (the callers), the console's
live plots (:mod:`daq.console`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from ident.model.flutter import FlutterResult

__all__ = ["DerivativeCurves", "ModeCurves", "flutter_derivative_grid", "flutter_diagram"]

FloatArray = npt.NDArray[np.float64]


class DerivativeCurves(NamedTuple):
    """One set of flutter derivatives to draw.

    Attributes
    ----------
    label : str
        Legend text (e.g. ``"truth"``, ``"identified"``); empty for no legend entry.
    style : str
        Matplotlib format string, e.g. ``"k-"``.
    values : mapping of str to ndarray
        Derivative name (``"H1"`` ... ``"A4"``) to its values at the grid's reduced frequencies.
    """

    label: str
    style: str
    values: Mapping[str, FloatArray]


class ModeCurves(NamedTuple):
    """One flutter analysis to draw in the flutter diagram.

    Attributes
    ----------
    result : FlutterResult
        Frequencies and damping ratios of every branch against U.
    style : str
        Line style, e.g. ``"-"`` or ``"--"``.
    label : str
        Appended to each branch's name in the legend (``"heave, truth"``).
    """

    result: FlutterResult
    style: str
    label: str


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def flutter_derivative_grid(path: Path, K: FloatArray, curves: Sequence[DerivativeCurves], *,
                            title: str | None = None, dpi: int = 100) -> Path:
    """Draw the flutter derivatives against the reduced velocity ``1/K``, one panel each.

    Parameters
    ----------
    path : Path
        PNG file to write.
    K : ndarray, shape (n,)
        Reduced frequencies ``B omega / U`` (dimensionless) the values are given at.
    curves : sequence of DerivativeCurves
        Drawn in order; the panels are those of the first set's derivatives (in its order).
    title : str, optional
        Figure title.
    dpi : int
        Resolution of the PNG, dots per inch.

    Returns
    -------
    Path
        ``path``.
    """
    plt = _pyplot()
    names = list(curves[0].values) if curves else []
    rows = max(1, -(-len(names) // 4))
    fig, grid = plt.subplots(rows, 4, figsize=(14, 3 * rows), squeeze=False)
    for ax, name in zip(grid.ravel(), names, strict=False):
        for curve in curves:
            if name in curve.values:
                ax.plot(1.0 / K, curve.values[name], curve.style, lw=1.2,
                        label=curve.label or None)
        ax.set_title(f"{name}*")
        ax.set_xlabel("1/K = U/(B omega)")
    for ax in grid.ravel()[len(names):]:  # 18 derivatives (3 DOF) leave two panels empty
        ax.set_visible(False)
    if any(curve.label for curve in curves):
        grid[0, 0].legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


def flutter_diagram(path: Path, curves: Sequence[ModeCurves], tested: Sequence[float], *,
                    title: str, damping_top: float, U_limit: float | None = None,
                    dpi: int = 100) -> Path:
    """Draw frequency and damping ratio of every branch against U, the speeds tested marked.

    Parameters
    ----------
    path : Path
        PNG file to write.
    curves : sequence of ModeCurves
        The analyses to compare (e.g. truth with ``"-"``, identified with ``"--"``); each one's
        flutter speed is a vertical line in its style.
    tested : sequence of float
        Wind speeds released at, m/s (thin green lines).
    title : str
        Title above the frequency panel.
    damping_top : float
        Upper limit of the damping-ratio axis (the lower is -0.05: what matters is the zero
        crossing, not how far an overdamped branch goes).
    U_limit : float, optional
        Upper limit of the wind-speed axis, m/s (default: the analyses' range).
    dpi : int
        Resolution of the PNG, dots per inch.

    Returns
    -------
    Path
        ``path``.
    """
    plt = _pyplot()
    fig, (ax_f, ax_z) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    for curve in curves:
        res = curve.result
        for j, mode in enumerate(res.mode_names):
            ax_f.plot(res.U, res.frequencies[:, j], curve.style, label=f"{mode}, {curve.label}")
            ax_z.plot(res.U, res.damping[:, j], curve.style, label=f"{mode}, {curve.label}")
        if res.speed is not None:
            ax_z.axvline(res.speed, ls=curve.style, color="grey", lw=0.8)
    for U in tested:
        ax_z.axvline(U, color="tab:green", lw=0.5, alpha=0.6)
    ax_z.axhline(0.0, color="k", lw=0.6)
    ax_z.set_ylim(-0.05, damping_top)
    if U_limit is not None:
        ax_z.set_xlim(0.0, U_limit)
    ax_f.set_ylabel("frequency (Hz)")
    ax_z.set_ylabel("damping ratio")
    ax_z.set_xlabel("U (m/s)")
    ax_f.legend(fontsize=8)
    ax_f.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path
