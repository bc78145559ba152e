"""``windrig identify`` and ``windrig flutter``: E2RFC on run files, flutter of a section.

``windrig identify FILES`` reads recorded runs, identifies the rational-function model of their
releases (E2RFC with its uncertainty, :func:`ident.identification.campaign.analyze_campaign`) and
prints the flutter speed; for runs of three degrees of freedom also the 18 flutter derivatives over
the releases' reduced frequencies (:mod:`daq.offline.derivative_table`; a model that left out the
sway is refused); ``--table OUT.csv`` writes the flutter-derivative table with each derivative's
standard deviation. ``windrig flutter --section S.json (--model M.json | --table T.csv)`` analyses a
section of two or three degrees of freedom with a model (``windrig identify --json`` output or
``{"A": ..., "d": ...}``) or a flutter-derivative table
(``docs/reference/flutter_derivative_tables.md``): the state-space analysis (a table is first fitted
with rational functions,
:func:`ident.tables.roger_table.fit_table`) and the frequency-domain one as its check.

Every mistake in what the user gave (a file that cannot be read, a section or model that is not
valid, a 2-DOF model for a section with sway) is a :class:`~daq.errors.UsageError` naming the file.

Not responsible for: parsing the command line or the error boundary (:mod:`daq.cli`).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from daq.errors import UsageError

__all__ = ["run_flutter", "run_identify"]


def run_identify(files: Sequence[Path], *, json_path: Path | None = None,
                 n_lags: int | None = None, tubing_correction: bool = True,
                 route: str = "auto", detect_releases: bool = False,
                 table_path: Path | None = None, reduced_velocities: str | None = None,
                 turbulent_estimator: str | None = None,
                 closed_loop_buffeting: str | None = None) -> int:
    """Identify the releases of run files and print the model and flutter speed; return 0.

    Parameters
    ----------
    files : sequence of Path
        windrig HDF5 run files of one section.
    json_path : Path, optional
        Also write the model, its diagnostics and the flutter result here.
    n_lags : int, optional
        Number of lag terms (default: chosen by held-out error).
    tubing_correction : bool
        Correct the forces for the taps' pneumatic tubing recorded in the files.
    route : {"auto", "e2rfc", "displacement"}
        E2RFC (forces and displacements), or the displacement-only route
        (:mod:`daq.offline.displacement_route`); ``"auto"``: E2RFC when every file holds
        forces, else the displacement-only route.
    detect_releases : bool
        Find the releases in the lasers' signals (files without release rows).
    table_path : Path, optional
        Write the flutter-derivative table with each derivative's std here (CSV,
        :func:`daq.offline.derivative_table.write_derivative_table`; E2RFC only).
    reduced_velocities : str, optional
        ``START:STOP:STEP`` of the table's reduced velocities ``U / (f B)``; default: the
        releases' span.
    turbulent_estimator : {"iv", "ml"}, optional
        The estimator of releases in turbulence (default: E2RFC's, closed-loop maximum
        likelihood, :mod:`ident.identification.closed_loop_ml`); ``"iv"``: refined IV.
    closed_loop_buffeting : {"second-order", "fourth-order", "by-evidence"}, optional
        The closed-loop estimator's buffeting model (default E2RFC's, by evidence), or either
        model alone.
    """
    from daq.offline.derivative_table import (
        check_model_dof,
        derivative_rows,
        format_derivative_table,
        parse_reduced_velocities,
        write_derivative_table,
    )
    from ident.errors import IdentError
    from ident.identification.campaign import analyze_campaign
    from ident.identification.covariance import ModelCovariance
    from ident.records.run_file import forces_recorded, read_run
    from ident.records.run_set import campaign_section, recording_notes, tubing_note

    if route not in ("auto", "e2rfc", "displacement"):
        raise UsageError(f"--route {route!r}: one of auto, e2rfc, displacement")
    if reduced_velocities is not None and table_path is None:
        raise UsageError("--reduced-velocities sets the rows of --table OUT.csv: give --table")
    Ur = None if reduced_velocities is None else parse_reduced_velocities(reduced_velocities)
    without = [p for p in files if not forces_recorded(p)]
    if route == "e2rfc" and without:
        raise UsageError(f"{without[0]}: holds no forces (a rig without taps): E2RFC needs "
                         "them; identify it by the displacement-only route (--route "
                         "displacement)")
    displacement = route == "displacement" or bool(without)
    if displacement and table_path is not None:
        raise UsageError("--table: the displacement-only route has no parameter covariance to "
                         "give the derivatives' std; the table needs E2RFC (files with forces)")
    runs = [read_run(p, tubing_correction=tubing_correction, detect_releases=detect_releases,
                     displacements_only=displacement) for p in files]
    notes = (_detections(runs) if detect_releases else []) + recording_notes(runs)
    section = campaign_section(runs)
    if displacement:
        from daq.offline.displacement_route import run_displacement_route

        why = ("asked for" if route == "displacement" else
               f"{len(without)} of {len(files)} file(s) hold no forces, e.g. {without[0]}")
        return run_displacement_route(runs, files, section, why=why, json_path=json_path,
                                      n_lags=n_lags, extra_warnings=notes)
    releases = [r for run in runs for r in run.releases]
    print(f"{len(releases)} release(s) from {len(runs)} file(s); wind speeds "
          f"{sorted({round(r.U, 2) for r in releases})} m/s{tubing_note(runs)}")
    try:
        analysis = analyze_campaign(releases, section, n_lags=n_lags, table=False,
                                    turbulent_estimator=turbulent_estimator,
                                    closed_loop_buffeting=closed_loop_buffeting)
    except ValueError as exc:
        if section.n_dof == 2 or isinstance(exc, IdentError):
            raise
        raise IdentError(f"E2RFC could not identify the 3-DOF releases ({exc}): a 3-DOF "
                         "campaign needs E2RFC in 3x3") from exc
    check_model_dof(analysis.model, section)
    model, result, spread = analysis.model, analysis.flutter, analysis.structures
    u = analysis.uncertainty
    diagnostics = model.diagnostics
    print(f"structure: {diagnostics.reason}")
    print(f"lag roots d = {np.round(model.d, 4).tolist()}")
    for k, A_k in enumerate(model.A, start=1):
        print(f"A{k} = {np.round(A_k, 4).tolist()}")
    if section.n_dof == 3:  # the 18 derivatives (a 2-DOF run prints as it always did)
        print("\n".join(format_derivative_table(model, analysis.K)))
    if result.speed is None:
        print(result.summary())
    else:
        print(f"flutter speed {result.speed:.3f} +/- {u.total:.3f} m/s, frequency "
              f"{result.frequency:.3f} Hz ({result.critical_mode} branch); "
              f"{spread.summary()}")
        parts = [f"noise {u.parametric:.3f}", f"structure {u.structure:.3f}",
                 f"extrapolation {u.extrapolation:.3f}", f"one lag more {u.refinement:.3f}"]
        if u.turbulence:
            parts.insert(1, f"release scatter {u.turbulence:.3f}")
        if u.below_decay:
            parts.append(f"below a decaying release {u.below_decay:.3f}")
        if u.cross_check:
            parts.append(f"other estimator {u.cross_check:.3f}")
        print("  its std (m/s): " + ", ".join(parts))
        low, high = u.interval()
        print(f"  2-std interval {low:.3f} to {high:.3f} m/s"
              + ("" if u.floor is None else
                 f" (drawn beyond {u.floor:.3g} m/s, the highest wind speed the releases show "
                 "stable: longer above)"))
    for label, speed, speed_std in zip(spread.labels[1:], spread.speeds[1:], spread.stds[1:],
                                       strict=True):
        print(f"  also within one SE: {label}: " + (
            f"no flutter below {spread.U_max:.3g} m/s" if speed is None or speed_std is None
            else f"flutter speed {speed:.3f} +/- {speed_std:.3f} m/s"))
    if table_path is not None:
        notes += write_derivative_table(model, table_path, analysis.K, Ur)
        print(f"wrote {table_path} (flutter derivatives and their std, Scanlan's signs)")
    for warning in [*notes, *analysis.warnings]:
        print(f"warning: {warning}")
    if json_path is not None:
        summary = analysis.to_dict()
        K_table, derivative_values = derivative_rows(model, analysis.K)
        json_path.write_text(json.dumps({
            "files": [str(p) for p in files],
            "model": summary["model"],
            # For later analyses of the model (`windrig bridge --uncertainty`).
            "model_covariance": ModelCovariance.of(model).to_dict(),
            "structure": summary["reason"],
            "release_residuals": diagnostics.release_residuals.tolist(),
            "flutter_speed": result.speed,
            "flutter_speed_std": analysis.flutter_std,
            "flutter_speed_std_parts": summary["flutter_std_parts"],
            "flutter_speed_interval": summary["flutter_interval"],
            "flutter_speed_structures": summary["flutter_structures"],
            "flutter_frequency": result.frequency,
            "critical_mode": result.critical_mode,
            "warnings": [*notes, *summary["warnings"]],
            **({} if table_path is None else {"table": str(table_path)}),
            **({} if section.n_dof == 2 else {"flutter_derivatives": {
                name: values.tolist() for name, values in
                (("K", K_table), *derivative_values.items())}}),
        }, indent=2))
        print(f"wrote {json_path}")
    return 0


def _detections(runs: Sequence[Any]) -> list[str]:
    """Print the releases found in each file's signals; return warnings (weak onsets, none)."""
    warnings = []
    for run in runs:
        print(f"{run.path}: {len(run.detected)} release(s) found in the lasers' signals"
              + "".join(f"\n  at {o.time:.4f} s (std {1e3 * o.std:.2f} ms, snr {o.snr:.0f})"
                        for o in run.detected))
        if not run.detected:
            warnings.append(f"{run.path}: no release found in its signals (a hold of at least "
                            "0.3 s still, then a free decay of 3 periods or more)")
        weak = [o for o in run.detected if not o.reliable]
        if weak:
            warnings.append(f"{run.path}: {len(weak)} release(s) with a weak onset (snr below "
                            "150): their instants may be off by several std")
    return warnings


