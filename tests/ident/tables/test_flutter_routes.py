"""Both flutter routes from awkward tables (ident.tables.flutter_routes, roger_table accuracy).

The tables are the shipped bluff-deck table (daq/rig_configs/bridges/example_deck_table.csv,
19 rows, reduced velocity 2-20) with one mistake each, and tables of known models. The
independent results: the frequency domain on the table itself, and the state space of the model
a table was made from.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ident.model import flat_plate, flutter
from ident.model.flat_plate import plate_model
from ident.model.section import SectionModel
from ident.tables.fd_table import FlutterDerivativeTable
from ident.tables.flutter_routes import (
    ROUTE_TOLERANCE,
    compare_routes,
    section_flutter,
    table_divergence_speed,
)
from ident.tables.roger_table import ACCURACY, fit_table

from support.configs import BRIDGES
from support.sections import FLAT_PLATE

EXAMPLE = FlutterDerivativeTable.from_csv(BRIDGES / "example_deck_table.csv")


@pytest.fixture(scope="module")
def clean():
    """Both routes on the shipped table (computed once: a fit takes a few seconds)."""
    return section_flutter(FLAT_PLATE, table=EXAMPLE)


def _variant(**changes: np.ndarray) -> FlutterDerivativeTable:
    values = {**EXAMPLE.values, **changes}
    return FlutterDerivativeTable(K=EXAMPLE.K, values=values)


def test_a_clean_table_needs_one_caveat(clean):
    """The shipped table: the routes agree within 0.5 %; only the divergence is extrapolated."""
    routes = clean
    c = routes.comparison
    assert c.basis == "state-space" and abs(c.difference) < ROUTE_TOLERANCE
    assert len(c.warnings) == 1 and c.warnings[0].startswith(
        f"divergence at {c.divergence_speed:.4g} m/s lies outside the table's K range")
    assert routes.fit is not None and routes.fit.meets_accuracy
    assert c.K_range == (EXAMPLE.K[0], EXAMPLE.K[-1])
    assert c.fit_error_at_flutter is not None and max(c.fit_error_at_flutter.values()) < ACCURACY
    assert "extrapolated beyond the table's lowest K = 0.314" in c.divergence_basis
    d = c.to_dict()
    assert d["warnings"] == list(c.warnings) and d["units"]["flutter_speed"] == "m/s"


def test_a_shifted_damping_derivative_is_not_flutter_at_walking_pace():
    """A2* + 0.15 at every row: the fit's state space once fluttered at 0.003 m/s (K ~ 2000).

    That instability lies far below the table's wind speeds and the table does not show it
    (its frequency domain is stable at its lowest reduced velocity): the next structure
    replaces the fit, the routes still disagree (the fit misses 2 %), the result rests on the
    table, and the warnings say all of it.
    """
    routes = section_flutter(FLAT_PLATE, table=_variant(A2=EXAMPLE.values["A2"] + 0.15))
    c = routes.comparison
    assert c.speed is not None and c.speed > 5.0
    assert c.basis == "frequency-domain" and c.speed == c.frequency_domain_speed
    assert c.K_range is not None and c.K_range[0] <= c.reduced_frequency <= c.K_range[1]
    text = " | ".join(c.warnings)
    assert "below the table's range, which the table does not show" in text
    assert "the two routes disagree" in text and "rests on the frequency domain" in text
    assert routes.state_space.speed is not None and routes.state_space.speed > 5.0
    # The fit's error at the flutter point is that of the structure the state space used.
    fit = routes.fit
    assert fit is not None and routes.model is not fit.model and c.reduced_frequency is not None
    assert c.fit_error_at_flutter == fit.error_at(c.reduced_frequency, routes.model)
    assert c.fit_error_at_flutter != fit.error_at(c.reduced_frequency)


def test_a_sign_typo_at_one_row_is_named_by_the_fit():
    """One A2* with its sign flipped: no structure reaches 2 %; the fit says where it misses."""
    a2 = EXAMPLE.values["A2"].copy()
    a2[5] = -a2[5]
    routes = section_flutter(FLAT_PLATE, table=_variant(A2=a2))
    fit = routes.fit
    assert fit is not None and not fit.meets_accuracy
    name, row, error = fit.worst
    assert name == "A2" and abs(row - 5) <= 1 and error > ACCURACY
    assert any("MISSES the 2 %" in w for w in routes.comparison.warnings)


def test_a_table_that_stops_short_of_flutter_gives_no_flutter_speed():
    """Rows only up to a reduced velocity of 8: flutter (at ~10) lies beyond the table.

    Neither route reports a flutter speed; a warning says the table ends and what the fit,
    extrapolated, would say, "not a result".
    """
    keep = EXAMPLE.K > 2 * math.pi / 8
    short = FlutterDerivativeTable(K=EXAMPLE.K[keep],
                                   values={k: v[keep] for k, v in EXAMPLE.values.items()})
    c = section_flutter(FLAT_PLATE, table=short).comparison
    assert c.speed is None and c.basis == "none"
    assert any("no flutter within the table" in w and "not a result" in w for w in c.warnings)


def test_a_sparse_table_holds_within_its_accuracy(clean):
    """Eight rows of the 19: the fit still reaches 2 % and the routes agree within 0.5 %."""
    rows = np.linspace(0, EXAMPLE.K.size - 1, 8).round().astype(int)
    sparse = FlutterDerivativeTable(K=EXAMPLE.K[rows],
                                    values={k: v[rows] for k, v in EXAMPLE.values.items()})
    c = section_flutter(FLAT_PLATE, table=sparse).comparison
    full = clean.comparison
    assert abs(c.difference) < ROUTE_TOLERANCE
    # Tolerance 1 %: eight rows interpolated (PCHIP) against nineteen.
    assert c.speed == pytest.approx(full.speed, rel=0.01)


def test_a_noisy_table_is_reported_and_rests_on_the_table(clean):
    """5 % scatter (seeded): the fit cannot reach 2 %, and says so; the result is the table's."""
    rng = np.random.default_rng(3)
    noisy = _variant(**{k: v * (1 + 0.05 * rng.standard_normal(v.size))
                        for k, v in EXAMPLE.values.items()})
    c = section_flutter(FLAT_PLATE, table=noisy).comparison
    assert any("MISSES the 2 %" in w for w in c.warnings)
    # Within 5 % of the clean table's flutter speed: the scatter moves the damping
    # derivatives near the flutter K by about as much.
    assert c.speed == pytest.approx(clean.comparison.speed, rel=0.05)


