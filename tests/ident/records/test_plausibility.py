"""Guards against unit and sign mistakes: the issue's table of conversion mistakes, each caught.

The data: the flat plate of the tests (Jones's aerodynamics, flutter at 11.75 m/s) released from
4 mm and 0.02 rad at 0.4, 0.6 and 0.8 of its flutter speed, 20 s at 500 Hz, simulated by
``ident.simulation.simulate_decay``, with 0.5 s held still before each release (the first
sample's values), and 2 % white noise (seeded) on every channel. Converted rightly, the
releases identify with no warning; each mistake of the issue's table is made on the same
samples, identified by ``e2rfc.identify`` (as a lab's 20-line script would), and must be
caught by a message that names it.
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

from ident.errors import PlausibilityError
from ident.identification import e2rfc
from ident.model import flat_plate, flutter
from ident.model.quasi_steady import StaticCoefficients
from ident.physics.turbulence import TurbulenceSpec
from ident.records import plausibility
from ident.records.release import Release, ReleaseHold
from ident.simulation.decay import simulate_decay
from simulators.tunnel import simulate_release

from support.sections import FLAT_PLATE

JONES = flat_plate.jones_model()
U_F = flutter.analyze(FLAT_PLATE, JONES).speed
FS = 500.0
NOISE = 0.02
SPAN = 0.9


@pytest.fixture(scope="module")
def records():
    """Simulate the three releases with their holds: (t, channels, U), noise seeded."""
    out = []
    for i, fraction in enumerate((0.4, 0.6, 0.8)):
        U = fraction * U_F
        sim = simulate_decay(FLAT_PLATE, JONES, U, 0.004, 0.02, n=int(20 * FS), fs=FS)
        rng = np.random.default_rng(101 + i)
        held = int(0.5 * FS)
        t = np.concatenate([(np.arange(held) - held) / FS, sim.t])
        channels = {}
        for name in ("h", "alpha", "lift", "moment"):
            x = getattr(sim, name)
            x = np.concatenate([np.full(held, x[0]), x])
            channels[name] = x + NOISE * np.std(x[held:]) * rng.standard_normal(x.size)
        out.append((t, channels, U))
    return out


def _releases(records, convert=lambda c: c, *, late=0.0, hold=True):
    """Releases from the records, converted by ``convert``, with the instant ``late`` s late."""
    out = []
    for t, channels, U in records:
        converted = convert(dict(channels))
        shifted = t - late
        after = shifted >= 0.0
        before = ~after if hold else np.zeros_like(after)
        held = (ReleaseHold(t=shifted[before], **{k: v[before] for k, v in converted.items()})
                if np.count_nonzero(before) >= 2 else None)
        out.append(Release(t=shifted[after], **{k: v[after] for k, v in converted.items()},
                           U=U, hold=held))
    return out


def test_rightly_converted_releases_raise_no_warning(records):
    """No false alarm: the guards say nothing and the flutter speed is the truth's."""
    model = e2rfc.identify(_releases(records), FLAT_PLATE)
    assert model.diagnostics.warnings == ()
    # 2 % noise on three releases: the E2RFC tests' accuracy (within 1.5 %).
    assert model.flutter(FLAT_PLATE)[0].speed == pytest.approx(U_F, rel=0.015)


def test_pitch_left_in_degrees_is_refused_naming_it(records):
    """Unguarded: 27.1 m/s for 11.75. A pitch of 0.8 'rad' about its mean is no model's."""
    releases = _releases(records, lambda c: {**c, "alpha": np.degrees(c["alpha"])})
    with pytest.raises(PlausibilityError, match="alpha looks like degrees"):
        e2rfc.identify(releases, FLAT_PLATE)


def test_total_forces_over_the_span_are_warned_of_with_their_factor(records):
    """Unguarded: 12.36 m/s (+5 %) and no word. The decays say the forces are 0.9 times."""
    releases = _releases(records, lambda c: {**c, "lift": SPAN * c["lift"],
                                             "moment": SPAN * c["moment"]})
    model = e2rfc.identify(releases, FLAT_PLATE)
    found = [w for w in model.diagnostics.warnings if "per unit span" in w]
    assert len(found) == 1, model.diagnostics.warnings
    factor = float(re.search(r"the forces are ([0-9.]+) times", found[0]).group(1))
    # The factor is fitted from the modes' eigenvalue shifts (2 % noise): within 2 % of 0.9.
    assert factor == pytest.approx(SPAN, rel=0.02)


def test_lift_of_the_wrong_sign_is_refused_naming_it(records):
    """Unguarded: flutter at 0.65 m/s. H1* > 0 and a growing heave the decays deny."""
    releases = _releases(records, lambda c: {**c, "lift": -c["lift"]})
    with pytest.raises(PlausibilityError, match="lift's sign looks flipped"):
        e2rfc.identify(releases, FLAT_PLATE)


