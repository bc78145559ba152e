"""Run files another program wrote, or that were damaged: each read refused in one clear sentence.

Each test writes docs/reference/file_format.md's smallest run file with h5py alone
(``support.run_files.write_smallest_run``: two flat-plate releases at 5 and 8 m/s, 200 Hz, the
first row of each release 0.5 s after its hold began), damages one part of it with h5py as a
converter or a hand edit would, and reads it back with :func:`read_run`. The error must name
the file and the part, and say what is wrong (not NumPy's words, not "truncated?" for a file
that is whole); what the reader takes in place of a missing part is said in
:attr:`RunFile.reading_notes`; nothing is counted twice.
"""

from __future__ import annotations

import re
import shutil

import h5py
import numpy as np
import pytest

from ident.records.run_file import FileFormatError, read_run
from ident.records.run_set import campaign_section, recording_notes

from support.run_files import write_smallest_run


@pytest.fixture(scope="module")
def smallest(tmp_path_factory):
    path = tmp_path_factory.mktemp("foreign") / "run.h5"
    write_smallest_run(path)
    return path


def damaged(smallest, tmp_path, part: str, value) -> str:
    """Copy the smallest file; replace ``/entry/<part>`` by ``value`` (a callable: of the old)."""
    path = tmp_path / f"{part.replace('/', '_')}.h5"
    shutil.copy(smallest, path)
    with h5py.File(path, "r+") as f:
        old = f[f"entry/{part}"][()]
        del f[f"entry/{part}"]
        f[f"entry/{part}"] = value(old) if callable(value) else value
    return str(path)


def refused(path: str, *words: str) -> str:
    with pytest.raises(FileFormatError) as info:
        read_run(path)
    text = str(info.value)
    assert text.startswith(f"{path}: ") and "\n" not in text, text
    for word in words:
        assert word in text, (word, text)
    return text


def test_a_release_table_written_as_a_plain_array_is_refused_by_its_layout(smallest, tmp_path):
    # A MATLAB or NumPy user's (2, 6) matrix of numbers. Before: IndexError with a traceback.
    path = damaged(smallest, tmp_path, "releases", np.zeros((2, 6)))
    refused(path, "/entry/releases is a float64 array of shape (2, 6)",
            "release_time, start_index, stop_index, U")


def test_a_release_table_without_a_field_names_the_field(smallest, tmp_path):
    # Before: "no field of name U", naming neither the file nor the table.
    def without_U(table):
        names = [n for n in table.dtype.names if n != "U"]
        out = np.zeros(table.shape, dtype=[(n, table.dtype[n]) for n in names])
        for n in names:
            out[n] = table[n]
        return out

    path = damaged(smallest, tmp_path, "releases", without_U)
    refused(path, "/entry/releases has no field U (it has release_time, start_index")


@pytest.mark.parametrize(("value", "words"), [
    (lambda h: np.array([b"x"] * h.size), ("/entry/sync/h holds |S1 values, not numbers",)),
    (lambda h: np.column_stack([h, h]), ("/entry/sync/h has shape (1800, 2)",)),
    (lambda h: h[:1000], ("release 1 rows 1000..1800 run past the end of /entry/sync/h (1000 "
                          "rows; /entry/sync/time has 1800)",)),
], ids=["text", "two columns", "short"])
def test_a_sync_column_of_the_wrong_type_or_shape_is_named(smallest, tmp_path, value, words):
    # Before: "unreadable (truncated or damaged?): could not convert string to float", NumPy's
    # "inhomogeneous shape" without the file, and "release channels must have equal lengths".
    refused(damaged(smallest, tmp_path, "sync/h", value), *words)


def test_a_release_listed_twice_is_refused_not_counted_twice(smallest, tmp_path):
    # Before: three releases, the one at 8 m/s weighing double in the least squares, and the
    # jackknife taking the copy for an independent release.
    path = damaged(smallest, tmp_path, "releases", lambda t: np.concatenate([t, t[1:]]))
    refused(path, "releases 1 and 2 of /entry/releases have the same release_time 5 s",
            "listed twice")


