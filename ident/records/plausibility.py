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
- **Sampling** (:func:`check_release`, and :func:`check_units` on bare channels, which
  ``windrig import`` runs on every record it converts). A record whose Nyquist frequency lies
  below a :data:`FREQUENCY_FACTOR`-th of the section's lowest still-air frequency cannot hold
  a mode: refused, naming a time axis in milliseconds when the factor says so (unguarded: "no
  flutter", with warnings about the release instant). Where the displacements' spectra peak
  is not checked: large-scale turbulence puts the peak below the modes.
- **Amplitudes** (:func:`check_release` and :func:`check_units`, before identification). A
  pitch oscillating over more than :data:`ALPHA_AMPLITUDE_MAX` (0.3 rad, 17 degrees) about
  its mean is no section model's: a pitch in degrees (holds of 2-10 degrees read as radians)
  is refused. So is a heave amplitude over :data:`HEAVE_AMPLITUDE_MAX` of the deck width
  (millimetres read as metres), and a sway likewise.
- **Force magnitude** (:func:`check_release`). The rms force per unit span, over
  ``qd B`` (lift, drag) or ``qd B^2`` (moment), cannot exceed the rms of the motion ``q``
  times :data:`FORCE_BOUND_FACTOR` times the largest entry of a flat plate's ``|Q(iK)|`` at
  the release's reduced frequencies (bluff decks' derivatives are a few times a plate's, never
  ten times): a force in a wrong unit, or total over a long span, is warned of. A total force
  over a span near 1 m (0.9x) is far inside any such bound: the forces against the motion
  (:mod:`ident.records.decay_checks`) find it.
- **The wind speed's unit** (:func:`reduced_velocity_warnings`, after identification). The
  identification is self-similar in the speed's unit: speeds all a factor off give a flutter
  speed that factor off, with no misfit. A flutter point beyond a reduced velocity ``U / (f B)``
  of :data:`UNUSUAL_REDUCED_VELOCITY` for the faster mode (decks' lie at about 5-15; the
  plate here 9.8, in mph 22) is warned of, naming km/h and mph.
- **Release instant** (:func:`check_start`). A release from rest starts with zero velocity in
  every coordinate. The instant where the decay's velocity vanishes, found from the modal
  fit extrapolated backwards (:func:`start_offset`) or, with a still hold before the release,
  by :func:`ident.records.release_onset.locate_release`, more than
  :data:`START_OFFSET_WARN_S` from the given instant is a warning that names the offset
  (a 30 ms late instant: found at -29.9 to -30.3 ms). The extrapolation is used only where the
  modal fit follows the displacements to their noise (friction or a cubic spring bend the
  decay away from exponentials and its zero 3-10 ms away from a right instant).

Not responsible for: the shapes, finiteness and sampling of a release
(:mod:`ident.records.release`), the section and the identified model against the measured
decays (:mod:`ident.records.decay_checks`), fitting anything (:mod:`ident.identification`).
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
from ident.model.section import SectionModel
from ident.records.release import Release
from ident.records.release_onset import locate_release

__all__ = ["AIR_DENSITY_RANGE", "ALPHA_AMPLITUDE_MAX", "FORCE_BOUND_FACTOR", "FREQUENCY_FACTOR",
           "HEAVE_AMPLITUDE_MAX", "START_OFFSET_WARN_S", "UNUSUAL_REDUCED_VELOCITY",
           "check_air_density", "check_channels", "check_release", "check_start", "check_units",
           "reduced_velocity_warnings", "start_offset"]

FloatArray = npt.NDArray[np.float64]

#: Reduced velocity ``U / (f B)`` (the faster of heave and pitch) beyond the flutter point of
#: most decks (full bridges' are about 5-15) and of the section models built for them.
UNUSUAL_REDUCED_VELOCITY = 15.0
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


def _amplitude(x: FloatArray) -> float:
    """Half the 0.5-99.5 percentile range of a channel (robust to a few noise spikes; gaps out).

    A channel of gaps only has no amplitude to judge: zero.
    """
    if not np.any(np.isfinite(x)):
        return 0.0
    low, high = np.nanpercentile(x, [0.5, 99.5])
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
    check_units(_name(release), release.fs, release.h, release.alpha, release.p, section)
    return _force_magnitude(release, section)