def run_flutter(section_path: Path, *, model_path: Path | None = None,
                table_path: Path | None = None, convention: str = "scanlan",
                u_max: float | None = None, json_path: Path | None = None,
                out: Path | None = None) -> int:
    """Analyse the flutter of a section with a model or a table; print it; return 0.

    Both routes run (:func:`ident.tables.flutter_routes.section_flutter`); the result is the one
    they support, with every caveat as a ``warning:`` line and in the JSON's ``warnings``.

    Parameters
    ----------
    section_path : Path
        JSON of :class:`ident.model.section.SectionModel` fields (with ``fp``: three degrees of
        freedom).
    model_path, table_path : Path
        Exactly one: a rational-function model (JSON) or a flutter-derivative table (CSV).
    convention : str
        Sign convention of the table (:data:`ident.tables.fd_table.CONVENTIONS`).
    u_max : float, optional
        Upper wind speed of the state-space search, m/s.
    json_path : Path, optional
        Write the result (DESIGN's keys, units, warnings), the section and the model used here.
    out : Path, optional
        Folder of the design report (``report.md`` and its plots, :mod:`daq.offline.design_report`).
    """
    from ident.model.section import proportion_warnings
    from ident.tables.flutter_routes import section_flutter

    if u_max is not None and not u_max > 0:
        raise UsageError(f"--u-max {u_max:g}: must be > 0 m/s")
    section, defaults = _read_section(section_path)
    out_keys: dict[str, Any] = {}
    warnings: list[str] = proportion_warnings(section, source=str(section_path))
    try:
        if table_path is not None:
            table, fit = _table_fit(table_path, convention, section, out_keys, warnings)
            routes = section_flutter(section, table=table, fit=fit, U_max=u_max)
        else:
            assert model_path is not None
            routes = section_flutter(section, model=_read_model(model_path, section.n_dof,
                                                                 section_path), U_max=u_max)
    except Exception:
        # The error line follows; what the checks found may be its cause.
        for warning in warnings:
            print(f"warning: {warning}")
        raise
    comparison = routes.comparison
    print(f"state space: {routes.state_space.summary()}")
    print(f"frequency domain ({'the table' if table_path else 'the model'}'s flutter "
          f"derivatives): {routes.frequency_domain.summary()}")
    print(f"result: {comparison.summary()}")
    if comparison.divergence_speed is not None:
        print(f"divergence: {comparison.divergence_speed:.4g} m/s ({comparison.divergence_basis})")
    warnings += list(comparison.warnings)
    for warning in warnings:
        print(f"warning: {warning}")
    summary = {**comparison.to_dict(), "critical_mode": routes.state_space.critical_mode,
               "U_max": routes.state_space.U_max, "n_dof": section.n_dof,
               "section": section.to_dict(), "section_file": str(section_path),
               "defaults": defaults, "model": routes.model.to_dict(), **out_keys,
               "warnings": warnings}
    if out is not None:
        from daq.offline.design_report import write_section_report

        inputs = [section_path, *(p for p in (model_path, table_path) if p is not None)]
        path = write_section_report(out, routes, summary, inputs)
        print(f"wrote {path}")
    if json_path is not None:
        json_path.write_text(json.dumps(summary, indent=2))
        print(f"wrote {json_path}")
    return 0