def test_releases_that_share_rows_are_refused(smallest, tmp_path):
    def overlapping(table):
        table = table.copy()
        table["stop_index"][0] = table["start_index"][1] + 50  # past the next release's start
        return table

    path = damaged(smallest, tmp_path, "releases", overlapping)
    refused(path, "releases 0 (rows 100..1050) and 1 (rows 1000..1800) of /entry/releases "
                  "share rows of /entry/sync")


def test_a_release_time_outside_the_record_is_named_as_such(smallest, tmp_path):
    # Before: "t starts at -495 s ... subtract the instant the model was let go", which
    # blamed the release's time axis rather than the row's release_time.
    def late(table):
        table = table.copy()
        table["release_time"][1] = 500.0
        return table

    path = damaged(smallest, tmp_path, "releases", late)
    refused(path, "release 1: its release_time 500 s lies outside the record "
                  "(/entry/sync/time runs from 0 to 8.995 s)", "disagree")


def test_a_time_base_in_milliseconds_is_named(smallest, tmp_path):
    path = damaged(smallest, tmp_path, "sync/time", lambda t: t * 1000.0)
    refused(path, "release 0", "/entry/sync/time looks like milliseconds")


def test_a_release_row_without_rows_is_left_out_and_said(smallest, tmp_path):
    # The recorder writes such a row for a release commanded as the recording ended. Before:
    # the whole file refused, "rows 100..100 are outside the 1800 rows (truncated run?)".
    def empty(table):
        table = table.copy()
        table["stop_index"][0] = table["start_index"][0]
        return table

    run = read_run(damaged(smallest, tmp_path, "releases", empty))
    assert [r.U for r in run.releases] == [8.0] and run.releases[0].meta["release"] == 1
    assert run.reading_notes == ("release 0 holds no rows of /entry/sync (released as the "
                                 "recording ended?): left out",)


def test_a_release_whose_rows_run_backwards_is_not_called_truncated(smallest, tmp_path):
    def backwards(table):
        table = table.copy()
        table["stop_index"][0] = table["start_index"][0] - 10
        return table

    text = refused(damaged(smallest, tmp_path, "releases", backwards),
                   "release 0 rows 100..90 run backwards", "stop_index must exceed")
    assert "truncated" not in text


def test_an_air_density_never_measured_is_said_not_taken_silently(smallest, tmp_path):
    path = damaged(smallest, tmp_path, "sync/rho", lambda rho: np.full(rho.shape, np.nan))
    run = read_run(path)
    assert run.section.rho == 1.225 and len(run.releases) == 2
    (note,) = recording_notes([run])
    assert note.startswith(f"{path}: /entry/sync/rho holds no air density (all NaN): the "
                           "default 1.225 kg/m^3 is used")
    assert recording_notes([read_run(smallest)]) == []  # a file with its density: nothing


def test_sway_columns_a_2dof_section_does_not_read_are_said(smallest, tmp_path):
    path = tmp_path / "sway.h5"
    shutil.copy(smallest, path)
    with h5py.File(path, "r+") as f:
        n = f["entry/sync/time"].shape[0]
        f["entry/sync/p"] = np.sin(np.arange(n) / 10.0) * 1e-3
        f["entry/sync/drag"] = np.zeros(n)
    run = read_run(path)
    assert run.section.n_dof == 2 and all(r.p is None for r in run.releases)
    assert run.reading_notes == ("/entry/sync has sway p and drag, but its [section] has no fp: "
                                 "read as 2-DOF, the sway left out (a 3-DOF section needs fp, "
                                 "zeta_p)",)


def test_sections_that_differ_name_the_parameter_and_a_file_given_twice_is_refused(
        smallest, tmp_path):
    other = damaged(smallest, tmp_path, "config",
                    lambda text: text.decode().replace("fh = 2.0", "fh = 2.1"))
    with pytest.raises(FileFormatError, match=re.escape(
            f"{other}: its section model differs from the one of {smallest} (fh = 2.1 "
            "against 2); identify one section model at a time")):
        campaign_section([read_run(smallest), read_run(other)])
    with pytest.raises(FileFormatError, match="given twice: its releases would count twice"):
        campaign_section([read_run(smallest), read_run(smallest)])
