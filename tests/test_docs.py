"""The documentation site's API reference leaves no public module out.

``docs/_apiref.py`` finds the modules from the source tree; here they are found a second way,
by importing the packages and walking them (:func:`pkgutil.walk_packages`), and every one must
have a page that documents it and that links reach from the reference's index (the module
pages are orphans linked by ``:doc:``, not entries of a table of contents: docs/_apiref.py says
why). ``make docs`` (in CI) builds the pages with warnings as errors.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "docs"))

import _apiref  # noqa: E402 - docs/ is not a package


def _walked_public_modules() -> set[str]:
    found = set()
    for name in _apiref.PACKAGES:
        package = importlib.import_module(name)
        found.add(name)
        for info in pkgutil.walk_packages(package.__path__, prefix=f"{name}."):
            if not any(part.startswith("_") for part in info.name.split(".")):
                found.add(info.name)
    return found


@pytest.fixture(scope="module")
def pages(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    out = tmp_path_factory.mktemp("api")
    _apiref.write_pages(out)
    return {p.stem: p.read_text(encoding="utf-8") for p in out.glob("*.rst")}


def test_the_reference_finds_the_modules_that_importing_finds():
    walked = _walked_public_modules()
    listed = set(_apiref.public_modules())
    assert walked == listed, (f"missing from the reference: {sorted(walked - listed)}; "
                              f"not modules: {sorted(listed - walked)}")
    assert len(listed) > 200  # daq, ident and simulators hold well over 200 today


def test_every_public_module_has_a_page_reached_from_the_index(pages):
    reached, todo = set(), ["index"]
    while todo:
        page = todo.pop()
        reached.add(page)
        for entry in re.findall(r"^ *- :doc:`([^`]+)`$", pages[page], flags=re.M):
            if entry in pages and entry not in reached:
                todo.append(entry)
    problems = []
    for module in _apiref.public_modules():
        if module not in pages:
            problems.append(f"{module}: no page")
        elif f".. automodule:: {module}\n" not in pages[module]:
            problems.append(f"{module}: its page does not document it")
        elif module not in reached:
            problems.append(f"{module}: not reached from the index")
        elif not pages[module].startswith(":orphan:\n"):
            problems.append(f"{module}: not marked an orphan (Sphinx would warn)")
    assert not problems, "\n".join(problems)


def test_a_name_left_out_of_a_page_is_defined_in_another_module():
    """What a page excludes as re-exported is documented where it is defined, not lost."""
    problems = []
    for module in _apiref.public_modules():
        mod = importlib.import_module(module)
        for name in _apiref.reexported_names(module):
            obj = getattr(mod, name)
            home = getattr(obj, "__module__", None)
            if (inspect.isclass(obj) or inspect.isfunction(obj)) and home == module:
                problems.append(f"{module}.{name} is defined there but left out")
    assert not problems, "\n".join(problems)


def test_a_module_defining_a_name_of_its_all_keeps_it():
    """Names that a module defines are never excluded (the check above's converse)."""
    excluded = _apiref.reexported_names("ident.identification.results")
    assert "distinct_wind_speeds" in excluded  # imported from uncertainty, exported again
    assert "E2RFCDiagnostics" not in excluded
