"""Parts of the benchmarks: command-line lists, the bound's inverse and exact check, its medians.

The benchmarks are scripts, not a package; these are the parts whose failure would be silent
(a wrong figure in a table) or a traceback for a user's typing.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import norm

from ident.model import flat_plate
from ident.model import flutter as fl
from simulators.decks import BLUFF_DECK, bluff_deck_model

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import flutter_crb  # noqa: E402 - benchmarks/ is not a package
import flutter_crb_exact as exact  # noqa: E402
import ident_accuracy  # noqa: E402
import result_files  # noqa: E402


@pytest.mark.parametrize(("text", "expected"), [
    ("0.01,abc", "--iw takes numbers separated by commas, got '0.01,abc'"),
    ("1,3", "--iw takes numbers between 0 and 0.5 (exclusive; fractions), got '1,3'"),
])
def test_number_list_refuses_bad_input_with_one_error_line(capsys, text, expected):
    parser = argparse.ArgumentParser(prog="bench")
    with pytest.raises(SystemExit) as exit_:
        result_files.number_list(parser, "--iw", text, 0.0, 0.5, "fractions")
    assert exit_.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[-1] == f"bench: error: {expected}"
    assert not any("Traceback" in line for line in lines)


@pytest.mark.parametrize(("text", "expected"), [
    ("0", "argument --workers: at least 1 is needed, got 0"),
    ("-2", "argument --workers: at least 1 is needed, got -2"),
    ("two", "argument --workers: an integer is needed, got 'two'"),
])
def test_workers_refuses_bad_input_with_one_error_line(capsys, text, expected):
    parser = argparse.ArgumentParser(prog="bench")
    result_files.add_workers(parser)
    with pytest.raises(SystemExit) as exit_:
        parser.parse_args(["--workers", text])
    assert exit_.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[-1] == f"bench: error: {expected}"


def test_workers_defaults_and_parses():
    parser = argparse.ArgumentParser(prog="bench")
    result_files.add_workers(parser, default=3)
    assert parser.parse_args([]).workers == 3
    assert parser.parse_args(["--workers", "1"]).workers == 1


def test_number_list_returns_the_numbers_in_order():
    parser = argparse.ArgumentParser(prog="bench")
    assert result_files.number_list(parser, "--speeds", "0.4, 0.6,0.8", 0.0, 1.0) == [0.4, 0.6,
                                                                                         0.8]


def test_bound_inverse_resolves_parameters_of_very_different_scale():
    """A badly scaled information matrix is inverted, not truncated.

    Its parameters span nine decades (a hold measures a displacement to micrometres, the
    coefficients are near one): invertible once scaled, while ``pinv``'s cut-off, relative to
    the largest singular value, drops directions of it unscaled.
    """
    rng = np.random.default_rng(3)
    Q = np.linalg.qr(rng.standard_normal((8, 8)))[0]
    well = Q @ np.diag(np.logspace(0, 3, 8)) @ Q.T  # condition number 1e3 once scaled
    scale = np.diag(np.logspace(-3, 6, 8))
    F = scale @ well @ scale
    exact = np.linalg.inv(scale) @ np.linalg.inv(well) @ np.linalg.inv(scale)
    # Relative to each variance: a well-conditioned inverse is good to about 1e-12; 1e-8 leaves
    # room for the scaling's rounding, and the unscaled pinv misses by orders more.
    relative = np.sqrt(np.outer(np.diag(exact), np.diag(exact)))
    assert np.max(np.abs(flutter_crb._inverse(F) - exact) / relative) < 1e-8
    assert np.max(np.abs(np.linalg.pinv(F) - exact) / relative) > 1e-2


def test_exact_bounds_covariance_is_the_process_whittle_sees():
    """The surrogate's two descriptions of one process agree.

    The stationary covariance that the exact bound builds by the Lyapunov recursion must be the
    inverse DTFT of the spectral matrix that Whittle's bound uses. The midpoint rule on 4096
    frequencies is spectrally accurate for that smooth periodic integrand (the modes' peaks,
    0.5 % damped, are some 0.002 cycles per sample wide): 3e-14 of the covariance's largest
    entry is what it gives, 1e-9 the bound; a transposed lag misses by 1e-2.
    """
    A, B_w, C = exact._augmented(flutter_crb.PLATE, flat_plate.jones_model(), 6.0, np.zeros(2))
    Phi, Q_d = exact._sampled(A, B_w, np.array([[1.0, 0.2], [0.2, 0.5]]), 0.1)
    N = 30
    cov = exact._covariance(Phi, Q_d, C, A.shape[0] - 4, N, from_rest=False)
    nu = (np.arange(4096) + 0.5) / 4096 - 0.5
    S = exact._spectrum(Phi, Q_d, C, nu)
    for lag in (0, 1, 7, 29):
        from_spectrum = np.real(np.mean(S * np.exp(2j * np.pi * nu * lag)[:, None, None],
                                        axis=0))
        block = cov[4 * lag:4 * lag + 4, 0:4]  # E[y_lag y_0^T]
        assert np.max(np.abs(block - from_spectrum)) < 1e-9 * np.max(np.abs(cov))
    # From rest the section has not moved yet: the first sample's displacements are certain.
    rest = exact._covariance(Phi, Q_d, C, A.shape[0] - 4, N, from_rest=True)
    assert rest[0, 0] == 0.0 and rest[1, 1] == 0.0
    assert rest[4 * (N - 1), 4 * (N - 1)] > 0.5 * cov[0, 0]


def test_two_lag_approximant_is_the_fits_class_and_flutters_with_the_deck():
    """The bound in the closed-loop fit's own class is taken at a model that stands for the deck.

    Its class is the fit's (two lags and A3); its flutter speed is checked against the deck's
    own flutter analysis (ten lags, independent of the fit). The least-squares fit flutters
    0.2 % above it (one lag or no A3: within 0.25 % too); 0.5 % leaves room for a change of
    the table's grid while a model that is not the deck's fails by far (the flat plate's
    aerodynamics on this section: 31 % above).
    """
    model = flutter_crb.two_lag_approximant()
    assert model.d.size == 2 and model.A.shape == (5, 2, 2)
    assert np.all(model.A[2] != 0.0)  # A3, the added mass, fitted too
    deck = fl.analyze(BLUFF_DECK, bluff_deck_model()).speed
    assert abs(fl.analyze(BLUFF_DECK, model).speed / deck - 1.0) < 0.005


@pytest.mark.parametrize("three_dof", [False, True])
def test_bounds_transfer_is_the_state_space_models(three_dof):
    """The bound's frequency response agrees with the closed-loop model's state space.

    ``flutter_crb._transfer`` inverts the impedance with Roger's ``Q(iK)``; the state-space
    system (:class:`ident.model.statespace.AeroelasticSystem`, the lag states explicit) is an
    independent route to the same response of every channel, sway and drag included, to the
    buffeting force: ``q = C_q (iw - A)^-1 E f_b`` and force ``F (iw - A)^-1 E f_b + Ms
    Meff^-1 f_b``. Both are exact: 1e-9 of each entry's scale is rounding, a channel out of
    place or a missing scale misses by order one.
    """
    from ident.identification.channels import (
        coordinate_scales,
        displacement_channels,
        force_channels,
    )
    from ident.model.statespace import AeroelasticSystem
    from simulators.decks import BLUFF_DECK_3DOF, bluff_deck_3dof_model

    section, model = ((BLUFF_DECK_3DOF, bluff_deck_3dof_model()) if three_dof
                      else (flutter_crb.PLATE, flat_plate.jones_model()))
    U, f = 0.6 * fl.analyze(section, model).speed, np.array([0.3, 1.1, 2.7, 4.0, 9.0])
    T = flutter_crb._transfer(section, model, U, f)
    system = AeroelasticSystem(section, model, U)
    A, n = system.matrix(), section.n_dof
    F = system.force_matrix(A)
    Meff_inv = np.linalg.inv(system.effective_mass())
    E = np.zeros((A.shape[0], n))
    E[n:2 * n] = Meff_inv
    scale = coordinate_scales(n, section.B)[:, None]
    for k, freq in enumerate(f):
        Z = np.linalg.solve(2j * np.pi * freq * np.eye(A.shape[0]) - A, E)
        expected = np.zeros((2 * n, n), dtype=complex)
        expected[displacement_channels(n)] = scale * Z[:n]
        expected[force_channels(n)] = (F @ Z + section.mass_matrix() @ Meff_inv) / scale
        assert T[k].shape == (2 * n, n)
        assert np.allclose(T[k], expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())


def test_bound_takes_sway_and_its_parts_order_as_information_does():
    """The Whittle bound runs with sway, and more data never loosens it.

    Short releases of the 3-DOF bluff deck's two-lag approximant in 1 % gusts (4 s at 100 Hz,
    to keep it quick): the std is finite and positive; the holds add information to the
    nuisance (std with holds <= without), and the random response adds it to the decay (the
    decay's alone, its own Schur complement, >= the full std). Each comparison holds for any
    information matrices the code builds correctly; a nuisance block out of place (the drag's
    level entries, the third held displacement) breaks the inverse's shape or its order.
    """
    from ident.physics.turbulence import TurbulenceSpec
    from ident.tables import roger_table
    from ident.tables.fd_table import FlutterDerivativeTable
    from simulators.decks import BLUFF_DECK_3DOF, BLUFF_DECK_3DOF_STATIC, bluff_deck_3dof_model

    table = FlutterDerivativeTable.from_model(bluff_deck_3dof_model(), np.linspace(0.25, 2.0, 12))
    model = roger_table.fit_table(table, n_lags=2, with_A3=True).model
    gusts = TurbulenceSpec(Iu=0.0, Iw=0.01, Lux=1.0, Lwx=0.3, Cuy=10.0, Cwy=8.0)
    bound = flutter_crb.flutter_speed_bound(
        BLUFF_DECK_3DOF, model, 0.01, static=BLUFF_DECK_3DOF_STATIC, fractions=(0.5, 0.8),
        holds=((0.01, 0.03, 0.01),), gusts=gusts, duration=4.0, fs=100.0, hold_s=2.0)
    assert 0.0 < bound.std < np.inf
    assert bound.std_with_holds <= bound.std
    assert bound.deterministic >= bound.std


def test_median_ratio_scatter_is_the_sample_medians_asymptotic_law():
    # The median of n half-normal errors is asymptotically normal about the half-normal's
    # median m with std 1 / (2 f(m) sqrt(n)), f = 2 phi the half-normal density: an
    # independent closed form for the simulated band and tail that bound_note prints. The
    # law's skew moves the band's edges by under 0.02 at 80 errors and under 0.05 at 20 (the
    # lower edge most), the tail's share by under 0.03 (the simulation's own scatter, 100 000
    # or 20 000 draws, is a tenth of that).
    m = ident_accuracy.HALF_NORMAL_MEDIAN
    for n, edge_tol, tail_tol in ((80, 0.02, 0.03), (20, 0.05, 0.03)):
        sd = 1.0 / (2 * 2 * norm.pdf(m) * np.sqrt(n)) / m  # in units of the median
        low, high, above = ident_accuracy._median_ratio_scatter(n)
        assert abs(low - (1 - norm.ppf(0.9) * sd)) < edge_tol
        assert abs(high - (1 + norm.ppf(0.9) * sd)) < edge_tol
        assert abs(above - norm.sf(0.2 / sd)) < tail_tol


def test_section_rows_replace_the_section_and_intensity_everywhere_the_row_is_read():
    # The releases, the truth and the bound all read row_spec: a row that kept the plate's
    # section or intensity anywhere would compare the identification with another truth.
    names = ident_accuracy.tunnel_rows("sections")
    assert names == list(ident_accuracy.SECTION_ROWS)
    section, make_model, _, Iw, _, _ = ident_accuracy.row_spec("low-frequency, Iw 2 %")
    assert section is ident_accuracy.LOW_FREQUENCY and Iw == 0.02
    assert make_model is flat_plate.jones_model
    section, _, _, Iw, _, _ = ident_accuracy.row_spec("deck (mu 41), Iw 3 %")
    assert section is ident_accuracy.DECK and Iw == 0.03
    assert ident_accuracy.row_spec("plate, Jones, Iw 1 %")[0] is ident_accuracy.PLATE
