"""``windrig bridge``: multimode flutter (and buffeting) of a full bridge from section aerodynamics.

``windrig bridge BRIDGE.json --aero MODEL.json|TABLE.csv`` reads the bridge model file
(:class:`ident.bridge.model.BridgeModel`) and the deck section's aerodynamics: a rational-function
model (what ``windrig identify --json`` writes, or ``{"A": ..., "d": ...}``: the same reading as
``windrig flutter --model``) or a flutter-derivative table
(``docs/reference/flutter_derivative_tables.md``), Roger-fitted for the state space with its
relative error at every tabulated K reported. It prints the state-space flutter speed, frequency and
participating modes, the frequency-domain check, and writes the JSON of DESIGN (``--json``) and the
in-wind frequency and damping of every mode against U as a table and a plot (``--out``).

``--modes M1.csv M2.csv ...`` builds the bridge from plain mode tables
(:mod:`ident.bridge.mode_tables`, ``docs/guides/bridge.md``); BRIDGE.json then holds the deck data
only (``B``, ``rho``, ``name``, ``static``) and ``--write-bridge OUT.json`` writes the whole bridge
model file. ``--buffeting U1,U2 --wind WIND.toml [--time-domain SECONDS]`` adds the buffeting
response (:mod:`ident.bridge.buffeting`, :mod:`ident.bridge.buffeting_time`): RMS along the deck in
the JSON and, with ``--out``, plots of it and of the response spectra
(:mod:`daq.offline.buffeting_plots`). ``--uncertainty [--samples N] [--seed S] [--workers N |
--scheduler ADDRESS]`` carries the section's uncertainty (an identify JSON's covariance, a
table's std columns) to the flutter speed (:mod:`daq.offline.bridge_uncertainty`).

Every mistake in what the user gave is a :class:`~daq.errors.UsageError` naming the file or
option.

Not responsible for: the numerics (:mod:`ident.bridge`), the error boundary (:mod:`daq.cli`).
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path
from typing import Any

from daq.errors import UsageError
from daq.offline.flutter_commands import read_json, read_model

__all__ = ["add_parser", "run", "run_bridge"]


def add_parser(sub: Any) -> None:
    """Register the ``bridge`` subcommand on the subparsers ``sub`` of :mod:`daq.cli`."""
    p = sub.add_parser(
        "bridge", help="multimode flutter (and buffeting) of a full bridge from its still-air "
                       "modes and the section's RFC model or flutter-derivative table")
    p.add_argument("bridge", type=Path,
                   help="bridge model file (JSON: B, rho, nodes_x, modes, static); with --modes "
                        "the deck data only")
    p.add_argument("--aero", type=Path, default=None,
                   help="the section's aerodynamics: an RFC model (.json, e.g. `windrig "
                        "identify --json` output) or a flutter-derivative table (.csv)")
    p.add_argument("--convention", choices=("scanlan", "z_up"), default="scanlan",
                   help="sign convention of a .csv table (default: scanlan, windrig's)")
    p.add_argument("--u-max", type=float, default=None,
                   help="top wind speed of the flutter search, m/s (default: the lowest "
                        "torsional mode at a reduced frequency of 0.2)")
    p.add_argument("--method", choices=("auto", "dense", "fast"), default="auto",
                   help="how both flutter routes are solved: every branch on a grid (dense), "
                        "the branches that can flutter followed (fast), or fast above 40 modes "
                        "(auto, the default)")
    p.add_argument("--json", type=Path, default=None,
                   help="write the flutter speeds, frequency, participating modes, mode curves "
                        "(and buffeting RMS) to this file")
    p.add_argument("--out", type=Path, default=None,
                   help="folder for the mode curves' table (CSV) and plot (PNG)")
    p.add_argument("--modes", type=Path, nargs="+", default=None, metavar="MODE.csv",
                   help="build the bridge from mode tables (one CSV per mode, "
                         "docs/guides/bridge.md)")
    p.add_argument("--write-bridge", type=Path, default=None,
                   help="with --modes: write the whole bridge model file (JSON) here")
    p.add_argument("--buffeting", type=_speed_list, default=None, metavar="U1,U2,...",
                   help="buffeting response at these mean wind speeds, m/s (needs --wind)")
    p.add_argument("--wind", type=Path, default=None,
                   help="WIND.toml: Iu, Iw, Lux, Lwx, Cuy, Cwy, admittance")
    p.add_argument("--time-domain", type=float, default=None, metavar="SECONDS",
                   help="also simulate the buffeting in time over this record length, s")
    p.add_argument("--uncertainty", action="store_true",
                   help="carry the section's uncertainty to the flutter speed: delta method and "
                        "Monte Carlo from an identify JSON's model_covariance, Monte Carlo from "
                        "a table's std columns (docs/guides/bridge.md)")
    p.add_argument("--samples", type=int, default=None,
                   help="Monte Carlo samples with --uncertainty (default 1000)")
    p.add_argument("--seed", type=int, default=None,
                   help="seed the samples are drawn from (default 0)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None,
                       help="with --uncertainty: a local Dask cluster of this many worker "
                            "processes (default: serial below ~30 s of samples, else every core)")
    where.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="with --uncertainty: an existing Dask scheduler, e.g. "
                            "tcp://10.0.0.5:8786")


def _speed_list(text: str) -> tuple[float, ...]:
    try:
        speeds = tuple(float(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected wind speeds in m/s separated by "
                                         "commas, e.g. 30,45") from None
    if not speeds or any(not u > 0 for u in speeds):
        raise argparse.ArgumentTypeError(f"{text!r}: wind speeds must be > 0 m/s")
    return speeds


def run(args: argparse.Namespace) -> int:
    """Run ``windrig bridge`` from parsed arguments."""
    return run_bridge(args.bridge, aero_path=args.aero, convention=args.convention,
                      u_max=args.u_max, json_path=args.json, out=args.out,
                      mode_tables=args.modes, write_bridge=args.write_bridge,
                      buffeting=args.buffeting, wind=args.wind, time_domain=args.time_domain,
                      method=args.method, uncertainty=args.uncertainty, samples=args.samples,
                      seed=args.seed, workers=args.workers, scheduler=args.scheduler)


def run_bridge(bridge_path: Path, *, aero_path: Path | None = None, convention: str = "scanlan",
               u_max: float | None = None, json_path: Path | None = None,
               out: Path | None = None, mode_tables: list[Path] | None = None,
               write_bridge: Path | None = None, buffeting: tuple[float, ...] | None = None,
               wind: Path | None = None, time_domain: float | None = None,
               method: str = "auto", uncertainty: bool = False, samples: int | None = None,
               seed: int | None = None, workers: int | None = None,
               scheduler: str | None = None) -> int:
    """Analyse a bridge's multimode flutter (see the module docstring); return 0.

    Parameters
    ----------
    bridge_path : Path
        Bridge model file, or with ``mode_tables`` its deck data.
    aero_path : Path, optional
        RFC model (.json) or flutter-derivative table (.csv); required unless only converting.
    convention : str
        Signs of a table (:data:`ident.tables.fd_table.CONVENTIONS`).
    u_max : float, optional
        Top of the state-space search, m/s.
    json_path, out : Path, optional
        JSON result; folder of the mode curves' CSV and PNG.
    mode_tables, write_bridge : optional
        Mode tables to build the bridge from, and where to write it.
    buffeting, wind, time_domain : optional
        Buffeting speeds (m/s), the wind file, the time-domain record length (s).
    method : str
        How the flutter routes are solved (:data:`ident.bridge.routes.METHODS`).
    uncertainty : bool
        Carry the section's uncertainty to the flutter speed
        (:mod:`daq.offline.bridge_uncertainty`).
    samples, seed, workers, scheduler : optional
        Its Monte Carlo samples and seed, and where they run.
    """
    from daq.offline.derivative_table import table_std_report
    from ident.bridge.routes import bridge_flutter_routes

    if u_max is not None and not u_max > 0:
        raise UsageError(f"--u-max {u_max:g}: must be > 0 m/s")
    if write_bridge is not None and mode_tables is None:
        raise UsageError("--write-bridge needs --modes (the mode tables to build the bridge "
                         "from)")
    if buffeting is not None and wind is None:
        raise UsageError("--buffeting needs --wind WIND.toml (turbulence intensities, length "
                         "scales, coherence, admittance)")
    if time_domain is not None and (buffeting is None or not time_domain > 0):
        raise UsageError(f"--time-domain {time_domain:g}: needs --buffeting and a record "
                         "length > 0 s")
    _check_uncertainty_options(uncertainty, samples, seed, workers, scheduler)
    bridge = _read_bridge(bridge_path, mode_tables)
    spec, wind_lines = (_read_wind(wind) if buffeting is not None and wind is not None
                        else (None, []))
    print(f"{bridge_path}: {bridge.name}: {bridge.n_modes} modes, {bridge.n_nodes} deck nodes "
          f"over {bridge.nodes_x[-1] - bridge.nodes_x[0]:.4g} m, B = {bridge.B:g} m, "
          f"rho = {bridge.rho:g} kg/m^3")
    for note in bridge.notes():
        print(f"note: {note}")
    _print_inputs_checked(bridge)
    if write_bridge is not None:
        write_bridge.write_text(json.dumps(bridge.to_dict(), indent=1), encoding="utf-8")
        print(f"wrote {write_bridge}")
    if aero_path is None:
        if write_bridge is not None:
            return 0
        raise UsageError("--aero is required: the section's RFC model (.json) or "
                         "flutter-derivative table (.csv)")
    aero = _read_aero(aero_path, bridge, convention)
    source = None
    if uncertainty:
        from daq.offline.bridge_uncertainty import read_uncertainty_input

        source = read_uncertainty_input(aero_path, aero)
    table_warnings = _check_table(aero, aero_path)
    for note in aero.notes:
        print(f"note: {note}")

    routes = bridge_flutter_routes(bridge, aero, U_max=u_max, method=method)
    result, check, comparison = routes.state_space, routes.frequency_domain, routes.comparison
    aero = routes.aero
    print(f"state space: {result.summary()}")
    print(f"frequency domain ({'the table' if aero.table is not None else 'the model'}'s "
          f"flutter derivatives): {check.summary()}")
    print(f"result: {comparison.summary()}")
    for label, share in result.participating():
        print(f"  {label}: {100 * share:.1f} % of the flutter mode's strain energy")
    if comparison.divergence_speed is not None:
        print(f"divergence: {comparison.divergence_speed:.4g} m/s ({comparison.divergence_basis})")
    warnings = [*aero.notes, *comparison.warnings, *wind_lines]
    for warning in comparison.warnings:
        print(f"warning: {warning}")

    summary: dict[str, Any] = {
        **comparison.to_dict(),
        "critical_mode": None if result.critical_mode is None
        else result.mode_labels[result.critical_mode],
        "participation": [{"mode": label, "share": share}
                          for label, share in result.participating()],
        "U_max": result.U_max,
        "bridge": {"file": str(bridge_path), "name": bridge.name, "B": bridge.B,
                   "rho": bridge.rho, "n_modes": bridge.n_modes, "n_nodes": bridge.n_nodes},
        "aero": str(aero_path), "model": aero.model.to_dict(),
        "modes": {"labels": list(result.mode_labels), "U": result.U.tolist(),
                  "frequencies": result.frequencies.tolist(),
                  "damping": result.damping.tolist()},
        "warnings": warnings,
    }
    if aero.table is not None and aero.table_fit is not None:
        fit = aero.table_fit
        summary.update({"table_convention": convention, "table_K": aero.table.K.tolist(),
                        "table_fit_relative_error": fit.relative_error.tolist(),
                        "table_fit_derivative_error": {name: error.tolist() for name, error
                                                       in fit.derivative_error.items()},
                        "table_fit_accuracy": fit.accuracy, "table_fit_structure": fit.reason})
        std_line, std_keys = table_std_report(aero.table)
        if std_line is not None:
            print(f"note: {std_line}")
        summary.update(std_keys)
    _record_inputs_checked(summary, bridge, table_warnings)
    if source is not None:
        from daq.offline.bridge_uncertainty import DEFAULT_SAMPLES, run_uncertainty

        summary["uncertainty"] = run_uncertainty(
            bridge, aero, source, U_max=result.U_max, out=out, workers=workers,
            scheduler=scheduler, samples=DEFAULT_SAMPLES if samples is None else samples,
            seed=0 if seed is None else seed)
        summary["warnings"].extend(summary["uncertainty"]["warnings"])
    if buffeting is not None:
        buffeted, buffeting_warnings = _buffeting(bridge, aero, buffeting, spec, time_domain,
                                                  out)
        summary.update(buffeted)
        summary["warnings"].extend(buffeting_warnings)
    if out is not None:
        from daq.offline.design_report import write_bridge_report

        _write_curves(out, result, check, aero.K_range, bridge.B)
        inputs = [bridge_path, *(mode_tables or []), aero_path,
                  *([wind] if wind is not None else [])]
        report = write_bridge_report(out, result, summary, inputs, table_fit=aero.table_fit,
                                     model=aero.model)
        print(f"wrote {report}")
    if json_path is not None:
        json_path.write_text(json.dumps(summary, indent=2), encoding="utf-8")
        print(f"wrote {json_path}")
    return 0


def _check_uncertainty_options(uncertainty: bool, samples: int | None, seed: int | None,
                               workers: int | None, scheduler: str | None) -> None:
    """Refuse the Monte Carlo's options without ``--uncertainty``, and impossible values."""
    if not uncertainty:
        given = [name for name, value in (("--samples", samples), ("--seed", seed),
                                          ("--workers", workers), ("--scheduler", scheduler))
                 if value is not None]
        if given:
            raise UsageError(f"{', '.join(given)}: only with --uncertainty (the Monte Carlo's "
                             "options)")
        return
    if samples is not None and samples < 2:
        raise UsageError(f"--samples {samples}: must be >= 2 (a std needs two samples)")
    if workers is not None and workers < 1:
        raise UsageError(f"--workers {workers}: must be >= 1")
    if seed is not None and seed < 0:
        raise UsageError(f"--seed {seed}: must be >= 0")


