"""The eigen route of the frequency-domain buffeting equals the direct one.

The module under test: ident.bridge.buffeting_eigen, through ident.bridge.buffeting.

The direct route (``route="direct"``) inverts the impedance and forms the exact modal force
matrix at every frequency; the eigen route (the default) takes one eigen decomposition of the
modal state space and splines the load matrix in frequency. On the same grid their trapezoid
sums differ only by the spline's error: measured 7.6e-6 relative on a load matrix at the
default 8 points a decade, 1e-5 on the RMS of the 200-mode benchmark deck (2.2e-5 on its
modal RMS). The tolerances below leave a margin of 4 to 8 over what is measured; where the
load matrix does not depend on frequency (full coherence) the routes are equal to rounding.
"""

from __future__ import annotations

import numpy as np
import pytest

from ident.bridge import buffeting as bf
from ident.bridge import buffeting_eigen as be
from ident.bridge.model import BridgeModel
from ident.bridge.statespace import BridgeStateSpace
from ident.bridge.wind import wind_from_dict
from ident.model import flat_plate
from ident.model.quasi_steady import quasi_steady_model
from ident.physics.turbulence import TurbulenceSpec

from support.iabse import IABSE_WIND, iabse_state_space

#: RMS (and modal RMS) of the two routes, relative: the spline's error (2.2e-5 measured on the
#: 200-mode deck's modal RMS) x 4.5.
RMS_TOLERANCE = 1e-4
#: Spectra, relative to each spectrum's peak: measured up to 2.6e-4 (modal spectra of the
#: 200-mode deck), x 4.
SPECTRUM_TOLERANCE = 1e-3
#: Correlation times of the modal spectra, relative: measured up to 6.4e-5, x 8.
CORRELATION_TOLERANCE = 5e-4

WIND = wind_from_dict({"Iu": 0.12, "Iw": 0.07, "Lux": 120.0, "Lwx": 30.0, "Cuy": 10.0,
                       "Cwy": 8.0, "admittance": {"kind": "davenport", "decay": 7.0}})


def _three_dof_deck() -> BridgeStateSpace:
    """Return a 600 m deck, 31 nodes, five modes coupling h, alpha and p; flat plate with two lags.

    The section model is 3-DOF (Jones's two lags on heave and pitch, quasi-steady sway from the
    static coefficients), so the state space has 5 (2 + 2) states and couples all three.
    """
    x = np.linspace(0.0, 600.0, 31)
    s1, s2 = np.sin(np.pi * x / 600.0), np.sin(2 * np.pi * x / 600.0)
    bridge = BridgeModel.from_dict({
        "B": 25.0, "rho": 1.22, "nodes_x": x.tolist(),
        "modes": [{"frequency": 0.12, "damping": 0.005, "generalised_mass": 6e6,
                   "h": s1.tolist(), "alpha": (0.001 * s1).tolist()},
                  {"frequency": 0.08, "damping": 0.004, "generalised_mass": 6e6,
                   "p": s1.tolist(), "alpha": (0.002 * s1).tolist()},
                  {"frequency": 0.17, "damping": 0.005, "generalised_mass": 6e6,
                   "h": s2.tolist()},
                  {"frequency": 0.35, "damping": 0.005, "generalised_mass": 3e8,
                   "alpha": s1.tolist(), "h": (0.05 * s1).tolist()},
                  {"frequency": 0.52, "damping": 0.006, "generalised_mass": 3e8,
                   "alpha": s2.tolist(), "p": (0.02 * s2).tolist()}],
        "static": {"C_D": 0.9, "C_L": -0.1, "C_M": 0.02, "dC_D": 0.1, "dC_L": -4.5,
                   "dC_M": 1.1}})
    static = bridge.static
    assert static is not None
    model = flat_plate.jones_model().with_sway(quasi_steady_model(static))
    assert model.n_dof == 3 and model.n_lags == 2
    return BridgeStateSpace(bridge, model)


def _sine_deck(n_modes: int, n_nodes: int) -> BridgeStateSpace:
    """Return the speed benchmark's deck (vertical, torsional, lateral sine modes), smaller."""
    x = np.linspace(0.0, 1200.0, n_nodes)
    modes = []
    for r in range(n_modes):
        kind, k = r % 3, r // 3 + 1
        shape = np.sin(k * np.pi * x / 1200.0)
        entry: dict[str, object] = {"damping": 0.005}
        if kind == 0:
            entry.update(frequency=0.085 + 0.03 * (k - 1), generalised_mass=22740.0 * 600.0,
                         h=shape.tolist())
        elif kind == 1:
            entry.update(frequency=0.28 + 0.09 * (k - 1), generalised_mass=2.47e6 * 600.0,
                         alpha=shape.tolist())
        else:
            entry.update(frequency=0.05 + 0.04 * (k - 1), generalised_mass=22750.0 * 600.0,
                         p=shape.tolist(), alpha=(0.002 * shape).tolist())
        modes.append(entry)
    bridge = BridgeModel.from_dict({
        "B": 31.0, "rho": 1.22, "nodes_x": x.tolist(), "modes": modes,
        "static": {"C_D": 0.08, "C_L": -0.1, "C_M": 0.02, "dC_D": 0.0, "dC_L": -5.0,
                   "dC_M": 1.2}})
    return BridgeStateSpace(bridge, flat_plate.jones_model())


