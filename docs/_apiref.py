"""The API reference's pages, written before each build from the source tree.

One page per public module of daq, ident and simulators (a module is public when no part of
its dotted name starts with an underscore). A page documents the names the module itself
defines (autodoc's ``:members:``, which follows ``__all__``), less the names of ``__all__`` it
imports: a name a package or module only re-exports is documented where it is defined, so that
each object has one page and a cross-reference one target.

The index links the packages, and each package page its modules, by plain links (``:doc:``),
not by a table of contents: the module pages are orphans (``:orphan:``). The theme (furo)
draws the whole table of contents into every page's sidebar, the source pages included, so
some 250 module entries there cost every one of some 580 pages: about three of the build's
four minutes. The sidebar shows the index; the pages are reached from it, and from search.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("daq", "ident", "simulators")
TITLES = {
    "daq": "daq: instruments, acquisition, recording, campaigns, console",
    "ident": "ident: models, identification, simulation, bridge",
    "simulators": "simulators: the virtual tunnel and its instruments",
}


def public_modules(root: Path = ROOT) -> list[str]:
    """Return the dotted names of the public modules of daq, ident and simulators, sorted."""
    names = []
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            if any(p.startswith("_") for p in parts):
                continue
            names.append(".".join(parts))
    return sorted(names)


def _source(module: str, root: Path = ROOT) -> Path:
    path = root.joinpath(*module.split("."))
    return path / "__init__.py" if path.is_dir() else path.with_suffix(".py")


def _defined_names(tree: ast.Module) -> list[str]:
    """Names bound at a module's top level by a def, class or assignment, in source order."""
    names: list[str] = []
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.append(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.append(node.target.id)
        elif isinstance(node, ast.Assign):
            names.extend(t.id for t in node.targets if isinstance(t, ast.Name))
    return names


def _exported(tree: ast.Module) -> list[str] | None:
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets):
            return [str(ast.literal_eval(e)) for e in node.value.elts]  # type: ignore[attr-defined]
    return None


def reexported_names(module: str, root: Path = ROOT) -> list[str]:
    """Return the names of a module's ``__all__`` that it imports rather than defines.

    autodoc documents every name of ``__all__``; these are excluded from the module's page
    (their own module's page documents them). Without ``__all__`` autodoc itself leaves
    imported classes and functions out.
    """
    tree = ast.parse(_source(module, root).read_text(encoding="utf-8"))
    exported = _exported(tree) or []
    defined = set(_defined_names(tree))
    return [n for n in exported if n not in defined]


def _page(module: str, modules: list[str]) -> str:
    title = f"``{module}``"
    lines = [":orphan:", "", title, "=" * len(title), ""]
    children = [m for m in modules if m.rpartition(".")[0] == module]
    if children:  # before the members: a package's page opens with its modules
        lines += ["Modules:", ""] + [f"- :doc:`{child}`" for child in children] + [""]
    lines += [f".. automodule:: {module}", "   :members:"]
    reexported = reexported_names(module)
    if reexported:
        lines.append(f"   :exclude-members: {', '.join(reexported)}")
    return "\n".join(lines) + "\n"


def write_pages(out: Path) -> None:
    """Write ``out/<module>.rst`` for every public module and ``out/index.rst``; prune others."""
    out.mkdir(parents=True, exist_ok=True)
    modules = public_modules()  # one walk of the source tree, not one per page
    wanted = {f"{m}.rst": _page(m, modules) for m in modules}
    index = ["API reference", "=============", "",
             "One page per public module, from its docstrings (numpydoc). Units are SI unless a "
             "docstring says otherwise; the conventions are those of "
             ":doc:`/reference/conventions`.",
             ""]
    for package in PACKAGES:
        index += [TITLES[package], "-" * len(TITLES[package]), "", f"- :doc:`{package}`", ""]
        index += [f"  - :doc:`{m}`" for m in modules if m.count(".") == 1
                  and m.startswith(f"{package}.")] + [""]
    wanted["index.rst"] = "\n".join(index)
    for name, text in wanted.items():
        path = out / name
        if not path.exists() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")  # unchanged pages keep their time stamps
    for stale in {p.name for p in out.glob("*.rst")} - set(wanted):
        (out / stale).unlink()
