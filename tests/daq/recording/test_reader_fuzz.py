"""The run-file readers on damaged files: a specific error or a result, never a hang or crash.

Hypothesis damages a real run file (bytes set, the file truncated, blocks zeroed) and a child
process (``_reader_fuzz_child.py``) runs ``read_run`` (what ``identify``, ``diagnose`` and
``reprocess`` read through), ``run_info`` (``windrig info``) and ``recover_run`` (``windrig
recover``) on it, each under a watchdog. Allowed: a result, or the readers' own errors
(:class:`~ident.records.run_file.FileFormatError`, :class:`~daq.errors.NotARunFileError`,
:class:`~daq.errors.RecoveryError`, all of which the command line prints as one ``error:``
line). A crash of the child or a call past the watchdog fails the example.

Found by this test (issue 17), and fixed: a damaged closed file took minutes to fail, because the
readers opened every file as a SWMR reader, which retries each metadata block whose checksum
fails, with pauses (they now open a file as a SWMR reader only when a writer has it open); h5py's
RuntimeError (a damaged link) and KeyError (a damaged object header) escaped ``windrig info``
and ``recover`` as tracebacks.

The gap it marks: libhdf5 2.0 itself can loop for minutes, holding the interpreter, on some
damage, e.g. reading a variable-length string (``/entry/config``) whose global-heap reference
was zeroed (15 bytes at offset 2058 of this test's base file; found with
``--hypothesis-seed=3``). A reader in the same process cannot interrupt it. The watchdog ends
such a call; an example whose stack shows it stuck inside h5py is rejected (``reject()``, with
the stack in the notes), every other hang or crash fails.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, note, reject, settings
from hypothesis import strategies as st

from daq.config import load_rig_config
from daq.recording.synthetic import write_release_run
from ident import Release
from ident.model import flat_plate
from simulators import simulate_release

from support.configs import SIM_FLAT_PLATE
from support.sections import FLAT_PLATE

pytestmark = pytest.mark.realtime

CHILD = Path(__file__).with_name("_reader_fuzz_child.py")
CONFIG = SIM_FLAT_PLATE
#: Longest a reader may take on one damaged file, s (they take milliseconds).
WATCHDOG_S = 5.0
ALLOWED = ("ok", "ident.records.run_file.FileFormatError:", "daq.errors.NotARunFileError:",
           "daq.errors.RecoveryError:")

mutations = st.lists(st.one_of(
    st.tuples(st.just("set"), st.integers(0, 2**20), st.integers(0, 255)),
    st.tuples(st.just("truncate"), st.integers(0, 2**20)),
    st.tuples(st.just("zero"), st.integers(0, 2**20), st.integers(1, 4096)),
), min_size=1, max_size=8)


class HDF5Hang(Exception):
    """The watchdog ended a reader stuck inside libhdf5 (the known gap; module docstring)."""


class Child:
    """The reader process, restarted after it dies."""

    def __init__(self, base: Path, work: Path) -> None:
        self.base, self.work = base, work
        self.proc: subprocess.Popen[str] | None = None

    def run(self, mutation: list[tuple[object, ...]]) -> dict[str, str]:
        if self.proc is None or self.proc.poll() is not None:
            self.proc = subprocess.Popen(
                [sys.executable, str(CHILD), str(self.base), str(self.work), str(WATCHDOG_S)],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(json.dumps(mutation) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            _, stderr = self.proc.communicate()  # reads to the end and closes the pipes
            code = self.proc.returncode
            self.proc = None
            stack = [frame for frame in stderr.splitlines() if frame.strip().startswith("File ")]
            if "Timeout" in stderr and stack and "/h5py/" in stack[0]:
                raise HDF5Hang(f"libhdf5 did not return within {WATCHDOG_S:g} s on {mutation}:"
                               f"\n{stderr[-2000:]}")
            raise AssertionError(f"the readers crashed (exit status {code}) or hung outside "
                                 f"HDF5 on {mutation}:\n{stderr[-3000:]}")
        return json.loads(line)

    def close(self) -> None:
        if self.proc is not None:
            self.proc.kill()
            self.proc.communicate()


@pytest.fixture(scope="module")
def child(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Child]:
    work = tmp_path_factory.mktemp("fuzz")
    section = FLAT_PLATE
    releases = [Release.from_simulation(simulate_release(
        section, flat_plate.jones_model(), 5.0, 0.004, 0.02, duration=3.0, fs=250.0))]
    base = work / "base.h5"
    write_release_run(base, load_rig_config(CONFIG), releases)
    runner = Child(base, work)
    yield runner
    runner.close()


def test_the_undamaged_file_reads(child):
    assert child.run([]) == {"read_run": "ok", "info": "ok", "recover": "ok"}


@settings(max_examples=150, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(mutation=mutations)
def test_a_damaged_file_gives_a_result_or_a_specific_error(child, mutation):
    try:
        result = child.run([list(m) for m in mutation])
    except HDF5Hang as hang:
        note(str(hang))
        reject()  # the known gap (module docstring): not windrig's to fix, counted by hypothesis
    else:
        for reader, outcome in result.items():
            assert outcome.startswith(ALLOWED), (reader, outcome, mutation)