def _read_bridge(path: Path, mode_tables: list[Path] | None) -> Any:
    from ident.bridge.mode_tables import bridge_from_mode_tables
    from ident.bridge.model import BridgeModel

    try:
        if mode_tables is None:
            return BridgeModel.from_json(path)
        template = read_json(path, "deck data")
        if not isinstance(template, dict):
            raise UsageError(f"{path}: expected a JSON object of the deck data (B, rho, name, "
                             "static)")
        try:
            return bridge_from_mode_tables(template, mode_tables, source=str(path))
        except ValueError as exc:
            raise UsageError(f"{path} with --modes: {exc}") from exc
    except UsageError:
        raise
    except ValueError as exc:
        raise UsageError(str(exc)) from exc


def _print_inputs_checked(bridge: Any) -> None:
    """Print every default the bridge file left to take, and every implausible input."""
    for line in bridge.defaults:
        print(f"default: {line}")
    for line in bridge.warnings:
        print(f"warning: {line}")


def _check_table(aero: Any, path: Path) -> list[str]:
    """Print and return a table's warnings (:func:`ident.tables.table_checks.check_table`)."""
    from ident.tables.table_checks import check_table

    if aero.table is None:
        return []
    found = check_table(aero.table, path)
    for line in found:
        print(f"warning: {line}")
    return found


