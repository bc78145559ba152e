"""The fast many-mode flutter route against the dense sweep, and its certification.

Both routes solve the same eigenproblem (the elimination of the lag states is exact): the dense
sweep finds the root of the largest growth by Brent's method (xtol 1e-12 U_max, with a growth
allowance of 1e-12 |lambda|), the fast route solves ``T(i omega, U) v = 0`` by Newton to 1e-13.
They agree to ~1e-11 (measured 1e-12 to 4e-11); the tests ask for 1e-9, a thousand times looser
than measured and still far below the 1e-6 a flutter speed is read to.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from ident.bridge import fast_flutter as ff
from ident.bridge import flutter as bf
from ident.bridge.aero import aero_from_table
from ident.bridge.model import BridgeModel
from ident.bridge.statespace import BridgeStateSpace
from ident.errors import FlutterCertificationError
from ident.model import flat_plate
from ident.model.rfc import RationalFunctionModel
from ident.tables.fd_table import FlutterDerivativeTable

from support.configs import BRIDGES

#: The agreement asked of the two routes (module docstring).
REL = 1e-9
SPAN = 600.0
#: Generalised masses of sine modes of the IABSE deck (m = 22740 kg/m, I = 2.47e6 kg m^2/m)
#: over half the span.
M_H, M_A = 22740.0 * SPAN / 2, 2.47e6 * SPAN / 2


def _deck(modes: list[tuple[str, float, str, int, float]], damping: float = 0.005
          ) -> BridgeModel:
    """Return a 600 m deck (B = 31 m), sine modes ``(name, Hz, "h"|"alpha", half-waves, mass)``."""
    x = np.linspace(0.0, SPAN, 61)
    return BridgeModel.from_dict({
        "B": 31.0, "rho": 1.22, "nodes_x": x.tolist(),
        "modes": [{"name": name, "frequency": f, "damping": damping, "generalised_mass": mass,
                   kind: np.sin(k * np.pi * x / SPAN).tolist()}
                  for name, f, kind, k, mass in modes]})


def _same_flutter(bridge: BridgeModel, model: RationalFunctionModel,
                  U_max: float | None = None) -> tuple[bf.BridgeFlutterResult,
                                                       bf.BridgeFlutterResult]:
    dense = bf.analyze(bridge, model, U_max)
    fast = ff.analyze(bridge, model, U_max)
    assert dense.speed is not None and fast.speed is not None
    assert fast.speed == pytest.approx(dense.speed, rel=REL)
    assert fast.frequency == pytest.approx(dense.frequency, rel=REL)
    assert fast.critical_mode == dense.critical_mode
    assert fast.participation is not None and dense.participation is not None
    # The flutter vectors are the same up to a complex factor: shares to the solvers' 1e-6
    # (a vector's error is the square root of its eigenvalue's).
    np.testing.assert_allclose(fast.participation, dense.participation, atol=1e-6)
    assert fast.certification is not None and "certified by dense" in fast.certification
    return dense, fast


def test_the_dense_eigenvalues_are_the_roots_of_det_T_on_a_random_model():
    """In the wind every eigenvalue of the state matrix makes ``T`` singular.

    A random 3-DOF Roger model (two lags) on three random modes coupling h, alpha and p: the
    smallest singular value of ``T(lambda, U)`` relative to its largest is at round-off
    (measured 1e-15; 1e-9 allows for the conditioning of the dense eigenvalues). The real
    eigenvalues of the lag states lie near, not at, the poles ``-U d_l / B`` of ``T``: all
    ``n (2 + m)`` are roots. In still air the lag states decouple (``x_l' = eta'``) with
    eigenvalue 0, not a root (``T(0, 0) = Ks``): the ``2 n`` others are.
    """
    rng = np.random.default_rng(40)
    x = np.linspace(0.0, 100.0, 11)
    modes = [{"frequency": f, "damping": 0.01, "generalised_mass": mass,
              "h": rng.normal(size=11).tolist(), "alpha": (0.05 * rng.normal(size=11)).tolist(),
              "p": rng.normal(size=11).tolist()}
             for f, mass in ((0.3, 2e5), (0.5, 3e5), (0.8, 1e5))]
    bridge = BridgeModel.from_dict({"B": 5.0, "rho": 1.2, "nodes_x": x.tolist(),
                                    "modes": modes})
    model = RationalFunctionModel(rng.normal(scale=0.5, size=(5, 3, 3)), np.array([0.2, 0.9]))
    problem = ff.ModalRationalProblem(bridge, model)
    ss = BridgeStateSpace(bridge, model)
    for U in (0.0, 7.0, 20.0):
        lam = ss.eigenvalues(U)
        roots = [x for x in lam if U > 0.0 or abs(x) > 1e-9]
        assert len(roots) == bridge.n_modes * (2 + (2 if U > 0.0 else 0))
        for root in roots:
            s = np.linalg.svd(problem.T(complex(root), U), compute_uv=False)
            assert s[-1] <= 1e-9 * s[0], (U, root)
        # And a value that is no eigenvalue leaves T regular (the check can fail).
        s = np.linalg.svd(problem.T(complex(roots[0]) + 0.1j, U), compute_uv=False)
        assert s[-1] > 1e-6 * s[0]


def test_two_torsional_branches_close_in_frequency():
    """T1 at 0.28 Hz and a second torsional mode at 0.281 Hz sharing its half-wave.

    The two branches start 0.36 % apart and couple through the heave mode; the continuation must
    not swap them: the same flutter point, branch and flutter vector as the dense sweep.
    """
    x = np.linspace(0.0, SPAN, 61)
    s1, s2 = np.sin(np.pi * x / SPAN), np.sin(2 * np.pi * x / SPAN)
    bridge = BridgeModel.from_dict({
        "B": 31.0, "rho": 1.22, "nodes_x": x.tolist(),
        "modes": [{"name": "V1", "frequency": 0.10, "damping": 0.005, "generalised_mass": M_H,
                   "h": s1.tolist()},
                  {"name": "T1", "frequency": 0.28, "damping": 0.005, "generalised_mass": M_A,
                   "alpha": s1.tolist()},
                  {"name": "T1b", "frequency": 0.281, "damping": 0.005,
                   "generalised_mass": M_A, "alpha": (s1 + 0.3 * s2).tolist()}]})
    dense, fast = _same_flutter(bridge, flat_plate.jones_model())
    # The flutter mode mixes both close torsional modes with the heave mode.
    shares = dict(fast.participating())
    assert min(shares[label] for label in fast.mode_labels) > 0.2


@pytest.mark.parametrize(("f_T2", "dominant"), [(0.13, "T2"), (0.17, "V1")])
def test_a_mode_switch_between_torsion_and_heave_dominated_flutter(f_T2, dominant):
    """Two independent pairs (1 and 2 half-waves); which one flutters first depends on T2.

    V1 (0.2 Hz) with T1 (0.22 Hz): frequencies 10 % apart, a heave-dominated flutter (V1 ~80 %
    of the strain energy) at 41.9 m/s. V2 (0.06 Hz) with T2: torsion-dominated flutter, below
    41.9 m/s with T2 at 0.13 Hz and above it at 0.17 Hz. Both routes switch alike.
    """
    bridge = _deck([("V1", 0.2, "h", 1, M_H), ("T1", 0.22, "alpha", 1, M_A),
                    ("V2", 0.06, "h", 2, M_H), ("T2", f_T2, "alpha", 2, M_A)])
    dense, fast = _same_flutter(bridge, flat_plate.jones_model())
    label, share = fast.participating()[0]
    assert label.startswith(dominant) and share > 0.5


def test_a_3dof_bridge_with_sway_modes_and_the_example_deck_table():
    """The example bridge (a lateral mode among six) with the example deck's table.

    The table's Roger fit, with quasi-steady drag and sway terms from the bridge's static
    coefficients (3 DOF); flutter on the T1S branch at 64.6 m/s.
    """
    bridge = BridgeModel.from_json(BRIDGES / "example_bridge.json")
    aero = aero_from_table(bridge, FlutterDerivativeTable.from_csv(
        BRIDGES / "example_deck_table.csv"))
    assert aero.model.n_dof == 3 and any(np.any(mode.p) for mode in bridge.modes)
    dense, fast = _same_flutter(bridge, aero.model)
    assert fast.critical_mode is not None
    assert fast.mode_labels[fast.critical_mode].startswith("T1S")


def test_the_certification_catches_a_branch_the_screening_skipped():
    """Skip the critical branch: the next pair's flutter is found, and the check refuses it."""
    bridge = _deck([("V1", 0.2, "h", 1, M_H), ("T1", 0.22, "alpha", 1, M_A),
                    ("V2", 0.06, "h", 2, M_H), ("T2", 0.17, "alpha", 2, M_A)])
    model = flat_plate.jones_model()
    dense = bf.analyze(bridge, model)
    assert dense.critical_mode == 1
    with pytest.raises(FlutterCertificationError, match="already grow"):
        ff.analyze(bridge, model, follow=[0, 2, 3])
    # Followed alone, the critical branch gives the dense answer.
    alone = ff.analyze(bridge, model, follow=[1])
    assert alone.speed == pytest.approx(dense.speed, rel=REL)
    assert alone.certification is not None and "1 of 4 branches" in alone.certification


