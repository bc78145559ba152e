"""PLAN.toml: what a headless campaign does, parsed and checked before anything moves.

Responsibility: :func:`load_plan` / :func:`parse_plan` read a campaign plan into a frozen
:class:`CampaignPlan`, and :meth:`CampaignPlan.check_against` checks it against a rig config's
safety limits. Every error is a :class:`~daq.errors.ConfigError` naming the table, the key and
what is allowed, so an operator can fix the plan before the fan starts.

The plan (units SI; the example plans are ``rig_configs/plans/*.toml``)::

    [campaign]
    mode = "fixed"              # "fixed": every listed speed; "adaptive": see [adaptive]
    releases_per_speed = 2      # 1..20
    decay_s = 5.0               # recorded decay per release, s (default: 15 slow periods)
    decay_end = "fixed"         # "settled": end a release's recording once its decay is
                                # down to 20 % (decay_s the longest), daq.campaign.monitor
    settle_s = 1.0              # the wind must stay steady this long before the first release
    steady_tolerance = 0.01     # steady: fan speed within this fraction of its set-point
    pause_s = 0.0               # extra wait between releases, s
    hold_s = 0.5                # held in the wind between arming and releasing, s; in
                                # turbulence 11: E2RFC's turbulence branch takes its noise
                                # model from >= 10 s of each hold
                                # (docs/development/e2rfc_turbulence.md)
    calz_start = true           # zero the scanner wind-off before the first speed
    calz_end = true             # ... and once more wind-off after the fan is down
    files = "per_speed"         # one run file per speed; "per_release": one per release
    release = "auto"            # "plc": the PLC's magnet; "manual": by hand, the operator
                                # prompted on the terminal between releases (the instant
                                # found in the lasers' signals); "auto": the PLC if the rig
                                # has one, else by hand
    identification = "e2rfc"    # "e2rfc" (the taps' forces); "displacement": the
                                # displacement-only route, for a rig without taps (fixed
                                # mode, 3 or more speeds; `windrig identify` after the
                                # campaign, with its caveats)
    turbulent_estimator = "ml"  # releases in turbulence: "ml" (closed-loop maximum
                                # likelihood; holds optional; 2-DOF, a 3-DOF section runs
                                # "iv") or "iv" (refined IV, needs the holds)
    closed_loop_buffeting = "by-evidence"  # the "ml" estimator's buffeting model: the
                                # fourth-order one where the second-order one's innovations
                                # pooled over the records are not white, else the second;
                                # or either alone ("second-order", "fourth-order"); each
                                # one filter for all speeds, scaled with the speed, or
                                # "-per-speed" (turbulence changed between speeds)

    [speeds]
    wind_speeds = [5.0, 7.0]    # m/s; or fan_rpm = [500, 700] (set-points, rpm), not both

    [adaptive]                  # mode = "adaptive" only
    target_std = 0.01           # stop when std(U_F) / U_F <= this
    safety_fraction = 0.9       # never above safety_fraction * (U_F - 3 std)
    candidate_min = 4.0         # candidate wind speeds, m/s: min..max every candidate_step
    candidate_max = 11.0
    candidate_step = 0.5
    max_speeds = 6              # at most this many speeds in all (>= the listed ones)
    max_releases_per_speed = 4  # optional: each chosen speed gets 1..4 releases, as many as
                                # the predicted gain per wind-on second says (default: the
                                # plan's releases_per_speed at every speed)

In adaptive mode the listed speeds are the first ones (two at least: E2RFC needs two wind
speeds before it says anything); the next are chosen by :mod:`daq.campaign.adaptive`.

Before the fan turns (:meth:`CampaignPlan.check_against`): the listed speeds and the adaptive
candidates within the rig's limits, and the speeds set before any E2RFC estimate
(:meth:`CampaignPlan.blind_speeds`) below the safety fraction of the still-air prediction
(:func:`daq.campaign.adaptive.still_air_flutter_speed`); (:meth:`CampaignPlan.check_rig`) the
rig must be able to release (a PLC, or releases by hand, which need lasers) and to identify (a
pressure scanner for E2RFC, or the displacement-only route named); anything else is refused in
one line. :meth:`CampaignPlan.defaults_taken` names the defaults the plan took, which the
runner says before it starts.

Not supported: a hold displacement per release. The release PLC of these rigs switches a
magnet on and off; the hold position is set by the rig's mechanics (on a simulated rig by
``[simulation] hold_h, hold_alpha``), so a plan cannot change it and does not pretend to.

Not responsible for: running the plan (:mod:`daq.campaign.runner`) or choosing speeds
(:mod:`daq.campaign.adaptive`).
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from daq.config import RigConfig
from daq.errors import ConfigError
from daq.procedure import HOLD_S, MIN_DECAY_PERIODS, default_decay_s
from daq.validation import check_keys, number

__all__ = ["AdaptiveSettings", "CampaignPlan", "load_plan", "parse_plan"]

MODES = ("fixed", "adaptive")
#: How releases are grouped into run files (:mod:`daq.campaign.files`).
FILE_MODES = ("per_speed", "per_release")
#: When a release's recording ends: after decay_s, or once the decay has settled (or decay_s).
DECAY_ENDS = ("fixed", "settled")
#: How the model is released: the PLC, by hand, or whichever the rig allows (PLC first).
RELEASES = ("auto", "plc", "manual")
#: How the campaign's releases are identified.
IDENTIFICATIONS = ("e2rfc", "displacement")
#: E2RFC's estimators of releases in turbulence (``e2rfc.TURBULENT_ESTIMATORS``).
TURBULENT_ESTIMATORS = ("iv", "ml")
#: The closed-loop estimator's buffeting models, or the evidence's choice between them
#: (``e2rfc.CLOSED_LOOP_BUFFETING_CHOICES``).
CLOSED_LOOP_BUFFETINGS = ("second-order", "fourth-order", "second-order-per-speed",
                          "fourth-order-per-speed", "fourth-order-mixed",
                          "fourth-order-mixed-per-speed", "by-evidence")
#: Fewest wind speeds the displacement-only route identifies from (its known weakness).
DISPLACEMENT_MIN_SPEEDS = 3
MAX_RELEASES_PER_SPEED = 20
MAX_SPEEDS = 50
#: Safety fraction of a fixed plan (an adaptive plan gives its own).
FIXED_SAFETY_FRACTION = 0.9
#: The fan drive's ramp rate a campaign assumes when the rig's ``[fan]`` gives none, rpm/s
#: (docs/guides/drivers.md, "fan": the drivers' own default).
DEFAULT_RAMP_RPM_PER_S = 100.0


@dataclass(frozen=True)
class AdaptiveSettings:
    """The ``[adaptive]`` table (see the module docstring).

    Attributes
    ----------
    target_std : float
        Target relative standard deviation of the flutter speed (fraction, e.g. 0.01).
    safety_fraction : float
        Speeds stay below ``safety_fraction * (U_F - 3 std)``, (0, 1].
    candidate_min, candidate_max, candidate_step : float
        Candidate wind speeds, m/s.
    max_speeds : int
        Most wind speeds of the whole campaign.
    max_releases_per_speed : int or None
        With a number, each chosen speed gets 1 to this many releases, as many as the
        predicted gain per wind-on second says (:mod:`daq.campaign.adaptive`); None: the
        plan's ``releases_per_speed`` at every speed.
    """

    target_std: float
    safety_fraction: float
    candidate_min: float
    candidate_max: float
    candidate_step: float
    max_speeds: int
    max_releases_per_speed: int | None = None

    def release_options(self) -> list[int]:
        """Numbers of releases a chosen speed may get (empty: the plan's fixed number)."""
        n = self.max_releases_per_speed
        return [] if n is None else list(range(1, n + 1))

    def candidates(self) -> list[float]:
        """Candidate wind speeds, m/s, from ``candidate_min`` to ``candidate_max``."""
        n = int(math.floor((self.candidate_max - self.candidate_min) / self.candidate_step
                           + 1e-9))
        return [self.candidate_min + i * self.candidate_step for i in range(n + 1)]


@dataclass(frozen=True)
class CampaignPlan:
    """A parsed, validated campaign plan (see the module docstring).

    Attributes
    ----------
    mode : str
        ``"fixed"`` or ``"adaptive"``.
    wind_speeds : tuple of float or None
        Listed wind speeds, m/s (None when the plan gives fan set-points).
    fan_rpm : tuple of float or None
        Listed fan set-points, rpm (None when the plan gives wind speeds).
    releases_per_speed : int
    decay_s : float or None
        Recorded decay per release, s (None: :func:`daq.procedure.default_decay_s`).
    settle_s : float
        Time the wind must stay steady before the first release, s.
    steady_tolerance : float
        Steady: fan speed within this fraction of its set-point.
    pause_s : float
        Extra wait between releases, s.
    hold_s : float
        Time the model is held in the wind between arming and releasing, s (default
        :data:`daq.procedure.HOLD_S`). ``ident.records.run_file`` reads the hold from 0.25 s after
        the arm event to 0.05 s before the release; E2RFC's turbulence branch needs 10 s of it.
    calz_start, calz_end : bool
    adaptive : AdaptiveSettings or None
    source : str
    files : str
        ``"per_speed"`` (one run file per wind speed) or ``"per_release"`` (one per release,
        each closed and its modal fit reported as soon as its decay is recorded).
    decay_end : str
        ``"fixed"`` (every release recorded for ``decay_s``) or ``"settled"`` (a release's
        recording ends once its decay has settled,
        :attr:`daq.campaign.monitor.DecayMonitor.settled`; ``decay_s`` the longest).
    release : str
        ``"auto"``, ``"plc"`` or ``"manual"`` (:meth:`release_method` resolves ``"auto"``).
    identification : str
        ``"e2rfc"`` or ``"displacement"`` (the displacement-only route).
    turbulent_estimator : str
        E2RFC's estimator of releases in turbulence, ``"ml"`` (default) or ``"iv"``
        (:func:`ident.identification.e2rfc.identify`).
    closed_loop_buffeting : str
        The closed-loop estimator's buffeting model, ``"by-evidence"`` (default),
        ``"second-order"`` or ``"fourth-order"`` (:func:`ident.identification.e2rfc.identify`).
    given : frozenset of str
        The keys the plan's ``[campaign]`` and ``[adaptive]`` tables gave; the others took
        their defaults, which :meth:`defaults_taken` names.
    """

    mode: str
    wind_speeds: tuple[float, ...] | None
    fan_rpm: tuple[float, ...] | None
    releases_per_speed: int
    decay_s: float | None
    settle_s: float
    steady_tolerance: float
    pause_s: float
    calz_start: bool
    calz_end: bool
    adaptive: AdaptiveSettings | None
    source: str = ""
    files: str = "per_speed"
    decay_end: str = "fixed"
    hold_s: float = HOLD_S
    release: str = "auto"
    identification: str = "e2rfc"
    turbulent_estimator: str = "ml"
    closed_loop_buffeting: str = "by-evidence"
    given: frozenset[str] = frozenset()

    def defaults_taken(self, config: RigConfig) -> list[str]:
        """Return ``key = value`` for each optional key the plan left to its default.

        Said before the campaign starts (no default is taken silently), with the values as
        resolved on ``config``: the decay from the section's slower mode, ``release = "auto"``
        as the PLC or the hand, and the fan drive's ramp rate when its ``[fan]`` gives none.

        Parameters
        ----------
        config : RigConfig
            The rig the plan runs on.

        Returns
        -------
        list of str
            One phrase per default, units in SI (s, m/s, rpm/s); empty when none was taken.
        """
        values: dict[str, str] = {
            "releases_per_speed": str(self.releases_per_speed),
            "decay_s": (f"{default_decay_s(config.section):.3g} s ({MIN_DECAY_PERIODS:g} "
                        "periods of the slower mode)"),
            "decay_end": repr(self.decay_end), "settle_s": f"{self.settle_s:g} s",
            "steady_tolerance": f"{self.steady_tolerance:g}", "pause_s": f"{self.pause_s:g} s",
            "hold_s": f"{self.hold_s:g} s", "calz_start": str(self.calz_start).lower(),
            "calz_end": str(self.calz_end).lower(), "files": repr(self.files),
            "release": f"'auto' (here: {self.release_method(config)})",
            "identification": repr(self.identification),
            "turbulent_estimator": repr(self.turbulent_estimator),
            "closed_loop_buffeting": repr(self.closed_loop_buffeting),
        }
        if self.adaptive is not None:
            a = self.adaptive
            values.update({"safety_fraction": f"{a.safety_fraction:g}",
                           "candidate_step": f"{a.candidate_step:g} m/s",
                           "max_speeds": str(a.max_speeds),
                           "max_releases_per_speed": "none (releases_per_speed at every speed)"})
        out = [f"{key} = {value}" for key, value in values.items() if key not in self.given]
        for fan in config.by_role("fan"):  # the campaign waits out the ramp at this rate
            if "ramp_rpm_per_s" not in fan.settings:
                out.append(f"[{fan.name}] ramp_rpm_per_s = {DEFAULT_RAMP_RPM_PER_S:g} rpm/s "
                           f"(not in {config.source})")
        return out

    def release_method(self, config: RigConfig) -> str:
        """Return how this plan releases on ``config``: ``"plc"`` or ``"manual"``."""
        if self.release != "auto":
            return self.release
        return "plc" if config.by_role("plc") else "manual"

    def check_rig(self, config: RigConfig) -> None:
        """Raise ConfigError unless the rig can release and identify as this plan says.

        Checked before the fan turns (with :meth:`check_against`): a campaign that cannot
        release, or whose releases cannot be identified, must not blow the wind first.
        """
        where = f"{self.source} [campaign]"
        method = self.release_method(config)
        if method == "plc" and not config.by_role("plc"):
            raise ConfigError(f'{where} release = "plc": {config.source} has no [plc]; release '
                              'by hand instead (release = "manual": the operator is prompted '
                              "between releases)")
        if not config.by_role("lasers"):
            raise ConfigError(f"{where}: {config.source} has no lasers: no release can be seen "
                              "or identified (h and alpha come from them)")
        if self.identification == "e2rfc" and not config.by_role("scanner"):
            raise ConfigError(
                f"{where}: {config.source} has no pressure scanner, so no forces: E2RFC cannot "
                'identify its releases; name the displacement-only route (identification = '
                f'"displacement": fixed mode, {DISPLACEMENT_MIN_SPEEDS} or more speeds)')
        if self.identification == "displacement":
            if self.mode != "fixed":
                raise ConfigError(f'{where} identification = "displacement" needs mode = '
                                  '"fixed": the adaptive choice of speeds is E2RFC\'s')
            speeds = {round(U, 6) for U in self.listed_speeds(config.wind_per_rpm)}
            if len(speeds) < DISPLACEMENT_MIN_SPEEDS:
                raise ConfigError(
                    f'{self.source} [speeds]: identification = "displacement" needs '
                    f"{DISPLACEMENT_MIN_SPEEDS} or more distinct speeds (in practice many), "
                    f"got {len(speeds)}")

    def listed_speeds(self, wind_per_rpm: float) -> list[float]:
        """Return the listed speeds as wind speeds, m/s (fan set-points times the calibration)."""
        if self.wind_speeds is not None:
            return list(self.wind_speeds)
        assert self.fan_rpm is not None
        return [rpm * wind_per_rpm for rpm in self.fan_rpm]

    @property
    def safety_fraction(self) -> float:
        """The fraction of the flutter speed the campaign stays below (an adaptive plan's own)."""
        return self.adaptive.safety_fraction if self.adaptive else FIXED_SAFETY_FRACTION

    def blind_speeds(self, wind_per_rpm: float) -> list[float]:
        """Return the listed speeds set before any E2RFC estimate can bound them, m/s.

        E2RFC gives its first flutter speed after the second distinct wind speed, so the
        listed speeds up to and including that one are set blind; with the displacement-only
        route nothing is identified between speeds, so every listed speed is.
        """
        # Imported here: parsing a plan needs no numerics, only checking it against a rig.
        from ident.identification.uncertainty import distinct_wind_speeds

        listed = self.listed_speeds(wind_per_rpm)
        if self.identification == "displacement":
            return listed
        for k in range(len(listed)):
            if len(distinct_wind_speeds(listed[:k + 1])) >= 2:  # as E2RFC counts them
                return listed[:k + 1]
        return listed

    def check_against(self, config: RigConfig) -> None:
        """Raise ConfigError when a listed or candidate speed breaks the rig's limits.

        A plan is checked as a whole before the fan starts: a speed the drive would refuse
        halfway through a campaign is a mistake of the plan, not of the tunnel. So is an
        adaptive candidate range above the limits (km/h for m/s, say), and a speed set before
        any flutter estimate (:meth:`blind_speeds`) above the safety fraction of the flutter
        speed a flat plate of the section's structure would have
        (:func:`daq.campaign.adaptive.still_air_flutter_speed`): nothing measured would bound
        it, and only the decay monitor would stand between the model and flutter.
        """
        limit = min(config.limits.max_wind_speed, config.limits.max_fan_rpm * config.wind_per_rpm)
        where = f"{self.source} [speeds]"
        limits = (f"({config.source}: max_wind_speed {config.limits.max_wind_speed:g} m/s, "
                  f"max_fan_rpm {config.limits.max_fan_rpm:g} x wind_per_rpm "
                  f"{config.wind_per_rpm:g})")
        for U in self.listed_speeds(config.wind_per_rpm):
            if U > limit + 1e-9:
                raise ConfigError(f"{where}: {U:.3g} m/s is above the rig's limit {limit:.3g} m/s "
                                  f"{limits}")
        if self.adaptive is not None and self.adaptive.candidate_max > limit + 1e-9:
            raise ConfigError(
                f"{self.source} [adaptive] candidate_max = {self.adaptive.candidate_max:g} m/s "
                f"is above the rig's limit {limit:.3g} m/s {limits}; allowed: candidate_max "
                f"<= {limit:.3g} (candidates are wind speeds in m/s)")
        # Imported here: parsing a plan needs no numerics, only checking it against a rig.
        from daq.campaign.adaptive import still_air_flutter_speed

        prior = still_air_flutter_speed(config.section)
        if prior is None:
            return
        bound = self.safety_fraction * prior
        for U in self.blind_speeds(config.wind_per_rpm):
            if U > bound + 1e-9:
                raise ConfigError(
                    f"{where}: {U:.3g} m/s is set before any flutter estimate and is above "
                    f"{self.safety_fraction:g} x {prior:.3g} m/s = {bound:.3g} m/s, the still-air "
                    f"prediction (the flutter speed of a flat plate of {config.source}'s "
                    "[section]); start lower: the speeds after the first estimate are bounded "
                    "by it instead")


def _bool(table: Mapping[str, Any], key: str, where: str, default: bool) -> bool:
    value = table.get(key, default)
    if not isinstance(value, bool):
        raise ConfigError(f"{where} {key} must be true or false, got {value!r}")
    return value


def _integer(table: Mapping[str, Any], key: str, where: str, lo: int, hi: int,
             default: int | None = None) -> int:
    if key not in table:
        if default is None:
            raise ConfigError(f"{where}: missing required key {key!r}")
        return default
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ConfigError(f"{where} {key} = {value!r} must be an integer in [{lo}, {hi}]")
    return int(value)


def _speed_list(table: Mapping[str, Any], key: str, where: str, lo_open: float, hi: float,
                unit: str) -> tuple[float, ...]:
    value = table[key]
    if not isinstance(value, list) or not value:
        raise ConfigError(f"{where} {key} must be a non-empty list of numbers ({unit})")
    out = []
    for i, x in enumerate(value):
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            raise ConfigError(f"{where} {key}[{i}] must be a number ({unit}), got {x!r}")
        if not math.isfinite(x) or not lo_open < x <= hi:
            raise ConfigError(f"{where} {key}[{i}] = {x!r} is outside the allowed range "
                              f"({lo_open:g}, {hi:g}] {unit}")
        out.append(float(x))
    if len(out) > MAX_SPEEDS:
        raise ConfigError(f"{where} {key}: {len(out)} speeds, at most {MAX_SPEEDS}")
    return tuple(out)


def parse_plan(text: str, source: str = "<string>") -> CampaignPlan:
    """Parse and validate a plan's TOML text.

    Parameters
    ----------
    text : str
        The plan (module docstring).
    source : str
        Where it came from, for messages.

    Returns
    -------
    CampaignPlan

    Raises
    ------
    ConfigError
        Not TOML, an unknown or missing key, a value out of its range (named).
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: not valid TOML: {exc}") from exc
    check_keys(data, source, {"campaign", "speeds"}, {"adaptive"})
    where = f"{source} [campaign]"
    c = data["campaign"]
    check_keys(c, where, {"mode"}, {"releases_per_speed", "decay_s", "settle_s",
                                    "steady_tolerance", "pause_s", "calz_start", "calz_end",
                                    "files", "decay_end", "hold_s", "release",
                                    "identification", "turbulent_estimator",
                                    "closed_loop_buffeting"})
    mode = c["mode"]
    if mode not in MODES:
        raise ConfigError(f"{where} mode = {mode!r}; allowed: {', '.join(MODES)}")
    releases = _integer(c, "releases_per_speed", where, 1, MAX_RELEASES_PER_SPEED, default=2)
    decay_s = number(c, "decay_s", where, lo=1.0, hi=600.0) if "decay_s" in c else None
    settle_s = number(c, "settle_s", where, lo=0.0, hi=600.0, default=1.0)
    steady = number(c, "steady_tolerance", where, lo=0.0, hi=0.2, lo_open=True, default=0.01)
    pause_s = number(c, "pause_s", where, lo=0.0, hi=600.0, default=0.0)
    hold_s = number(c, "hold_s", where, lo=0.1, hi=600.0, default=HOLD_S)
    calz_start = _bool(c, "calz_start", where, True)
    calz_end = _bool(c, "calz_end", where, True)
    files = c.get("files", "per_speed")
    if files not in FILE_MODES:
        raise ConfigError(f"{where} files = {files!r}; allowed: {', '.join(FILE_MODES)}")
    decay_end = c.get("decay_end", "fixed")
    if decay_end not in DECAY_ENDS:
        raise ConfigError(f"{where} decay_end = {decay_end!r}; allowed: "
                          f"{', '.join(DECAY_ENDS)}")
    release = c.get("release", "auto")
    if release not in RELEASES:
        raise ConfigError(f"{where} release = {release!r}; allowed: {', '.join(RELEASES)}")
    identification = c.get("identification", "e2rfc")
    if identification not in IDENTIFICATIONS:
        raise ConfigError(f"{where} identification = {identification!r}; allowed: "
                          f"{', '.join(IDENTIFICATIONS)}")
    estimator = c.get("turbulent_estimator", "ml")
    if estimator not in TURBULENT_ESTIMATORS:
        raise ConfigError(f"{where} turbulent_estimator = {estimator!r}; allowed: "
                          f"{', '.join(TURBULENT_ESTIMATORS)}")
    buffeting = c.get("closed_loop_buffeting", "by-evidence")
    if buffeting not in CLOSED_LOOP_BUFFETINGS:
        raise ConfigError(f"{where} closed_loop_buffeting = {buffeting!r}; allowed: "
                          f"{', '.join(CLOSED_LOOP_BUFFETINGS)}")

    where = f"{source} [speeds]"
    s = data["speeds"]
    check_keys(s, where, set(), {"wind_speeds", "fan_rpm"})
    if ("wind_speeds" in s) == ("fan_rpm" in s):
        raise ConfigError(f"{where}: give exactly one of wind_speeds (m/s) or fan_rpm (rpm)")
    wind = _speed_list(s, "wind_speeds", where, 0.0, 200.0, "m/s") if "wind_speeds" in s \
        else None
    rpm = _speed_list(s, "fan_rpm", where, 0.0, 100000.0, "rpm") if "fan_rpm" in s else None
    listed = wind if wind is not None else rpm
    assert listed is not None

    adaptive = None
    if mode == "adaptive":
        where = f"{source} [adaptive]"
        if "adaptive" not in data:
            raise ConfigError(f"{where}: missing: mode = \"adaptive\" needs an [adaptive] table")
        a = data["adaptive"]
        check_keys(a, where, {"target_std", "candidate_min", "candidate_max"},
                   {"safety_fraction", "candidate_step", "max_speeds",
                    "max_releases_per_speed"})
        target = number(a, "target_std", where, lo=0.0, hi=0.5, lo_open=True)
        fraction = number(a, "safety_fraction", where, lo=0.0, hi=1.0, lo_open=True,
                          default=0.9)
        lo = number(a, "candidate_min", where, lo=0.0, hi=200.0, lo_open=True)
        hi = number(a, "candidate_max", where, lo=lo, hi=200.0)
        step = number(a, "candidate_step", where, lo=0.01, hi=max(hi - lo, 0.01),
                      default=max((hi - lo) / 10.0, 0.01))
        max_speeds = _integer(a, "max_speeds", where, max(len(listed), 2), MAX_SPEEDS,
                              default=max(len(listed), 6))
        if len(set(listed)) < 2:
            raise ConfigError(f"{source} [speeds]: adaptive mode needs two or more distinct "
                              "first speeds (E2RFC needs two wind speeds), got "
                              f"{list(listed)}")
        most = (_integer(a, "max_releases_per_speed", where, 1, MAX_RELEASES_PER_SPEED,
                         default=1) if "max_releases_per_speed" in a else None)
        adaptive = AdaptiveSettings(target, fraction, lo, hi, step, max_speeds, most)
    elif "adaptive" in data:
        raise ConfigError(f"{source} [adaptive]: only for mode = \"adaptive\" (mode is "
                          f"{mode!r})")
    return CampaignPlan(mode=mode, wind_speeds=wind, fan_rpm=rpm, releases_per_speed=releases,
                        decay_s=decay_s, settle_s=settle_s, steady_tolerance=steady,
                        pause_s=pause_s, calz_start=calz_start, calz_end=calz_end,
                        adaptive=adaptive, source=source, files=files, decay_end=decay_end,
                        hold_s=hold_s, release=release, identification=identification,
                        turbulent_estimator=estimator, closed_loop_buffeting=buffeting,
                        given=frozenset(c) | frozenset(data.get("adaptive", {})))


def load_plan(path: str | Path) -> CampaignPlan:
    """Read and validate a plan file (:func:`parse_plan`); a missing file is a ConfigError."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"cannot read plan {path}: {exc.strerror or exc}") from exc
    return parse_plan(text, str(path))
