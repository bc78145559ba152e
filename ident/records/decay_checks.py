"""Checks of the section and of an identified model against the releases' measured decays.

:mod:`ident.records.plausibility` checks each release on its own; these checks hold what the
modal fits measured (each release's oscillatory eigenvalues) against what the section and the
identified model say. :func:`ident.identification.e2rfc.identify` runs the model and damping
checks on releases in smooth flow (in turbulence the modal fits neither start from rest nor
give the damping to the precision needed), the frequency check on every release (in
turbulence on the spectral peaks, :func:`ringing_frequencies`), and adds their warnings to the
model's; the displacement-only route (:mod:`ident.identification.fd_method`) runs the
frequency check, and the damping check where the section's damping is its reference.

Measured on the flat plate of the tests (B = 0.3 m, fh = 2 Hz, fa = 4 Hz, Jones's
aerodynamics, releases from 4 mm and 0.02 rad at 0.4, 0.6 and 0.8 of its flutter speed, 2 %
noise; ``tests/ident/records/test_decay_checks.py``):

- **Still-air frequencies** (:func:`check_frequencies`, before identification). At the
  lowest wind speed the wind moves a mode's frequency by a few per cent (the plate's pitch at
  0.4 of its flutter speed: 3 %); each named mode (heave, pitch, sway: by its shape) must ring
  within :data:`FREQUENCY_MATCH` of its still-air frequency. Frequencies in rad/s where Hz are
  meant (a factor 2 pi) and heave's and pitch's swapped are refused by name: unguarded, the
  first gave a flutter speed 6.3 times the truth with a std of 0.3 %, the second "no flutter",
  each with a warning that named neither. Frequencies off in any other way are warned of. In
  turbulence each coordinate's spectral peak stands for its mode: over the benchmark's
  turbulence rows (plate and bluff deck at Iw 1 and 3 %, long gusts, non-Gaussian gusts,
  friction; 20 seeds, with and without holds: 280 campaigns) the median at the lowest speed
  lies within 7.6 % of the still-air frequencies (10.8 % with friction), none is warned of,
  and each is refused with its frequencies in rad/s or swapped.
- **Still-air damping** (:func:`check_damping`, before identification, smooth releases). At
  the lowest wind speed each mode decays at its structural damping plus the wind's; on the
  benchmark's smooth rows (plate and deck with Jones's aerodynamics, exact Theodorsen, the
  bluff deck) the total is 10.7-27.5 times the structural damping in heave and 3.8-7.6 times
  in pitch. Damping ratios given in per cent (0.5 for 0.005) are refused by name: unguarded,
  50 % of critical gave a warning that blamed a force channel's sign or unit. A ratio more
  than twice the measured total and 1 % of critical above it is warned of.
- **Forces against motion** (:func:`check_model`, after identification). The identified
  model, put into the section's equations of motion at each release's wind speed, must
  predict the decays that were measured: each mode's eigenvalue shift from still air,
  predicted against measured. Correct data agree to 0.2 %. A lift of the wrong sign predicts
  heave modes that grow where the measured ones decay (and ``H1* > 0`` at every release,
  where any deck's aerodynamic damping of heave makes ``H1* < 0``): refused. Forces off by a
  common factor (total over a 0.9 m span: the predicted aerodynamic shifts are 0.84-0.93 of
  the measured ones) are warned of with the factor that reconciles them, when it is more than
  :data:`FORCE_SCALE_TOLERANCE` from 1 and explains the decays (:data:`SCALE_EXPLAINS`); this
  also catches a section whose mass or inertia is off by that factor, which the message says.
  A model that predicts the decays badly however scaled (a moment of the wrong sign: 138 %
  off, its pitch mode growing at 4.7 m/s where the measured one is damped 1.9 %; a lift alone
  halved: 36 %) is warned of with its worst mode, above :data:`MISFIT_WARN`. Effects the
  model lacks stay below it (friction 0.24, a 10 ms channel delay 0.21, a cubic spring 0.03:
  the whiteness of the force residuals speaks for them). Where the model with one
  displacement's column rescaled by a unit's factor (:data:`UNIT_MISTAKES`: heave in mm or
  cm, pitch in degrees) predicts the decays within :data:`SCALE_EXPLAINS`, the warning names
  that unit instead: a pitch of 0.23 degrees read as radians passes the amplitude check and
  identified +131 % with a std of 0.5 %; rescaled, its model predicts the decays to 0.1 %.
  The decays cannot tell a heave column too weak from a section mass too large (or pitch
  from inertia): the warning gives that reading too (the plate with m in g/m: "h looks like
  millimetres ... the section's m = 3000 kg/m may be 1e+03 times too large"), beside the
  section's own proportion check (:func:`ident.model.section.proportion_warnings`).

Not responsible for: a release's own checks (:mod:`ident.records.plausibility`), the modal
fits (:mod:`ident.identification.modal`).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
from scipy.optimize import minimize_scalar
from scipy.signal import welch

from ident.errors import PlausibilityError
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.model.statespace import AeroelasticSystem
from ident.records.release import Release

__all__ = ["FORCE_SCALE_TOLERANCE", "FREQUENCY_MATCH", "FREQUENCY_MISTAKES",
           "FREQUENCY_WARN", "MISFIT_WARN", "SCALE_EXPLAINS",
           "UNIT_MISTAKES", "DAMPING_IN_PER_CENT", "DAMPING_WARN", "DAMPING_WARN_EXCESS",
           "check_damping", "check_frequencies", "check_model", "force_scale",
           "ringing_frequencies"]

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]

#: Force scale (measured over what the motion implies) further than this from 1 is warned
#: of. Correct simulated data give 1 within 0.3 %; a section's still-air damping known to
#: 0.1 % of critical moves the scale by about 1 % at the wind speeds of a campaign.
FORCE_SCALE_TOLERANCE = 0.05
#: A common factor on the forces is named only when it explains the decays: the shifts'
#: misfit with it below this (0.001 on 2 % noise; friction or a delayed channel leave 0.2).
SCALE_EXPLAINS = 0.1
#: Misfit of the model's predicted shifts (as identified) above which the model is said not
#: to predict the decays (correct data 0.001-0.002; a 10 ms channel delay 0.2, friction 0.2).
MISFIT_WARN = 0.25
#: Largest factor between a mode's frequency at the lowest wind speed and its still-air one.
#: The wind moves it by a few per cent there (by tens of per cent only close to flutter or
#: divergence); the mistakes named are factors of 2 pi, or fa / fh (1.3-3 on section models).
FREQUENCY_MATCH = 1.25
#: A mode this many times off its still-air frequency at the lowest wind speed, where no
#: mistake of :func:`check_frequencies` explains it, is warned of (not refused: a first
#: release close to flutter may move the pitch's frequency this far).
FREQUENCY_WARN = 1.5


#: A still-air damping ratio this large (10 % of critical) or more, where the releases at the
#: lowest wind speed decay at less than half of it, is taken as given in per cent: a section
#: model on springs is damped 0.1-2 % of critical, rarely 5 % with added dampers.
DAMPING_IN_PER_CENT = 0.1
#: A still-air damping ratio more than this many times the total the releases decay at, at the
#: lowest wind speed, and more than :data:`DAMPING_WARN_EXCESS` above it, is warned of: only a
#: negative aerodynamic damping lowers the total (the benchmark's sections decay there at 3.8
#: times their structural damping or more); a deck's pitch near torsional flutter may approach
#: zero total damping, which the excess a warning needs leaves alone at usual damping.
DAMPING_WARN = 2.0
#: The excess of the still-air damping over the measured total that a warning needs (1 %).
DAMPING_WARN_EXCESS = 0.01


#: Mistakes of the still-air frequencies that :func:`check_frequencies` names: what it says
#: of them, and the factor from the given frequencies to the right ones.
FREQUENCY_MISTAKES = (("look like rad/s, not Hz", "give them in Hz (/2 pi)", 1 / (2 * math.pi)),
                      ("look divided by 2 pi once too often", "multiply them by 2 pi",
                       2 * math.pi))
#: The section's still-air frequencies by coordinate: attribute and name.
_STILL_AIR = (("fh", "heave"), ("fa", "pitch"), ("fp", "sway"))


def _median_at_lowest(speeds: Sequence[float], values: Sequence[Sequence[float]]
                      ) -> tuple[float, FloatArray]:
    """Return the lowest wind speed (m/s) and the median of its releases' values per mode."""
    lowest = min(speeds)
    at_lowest = [x for U, x in zip(speeds, values, strict=True) if U <= lowest * 1.001]
    return lowest, np.median(np.asarray(at_lowest, dtype=float), axis=0)