def test_no_flutter_below_u_max_is_certified_and_a_missed_one_is_not():
    bridge = _deck([("V1", 0.2, "h", 1, M_H), ("T1", 0.22, "alpha", 1, M_A)])
    model = flat_plate.jones_model()
    low = ff.analyze(bridge, model, U_max=30.0)
    assert low.speed is None and low.certification is not None
    assert "no eigenvalue grows at U_max" in low.certification
    with pytest.raises(FlutterCertificationError, match="found no flutter"):
        ff.analyze(bridge, model, U_max=60.0, follow=[0])


def test_above_the_dense_limit_the_result_says_it_is_not_certified():
    bridge = _deck([("V1", 0.2, "h", 1, M_H), ("T1", 0.22, "alpha", 1, M_A)])
    result = ff.analyze(bridge, flat_plate.jones_model(), certify_max_states=4)
    assert result.certification is not None and "not certified" in result.certification
    data = json.loads(json.dumps(result.to_dict(), allow_nan=False))  # strict JSON
    assert data["certification"] == result.certification
    # Each branch has its own wind speeds; a branch's curve ends with null, not NaN.
    assert len(data["U"][0]) == 2 and data["U"][0] == [0.0, 0.0]
    with pytest.raises(ValueError, match="follow"):
        ff.analyze(bridge, flat_plate.jones_model(), follow=[5])


def test_a_branch_near_zero_damping_in_its_neighbourhood_is_followed_among_all_modes():
    """A branch near zero damping is followed again among all the modes.

    Neighbourhoods of one mode each (a coupling_tol no coupling reaches): heave-torsion
    flutter cannot happen in them. With 0.5 % structural damping no branch comes near zero
    damping alone, the flutter is missed and the dense check refuses the result; with 0.05 %
    (inside NEAR_MISS) every branch starts near zero, is followed again among all the modes,
    and the dense sweep's flutter is found.
    """
    modes = [("V1", 0.2, "h", 1, M_H), ("T1", 0.22, "alpha", 1, M_A)]
    model = flat_plate.jones_model()
    assert 0.0005 < ff.NEAR_MISS < 0.005
    with pytest.raises(FlutterCertificationError):
        ff.analyze(_deck(modes), model, coupling_tol=1e9)
    bridge = _deck(modes, damping=0.0005)
    dense = bf.analyze(bridge, model)
    fast = ff.analyze(bridge, model, coupling_tol=1e9)
    assert dense.speed is not None and fast.speed == pytest.approx(dense.speed, rel=REL)
    assert fast.certification is not None
    assert "2 followed again among all modes" in fast.certification
    assert "certified by dense" in fast.certification
