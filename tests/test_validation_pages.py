"""Every figure on the validation pages comes from a benchmark's result file.

The pages (``docs/validation/*.md``) are prose around ``{include}`` directives of
``docs/validation/results/<name>.md``; those Markdown tables are rendered from the JSON beside
them by ``benchmarks/result_files.render_markdown`` alone. So:

- each included file exists, and each result file is included by some page (none orphaned);
- each Markdown result file is exactly what rendering its JSON gives (nobody edited a figure);
- the prose itself holds no figure: no digit outside code (commands, file names) and link
  targets, except in names such as E2RFC, HDF5 or 3-DOF.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
VALIDATION = ROOT / "docs" / "validation"
RESULTS = VALIDATION / "results"
sys.path.insert(0, str(ROOT / "benchmarks"))

import result_files  # noqa: E402 - benchmarks/ is not a package

INCLUDE = re.compile(r"^```\{include\}\s+(\S+)\s*\n```", re.M)
#: Digits that are part of a name, not a figure.
NAMES = re.compile(r"\b(?:E2RFC|HDF5|NeXus|[23]-DOF|MPS4264|ILD1420|PTB330|ACS580|DSA3217)\b")
FIGURE = re.compile(r"\d")


def _pages() -> list[Path]:
    return sorted(VALIDATION.glob("*.md"))


def _prose(text: str) -> str:
    """Return the page without its includes, code blocks and inline code."""
    text = INCLUDE.sub("", text)
    text = re.sub(r"^```.*?^```", "", text, flags=re.M | re.S)
    text = re.sub(r"`[^`\n]+`", "", text)
    text = re.sub(r"\]\([^)\s]+\)", "]", text)  # a link's target is a path, not prose
    return NAMES.sub("", text)


def test_the_pages_include_result_files_that_exist_and_leave_none_out():
    included = set()
    for page in _pages():
        for target in INCLUDE.findall(page.read_text(encoding="utf-8")):
            path = (page.parent / target).resolve()
            assert path.parent == RESULTS, f"{page.name} includes {target}, not a result file"
            assert path.exists(), f"{page.name} includes {target}, which does not exist"
            included.add(path.name)
    written = {p.name for p in RESULTS.glob("*.md")}
    assert included, "the validation pages include no result file"
    assert written <= included, f"result files no page includes: {sorted(written - included)}"


def test_each_result_table_is_its_json_rendered():
    records = sorted(RESULTS.glob("*.json"))
    assert records, "no result files in docs/validation/results"
    for record_path in records:
        record = json.loads(record_path.read_text(encoding="utf-8"))
        markdown = record_path.with_suffix(".md")
        assert markdown.exists(), f"{record_path.name} has no Markdown table"
        assert markdown.read_text(encoding="utf-8") == result_files.render_markdown(record), (
            f"{markdown.name} is not {record_path.name} rendered: edited by hand, or stale")
        assert record["mode"] in result_files.MODES
        assert record["tables"], f"{record_path.name} holds no table"
    assert {p.stem for p in RESULTS.glob("*.md")} == {p.stem for p in records}


def test_the_prose_types_no_figure():
    found = []
    for page in _pages():
        for line in _prose(page.read_text(encoding="utf-8")).splitlines():
            if FIGURE.search(line):
                found.append(f"{page.name}: {line.strip()}")
    assert not found, "figures typed into the validation pages:\n" + "\n".join(found)


def test_a_typed_figure_would_be_found():
    """The check above is not blind: a figure in prose is caught, one in code is not."""
    assert FIGURE.search(_prose("The median error is 2.9 %.\n"))
    assert not FIGURE.search(_prose("Run `benchmarks/ident_accuracy.py --seeds 20` on 3-DOF.\n"))
    assert not FIGURE.search(_prose("```{include} results/x.md\n```\n"))
    assert not FIGURE.search(_prose("The [notes](../development/e2rfc_speed.md) say why.\n"))
    assert FIGURE.search(_prose("The [notes, 2 pages](../development/e2rfc_speed.md).\n"))
