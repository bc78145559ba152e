"""The fast frequency-domain route against the dense scan of reduced frequencies.

Both solve the same quadratic problem at each K: the dense scan refines the crossing by Brent's
method on K (xtol 1e-14, rtol 1e-12), the fast route by Newton on ``T(i omega, 1/K) v = 0`` to
1e-13. Measured agreement 1e-16 to 1e-13; the tests ask for 1e-9 (the state-space route's
bound), far below the 1e-6 a flutter speed is read to.
"""

from __future__ import annotations

import numpy as np
import pytest

from ident.bridge import fast_flutter_fd as fdf
from ident.bridge import flutter as bf
from ident.bridge.aero import aero_from_table
from ident.bridge.model import BridgeModel
from ident.errors import FlutterCertificationError
from ident.model import flat_plate
from ident.tables.fd_table import FlutterDerivativeTable

from support.configs import BRIDGES

REL = 1e-9
SPAN = 600.0
M_H, M_A = 22740.0 * SPAN / 2, 2.47e6 * SPAN / 2
PLATE = flat_plate.jones_model().flutter_derivatives


def _deck(modes: list[tuple[str, float, str, list[float], float]], damping: float = 0.005
          ) -> BridgeModel:
    """Return a 600 m deck (B = 31 m) of modes ``(name, Hz, kind, sine amplitudes, mass)``."""
    x = np.linspace(0.0, SPAN, 61)
    return BridgeModel.from_dict({
        "B": 31.0, "rho": 1.22, "nodes_x": x.tolist(),
        "modes": [{"name": name, "frequency": f, "damping": damping, "generalised_mass": mass,
                   kind: np.sum([a * np.sin((k + 1) * np.pi * x / SPAN)
                                 for k, a in enumerate(amps)], axis=0).tolist()}
                  for name, f, kind, amps, mass in modes]})


def _same_flutter(bridge: BridgeModel, fd: bf.FlutterDerivativeFunction,
                  K_range: tuple[float, float] | None = None) -> bf.BridgeFlutterResult:
    dense = bf.frequency_domain(bridge, fd, K_range)
    fast = fdf.frequency_domain(bridge, fd, K_range)
    assert dense.speed is not None and fast.speed is not None
    assert fast.speed == pytest.approx(dense.speed, rel=REL)
    assert fast.frequency == pytest.approx(dense.frequency, rel=REL)
    assert fast.critical_mode == dense.critical_mode
    assert fast.method == "frequency-domain" and not fast.unstable_at_start
    assert fast.certification is not None and "certified by dense roots" in fast.certification
    return fast


def test_two_torsional_branches_close_in_frequency():
    """T1 at 0.28 Hz and a second torsional mode at 0.281 Hz, both coupled to V1."""
    bridge = _deck([("V1", 0.10, "h", [1.0], M_H), ("T1", 0.28, "alpha", [1.0], M_A),
                    ("T1b", 0.281, "alpha", [1.0, 0.3], M_A)])
    _same_flutter(bridge, PLATE)


@pytest.mark.parametrize(("f_T2", "dominant"), [(0.13, "T2"), (0.17, "V1")])
def test_a_mode_switch_between_torsion_and_heave_dominated_flutter(f_T2, dominant):
    """The state-space test's pairs: the heave-dominated V1-T1 pair or the torsional V2-T2."""
    bridge = _deck([("V1", 0.2, "h", [1.0], M_H), ("T1", 0.22, "alpha", [1.0], M_A),
                    ("V2", 0.06, "h", [0.0, 1.0], M_H), ("T2", f_T2, "alpha", [0.0, 1.0], M_A)])
    fast = _same_flutter(bridge, PLATE)
    label, share = fast.participating()[0]
    assert label.startswith(dominant) and share > 0.5


def test_a_3dof_bridge_with_sway_modes_and_the_example_deck_table():
    """The example bridge with the table's own rows (interpolated; 18 derivatives with sway)."""
    bridge = BridgeModel.from_json(BRIDGES / "example_bridge.json")
    aero = aero_from_table(bridge, FlutterDerivativeTable.from_csv(
        BRIDGES / "example_deck_table.csv"))
    assert "P1" in aero.flutter_derivatives(np.array([1.0]))
    fast = _same_flutter(bridge, aero.flutter_derivatives, aero.K_range)
    assert fast.critical_mode is not None
    assert fast.mode_labels[fast.critical_mode].startswith("T1S")


def test_the_certification_catches_a_branch_the_screening_skipped():
    bridge = _deck([("V1", 0.2, "h", [1.0], M_H), ("T1", 0.22, "alpha", [1.0], M_A),
                    ("V2", 0.06, "h", [0.0, 1.0], M_H), ("T2", 0.17, "alpha", [0.0, 1.0], M_A)])
    assert bf.frequency_domain(bridge, PLATE).critical_mode == 1
    with pytest.raises(FlutterCertificationError, match="fluttered first"):
        fdf.frequency_domain(bridge, PLATE, follow=[0, 2, 3])
    small = fdf.frequency_domain(bridge, PLATE, certify_max_states=4)
    assert small.certification is not None and "not certified" in small.certification


def test_a_branch_near_zero_damping_in_its_neighbourhood_is_followed_among_all_modes():
    """A branch near zero damping is followed again among all the modes.

    As the state space's test: one-mode neighbourhoods miss the coupled flutter (found
    nowhere, and not certified: no dense scan was run) unless the branches start inside
    NEAR_MISS and are followed again. The K range starts at K = 50 (under 1 m/s), where the
    branches still have their structural damping.
    """
    modes = [("V1", 0.2, "h", [1.0], M_H), ("T1", 0.22, "alpha", [1.0], M_A)]
    K_range = (0.05, 50.0)
    missed = fdf.frequency_domain(_deck(modes), PLATE, K_range, coupling_tol=1e9)
    assert missed.speed is None and missed.certification is not None
    assert "not certified: no flutter found" in missed.certification
    bridge = _deck(modes, damping=0.0005)
    dense = bf.frequency_domain(bridge, PLATE, K_range)
    fast = fdf.frequency_domain(bridge, PLATE, K_range, coupling_tol=1e9)
    assert dense.speed is not None and fast.speed == pytest.approx(dense.speed, rel=REL)
    assert fast.certification is not None
    assert "followed again among all modes" in fast.certification
    assert "certified by dense roots" in fast.certification