def _assert_routes_agree(ss: BridgeStateSpace, spec: TurbulenceSpec, U: float,
                         rms_tol: float = RMS_TOLERANCE,
                         spectrum_tol: float = SPECTRUM_TOLERANCE,
                         correlation_tol: float = CORRELATION_TOLERANCE) -> None:
    fast = bf.frequency_domain(ss, spec, U)
    direct = bf.frequency_domain(ss, spec, U, route="direct")
    assert fast.route == "eigen" and direct.route == "direct"
    assert np.array_equal(fast.f, direct.f)  # the same grid
    for name in ("h", "alpha", "p"):
        a, b = getattr(fast, f"rms_{name}"), getattr(direct, f"rms_{name}")
        scale = max(float(b.max()), 1e-300)
        # Relative at every node, against the largest for nodes that barely move (supports).
        assert np.all(np.abs(a - b) <= rms_tol * np.maximum(b, 1e-6 * scale)), name
        S_a, S_b = fast.spectra[name], direct.spectra[name]
        assert np.abs(S_a - S_b).max() <= spectrum_tol * max(np.abs(S_b).max(), 1e-300), name
    assert fast.rms_modal == pytest.approx(direct.rms_modal, rel=rms_tol)
    peak = np.abs(direct.modal_spectra).max(axis=0)
    assert np.all(np.abs(fast.modal_spectra - direct.modal_spectra).max(axis=0)
                  <= spectrum_tol * peak)
    assert fast.modal_correlation_time == pytest.approx(direct.modal_correlation_time,
                                                        rel=correlation_tol)


def test_three_dof_deck_with_lags_both_routes_agree() -> None:
    ss = _three_dof_deck()
    _assert_routes_agree(ss, WIND, 30.0)


def test_sine_deck_both_routes_agree() -> None:
    """24 modes on 120 nodes, 2 lags (96 states): the benchmark's deck in small."""
    _assert_routes_agree(_sine_deck(24, 120), WIND, 40.0)


def test_full_coherence_routes_are_equal_to_rounding() -> None:
    """IABSE step 1.1a (full coherence, 8 lags): the load matrix is constant, no spline error.

    Tolerance 1e-9: rounding through an eigen decomposition of 20 states.
    """
    ss = iabse_state_space()
    assert IABSE_WIND.Cwy == 0.0
    _assert_routes_agree(ss, IABSE_WIND, 45.0, rms_tol=1e-9, spectrum_tol=1e-9,
                         correlation_tol=1e-9)


def test_rms_without_spectra_is_the_same() -> None:
    ss = _three_dof_deck()
    full = bf.frequency_domain(ss, WIND, 30.0)
    bare = bf.frequency_domain(ss, WIND, 30.0, spectra=False)
    assert bare.route == "eigen"
    assert np.array_equal(bare.rms_h, full.rms_h) and np.array_equal(bare.rms_p, full.rms_p)
    assert bare.spectra == {} and bare.correlation_time == {}
    assert bare.modal_spectra.size == 0 and bare.rms_modal.shape == (ss.n_modes,)


def test_spline_of_the_load_matrix_is_within_its_stated_error() -> None:
    """The coherent load matrix splined at 8 a decade against the exact one: 3e-5 relative.

    Measured 7.6e-6 here (the largest error against the largest entry, 40 frequencies; 9e-7
    at 14 a decade); the bound is 4 times that.
    """
    ss = _sine_deck(24, 120)
    f = bf.frequency_grid(ss, 40.0)
    P = bf.modal_gust_projection(ss.bridge)[1]
    x = ss.bridge.nodes_x
    basis = be.load_basis(lambda f_coarse: bf._coherent_quadratic(P, x, 8.0 / 40.0 * f_coarse),
                          f)
    assert basis.coefs.shape[0] < 100 and np.allclose(basis.design.sum(axis=1), 1.0)
    picks = np.linspace(0, f.size - 1, 40).astype(int)
    exact = bf._coherent_quadratic(P, x, 8.0 / 40.0 * f[picks])
    splined = np.einsum("fm,mij->fij", basis.design[picks], basis.coefs)
    assert np.abs(splined - exact).max() <= 3e-5 * np.abs(exact).max()


def test_certificate_catches_a_wrong_decomposition() -> None:
    """Eigenvalues paired with the wrong eigenvectors: the certificate refuses them.

    The right decomposition's mismatch is rounding (< 1e-9); two oscillatory poles swapped
    give an O(1) one, far above the route's tolerance (1e-5).
    """
    ss = _three_dof_deck()
    U = 30.0
    lam, vec = ss.eig(U)
    f = bf.frequency_grid(ss, U)
    assert bf.eigen_mismatch(ss, WIND, U, lam, vec, f) < 1e-9
    osc = np.flatnonzero(lam.imag > 0.0)
    order = np.argsort(-lam.real[osc] / np.abs(lam[osc]))  # least damped first
    a, b = osc[order[0]], osc[order[1]]
    wrong = lam.copy()
    wrong[[a, b]] = lam[[b, a]]
    assert bf.eigen_mismatch(ss, WIND, U, wrong, vec, f) > 1e-2


def test_unknown_route_is_refused() -> None:
    with pytest.raises(ValueError, match="route must be 'eigen' or 'direct'"):
        bf.frequency_domain(_three_dof_deck(), WIND, 30.0, route="fast")
