"""``windrig demo``: a whole simulated campaign on the embedded default rig, end to end.

What it runs (README, "Two commands"): the simulated instruments of the default rig config
(``rig_configs/sim_flat_plate.toml``: a flat-plate section model, one pressure scanner module,
three lasers, the fan drive, the release PLC and a barometer) are started on loopback
transports, in a process of their own (:class:`daq.sim.rig_process.RigProcess`); the real drivers
and the acquisition engine record, through :func:`daq.sim.campaign.run_campaign`, two releases at
each of three wind speeds (0.5, 0.65 and 0.8 of the simulated flutter speed) into one HDF5 run
file per wind speed; the files are read back and identified by E2RFC; the identified flutter
speed is compared with the simulator's truth.

Printed: the truth (state-space flutter analysis of the simulated aerodynamics, cross-checked by
the frequency-domain solution with Theodorsen's exact flutter derivatives), one line per
release (measured frequencies and damping ratios against the truth at that wind speed), the
identified flutter speed with its standard deviation and its error, and the wall times.
Written into the output folder: the run files, ``campaign_decays.png``,
``campaign_flutter_derivatives.png``, ``campaign_flutter.png`` and ``summary.json``.

Not responsible for: the campaign itself (:mod:`daq.sim.campaign`), the numerics (:mod:`ident`).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from daq.config import SHIPPED_CONFIGS, load_rig_config
from daq.sim.campaign import run_campaign
from ident.model import flat_plate, flutter
from simulators.virtual_tunnel import AirState

#: The embedded default rig, shipped inside the package (``daq/rig_configs``).
DEFAULT_CONFIG = SHIPPED_CONFIGS / "sim_flat_plate.toml"
#: The issue's end-to-end target: identified flutter speed within 3 % of the truth.
TARGET_RELATIVE_ERROR = 0.03


def run(out: Path, config_path: Path | None = None, *, progress: bool = True) -> int:
    """Run the demo campaign into ``out`` (its old run files are replaced); return the exit code.

    Parameters
    ----------
    out : Path
        Output folder (created).
    config_path : Path, optional
        A simulated rig config; default :data:`DEFAULT_CONFIG`.
    progress : bool
        Progress bars while recording.

    Returns
    -------
    int
        0 when the campaign ran and flutter was identified, 1 otherwise (the reason is printed).
    """
    path = DEFAULT_CONFIG if config_path is None else Path(config_path)
    config = load_rig_config(path)
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob("campaign_U*.h5"):  # a re-run replaces the previous demo's files
        old.unlink()

    section = config.section
    print(f"windrig demo: simulated campaign on {config.name} ({path})")
    print(f"section: B = {section.B:g} m, m = {section.m:g} kg/m, I = {section.I:g} kg m^2/m, "
          f"fh = {section.fh:g} Hz, fa = {section.fa:g} Hz, zeta = {section.zeta_h:.2%} / "
          f"{section.zeta_a:.2%}")
    if section.n_dof == 3:  # the sway spring: three degrees of freedom
        print(f"sway: fp = {section.fp:g} Hz, zeta_p = {section.zeta_p:.2%}, "
              f"m_p = {section.m_p:g} kg/m (three degrees of freedom: h, alpha, p)")
    started = time.monotonic()
    result = run_campaign(config, out, progress=progress)
    truth_section = config.section.replace(rho=_simulated_density(config))
    truth_model = config.aerodynamic_model()
    truth = flutter.analyze(truth_section, truth_model)

    print()
    print("truth (the simulator's aerodynamics)")
    print(f"  state-space flutter analysis      U_F = {truth.speed:.3f} m/s, "
          f"f_F = {truth.frequency:.3f} Hz ({truth.critical_mode} branch)")
    if config.simulation is not None and config.simulation.aerodynamics == "flat_plate_jones":
        exact = flutter.frequency_domain(truth_section, flat_plate.flutter_derivatives)
        if exact.speed is not None and truth.speed is not None:
            print(f"  frequency domain, exact Theodorsen U_F = {exact.speed:.3f} m/s "
                  f"({100 * (truth.speed / exact.speed - 1):+.2f} %: the Jones approximation)")
    rows = _release_rows(result, truth)
    print()
    print(f"{'release':<28}{'U (m/s)':>8}{'f_h (Hz)':>10}{'f_a (Hz)':>10}{'zeta_h':>9}"
          f"{'zeta_a':>9}{'truth zeta_h':>14}{'truth zeta_a':>14}")
    for row in rows:
        print(f"{row['release']:<28}{row['U']:>8.2f}{row['f_h']:>10.3f}{row['f_a']:>10.3f}"
              f"{row['zeta_h']:>9.2%}{row['zeta_a']:>9.2%}{row['truth_zeta_h']:>14.2%}"
              f"{row['truth_zeta_a']:>14.2%}")
    print()
    print(result.summary())
    ok = result.relative_error is not None
    if ok:
        assert result.relative_error is not None
        verdict = ("within" if abs(result.relative_error) <= TARGET_RELATIVE_ERROR
                   else "NOT within")
        print(f"identified flutter speed {verdict} {TARGET_RELATIVE_ERROR:.0%} of the truth")
    elif result.identification_error is not None:
        print(f"not identified ({result.identification_error}): the run files, the decays and "
              "the truth's plots are written")
    else:
        print("no flutter speed identified: see the plots and the summary")
    summary = _summary(result, truth, rows, time.monotonic() - started)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    print(f"wrote {out / 'summary.json'}")
    return 0 if ok else 1


def _simulated_density(config: Any) -> float:
    sim = config.simulation
    air = AirState(pressure_pa=sim.pressure_pa, temperature_k=sim.temperature_c + 273.15)
    return float(air.density)


def _release_rows(result: Any, truth: Any) -> list[dict[str, Any]]:
    """Per release: modal frequencies and damping ratios, and the truth's at the same U."""
    analysis = result.analysis
    rows: list[dict[str, Any]] = []
    if analysis is None:
        return rows
    names = list(truth.mode_names)
    j_h = names.index("heave") if "heave" in names else 0
    j_a = names.index("pitch") if "pitch" in names else 1
    for i, (U, modes) in enumerate(zip(analysis.release_speeds, analysis.modes, strict=True)):
        truth_z = {j: float(np.interp(U, truth.U, truth.damping[:, j])) for j in (j_h, j_a)}
        source = result.releases[i].meta
        rows.append({"release": f"{Path(str(source['file'])).name} #{source['release']}",
                     "U": U, "f_h": modes.f_h, "f_a": modes.f_a, "zeta_h": modes.zeta_h,
                     "zeta_a": modes.zeta_a, "truth_zeta_h": truth_z[j_h],
                     "truth_zeta_a": truth_z[j_a]})
    return rows