def test_more_lags_when_three_miss_the_accuracy():
    """A plate with five lags spread over three decades, tabulated at 151 K from 0.021 to 1.26.

    Whatever structure is chosen must reach 2 % of each force, and its state space agree with
    the model's own flutter speed (the independent result) within 0.5 %.
    """
    truth = plate_model([0.12, 0.15, 0.1, 0.08, 0.05], [0.02, 0.08, 0.35, 1.4, 5.0])
    table = FlutterDerivativeTable.from_model(truth, np.geomspace(0.021, 1.26, 151))
    fit = fit_table(table)
    assert fit.meets_accuracy, fit.summary()
    true_speed = flutter.analyze(FLAT_PLATE, truth).speed
    c = section_flutter(FLAT_PLATE, table=table, fit=fit).comparison
    assert c.speed == pytest.approx(true_speed, rel=ROUTE_TOLERANCE)
    assert abs(c.difference) < ROUTE_TOLERANCE


def test_a_model_states_its_divergence_as_an_extrapolation():
    c = section_flutter(FLAT_PLATE, model=plate_model([0.165, 0.335], [0.0455, 0.3])).comparison
    assert c.source == "model" and c.basis == "state-space"
    assert "extrapolated" in c.divergence_basis


def test_table_divergence_is_the_closed_form_for_pitch_alone():
    """Pitch only (A3* alone): U_D = sqrt(2 k_alpha / (rho B^2 K^2 A3*)) at the lowest K."""
    section = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)
    values = {name: np.zeros(4) for name in EXAMPLE.values}
    values["A3"] = np.array([8.0, 4.0, 2.0, 1.0])
    table = FlutterDerivativeTable(K=np.array([0.3, 0.6, 1.2, 2.4]), values=values)
    k_alpha = section.I * (2 * math.pi * section.fa) ** 2
    expected = math.sqrt(2 * k_alpha / (section.rho * section.B**2 * 0.3**2 * 8.0))
    assert table_divergence_speed(section, table) == pytest.approx(expected, rel=1e-12)