def check_units(name: str, fs: float, h: FloatArray, alpha: FloatArray, p: FloatArray | None,
                section: SectionModel) -> None:
    """Refuse a record whose time, pitch or heave unit no section model's motion allows.

    The sampling, amplitude and unit part of :func:`check_release`, on bare channels, so that
    a conversion (``windrig import``'s map) can run it before a release exists. Gaps (NaN) are
    left out of the amplitudes.

    Parameters
    ----------
    name : str
        The record, for the messages.
    fs : float
        Sampling rate, Hz.
    h, alpha : ndarray
        Heave (m) and pitch (rad).
    p : ndarray or None
        Sway (m), if the section has it.
    section : SectionModel
        Its width ``B`` (m) and still-air frequencies (Hz).

    Raises
    ------
    PlausibilityError
        A record sampled too slowly for any mode (:data:`FREQUENCY_FACTOR`; "t looks like
        milliseconds"), a pitch amplitude over :data:`ALPHA_AMPLITUDE_MAX` ("alpha looks like
        degrees"), a heave or sway amplitude over :data:`HEAVE_AMPLITUDE_MAX` deck widths
        ("looks like millimetres").
    """
    _check_sampling(fs, section, name)
    alpha_amplitude = _amplitude(alpha)
    if alpha_amplitude > ALPHA_AMPLITUDE_MAX:
        raise PlausibilityError(
            f"{name}: alpha looks like degrees: it oscillates by {alpha_amplitude:.3g} rad "
            f"({math.degrees(alpha_amplitude):.0f} degrees) about its mean, no section model's "
            f"motion (at most {ALPHA_AMPLITUDE_MAX:g} rad); convert the pitch to radians "
            f"(x pi/180: {math.radians(alpha_amplitude):.3g} rad)")
    B = section.B
    for channel, values in (("h", h), ("p", p)):
        if values is None:
            continue
        amplitude = _amplitude(values)
        if amplitude > HEAVE_AMPLITUDE_MAX * B:
            raise PlausibilityError(
                f"{name}: {channel} looks like millimetres: it oscillates by {amplitude:.3g} m, "
                f"{amplitude / B:.3g} deck widths (B = {B:g} m; at most {HEAVE_AMPLITUDE_MAX:g} "
                f"B); convert it to metres (/1000: {amplitude / 1000:.3g} m)")


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


def _check_sampling(fs: float, section: SectionModel, name: str) -> None:
    """Raise PlausibilityError when the record is sampled too slowly to hold any of the modes.

    Only that: where the displacements' spectra peak is no test of the section's frequencies,
    since large-scale turbulence puts most of the motion below the modes (gusts of 3 m on the
    0.3 m plate at Iw 10 %: the peak at 0.1 Hz, a third of the heave's power in the modes' band).
    """
    still_air = [f for f in (section.fh, section.fa, section.fp) if f is not None]
    nyquist = 0.5 * fs
    if nyquist * FREQUENCY_FACTOR >= min(still_air):
        return
    if nyquist * 1e3 >= min(still_air):
        why = ("t looks like milliseconds: give it in seconds (/1000; the record would then "
               f"be sampled at {fs * 1e3:.4g} Hz)")
    else:
        why = "the time axis's unit, or the section's frequencies, are not this record's"
    raise PlausibilityError(
        f"{name}: sampled at {fs:.4g} Hz, the record holds nothing above "
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


def reduced_velocity_warnings(section: SectionModel, speed: float) -> tuple[str, ...]:
    """Warn of a flutter speed whose reduced velocity no deck's flutter point has.

    Identification is self-similar in the wind speed's unit: releases whose speeds are all a
    factor off (km/h, mph read as m/s) identify a model that flutters at the same factor times
    the truth, with no misfit to show for it (the flat plate of the tests at 11.75 m/s, its
    speeds in mph: 26.3 m/s, warned only of an extrapolation). The flutter point's reduced
    velocity is what betrays it.

    Parameters
    ----------
    section : SectionModel
        Its width ``B`` (m) and still-air frequencies (Hz).
    speed : float
        The flutter speed, m/s.

    Returns
    -------
    tuple of str
        One warning when ``speed / (f B)``, ``f`` the faster of heave and pitch, exceeds
        :data:`UNUSUAL_REDUCED_VELOCITY`, naming km/h and mph; else none.
    """
    f_fast = max(section.fh, section.fa)
    reduced_velocity = speed / (f_fast * section.B)
    if reduced_velocity <= UNUSUAL_REDUCED_VELOCITY:
        return ()
    return (f"the flutter speed {speed:.3g} m/s is a reduced velocity U / (f B) of "
            f"{reduced_velocity:.3g} for the {f_fast:g} Hz mode, beyond most decks' flutter "
            f"point (5 to {UNUSUAL_REDUCED_VELOCITY:g}): if the wind speeds are in km/h or mph, "
            "convert them to m/s (/3.6, /2.237) and identify again; the flutter speed scales "
            "with their unit",)
