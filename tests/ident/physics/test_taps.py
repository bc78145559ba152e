"""Tap geometry: pressures integrate to lift and moment with Scanlan's signs, and back."""

from __future__ import annotations

import numpy as np
import pytest

from ident import TapLayout

PLATE = TapLayout.rectangle(B=0.3, D=0.01, taps_per_face=32)


def test_signs_follow_scanlan():
    """Suction on the upper face lifts the deck (L < 0); on the front half it pitches nose-up."""
    p = np.zeros((2, PLATE.n_taps))
    upper = PLATE.nz < 0
    p[0, upper] = -100.0  # Pa, suction on the whole upper face
    p[1, upper & (PLATE.x < 0)] = -100.0  # suction on the upper front half only
    lift, moment = PLATE.integrate(p)
    assert lift[0] == pytest.approx(-100.0 * 0.3, rel=1e-12)  # p * chord, upward
    assert moment[0] == pytest.approx(0.0, abs=1e-12)  # symmetric about the axis
    assert lift[1] == pytest.approx(-100.0 * 0.15, rel=1e-12)
    # Upward force 15 N/m centred 75 mm upstream of the axis: 1.125 N m/m nose-up.
    assert moment[1] == pytest.approx(15.0 * 0.075, rel=1e-12)


def test_uniform_pressure_on_a_closed_outline_gives_no_force():
    """A uniform pressure on a closed outline integrates to zero force and moment."""
    lift, moment = PLATE.integrate(np.full((1, PLATE.n_taps), 250.0))
    assert abs(lift[0]) < 1e-10 and abs(moment[0]) < 1e-10


def test_pressures_for_integrate_back_exactly_with_any_mean_field():
    """Generated tap pressures reproduce the forces to round-off, whatever steady field is added."""
    rng = np.random.default_rng(4)
    lift, moment = rng.normal(size=50), rng.normal(size=50)
    mean = rng.normal(scale=300.0, size=PLATE.n_taps)
    p = PLATE.pressures_for(lift, moment, mean=mean)
    back_lift, back_moment = PLATE.integrate(p)
    np.testing.assert_allclose(back_lift, lift, atol=1e-10)
    np.testing.assert_allclose(back_moment, moment, atol=1e-10)
    # The steady field is kept apart from its own lift and moment: not silently dropped.
    assert np.abs(p - PLATE.pressures_for(lift, moment)).max() > 100.0


def test_a_missing_tap_marks_that_sample_only():
    """A NaN at one tap makes only that sample's forces NaN (a marked gap, not a wrong number)."""
    p = PLATE.pressures_for(np.ones(3), np.zeros(3))
    p[1, 5] = np.nan
    lift, moment = PLATE.integrate(p)
    assert np.isnan(lift[1]) and np.isnan(moment[1])
    assert np.all(np.isfinite(lift[[0, 2]]))


def test_from_table_reads_both_forms_and_names_bad_keys():
    """Config tables: generated rectangle or explicit arrays; unknown/missing keys are named."""
    generated = TapLayout.from_table({"shape": "rectangle", "B": 0.3, "D": 0.01,
                                      "taps_per_face": 32})
    np.testing.assert_array_equal(generated.x, PLATE.x)
    explicit = TapLayout.from_table({"x": [0.0, 0.1], "z": [-0.01, 0.01], "nx": [0, 0],
                                     "nz": [-1, 1], "length": [0.1, 0.1]})
    assert explicit.n_taps == 2
    with pytest.raises(ValueError, match=r"missing keys \['length'\], unknown keys \['len'\]"):
        TapLayout.from_table({"x": [0.0, 0.1], "z": [0, 0], "nx": [0, 0], "nz": [-1, 1],
                              "len": [0.1, 0.1]})
    with pytest.raises(ValueError, match="shape must be one of"):
        TapLayout.from_table({"shape": "circle"})
    deck = TapLayout.from_table({"shape": "streamlined_deck", "B": 0.45, "D": 0.05,
                                 "n_taps": 64})
    assert deck.n_taps == 64


@pytest.mark.parametrize("layout", [
    TapLayout.streamlined_deck(0.45, 0.05, 64),
    TapLayout.polygon([(-0.1, 0.0), (0.0, -0.03), (0.1, 0.0), (0.0, 0.03)], 13),
    TapLayout.polygon([(-0.1, 0.0), (0.0, 0.03), (0.1, 0.0), (0.0, -0.03)], 13),  # clockwise
], ids=["deck", "diamond-ccw", "diamond-cw"])
def test_generated_outlines_are_closed_with_outward_normals(layout):
    """Uniform pressure gives no force or moment; normals point away from the centroid."""
    lift, moment = layout.integrate(np.full((1, layout.n_taps), 500.0))
    assert abs(lift[0]) < 1e-10 and abs(moment[0]) < 1e-10
    centroid = np.array([np.average(layout.x, weights=layout.length),
                         np.average(layout.z, weights=layout.length)])
    outward = (layout.x - centroid[0]) * layout.nx + (layout.z - centroid[1]) * layout.nz
    assert np.all(outward > 0)
    assert layout.length.sum() > 0


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"nx": [0.5, 0.0]}, "unit vectors; tap 0"),
        ({"length": [0.1, 0.0]}, "length must be > 0"),
        ({"x": [0.0, np.nan]}, "x contains 1 non-finite"),
        ({"z": [0.0, 0.0, 0.0]}, "equal lengths"),
    ],
)
def test_bad_geometry_is_refused(change, match):
    """Non-unit normals, zero lengths, NaNs and ragged arrays raise ValueError naming the field."""
    good = {"x": [0.0, 0.1], "z": [-0.01, 0.01], "nx": [0.0, 0.0], "nz": [-1.0, 1.0],
            "length": [0.1, 0.1]}
    with pytest.raises(ValueError, match=match):
        TapLayout(**(good | change))


def test_wrong_pressure_shape_is_refused():
    """Pressures must be (n_samples, n_taps)."""
    with pytest.raises(ValueError, match=rf"shape \(n_samples, {PLATE.n_taps}\)"):
        PLATE.integrate(np.zeros((3, 10)))


def test_drag_from_the_faces_across_the_wind():
    """Stagnation pressure on the front face pushes downwind: D = p D_face; back again exactly."""
    box = TapLayout.rectangle(B=0.3, D=0.05, taps_per_face=16)
    assert box.carries_drag
    p = np.zeros((1, box.n_taps))
    p[0, box.nx < -0.5] = 100.0  # Pa on the upstream face (outward normal upstream)
    assert box.integrate_drag(p)[0] == pytest.approx(100.0 * 0.05, rel=1e-12)
    assert box.integration_matrix(drag=True).shape == (3, box.n_taps)
    rng = np.random.default_rng(9)
    lift, moment, drag = rng.normal(size=(3, 50))
    back = box.pressures_for(lift, moment, drag=drag)
    np.testing.assert_allclose(box.integrate(back)[0], lift, atol=1e-9)
    np.testing.assert_allclose(box.integrate(back)[1], moment, atol=1e-9)
    np.testing.assert_allclose(box.integrate_drag(back), drag, atol=1e-9)


def test_a_plate_of_upper_and_lower_taps_carries_no_drag():
    x = np.tile(np.linspace(-0.14, 0.14, 8), 2)
    nz = np.repeat([-1.0, 1.0], 8)
    flat = TapLayout(x=x, z=0.0 * x, nx=0.0 * x, nz=nz, length=np.full(16, 0.0375))
    assert not flat.carries_drag
    with pytest.raises(ValueError, match="cannot carry a drag"):
        flat.pressures_for([1.0], [0.0], drag=[0.5])
