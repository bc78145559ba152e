"""The campaign's report: DIR/campaign.json, PNG plots and a short Markdown page.

Responsibility: :func:`write_report` writes what a :class:`~daq.campaign.runner.CampaignOutcome`
holds into the output directory: ``campaign.json`` (``flutter_speed``, ``flutter_speed_std`` and
``flutter_speed_interval`` (m/s, the 2-std interval),
``speeds`` (m/s, in the order tested), ``wind_on_s``, ``stopped_because``, with a simulated rig
``truth_flutter_speed``; the std after each speed, the adaptive decisions, the E2RFC analysis, and
``warnings``: the run files' and the analysis's caveats), ``campaign_std_history.png`` (the flutter
speed and its std after each speed), ``campaign_flutter.png`` (frequency and damping of both
branches against U, the speeds tested marked), ``campaign_flutter_derivatives.png`` (the model's
derivatives over the covered reduced frequencies) and ``campaign.md``. :func:`read_previous` reads
an earlier session's ``campaign.json`` back (a resumed campaign carries its wind-on time on).

Not responsible for: running the campaign (:mod:`daq.campaign.runner`) or the numbers
(:mod:`ident`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from daq.campaign.runner import CampaignOutcome
from daq.offline.report_plots import (
    DerivativeCurves,
    ModeCurves,
    flutter_derivative_grid,
    flutter_diagram,
)
from ident.model import flutter
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel

__all__ = ["read_previous", "report_dict", "write_report"]

JSON_NAME = "campaign.json"


def read_previous(out_dir: str | Path) -> dict[str, Any] | None:
    """Read an earlier session's ``campaign.json`` in ``out_dir``, or None (none, or unreadable)."""
    path = Path(out_dir) / JSON_NAME
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _number(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def _largest_part(parts: dict[str, float | None] | None) -> str:
    """Return the std's largest part as ``"release scatter 0.412"`` ("" without parts)."""
    known = {name: value for name, value in (parts or {}).items() if value}
    if not known:
        return ""
    name = max(known, key=lambda k: known[k] or 0.0)
    return f"{name.replace('_', ' ')} {known[name]:.3f}"


def report_dict(outcome: CampaignOutcome) -> dict[str, Any]:
    """Return the JSON content of ``campaign.json`` (module docstring)."""
    U_F, std = outcome.flutter_speed, outcome.flutter_std
    data: dict[str, Any] = {
        "flutter_speed": _number(U_F),
        "flutter_speed_std": _number(std),
        "flutter_speed_std_relative": (None if U_F is None or std is None else std / U_F),
        "flutter_speed_interval": (
            None if outcome.analysis is None or outcome.analysis.flutter_interval is None
            else [_number(v) for v in outcome.analysis.flutter_interval]),
        "speeds": [s.U for s in outcome.steps],
        "wind_on_s": outcome.wind_on_s,
        "wall_s": outcome.wall_s,
        "stopped_because": outcome.stopped_because,
        "max_fan_rpm_commanded": outcome.max_fan_rpm_commanded,
        "resumed_speeds": outcome.resumed,
        "history": [{"index": s.index, "U": s.U, "file": s.path.name,
                     "files": [path.name for path in s.paths], "releases": s.releases,
                     "why": s.why, "flutter_speed": _number(s.flutter_speed),
                     "flutter_speed_std": _number(s.flutter_std),
                     "flutter_speed_std_parts": (
                         None if s.flutter_std_parts is None
                         else {k: _number(v) for k, v in s.flutter_std_parts.items()}),
                     "wind_on_s": s.wind_on_s} for s in outcome.steps],
        "choices": [{"speed": c.speed, "releases": c.releases, "reason": c.reason,
                     "current_std": _number(c.current_std),
                     "bound": _number(c.bound),
                     "predicted_std": [[u, s] for u, s in c.predicted]}
                    for c in outcome.choices],
    }
    if outcome.truth_flutter_speed is not None:
        data["truth_flutter_speed"] = outcome.truth_flutter_speed
        data["relative_error"] = (None if U_F is None
                                  else U_F / outcome.truth_flutter_speed - 1.0)
    if outcome.analysis is not None:
        data["analysis"] = outcome.analysis.to_dict()
    # The recordings' caveats and the last analysis's, in one place.
    data["warnings"] = list(outcome.recording_warnings) + list(
        data.get("analysis", {}).get("warnings", []))
    return data


def write_report(outcome: CampaignOutcome, out_dir: str | Path, *,
                 truth: tuple[SectionModel, RationalFunctionModel] | None = None,
                 plots: bool = True) -> dict[str, Path]:
    """Write ``campaign.json``, the plots and ``campaign.md``; return name -> path.

    Parameters
    ----------
    outcome : CampaignOutcome
    out_dir : str or Path
    truth : (SectionModel, RationalFunctionModel), optional
        A simulated rig's truth, drawn next to the identified curves.
    plots : bool
        Also draw the PNG plots (matplotlib, Agg).
    """
    out = Path(out_dir)
    data = report_dict(outcome)
    paths = {"json": out / JSON_NAME}
    paths["json"].write_text(json.dumps(data, indent=2, default=_json_default) + "\n",
                             encoding="utf-8")
    if plots and outcome.steps:
        paths.update(_plots(outcome, out, truth))
    paths["markdown"] = out / "campaign.md"
    paths["markdown"].write_text(_markdown(data, paths), encoding="utf-8")
    return paths


def _json_default(value: Any) -> Any:
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


def _markdown(data: dict[str, Any], paths: dict[str, Path]) -> str:
    U_F, std = data["flutter_speed"], data["flutter_speed_std"]
    lines = ["# Campaign report", ""]
    headline = ("No flutter speed identified" if U_F is None or std is None
                else f"**Flutter speed {U_F:.3f} +- {std:.3f} m/s** ({100 * std / U_F:.2f} %)")
    if "truth_flutter_speed" in data:
        err = data.get("relative_error")
        headline += (f"; simulated truth {data['truth_flutter_speed']:.3f} m/s"
                     + ("" if err is None else f" (error {100 * err:+.2f} %)"))
    lines.append(headline + ".")
    if data["warnings"]:  # next to the number they qualify
        lines += ["", "Warnings:", ""] + [f"- {w}" for w in data["warnings"]]
    lines += ["", f"Stopped because: {data['stopped_because']}", "",
              f"Wind on {data['wind_on_s']:.1f} s, wall time {data['wall_s']:.1f} s.", "",
              "| # | U (m/s) | releases | U_F after (m/s) | std (m/s) | its largest part (m/s) "
              "| wind on (s) | why |",
              "|---|---|---|---|---|---|---|---|"]
    for h in data["history"]:
        uf = "" if h["flutter_speed"] is None else f"{h['flutter_speed']:.3f}"
        sd = "" if h["flutter_speed_std"] is None else f"{h['flutter_speed_std']:.3f}"
        on = "" if h["wind_on_s"] is None else f"{h['wind_on_s']:.1f}"
        lines.append(f"| {h['index']} | {h['U']:.2f} | {h['releases']} | {uf} | {sd} | "
                     f"{_largest_part(h.get('flutter_speed_std_parts'))} | {on} | {h['why']} |")
    lines.append("")
    if data["choices"]:
        lines += ["Adaptive decisions (predicted std of the flutter speed after releases at each "
                  "candidate below the safety bound, m/s):", ""]
        for c in data["choices"]:
            table = ", ".join(f"{u:.2f}: {p:.3f}" for u, p in c["predicted_std"])
            lines.append(f"- {c['reason']} (bound {c['bound']:.2f} m/s; {table})")
        lines.append("")
    for name, path in paths.items():
        if path.suffix == ".png":
            lines += [f"![{name}]({path.name})", ""]
    return "\n".join(lines)


def _plots(outcome: CampaignOutcome, out: Path,
           truth: tuple[SectionModel, RationalFunctionModel] | None) -> dict[str, Path]:
    import matplotlib  # here: the backend is chosen before pyplot loads, only when plotting

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths: dict[str, Path] = {}
    steps = [s for s in outcome.steps if s.flutter_speed is not None]
    fig, ax = plt.subplots(figsize=(8, 4.5))
    if steps:
        idx = [s.index for s in steps]
        ax.errorbar(idx, [s.flutter_speed or math.nan for s in steps],
                    yerr=[s.flutter_std or 0.0 for s in steps], fmt="o-", capsize=4,
                    label="identified U_F +- std")
    ax.plot([s.index for s in outcome.steps], [s.U for s in outcome.steps], "s--",
            color="tab:green", label="wind speed tested")
    if outcome.truth_flutter_speed is not None:
        ax.axhline(outcome.truth_flutter_speed, color="k", lw=0.8, label="truth")
    ax.set_xlabel("speed number")
    ax.set_ylabel("m/s")
    ax.set_title("flutter speed and its std after each speed")
    ax.legend(fontsize=8)
    fig.tight_layout()
    paths["std_history"] = out / "campaign_std_history.png"
    fig.savefig(paths["std_history"], dpi=100)
    plt.close(fig)

    analysis = outcome.analysis
    if analysis is None:
        return paths
    U_max = analysis.flutter.U_max
    curves = [ModeCurves(analysis.flutter, "--", "identified")]
    if truth is not None:
        curves.insert(0, ModeCurves(flutter.analyze(truth[0], truth[1], U_max), "-", "truth"))
    # Up to 1.6 times the flutter speed: the curves far beyond flutter say nothing here.
    reach = None if analysis.flutter_speed is None else min(U_max, 1.6 * analysis.flutter_speed)
    paths["flutter"] = flutter_diagram(
        out / "campaign_flutter.png", curves, [s.U for s in outcome.steps],
        title="flutter diagram (green: speeds tested)", damping_top=0.3, U_limit=reach)

    K = analysis.K
    derivatives = [DerivativeCurves("identified", "r--", analysis.derivatives)]
    if truth is not None:
        derivatives.insert(0, DerivativeCurves("truth", "k-", truth[1].flutter_derivatives(K)))
    paths["flutter_derivatives"] = flutter_derivative_grid(
        out / "campaign_flutter_derivatives.png", K, derivatives)
    return paths
