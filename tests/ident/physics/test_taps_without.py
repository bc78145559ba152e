"""Dead taps left out of a layout: TapLayout.without keeps the outline covered."""

from __future__ import annotations

import numpy as np
import pytest

from ident.physics.taps import TapLayout

RECT = TapLayout.rectangle(0.3, 0.01, 28)  # taps 0-27 upper face, 28-55 lower, 56-61 the ends


def test_lengths_add_up_and_go_to_the_neighbours_on_the_same_face():
    out = RECT.without([10, 45])
    assert out.n_taps == 60
    assert out.length.sum() == pytest.approx(RECT.length.sum(), rel=1e-12)
    ds = RECT.length[0]
    # tap 10's neighbours 9 and 11 (now 9 and 10) get half each; the other taps are unchanged.
    assert out.length[9] == pytest.approx(1.5 * ds) and out.length[10] == pytest.approx(1.5 * ds)
    assert out.length[0] == pytest.approx(ds)
    # a tap at the end of a face hands all its length to the one neighbour on that face
    end = RECT.without([0])
    assert end.length[0] == pytest.approx(2 * ds)


def test_linear_pressures_integrate_as_with_every_tap():
    """Linear pressures: the live taps integrate as all of them.

    Pressures linear along each face (the simulated tunnel's field is of this kind): the
    live taps give the full set's lift exactly and its moment to second order in the tap
    spacing (here 0.055 %; tolerance 0.1 %).
    """
    p = RECT.pressures_for([0.8, -0.5], [0.01, 0.02], mean=np.where(RECT.nz < 0, -13.0, -4.0))
    full_l, full_m = RECT.integrate(p)
    live = np.setdiff1d(np.arange(RECT.n_taps), [10, 45])
    lift, moment = RECT.without([10, 45]).integrate(p[:, live])
    assert lift == pytest.approx(full_l, rel=1e-9)
    assert moment == pytest.approx(full_m, rel=1e-3)


def test_a_uniform_pressure_still_integrates_to_zero():
    """The closed outline stays closed: a uniform pressure gives no force and no moment."""
    lift, moment = RECT.without([3, 30, 57]).integrate(np.full((1, 59), 100.0))
    assert abs(lift[0]) < 1e-12 and abs(moment[0]) < 1e-12


def test_a_curved_outline_uses_the_neighbours_in_order():
    """A curved outline: the neighbours in the layout's order.

    Explicit taps on a circle (each its own normal): a dead tap's length goes to the taps
    before and after it in the layout's order.
    """
    theta = np.linspace(0.0, 2 * np.pi, 24, endpoint=False)
    circle = TapLayout(x=0.1 * np.cos(theta), z=0.1 * np.sin(theta), nx=np.cos(theta),
                       nz=np.sin(theta), length=np.full(24, 2 * np.pi * 0.1 / 24))
    out = circle.without([0])
    assert out.length[0] == pytest.approx(1.5 * circle.length[0])
    assert out.length[-1] == pytest.approx(1.5 * circle.length[0])


@pytest.mark.parametrize(("dead", "match"), [
    ([62], r"indices in \[0, 61\]"),
    ([56, 57, 58], "dead tap 56 has no live tap on its face"),
    (list(range(61)), "fewer than 2 live taps"),
])
def test_impossible_dead_sets_are_refused(dead, match):
    with pytest.raises(ValueError, match=match):
        RECT.without(dead)