def _record_inputs_checked(summary: dict[str, Any], bridge: Any,
                           table_warnings: list[str]) -> None:
    """Record the bridge's defaults (``defaults``) and its and the table's ``warnings``."""
    summary["defaults"] = list(bridge.defaults)
    summary.setdefault("warnings", []).extend([*bridge.warnings, *table_warnings])


def _read_aero(path: Path, bridge: Any, convention: str) -> Any:
    from ident.bridge.aero import aero_from_model, aero_from_table
    from ident.errors import IdentError
    from ident.tables.fd_table import FlutterDerivativeTable

    suffix = path.suffix.lower()
    if suffix == ".json":
        return aero_from_model(bridge, read_model(path), source=str(path))
    if suffix == ".csv":
        try:
            table = FlutterDerivativeTable.from_csv(path, convention=convention)
            aero = aero_from_table(bridge, table, source=str(path))
        except (ValueError, IdentError) as exc:
            raise UsageError(str(exc) if str(path) in str(exc) else f"{path}: {exc}") from exc
        assert aero.table_fit is not None
        fit = aero.table_fit
        print(f"{path}: {table.K.size} rows, K {table.K[0]:.3g} to {table.K[-1]:.3g}; "
              f"{fit.summary()}")
        return aero
    raise UsageError(f"--aero {path}: expected an RFC model (.json) or a flutter-derivative "
                     "table (.csv)")


