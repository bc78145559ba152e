"""A run file's parts against the layout its readers need (docs/reference/file_format.md).

Responsible for: checking what :mod:`ident.records.run_file` has read from a run file written
by windrig or by another program (a converter, a script, a hand edit), and saying in one
sentence what does not fit: a column of text or of two values per row, a release table of
plain numbers or without a field, a release listed twice or two sharing rows, a
``release_time`` that is not where its first row is (outside the record, a time base in
milliseconds). Each check returns the problem (None: none); the reader raises it as a
``FileFormatError`` led by the file's path, and ``windrig info`` (:mod:`daq.recording.info`)
lists the release rows' problems as warnings.

Not responsible for: opening and reading the file (:mod:`ident.records.run_file`), a release's
own checks (:class:`ident.records.release.Release`), the plausibility of the values
(:mod:`ident.records.plausibility`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ident.records.release import START_MAX_S

__all__ = ["RELEASE_FIELDS", "column_problem", "empty_release", "release_rows_problem",
           "release_table_problem", "release_time_problem", "shared_rows_problem"]

#: Fields of ``/entry/releases`` every reader uses (docs/reference/file_format.md; ``h0`` and
#: ``alpha0`` are shown by ``windrig info`` but not needed to identify).
RELEASE_FIELDS = ("release_time", "start_index", "stop_index", "U")


def column_problem(dtype: np.dtype[Any], shape: tuple[int, ...], part: str) -> str | None:
    """Return what keeps a dataset from being a column of ``/entry/sync`` (None: nothing).

    Parameters
    ----------
    dtype, shape
        The dataset's.
    part : str
        Its path in the file, e.g. ``/entry/sync/h``.

    Returns
    -------
    str or None
        Text or compound values, or more than one value per row: said before NumPy's
        conversion fails with a message that names neither the file nor the column.
    """
    if dtype.kind not in "biuf":
        return f"{part} holds {dtype} values, not numbers"
    if len(shape) != 1:
        return f"{part} has shape {shape}: a column of /entry/sync holds one number per row"
    return None


def release_table_problem(table: np.ndarray) -> str | None:
    """Return what keeps ``/entry/releases`` from being a table the readers use (None: nothing).

    Parameters
    ----------
    table : ndarray
        The dataset's values.

    Returns
    -------
    str or None
        Not a 1-D compound array with every field of :data:`RELEASE_FIELDS`: a plain 2-D array
        of numbers, a field renamed or left out by another program.
    """
    names = table.dtype.names or ()
    if not names or table.ndim != 1:
        return (f"/entry/releases is a {table.dtype} array of shape {table.shape}, not a table "
                f"of rows with the fields {', '.join(RELEASE_FIELDS)} "
                "(docs/reference/file_format.md)")
    missing = [name for name in RELEASE_FIELDS if name not in names]
    if missing:
        return (f"/entry/releases has no field {', '.join(missing)} (it has "
                f"{', '.join(names)}); its rows need {', '.join(RELEASE_FIELDS)}")
    return None


def empty_release(index: int) -> str:
    """Say that release row ``index`` holds no rows (``start_index == stop_index``).

    The recorder writes such a row for a release commanded as the recording ended
    (:mod:`daq.recording.releases`): the readers leave it out, and say so.
    """
    return (f"release {index} holds no rows of /entry/sync (released as the recording "
            "ended?)")


def release_rows_problem(start: int, stop: int, rows: int, index: int) -> str | None:
    """Return what is wrong with a release's rows ``start..stop`` of ``rows`` (None: nothing).

    Parameters
    ----------
    start, stop : int
        Its ``start_index`` and ``stop_index``, not equal (:func:`empty_release` says that).
    rows : int
        The rows of ``/entry/sync``.
    index : int
        The release's row, for the message.
    """
    if stop < start:
        return (f"release {index} rows {start}..{stop} run backwards: its stop_index must "
                "exceed its start_index")
    if not 0 <= start < stop <= rows:
        return (f"release {index} rows {start}..{stop} are outside the {rows} rows of "
                "/entry/sync (truncated run?)")
    return None


def shared_rows_problem(table: np.ndarray) -> str | None:
    """Return a release listed twice, or two releases that share rows of ``/entry/sync``.

    The same decay in two rows would weigh double in E2RFC's least squares, and would look
    like a second, independent release to the uncertainty's jackknife. Rows that are empty or
    run backwards are not compared (the reader names them).

    Parameters
    ----------
    table : ndarray
        ``/entry/releases`` (with the fields of :data:`RELEASE_FIELDS`).

    Returns
    -------
    str or None
        Naming the two releases (their indices, and the release time in s or their rows).
    """
    times = np.asarray(table["release_time"], dtype=float)
    for j in range(1, times.size):
        same = np.flatnonzero(times[:j] == times[j])
        if same.size:
            return (f"releases {int(same[0])} and {j} of /entry/releases have the same "
                    f"release_time {times[j]:g} s: one release listed twice? (each release is "
                    "one row)")
    starts = np.asarray(table["start_index"], dtype=np.int64)
    stops = np.asarray(table["stop_index"], dtype=np.int64)
    reach, owner = -1, -1  # the furthest stop so far, and its release
    for k in np.argsort(starts, kind="stable"):
        if starts[k] >= stops[k]:
            continue
        if starts[k] < reach:
            i, j = sorted((owner, int(k)))
            return (f"releases {i} (rows {starts[i]}..{stops[i]}) and {j} (rows "
                    f"{starts[j]}..{stops[j]}) of /entry/releases share rows of /entry/sync: "
                    "a decay's rows belong to one release (a stop_index past the next "
                    "release?)")
        if stops[k] > reach:
            reach, owner = int(stops[k]), int(k)
    return None


def release_time_problem(time: np.ndarray, row: Any, index: int) -> str | None:
    """Return why a release row's ``release_time`` is not where its first row is (None: it is).

    A release's first row lies at its instant or at most :data:`START_MAX_S` after it
    (:class:`~ident.records.release.Release`); one that does not is a row another program
    wrote wrongly, and the problem says which of the two looks wrong (an instant outside the
    record, a time base in milliseconds) rather than only that the release's time axis does
    not start at zero.

    Parameters
    ----------
    time : ndarray
        ``/entry/sync/time``, s.
    row : numpy.void
        The release's row, its ``start_index`` < ``stop_index`` within ``time``.
    index : int
        The row's index, for the message.
    """
    start, stop = int(row["start_index"]), int(row["stop_index"])
    instant, first = float(row["release_time"]), float(time[start])
    if not np.isfinite(instant):
        return f"release {index} has no release_time (NaN) in /entry/releases"
    steps = np.diff(time[start:stop])
    dt = float(np.median(steps)) if steps.size else 0.0
    if -dt <= first - instant <= START_MAX_S or not np.isfinite(first):
        return None  # (a NaN time is a gap: Release names it)
    finite = time[np.isfinite(time)]
    where = ""
    if finite.size and not finite[0] - dt <= instant <= finite[-1]:
        where = (f" lies outside the record (/entry/sync/time runs from {finite[0]:g} to "
                 f"{finite[-1]:g} s), and")
    hint = ""
    if instant > 0 and 900.0 < first / instant < 1100.0:
        hint = "; /entry/sync/time looks like milliseconds (both must be in s)"
    return (f"release {index}: its release_time {instant:g} s{where} is {first - instant:+g} s "
            f"from its first row ({start}, at {first:g} s): release_time and start_index "
            f"disagree (the first row is at the instant or up to {START_MAX_S:g} s after it)"
            f"{hint}")
