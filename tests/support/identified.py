"""An identified flat-plate section as ``windrig identify --json`` writes it, for bridge tests.

Six simulated releases of :data:`support.sections.FLAT_PLATE` (R. T. Jones's flat plate, the
exact Roger model) at 0.4, 0.6 and 0.8 of its flutter speed, two holds each, 2 % measurement
noise, seeded; identified by E2RFC with the structure given (two lags with ``A3``: the truth's,
so the covariance is that of the true structure and no structure search is timed). The dict
holds what the bridge's uncertainty reads of the identify JSON: ``model``,
``model_covariance``, ``flutter_speed`` and ``flutter_speed_std_parts``.
"""

from __future__ import annotations

import functools
from typing import Any

from ident import Release
from ident.identification import e2rfc
from ident.identification.covariance import ModelCovariance
from ident.model import flat_plate
from ident.model import flutter as fl
from simulators import simulate_release

from support.sections import FLAT_PLATE

#: (h0 m, alpha0 rad) of the two holds.
HOLDS = ((0.004, 0.02), (-0.003, 0.012))


@functools.lru_cache(maxsize=1)
def identified_flat_plate() -> dict[str, Any]:
    """Return the identify-JSON dict of the seeded flat-plate identification (module doc)."""
    truth = flat_plate.jones_model()
    U_F = fl.analyze(FLAT_PLATE, truth).speed
    releases = [Release.from_simulation(simulate_release(
        FLAT_PLATE, truth, f * U_F, h0, a0, duration=6.0, fs=500.0, noise=0.2,
        rng=(40, i, j)))
        for i, f in enumerate((0.4, 0.6, 0.8)) for j, (h0, a0) in enumerate(HOLDS)]
    model = e2rfc.identify(releases, FLAT_PLATE, n_lags=2, with_A3=True)
    u = model.uncertainty(FLAT_PLATE)
    return {"model": model.to_dict(), "model_covariance": ModelCovariance.of(model).to_dict(),
            "flutter_speed": u.speed,
            "flutter_speed_std_parts": u.parts(),
            "warnings": list(u.warnings)}
