"""The split of the suite into a pure and a real-time part stays honest.

``make test`` runs the tests not marked ``realtime`` on two workers at the lowest CPU priority
(nice 19), beside the ``realtime`` ones in one process at normal priority (Makefile): the pure part
only fills the cycles the real-time part leaves idle. A real-time test left unmarked would run
beside another test at full priority, or be starved at nice 19, and meet its
deadlines only while the machine happens to be idle; a flaky CI run would be the first sign. Which
modules are real-time was measured once (per test: a socket connected or bound, a thread or
process started, a sleep); this module keeps it so by reading every test module's source
(``ast``; tests/ and the example plugin's tests, the test folders of ``testpaths``) and
requiring the mark of each module that shows a sign of streaming in real time:

- it imports the simulated rig (``daq.sim``), the simulated instruments (``simulators.devices``),
  the console's live sources, the acquisition engine, or ``socket``, ``subprocess``,
  ``multiprocessing``, ``threading``, ``concurrent.futures``, ``asyncio``, ``dask``;
- a test or fixture takes ``qtbot`` (a Qt event loop and its timers) or ``wait_until`` (a poll of
  what another thread or process delivers);
- it calls ``time.sleep``.

The mark is the module's ``pytestmark`` (``pytestmark = pytest.mark.realtime``, or a list that
holds it). A module with such a sign that is pure all the same is listed in ``PURE_DESPITE`` with
the reason. The converse (a marked module with no sign, e.g. one that runs ``windrig demo``
through ``daq.cli.main``) is the measurement's call and is not checked.
"""

from __future__ import annotations

import ast
import re
import tomllib
from pathlib import Path

import pytest

from support.configs import REPO

#: Imports (a module or any submodule of it) that stream in real time.
REALTIME_IMPORTS = (
    "daq.sim", "simulators.devices", "daq.console.live_source", "daq.console.process_source",
    "daq.acquisition.engine", "socket", "subprocess", "multiprocessing", "threading",
    "concurrent.futures", "asyncio", "dask", "distributed",
)
#: Fixtures whose tests run a real event loop or poll another thread.
REALTIME_FIXTURES = frozenset({"qtbot", "wait_until"})

#: Modules with a sign of real time that are pure all the same, and why.
PURE_DESPITE = {
    # `git ls-files` once (the tracked files); the simulators' fault tables are read, none started.
    "tests/test_repository.py": "runs git once; reads the simulated instruments' fault names",
    # The laser simulator's noise model, called as a function: no server is started.
    "tests/simulators/test_noise.py": "calls the laser simulator's noise model, starts no server",
    # The live config is text: the simulated rig's URLs written into a copy of the config.
    "tests/daq/sim/test_live_config.py": "daq.sim.live_config rewrites TOML text, starts nothing",
    # The run writer fed synthetic documents; record_simulated_run only refuses an existing
    # file, before it would start the simulated rig.
    "tests/daq/recording/test_writer.py": "record_simulated_run refuses before the rig starts",
    # The simulators' entry points are looked up (daq.sim.devices), none is started.
    "tests/daq/instruments/test_plugins.py": "looks up simulator entry points, starts none",
}


def realtime_signs(source: str) -> list[str]:
    """Return what in a test module's source streams in real time (empty for a pure module)."""
    signs: set[str] = set()

    def imported(name: str) -> None:
        for prefix in REALTIME_IMPORTS:
            if name == prefix or name.startswith(prefix + "."):
                signs.add(f"imports {prefix}")

    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                imported(alias.name)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            imported(node.module)
            for alias in node.names:
                imported(f"{node.module}.{alias.name}")
                if node.module == "time" and alias.name == "sleep":
                    signs.add("calls time.sleep")
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            for arg in node.args.args + node.args.kwonlyargs:
                if arg.arg in REALTIME_FIXTURES:
                    signs.add(f"uses the {arg.arg} fixture")
        elif (isinstance(node, ast.Attribute) and node.attr == "sleep"
              and isinstance(node.value, ast.Name) and node.value.id == "time"):
            signs.add("calls time.sleep")
    return sorted(signs)


def is_marked_realtime(source: str) -> bool:
    """Return whether the module's ``pytestmark`` (a mark or a list of marks) holds ``realtime``."""
    for node in ast.parse(source).body:
        if isinstance(node, ast.Assign) and any(
                isinstance(target, ast.Name) and target.id == "pytestmark"
                for target in node.targets):
            marks = node.value.elts if isinstance(node.value, ast.List | ast.Tuple) else [
                node.value]
            return any(isinstance(mark, ast.Attribute) and mark.attr == "realtime"
                       for mark in marks)
    return False