def _read_section(path: Path) -> tuple[Any, list[str]]:
    """Read a section file; print and return the defaults it took (what the file left out)."""
    from ident import SectionModel
    from ident.model.section import section_defaults

    data = read_json(path, "section")
    if not isinstance(data, dict):
        raise UsageError(f"{path}: expected a JSON object of SectionModel fields")
    try:
        section = SectionModel.from_dict(data)
    except (TypeError, ValueError) as exc:
        raise UsageError(f"{path}: {exc}") from exc
    defaults = section_defaults(data, source=str(path))
    for default in defaults:
        print(f"note: {default}")
    return section, defaults


def read_model(path: Path) -> Any:
    """Read a rational-function model: its JSON, or ``windrig identify --json`` output.

    A bad file is a usage error naming it and what was expected.
    """
    from ident import RationalFunctionModel

    data = read_json(path, "model")
    if isinstance(data, dict) and "model" in data:  # `windrig identify --json`
        data = data["model"]
    if not isinstance(data, dict):
        raise UsageError(f"{path}: expected a JSON object, the model or `windrig identify "
                         "--json` output")
    try:
        return RationalFunctionModel.from_dict(data)
    except (TypeError, ValueError, KeyError) as exc:
        raise UsageError(f"{path}: not a rational-function model ({exc}); expected "
                         '{"A": [[[...]]], "d": [...]} or `windrig identify --json` output'
                         ) from exc