def check_frequencies(section: SectionModel, speeds: Sequence[float],
                      frequencies: Sequence[Sequence[float]]) -> list[str]:
    """Check the section's still-air frequencies against the modes the releases ring at.

    At the lowest wind speed (the median over its releases) each named mode's frequency must
    lie within :data:`FREQUENCY_MATCH` of its coordinate's still-air frequency.

    Parameters
    ----------
    section : SectionModel
    speeds : sequence of float
        Each release's wind speed, m/s.
    frequencies : sequence of sequences of float
        Each release's damped frequency of its heave-, pitch- (and sway-) dominated mode, Hz,
        in that order (the modal fit's modes named by their shapes).

    Returns
    -------
    list of str
        A warning when a mode is more than :data:`FREQUENCY_WARN` times off in a way no
        mistake below explains.

    Raises
    ------
    PlausibilityError
        The frequencies look like rad/s, divided by 2 pi twice (:data:`FREQUENCY_MISTAKES`),
        or two coordinates' swapped: that mistake predicts every mode within
        :data:`FREQUENCY_MATCH` and the frequencies as given predict none of those it moves.
    """
    if not speeds:
        return []
    n = section.n_dof
    given = np.array([getattr(section, attr) for attr, _ in _STILL_AIR[:n]], dtype=float)
    lowest, rung = _median_at_lowest(speeds, frequencies)
    names = [name for _, name in _STILL_AIR[:n]]

    def off(still: FloatArray) -> FloatArray:
        return np.asarray(np.abs(np.log(rung / still)), dtype=float)

    limit = math.log(FREQUENCY_MATCH)
    as_given = off(given)
    if np.all(as_given <= limit):
        return []
    attrs = [attr for attr, _ in _STILL_AIR[:n]]
    where = (f"at {lowest:.3g} m/s the releases ring at "
             + ", ".join(f"{f:.3g} Hz ({name})" for f, name in zip(rung, names, strict=True))
             + " against the section's "
             + ", ".join(f"{a} = {f:.4g} Hz" for a, f in zip(attrs, given, strict=True)))
    for what, fix, factor in FREQUENCY_MISTAKES:
        if np.all(off(given * factor) <= limit) and np.all(as_given > limit):
            raise PlausibilityError(
                f"the section's still-air frequencies {what}: {where}; {fix}: "
                + ", ".join(f"{a} = {f * factor:.4g} Hz"
                            for a, f in zip(attrs, given, strict=True)))
    for order in itertools.permutations(range(n)):
        moved = [i for i in range(n) if order[i] != i]
        if not moved or given[moved[0]] == given[order[moved[0]]]:
            continue
        swapped = given[list(order)]
        if np.all(off(swapped) <= limit) and np.all(as_given[moved] > limit):
            pairs = " and ".join(attrs[i] for i in moved)
            raise PlausibilityError(
                f"the section's {pairs} look swapped: {where}; swap them ("
                + ", ".join(f"{attrs[i]} = {swapped[i]:.4g} Hz" for i in moved) + ")")
    if np.all(as_given <= math.log(FREQUENCY_WARN)):
        return []
    return [f"the section's still-air frequencies are not the releases': {where}, more than "
            f"{FREQUENCY_WARN:g} times off; at the lowest wind speed the wind moves a mode "
            "by a few per cent: check the section's frequencies (and that they are in Hz), "
            "or the flutter speed is wrong"]