def unmarked_realtime_modules(root: Path, folders: tuple[str, ...] = ("tests",)) -> list[str]:
    """Return each test module in ``folders`` of ``root`` that shows real time but is unmarked."""
    problems = []
    paths = sorted(path for folder in folders for path in root.glob(f"{folder}/**/test_*.py"))
    for path in paths:
        name = path.relative_to(root).as_posix()
        source = path.read_text(encoding="utf-8")
        signs = realtime_signs(source)
        if signs and name not in PURE_DESPITE and not is_marked_realtime(source):
            problems.append(f"{name}: {', '.join(signs)}")
    return problems


def test_every_real_time_test_module_is_marked_realtime():
    """Every test folder of ``testpaths`` counts: tests/ and the example plugin's tests."""
    options = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["pytest"][
        "ini_options"]
    folders = tuple(path for path in options["testpaths"]
                    if path == "tests" or path.endswith("/tests"))
    assert "tests" in folders
    problems = unmarked_realtime_modules(REPO, folders)
    assert not problems, (
        "test modules that stream in real time but are not marked "
        "(add `pytestmark = pytest.mark.realtime`, or list a pure one in PURE_DESPITE):\n"
        + "\n".join(problems))


def test_the_exemptions_still_exist_and_still_need_to_be():
    for name in PURE_DESPITE:
        path = REPO / name
        assert path.is_file(), f"PURE_DESPITE names {name}, which no longer exists"
        source = path.read_text(encoding="utf-8")
        assert realtime_signs(source), f"{name} shows no sign of real time: drop its exemption"
        assert not is_marked_realtime(source), f"{name} is marked realtime: drop its exemption"


@pytest.mark.parametrize(("source", "signs"), [
    ("import socket\n\ndef test_x():\n    pass\n", ["imports socket"]),
    ("from daq.sim.rig import start_simulated_rig\n", ["imports daq.sim"]),
    ("from simulators import devices\n", ["imports simulators.devices"]),
    ("import time\n\ndef test_x():\n    time.sleep(0.1)\n", ["calls time.sleep"]),
    ("def test_x(qtbot):\n    pass\n", ["uses the qtbot fixture"]),
    ("import pytest\n\n@pytest.fixture\ndef f(wait_until):\n    pass\n",
     ["uses the wait_until fixture"]),
    ("import numpy as np\nfrom ident.model import flat_plate\n", []),
    ("from daq.simulation_helpers import x\n", []),  # a prefix of a name is not the module
])
def test_the_signs_are_found_and_only_they(source, signs):
    assert realtime_signs(source) == signs


def test_a_real_time_module_without_the_mark_fails_the_check(tmp_path):
    """The check itself can fail: a socket test unmarked, then marked, then marked in a list."""
    suite = tmp_path / "suite"
    suite.mkdir()
    module = suite / "test_new.py"
    module.write_text("import socket\n\ndef test_x():\n    socket.socket().close()\n")
    assert unmarked_realtime_modules(tmp_path, ("suite",)) == ["suite/test_new.py: imports socket"]
    module.write_text("import socket\n\nimport pytest\n\npytestmark = pytest.mark.realtime\n")
    assert unmarked_realtime_modules(tmp_path, ("suite",)) == []
    module.write_text("import socket\n\nimport pytest\n\n"
                      "pytestmark = [pytest.mark.slow, pytest.mark.realtime]\n")
    assert unmarked_realtime_modules(tmp_path, ("suite",)) == []
    module.write_text("import socket\n\nimport pytest\n\npytestmark = pytest.mark.slow\n")
    assert unmarked_realtime_modules(tmp_path, ("suite",)) == ["suite/test_new.py: imports socket"]


def test_the_marker_is_registered_and_make_test_splits_by_it():
    """The marker is registered (with --strict-markers); the Makefile runs both parts by it."""
    options = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["pytest"][
        "ini_options"]
    assert "--strict-markers" in options["addopts"]
    assert any(line.startswith("realtime:") for line in options["markers"])
    makefile = (REPO / "Makefile").read_text()
    pure = re.search(r"^PURE_TESTS := ((?:.*\\\n)*.*)$", makefile, re.M)
    realtime = re.search(r"^REALTIME_TESTS := (.*)$", makefile, re.M)
    assert pure and " -n 2 " in pure.group(1) and '-m "not realtime"' in pure.group(1)
    assert realtime and "-m realtime" in realtime.group(1)
    assert not re.search(r"\s-n\s", realtime.group(1))  # the real-time part runs alone
    test_recipe = makefile.split("\ntest: ", 1)[1].split("\n\n", 1)[0]
    assert "$(PURE_TESTS)" in test_recipe and "$(REALTIME_TESTS)" in test_recipe
    # Beside the real-time part, the pure part yields every core a deadline wants.
    assert "nice -n 19 $(PURE_TESTS)" in test_recipe
    assert re.search(r"^\t\$\(REALTIME_TESTS\)", test_recipe, re.M)  # at normal priority
    fast_recipe = makefile.split("\ntest-fast: ", 1)[1].split("\n\n", 1)[0]
    assert "$(PURE_TESTS)" in fast_recipe and "$(REALTIME_TESTS)" not in fast_recipe
