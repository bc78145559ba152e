"""Each named effect changes a simulated release the way its physics says it should.

Structural effects are checked on a still-air release (no aerodynamic force) against the classical
single-degree-of-freedom results, so that the expectation is independent of the simulator's code.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import eigh, expm
from scipy.signal import find_peaks

from ident import AeroelasticSystem, RationalFunctionModel, SectionModel
from ident.model import flat_plate, flutter
from simulators import EFFECT_NAMES, simulate_release
from simulators.effects import (
    AerodynamicNonlinearity,
    BaseVibration,
    ChannelDelay,
    CoulombFriction,
    CubicStiffness,
    QuadraticDamping,
    SensorCrosstalk,
    StaticUnbalance,
    TubingDistortion,
    VortexShedding,
)

UNDAMPED = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.0, zeta_a=0.0)
SECTION = UNDAMPED.replace(zeta_h=0.005, zeta_a=0.005)
STILL_AIR = RationalFunctionModel(np.zeros((3, 2, 2)), [])
K_H = UNDAMPED.m * UNDAMPED.omega_h**2  # heave spring, N/m per m span


def heave_peaks(effect, *, section=UNDAMPED, h0=0.005, duration=8.0, fs=2000.0):
    rel = simulate_release(section, STILL_AIR, 0.0, h0, 0.0, duration=duration, fs=fs,
                           effects=[effect])
    peaks, _ = find_peaks(rel.h)
    return rel, peaks


def test_the_design_names_are_all_there():
    """The effect registry holds exactly the names of docs/reference/conventions.md."""
    assert set(EFFECT_NAMES) == {
        "coulomb_friction", "quadratic_damping", "cubic_stiffness", "channel_delay",
        "vortex_shedding", "static_unbalance", "sensor_crosstalk", "base_vibration",
        "aerodynamic_nonlinearity", "tubing_distortion",
    }


def test_coulomb_friction_gives_a_linear_envelope():
    """Dry friction removes 4 F / k of amplitude per cycle: a straight-line envelope."""
    friction = 0.05  # N/m
    rel, peaks = heave_peaks(CoulombFriction(force_h=friction))
    amplitudes = rel.h[peaks]
    amplitudes = amplitudes[amplitudes > 5 * 4 * friction / K_H]  # before sticking sets in
    cycles = np.arange(amplitudes.size)
    slope, intercept = np.polyfit(cycles, amplitudes, 1)
    # Smoothing the sign over 1e-4 m/s (0.2 % of the peak velocity) takes < 3 % off the loss.
    assert -slope == pytest.approx(4 * friction / K_H, rel=0.03)
    linear_misfit = np.abs(amplitudes - (intercept + slope * cycles)).max()
    log_fit = np.polyval(np.polyfit(cycles, np.log(amplitudes), 1), cycles)
    exponential_misfit = np.abs(amplitudes - np.exp(log_fit)).max()
    assert linear_misfit < 0.2 * exponential_misfit  # clearly linear, not exponential


def test_quadratic_damping_loses_amplitude_in_proportion_to_its_square():
    """Velocity-squared damping: dA per cycle = (8/3) (c2/m) A^2, i.e. damping grows with A."""
    c2 = 20.0  # N s^2/m^3
    rel, peaks = heave_peaks(QuadraticDamping(c2_h=c2), h0=0.01)
    amplitudes = rel.h[peaks]
    loss = -np.diff(amplitudes)
    mean_amplitude = 0.5 * (amplitudes[:-1] + amplitudes[1:])
    expected = (8 / 3) * (c2 / UNDAMPED.m) * mean_amplitude**2
    # The first-order energy balance is accurate to O(loss/A) ~ 5 % for these amplitudes.
    np.testing.assert_allclose(loss, expected, rtol=0.06)
    # Relative loss per cycle falls with amplitude (here A falls ~3x): not exponential decay.
    assert loss[0] / amplitudes[0] > 2 * loss[-1] / amplitudes[-1]


def test_cubic_stiffness_makes_the_frequency_depend_on_amplitude():
    """Hardening spring: f(A) = f0 (1 + 3/8 (k3/k) A^2) (Duffing backbone), falling as A decays."""
    k3 = 2.5e6  # N/m^4: a 5 % frequency rise at 5 mm
    section = UNDAMPED.replace(zeta_h=0.02)
    rel, peaks = heave_peaks(CubicStiffness(k3_h=k3), section=section, duration=20.0)
    periods = np.diff(rel.t[peaks])
    amplitude = rel.h[peaks[:-1]] * np.exp(-0.5 * 0.02 * 2 * np.pi)  # mid-cycle amplitude
    f_linear = section.fh * np.sqrt(1 - 0.02**2)
    shift = 1 / periods / f_linear - 1
    expected = 3 / 8 * k3 / K_H * amplitude**2
    assert shift[0] > 0.03 and shift[-1] < 0.005  # visibly amplitude dependent
    # Lindstedt's first-order backbone errs by O(shift^2) and the damped-amplitude estimate by
    # ~1 %: within 0.003 absolute (10 % of the largest shift).
    np.testing.assert_allclose(shift, expected, atol=3e-3)


def test_channel_delay_shifts_the_forces_only():
    """Delayed forces equal the exact forces at t - tau; displacements are untouched."""
    model, U, tau = flat_plate.jones_model(), 7.0, 0.0033
    args = (SECTION, model, U, 0.004, 0.015)
    plain = simulate_release(*args, duration=4.0, fs=500.0)
    delayed = simulate_release(*args, duration=4.0, fs=500.0, effects=[ChannelDelay(tau)])
    np.testing.assert_array_equal(delayed.h, plain.h)
    system = AeroelasticSystem(SECTION, model, U)
    z0 = system.initial_state(0.004, 0.015)
    for k in (10, 333, 1999):
        exact = system.force_matrix() @ expm(system.matrix() * (delayed.t[k] - tau)) @ z0
        # Cubic-spline interpolation at 500 Hz of a ~3 Hz signal: error ~ (w dt)^4 / 384 ~ 1e-8.
        assert delayed.lift[k] == pytest.approx(exact[0] / SECTION.B, rel=1e-5, abs=1e-9)
        assert delayed.moment[k] == pytest.approx(exact[1], rel=1e-5, abs=1e-9)
    before = delayed.t < tau
    static = system.forces(z0, np.zeros(2))
    np.testing.assert_allclose(delayed.lift[before], static[0] / SECTION.B, rtol=1e-12)


def test_vortex_shedding_adds_a_line_at_the_strouhal_frequency():
    """Harmonic forcing at St U / D appears in the lift spectrum with amplitude qd B cl."""
    U, vortex = 6.0, VortexShedding(strouhal=0.12, depth=0.03, cl=0.05, cm=0.01)
    fs, duration = 500.0, 20.0
    model = flat_plate.jones_model()
    forced = simulate_release(SECTION, model, U, 0.0, 0.01, duration=duration, fs=fs,
                              effects=[vortex])
    plain = simulate_release(SECTION, model, U, 0.0, 0.01, duration=duration, fs=fs)
    f_v = vortex.frequency(U)
    assert f_v == pytest.approx(24.0)
    freqs = np.fft.rfftfreq(forced.t.size, 1 / fs)
    line = np.argmin(np.abs(freqs - f_v))
    amp_forced = 2 * np.abs(np.fft.rfft(forced.lift)) / forced.t.size
    amp_plain = 2 * np.abs(np.fft.rfft(plain.lift)) / plain.t.size
    qd_B = 0.5 * SECTION.rho * U**2 * SECTION.B
    # The structure's forced response feeds back ~3 % (added mass at 24 Hz): 10 % tolerance.
    assert amp_forced[line] == pytest.approx(qd_B * vortex.cl, rel=0.1)
    assert amp_plain[line] < 0.01 * amp_forced[line]
    still = simulate_release(SECTION, STILL_AIR, 0.0, 0.0, 0.01, duration=2.0, fs=fs,
                             effects=[vortex])
    assert np.all(still.lift == 0.0)  # no wind, no shedding


def test_static_unbalance_couples_heave_and_pitch_in_still_air():
    """With S != 0 a pure heave release excites pitch at zero wind, at the coupled frequencies."""
    S = 0.05  # kg m/m: centre of mass 17 mm off the axis
    rel = simulate_release(UNDAMPED, STILL_AIR, 0.0, 0.005, 0.0, duration=40.0, fs=200.0,
                           effects=[StaticUnbalance(S)])
    assert np.abs(rel.alpha).max() > 1e-3
    assert rel.section.S == S
    coupled = UNDAMPED.replace(S=S)
    omega2 = eigh(coupled.stiffness_matrix(), coupled.mass_matrix(), eigvals_only=True)
    spectrum = np.abs(np.fft.rfft(rel.alpha * np.hanning(rel.t.size)))
    freqs = np.fft.rfftfreq(rel.t.size, 1 / 200.0)
    peaks, _ = find_peaks(spectrum, height=0.1 * spectrum.max())
    # 40 s records resolve 0.025 Hz; the two coupled modes must be the two spectral lines.
    np.testing.assert_allclose(np.sort(freqs[peaks]), np.sqrt(omega2) / (2 * np.pi), atol=0.03)


def test_sensor_crosstalk_mixes_the_measured_displacements_only():
    """h_measured = h + c_ha alpha and alpha_measured = alpha + c_ah h, forces untouched."""
    effect = SensorCrosstalk(h_from_alpha=0.01, alpha_from_h=0.2)
    rel = simulate_release(SECTION, flat_plate.jones_model(), 6.0, 0.004, 0.02, duration=3.0,
                           fs=200.0, effects=[effect])
    np.testing.assert_allclose(rel.h, rel.clean["h"] + 0.01 * rel.clean["alpha"], rtol=1e-14)
    np.testing.assert_allclose(rel.alpha, rel.clean["alpha"] + 0.2 * rel.clean["h"], rtol=1e-14)
    np.testing.assert_array_equal(rel.lift, rel.clean["lift"])


def test_base_vibration_forces_the_model_as_a_moving_support_and_the_taps_see_nothing():
    """Still air, released at rest from zero: the steady heave is the base-excited oscillator's.

    A support accelerating with ``a sin(w t)`` drives the relative heave ``m h'' + c h' + k h =
    -m a sin(w t)``: amplitude ``a / sqrt((wn^2 - w^2)^2 + (2 zeta wn w)^2)`` (any vibration
    textbook, e.g. Rao, Mechanical Vibrations, base excitation), pitch untouched without an
    unbalance, and no force in the measured lift and moment.
    """
    section = SECTION.replace(zeta_h=0.05)  # the start's transient dies out (see below)
    f, accel = 6.0, 0.2
    rel = simulate_release(section, STILL_AIR, 0.0, 0.0, 0.0, duration=14.0, fs=1000.0,
                           effects=[BaseVibration(frequency_hz=f, accel=accel, phase=0.4)])
    w, wn = 2 * np.pi * f, section.omega_h
    expected = accel / np.hypot(wn**2 - w**2, 2 * 0.05 * wn * w)
    steady = rel.h[rel.t > 10.0]
    # The peak of a sampled sine at 1 kHz is within 0.05 % of its amplitude; the free
    # transient of the start (up to w / wn = 3 times the steady amplitude) is down to
    # exp(-0.05 wn 10) = 0.2 % of itself after 10 s: 1 % all told (6 % was seen at 6 s).
    assert np.max(np.abs(steady)) == pytest.approx(expected, rel=0.01)
    assert np.max(np.abs(rel.alpha)) < 1e-12
    assert np.max(np.abs(rel.lift)) < 1e-12 and np.max(np.abs(rel.moment)) < 1e-12


@pytest.mark.parametrize(
    "effect",
    [
        CoulombFriction(force_h=0.05, moment_a=0.001),
        QuadraticDamping(c2_h=20.0, c2_a=0.05),
        CubicStiffness(k3_h=2.5e6, k3_a=50.0),
        ChannelDelay(0.005),
        VortexShedding(cl=0.05, cm=0.01),
        StaticUnbalance(0.05),
        SensorCrosstalk(h_from_alpha=0.01, alpha_from_h=0.2),
        BaseVibration(frequency_hz=6.0, accel=0.2),
        AerodynamicNonlinearity(e_h=-4.0, e_a=-0.2),
        TubingDistortion(frequency_hz=10.0, damping=1.0),
    ],
    ids=lambda e: e.name,
)
def test_every_effect_works_in_the_wind(effect):
    """At 70 % of the flutter speed every effect visibly changes a noisy release."""
    model = flat_plate.jones_model()
    U = 0.7 * flutter.analyze(SECTION, model).speed
    args = (SECTION, model, U, 0.004, 0.02)
    kw = {"duration": 10.0, "fs": 500.0, "noise": 0.02, "rng": 3}
    base = simulate_release(*args, **kw)
    changed = simulate_release(*args, effects=[effect], **kw)
    difference = max(
        np.sqrt(np.mean((getattr(changed, ch) - getattr(base, ch)) ** 2))
        / np.sqrt(np.mean(base.clean[ch] ** 2))
        for ch in ("h", "alpha", "lift", "moment")
    )
    assert difference > 0.05  # larger than the 2 % noise: visible
    assert all(np.all(np.isfinite(getattr(changed, ch))) for ch in ("h", "alpha", "lift", "moment"))


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: CoulombFriction(force_h=-1.0), "force_h must be >= 0"),
        (lambda: CoulombFriction(v_smooth_h=0.0), "v_smooth_h must be > 0"),
        (lambda: QuadraticDamping(c2_a=-1.0), "c2_a must be >= 0"),
        (lambda: CubicStiffness(k3_h=float("inf")), "k3_h must be finite"),
        (lambda: ChannelDelay(-0.1), "delay_s must be >= 0"),
        (lambda: VortexShedding(depth=0.0), "depth must be > 0"),
        (lambda: VortexShedding(cl=-0.1), "cl must be >= 0"),
        (lambda: StaticUnbalance(float("nan")), "S must be finite"),
        (lambda: SensorCrosstalk(h_from_alpha=float("nan")), "h_from_alpha must be finite"),
        (lambda: BaseVibration(frequency_hz=0.0), "frequency_hz must be > 0"),
        (lambda: BaseVibration(accel=-1.0), "accel must be >= 0"),
        (lambda: AerodynamicNonlinearity(e_h=float("nan")), "e_h must be finite"),
        (lambda: AerodynamicNonlinearity(q_ref=0.0), "q_ref must be > 0"),
        (lambda: TubingDistortion(frequency_hz=-1.0), "frequency_hz must be > 0"),
        (lambda: TubingDistortion(damping=0.0), "damping must be > 0"),
    ],
)
def test_effect_parameters_are_validated(make, match):
    """Out-of-range effect parameters raise ValueError naming the parameter."""
    with pytest.raises(ValueError, match=match):
        make()


def test_repeated_or_foreign_effects_are_refused():
    """Two effects of one kind, or something that is not an effect, raise."""
    args = (SECTION, STILL_AIR, 0.0, 0.001, 0.0)
    with pytest.raises(ValueError, match="repeated"):
        simulate_release(*args, duration=1.0, fs=100.0,
                         effects=[ChannelDelay(0.1), ChannelDelay(0.2)])
    with pytest.raises(TypeError, match="Effect instances"):
        simulate_release(*args, duration=1.0, fs=100.0, effects=["coulomb_friction"])


def test_static_unbalance_beyond_the_mass_matrix_limit_is_refused():
    """S^2 >= m I would make the mass matrix singular: a clear error, not a NaN record."""
    with pytest.raises(ValueError, match="positive-definite"):
        simulate_release(SECTION, STILL_AIR, 0.0, 0.001, 0.0, duration=1.0, fs=100.0,
                         effects=[StaticUnbalance(0.4)])


def test_aerodynamic_nonlinearity_is_an_amplitude_dependent_flutter_derivative():
    """Harmonic motion of amplitude a: the force's fundamental changes K H1* by e (a/q_ref)^2/4.

    Closed form: the fundamental of cos^2 sin is sin / 4. And there is no force at zero wind.
    """
    effect = AerodynamicNonlinearity(e_h=-2.0, e_a=-0.1, q_ref=0.01)
    B, U, rho, w = 0.3, 6.0, 1.2, 2 * np.pi * 2.0
    t = np.linspace(0.0, 1.0, 4000, endpoint=False)  # two whole periods
    for a in (0.005, 0.02):
        q = np.column_stack([a * np.cos(w * t), a * np.cos(w * t)])
        qd = np.column_stack([-a * w * np.sin(w * t), -a * w * np.sin(w * t)])
        force = effect.aerodynamic_force(q, qd, B, U, rho)
        # Linear damping force qd B^2 dA2 (B/U) q' has the sine coefficient -qd B^3/U dA2 a w.
        sine = 2 * np.mean(force * np.sin(w * t)[:, None], axis=0)
        dA2 = sine / (-0.5 * rho * U * B**3 * a * w)
        assert dA2 == pytest.approx([e * (a / 0.01) ** 2 / 4 for e in (-2.0, -0.1)], rel=1e-9)
        assert np.all(effect.aerodynamic_force(q, qd, B, 0.0, rho) == 0.0)
    # In still air the effect does nothing to a release (unlike quadratic damping).
    still = simulate_release(SECTION, flat_plate.jones_model(), 0.0, 0.004, 0.02, duration=2.0,
                             fs=500.0)
    with_effect = simulate_release(SECTION, flat_plate.jones_model(), 0.0, 0.004, 0.02,
                                   duration=2.0, fs=500.0, effects=[effect])
    # (The nonlinear integrator runs instead of the exact one: equal to rounding.)
    for channel in ("h", "alpha", "lift", "moment"):
        a, b = getattr(still, channel), getattr(with_effect, channel)
        assert np.allclose(a, b, rtol=0.0, atol=1e-9 * np.abs(a).max()), channel


def test_aerodynamic_nonlinearity_damps_large_amplitudes_more_and_the_taps_see_it():
    """Negative e: the decay's start is damped more; the force record holds the extra force."""
    model = flat_plate.jones_model()
    U = 0.65 * flutter.analyze(SECTION, model).speed
    effect = AerodynamicNonlinearity(e_h=-3.0, e_a=-0.15)
    base = simulate_release(SECTION, model, U, 0.004, 0.02, duration=4.0, fs=500.0)
    changed = simulate_release(SECTION, model, U, 0.004, 0.02, duration=4.0, fs=500.0,
                               effects=[effect])
    first = slice(0, 250)  # the first half second, at large amplitude
    assert np.abs(changed.alpha[first]).max() <= np.abs(base.alpha[first]).max()
    assert np.sqrt(np.mean(changed.alpha[250:] ** 2)) < np.sqrt(np.mean(base.alpha[250:] ** 2))
    # The taps see the force: at the release (same position, no velocity) the records agree,
    # half a second in they differ by more than the motion's change alone would explain.
    assert changed.moment[0] == pytest.approx(base.moment[0])
    diff_moment = np.abs(changed.moment[:250] - base.moment[:250]).max()
    assert diff_moment > 0.01 * np.abs(base.moment[:250]).max()