def check_damping(section: SectionModel, speeds: Sequence[float],
                  damping: Sequence[Sequence[float]]) -> list[str]:
    """Check the section's still-air damping ratios against the total the releases decay at.

    At the lowest wind speed (the median over its smooth releases) the measured damping ratio
    of each named mode is the structural one plus the wind's, which there is small and, for
    heave, positive. A structural ratio far above the measured total cannot be.

    Parameters
    ----------
    section : SectionModel
    speeds : sequence of float
        Each release's wind speed, m/s.
    damping : sequence of sequences of float
        Each release's damping ratio (fraction of critical) of its heave-, pitch- (and sway-)
        dominated mode, in that order.

    Returns
    -------
    list of str
        A warning per mode whose still-air ratio is more than :data:`DAMPING_WARN` times the
        measured total and :data:`DAMPING_WARN_EXCESS` above it; where that total is negative
        (the mode grows), the warning names the releases, not the section's damping.

    Raises
    ------
    PlausibilityError
        A still-air ratio of :data:`DAMPING_IN_PER_CENT` or more, over twice the measured
        total: given in per cent where a fraction of critical is meant.
    """
    if not speeds:
        return []
    n = section.n_dof
    attrs = ("zeta_h", "zeta_a", "zeta_p")[:n]
    names = [name for _, name in _STILL_AIR[:n]]
    given = np.array([getattr(section, a) or 0.0 for a in attrs], dtype=float)
    lowest, measured = _median_at_lowest(speeds, damping)
    where = (f"at {lowest:.3g} m/s the releases decay at "
             + ", ".join(f"{100 * z:.2g} % of critical ({name})"
                         for z, name in zip(measured, names, strict=True)))
    high = given > DAMPING_WARN * measured
    percent = high & (given >= DAMPING_IN_PER_CENT)
    if percent.any():
        wrong = [i for i in range(n) if percent[i]]
        raise PlausibilityError(
            "the section's still-air damping looks given in per cent, not as a fraction of "
            "critical: " + ", ".join(f"{attrs[i]} = {given[i]:.4g}" for i in wrong)
            + f" ({', '.join(f'{100 * given[i]:.3g} %' for i in wrong)}), where {where}; "
            "give " + ", ".join(f"{attrs[i]} = {given[i] / 100:.4g}" for i in wrong))
    out = []
    for i in np.flatnonzero(high & (given - measured > DAMPING_WARN_EXCESS)):
        if measured[i] < 0.0:
            # A mode that grows at the lowest speed says nothing of the structural damping.
            out.append(f"the {names[i]} mode grows at the lowest wind speed ({where}): those "
                       "releases are not free decays (a random response of turbulence too "
                       "weak to be recognised as one, forcing by vortex shedding or a "
                       "vibrating floor, or an instability already at that speed), so the "
                       f"section's {attrs[i]} is not checked against them")
            continue
        out.append(f"the section's {attrs[i]} = {given[i]:.4g} ({100 * given[i]:.3g} % of "
                   f"critical) is more than {DAMPING_WARN:g} times what the {names[i]} mode "
                   f"decays at with the wind ({where}): only a negative aerodynamic damping "
                   "could take it that far down; check the section's damping (a fraction of "
                   "critical, not per cent), or the flutter speed is wrong")
    return out


