"""The repository is self-contained: its files refer to nothing outside it, and to docs that exist.

Every tracked text file (``git ls-files``: ``*.py``, ``*.md``, ``*.toml``, the Makefile and
``.ci/*``) is read. A failure names the file and the line, so that the stale reference can be
fixed where it is.

- No file cites the design notes that were kept outside the repository (the upper-case design,
  devices and style notes, or a ``shared`` folder beside the checkout). What those notes said that
  the code relies on is stated in ``docs/``, or in the docstring itself.
- Every ``docs/<name>.md`` a file mentions exists; where the mention names a section
  (``docs/reference/wire_formats.md, "Fan drive"``), one of that page's headings contains the name.
- Every file path under the top-level folders that a file mentions (a module of ``daq``, a test
  module, a rig config) exists.
- ``docs/`` names every fault the simulators inject and every named effect.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

#: Citations of notes outside the repository (spelled so that this file does not match itself).
_SHARED = "sha" + "red"  # split, so that the pattern's own source does not match it
OUTSIDE = re.compile(r"\b(?:DESIGN|DEVICES|STYLE)\.md\b|\.\./" + _SHARED + r"\b|/work/"
                     + _SHARED + r"\b")

#: ``docs/<name>.md``, optionally followed by a quoted section name (which may wrap a line).
DOC_REFERENCE = re.compile(
    r"\bdocs/(?P<page>(?:[A-Za-z0-9_-]+/)*[A-Za-z0-9_.-]+?\.md)\b"
    r"(?:`{0,2},?(?:\s|#:?)+\"(?P<section>[^\"]{1,80})\")?"
)

#: A path under one of the repository's top-level folders, to a file of a tracked kind.
REPO_PATH = re.compile(
    r"(?<![\w./-])(?:daq|ident|simulators|tests|benchmarks|rig_configs|docs)"
    r"/[A-Za-z0-9_/.-]*?\.(?:py|md|toml|png)\b"
)


def _is_text_file(path: str) -> bool:
    return (path.endswith((".py", ".md", ".toml")) or path == "Makefile"
            or path.startswith(".ci/"))


@cache
def tracked_text_files() -> tuple[str, ...]:
    """Return the tracked text files, relative to the repository root."""
    git = shutil.which("git")
    if git is not None and (ROOT / ".git").exists():
        out = subprocess.run([git, "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True)
        files = [name for name in out.stdout.decode().split("\0") if name]
    else:  # an unpacked source tree: every file outside the build and cache folders
        skip = {".git", ".venv", "build", "demo_output", "__pycache__", ".mypy_cache",
                ".ruff_cache", ".pytest_cache", ".hypothesis"}
        files = [str(path.relative_to(ROOT)) for path in ROOT.rglob("*")
                 if not skip & set(path.relative_to(ROOT).parts)
                 and not path.name.endswith(".egg-info")]
    return tuple(sorted(name for name in files
                        if _is_text_file(name) and (ROOT / name).is_file()))


def _line_of(text: str, offset: int) -> int:
    return text.count("\n", 0, offset) + 1


def _headings(page: Path) -> list[str]:
    """Return the page's headings (any level), whitespace collapsed, lower case."""
    return [" ".join(m.group(1).split()).lower()
            for m in re.finditer(r"^#{1,6}\s+(.+)$", page.read_text(encoding="utf-8"), re.M)]


def _section_name(raw: str) -> str:
    """Return a quoted section name without its line breaks and comment markers, lower case."""
    return " ".join(re.sub(r"\n\s*(?:#:?)?", " ", raw).split()).lower()


def test_the_text_files_are_found():
    files = tracked_text_files()
    assert "Makefile" in files and "README.md" in files and "pyproject.toml" in files
    assert any(name.startswith(".ci/") for name in files)


def test_no_file_refers_to_notes_outside_the_repository():
    hits = []
    for name in tracked_text_files():
        for number, line in enumerate((ROOT / name).read_text(encoding="utf-8").splitlines(), 1):
            if OUTSIDE.search(line):
                hits.append(f"{name}:{number}: {line.strip()}")
    assert not hits, "references to files outside the repository:\n" + "\n".join(hits)


def test_every_docs_page_and_section_mentioned_exists():
    headings = {page.relative_to(DOCS).as_posix(): _headings(page)
                for page in DOCS.rglob("*.md") if "_build" not in page.parts}
    problems = []
    for name in tracked_text_files():
        text = (ROOT / name).read_text(encoding="utf-8")
        for m in DOC_REFERENCE.finditer(text):
            where = f"{name}:{_line_of(text, m.start())}"
            page = m.group("page")
            if page not in headings:
                problems.append(f"{where}: docs/{page} does not exist")
                continue
            section = m.group("section")
            if section is not None and not any(_section_name(section) in heading
                                               for heading in headings[page]):
                problems.append(f"{where}: docs/{page} has no section {section!r}")
    assert not problems, "stale references to docs/:\n" + "\n".join(problems)


def test_every_repository_path_mentioned_exists():
    missing = []
    for name in tracked_text_files():
        text = (ROOT / name).read_text(encoding="utf-8")
        for m in REPO_PATH.finditer(text):
            if not (ROOT / m.group(0)).exists():
                missing.append(f"{name}:{_line_of(text, m.start())}: {m.group(0)}")
    assert not missing, "paths that do not exist:\n" + "\n".join(missing)


def test_the_docs_name_every_simulated_fault_and_named_effect():
    from ident.physics.effects import EFFECT_NAMES
    from simulators.devices import abb_acs580, modbus_plc, vaisala_ptb330
    from simulators.devices.scanivalve_mps4264 import scanner as scanivalve_mps4264

    wire = (DOCS / "reference" / "wire_formats.md").read_text(encoding="utf-8")
    faults = wire[wire.index("## Faults the simulators inject"):]
    conventions = (DOCS / "reference" / "conventions.md").read_text(encoding="utf-8")
    effects = conventions[conventions.index("## Named effects"):]
    missing = [f"wire_formats.md: {module.__name__} fault {fault!r}"
               for module in (abb_acs580, modbus_plc, scanivalve_mps4264, vaisala_ptb330)
               for fault in module.FAULTS if f"`{fault}`" not in faults]
    missing += [f"conventions.md: effect {effect!r}" for effect in EFFECT_NAMES
                if f"`{effect}`" not in effects]
    assert not missing, "not in docs/:\n" + "\n".join(missing)
