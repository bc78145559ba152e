"""Multimode flutter of a bridge: against the section analysis, closed forms and a benchmark."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from ident.bridge import flutter as bf
from ident.bridge.aero import aero_from_model, aero_from_table
from ident.bridge.model import BridgeModel
from ident.bridge.statespace import BridgeStateSpace, system_matrix
from ident.model import flat_plate
from ident.model import flutter as section_flutter
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.model.statespace import AeroelasticSystem
from ident.tables.fd_table import FlutterDerivativeTable
from simulators.decks import BLUFF_DECK, bluff_deck_model

from support.configs import BRIDGES
from support.sections import FLAT_PLATE


def _uniform_bridge(section: SectionModel, length: float = 1.0, nodes: int = 2,
                    shapes: tuple[str, ...] = ("h", "alpha")) -> BridgeModel:
    """Return the section as a bridge: uniform modes (shape 1) on a deck of ``length``."""
    x = np.linspace(0.0, length, nodes).tolist()
    data = {"h": (section.fh, section.zeta_h, section.m), "alpha": (section.fa, section.zeta_a,
                                                                  section.I)}
    modes = [{"frequency": data[s][0], "damping": data[s][1],
              "generalised_mass": data[s][2] * length, s: [1.0] * nodes} for s in shapes]
    return BridgeModel.from_dict({"B": section.B, "rho": section.rho, "nodes_x": x,
                                  "modes": modes})


@pytest.mark.parametrize(("section", "model"), [
    (FLAT_PLATE,
     flat_plate.jones_model()),
    (BLUFF_DECK, bluff_deck_model()),
], ids=["flat plate", "bluff deck"])
def test_two_uniform_modes_on_a_1m_deck_are_the_2dof_section(section, model):
    """Heave and pitch modes of shape 1 on a 1 m deck (two nodes): the section's equations.

    With ``eta = [h, alpha]`` the bridge's matrices are the section's in ``q = [h/B, alpha]``
    scaled by ``diag(B, 1)``: the eigenvalues are the same to round-off, so the flutter speeds
    agree to the root solver's tolerance (1e-12 relative); 1e-6 is the bound asked for.
    """
    bridge = _uniform_bridge(section)
    for U in (0.0, 5.0, 12.0):
        a = np.sort_complex(BridgeStateSpace(bridge, model).eigenvalues(U))
        b = np.sort_complex(AeroelasticSystem(section, model, U).eigenvalues())
        np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-9 * np.abs(b).max())
    truth = section_flutter.analyze(section, model)
    result = bf.analyze(bridge, model)
    assert result.speed == pytest.approx(truth.speed, rel=1e-6)
    assert result.frequency == pytest.approx(truth.frequency, rel=1e-6)
    assert result.mode_labels[result.critical_mode].startswith("mode 2")  # pitch, like truth
    assert truth.critical_mode == "pitch"
    check = bf.frequency_domain(bridge, model.flutter_derivatives)
    assert check.speed == pytest.approx(truth.speed, rel=1e-6)


def test_a_single_uniform_mode_on_a_long_deck_is_the_section():
    """One pitch mode, shape 1 on 120 m (13 uneven nodes): the section's pitch branch.

    The section gets aerodynamics without heave-pitch coupling (the bluff deck's pitch-pitch
    entry alone), so its pitch branch is one degree of freedom; the bridge's single mode, of
    generalised mass I L, must give the same flutter speed and the same damping curve: the
    deck length, the node spacing and the quadrature must cancel exactly (1e-9).
    """
    model = bluff_deck_model()
    A = np.zeros_like(model.A)
    A[:, 1, 1] = model.A[:, 1, 1]
    pitch_only = RationalFunctionModel(A, model.d)
    x = np.sort(np.concatenate([[0.0, 120.0], np.random.default_rng(3).uniform(0, 120, 11)]))
    bridge = BridgeModel.from_dict({
        "B": BLUFF_DECK.B, "rho": BLUFF_DECK.rho, "nodes_x": x.tolist(),
        "modes": [{"frequency": BLUFF_DECK.fa, "damping": BLUFF_DECK.zeta_a,
                   "generalised_mass": BLUFF_DECK.I * 120.0, "alpha": [1.0] * x.size}]})
    truth = section_flutter.analyze(BLUFF_DECK, pitch_only)
    result = bf.analyze(bridge, pitch_only, U_max=truth.U_max, n_points=400)
    assert truth.critical_mode == "pitch"
    assert result.speed == pytest.approx(truth.speed, rel=1e-9)
    np.testing.assert_allclose(result.damping[:, 0], truth.damping[:, 1], rtol=0, atol=1e-9)
    assert result.participation.tolist() == [1.0]


def test_sine_modes_of_a_simply_supported_deck_are_the_section_too():
    """V1 and T1 of shape sin(pi x/L), generalised masses m L/2 and I L/2: the section.

    The trapezoid sum of sin^2 over equal steps with zero ends is L/2 exactly, so the modal
    aerodynamic matrices are L/2 times the section's and the flutter speed is the section's
    (1e-9). The integrals themselves are checked against L/2 and zero (orthogonal sines).
    """
    section = SectionModel(B=31.0, m=22740.0, I=2.47e6, fh=0.105, fa=0.28, zeta_h=0.005,
                           zeta_a=0.005, rho=1.22)
    L, x = 800.0, np.linspace(0.0, 800.0, 41)
    s1, s2 = np.sin(np.pi * x / L), np.sin(2 * np.pi * x / L)
    bridge = BridgeModel.from_dict({"B": 31.0, "rho": 1.22, "nodes_x": x.tolist(), "modes": [
        {"frequency": 0.105, "damping": 0.005, "generalised_mass": 22740.0 * L / 2,
         "h": s1.tolist()},
        {"frequency": 0.28, "damping": 0.005, "generalised_mass": 2.47e6 * L / 2,
         "alpha": s1.tolist()},
        {"frequency": 0.36, "damping": 0.005, "generalised_mass": 2.47e6 * L / 2,
         "alpha": s2.tolist()}]})
    G = bridge.shape_integrals()
    assert G[1, 1, 1, 1] == pytest.approx(L / 2, rel=1e-12)
    assert G[0, 0, 0, 0] == pytest.approx(L / 2 / 31.0**2, rel=1e-12)
    assert abs(G[1, 1, 1, 2]) < 1e-12 * L and abs(G[0, 1, 0, 2]) < 1e-12 * L
    model = flat_plate.jones_model()
    truth = section_flutter.analyze(section, model)
    result = bf.analyze(bridge, model)
    assert result.speed == pytest.approx(truth.speed, rel=1e-9)
    shares = dict(result.participating())
    assert set(shares) == {bridge.mode_labels()[0], bridge.mode_labels()[1]}  # not T1A


def test_iabse_step_1_1a_flutter_speed():
    """IABSE superstructure benchmark, step 1.1a: flutter at 77.45 m/s (within 1 %).

    A 1 m uniform deck (two nodes), heave and pitch modes of shape 1, generalised masses
    m x 1 m and I x 1 m, the flat plate's Theodorsen forces: state space with the 8-lag
    rational fit of the exact Theodorsen function, frequency domain with the exact function.
    Measured: 77.24 m/s both, 0.1936 Hz (-0.27 % of the benchmark's value).
    """
    bridge = BridgeModel.from_dict({"B": 31.0, "rho": 1.22, "nodes_x": [0.0, 1.0], "modes": [
        {"frequency": 0.100, "damping": 0.003, "generalised_mass": 22740.0, "h": [1.0, 1.0]},
        {"frequency": 0.278, "damping": 0.003, "generalised_mass": 2.47e6,
         "alpha": [1.0, 1.0]}]})
    state_space = bf.analyze(bridge, flat_plate.theodorsen_model())
    frequency_domain = bf.frequency_domain(bridge, flat_plate.flutter_derivatives)
    assert state_space.speed == pytest.approx(77.45, rel=0.01)
    assert frequency_domain.speed == pytest.approx(77.45, rel=0.01)
    # The two routes differ by the rational fit of Theodorsen's function only (error 5e-5).
    assert state_space.speed == pytest.approx(frequency_domain.speed, rel=1e-4)
    assert state_space.mode_labels[state_space.critical_mode].startswith("mode 2")


def _example() -> BridgeModel:
    return BridgeModel.from_json(BRIDGES / "example_bridge.json")


def test_state_space_equals_frequency_domain_on_the_example_bridge_with_a_model():
    """The shipped example (6 modes) with the flat-plate model: both routes, within 0.5 %.

    The same Q(p) enters both, so they agree to the root solvers (measured 1e-7); sway is
    quasi-steady from the static coefficients (a note says so). Flutter couples T1S and V1S.
    """
    bridge = _example()
    model = RationalFunctionModel.from_dict(
        json.loads((BRIDGES / "example_deck_model.json").read_text()))
    aero = aero_from_model(bridge, model, source="model.json")
    assert aero.model.n_dof == 3 and "quasi-steady" in aero.notes[0]
    ss = bf.analyze(bridge, aero.model)
    fd = bf.frequency_domain(bridge, aero.flutter_derivatives, U_max=ss.U_max)
    assert ss.speed == pytest.approx(fd.speed, rel=0.005)
    assert ss.speed == pytest.approx(fd.speed, rel=1e-6)
    names = [label.split(" (")[0] for label, _ in ss.participating()]
    assert names == ["T1S", "V1S"]
    assert ss.frequencies.shape == (120, 6) and ss.damping.shape == (120, 6)
    # In still air each branch starts at its mode's frequency lowered by the flat plate's added
    # mass, rho pi B^2/4 per metre in heave and rho pi B^4/128 in pitch (closed form; the
    # lateral mode feels the pitch's through its 0.002 rad/m; 1e-6 leaves room for the
    # coupling of modes through it, ~1e-8); damped, with the ratio 0.005 lowered alike.
    m, I, L = 22740.0, 2.47e6, 800.0
    heave = (1 + 1.22 * np.pi * 31.0**2 / 4 / m) ** -0.5
    pitch = (1 + 1.22 * np.pi * 31.0**4 / 128 / I) ** -0.5
    sway = (1 + 1.22 * np.pi * 31.0**4 / 128 * 0.002**2 * L / 2 / bridge.modes[0]
            .generalised_mass) ** -0.5
    factor = np.array([sway, heave, heave, heave, pitch, pitch])
    expected = bridge.frequencies * factor * np.sqrt(1 - (0.005 * factor) ** 2)
    np.testing.assert_allclose(ss.frequencies[0], expected, rtol=1e-6)


def test_state_space_equals_frequency_domain_on_the_example_bridge_with_a_bluff_table():
    """The example bridge with the bluff deck's table (reduced velocities 2 to 20).

    The state space uses the table's Roger fit (relative error below 0.5 % at every row:
    measured 0.14 % worst), the frequency domain the table itself: flutter speeds within
    0.5 % (measured 64.62 and 64.67 m/s, 0.08 %).
    """
    bridge = _example()
    table = FlutterDerivativeTable.from_csv(BRIDGES / "example_deck_table.csv")
    aero = aero_from_table(bridge, table, source="table.csv")
    assert aero.table_fit is not None
    assert aero.table_fit.relative_error.shape == table.K.shape
    assert aero.table_fit.relative_error.max() < 0.005
    ss = bf.analyze(bridge, aero.model)
    fd = bf.frequency_domain(bridge, aero.flutter_derivatives, aero.K_range)
    assert ss.speed is not None and fd.speed is not None
    assert ss.speed == pytest.approx(fd.speed, rel=0.005)
    assert ss.mode_labels[ss.critical_mode].startswith("T1S")


def test_no_flutter_below_u_max_and_the_system_matrix_function():
    bridge = _example()
    model = flat_plate.jones_model()
    result = bf.analyze(bridge, model, U_max=40.0, n_points=20)
    assert result.speed is None and not result.found
    assert "no flutter below U_max = 40 m/s" in result.summary()
    S = system_matrix(bridge, model, 30.0)
    assert S.shape == (6 * (2 + 2),) * 2
    np.testing.assert_array_equal(S, BridgeStateSpace(bridge, model).matrix(30.0))
    with pytest.raises(ValueError, match="U must be >= 0"):
        BridgeStateSpace(bridge, model).matrix(-1.0)
    with pytest.raises(ValueError, match="n_points must be an integer >= 20"):
        bf.analyze(bridge, model, n_points=5)


def test_the_lag_states_are_modal_the_input_matrix_is_the_inverse_effective_mass():
    """A constant generalised force gives the static deflection K_eff^-1 F (lags settle)."""
    bridge = _example()
    model = flat_plate.jones_model().with_sway(
        __import__("ident.model.quasi_steady", fromlist=["x"]).quasi_steady_model(bridge.static))
    ss = BridgeStateSpace(bridge, model)
    U = 30.0
    S, E = ss.matrix(U), ss.input_matrix()
    F = np.linspace(1.0, 2.0, bridge.n_modes) * 1e5
    z = np.linalg.solve(S, -E @ F)  # steady state: S z + E F = 0
    # At rest the lag states equal zero (x_l' = eta' - (U/B) d_l x_l with eta' = 0), so the
    # static equation is (Ks - rho/2 U^2 B^2 A1m) eta = F.
    K_eff = bridge.stiffness_matrix() - 0.5 * bridge.rho * U**2 * bridge.B**2 * ss.modal_A[0]
    np.testing.assert_allclose(z[: bridge.n_modes], np.linalg.solve(K_eff, F), rtol=1e-9)
    np.testing.assert_allclose(z[bridge.n_modes:], 0.0, atol=1e-12 * np.abs(z).max())
    assert math.isclose(float(np.abs(ss.modal_part(z) - z[:6]).max()), 0.0)


def test_a_table_of_18_derivatives_gives_what_the_completed_model_gives():
    """Sway from an 18-derivative table equals the 2-DOF model completed quasi-steadily.

    The table tabulates the flat plate (Jones) with the quasi-steady drag and sway terms of the
    example's static coefficients at 25 reduced velocities from 1 to 40; its Roger fit is exact
    up to the fit (the model is of Roger's form: relative error < 1e-6 at every row), so the
    flutter speed equals the one from the 2-DOF model, which the bridge completes with the same
    terms, to 1e-5. The frequency domain interpolates the table's rows (monotone cubic between
    reduced velocities 1.6 apart): 0.1 % (measured 0.025 %).
    """
    from ident.model.quasi_steady import quasi_steady_model

    bridge = _example()
    model_3dof = flat_plate.jones_model().with_sway(quasi_steady_model(bridge.static))
    K = 2 * np.pi / np.linspace(1.0, 40.0, 25)
    table = FlutterDerivativeTable.from_model(model_3dof, K)
    assert table.n_dof == 3
    aero = aero_from_table(bridge, table)
    assert aero.notes == [] and aero.model.n_dof == 3
    assert aero.table_fit is not None and aero.table_fit.relative_error.max() < 1e-6
    completed = aero_from_model(bridge, flat_plate.jones_model())
    truth = bf.analyze(bridge, completed.model).speed
    assert bf.analyze(bridge, aero.model).speed == pytest.approx(truth, rel=1e-5)
    fd = bf.frequency_domain(bridge, aero.flutter_derivatives, aero.K_range)
    assert fd.speed == pytest.approx(truth, rel=1e-3)
