"""What ``windrig reprocess`` writes: the tables, the plots and the HTML report.

Responsibility: :func:`write_outputs` turns the per-file and per-campaign results of a
reprocessing run (:class:`ReprocessSummary`) into the output directory: ``releases.csv`` and
``campaigns.csv``, ``summary.json`` (the same rows, each campaign's model and its
``warnings``, and every campaign's ``warnings`` led by its name), two plots per
campaign (the model's flutter derivatives; the modes' frequency and damping against the wind
speed, the model's curves with each release's fit) and a static ``report.html`` linking them.
Only the client process writes.

Not responsible for: computing the results (:mod:`daq.offline.reprocess`, on Dask, and
:mod:`ident`).
"""

from __future__ import annotations

import csv
import html
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from daq.offline.report_plots import DerivativeCurves, flutter_derivative_grid

__all__ = ["ReprocessSummary", "write_outputs"]


@dataclass
class ReprocessSummary:
    """What :func:`reprocess` did.

    Attributes
    ----------
    files : list of str
        Every run file found.
    failed : dict of str to str
        Files that could not be used, with the reason.
    reused : list of str
        Files taken from the cache (not redone).
    campaigns : list of dict
        One per campaign (see :func:`process_campaign`).
    outputs : dict of str to Path
        The tables, plots and report written.
    timings : dict of str to float
        Wall time of the phases, s.
    """

    files: list[str]
    failed: dict[str, str] = field(default_factory=dict)
    reused: list[str] = field(default_factory=list)
    campaigns: list[dict[str, Any]] = field(default_factory=list)
    outputs: dict[str, Path] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def warnings(self) -> list[str]:
        """Every campaign's warnings, each led by the campaign's name, in campaign order.

        A campaign's own: its files' recording warnings and reading notes, then the
        identification's.
        """
        return [f"{c.get('name')}: {text}" for c in self.campaigns
                for text in c.get("warnings", [])]


_RELEASE_FIELDS = ("file", "release", "U", "f_h", "zeta_h", "f_a", "zeta_a", "campaign")


_CAMPAIGN_FIELDS = ("campaign", "n_files", "n_releases", "wind_speeds", "flutter_speed",
                    "flutter_std", "flutter_speed_low", "flutter_speed_high",
                    "flutter_frequency", "structure", "effect", "gap_before", "gap_after",
                    "effects", "explained", "error")


def write_outputs(out: Path, results: dict[str, dict[str, Any]],
                  summary: ReprocessSummary) -> dict[str, Path]:
    """Write the tables, plots and report into ``out``; return their paths by name."""
    outputs: dict[str, Path] = {}
    names = {id(c): str(c.get("name", f"campaign_{i + 1}"))
             for i, c in enumerate(summary.campaigns)}
    campaign_of = {p: names[id(c)] for c in summary.campaigns for p in c.get("files", [])}
    release_rows = []
    for path in summary.files:
        result = results[path]
        for r in result.get("releases", []):
            release_rows.append({"file": path, "release": r["index"], "U": r["U"],
                                 "f_h": r["f_h"], "zeta_h": r["zeta_h"], "f_a": r["f_a"],
                                 "zeta_a": r["zeta_a"], "campaign": campaign_of.get(path, "")})
    campaign_rows = []
    for c in summary.campaigns:
        campaign_rows.append({
            "campaign": names[id(c)], "n_files": len(c.get("files", [])),
            "n_releases": c.get("n_releases"), "wind_speeds": c.get("wind_speeds"),
            "flutter_speed": c.get("flutter_speed"), "flutter_std": c.get("flutter_std"),
            # Over the structures within one standard error of the best (high: inf when one
            # of them has no flutter below the analysis' upper speed).
            "flutter_speed_low": c.get("flutter_speed_low"),
            "flutter_speed_high": c.get("flutter_speed_high"),
            "flutter_frequency": c.get("flutter_frequency"), "structure": c.get("structure"),
            "effect": c.get("effect"), "gap_before": c.get("gap_before"),
            "gap_after": c.get("gap_after"), "effects": _sequence(c.get("effects")),
            "explained": c.get("explained"), "error": c.get("error")})
    for name, rows, fields in (("releases", release_rows, _RELEASE_FIELDS),
                               ("campaigns", campaign_rows, _CAMPAIGN_FIELDS)):
        csv_path = out / f"{name}.csv"
        with csv_path.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=fields)
            writer.writeheader()
            writer.writerows(rows)
        outputs[f"{name}_csv"] = csv_path
    summary_json = out / "summary.json"
    # The JSON's campaigns carry their warnings (the CSV's one line per campaign does not):
    # a km/h wind speed or an extrapolated flutter speed is said where the number is.
    summary_json.write_text(json.dumps({
        "files": summary.files, "failed": summary.failed, "reused": summary.reused,
        "releases": release_rows,
        "campaigns": [{**row, "warnings": list(c.get("warnings", []))}
                      for row, c in zip(campaign_rows, summary.campaigns, strict=True)],
        "models": {names[id(c)]: c.get("model") for c in summary.campaigns},
        "warnings": summary.warnings,
    }, indent=2, default=_json_default))
    outputs["summary_json"] = summary_json
    plots = {names[id(c)]: _campaign_plots(out, names[id(c)], c, results)
             for c in summary.campaigns if "model" in c}
    outputs.update({f"plot_{name}_{kind}": path for name, paths in plots.items()
                    for kind, path in paths.items()})
    outputs["report"] = _html_report(out, summary, campaign_rows, plots)
    return outputs


