"""What a campaign did and found: each recorded wind speed, and the campaign's outcome.

Responsibility: the records :mod:`daq.campaign.runner` fills in as the campaign goes and
:mod:`daq.campaign.report` writes out: :class:`SpeedStep` (one wind speed: its files, why it
was chosen, the estimate and the wind-on time after it) and :class:`CampaignOutcome` (the
steps, the last analysis, why the campaign stopped, the tunnel time, the adaptive decisions).

Not responsible for: running the campaign (:mod:`daq.campaign.runner`) or writing the report
(:mod:`daq.campaign.report`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from daq.campaign.adaptive import Choice
from ident.identification.campaign import CampaignAnalysis

__all__ = ["CampaignOutcome", "SpeedStep"]


@dataclass
class SpeedStep:
    """One recorded wind speed.

    Attributes
    ----------
    index : int
        Order in the campaign, from 1.
    U : float
        Requested wind speed, m/s.
    path : Path
        Its (first) run file.
    releases : int
        Releases read back from its file(s).
    why : str
        Why this speed (listed in the plan, or the adaptive choice).
    flutter_speed, flutter_std : float or None
        The estimate after this speed, m/s.
    wind_on_s : float or None
        Wind-on time of the campaign when this speed's estimate was known, s (None: read
        back from an earlier session).
    paths : list of Path
        Every run file of the speed (one, or one per release).
    resumed : bool
        Read back from an earlier session (not known to have decayed: its file may be the
        one a growing decay stopped).
    flutter_std_parts : dict of str to float or None
        The std's parts after this speed, by their JSON names
        (:meth:`~ident.identification.uncertainty.FlutterUncertainty.parts`), m/s: which part
        moved when the std did.
    """

    index: int
    U: float
    path: Path
    releases: int
    why: str
    flutter_speed: float | None = None
    flutter_std: float | None = None
    wind_on_s: float | None = None
    paths: list[Path] = field(default_factory=list)
    resumed: bool = False
    flutter_std_parts: dict[str, float] | None = None

    def __post_init__(self) -> None:
        if not self.paths:
            self.paths = [self.path]


@dataclass
class CampaignOutcome:
    """What a campaign did and found (what :mod:`daq.campaign.report` writes).

    Attributes
    ----------
    steps : list of SpeedStep
        In the order tested.
    analysis : CampaignAnalysis or None
        The last E2RFC analysis (None before two speeds).
    stopped_because : str
    wind_on_s : float
        Fan start to fan stopped, s, this session plus the resumed ones.
    wall_s : float
        This session's wall time, s.
    truth_flutter_speed : float or None
        The simulated tunnel's own (``simulate=True``), m/s.
    resumed : int
        Speeds read back from an earlier session.
    choices : list of Choice
        The adaptive decisions, in order.
    max_fan_rpm_commanded : float
        Highest fan set-point sent this session, rpm.
    recording_warnings : list of str
        What the run files' writers warned of (a clock map without a trigger anchor), each
        prefixed with its file's name.
    """

    steps: list[SpeedStep] = field(default_factory=list)
    analysis: CampaignAnalysis | None = None
    stopped_because: str = ""
    wind_on_s: float = 0.0
    wall_s: float = 0.0
    truth_flutter_speed: float | None = None
    resumed: int = 0
    choices: list[Choice] = field(default_factory=list)
    max_fan_rpm_commanded: float = 0.0
    recording_warnings: list[str] = field(default_factory=list)

    @property
    def flutter_speed(self) -> float | None:
        """Identified flutter speed, m/s."""
        return None if self.analysis is None else self.analysis.flutter_speed

    @property
    def flutter_std(self) -> float | None:
        """Its standard deviation, m/s."""
        return None if self.analysis is None else self.analysis.flutter_std
