"""A campaign's run files: their names, and reading back what an earlier session recorded.

Responsibility: the file names of a campaign's output directory and what they mean, in one
place, so that the runner that writes them and the resume that reads them agree:

- one file per wind speed (``files = "per_speed"``, the default): ``speed03_U07.50.h5``;
- one file per release (``files = "per_release"``): ``speed03_U07.50_r01.h5``,
  ``speed03_U07.50_r02.h5``, ...: each release is a file of its own, closed (and analysed)
  as soon as its decay is recorded;
- a speed interrupted by Ctrl-C keeps its file(s) as ``*.interrupted.h5``, which are never
  read back: the speed is repeated whole on resume (its releases were taken at one wind
  setting, and half a speed would weigh that speed less than the plan said).

:func:`read_back` groups the files of the directory by speed, in the order recorded.

Not responsible for: recording (:mod:`daq.campaign.runner`) or identification (:mod:`ident`).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from ident.errors import IdentError
from ident.records.run_file import RunFile, read_run

__all__ = ["RecordedSpeed", "interrupted_name", "read_back", "run_file_name"]

#: ``speedNN_U<m/s>.h5`` or ``speedNN_U<m/s>_rMM.h5``; nothing else in the directory counts.
_NAME = re.compile(r"^speed(?P<index>\d{2})_U(?P<U>\d+\.\d{2})(?:_r(?P<release>\d{2}))?\.h5$")


def run_file_name(index: int, U: float, release: int | None = None) -> str:
    """Return the file name of a speed (or of one of its releases).

    Parameters
    ----------
    index : int
        Order of the speed in the campaign, from 1.
    U : float
        Requested wind speed, m/s.
    release : int, optional
        Release number within the speed, from 1, for one file per release.

    Examples
    --------
    >>> run_file_name(3, 7.5), run_file_name(3, 7.5, 2)
    ('speed03_U07.50.h5', 'speed03_U07.50_r02.h5')
    """
    suffix = "" if release is None else f"_r{release:02d}"
    return f"speed{index:02d}_U{U:05.2f}{suffix}.h5"


def interrupted_name(path: Path) -> Path:
    """Return where an interrupted run file is kept (``x.h5`` -> ``x.interrupted.h5``)."""
    return path.with_name(path.name[:-3] + ".interrupted.h5")


@dataclass
class RecordedSpeed:
    """The run files of one speed found in a campaign's directory.

    Attributes
    ----------
    index : int
        Order of the speed in the campaign, from 1.
    U : float
        Requested wind speed, m/s.
    paths : list of Path
        Its file (one per speed) or files (one per release, in release order).
    runs : list of RunFile
        The files that could be read (a file that cannot is reported and left out).
    """

    index: int
    U: float
    paths: list[Path] = field(default_factory=list)
    runs: list[RunFile] = field(default_factory=list)

    @property
    def releases(self) -> int:
        """Releases read back from the files."""
        return sum(len(run.releases) for run in self.runs)

    @property
    def recording_warnings(self) -> list[str]:
        """What the files' writer warned of, each led by its file's name (as when recorded)."""
        return [f"{Path(run.path).name}: {text}" for run in self.runs
                for text in run.recording_warnings]


def read_back(out: Path, say: Callable[[str], None], *,
              displacements_only: bool = False) -> list[RecordedSpeed]:
    """Read the run files of earlier sessions in ``out``, grouped by speed in campaign order.

    A file that cannot be read (not a run file, no usable release) is reported through ``say``
    and left out of the fit; it stays on disk. ``displacements_only``: read h and alpha alone,
    as the displacement-only route does (a rig without taps).
    """
    speeds: dict[tuple[int, str], RecordedSpeed] = {}
    for path in sorted(out.glob("speed[0-9][0-9]_U*.h5")):
        match = _NAME.match(path.name)
        if match is None:  # *.interrupted.h5 and anything else: not part of the campaign
            continue
        key = (int(match["index"]), match["U"])
        speed = speeds.setdefault(key, RecordedSpeed(key[0], float(key[1])))
        speed.paths.append(path)
        try:
            speed.runs.append(read_run(path, cut_at_gaps=True,  # as when recorded
                                       displacements_only=displacements_only))
        except (IdentError, ValueError, OSError) as exc:
            say(f"resume: {path.name} is not usable ({exc}); left out")
    return [speeds[key] for key in sorted(speeds)]
