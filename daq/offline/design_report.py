"""The design report of ``windrig flutter --out`` and ``windrig bridge --out``: one page to sign.

A Markdown page (``report.md``) with its PNGs: the inputs and their SHA-256 (what the numbers
were computed from, so that a reviewer can tell the files are the ones meant), both routes'
flutter speeds and the one the result rests on, the divergence and its basis, the table against
its fit for every derivative with the flutter K marked, frequency and damping against U only
where the table holds (a table's branch is drawn while its reduced frequency lies within the
table), the buffeting RMS (bridges), every warning, units everywhere.

Matplotlib is imported inside the functions with the ``Agg`` backend (headless hosts).

Not responsible for: the numbers (:mod:`ident.tables.flutter_routes`, :mod:`ident.bridge`), the
JSON (the commands write it from the same summary).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["file_hashes", "write_bridge_report", "write_section_report"]

FloatArray = npt.NDArray[np.float64]


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def file_hashes(paths: Sequence[Path]) -> list[tuple[str, str]]:
    """Return ``(path, SHA-256 hex digest)`` of each input file."""
    return [(str(p), hashlib.sha256(Path(p).read_bytes()).hexdigest()) for p in paths]


def _number(value: Any, unit: str = "", digits: int = 4) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "none"
    return f"{value:.{digits}g}{(' ' + unit) if unit else ''}"


def _result_lines(summary: Mapping[str, Any]) -> list[str]:
    """Return the result table: both routes, the basis, the flutter K, divergence (Markdown)."""
    K_range = summary.get("table_K_range")
    difference = summary.get("route_difference")
    result = summary.get("result", {})
    rows = [
        ("flutter speed (the result)", _number(result.get("flutter_speed"), "m/s")),
        ("rests on", f"{result.get('basis')}: {result.get('basis_reason')}"),
        ("state-space route", _number(summary.get("flutter_speed"), "m/s")),
        ("frequency-domain route", _number(summary.get("flutter_speed_frequency_domain"),
                                           "m/s")),
        ("difference (frequency domain / state space - 1)",
         "none" if difference is None else f"{100 * difference:+.2f} % (tolerance "
                                           f"{100 * summary.get('route_tolerance', 0.0):g} %)"),
        ("flutter frequency (the result)", _number(result.get("flutter_frequency"), "Hz")),
        ("flutter reduced frequency K = B omega / U",
         _number(result.get("reduced_frequency"))),
        ("critical branch or mode", str(result.get("critical_mode"))),
        ("table's K range", "no table" if not K_range else
         f"{K_range[0]:.4g} to {K_range[1]:.4g} (reduced velocity U/(fB) "
         f"{2 * math.pi / K_range[1]:.3g} to {2 * math.pi / K_range[0]:.3g})"),
        ("divergence speed", f"{_number(summary.get('divergence_speed'), 'm/s')} "
                             f"({summary.get('divergence_basis')})"),
    ]
    lines = ["| quantity | value |", "|---|---|"]
    lines += [f"| {name} | {value} |" for name, value in rows]
    errors = summary.get("fit_error_at_flutter")
    if errors:
        lines += ["", "Fit error at the flutter K (each derivative's error over its force's "
                      "size there):", "", "| derivative | error |", "|---|---|"]
        lines += [f"| {name}* | {100 * value:.2g} % |" for name, value in errors.items()]
    return lines


def _warning_lines(warnings: Sequence[str]) -> list[str]:
    if not warnings:
        return ["None."]
    return [f"- {w}" for w in warnings]


def _input_lines(inputs: Sequence[Path], defaults: Sequence[str]) -> list[str]:
    from importlib.metadata import version

    lines = [f"Computed by windrig {version('windrig')}.", "", "| file | SHA-256 |", "|---|---|"]
    lines += [f"| `{path}` | `{digest}` |" for path, digest in file_hashes(inputs)]
    if defaults:
        lines += ["", "Defaults taken for what the inputs left out:", ""]
        lines += [f"- {d}" for d in defaults]
    return lines


def derivative_plot(path: Path, table: Any, model: Any, K_flutter: float | None) -> Path:
    """Each flutter derivative: the table's rows and the fit between them, the flutter K marked.

    Drawn against the reduced velocity ``U/(fB) = 2 pi / K``, the fit over the table's range.
    """
    plt = _pyplot()
    names = list(table.values)
    K_fine = np.geomspace(float(table.K[0]), float(table.K[-1]), 300)
    fitted = model.flutter_derivatives(K_fine)
    rows = -(-len(names) // 4)
    fig, grid = plt.subplots(rows, 4, figsize=(14, 2.8 * rows), squeeze=False)
    for ax, name in zip(grid.ravel(), names, strict=False):
        ax.plot(2 * math.pi / table.K, table.values[name], "ko", ms=3, label="table")
        if name in fitted:
            ax.plot(2 * math.pi / K_fine, fitted[name], "r-", lw=1.0, label="Roger fit")
        if K_flutter is not None:
            ax.axvline(2 * math.pi / K_flutter, color="tab:blue", lw=0.8, ls="--",
                       label="flutter")
        ax.set_title(f"{name}*")
        ax.set_xlabel("U/(fB)")
    for ax in grid.ravel()[len(names):]:
        ax.set_visible(False)
    grid[0, 0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def mode_plot(path: Path, U: FloatArray, frequencies: FloatArray, damping: FloatArray,
              labels: Sequence[str], *, B: float, K_range: tuple[float, float] | None,
              speeds: Mapping[str, float | None]) -> Path:
    """Frequency (Hz) and damping ratio of every branch against U (m/s), within the table.

    A point is drawn only while its branch's reduced frequency ``2 pi f B / U`` lies within
    ``K_range`` (a model: everywhere); each route's flutter speed is a vertical line.
    """
    plt = _pyplot()
    f = np.array(frequencies, dtype=float)
    z = np.array(damping, dtype=float)
    if K_range is not None:
        with np.errstate(divide="ignore", invalid="ignore"):
            K = 2 * math.pi * f * B / np.asarray(U, dtype=float)[:, None]
        outside = ~((K >= K_range[0] * (1 - 1e-9)) & (K <= K_range[1] * (1 + 1e-9)))
        f[outside] = np.nan
        z[outside] = np.nan
    fig, (ax_f, ax_z) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    for j, label in enumerate(labels):
        ax_f.plot(U, f[:, j], label=label)
        ax_z.plot(U, z[:, j], label=label)
    for (name, speed), style in zip(speeds.items(), ("-", "--", ":"), strict=False):
        if speed is not None:
            ax_z.axvline(speed, color="grey", ls=style, lw=0.8, label=f"{name}")
    ax_z.axhline(0.0, color="k", lw=0.6)
    finite = z[np.isfinite(z)]
    ax_z.set_ylim(-0.05, max(0.05, float(finite.max()) if finite.size else 0.05))
    ax_f.set_ylabel("frequency (Hz)")
    ax_z.set_ylabel("damping ratio (1)")
    ax_z.set_xlabel("U (m/s)")
    ax_f.legend(fontsize=7, ncol=2)
    ax_z.legend(fontsize=7)
    ax_f.set_title("in-wind frequency and damping"
                   + ("" if K_range is None else " where the table holds"))
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def write_section_report(out: Path, routes: Any, summary: Mapping[str, Any],
                         inputs: Sequence[Path]) -> Path:
    """Write ``out/report.md`` for a section (``windrig flutter --out``); return its path.

    Parameters
    ----------
    out : Path
        Folder (created).
    routes : ident.tables.flutter_routes.SectionFlutter
        Both routes and their comparison.
    summary : mapping
        The command's JSON summary (the same numbers the JSON holds).
    inputs : sequence of Path
        The input files (hashed).
    """
    out.mkdir(parents=True, exist_ok=True)
    comparison = routes.comparison
    ss = routes.state_space
    section = summary["section"]
    lines = ["# Flutter of a section: design report", "",
             f"Section: B = {section['B']:g} m, {summary['n_dof']} degrees of freedom; "
             f"air density {section['rho']:g} kg/m^3.", "", "## Inputs", ""]
    lines += _input_lines(inputs, summary.get("defaults", []))
    lines += ["", "## Result", ""] + _result_lines(summary)
    lines += ["", "## Warnings", ""] + _warning_lines(summary.get("warnings", []))
    if routes.fit is not None:
        derivative_plot(out / "derivatives.png", routes.fit.table, routes.model,
                        comparison.reduced_frequency)
        lines += ["", "## Table and fit", "", f"{routes.fit.summary()}.", "",
                  "![flutter derivatives, table and fit](derivatives.png)"]
    mode_plot(out / "modes.png", ss.U, ss.frequencies, ss.damping, ss.mode_names,
              B=float(section["B"]), K_range=comparison.K_range,
              speeds={"state space": ss.speed,
                      "frequency domain": routes.frequency_domain.speed})
    lines += ["", "## Frequency and damping against wind speed", "",
              "State-space branches (U in m/s, frequency in Hz, damping ratio).", "",
              "![frequency and damping against U](modes.png)", "", "## Units", ""]
    lines += [f"- {key}: {unit}" for key, unit in summary.get("units", {}).items()]
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def write_bridge_report(out: Path, result: Any, summary: Mapping[str, Any],
                        inputs: Sequence[Path], *, table_fit: Any = None,
                        model: Any = None) -> Path:
    """Write ``out/report.md`` for a full bridge (``windrig bridge --out``); return its path.

    Parameters
    ----------
    out : Path
        Folder (created).
    result : ident.bridge.flutter.BridgeFlutterResult
        The state-space analysis (mode curves).
    summary : mapping
        The command's JSON summary.
    inputs : sequence of Path
        Input files (hashed).
    table_fit, model : optional
        A table's fit and the model used (for the derivative plot).
    """
    out.mkdir(parents=True, exist_ok=True)
    bridge = summary["bridge"]
    lines = ["# Flutter and buffeting of a bridge: design report", "",
             f"{bridge['name']}: {bridge['n_modes']} modes, {bridge['n_nodes']} deck nodes, "
             f"B = {bridge['B']:g} m, air density {bridge['rho']:g} kg/m^3.", "",
             "## Inputs", ""]
    lines += _input_lines(inputs, summary.get("defaults", []))
    lines += ["", "## Flutter", ""] + _result_lines(summary)
    participation = summary.get("participation") or []
    if participation:
        lines += ["", "Modes in the flutter motion (share of its strain energy):", ""]
        lines += [f"- {p['mode']}: {100 * p['share']:.1f} %" for p in participation]
    lines += _uncertainty_lines(summary.get("uncertainty"))
    buffeting = summary.get("buffeting")
    if buffeting:
        lines += ["", "## Buffeting", "", "Largest RMS along the deck (frequency domain):", "",
                  "| U (m/s) | heave h (m) | pitch alpha (rad) | sway p (m) |", "|---|---|---|---|"]
        for entry in buffeting:
            lines.append(f"| {entry['U']:g} | {max(entry['rms_h']):.4g} | "
                         f"{max(entry['rms_alpha']):.4g} | {max(entry['rms_p']):.4g} |")
        for png, what in (("buffeting_rms.png", "RMS along the deck"),
                          ("buffeting_spectra.png", "response spectra")):
            if (out / png).exists():
                lines += ["", f"![{what}]({png})"]
    lines += ["", "## Warnings", ""] + _warning_lines(summary.get("warnings", []))
    if table_fit is not None and model is not None:
        derivative_plot(out / "derivatives.png", table_fit.table, model,
                        summary.get("result", {}).get("reduced_frequency"))
        lines += ["", "## Table and fit", "", f"{table_fit.summary()}.", "",
                  "![flutter derivatives, table and fit](derivatives.png)"]
    K_range = summary.get("table_K_range")
    mode_plot(out / "modes.png", result.U, result.frequencies, result.damping,
              result.mode_labels, B=float(bridge["B"]),
              K_range=None if not K_range else (K_range[0], K_range[1]),
              speeds={"state space": summary.get("flutter_speed"),
                      "frequency domain": summary.get("flutter_speed_frequency_domain")})
    lines += ["", "## Frequency and damping against wind speed", "",
              "![frequency and damping of every mode against U](modes.png)", "", "## Units", ""]
    lines += [f"- {key}: {unit}" for key, unit in summary.get("units", {}).items()]
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _uncertainty_lines(u: Mapping[str, Any] | None) -> list[str]:
    """Return the bridge's ``uncertainty`` entry (``--uncertainty``) as report lines."""
    if not u or u.get("flutter_speed") is None:
        return []
    lines = ["", "## Uncertainty (the section's, carried to the bridge)", "",
             f"{u['method']}.", ""]
    if u.get("delta_std") is not None:
        lines.append(f"- delta method: {u['flutter_speed']:.4f} +- {u['delta_std']:.3g} m/s")
    mc = u.get("monte_carlo") or {}
    if mc.get("std") is not None:
        q = mc["quantiles"]
        lines.append(f"- Monte Carlo, {mc['fluttering']} of {mc['n']} samples: mean "
                     f"{mc['mean']:.4f} m/s, std {mc['std']:.3g} m/s, 95 % within "
                     f"{q['0.025']:.4f} to {q['0.975']:.4f} m/s")
    if u.get("total_std") is not None:
        lines.append(f"- with the section's other std parts (scaled, not propagated): std "
                     f"{u['total_std']:.3g} m/s")
    if u.get("plot"):
        lines += ["", f"![flutter speed of the samples]({Path(u['plot']).name})"]
    return lines
