"""The adaptive choice of the next wind speed (c-optimal), and the safety bound.

Responsibility: :func:`choose_next` picks, among candidate wind speeds, the one whose releases
are predicted to reduce the flutter speed's standard deviation most; :func:`safety_bound` is
the highest speed a campaign may set given what it has learnt so far.

The prediction (c-optimal design: the criterion is the variance of one function of the
parameters, the flutter speed ``U_F(theta)``): E2RFC's parameters ``theta`` (the ``A`` entries and
``log d``) have the covariance ``C`` of :class:`ident.identification.results.E2RFCDiagnostics`, and
``U_F`` the gradient ``g = dU_F/dtheta`` (:func:`ident.model.flutter.speed_sensitivity`), so that
``var(U_F) = g^T C g`` (how :mod:`ident.identification.e2rfc` computes its noise part). ``n`` more
releases at a candidate speed ``U_c`` add the information ``n J_c^T J_c``, where ``J_c`` is the
weighted Jacobian of E2RFC's force residuals for the release the identified model predicts there:
its decay simulated from the campaign's hold position
(:func:`ident.simulation.decay.simulate_decay`), the regressors ``q, (B/U) q', (B/U)^2 q'', x_l`` of
``docs/reference/conventions.md`` computed from it, each force row weighted by ``qd B^2 / sigma``
(the force noise ``sigma``, N/m and N m/m, measured on the recorded releases and taken as
independent of U: the scanner's). The same construction for the recorded releases gives ``I_0 =
sum_r J_r^T J_r``; its prediction of today's variance is scaled to the identified one (``kappa``),
so only ratios of information matter::

    var_new(U_c) = kappa g^T (I_0 + n J_c^T J_c)^+ g,  kappa = sigma_param^2 / (g^T I_0^+ g)

The one-lag-more part (how far a fit with one lag more moves the flutter speed) is that finer
fit's noise: it shrinks with information as the statistical part does (seen on the flat plate:
0.37, 0.11, 0.06, 0.02 m/s over four repeats of the top speed) and is scaled by the same ratio.
The structure part (the spread of the structures the data cannot tell apart) and the
extrapolation part (how far the flutter speed moves when the top speed's releases are left
out, :mod:`ident.identification.e2rfc`) are carried into the prediction unchanged: more releases at
the top speed leave the reduced fit as it is (a campaign whose prediction let them shrink the
extrapolation part repeated its top speed four times, each time expecting the std to halve,
and stayed at 3.4 %), and releases below the top speed may move the reduced fit, but by how
much and which way the data cannot tell beforehand, so no gain is counted on. Only a
candidate above the top speed changes the extrapolation part: it covers reduced frequencies
closer to the flutter one, and the part is scaled by ``log(K_c / K_F) / log(K_min / K_F)``
(clipped to [0, 1]; ``K_c = B omega(U_c) / U_c`` of the critical branch from the identified
model, ``K_min`` the lowest covered now). So the choice prefers speeds closer to flutter
(within the safety bound).

The candidate with the smallest predicted total is chosen (ranked by the predicted parts that
differ between candidates, so that a large carried part does not drown the differences), none
when no candidate below the bound is predicted to reduce those parts (statistical,
one-lag-more, extrapolation) by :data:`MIN_GAIN`, unless the best is predicted to meet the
campaign's target (a campaign at 1.002 % once stopped there, its best candidate predicting
0.97 %: a gain of 2.5 % was all it lacked). The part below a decaying release (turbulent
flow, :mod:`ident.identification.e2rfc`) is carried too: it is a bias the releases share. The
structure part, carried in the predicted
total, does not stop a campaign by itself: no gain is promised for it, but new data may tell
the structures apart (on the plate a third speed took it from 0.24 to 0.006 m/s; on the deck
one took the std to 44 %, a structure without flutter below the search limit).
Before :data:`MIN_SPEEDS` distinct wind speeds there is no stop for want of gain: the std of
two speeds lacks its extrapolation part (E2RFC needs a third speed to measure it), and a new
speed does tell structures apart, which the carried parts do not count on; the best candidate
at a speed not yet covered is chosen, and among candidates whose predicted totals lie within
:data:`TIE_RTOL` of the best (a wide structure part makes them all alike) the highest.

Releases per speed (optional, ``release_options``): the choice is then over pairs (speed,
number of releases ``n``), each costing the wind-on time ``overhead_s + n per_release_s`` (the
settling and the analysis between speeds, then each release's hold, decay and pause). The
pair with the largest predicted reduction of the reducible variance per wind-on second is
chosen among those that gain (the stop for want of gain judges each speed at its most
releases, so offering fewer never stops a campaign sooner). Few releases at a new top speed
buy its extrapolation gain cheaply; many pay off where the overhead of a speed is large
against a release. Without options every speed gets ``releases_per_speed``, as before.

Safety: :func:`safety_bound` is ``fraction * (U_F - 3 std)`` of the current estimate; without
one (the first speeds, or an E2RFC that gave no flutter speed) ``fraction`` times the still-air
prediction, the flutter speed of a flat plate of the section's structure
(:func:`still_air_flutter_speed`); the runner also applies the rig's limits.

Not responsible for: recording (:mod:`daq.campaign.runner`) or the identification itself
(:mod:`ident.identification.e2rfc`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.signal import lfilter

from ident.identification.campaign import CampaignAnalysis
from ident.identification.modal import noise_std
from ident.identification.results import DISTINCT_U_RTOL, IdentifiedModel, distinct_wind_speeds
from ident.identification.uncertainty import FlutterUncertainty
from ident.model import flutter
from ident.model.section import SectionModel
from ident.records.release import Release
from ident.simulation.decay import simulate_decay

__all__ = ["MIN_GAIN", "MIN_SPEEDS", "TIE_RTOL", "Choice", "choose_next", "predicted_std",
           "safety_bound", "still_air_flutter_speed"]

FloatArray = npt.NDArray[np.float64]

#: A candidate must be predicted to reduce the standard deviation by this fraction to be chosen.
MIN_GAIN = 0.05
#: Predicted totals within this fraction of the best are a tie, broken towards the highest speed.
TIE_RTOL = 0.005
#: Distinct wind speeds before a campaign's std is complete (extrapolation part measured): the
#: target counts from here on, and before it a new speed is always chosen.
MIN_SPEEDS = 3
#: Sampling rate of the predicted releases, Hz: ~50 samples per period of a 4 Hz mode; only
#: ratios of information matter, so the rate need not be the recorder's.
PREDICT_FS = 200.0


@dataclass(frozen=True)
class Choice:
    """One adaptive decision.

    Attributes
    ----------
    speed : float or None
        The next wind speed, m/s (None: stop).
    reason : str
        Why (also the stop reason).
    current_std : float
        The flutter speed's standard deviation now, m/s.
    predicted : tuple of (float, float)
        ``(U_c, predicted std)`` of each candidate below the bound, m/s.
    bound : float
        The safety bound applied, m/s.
    releases : int or None
        Releases to record at ``speed`` (None: the plan's ``releases_per_speed``).
    """

    speed: float | None
    reason: str
    current_std: float
    predicted: tuple[tuple[float, float], ...]
    bound: float
    releases: int | None = None

    def summary(self) -> str:
        """One line per decision, with the candidates' predictions."""
        table = ", ".join(f"{u:.2f}: {s:.3f}" for u, s in self.predicted)
        return (f"adaptive: {self.reason} [now {self.current_std:.3f} m/s; predicted std at "
                f"candidates <= {self.bound:.2f} m/s: {table or 'none'}]")


def safety_bound(analysis: CampaignAnalysis | None, fraction: float, held: float = 0.0,
                 prior: float | None = None) -> float:
    """Highest wind speed allowed now, m/s.

    ``fraction * (U_F - 3 std)`` of the current estimate; without one, ``fraction * prior``
    (inf without a prior either), but never below ``held``: the highest speed at which releases
    were just seen to decay, which the wind may always go back to however wide the estimate's
    std (a std near U_F / 3 puts the estimate's own bound at zero, below speeds the model has
    just shown to be stable).

    Parameters
    ----------
    analysis : CampaignAnalysis or None
        The current E2RFC estimate.
    fraction : float
        Safety fraction, (0, 1].
    held : float
        Highest wind speed held with decaying releases so far, m/s (0: none).
    prior : float or None
        The still-air prediction of the flutter speed, m/s (:func:`still_air_flutter_speed`),
        the bound before anything is measured; None: none.
    """
    if analysis is None or analysis.flutter_speed is None or analysis.flutter_std is None:
        return math.inf if prior is None else max(fraction * prior, held)
    std = analysis.flutter_std if math.isfinite(analysis.flutter_std) else analysis.flutter_speed
    return max(fraction * (analysis.flutter_speed - 3.0 * std), 0.0, held)


@functools.lru_cache(maxsize=8)
def still_air_flutter_speed(section: SectionModel) -> float | None:
    """Flutter speed a thin flat plate of the section's structure would have, m/s.

    The prior before anything is measured: Theodorsen's plate (R.T. Jones's Roger form,
    :func:`ident.model.flat_plate.jones_model`) on the section's still-air masses,
    frequencies, damping and air density, in heave and pitch (a lateral spring is left out:
    the plate has no drag terms). Bridge decks mostly flutter below it, bluff ones well below
    (some slotted twin boxes above), so it bounds only the speeds a campaign sets blind; once
    E2RFC has an estimate, that bounds the speeds instead, and a growing decay is caught
    whatever the bound.

    Parameters
    ----------
    section : SectionModel
        The rig's section model (still-air structure, SI units).

    Returns
    -------
    float or None
        The flat plate's flutter speed, m/s; None when it has none below the flutter search's
        ceiling (:func:`ident.model.flutter.default_U_max`).
    """
    from ident.model.flat_plate import jones_model  # the prior's model only

    speed = flutter.analyze(section.planar(), jones_model()).speed
    return None if speed is None else float(speed)


def _gradient(model: IdentifiedModel, section: SectionModel, result: flutter.FlutterResult
              ) -> FloatArray:
    """``dU_F/dtheta`` in the covariance's parameter order (as E2RFC builds it)."""
    assert result.speed is not None and result.frequency is not None
    dU_dA, dU_dd = flutter.speed_sensitivity(section, model, result.speed, result.frequency)
    index = model.diagnostics.parameter_index
    return np.array([dU_dA[k, i, j] for k, i, j in index] + list(dU_dd * model.d))


def _lag_states(qdot: FloatArray, rate: float, d: float, dt: float) -> FloatArray:
    """``x' = q' - rate d x`` from ``x(0) = 0``, exact for ``q'`` held over each step."""
    a = rate * d
    decay = math.exp(-a * dt)
    gain = (1.0 - decay) / a
    # x[k] = decay x[k-1] + gain q'[k-1]: a first-order recursion, as a filter.
    return np.asarray(lfilter([0.0, gain], [1.0, -decay], qdot, axis=0), dtype=float)


def _information(model: IdentifiedModel, section: SectionModel, U: float, h0: float,
                 alpha0: float, duration_s: float, sigma: FloatArray) -> FloatArray:
    """``J^T J`` of one predicted release at ``U`` (module docstring), parameter order of C."""
    n = max(int(duration_s * PREDICT_FS), 64)
    decay = simulate_decay(section, model, U, h0, alpha0, n=n, fs=PREDICT_FS)
    B, dt = section.B, 1.0 / PREDICT_FS
    q = np.column_stack([decay.h / B, decay.alpha])
    qdot = np.gradient(q, dt, axis=0)
    qddot = np.gradient(qdot, dt, axis=0)
    c = B / U
    regressors = {0: q, 1: c * qdot, 2: c**2 * qddot}
    rate = U / B
    lags = [_lag_states(qdot, rate, float(d), dt) for d in model.d]
    for l, x in enumerate(lags):
        regressors[3 + l] = x
    qd = 0.5 * section.rho * U**2
    weights = qd * B**2 / sigma  # normalised force noise sigma / (qd B^2), inverted
    index = model.diagnostics.parameter_index
    columns = []
    for k, i, j in index:
        col = np.zeros(2 * n)
        col[i * n:(i + 1) * n] = weights[i] * (regressors[k][:, j] - regressors[k][:, j].mean())
        columns.append(col)
    h = 1e-4
    for l, d in enumerate(model.d):
        dx = (_lag_states(qdot, rate, float(d) * math.exp(h), dt)
              - _lag_states(qdot, rate, float(d) * math.exp(-h), dt)) / (2 * h)
        col = np.zeros(2 * n)
        for i in range(2):
            v = dx @ model.A[3 + l, i, :]
            col[i * n:(i + 1) * n] = weights[i] * (v - v.mean())
        columns.append(col)
    J = np.column_stack(columns)
    return np.asarray(J.T @ J, dtype=float)


def _noise(releases: Sequence[Release], section: SectionModel) -> FloatArray:
    """Force noise of the recorded releases, ``[L B, M]``, N m/m (median over releases)."""
    levels = [noise_std(np.column_stack([r.lift * section.B, r.moment])) for r in releases]
    return np.maximum(np.median(np.array(levels), axis=0), 1e-12)


def _hold(releases: Sequence[Release]) -> tuple[float, float]:
    """Return the campaign's hold position (median release start), m and rad."""
    return (float(np.median([r.h[0] for r in releases])),
            float(np.median([r.alpha[0] for r in releases])))


def _variance(g: FloatArray, information: FloatArray) -> float:
    """``g^T I^+ g``: the variance of ``U_F`` up to the common scale ``kappa``."""
    return float(g @ np.linalg.pinv(information) @ g)


def _ratio(new: float, old: float) -> float:
    """Standard-deviation ratio ``sqrt(new / old)``, 1 when it cannot be told."""
    if not (math.isfinite(new) and math.isfinite(old)) or old <= 0 or new < 0:
        return 1.0
    return min(math.sqrt(new / old), 1.0)


def _branch_K(result: flutter.FlutterResult, U: float, B: float) -> float:
    """Reduced frequency of the critical branch at ``U`` (identified model's curves)."""
    column = result.mode_names.index(result.critical_mode or result.mode_names[-1])
    f = float(np.interp(U, result.U, result.frequencies[:, column]))
    return B * 2.0 * math.pi * f / U if f > 0 else math.nan


def predicted_std(analysis: CampaignAnalysis, releases: Sequence[Release],
                  candidates: Sequence[float], *, releases_per_speed: int, decay_s: float,
                  ) -> list[float]:
    """Predicted total std of the flutter speed after releases at each candidate, m/s.

    Parameters
    ----------
    analysis : CampaignAnalysis
        The campaign so far (it must predict flutter).
    releases : sequence of Release
        Its recorded releases (hold position, force noise, information so far).
    candidates : sequence of float
        Wind speeds, m/s.
    releases_per_speed : int
        Releases the next speed would record.
    decay_s : float
        Their length, s.

    Returns
    -------
    list of float
        One per candidate, m/s (module docstring for the formula).
    """
    result, u = analysis.flutter, analysis.uncertainty
    if result.speed is None or not math.isfinite(u.total):
        raise ValueError("predicted_std needs an analysis that predicts flutter")
    carried = _carried(u)
    return [math.sqrt(carried**2 + v) for v in _reducible(analysis, releases, candidates,
                                                          releases_per_speed, decay_s)]


def _carried(u: FlutterUncertainty) -> float:
    """Return the parts carried unchanged into every prediction, m/s.

    The structure spread, the distance below a decaying release (a bias of the fit in
    turbulence that more releases at the same speeds share, :mod:`ident.identification.e2rfc`)
    and the distance to the other estimator's flutter speed (a misfit that more releases
    share).
    """
    return math.sqrt(u.structure**2 + u.below_decay**2 + u.cross_check**2)


def _reducible(analysis: CampaignAnalysis, releases: Sequence[Release],
               candidates: Sequence[float], releases_per_speed: int, decay_s: float
               ) -> list[float]:
    """Predicted variance of the parts that differ between candidates, m^2/s^2.

    The statistical and one-lag-more parts (scaled by the information ratio) and the
    extrapolation part (by the reduced frequencies a speed above the top one adds); the
    structure part, the same for all, is left out (module docstring).
    """
    result, u = analysis.flutter, analysis.uncertainty
    section, model = analysis.section, analysis.model
    g = _gradient(model, section, result)
    sigma = _noise(releases, section)
    h0, alpha0 = _hold(releases)
    infos = [_information(model, section, r.U, h0, alpha0, float(r.t[-1] - r.t[0]), sigma)
             for r in releases]
    I0 = np.sum(infos, axis=0)
    now = _variance(g, I0)
    top = max(distinct_wind_speeds([r.U for r in releases]))
    K_min = min(_branch_K(result, r.U, section.B) for r in releases)
    out = []
    for U in candidates:
        Ic = releases_per_speed * _information(model, section, U, h0, alpha0, decay_s, sigma)
        ratio = _ratio(_variance(g, I0 + Ic), now)
        out.append((ratio * u.statistical)**2 + (ratio * u.refinement)**2
                   + (_reach(result, U, top, K_min, section.B) * u.extrapolation)**2)
    return out


def _reach(result: flutter.FlutterResult, U: float, top: float, K_min: float, B: float
           ) -> float:
    """Factor on the extrapolation part after releases at ``U`` (module docstring), in [0, 1].

    1 unless ``U`` is a wind speed above the top one (a repeat of the top speed, or a speed
    below it, leaves the reduced fit without the top speed as it is).
    """
    K_F = result.reduced_frequency
    if U <= top * (1 + DISTINCT_U_RTOL) or K_F is None or not math.isfinite(K_min) \
            or K_min <= K_F:
        return 1.0
    K_new = min(K_min, _branch_K(result, U, B))
    if not math.isfinite(K_new):
        return 1.0
    return min(max(math.log(K_new / K_F) / math.log(K_min / K_F), 0.0), 1.0)


def choose_next(analysis: CampaignAnalysis, releases: Sequence[Release],
                candidates: Sequence[float], *, bound: float, releases_per_speed: int,
                decay_s: float, release_options: Sequence[int] = (),
                overhead_s: float = 0.0, per_release_s: float | None = None,
                target: float | None = None) -> Choice:
    """Choose the next wind speed, or decide to stop (module docstring).

    Parameters
    ----------
    analysis : CampaignAnalysis
    releases : sequence of Release
        The campaign's recorded releases.
    candidates : sequence of float
        Candidate wind speeds, m/s (those above ``bound`` are never chosen).
    bound : float
        The safety bound, m/s (:func:`safety_bound` and the rig's limits).
    releases_per_speed : int
    decay_s : float
    release_options : sequence of int, optional
        Numbers of releases to choose among at the next speed (empty: ``releases_per_speed``).
    overhead_s : float
        Wind-on time a speed costs besides its releases, s (with ``release_options``).
    per_release_s : float, optional
        Wind-on time of one release, s (default ``decay_s``).
    target : float, optional
        The campaign's target std, m/s: a candidate predicted to meet it is chosen even when it
        gains less than :data:`MIN_GAIN`.

    Returns
    -------
    Choice
    """
    if analysis.flutter_speed is None or analysis.flutter_std is None \
            or not math.isfinite(analysis.flutter_std):
        return Choice(None, "stopped: the releases so far predict no flutter speed (nothing "
                      "to aim at: extend the candidate range or check the rig)", math.nan, (),
                      bound)
    current = analysis.flutter_std
    allowed = [float(U) for U in candidates if U <= bound]
    if not allowed:
        return Choice(None, f"stopped: no candidate speed below the safety bound {bound:.2f} "
                      "m/s", current, (), bound)
    options = sorted({int(n) for n in release_options}) or [releases_per_speed]
    # Ranked by the parts that differ between candidates: a large carried structure part
    # would round their differences away in the totals.
    by_n = {n: _reducible(analysis, releases, allowed, n, decay_s) for n in options}
    most = by_n[options[-1]]
    carried = _carried(analysis.uncertainty)
    u = analysis.uncertainty
    reducible_now = u.statistical**2 + u.refinement**2 + u.extrapolation**2
    cost = {n: overhead_s + n * (decay_s if per_release_s is None else per_release_s)
            for n in options}

    def rate(i: int, n: int) -> float:
        """Predicted reducible variance removed per wind-on second, m^2/s^3."""
        return (reducible_now - by_n[n][i]) / max(cost[n], 1e-9)

    # Each speed's number of releases: the one of the best rate there (one option: that one).
    n_at = [max(options, key=functools.partial(rate, i)) for i in range(len(allowed))]
    reducible = [by_n[n][i] for i, n in enumerate(n_at)]
    table = tuple((U, math.sqrt(carried**2 + v)) for U, v in zip(allowed, reducible,
                                                                 strict=True))
    several = len(options) > 1

    def said(i: int) -> str:
        return f" with {n_at[i]} release(s)" if several else ""

    covered = distinct_wind_speeds([r.U for r in releases])
    new = [i for i, U in enumerate(allowed)
           if all(abs(U - c) > DISTINCT_U_RTOL * c for c in covered)]
    if len(covered) < MIN_SPEEDS and new:
        i_new = (max(new, key=lambda i: rate(i, n_at[i])) if several
                 else min(new, key=lambda i: reducible[i]))
        # Candidates that promise the same total (a large carried structure part can make every
        # prediction alike): the highest of them, whose forces (~U^2) stand out most from the
        # same noise, rather than whichever the rounding favours (a deck campaign once chose
        # 0.4 U_F this way, and needed a fourth speed).
        tied = [i for i in new if table[i][1] <= (1.0 + TIE_RTOL) * table[i_new][1]
                and n_at[i] <= n_at[i_new]]
        i_new = max(tied, key=lambda i: allowed[i])
        best_U, best = table[i_new]
        return Choice(best_U, f"chosen {best_U:.2f} m/s{said(i_new)}: a new speed "
                      f"({len(covered)} so far, {MIN_SPEEDS} needed), predicted std {best:.3f} "
                      f"m/s (now {current:.3f} m/s)", current, table, bound,
                      n_at[i_new] if several else None)
    # The stop for want of gain: judged at each speed's most releases.
    i_most = int(np.argmin(most))
    best_most = math.sqrt(carried**2 + most[i_most])
    small_gain = math.sqrt(most[i_most]) > (1.0 - MIN_GAIN) * math.sqrt(reducible_now)
    if small_gain and not (target is not None and best_most <= target < current):
        best_U, best = allowed[i_most], best_most
        return Choice(None, f"stopped: no candidate gains (best {best_U:.2f} m/s predicts "
                      f"{best:.3f} m/s against {current:.3f} m/s now)", current, table, bound)
    i_best = i_most
    if several:  # the best rate among the speeds that gain at their chosen number
        gaining = [i for i in range(len(allowed))
                   if math.sqrt(reducible[i]) <= (1.0 - MIN_GAIN) * math.sqrt(reducible_now)]
        if gaining:
            i_best = max(gaining, key=lambda i: rate(i, n_at[i]))
        else:  # only the most releases gain: take them where they gain most
            n_at[i_most] = options[-1]
    best_U, best = allowed[i_best], math.sqrt(carried**2 + by_n[n_at[i_best]][i_best])
    why = f", less than {100 * MIN_GAIN:g} % but the target" if small_gain else ""
    return Choice(best_U, f"chosen {best_U:.2f} m/s{said(i_best)}: predicted std {best:.3f} "
                  f"m/s (now {current:.3f} m/s{why})", current, table, bound,
                  n_at[i_best] if several else None)
