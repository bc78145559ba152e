"""What a campaign's run files say together, for identification.

:func:`campaign_section`: their one section model, with the median of their measured air
densities (files of different models are refused, naming the parameters that differ,
:func:`section_difference`); :func:`tubing_note`: whether their forces
were corrected for the recorded tubing; :func:`recording_notes`: the warnings their writer
closed them with, each led by its file. Each file is read by :mod:`ident.records.run_file`.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from ident.model.section import SectionModel
from ident.records.run_file import FileFormatError, RunFile

__all__ = ["campaign_section", "differing_parameters", "recording_notes", "section_difference",
           "tubing_note"]


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
        If there are no runs, if a file is given twice, or if the files' sections differ
        (other than in air density): releases of different models cannot be identified
        together.
    """
    if not runs:
        raise FileFormatError("no run files given")
    seen: dict[str, str] = {}
    for run in runs:
        # The same file twice (a glob and a name, a link) would count its releases twice.
        real = os.path.realpath(run.path)
        if real in seen:
            also = "" if seen[real] == run.path else f" (also as {seen[real]})"
            raise FileFormatError(f"{run.path}: given twice{also}: its releases would count "
                                  "twice; give each run file once")
        seen[real] = run.path
    first = runs[0].section
    for run in runs[1:]:
        if run.section.replace(rho=first.rho) != first:
            raise FileFormatError(f"{run.path}: its section model differs from the one of "
                                  f"{runs[0].path} ({section_difference(run.section, first)}); "
                                  "identify one section model at a time")
    return first.replace(rho=float(np.median([run.section.rho for run in runs])))


def section_difference(section: SectionModel, reference: SectionModel) -> str:
    """Say in which stored parameters (air density aside) a section differs from another.

    Returns
    -------
    str
        E.g. ``"fh = 2.1 against 2"`` or ``"fp = 1.5 against none (3 DOF against 2)"``: the
        parameters in SectionModel's units (m, kg/m, kg m^2/m, Hz), so that a typo in one
        file's config is found without reading both.
    """
    mine, theirs = section.to_dict(), reference.to_dict()
    parts = [f"{name} = {_value(mine.get(name))} against {_value(theirs.get(name))}"
             for name in differing_parameters(section, reference)]
    if section.n_dof != reference.n_dof:
        parts.append(f"{section.n_dof} DOF against {reference.n_dof}")
    return "; ".join(parts) or "in no stored parameter"


def differing_parameters(section: SectionModel, reference: SectionModel) -> list[str]:
    """Return the stored parameters (air density aside) in which two sections differ.

    Returns
    -------
    list of str
        Their names (``SectionModel.to_dict``'s keys), the reference's order first.
    """
    mine, theirs = section.to_dict(), reference.to_dict()
    return [name for name in dict.fromkeys([*theirs, *mine])
            if name != "rho" and mine.get(name) != theirs.get(name)]


def _value(value: object) -> str:
    return "none" if value is None else f"{value:g}" if isinstance(value, float) else str(value)


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
    """Return the runs' recording warnings and reading notes, each led by its file's path.

    A file whose clocks no trigger pulse anchored has motion and forces up to a transport
    latency apart: what is identified from it inherits that, so its warning goes on. What the
    reader took in place of a missing part (:attr:`RunFile.reading_notes`: a default air
    density, sway left unread) goes on as well, so that no default is taken silently.
    """
    return [*(f"{run.path}: recorded with a warning: {text}"
              for run in runs for text in run.recording_warnings),
            *(f"{run.path}: {text}" for run in runs for text in run.reading_notes)]