def _write_curves(out: Path, result: Any, check: Any,
                  K_range: tuple[float, float] | None = None, B: float = 1.0) -> None:
    """Write the in-wind frequency and damping of every mode against U: CSV and PNG.

    With a table's ``K_range`` (and the deck width ``B``, m) a branch is drawn solid only while
    its reduced frequency lies within the table (faded beyond: the fit extrapolated), and the
    axis ends where the last branch leaves the table.
    """
    import matplotlib
    import numpy as np

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    table = out / "bridge_modes.csv"
    with table.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        names = [label.split(" (")[0] for label in result.mode_labels]
        writer.writerow(["U_m_s", *(f"f_{n}_Hz" for n in names), *(f"zeta_{n}" for n in names)])
        for i, U in enumerate(result.U):
            writer.writerow([f"{U:.6g}", *(f"{x:.6g}" for x in result.frequencies[i]),
                             *(f"{x:.6g}" for x in result.damping[i])])
    fig, (ax_f, ax_z) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    inside = np.ones(result.frequencies.shape, dtype=bool)
    if K_range is not None:
        with np.errstate(divide="ignore", invalid="ignore"):
            K = 2 * np.pi * result.frequencies * B / result.U[:, None]
        inside = (K >= K_range[0]) & (K <= K_range[1])
    for j, label in enumerate(result.mode_labels):
        color = colors[j % len(colors)]
        f_in = np.where(inside[:, j], result.frequencies[:, j], np.nan)
        z_in = np.where(inside[:, j], result.damping[:, j], np.nan)
        ax_f.plot(result.U, f_in, "-", color=color, label=label)
        ax_z.plot(result.U, z_in, "-", color=color)
        if K_range is not None:
            ax_f.plot(result.U, result.frequencies[:, j], "-", color=color, alpha=0.2, lw=0.8)
            ax_z.plot(result.U, result.damping[:, j], "-", color=color, alpha=0.2, lw=0.8)
        keep = check.U[:, j] <= result.U_max
        ax_f.plot(check.U[keep, j], check.frequencies[keep, j], ":", color=color)
        ax_z.plot(check.U[keep, j], check.damping[keep, j], ":", color=color)
    if result.speed is not None:
        for ax in (ax_f, ax_z):
            ax.axvline(result.speed, color="grey", lw=0.8)
    ax_z.axhline(0.0, color="k", lw=0.6)
    ax_z.set_ylim(-0.05, max(0.1, float(min(1.0, result.damping.max()))))
    top = result.U_max
    if K_range is not None and inside.any():
        top = min(top, 1.05 * float(result.U[np.flatnonzero(inside.any(axis=1))[-1]]))
    ax_z.set_xlim(0.0, top)
    ax_f.set_ylabel("frequency (Hz)")
    ax_z.set_ylabel("damping ratio")
    ax_z.set_xlabel("U (m/s)")
    ax_f.legend(fontsize=7, ncol=2)
    ax_f.set_title("in-wind modes: state space (solid), frequency domain (dotted)"
                   + ("; faded: outside the table's K" if K_range is not None else ""))
    fig.tight_layout()
    plot = out / "bridge_modes.png"
    fig.savefig(plot, dpi=100)
    plt.close(fig)
    print(f"wrote {table} and {plot}")


