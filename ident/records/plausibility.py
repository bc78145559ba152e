"""Guards against unit and sign mistakes in releases: what no section model could have done.

Legacy decays come into :mod:`ident` converted by hand or by a map, and a conversion mistake
(a pitch left in degrees, forces over the span, a lift positive upward, a release instant
late) still identifies: numbers come out and nothing says they are wrong. These checks say
it, naming the likely mistake; where the answer would be meaningless they refuse it with a
:class:`~ident.errors.PlausibilityError`. :func:`ident.identification.e2rfc.identify` runs
them and adds their warnings to the model's (``diagnostics.warnings``, and so to every
front end's printed warnings and JSON ``warnings``).

What each check can honestly detect, measured on the flat plate of the tests (B = 0.3 m,
fh = 2 Hz, fa = 4 Hz, Jones's aerodynamics, releases from 4 mm and 0.02 rad at 0.4, 0.6 and
0.8 of its flutter speed, 2 % noise; ``tests/ident/records/test_plausibility.py``):

- **Dead channels** (:func:`check_release`, before identification). A channel that reads one
  value in every sample of a release (a tap or laser not connected, a column an import map
  filled with zeros) is refused, naming it: unguarded, a constant force broke the least
  squares with a linear-algebra error, and a stuck pitch identified a model whose warnings
  named every cause but the channel.
- **Sampling** (:func:`check_release`). A record whose Nyquist frequency lies below a
  :data:`FREQUENCY_FACTOR`-th of the section's lowest still-air frequency cannot hold a mode:
  refused, naming a time axis in milliseconds when the factor says so (unguarded: "no flutter",
  with warnings about the release instant). Where the displacements' spectra peak is not
  checked: large-scale turbulence puts the peak below the modes.
- **Amplitudes** (:func:`check_release`, before identification). A pitch oscillating over
  more than :data:`ALPHA_AMPLITUDE_MAX` (0.3 rad, 17 degrees) about its mean is no section
  model's: a pitch in degrees (holds of 2-10 degrees read as radians) is refused. So is a
  heave amplitude over :data:`HEAVE_AMPLITUDE_MAX` of the deck width (millimetres read as
  metres), and a sway likewise.
- **Force magnitude** (:func:`check_release`). The rms force per unit span, over
  ``qd B`` (lift, drag) or ``qd B^2`` (moment), cannot exceed the rms of the motion ``q``
  times :data:`FORCE_BOUND_FACTOR` times the largest entry of a flat plate's ``|Q(iK)|`` at
  the release's reduced frequencies (bluff decks' derivatives are a few times a plate's, never
  ten times): a force in a wrong unit, or total over a long span, is warned of. A total force
  over a span near 1 m (0.9x) is far inside any such bound: the consistency below finds it.
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
- **Release instant** (:func:`check_start`). A release from rest starts with zero velocity in
  every coordinate. The instant where the decay's velocity vanishes, found from the modal
  fit extrapolated backwards (:func:`start_offset`) or, with a still hold before the release,
  by :func:`ident.records.release_onset.locate_release`, more than
  :data:`START_OFFSET_WARN_S` from the given instant is a warning that names the offset
  (a 30 ms late instant: found at -29.9 to -30.3 ms). The extrapolation is used only where the
  modal fit follows the displacements to their noise (friction or a cubic spring bend the
  decay away from exponentials and its zero 3-10 ms away from a right instant).

Not responsible for: the shapes, finiteness and sampling of a release
(:mod:`ident.records.release`), fitting anything (:mod:`ident.identification`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt
from scipy.optimize import minimize_scalar

from ident.errors import PlausibilityError, ReleaseNotFoundError
from ident.model import flat_plate
from ident.model.conventions import Q_from_flutter_derivatives
from ident.model.rfc import RationalFunctionModel
from ident.model.section import SectionModel
from ident.model.statespace import AeroelasticSystem
from ident.records.release import Release
from ident.records.release_onset import locate_release

__all__ = ["AIR_DENSITY_RANGE", "ALPHA_AMPLITUDE_MAX", "FORCE_BOUND_FACTOR",
           "FORCE_SCALE_TOLERANCE", "FREQUENCY_FACTOR", "HEAVE_AMPLITUDE_MAX",
           "START_OFFSET_WARN_S", "UNIT_MISTAKES", "check_air_density", "check_channels",
           "check_model", "check_release", "check_start", "force_scale", "start_offset"]

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]

#: Largest pitch amplitude (half the peak-to-peak about the mean) of a section model, rad.
#: Holds are 0.01-0.1 rad; 0.3 rad (17 degrees) is beyond any rig's, and a hold of 0.3
#: degrees or more left in degrees exceeds it.
ALPHA_AMPLITUDE_MAX = 0.3
#: Largest heave (and sway) amplitude of a section model, in deck widths B. Holds are a few
#: per cent of B; millimetres read as metres are hundreds of B.
HEAVE_AMPLITUDE_MAX = 0.5
#: How far below the section's lowest still-air frequency a record's Nyquist frequency may
#: lie (the wind moves a mode by tens of per cent; a time axis in ms is a factor 1000).
FREQUENCY_FACTOR = 3.0
#: Air densities of a wind tunnel, kg/m^3: from a high-altitude laboratory on a hot day
#: (about 0.7 at 3000 m) to a cold sea-level one (1.4), with margin.
AIR_DENSITY_RANGE = (0.5, 1.6)
#: How far a force may exceed the flat plate's largest ``|Q(iK)|`` times the motion. Bluff
#: decks' flutter derivatives and static slopes are a few times a plate's (a lift slope of
#: 6-15 per rad against 2 pi), so ten times is generous enough never to warn on a real deck.
FORCE_BOUND_FACTOR = 10.0
#: Force scale (measured over what the motion implies) further than this from 1 is warned
#: of. Correct simulated data give 1 within 0.3 %; a section's still-air damping known to
#: 0.1 % of critical moves the scale by about 1 % at the wind speeds of a campaign.
FORCE_SCALE_TOLERANCE = 0.05
#: A release instant this far (s) from where the decay starts from rest is warned of. The
#: backward extrapolation finds the start within 0.5 ms on 2 % noise; release_onset within
#: 0.1-1.5 ms (its module docstring).
START_OFFSET_WARN_S = 0.005
#: Shortest still hold (s) handed to :func:`~ident.records.release_onset.locate_release`.
MIN_HOLD_S = 0.2
#: The backward extrapolation is trusted only when the modal fit follows the displacements
#: to this many times their noise (the larger channel): a decay with friction or a cubic
#: spring is no sum of exponentials, and its extrapolation lands 3-10 ms off a right instant
#: (measured on the simulated campaigns' effects; their fits are 1.2-4 times the noise).
MODAL_FIT_EXCESS_MAX = 1.5
#: ... and only when both coordinates' velocities vanish together there: their rms, each over
#: its scale, below this (0.01-0.06 on 2 % noise for a late instant).
START_VELOCITY_MAX = 0.1
#: A common factor on the forces is named only when it explains the decays: the shifts'
#: misfit with it below this (0.001 on 2 % noise; friction or a delayed channel leave 0.2).
SCALE_EXPLAINS = 0.1
#: Misfit of the model's predicted shifts (as identified) above which the model is said not
#: to predict the decays (correct data 0.001-0.002; a 10 ms channel delay 0.2, friction 0.2).
MISFIT_WARN = 0.25


def _amplitude(x: FloatArray) -> float:
    """Half the 0.5-99.5 percentile range of a channel (robust to a few noise spikes)."""
    low, high = np.percentile(x, [0.5, 99.5])
    return float(high - low) / 2.0


def check_release(release: Release, section: SectionModel) -> list[str]:
    """Check one release's amplitudes and force magnitudes against the section's size.

    Parameters
    ----------
    release : Release
    section : SectionModel
        Its width ``B`` (m) and, where the release has none, air density (kg/m^3).

    Returns
    -------
    list of str
        Warnings, each naming the release and the likely mistake.

    Raises
    ------
    PlausibilityError
        A channel that reads one value in every sample ("a dead channel"), a record sampled too
        slowly for any mode (:data:`FREQUENCY_FACTOR`; "t looks like milliseconds"), a pitch
        amplitude over :data:`ALPHA_AMPLITUDE_MAX` ("alpha looks like degrees"), a heave or
        sway amplitude over :data:`HEAVE_AMPLITUDE_MAX` deck widths ("looks like millimetres").
    """
    check_channels(release)
    name = _name(release)
    _check_sampling(release, section, name)
    alpha = _amplitude(release.alpha)
    if alpha > ALPHA_AMPLITUDE_MAX:
        raise PlausibilityError(
            f"{name}: alpha looks like degrees: it oscillates by {alpha:.3g} rad "
            f"({math.degrees(alpha):.0f} degrees) about its mean, no section model's motion "
            f"(at most {ALPHA_AMPLITUDE_MAX:g} rad); convert the pitch to radians "
            f"(x pi/180: {math.radians(alpha):.3g} rad)")
    B = section.B
    for channel, values in (("h", release.h), ("p", release.p)):
        if values is None:
            continue
        amplitude = _amplitude(values)
        if amplitude > HEAVE_AMPLITUDE_MAX * B:
            raise PlausibilityError(
                f"{name}: {channel} looks like millimetres: it oscillates by {amplitude:.3g} m, "
                f"{amplitude / B:.3g} deck widths (B = {B:g} m; at most {HEAVE_AMPLITUDE_MAX:g} "
                f"B); convert it to metres (/1000: {amplitude / 1000:.3g} m)")
    return _force_magnitude(release, section)


def check_air_density(releases: Sequence[Release], section: SectionModel) -> list[str]:
    """Warn once of each air density (a release's, else the section's) that is not air's.

    Returns
    -------
    list of str
        One warning per distinct density outside :data:`AIR_DENSITY_RANGE`, naming where it
        came from and the likely unit.
    """
    sources: dict[float, str] = {}
    for release in releases:
        if release.rho is None:
            sources.setdefault(section.rho, "the section's")
        else:
            sources.setdefault(release.rho, f"{_name(release)}'s")
    low, high = AIR_DENSITY_RANGE
    warnings = []
    for rho, where in sources.items():
        if low <= rho <= high:
            continue
        if low <= rho / 1e3 <= high:
            unit = "g/m^3? (/1000)"
        elif low <= rho * 1e3 <= high:
            unit = "g/cm^3 or kg/l? (x1000)"
        else:
            unit = "a unit or a typing mistake?"
        warnings.append(
            f"{where} air density is {rho:g} kg/m^3, no wind tunnel's air ({low:g}-{high:g}): "
            f"{unit}; the flutter speed does not depend on it, but the flutter derivatives "
            "scale with its inverse, and so would a bridge's analysis from them")
    return warnings


#: Each channel of a release: its name and unit (the Release's fields).
_CHANNEL_UNITS = {"h": "m", "alpha": "rad", "p": "m", "lift": "N/m", "moment": "N m/m",
                 "drag": "N/m"}


def check_channels(release: Release, channels: Sequence[str] = tuple(_CHANNEL_UNITS)) -> None:
    """Raise PlausibilityError on a channel that reads the same value in every sample.

    ``channels`` names the release's fields to check (those absent from it are skipped): all by
    default; the displacement-only route checks the motion alone, since it reads no force.

    Not a threshold on a small spread: a real channel that barely moves (a force at a low wind
    speed, a sway that the wind hardly drives) still carries its noise, and what is too little
    to identify from is for the fits to say. One value throughout is no sensor's reading.
    """
    name = _name(release)
    for channel in channels:
        unit = _CHANNEL_UNITS[channel]
        values = getattr(release, channel)
        if values is not None and values.size > 1 and np.ptp(values) == 0.0:
            force = channel in ("lift", "moment", "drag")
            raise PlausibilityError(
                f"{name}: the {channel} channel reads {float(values[0]):.6g} {unit} in every "
                f"one of its {values.size} samples: a dead or disconnected sensor, or a column "
                "the import filled; fix the channel or leave this release out"
                + ("; without forces, the displacement-only route (windrig identify --route "
                   "displacement) reads the lasers alone" if force else ""))


def _check_sampling(release: Release, section: SectionModel, name: str) -> None:
    """Raise PlausibilityError when the record is sampled too slowly to hold any of the modes.

    Only that: where the displacements' spectra peak is no test of the section's frequencies,
    since large-scale turbulence puts most of the motion below the modes (gusts of 3 m on the
    0.3 m plate at Iw 10 %: the peak at 0.1 Hz, a third of the heave's power in the modes' band).
    """
    still_air = [f for f in (section.fh, section.fa, section.fp) if f is not None]
    nyquist = 0.5 * release.fs
    if nyquist * FREQUENCY_FACTOR >= min(still_air):
        return
    if nyquist * 1e3 >= min(still_air):
        why = ("t looks like milliseconds: give it in seconds (/1000; the record would then "
               f"be sampled at {release.fs * 1e3:.4g} Hz)")
    else:
        why = "the time axis's unit, or the section's frequencies, are not this record's"
    raise PlausibilityError(
        f"{name}: sampled at {release.fs:.4g} Hz, the record holds nothing above "
        f"{nyquist:.4g} Hz, but the section's still-air frequencies are "
        f"{', '.join(f'{f:g}' for f in still_air)} Hz: {why}")


def _force_magnitude(release: Release, section: SectionModel) -> list[str]:
    """Warn of a force far beyond what ``qd B`` and a generous ``|Q|`` allow the motion."""
    rho = section.rho if release.rho is None else release.rho
    B = section.B
    qd = 0.5 * rho * release.U**2
    q = release.coordinates(B)
    motion = float(np.sum(np.std(q, axis=0)))
    if motion == 0.0:
        return []
    frequencies = [section.fh, section.fa] + ([] if section.fp is None else [section.fp])
    K = np.array([2 * math.pi * f * B / release.U for f in frequencies])
    Q_plate = Q_from_flutter_derivatives(K, flat_plate.flutter_derivatives(K))
    bound = FORCE_BOUND_FACTOR * float(np.abs(Q_plate).max())
    forces = release.generalised_forces(B) / (qd * B**2)
    labels = ("lift", "moment", "drag")
    warnings = []
    for i in range(forces.shape[1]):
        ratio = float(np.std(forces[:, i])) / motion
        if ratio > bound:
            warnings.append(
                f"{_name(release)}: the {labels[i]} is {ratio / bound * FORCE_BOUND_FACTOR:.3g} "
                f"times what a section {B:g} m wide can draw from the wind at {release.U:.3g} "
                f"m/s for its motion (a flat plate's largest |Q(iK)| here is "
                f"{bound / FORCE_BOUND_FACTOR:.3g}, {FORCE_BOUND_FACTOR:g} times that allowed): "
                "a force total over the model's span, not per unit span (N/m), or a unit left "
                "unconverted?")
    return warnings


def _name(release: Release) -> str:
    return str(release.meta.get("name", f"release at {release.U:.3g} m/s"))


def start_offset(velocity: Callable[[FloatArray], FloatArray], scale: Sequence[float],
                 period: float, dt: float) -> tuple[float, float]:
    """Return the instant near ``t = 0`` where a decay's velocity vanishes in every coordinate, s.

    A release from rest has zero velocity in every coordinate at its instant; a given
    instant that is late shows the decay already moving at ``t = 0``.

    Parameters
    ----------
    velocity : callable
        ``velocity(t)`` of each coordinate at times ``t`` (s), shape (n, n_coordinates), e.g.
        a modal fit's first derivative (exact backwards as well: the same exponentials).
    scale : sequence of float
        Each coordinate's velocity scale (its amplitude times its circular frequency), so that
        the coordinates weigh alike.
    period : float
        Period of the fastest mode, s: the search spans a quarter of it either side of 0.
    dt : float
        Sampling interval, s: the grid is a tenth of it before a bounded refinement.

    Returns
    -------
    start : float
        The start, s relative to the given instant (negative: the given instant is late).
    velocity : float
        The rms over the coordinates of each one's velocity there over its scale: near 0 when
        they vanish together (a release from rest), not when the extrapolation is poor.
    """
    weights = 1.0 / np.asarray(scale, dtype=float)

    def cost(t: FloatArray) -> FloatArray:
        return np.asarray(np.sum((velocity(np.atleast_1d(t)) * weights) ** 2, axis=1))

    span = period / 4.0
    grid = np.arange(-span, span + dt / 20.0, dt / 10.0)
    costs = cost(grid)
    best = int(np.argmin(costs))
    low, high = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]
    n = len(weights)
    if high <= low:
        return float(grid[best]), math.sqrt(float(costs[best]) / n)
    found = minimize_scalar(lambda t: float(cost(np.array([t]))[0]), bounds=(low, high),
                            method="bounded", options={"xatol": 1e-6})
    return float(found.x), math.sqrt(float(found.fun) / n)


def check_start(release: Release, section: SectionModel,
                velocity: Callable[[FloatArray], FloatArray] | None,
                scale: Sequence[float], fit_excess: float = 1.0) -> list[str]:
    """Warn when the decay starts from rest more than :data:`START_OFFSET_WARN_S` off ``t = 0``.

    With a still hold of at least :data:`MIN_HOLD_S` before the release, the onset is found
    in the displacements by :func:`~ident.records.release_onset.locate_release`; otherwise
    (no hold, a hold too short or moving: a ``ReleaseNotFoundError``, which says the hold
    cannot tell) from ``velocity`` (:func:`start_offset`), when the modal fit is a good one
    (``fit_excess`` at most :data:`MODAL_FIT_EXCESS_MAX`) and the velocities vanish together
    (:data:`START_VELOCITY_MAX`); else nothing is said.

    Parameters
    ----------
    release : Release
    section : SectionModel
        Its frequencies set the search span.
    velocity : callable or None
        The decay's velocity of ``[h/B, alpha(, p/B)]`` (see :func:`start_offset`); None
        skips that route.
    scale : sequence of float
        Velocity scales of those coordinates.
    fit_excess : float
        The modal fit's residual rms over the displacements' noise (larger channel).

    Returns
    -------
    list of str
        One warning naming the offset in ms, or none.
    """
    f_max = max(section.fh, section.fa, section.fp or 0.0)
    offset: float | None = None
    how = ""
    hold = release.hold
    if hold is not None and hold.duration >= MIN_HOLD_S:
        t = np.concatenate([hold.t, release.t])
        try:
            onset = locate_release(t, np.concatenate([hold.h, release.h]),
                                   np.concatenate([hold.alpha, release.alpha]),
                                   before=float(t[-1]), f_max=f_max,
                                   min_hold_s=min(0.3, 0.8 * hold.duration))
        except ReleaseNotFoundError:
            onset = None  # the hold moves (turbulence) or is too short: the velocity decides
        if onset is not None and onset.reliable:
            offset, how = onset.time, "where the displacements leave the hold"
    if offset is None and velocity is not None and fit_excess <= MODAL_FIT_EXCESS_MAX:
        found, rest = start_offset(velocity, scale, 1.0 / f_max, release.dt)
        if rest <= START_VELOCITY_MAX:
            offset = found
            how = "where the decay's velocity vanishes, as a release from rest's does"
    if offset is None or abs(offset) <= START_OFFSET_WARN_S:
        return []
    late = "late" if offset < 0 else "early"
    return [f"{_name(release)}: the release instant looks {1e3 * abs(offset):.0f} ms {late}: "
            f"the decay starts at t = {1e3 * offset:+.1f} ms ({how}); the lag states start at "
            "zero at t = 0, so the model is fitted to a release that did not happen then: "
            "give the instant the model was let go"]


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


def _unit_mistake(section: SectionModel, model: RationalFunctionModel, speeds: Sequence[float],
                  measured: Sequence[ComplexArray]) -> tuple[str, str, float] | None:
    """Return ``(channel, unit, misfit)`` of the unit mistake that explains the decays, or None.

    A displacement read in a wrong unit scales its column of the identified ``Q`` by the unit's
    factor, not the decays' eigenvalues: the model with that column rescaled predicts them
    again, to within :data:`SCALE_EXPLAINS`. Amplitude checks catch such a channel when its
    holds are large; with small ones (a pitch of 0.2 degrees) only this does.
    """
    best: tuple[str, str, float] | None = None
    for column, name, unit, factor in UNIT_MISTAKES:
        A = np.array(model.A, dtype=float)
        A[:, :, column] /= factor
        misfit = _misfit(section, RationalFunctionModel(A, model.d), speeds, measured)
        if misfit < SCALE_EXPLAINS and (best is None or misfit < best[2]):
            best = (name, unit, misfit)
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
        warnings.append(
            f"the identified model does not predict the measured decays "
            f"({100 * as_identified:.0f} % off), but does once {unit[0]} is taken as "
            f"{unit[1]} ({100 * unit[2]:.2g} % off): {unit[0]} looks like {unit[1]} (small "
            f"holds pass the amplitude check); convert it, or the flutter speed is wrong")
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