@pytest.mark.parametrize("hold", [True, False], ids=["with-hold", "without-hold"])
def test_release_instant_30_ms_late_is_warned_of_with_its_offset(records, hold):
    """Unguarded: 11.85 m/s and residuals not white. Every release's offset is named."""
    model = e2rfc.identify(_releases(records, late=0.030, hold=hold), FLAT_PLATE)
    found = [w for w in model.diagnostics.warnings if "release instant looks" in w]
    assert len(found) == 3, model.diagnostics.warnings
    # With a still hold before it, release_onset finds the instant in the displacements;
    # without, the modal fit's velocity extrapolated back.
    how = "leave the hold" if hold else "velocity vanishes"
    for warning in found:
        assert "ms late" in warning and how in warning
        offset = float(re.search(r"starts at t = ([-+0-9.]+) ms", warning).group(1))
        # The velocity's zero is found within 0.5 ms on 2 % noise (module docstring); 2 ms
        # leaves room for the onset detector's 1.5 ms worst case.
        assert offset == pytest.approx(-30.0, abs=2.0)


def test_moment_of_the_wrong_sign_is_warned_of_naming_it(records):
    """Unguarded: flutter at 2.1 m/s. The model's pitch mode grows where the measured decays."""
    model = e2rfc.identify(_releases(records, lambda c: {**c, "moment": -c["moment"]}),
                           FLAT_PLATE)
    found = [w for w in model.diagnostics.warnings if "does not predict the measured" in w]
    assert len(found) == 1 and "a moment of the wrong sign" in found[0]
    # The worst mode is a pitch mode (3.4-3.9 Hz) predicted to grow (negative damping).
    worst = re.search(r"the ([0-9.]+) Hz mode: damping ratio (-[0-9.]+) % predicted", found[0])
    assert worst is not None and 3.0 < float(worst.group(1)) < 4.0


def test_heave_in_millimetres_is_refused_naming_it(records):
    """A heave of 4 'm' on a 0.3 m deck: millimetres read as metres."""
    releases = _releases(records, lambda c: {**c, "h": 1e3 * c["h"]})
    with pytest.raises(PlausibilityError, match="h looks like millimetres"):
        e2rfc.identify(releases, FLAT_PLATE)


@pytest.mark.parametrize(("channel", "value"), [("moment", 0.0), ("lift", 0.0), ("alpha", 0.01)],
                         ids=["moment-zeros", "lift-zeros", "alpha-stuck"])
def test_a_dead_channel_is_refused_naming_it(records, channel, value):
    """A channel of one value is refused by name.

    Unguarded: zeros in a force broke the least squares with a LinAlgError; a stuck pitch
    identified a model whose warnings named everything but the channel.
    """
    releases = _releases(records)
    releases[1] = dataclasses.replace(
        releases[1], **{channel: np.full_like(getattr(releases[1], channel), value)})
    with pytest.raises(PlausibilityError, match=f"the {channel} channel reads {value:g} "):
        e2rfc.identify(releases, FLAT_PLATE)


def test_a_time_axis_in_milliseconds_is_refused_naming_it(records):
    """Unguarded: "no flutter", with warnings of release instants 8-57 ms off."""
    releases = [dataclasses.replace(r, t=1e3 * r.t) for r in _releases(records, hold=False)]
    with pytest.raises(PlausibilityError, match="t looks like milliseconds"):
        e2rfc.identify(releases, FLAT_PLATE)


def test_a_release_in_large_scale_turbulence_is_not_refused():
    """Gusts of 3 m on the 0.3 m plate at Iw 10 %: no false alarm on a low spectral peak.

    Both displacements' spectra peak at 0.1 Hz, below the modes, and a third of the heave's
    power lies in their band: a check of where the spectra peak refused it (tried, not kept).
    """
    gusts = TurbulenceSpec(Iu=0.0, Iw=0.10, Lux=1.0, Lwx=3.0, Cuy=10.0, Cwy=8.0)
    sim = simulate_release(FLAT_PLATE, JONES, 0.8 * U_F, 0.004, 0.02, duration=20.0, fs=FS,
                           noise=NOISE, rng=(1, 0, 0), static=StaticCoefficients.flat_plate(),
                           turbulence=gusts, span=1.0)
    assert plausibility.check_release(Release.from_simulation(sim), FLAT_PLATE) == []


@pytest.fixture(scope="module")
def small_holds():
    """Releases from 0.2 mm and 0.004 rad (0.23 degrees): within any amplitude check."""
    out = []
    for i, fraction in enumerate((0.4, 0.6, 0.8)):
        sim = simulate_decay(FLAT_PLATE, JONES, fraction * U_F, 0.0002, 0.004, n=int(20 * FS),
                             fs=FS)
        rng = np.random.default_rng(201 + i)
        channels = {name: getattr(sim, name) for name in ("h", "alpha", "lift", "moment")}
        channels = {name: x + NOISE * np.std(x) * rng.standard_normal(x.size)
                    for name, x in channels.items()}
        out.append(Release(t=sim.t, **channels, U=fraction * U_F))
    return out