def ringing_frequencies(release: Release, n_dof: int) -> list[float]:
    """Return the frequency at which each coordinate's velocity spectrum peaks, Hz.

    For releases in turbulence, whose modal fits do not name the modes reliably: the buffeted
    response rings at the modes too, and at the lowest wind speed each coordinate's largest
    peak is its own mode's. The velocity's spectrum (the displacement's times ``f^2``) is
    used because the displacement's own is dominated below the modes by the gusts' slow
    quasi-static push wherever the gusts are long (a 1 m length scale put the plate's heave
    peak at 0.12-0.25 Hz against its 2 Hz mode); the band is from two cycles per record to a
    quarter of the sampling rate (above it, the sensors' noise), the spectrum Welch's over
    halves of the record (Hann window), the peak located to a fraction of a bin by a parabola
    through the logarithms of the three bins about it.

    Parameters
    ----------
    release : Release
    n_dof : int
        2 (heave, pitch) or 3 (and sway).

    Returns
    -------
    list of float
        Heave's, pitch's (and sway's) peak frequency, Hz.
    """
    t = np.asarray(release.t, dtype=float)
    fs = 1.0 / float(np.median(np.diff(t)))
    out = []
    for x in [release.h, release.alpha, release.p][:n_dof]:
        x = np.asarray(x, dtype=float)
        # A release has at least 64 samples: bins 2 to 16 of 64 at the least.
        f, P = welch(x - x.mean(), fs=fs, nperseg=max(64, x.size // 2), window="hann")
        velocity = f**2 * P
        band = np.flatnonzero((f >= 2.0 * fs / x.size) & (f <= fs / 4.0))
        i = int(band[np.argmax(velocity[band])])
        if i in (band[0], band[-1]) or np.any(velocity[i - 1:i + 2] <= 0.0):
            out.append(float(f[i]))
            continue
        lo, mid, hi = np.log(velocity[i - 1:i + 2])
        curvature = lo - 2.0 * mid + hi  # < 0 at a strict peak; 0 on a flat top
        shift = 0.5 * (lo - hi) / curvature if curvature < 0.0 else 0.0
        out.append(float(f[i] + shift * (f[1] - f[0])))
    return out


def _oscillatory(eigenvalues: ComplexArray) -> ComplexArray:
    return eigenvalues[eigenvalues.imag > 1e-9 * np.abs(eigenvalues).max()]


def _shifts(section: SectionModel, model: RationalFunctionModel, speeds: Sequence[float],
            measured: Sequence[ComplexArray]) -> tuple[ComplexArray, ComplexArray]:
    """Return the predicted and the measured eigenvalue shifts from still air, 1/s.

    One entry per measured mode of every release, in order; each matched to the nearest
    still-air and the nearest predicted oscillatory eigenvalue.
    """
    still_model = RationalFunctionModel(np.zeros((3, model.n_dof, model.n_dof)), [])
    still = _oscillatory(AeroelasticSystem(section, still_model, 0.0).eigenvalues())
    predicted_all, measured_all = [], []
    for U, modes in zip(speeds, measured, strict=True):
        predicted = _oscillatory(AeroelasticSystem(section, model, U).eigenvalues())
        for lam in modes:
            lam0 = still[np.argmin(np.abs(still - lam))]
            lam_p = predicted[np.argmin(np.abs(predicted - lam))]
            predicted_all.append(lam_p - lam0)
            measured_all.append(lam - lam0)
    return np.asarray(predicted_all), np.asarray(measured_all)


def _zeta(lam: complex) -> float:
    """Damping ratio of an eigenvalue, ``-Re / |lam|`` (negative: the mode grows)."""
    return float(-lam.real / abs(lam))


def _misfit(section: SectionModel, model: RationalFunctionModel, speeds: Sequence[float],
            measured: Sequence[ComplexArray]) -> float:
    """Return the rms misfit of the predicted eigenvalue shifts, each over the measured one."""
    predicted, measured_shift = _shifts(section, model, speeds, measured)
    size = np.maximum(np.abs(measured_shift), 1e-12)
    return float(np.sqrt(np.mean(np.abs(predicted - measured_shift) ** 2 / size**2)))


#: Unit mistakes of a displacement tried by :func:`_unit_mistake`: (coordinate, its name,
#: the unit it was read in, the factor from the wrong unit's numbers to the right one's).
UNIT_MISTAKES = ((0, "h", "millimetres", 1e-3), (0, "h", "centimetres", 1e-2),
                 (1, "alpha", "degrees", math.pi / 180))
#: The section's field whose excess by the unit's factor the decays cannot tell from a
#: displacement in that unit (a heave column too weak acts as a mass too large).
_UNIT_TWIN = {"h": ("m", "kg/m"), "alpha": ("I", "kg m^2/m")}


def _unit_mistake(section: SectionModel, model: RationalFunctionModel, speeds: Sequence[float],
                  measured: Sequence[ComplexArray]) -> tuple[str, str, float, float] | None:
    """Return ``(channel, unit, misfit, factor)`` of the unit mistake that explains the decays.

    A displacement read in a wrong unit scales its column of the identified ``Q`` by the unit's
    factor, not the decays' eigenvalues: the model with that column rescaled predicts them
    again, to within :data:`SCALE_EXPLAINS`. Amplitude checks catch such a channel when its
    holds are large; with small ones (a pitch of 0.2 degrees) only this does.
    """
    best: tuple[str, str, float, float] | None = None
    for column, name, unit, factor in UNIT_MISTAKES:
        A = np.array(model.A, dtype=float)
        A[:, :, column] /= factor
        misfit = _misfit(section, RationalFunctionModel(A, model.d), speeds, measured)
        if misfit < SCALE_EXPLAINS and (best is None or misfit < best[2]):
            best = (name, unit, misfit, factor)
    return best


def force_scale(section: SectionModel, model: RationalFunctionModel, speeds: Sequence[float],
                measured: Sequence[ComplexArray]) -> tuple[float, float]:
    """Return the factor on the model's forces that best predicts the measured decays.

    The model times ``k``, in the section's equations of motion at each wind speed, predicts
    each measured mode's eigenvalue shift from still air; ``k`` minimises the shifts' misfit
    relative to their size (a bounded search over ``log k`` in ``[-log 1000, log 1000]``).

    Returns
    -------
    k : float
        1 for forces consistent with the motion; 1/0.9 for forces total over a 0.9 m span.
    misfit : float
        The remaining rms misfit of the shifts relative to the measured shifts.
    """
    def misfit(log_k: float) -> float:
        scaled = RationalFunctionModel(math.exp(log_k) * model.A, model.d)
        return _misfit(section, scaled, speeds, measured)

    found = minimize_scalar(misfit, bounds=(-math.log(1e3), math.log(1e3)), method="bounded",
                            options={"xatol": 1e-4})
    return math.exp(float(found.x)), float(found.fun)


def check_model(section: SectionModel, model: RationalFunctionModel, speeds: Sequence[float],
                measured: Sequence[ComplexArray], heave: Sequence[int]) -> list[str]:
    """Check an identified model against the decays it came from (module docstring).

    Parameters
    ----------
    section : SectionModel
    model : RationalFunctionModel
        The identified model.
    speeds : sequence of float
        Each release's wind speed, m/s.
    measured : sequence of complex ndarray
        Each release's measured oscillatory eigenvalues (modal fit), 1/s.
    heave : sequence of int
        Index into each ``measured`` of its heave-dominated mode.

    Returns
    -------
    list of str
        Warnings: forces off by a factor, or a model that does not predict the decays.

    Raises
    ------
    PlausibilityError
        The lift's sign looks flipped: every release's measured heave mode is damped by the
        wind, the model's heave mode grows, and ``H1* > 0`` at every release.
    """
    predicted, measured_shift = _shifts(section, model, speeds, measured)
    n_modes = [len(m) for m in measured]
    starts = np.cumsum([0, *n_modes[:-1]])
    heave_rows = [int(s + i) for s, i in zip(starts, heave, strict=True)]
    damped = all(measured_shift[r].real < 0 for r in heave_rows)
    grows = all(predicted[r].real > 0 for r in heave_rows)
    K = np.array([section.B * abs(m[i].imag) / U
                  for m, i, U in zip(measured, heave, speeds, strict=True)])
    H1 = model.flutter_derivatives(K)["H1"]
    if damped and grows and np.all(H1 > 0):
        raise PlausibilityError(
            "the lift's sign looks flipped (lift positive upward; windrig's is positive "
            "downward, along h): the wind damps every release's heave mode, but the model "
            f"identified from these forces has H1* = {float(H1.min()):.3g} to "
            f"{float(H1.max()):.3g} > 0 at the releases' reduced frequencies (any deck's "
            "aerodynamic damping of heave makes H1* < 0) and predicts heave modes that grow; "
            "negate the lift")
    as_identified = _misfit(section, model, speeds, measured)
    warnings: list[str] = []
    if as_identified < FORCE_SCALE_TOLERANCE / 2:
        # The shifts scale about as the forces do: a misfit this small leaves no room for a
        # factor beyond the tolerance (and the search, 85 % of these checks' time, is spared).
        return warnings
    k, remaining = force_scale(section, model, speeds, measured)
    if abs(1.0 / k - 1.0) > FORCE_SCALE_TOLERANCE and remaining < SCALE_EXPLAINS:
        warnings.append(
            f"the forces are {1.0 / k:.3g} times what the decays imply (the model predicts "
            f"the measured frequencies and damping with its forces times {k:.3g}): forces "
            "total over the model's span rather than per unit span (N/m; a span of "
            f"{1.0 / k:.3g} m?), a force calibration off, or the section's mass and inertia "
            f"off by {k:.3g}")
    elif as_identified > MISFIT_WARN and (unit := _unit_mistake(section, model, speeds,
                                                                measured)) is not None:
        twin = _UNIT_TWIN[unit[0]]
        twin_value = float(getattr(section, twin[0]))
        warnings.append(
            f"the identified model does not predict the measured decays "
            f"({100 * as_identified:.0f} % off), but does once {unit[0]} is taken as "
            f"{unit[1]} ({100 * unit[2]:.2g} % off): {unit[0]} looks like {unit[1]} (small "
            f"holds pass the amplitude check); convert it, or the flutter speed is wrong "
            f"(if {unit[0]} is right, the section's {twin[0]} = {twin_value:.4g} {twin[1]} "
            f"may be {1 / unit[3]:.3g} times too large: it acts alike)")
    elif as_identified > MISFIT_WARN:
        errors = np.abs(predicted - measured_shift) / np.maximum(np.abs(measured_shift), 1e-12)
        worst = int(np.argmax(errors))
        U = np.repeat(np.asarray(speeds, dtype=float), n_modes)[worst]
        lam = np.concatenate(list(measured))[worst]
        lam_p = lam - measured_shift[worst] + predicted[worst]
        warnings.append(
            f"the identified model does not predict the measured decays (the frequency and "
            f"damping shifts from still air it predicts are {100 * as_identified:.0f} % off "
            f"the measured ones; worst at {U:.3g} m/s, the {lam.imag / (2 * math.pi):.3g} Hz "
            f"mode: damping ratio {100 * _zeta(lam_p):.2g} % predicted, {100 * _zeta(lam):.2g} % "
            "measured): a force channel's sign or unit (a moment of the wrong sign, a lift "
            "scaled apart from the moment), an effect the model lacks (friction, a delayed "
            "channel: windrig diagnose names it), or the section's still-air frequencies and "
            "damping")
    return warnings
