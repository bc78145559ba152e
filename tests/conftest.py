"""Suite-wide pytest hygiene for windrig.

- Every test must stop the threads it starts (autouse ``no_leaked_threads``), in the manner of
  pymodbus's ``system_health_check``: a leaked reader thread keeps a port open and makes later
  tests flaky.
- ``wait_until(condition, what, timeout_s)`` (fixture): the one poll for what another thread or
  process delivers, failing with ``what`` at its deadline, instead of a fixed sleep.
- Tests that stream in real time (sockets, the simulated rig, threads with deadlines, real
  clocks, Qt timers, Dask clusters) carry ``pytestmark = pytest.mark.realtime``: ``make test``
  runs them in one process beside the pure tests, which run on two workers at the lowest CPU
  priority. ``test_suite_split.py`` fails on a module that shows such a sign without the mark.
- What many test modules share (the flat-plate section, the config paths, the fast fan, run
  files) is written once in the package ``tests/support`` (on the ``pythonpath``).
- Hardware tests (``@pytest.mark.hardware``) run only with ``--rig-config PATH``; without it they
  are skipped, and the ``rig_config`` fixture gives them the path (pymeasure's ``conftest.py``).
- Hypothesis draws the same examples on every run (``derandomize``): a fuzz test that passes in
  CI passes again on the next run; a new search for failures is run by hand with
  ``--hypothesis-profile=explore``.
- Ctrl-C works in the tests even when the suite was started in the background by a shell without
  job control (``make test &`` in a script, some CI runners): such a shell starts it with SIGINT
  ignored, Python then installs no KeyboardInterrupt handler, and the tests of Ctrl-C (the
  engine's ``run_until``, ``windrig simulate`` stopped by SIGINT) would hang until their timeout.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from hypothesis import settings

settings.register_profile("windrig", derandomize=True, print_blob=True)
settings.register_profile("explore", derandomize=False, max_examples=2000)
settings.load_profile("windrig")

# Headless by default, so that a bare `pytest` behaves like `make test` on a machine without a
# display (Qt aborts the whole process when it cannot open its platform). An explicit setting wins.
os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
os.environ.setdefault("MPLBACKEND", "Agg")

# Python's own handler, as in a foreground run; a child process then starts with SIGINT at its
# default again (an ignored signal stays ignored across exec, a caught one does not).
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

#: How long a test's threads get to finish after the test before they count as leaked, in s.
THREAD_GRACE_S = 2.0


def pytest_addoption(parser: pytest.Parser) -> None:
    """Add ``--rig-config PATH``, the rig description that hardware tests talk to."""
    parser.addoption(
        "--rig-config",
        metavar="PATH",
        default=None,
        help="TOML rig config of the real rig; enables tests marked 'hardware'",
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Skip tests marked ``hardware`` when no ``--rig-config`` was given."""
    if config.getoption("--rig-config") is not None:
        return
    skip = pytest.mark.skip(reason="hardware test: needs --rig-config PATH")
    for item in items:
        if item.get_closest_marker("hardware") is not None:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def rig_config(pytestconfig: pytest.Config) -> Path:
    """Path of the rig config given with ``--rig-config``; skips the test when there is none."""
    value = pytestconfig.getoption("--rig-config")
    if value is None:
        pytest.skip("hardware test: needs --rig-config PATH")
    path = Path(value)
    if not path.is_file():
        raise pytest.UsageError(f"--rig-config: no such file: {path}")
    return path


def _wait_until(condition: Callable[[], object], what: str, timeout_s: float = 10.0) -> None:
    """Poll ``condition`` until it holds; fail naming ``what`` after ``timeout_s``.

    Threads and processes deliver on their own schedule, and a loaded host takes far longer
    than an idle one: a test waits for what it needs rather than for a fixed time.
    """
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, f"{what}: not within {timeout_s:g} s"
        time.sleep(0.01)


@pytest.fixture
def wait_until() -> Callable[..., None]:
    """Return the poll ``wait_until(condition, what, timeout_s=10.0)`` (:func:`_wait_until`)."""
    return _wait_until


@pytest.fixture(autouse=True)
def no_leaked_threads() -> Iterator[None]:
    """Fail the test if it leaves threads alive (daemon or not) that were not there before it.

    Threads that existed before the test (for example those of a session-scoped fixture, which is
    set up before this one) are ignored. New threads get ``THREAD_GRACE_S`` in total to finish.
    ``threading._DummyThread`` objects stand for threads started outside Python (e.g. by Qt) that
    merely called into Python; they cannot be joined and never report finished, so they are skipped.
    """
    before = set(threading.enumerate())
    yield
    deadline = time.monotonic() + THREAD_GRACE_S
    leaked = []
    for thread in threading.enumerate():
        # tqdm's monitor: one daemon per process, started by the first progress bar and kept
        # (it holds no port or file); not a thread of ours. Likewise dask.distributed's
        # process-wide "offload" executor (one daemon thread, kept for the process's life).
        if (thread in before or isinstance(thread, threading._DummyThread)
                or type(thread).__name__ == "TMonitor"
                or thread.name.startswith("Dask-Offload")):
            continue
        thread.join(timeout=max(0.0, deadline - time.monotonic()))
        if thread.is_alive():
            leaked.append(thread)
    if leaked:
        names = ", ".join(f"{t.name} (daemon={t.daemon})" for t in leaked)
        pytest.fail(f"test left {len(leaked)} thread(s) running: {names}", pytrace=False)
