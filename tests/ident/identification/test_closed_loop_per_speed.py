"""Many releases per wind speed: the closed-loop fit takes a buffeting filter per speed.

One filter shape shared by the speeds misfits the gusts' spectrum a little differently near
each speed's modes, a lean that more releases do not shrink; with six releases or more at every
speed (``PER_SPEED_FROM``) the evidence weighs filters per speed instead. The case is the
benchmark's plate at Iw 1 % with six releases per speed and their holds
(``benchmarks/ident_accuracy.py``'s tunnel row with ``per_speed`` 6, seed 0).
"""

from __future__ import annotations

import re

import pytest

from ident import Release
from ident.identification import e2rfc
from ident.identification._e2rfc_turbulence import PER_SPEED_FROM, _filters_by_count
from ident.model import flat_plate
from ident.model import flutter as fl
from ident.model.quasi_steady import StaticCoefficients
from ident.physics.turbulence import TurbulenceSpec
from simulators import simulate_release

from support.sections import FLAT_PLATE

HOLDS = ((0.004, 0.02), (-0.003, 0.012))


def releases_per_speed(n, seed):
    """Return the plate's releases at Iw 1 %, ``n`` per speed at 0.4/0.6/0.8 U_F, with holds."""
    model = flat_plate.jones_model()
    U_F = fl.analyze(FLAT_PLATE, model).speed
    wind = {"static": StaticCoefficients.flat_plate(), "span": 1.0, "pre_s": 10.0,
            "turbulence": TurbulenceSpec(Iu=0.0, Iw=0.01, Lux=1.0, Lwx=0.3, Cuy=10.0, Cwy=8.0)}
    return [Release.from_simulation(simulate_release(
        FLAT_PLATE, model, f * U_F, *HOLDS[j % 2], duration=20.0, fs=500.0, noise=0.02,
        rng=(seed, i, j, 10), **wind))
        for i, f in enumerate((0.4, 0.6, 0.8)) for j in range(n)], U_F


@pytest.mark.slow
def test_six_releases_per_speed_take_a_buffeting_filter_per_speed():
    """The note names the per-speed model and why; the estimate is within the row's spread.

    Over the row's twenty seeds (filters per speed): median |error| 0.85 %, largest 3.9 %,
    19 of 20 intervals covering; with the shared filter 1.22 % and a mean of -0.7 %. Seed 0
    gives -1.6 % with a std of 3.3 %: the bound of 4 % is the twenty seeds' largest error,
    and the interval must cover.
    """
    assert PER_SPEED_FROM == 6  # the case below is the crossover's first row
    releases, U_F = releases_per_speed(6, seed=0)
    model = e2rfc.identify(releases, FLAT_PLATE)
    (note,) = [w for w in model.diagnostics.warnings if "chosen by evidence" in w]
    assert "fourth-order-per-speed buffeting model" in note
    assert "a filter per wind speed, with 6 or more releases at each" in note
    u = model.uncertainty(FLAT_PLATE)
    assert u.speed is not None
    assert abs(u.speed / U_F - 1.0) < 0.04
    low, high = u.interval()
    assert low <= U_F <= high


@pytest.mark.parametrize(("counts", "per_speed", "words"), [
    ([6, 7, 6], True, r"a filter per wind speed, with 6 or more releases at each"),
    ([8, 2, 8], False, r"a filter per speed needs 6 releases at every speed, and 6 m/s has 2"),
    ([2, 2, 2], False, r"^$"),
])
def test_the_note_says_why_the_filter_is_shared_or_per_speed(counts, per_speed, words):
    # Many releases at some speeds and few at another keep the shared filter: the note names
    # the speed that keeps it, so the user knows which releases would buy a filter per speed.
    chosen, note = _filters_by_count(counts, [4.0, 6.0, 8.0])
    assert chosen is per_speed
    assert re.search(words, note), note