def _read_model(path: Path, n_dof: int, section_path: Path) -> Any:
    model = read_model(path)
    if model.n_dof < n_dof:
        raise UsageError(f"{section_path} has a lateral spring (fp: three degrees of freedom) "
                         f"but {path} is a model of heave and pitch only: give a 3-DOF model "
                         "(3x3 matrices A)")
    if model.n_dof > n_dof:
        print(f"note: {section_path} has no lateral spring: using the heave-pitch part of "
              f"{path}'s 3-DOF model")
        model = model.planar()
    return model


def _table_fit(path: Path, convention: str, section: Any, out: dict[str, Any],
               warnings: list[str]) -> tuple[Any, Any]:
    """Read, check and fit a table; record its range, fit errors and checks in ``out``."""
    from daq.offline.derivative_table import table_std_report
    from ident.errors import IdentError
    from ident.model.conventions import FLUTTER_DERIVATIVE_NAMES
    from ident.tables.fd_table import FlutterDerivativeTable
    from ident.tables.roger_table import fit_table
    from ident.tables.table_checks import check_table

    try:
        table = FlutterDerivativeTable.from_csv(path, convention=convention)
    except ValueError as exc:
        raise UsageError(str(exc)) from exc
    if table.n_dof < section.n_dof:
        raise UsageError(f"{path} has the derivatives of heave and pitch only, but the section "
                         "has a lateral spring (fp): give all 18 (H1..H6, A1..A6, P1..P6)")
    if table.filled:
        print(f"note: {path} gives no {', '.join(table.filled)}: taken as zero")
    if table.n_dof > section.n_dof:
        # The section cannot sway, so these act on nothing; but a section file that left out
        # its lateral spring by mistake would lose the sway coupling without a word.
        sway = [n for n in table.values if n not in FLUTTER_DERIVATIVE_NAMES + table.filled]
        warnings.append(f"{path} gives the sway and drag derivatives {', '.join(sway)}, but the "
                        "section has no lateral spring (fp): they are left out and the "
                        "analysis is of heave and pitch alone; give fp and zeta_p in the "
                        "section for three degrees of freedom")
    if table.K.size < 4:
        raise UsageError(f"{path}: {table.K.size} row(s); a flutter analysis from a table "
                         "needs at least 4 reduced frequencies")
    warnings += check_table(table, path=str(path))
    try:
        fit = fit_table(table)
    except IdentError as exc:
        raise UsageError(f"{path}: {exc}") from exc
    print(f"{path}: {table.K.size} rows, K {table.K[0]:.3g} to {table.K[-1]:.3g}; "
          f"{fit.summary()}")
    std_line, std_keys = table_std_report(table)
    if std_line is not None:
        print(f"note: {std_line}")
    out.update(std_keys)
    out.update({"table": str(path), "table_convention": convention,
                "table_filled": list(table.filled), "table_K": table.K.tolist(),
                "table_fit_relative_error": fit.relative_error.tolist(),
                "table_fit_derivative_error": {name: error.tolist() for name, error
                                               in fit.derivative_error.items()},
                "table_fit_accuracy": fit.accuracy, "table_fit_structure": fit.reason})
    return table, fit


def read_json(path: Path, what: str) -> object:
    """Read a JSON file named on the command line (a bad one: a usage error naming it)."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise UsageError(f"{path}: cannot read the {what} file: {exc.strerror or exc}"
                         ) from exc
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise UsageError(f"{path}: not valid JSON ({exc.msg}, line {exc.lineno} column "
                         f"{exc.colno})") from exc