def test_disagreeing_routes_of_a_model_rest_on_the_state_space():
    """Routes 2 % apart for a model: the warning names both, the state space stands."""
    ss = flutter.analyze(FLAT_PLATE, plate_model([0.165, 0.335], [0.0455, 0.3]))
    fd = flutter.frequency_domain(FLAT_PLATE, lambda K: plate_model(
        [0.165, 0.335], [0.0455, 0.3]).flutter_derivatives(K))
    assert ss.speed is not None and fd.speed is not None
    moved = type(fd)(**{**fd.__dict__, "speed": 1.02 * ss.speed})
    c = compare_routes(ss, moved, source="model")
    assert c.basis == "state-space" and c.speed == ss.speed
    assert c.difference == pytest.approx(0.02)
    assert any("disagree by +2.00 %" in w for w in c.warnings)
    with pytest.raises(ValueError, match="source must be"):
        compare_routes(ss, fd, source="csv")


def test_a_table_unstable_at_its_lowest_reduced_velocity_says_so():
    """A2* + 0.6 at every row: the pitch branch grows already at the table's highest K.

    The frequency domain used to skip such a branch (no crossing seen); now its speed at the
    table's edge is the result, as an upper bound, and the warning says the table shows it.
    """
    c = section_flutter(FLAT_PLATE, table=_variant(A2=EXAMPLE.values["A2"] + 0.6)).comparison
    assert c.basis == "frequency-domain" and "an upper bound" in c.basis_reason
    assert c.reduced_frequency == pytest.approx(EXAMPLE.K[-1])
    assert any("already unstable at the highest K" in w and "the table itself says so" in w
               for w in c.warnings)


def test_a_wide_3dof_table_of_a_bluff_deck_agrees_within_half_a_percent():
    """The simulators' 3-DOF bluff deck tabulated at 151 K from 0.021 to 1.26 (18 derivatives).

    The issue's published 3-DOF table had this shape; the deck's own lags are not Roger's shared
    ones, so the fit is an approximation: it must reach 2 %, the routes must agree within 0.5 %,
    and the result must lie within 0.5 % of the deck's own flutter speed (the independent
    result: its exact model's eigenvalues).
    """
    from simulators.decks import bluff_deck_3dof_model

    section = SectionModel(**{**FLAT_PLATE.to_dict(), "fp": 1.5, "zeta_p": 0.005,
                              "m_p": FLAT_PLATE.m})
    truth = bluff_deck_3dof_model()
    table = FlutterDerivativeTable.from_model(truth, np.geomspace(0.021, 1.26, 151))
    routes = section_flutter(section, table=table)
    c = routes.comparison
    assert routes.fit is not None and routes.fit.meets_accuracy, routes.fit.summary()
    assert abs(c.difference) < ROUTE_TOLERANCE
    assert c.speed == pytest.approx(flutter.analyze(section, truth).speed, rel=ROUTE_TOLERANCE)


def test_a_table_with_its_h_and_a_columns_swapped_is_named_not_a_bare_root_count(tmp_path):
    """The flat plate's table with the lift's and the moment's columns swapped.

    The frequency domain loses a root where the swapped "A3*" (the lift's -132 at K = 0.2)
    overcomes the pitch spring; it stopped the command with "expected 2 oscillatory roots at
    K = 0.4825, found 1", naming neither the file nor a cause.
    """
    K = np.geomspace(0.2, 3.0, 40)
    plate = FlutterDerivativeTable(K, flat_plate.flutter_derivatives(K))
    swapped = {("A" if n[0] == "H" else "H") + n[1]: v for n, v in plate.values.items()}
    path = tmp_path / "swapped.csv"
    FlutterDerivativeTable(K, swapped).to_csv(path)
    table = FlutterDerivativeTable.from_csv(path)
    with pytest.raises(ValueError, match=r"swapped\.csv: the frequency-domain route .* cannot "
                                         r"follow the modes: expected 2 oscillatory roots") as err:
        section_flutter(FLAT_PLATE, table=table)
    assert "H and A swapped?" in str(err.value)