def _read_wind(path: Path) -> tuple[Any, list[str]]:
    """Read WIND.toml; return the wind and its warnings (printed here, for the JSON too)."""
    from ident.bridge.wind import read_wind, wind_warnings

    try:
        spec = read_wind(path)
    except ValueError as exc:
        raise UsageError(str(exc)) from exc
    lines = wind_warnings(spec, source=str(path))
    for line in lines:
        print(f"warning: {line}")
    return spec, lines


def _none_for_nan(values: Any) -> list[float | None]:
    return [None if v != v else float(v) for v in values]  # JSON has no NaN


def _buffeting(bridge: Any, aero: Any, speeds: tuple[float, ...], spec: Any,
               time_domain: float | None, out: Path | None
               ) -> tuple[dict[str, Any], list[str]]:
    """Buffeting at every speed (:mod:`ident.bridge.buffeting`), JSON entries, plots in ``out``.

    The time-domain record is seeded (0); its RMS is compared with the frequency domain at the
    node of largest RMS heave, against the stated relative standard deviation
    ``0.5 sqrt(T_c / T)`` of an RMS from a record of length T. With a table's aerodynamics
    (``aero.K_range``), each speed's entry lists in ``extrapolated_modes`` the modes that
    resonate outside the table's reduced frequencies, each with a warning. Returns the JSON
    entries and the warnings (also printed).
    """
    import numpy as np
    from tqdm import tqdm

    from ident.bridge.aero import extrapolated_modes
    from ident.bridge.buffeting import frequency_domain
    from ident.bridge.buffeting_time import simulate
    from ident.bridge.statespace import BridgeStateSpace

    ss = BridgeStateSpace(bridge, aero.model)
    result: dict[str, Any] = {"buffeting": []}
    warnings = _static_warnings(bridge)
    if time_domain is not None:
        result["time_domain"] = []
    responses, simulations = [], []
    for U in speeds:
        try:
            response = frequency_domain(ss, spec, U)
        except ValueError as exc:
            raise UsageError(f"--buffeting {U:g}: {exc}") from exc
        responses.append(response)
        entry = response.to_dict()
        if aero.K_range is not None:
            outside = extrapolated_modes(bridge, aero.model, U, aero.K_range)
            entry["extrapolated_modes"] = outside
            warnings.extend(_extrapolation_warning(U, row, aero.K_range) for row in outside)
        result["buffeting"].append(entry)
        print(f"buffeting at U = {U:g} m/s (frequency domain): largest RMS h "
              f"{response.rms_h.max():.4g} m, alpha {response.rms_alpha.max():.4g} rad, "
              f"p {response.rms_p.max():.4g} m")
        if time_domain is None:
            continue
        with tqdm(total=None, unit="step", mininterval=0.5, desc=f"time domain {U:g} m/s") as bar:
            def progress(done: int, total: int, bar: Any = bar) -> None:
                bar.total = total
                bar.update(done - bar.n)

            simulated, _ = simulate(ss, spec, U, time_domain, rng=0, progress=progress)
        simulations.append(simulated)
        std = response.rms_relative_std(simulated.duration)
        entry = simulated.to_dict()
        entry["duration"] = simulated.duration
        entry["rms_relative_std"] = {
            "x": response.x[response.spectrum_nodes].tolist(),
            **{name: _none_for_nan(values) for name, values in std.items()}}
        result["time_domain"].append(entry)
        j = int(np.argmax(response.rms_h[response.spectrum_nodes]))
        node = int(response.spectrum_nodes[j])
        parts = []
        for name in ("h", "alpha", "p"):
            ref = getattr(response, f"rms_{name}")[node]
            if ref > 0.0:
                ratio = getattr(simulated, f"rms_{name}")[node] / ref
                parts.append(f"{name} {100 * (ratio - 1):+.1f} % (stated std "
                             f"{100 * std[name][j]:.1f} %)")
        print(f"buffeting at U = {U:g} m/s (time domain, {simulated.duration:.4g} s): at x = "
              f"{response.x[node]:.4g} m, against the frequency domain: " + ", ".join(parts))
    if out is not None:
        from daq.offline.buffeting_plots import write_buffeting_outputs

        written = write_buffeting_outputs(out, responses, simulations)
        print("wrote " + ", ".join(str(p) for p in written))
    return result, warnings