def _summary(result: Any, truth: Any, rows: list[dict[str, Any]],
             wall_s: float) -> dict[str, Any]:
    analysis = {} if result.analysis is None else result.analysis.to_dict()
    return {
        "files": [str(p) for p in result.files],
        "wind_speeds": result.wind_speeds,
        "truth_flutter_speed": result.truth_speed,
        "truth_flutter_frequency": truth.frequency,
        "identified_flutter_speed": result.identified_speed,
        "identified_flutter_speed_std": result.identified_std,
        "identified_flutter_speed_structures": (
            None if result.structures is None
            else dict(zip(result.structures.labels, result.structures.speeds, strict=True))),
        "relative_error": result.relative_error,
        "target_relative_error": TARGET_RELATIVE_ERROR,
        "model": None if result.model is None else result.model.to_dict(),
        "structure": None if result.model is None else result.model.diagnostics.reason,
        "identified_flutter_speed_std_parts": analysis.get("flutter_std_parts"),
        "identified_flutter_speed_interval": analysis.get("flutter_interval"),
        "warnings": result.warnings,
        "identification_error": result.identification_error,
        "releases": rows,
        "timings_s": {**result.timings, "demo_total": wall_s},
        "plots": {k: str(v) for k, v in result.plots.items()},
    }


__all__ = ["DEFAULT_CONFIG", "TARGET_RELATIVE_ERROR", "run"]
