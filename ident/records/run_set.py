"""What a campaign's run files say together, for identification.

:func:`campaign_section`: their one section model, with the median of their measured air
densities (files of different models are refused); :func:`tubing_note`: whether their forces
were corrected for the recorded tubing; :func:`recording_notes`: the warnings their writer
closed them with, each led by its file. Each file is read by :mod:`ident.records.run_file`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ident.model.section import SectionModel
from ident.records.run_file import FileFormatError, RunFile

__all__ = ["campaign_section", "recording_notes", "tubing_note"]


def campaign_section(runs: Sequence[RunFile]) -> SectionModel:
    """Return the one section model of a campaign's run files, with the median air density.

    Parameters
    ----------
    runs : sequence of RunFile
        Files of one campaign (one section model, any wind speeds).

    Returns
    -------
    SectionModel
        The stored section with ``rho`` the median of the files' measured densities.

    Raises
    ------
    FileFormatError
        If there are no runs, or if the files' sections differ (other than in air density):
        releases of different models cannot be identified together.
    """
    if not runs:
        raise FileFormatError("no run files given")
    first = runs[0].section
    for run in runs[1:]:
        if run.section.replace(rho=first.rho) != first:
            raise FileFormatError(f"{run.path}: its section model differs from the one of "
                                  f"{runs[0].path}; identify one section model at a time")
    return first.replace(rho=float(np.median([run.section.rho for run in runs])))


def tubing_note(runs: Sequence[RunFile]) -> str:
    """Say whether the runs' forces were corrected for their recorded tubing ("" if none has).

    Returns
    -------
    str
        E.g. ``"; forces corrected for the pressure tubing of 2 of 3 file(s)"``.
    """
    tubed = [run for run in runs if run.tubing is not None]
    if not tubed:
        return ""
    state = "corrected for" if all(run.tubing_corrected for run in tubed) else "NOT corrected for"
    return f"; forces {state} the pressure tubing of {len(tubed)} of {len(runs)} file(s)"


def recording_notes(runs: Sequence[RunFile]) -> list[str]:
    """Return the runs' recording warnings, each led by its file's path (identification's too).

    A file whose clocks no trigger pulse anchored has motion and forces up to a transport
    latency apart: what is identified from it inherits that, so its warning goes on.
    """
    return [f"{run.path}: recorded with a warning: {text}"
            for run in runs for text in run.recording_warnings]
