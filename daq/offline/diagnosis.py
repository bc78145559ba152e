"""``windrig diagnose``: the discrepancy workflow on recorded run files, with its plots.

Responsibility: read the releases of one campaign's run files
(:func:`ident.records.run_file.read_run`, one section model), run
:func:`ident.discrepancy.workflow.diagnose` (E2RFC baseline), print its report and write three plots
(matplotlib, Agg) into the output directory:

- ``diagnose_decays.png``: h and alpha of one release per wind speed, measured against the
  baseline's and the refitted model's simulations;
- ``diagnose_backbone.png``: the backbone (instantaneous frequency against amplitude) and
  damping curves of the heave and pitch modes of those releases (Hilbert transform), measured
  against both models;
- ``diagnose_gap.png``: the gap of every release before and after;
- ``diagnose_residual.png``, only when the report is not explained: per channel with a
  systematic residual left, its averaged spectrum (the line found marked) and measured minus
  simulated of one release per wind speed.

Not responsible for: the numerics (:mod:`ident.discrepancy.workflow`) or reading files
(:mod:`ident.records.run_file`).
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ident.discrepancy.workflow import backbone, diagnose
from ident.errors import IdentError
from ident.records.run_file import read_run
from ident.records.run_set import campaign_section, recording_notes

__all__ = ["run_diagnose"]


def run_diagnose(files: Sequence[Path], out: Path, *, depth: float | None = None,
                 json_path: Path | None = None) -> int:
    """Diagnose the releases of ``files``; print the report, write the plots (and JSON).

    Parameters
    ----------
    files : sequence of Path
        Run files of one section model (two or more wind speeds).
    out : Path
        Directory of the plots (created).
    depth : float, optional
        Section depth, m, for the Strouhal number of a shedding line; default the ``depth`` of
        the first file's stored rig config (neither: a named shedding line's ``strouhal`` is
        per metre of depth, and a warning says so).
    json_path : Path, optional
        Write the report's numbers there.

    Returns
    -------
    int
        0, or 2 with a one-line message when a file cannot be used.
    """
    try:
        runs = [read_run(path) for path in files]
        section = campaign_section(runs)
        releases = [r for run in runs for r in run.releases]
        if depth is None:
            depth = runs[0].depth
        print(f"{len(releases)} release(s) from {len(runs)} file(s); wind speeds "
              f"{sorted({round(r.U, 2) for r in releases})} m/s")
        report = diagnose(releases, section, depth=depth)
    except (IdentError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(report.summary())
    # A file whose clocks had no trigger anchor holds motion and forces a latency apart,
    # which a channel delay found here may be: say so before any effect is believed.
    notes = recording_notes(runs)
    if depth is None and any(step.name == "vortex_shedding" for step in report.effects):
        # Without a depth the workflow reports St = k * 1 m (k the line's Hz per m/s): a
        # number that reads as a Strouhal number and is not one; say so, not silently.
        notes.append("no section depth (--depth, or depth in the stored config's [section]): "
                     "the shedding line's strouhal is its frequency per wind speed times 1 m "
                     "(Hz per m/s), not a Strouhal number")
    for note in notes:
        print(f"warning: {note}")
    out.mkdir(parents=True, exist_ok=True)
    for name, path in _plots(out, releases, report, section).items():
        print(f"plot {name}: {path}")
    if json_path is not None:
        json_path.write_text(json.dumps(_as_json(report, files, notes), indent=2))
        print(f"wrote {json_path}")
    return 0


def _as_json(report: Any, files: Sequence[Path], notes: Sequence[str]) -> dict[str, Any]:
    return {
        "files": [str(p) for p in files],
        "effect": report.effect,
        "effects": [{"effect": step.name, "parameters": step.parameters,
                     "uncertainty": step.uncertainty, "units": step.units,
                     "gap_after": step.gap_after} for step in report.effects],
        "explained": report.explained,
        "unexplained": [f.text() for f in report.unexplained],
        "parameters": report.parameters,
        "uncertainty": report.uncertainty,
        "gap_before": report.gap_before,
        "gap_after": report.gap_after,
        "gap_per_release": report.gap_per_release.tolist(),
        "runner_up": report.runner_up,
        "whiteness_before": report.whiteness_before,
        "whiteness_after": report.whiteness_after,
        # Candidates tried and undone by the gap rule (ident.discrepancy.gap_rule): named only
        # if the simulated gap shrinks by the margin; each with both gaps.
        "rejected": [{"effect": name, "gap_before": step.before, "gap_after": step.after,
                      "required_shrink": step.required} for name, step in report.rejected],
        "evidence": [{"effect": ev.effect, "parameters": ev.parameters, "std": ev.std,
                      "cv_ratio": ev.cv_ratio, "cv_ratio_se": ev.cv_ratio_se,
                      "verdict": ev.verdict} for ev in report.evidence],
        "units": {"gap_before": "1 (RMS gap of each channel over its RMS, averaged)",
                  "gap_after": "1 (as gap_before)", "parameters": "per effect: see units"},
        # What the named effects leave unexplained is what a reader must know first.
        "warnings": [f.text() for f in report.unexplained] + list(notes),
    }


def _plots(out: Path, releases: list[Any], report: Any, section: Any) -> dict[str, Path]:
    import matplotlib  # here: the backend is chosen before pyplot loads, only when plotting

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # One release per wind speed: the first at each.
    chosen: dict[float, int] = {}
    for i, r in enumerate(releases):
        chosen.setdefault(round(r.U, 1), i)
    picks = list(chosen.values())
    after_label = ("baseline" if report.effect is None
                   else "with " + " + ".join(step.name for step in report.effects))
    plots: dict[str, Path] = {}

    fig, axes = plt.subplots(2, len(picks), figsize=(5 * len(picks), 6), squeeze=False,
                             sharex=True)
    for col, i in enumerate(picks):
        r = releases[i]
        for row, (name, scale, unit) in enumerate((("h", 1e3, "mm"),
                                                   ("alpha", 180 / math.pi, "deg"))):
            ax = axes[row, col]
            ax.plot(r.t, getattr(r, name) * scale, "k", lw=0.6, label="measured")
            ax.plot(r.t, report.simulated_before[i][name] * scale, "tab:red", lw=0.9,
                    label="baseline")
            if report.effect is not None:
                ax.plot(r.t, report.simulated_after[i][name] * scale, "tab:blue", lw=0.9,
                        ls="--", label=after_label)
            ax.set_ylabel(f"{name} ({unit})")
            if row == 0:
                ax.set_title(f"U = {r.U:.2f} m/s")
        axes[1, col].set_xlabel("time from release (s)")
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    plots["decays"] = out / "diagnose_decays.png"
    fig.savefig(plots["decays"], dpi=100)
    plt.close(fig)

    fig, axes = plt.subplots(2, 2, figsize=(11, 7))
    for col, (name, f0, scale, unit) in enumerate((("h", section.fh, 1e3, "mm"),
                                                   ("alpha", section.fa, 180 / math.pi,
                                                    "deg"))):
        seen: dict[int, list[Any]] = {0: [], 1: []}  # measured frequency, damping
        for i in picks:
            r = releases[i]
            for data, style, label in ((getattr(r, name), "k.", "measured"),
                                       (report.simulated_before[i][name], "r-", "baseline"),
                                       (report.simulated_after[i][name], "b--", after_label)):
                if label == after_label and report.effect is None:
                    continue
                curve = backbone(r.t, np.asarray(data), _mode_frequency(r, name, f0))
                axes[0, col].plot(curve.amplitude * scale, curve.frequency, style, ms=1,
                                  lw=0.8, label=label if i == picks[0] else None)
                axes[1, col].plot(curve.amplitude * scale, curve.damping, style, ms=1,
                                  lw=0.8)
                if label == "measured":
                    seen[0].append(curve.frequency)
                    seen[1].append(curve.damping)
        for row in (0, 1):  # the bulk of the measured curves (their ends are noisy)
            values = np.concatenate(seen[row]) if seen[row] else np.zeros(0)
            if values.size:
                lo, hi = np.percentile(values, [2, 98])
                pad = 0.15 * (hi - lo) + 1e-6
                axes[row, col].set_ylim(lo - pad, hi + pad)
        axes[0, col].set_title(f"{name} mode")
        axes[0, col].set_ylabel("frequency (Hz)")
        axes[1, col].set_ylabel("damping ratio")
        axes[1, col].set_xlabel(f"amplitude ({unit})")
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    plots["backbone"] = out / "diagnose_backbone.png"
    fig.savefig(plots["backbone"], dpi=100)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(8, 4))
    n = len(releases)
    x = np.arange(n)
    ax.bar(x - 0.2, report.gap_per_release[:, 0], 0.4, color="tab:red", label="baseline")
    ax.bar(x + 0.2, report.gap_per_release[:, 1], 0.4, color="tab:blue", label=after_label)
    ax.set_xticks(x, [f"#{i} {r.U:.1f} m/s" for i, r in enumerate(releases)], rotation=45,
                  fontsize=8)
    ax.set_ylabel("gap (normalised RMS difference)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    plots["gap"] = out / "diagnose_gap.png"
    fig.savefig(plots["gap"], dpi=100)
    plt.close(fig)
    if report.unexplained:
        plots["residual"] = _residual_plot(plt, out, releases, report, picks)
    return plots


def _residual_plot(plt: Any, out: Path, releases: list[Any], report: Any,
                   picks: list[int]) -> Path:
    """Plot where the unexplained residual is: its spectrum and time history, per channel."""
    from scipy.signal import welch

    findings = report.unexplained
    fig, axes = plt.subplots(len(findings), 2, figsize=(12, 3.2 * len(findings)),
                             squeeze=False)
    for row, finding in enumerate(findings):
        name = finding.channel
        spectra = []
        for i, r in enumerate(releases):
            e = np.asarray(getattr(r, name)) - report.simulated_after[i][name]
            spectra.append(welch(e - e.mean(), fs=r.fs, nperseg=min(e.size, int(2 * r.fs))))
        f = spectra[0][0]  # the releases' lengths may differ: on the first one's grid
        axes[row, 0].semilogy(f, np.mean([np.interp(f, fi, pi) for fi, pi in spectra], axis=0),
                              "k", lw=0.8)
        if finding.line_hz is not None:
            axes[row, 0].axvline(finding.line_hz, color="tab:red", ls="--",
                                 label=f"line {finding.line_hz:.2f} Hz")
            axes[row, 0].legend(fontsize=8)
        axes[row, 0].set_xlim(0, min(50.0, f[-1]))
        axes[row, 0].set_xlabel("frequency (Hz)")
        axes[row, 0].set_ylabel(f"{name} residual PSD")
        axes[row, 0].set_title(f"{name}: systematic {finding.systematic:.1%} of RMS, "
                               f"noise {finding.noise:.1%}", fontsize=9)
        for i in picks:
            r = releases[i]
            e = np.asarray(getattr(r, name)) - report.simulated_after[i][name]
            axes[row, 1].plot(r.t, e, lw=0.6, label=f"{r.U:.1f} m/s")
        axes[row, 1].set_xlabel("time from release (s)")
        axes[row, 1].set_ylabel(f"{name}: measured - model")
        axes[row, 1].legend(fontsize=8)
    fig.tight_layout()
    path = out / "diagnose_residual.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _mode_frequency(release: Any, channel: str, still_air: float) -> float:
    """Return the frequency of the mode dominating ``channel`` (spectral peak near still air)."""
    x = np.asarray(getattr(release, channel), dtype=float)
    spectrum = np.abs(np.fft.rfft(x - x.mean()))
    freq = np.fft.rfftfreq(x.size, d=float(release.t[1] - release.t[0]))
    near = (freq > 0.6 * still_air) & (freq < 1.4 * still_air)
    return float(freq[near][np.argmax(spectrum[near])]) if near.any() else still_air
