"""Plots and a table of a bridge's buffeting response: RMS along the span and response spectra.

``windrig bridge --buffeting ... --out DIR`` writes them (:mod:`daq.offline.bridge_commands`):

- ``buffeting_rms.png``: RMS of h (m), alpha (rad) and p (m) along the deck at every mean wind
  speed, frequency domain as lines, the time-domain simulation (if any) as markers;
- ``buffeting_spectra.png``: the one-sided response spectra (frequency domain) at the node
  where the RMS of each component is largest among the nodes that kept spectra;
- ``buffeting_rms.csv``: the RMS at every node and speed (columns ``U_m_s, x_m, method,
  rms_h_m, rms_alpha_rad, rms_p_m``).

Matplotlib is imported inside the function after choosing the ``Agg`` backend, as in
:mod:`daq.offline.report_plots`: a headless host can write the plots.

Not responsible for: the numerics (:mod:`ident.bridge.buffeting`,
:mod:`ident.bridge.buffeting_time`).
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ident.bridge.buffeting import BuffetingResponse

__all__ = ["write_buffeting_outputs"]

_COMPONENTS = (("h", "h (m)"), ("alpha", "alpha (rad)"), ("p", "p (m)"))
_SPECTRUM_LABELS = {"h": "S_h (m^2/Hz)", "alpha": "S_alpha (rad^2/Hz)", "p": "S_p (m^2/Hz)"}


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def write_buffeting_outputs(out: Path, frequency: Sequence[BuffetingResponse],
                            time: Sequence[BuffetingResponse] = (), *,
                            dpi: int = 100) -> list[Path]:
    """Write the RMS table and the two plots of the module docstring into ``out``.

    Parameters
    ----------
    out : Path
        Folder (created if missing).
    frequency : sequence of BuffetingResponse
        Frequency-domain responses, one per mean wind speed (with spectra).
    time : sequence of BuffetingResponse
        Time-domain responses at some of those speeds (may be empty).
    dpi : int
        Resolution of the PNG files.

    Returns
    -------
    list of Path
        The files written.
    """
    out.mkdir(parents=True, exist_ok=True)
    table = out / "buffeting_rms.csv"
    with table.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(["U_m_s", "x_m", "method", "rms_h_m", "rms_alpha_rad", "rms_p_m"])
        for r in (*frequency, *time):
            for k, x in enumerate(r.x):
                writer.writerow([f"{r.U:.6g}", f"{x:.6g}", r.method, f"{r.rms_h[k]:.6g}",
                                 f"{r.rms_alpha[k]:.6g}", f"{r.rms_p[k]:.6g}"])
    plt = _pyplot()
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]

    fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    for i, r in enumerate(frequency):
        color = colors[i % len(colors)]
        for ax, (name, label) in zip(axes, _COMPONENTS, strict=True):
            ax.plot(r.x, getattr(r, f"rms_{name}"), "-", color=color,
                    label=f"U = {r.U:g} m/s, frequency domain")
            ax.set_ylabel(f"RMS {label}")
        for t in time:
            if t.U == r.U:
                for ax, (name, _) in zip(axes, _COMPONENTS, strict=True):
                    ax.plot(t.x, getattr(t, f"rms_{name}"), "o", ms=3, color=color,
                            label=f"U = {t.U:g} m/s, time domain ({t.duration:.4g} s)")
    axes[0].legend(fontsize=7)
    axes[-1].set_xlabel("x along the deck (m)")
    axes[0].set_title("buffeting RMS along the span")
    fig.tight_layout()
    rms_plot = out / "buffeting_rms.png"
    fig.savefig(rms_plot, dpi=dpi)
    plt.close(fig)

    fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    for i, r in enumerate(frequency):
        color = colors[i % len(colors)]
        for ax, (name, _) in zip(axes, _COMPONENTS, strict=True):
            S = r.spectra.get(name)
            if S is None or S.size == 0 or r.f.size < 2:
                continue
            j = int(np.argmax(np.trapezoid(S, r.f, axis=0)))
            keep = (r.f > 0.0) & (S[:, j] > 0.0)
            if not np.any(keep):
                continue
            node = int(r.spectrum_nodes[j])
            ax.loglog(r.f[keep], S[keep, j], "-", color=color,
                      label=f"U = {r.U:g} m/s, x = {r.x[node]:.4g} m")
            ax.set_ylabel(_SPECTRUM_LABELS[name])
            ax.legend(fontsize=7)
    axes[-1].set_xlabel("frequency (Hz)")
    axes[0].set_title("buffeting response spectra (frequency domain)")
    fig.tight_layout()
    spectra_plot = out / "buffeting_spectra.png"
    fig.savefig(spectra_plot, dpi=dpi)
    plt.close(fig)
    return [table, rms_plot, spectra_plot]