def _extrapolation_warning(U: float, row: dict[str, Any], K_range: tuple[float, float]) -> str:
    """One sentence for a mode that resonates at ``U`` outside the table's ``K_range``."""
    line = (f"buffeting at U = {U:g} m/s: {row['mode']} resonates at {row['frequency']:.4g} Hz, "
            f"K = {row['K']:.3g}, outside the table's K {K_range[0]:.3g} to {K_range[1]:.3g}: "
            "its aerodynamic damping there is the Roger fit's extrapolation, not the table's")
    print(f"warning: {line}")
    return line


def _static_warnings(bridge: Any) -> list[str]:
    """Warn (printed, returned for the JSON) of static coefficients a buffeting result rests on.

    A positive lift slope is what a source with lift positive upward gives: in windrig's signs
    (lift down) a deck's ``dC_L`` is negative, and the slope sets the vertical gust's lift
    ``(dC_L - C_D) w / U``, so the mistake changes the buffeting forces and their correlation
    with the moment. The flutter side only notes it; here it is a warning in the JSON.
    """
    static = bridge.static
    if static is None or not static.dC_L > 0.0:
        return []
    line = (f"static dC_L = {static.dC_L:g} > 0 drives the buffeting lift (dC_L - C_D) w/U: "
            "windrig's lift is positive downward, so a deck's dC_L is negative; from a source "
            "with lift positive upward? then flip the signs of C_L and dC_L")
    print(f"warning: {line}")
    return [line]