@pytest.mark.parametrize(("channel", "factor", "unit", "twin"),
                         [("alpha", 180 / math.pi, "degrees", "I = 0.03 kg m^2/m may be 57.3"),
                          ("h", 100.0, "centimetres", "m = 3 kg/m may be 100")])
def test_small_displacements_in_a_wrong_unit_are_warned_of_naming_it(small_holds, channel,
                                                                     factor, unit, twin):
    """A small pitch in degrees, or heave in centimetres, is named by the decays it explains.

    Unguarded (pitch in degrees): +131 % with a std of 0.5 %, "a force channel's sign or unit"
    the only hint. The model with that column rescaled predicts the decays again; so would
    the right one with the section's inertia (mass) that factor too large, which the warning
    names as the other reading.
    """
    right = e2rfc.identify(small_holds, FLAT_PLATE)
    assert right.diagnostics.warnings == ()  # no false alarm at these holds
    wrong = [dataclasses.replace(r, **{channel: factor * getattr(r, channel)})
             for r in small_holds]
    model = e2rfc.identify(wrong, FLAT_PLATE)
    found = [w for w in model.diagnostics.warnings if f"{channel} looks like {unit}" in w]
    assert len(found) == 1, model.diagnostics.warnings
    assert f"if {channel} is right, the section's {twin} times too large" in found[0]


@pytest.mark.parametrize(("rho", "unit"), [(1225.0, "g/m^3"), (0.001225, "g/cm^3")])
def test_an_air_density_in_a_wrong_unit_is_warned_of_once(records, rho, unit):
    """The section's density in g/m^3: the same flutter speed, flutter derivatives 1000 off."""
    model = e2rfc.identify(_releases(records), dataclasses.replace(FLAT_PLATE, rho=rho))
    found = [w for w in model.diagnostics.warnings if "no wind tunnel's air" in w]
    assert len(found) == 1 and unit in found[0], model.diagnostics.warnings
    assert found[0].startswith(f"the section's air density is {rho:g} kg/m^3")
    # Within the checks' own tolerance (2 % noise, the E2RFC tests' 1.5 %): it cancels.
    assert model.flutter(dataclasses.replace(FLAT_PLATE, rho=rho))[0].speed == pytest.approx(
        U_F, rel=0.015)


def test_a_channel_that_barely_moves_is_not_called_dead(records):
    """Only one value throughout is refused: a force a millionth of its size still has noise."""
    release = _releases(records, lambda c: {**c, "moment": 1e-6 * c["moment"]})[1]
    plausibility.check_channels(release)  # no error


def test_forces_far_beyond_what_the_wind_can_give_are_warned_of(records):
    """Forces 100 times too large (a unit unconverted) break the flat plate's bound x10."""
    release = _releases(records, lambda c: {**c, "lift": 100 * c["lift"]})[1]
    warnings = plausibility.check_release(release, FLAT_PLATE)
    assert len(warnings) == 1 and "the lift is" in warnings[0]
    assert "per unit span" in warnings[0]
    assert plausibility.check_release(_releases(records)[1], FLAT_PLATE) == []


def test_start_offset_finds_the_zero_of_an_exact_velocity():
    """Two modes released from rest at t0: their velocities vanish together only there."""
    t0 = -0.0123
    omega = 2 * math.pi * np.array([2.0, 4.0])

    def velocity(t):
        tau = np.asarray(t)[:, None] - t0
        return -omega * np.sin(omega * tau) * np.array([0.01, 0.02])

    found, rest = plausibility.start_offset(velocity, 0.01 * omega * [1.0, 2.0], 0.25, 0.002)
    # A bounded scalar search to 1e-6 s on an exact function.
    assert found == pytest.approx(t0, abs=1e-5) and rest < 1e-3


def test_wind_speeds_in_km_h_are_warned_of_where_no_flutter_is_found(records):
    """Unguarded: "no flutter", no word.

    The forces scale with the speed, so the data agree with themselves; but the releases then
    sit at 0.9 of the flutter search's ceiling.
    """
    releases = [dataclasses.replace(r, U=3.6 * r.U) for r in _releases(records)]
    result, uncertainty = e2rfc.identify(releases, FLAT_PLATE).analysis(FLAT_PLATE)
    assert result.speed is None
    found = [w for w in uncertainty.warnings if "km/h" in w]
    assert len(found) == 1 and "0.90 of that ceiling" in found[0], uncertainty.warnings
    right = e2rfc.identify(_releases(records), FLAT_PLATE).uncertainty(FLAT_PLATE)
    assert not [w for w in right.warnings if "km/h" in w]