def _sequence(effects: list[dict[str, Any]] | None) -> str | None:
    """Return the diagnosis' effects in the order added, each with its gap after, as a line."""
    if effects is None:
        return None
    return " > ".join(f"{e['effect']} (gap {e['gap_after']:.4f})" for e in effects) or "none"


def _json_default(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def _campaign_plots(out: Path, name: str, campaign: dict[str, Any],
                    results: dict[str, dict[str, Any]]) -> dict[str, Path]:
    """Write a campaign's plots; return their paths by kind.

    ``flutter_derivatives``: the model's eight derivatives over the releases' K span.
    ``modes``: frequency and damping ratio of the heave and pitch modes against U, the model's
    (its state-space flutter analysis) as lines, each release's modal fit as points, the
    flutter speed marked: where the model and the decays agree, and how far the prediction
    reaches beyond the measured wind speeds.
    """
    import matplotlib  # here: the backend is chosen before pyplot loads, only when plotting

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    speed = campaign.get("flutter_speed")
    title = (f"{name}: {campaign['n_releases']} releases at {campaign['wind_speeds']} m/s; "
             + (f"U_F = {speed:.2f} m/s" if speed is not None else "no flutter found"))
    paths = {"flutter_derivatives": out / f"{name}_flutter_derivatives.png",
             "modes": out / f"{name}_modes.png"}

    flutter_derivative_grid(paths["flutter_derivatives"], np.asarray(campaign["K"]),
                            [DerivativeCurves("", "r-", campaign["derivatives"])],
                            title=title, dpi=90)

    curves = campaign["curves"]
    releases = [r for path in campaign["files"] for r in results[path].get("releases", [])]
    fig, (ax_f, ax_z) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    measured = {"heave": ("f_h", "zeta_h"), "pitch": ("f_a", "zeta_a")}
    for j, mode in enumerate(curves["mode_names"]):
        line, = ax_f.plot(curves["U"], curves["frequencies"][:, j], "-", label=f"{mode}, model")
        ax_z.plot(curves["U"], curves["damping"][:, j], "-", color=line.get_color())
        if mode in measured:
            f_key, z_key = measured[mode]
            U = [r["U"] for r in releases]
            ax_f.plot(U, [r[f_key] for r in releases], "o", color=line.get_color(),
                      label=f"{mode}, releases")
            ax_z.plot(U, [r[z_key] for r in releases], "o", color=line.get_color())
    if speed is not None:
        for ax in (ax_f, ax_z):
            ax.axvline(speed, color="grey", ls="--", lw=0.8)
    ax_z.axhline(0.0, color="k", lw=0.6)
    # Up to half again the flutter speed (or the highest release): the range that matters.
    reach = max([speed or 0.0] + [r["U"] for r in releases])
    ax_z.set_xlim(0.0, min(1.5 * reach, float(np.max(curves["U"]))))
    ax_f.set_ylabel("frequency (Hz)")
    ax_z.set_ylabel("damping ratio")
    ax_z.set_xlabel("U (m/s)")
    finite = np.asarray(curves["damping"])[np.isfinite(curves["damping"])]
    ax_z.set_ylim(-0.05, max(0.1, 0.5 * float(finite.max())) if finite.size else 0.2)
    ax_f.legend(fontsize=8)
    ax_f.set_title(title)
    fig.tight_layout()
    fig.savefig(paths["modes"], dpi=90)
    plt.close(fig)
    return paths


def _html_report(out: Path, summary: ReprocessSummary, campaigns: list[dict[str, Any]],
                 plots: dict[str, dict[str, Path]]) -> Path:
    def cell(value: Any) -> str:
        if isinstance(value, float):
            return f"{value:.4g}"
        return html.escape("" if value is None else str(value))

    parts = ["<!doctype html><html><head><meta charset='utf-8'><title>windrig reprocess</title>",
             "<style>body{font-family:sans-serif} td,th{padding:2px 8px;border-bottom:1px solid"
             " #ccc}</style></head><body>",
             f"<h1>windrig reprocess</h1><p>{len(summary.files)} files, "
             f"{len(summary.failed)} failed, {len(summary.reused)} from the cache; "
             "<a href='releases.csv'>releases.csv</a>, <a href='campaigns.csv'>campaigns.csv"
             "</a>, <a href='summary.json'>summary.json</a></p>",
             "<h2>Campaigns</h2><table><tr>"
             + "".join(f"<th>{f}</th>" for f in _CAMPAIGN_FIELDS) + "</tr>"]
    for row in campaigns:
        parts.append("<tr>" + "".join(f"<td>{cell(row[f])}</td>" for f in _CAMPAIGN_FIELDS)
                     + "</tr>")
    parts.append("</table>")
    if summary.warnings:
        parts.append("<h2>Warnings</h2><ul>")
        parts.extend(f"<li>{html.escape(text)}</li>" for text in summary.warnings)
        parts.append("</ul>")
    for c in summary.campaigns:  # the diagnosis: the sequence, and a residual left unexplained
        if c.get("effects") is None:
            continue
        parts.append(f"<h3>{html.escape(str(c.get('name')))}: discrepancy</h3><ol>")
        parts.extend(
            "<li>" + html.escape(f"{e['effect']}: " + ", ".join(
                f"{k} = {v:.4g} +- {e['uncertainty'].get(k, float('nan')):.2g}"
                for k, v in e["parameters"].items()) + f"; gap after {e['gap_after']:.4f}")
            + "</li>" for e in c["effects"])
        parts.append("</ol>")
        if c.get("explained") is False:
            parts.append("<p>Not explained: a systematic residual is left that no named "
                         "effect explains:</p><ul>")
            parts.extend(f"<li>{html.escape(text)}</li>" for text in c.get("unexplained", []))
            parts.append("</ul>")
    for name, paths in plots.items():
        parts.append(f"<h3>{html.escape(name)}</h3>")
        parts.extend(f"<img src='{html.escape(path.name)}' width='900'>"
                     for path in paths.values())
    if summary.failed:
        parts.append("<h2>Files not used</h2><ul>")
        parts.extend(f"<li>{html.escape(p)}: {html.escape(reason)}</li>"
                     for p, reason in summary.failed.items())
        parts.append("</ul>")
    parts.append("</body></html>")
    path = out / "index.html"
    path.write_text("\n".join(parts))
    return path
