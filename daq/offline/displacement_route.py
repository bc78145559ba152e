"""``windrig identify`` on a rig without taps: the displacement-only route, with its caveats.

Responsibility: :func:`run_displacement_route` identifies the rational-function model of run
files from their displacements alone (:func:`ident.identification.fd_method.identify`: flutter
derivatives from the free decays' modal fits at each wind speed, then Roger's least-squares fit),
prints the derivative table, the chosen structure and the flutter speed, and says what the route
cannot do: every caveat (:data:`CAVEATS`) is printed as a ``warning:`` line and written to the
JSON's ``warnings``. ``windrig identify`` takes this route when the files hold no forces (a rig
without taps or scanner), or when told to (``--route displacement``).

Not responsible for: reading the files (:func:`ident.records.run_file.read_run` with
``displacements_only=True``), choosing the route (:mod:`daq.offline.flutter_commands`), or the
method (:mod:`ident.identification.fd_method`, whose docstring derives the biases below).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["CAVEATS", "run_displacement_route"]

#: What the displacement-only route cannot do, said every time it runs (the biases are those
#: :mod:`ident.identification.fd_method` measures on the flat plate).
CAVEATS = (
    "displacement-only route: it needs releases at many wind speeds (at least 3, in practice "
    "6 or more, up to near flutter); E2RFC with the forces of pressure taps works from 2",
    "displacement-only route: its flutter derivatives are biased even without noise, since "
    "each column is read at one mode's frequency while each decaying mode moves both degrees "
    "of freedom, and decays are not harmonic: errors of the order of the damping ratio, a few "
    "% on H1, H3, A2, A3 at moderate speeds and 10-20 % on H1 and A2 near flutter, the small "
    "H2, H4, A1, A4 worse",
    "displacement-only route: the still-air added mass is absorbed into the reference "
    "stiffness and damping and is missing from the derivatives",
    "displacement-only route: the flutter speed has no standard deviation (the route gives "
    "none); with taps, E2RFC's is stated",
)


def run_displacement_route(runs: Sequence[Any], files: Sequence[Path], section: Any, *,
                           why: str, json_path: Path | None = None,
                           n_lags: int | None = None,
                           extra_warnings: Sequence[str] = ()) -> int:
    """Identify by the displacement-only route, print the result and caveats; return 0.

    Parameters
    ----------
    runs : sequence of RunFile
        Read with ``displacements_only=True``.
    files : sequence of Path
        Their paths (for the JSON).
    section : SectionModel
        The campaign's section (a 2-DOF one: the route identifies heave and pitch).
    why : str
        Why this route (printed): the files have no forces, or the user asked.
    json_path : Path, optional
        Also write the model, the derivative table, the flutter result and ``warnings``.
    n_lags : int, optional
        Number of lag terms (default: chosen by leave-one-speed-out error).
    extra_warnings : sequence of str
        Further warnings (the detected releases' weak onsets), printed and written too.

    Raises
    ------
    RankDeficiencyError
        Releases at fewer than three wind speeds (the route's known weakness, in its message).
    UsageError
        A 3-DOF section: the route identifies heave and pitch only.
    """
    from daq.errors import UsageError
    from ident.identification.fd_method import identify
    from ident.identification.uncertainty import ceiling_warnings
    from ident.model import flutter

    if section.n_dof != 2:
        raise UsageError("the displacement-only route identifies heave and pitch only; these "
                         "files are of a section with a lateral spring (fp)")
    releases = [r for run in runs for r in run.releases]
    print(f"route: displacement only ({why}): flutter derivatives from {len(releases)} "
          "free decay(s), then Roger's fit")
    model = identify(releases, section, n_lags=n_lags)
    table, diagnostics = model.table, model.diagnostics
    print(f"structure: {diagnostics.n_lags} lag(s), "
          f"{'with' if diagnostics.with_A3 else 'without'} A3 ({diagnostics.reason})")
    names = ("H1", "H2", "H3", "H4", "A1", "A2", "A3", "A4")
    print(f"{'U (m/s)':>8} {'K_h':>7} {'K_a':>7} " + " ".join(f"{n:>8}" for n in names))
    for i, U in enumerate(table.U):
        print(f"{U:8.2f} {table.K_h[i]:7.3f} {table.K_a[i]:7.3f} "
              + " ".join(f"{table.derivatives[n][i]:8.3f}" for n in names))
    result = flutter.analyze(section, model)
    if result.speed is None:
        print(result.summary())
    else:
        print(f"flutter speed {result.speed:.3f} m/s (no std: see the warnings), frequency "
              f"{result.frequency:.3f} Hz ({result.critical_mode} branch)")
    ceiling = (ceiling_warnings(section, table.U, result.U_max) if result.speed is None
               else ())
    warnings = [*extra_warnings, *table.warnings, *ceiling, *CAVEATS]
    for warning in warnings:
        print(f"warning: {warning}")
    if json_path is not None:
        json_path.write_text(json.dumps({
            "files": [str(p) for p in files],
            "route": "displacement_only",
            "why": why,
            "model": model.to_dict(),
            "structure": diagnostics.reason,
            "flutter_derivatives": {"U": table.U.tolist(), "K_h": table.K_h.tolist(),
                                    "K_a": table.K_a.tolist(),
                                    **{n: np.asarray(table.derivatives[n]).tolist()
                                       for n in names}},
            "flutter_speed": result.speed,
            "flutter_speed_std": None,
            "flutter_frequency": result.frequency,
            "critical_mode": result.critical_mode,
            "warnings": warnings,
        }, indent=2))
        print(f"wrote {json_path}")
    return 0