def test_tubing_distortion_filters_the_forces_as_its_frequency_response_says():
    """The time-domain tube matches ident.physics.tubing's FFT filter with the same response."""
    from ident.physics.tubing import Air, TableResponse, Tube, TubingGroup, distort, tubing_set

    model = flat_plate.jones_model()
    U = 0.65 * flutter.analyze(SECTION, model).speed
    tube = TubingDistortion(frequency_hz=12.0, damping=0.6)
    base = simulate_release(SECTION, model, U, 0.004, 0.02, duration=6.0, fs=500.0)
    tubed = simulate_release(SECTION, model, U, 0.004, 0.02, duration=6.0, fs=500.0,
                             effects=[tube])
    assert np.array_equal(base.h, tubed.h) and np.array_equal(base.alpha, tubed.alpha)
    f = np.arange(0.25, 251.0, 0.25)
    H = tube.response(f)
    table = TableResponse(frequency=f, gain=np.abs(H), phase=np.unwrap(np.angle(H)))
    expected = distort(np.column_stack([base.lift, base.moment]), 500.0,
                       tubing_set([TubingGroup(taps=None, model=table)], 2))
    late = slice(250, None)  # after the release's transient (the FFT filter starts steady)
    for k, channel in enumerate(("lift", "moment")):
        got = getattr(tubed, channel)[late]
        rms = np.sqrt(np.mean(expected[late, k] ** 2))
        # Two discretisations of one filter (first-order hold against FFT): 0.5 % of the RMS.
        assert np.sqrt(np.mean((got - expected[late, k]) ** 2)) < 0.005 * rms
    # From a Bergh-Tijdeman tube: 2 m of 0.8 mm into 50 mm^3 is a 16.9 Hz, 0.99 low-pass that
    # matches the tube's gain at 4 Hz within 0.5 % and its phase (-0.47 rad) within 3 %.
    air = Air()
    real = Tube(length=2.0, diameter=0.8e-3, volume=50e-9)
    equivalent = TubingDistortion.from_tube(real, air)
    assert equivalent.frequency_hz == pytest.approx(16.9, abs=0.1)
    assert equivalent.damping == pytest.approx(0.99, abs=0.01)
    h_real, h_eq = real.response([4.0], air)[0], equivalent.response([4.0])[0]
    assert abs(h_eq) == pytest.approx(abs(h_real), rel=0.005)
    assert np.angle(h_eq) == pytest.approx(np.angle(h_real), rel=0.03)


def test_tubing_distortion_continues_across_records():
    """A continued record goes on from the tubes' state: the same as one long record."""
    from ident.simulation.decay import simulate_decay

    model = flat_plate.jones_model()
    U = 0.65 * flutter.analyze(SECTION, model).speed
    tube = TubingDistortion(frequency_hz=12.0, damping=0.6)
    whole = simulate_decay(SECTION, model, U, 0.004, 0.02, n=1000, fs=500.0, effects=[tube])
    part = simulate_decay(SECTION, model, U, 0.004, 0.02, n=600, fs=500.0, effects=[tube])
    rest = part.continued(400)
    rms = np.sqrt(np.mean(whole.moment**2))
    assert np.allclose(rest.moment, whole.moment[600:], atol=1e-6 * rms)
