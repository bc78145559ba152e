"""The architecture of daq/, ident/ and simulators/ as rules on their import graph.

The graph is built from the source with :mod:`ast`: every ``import`` and ``from ... import``
of a first-party module, at module level, inside functions and under ``TYPE_CHECKING`` alike
(a function-level import is still a dependency; it only hides a cycle). The rules
(``docs/architecture.md`` states them for readers):

- no import cycle among the modules of daq;
- ident imports nothing from daq or simulators; simulators imports nothing from daq;
- daq.recording and daq.acquisition import nothing from daq.sim or simulators (the production
  recording path knows no simulator);
- a package's ``__init__.py`` has a docstring (the map of its modules) and imports nothing, so
  that importing one module of a package never imports its siblings;
- no module of daq imports a private name (``_x``) from another module;
- no module of daq is longer than 600 lines unless its docstring has a paragraph starting
  ``Longer than 600 lines:`` that says why;
- every exception class of daq is defined in :mod:`daq.errors`;
- daq's packages form layers (:data:`LAYERS`): a module imports from its own layer or below.
"""

from __future__ import annotations

import ast
import importlib
import inspect
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PACKAGES = ("daq", "ident", "simulators")
MAX_LINES = 600
LONG_MARKER = "Longer than 600 lines:"
#: daq's layers, bottom first (``docs/architecture.md``): a module may import from its own layer
#: and from the layers below. ``daq.instruments.build`` (a configured instrument's driver) sits
#: above the rig config, which validates instrument tables through the driver registry.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("daq.errors", "daq.validation", "daq.log_file", "ident"),
    ("daq.transports",),
    ("daq.instruments",),
    ("daq.config", "daq.tubing_config", "daq.calibration", "daq.procedure",
     "daq.instruments.build"),
    ("daq.sync",),
    ("daq.acquisition",),
    ("daq.recording",),
    ("daq.sim", "daq.offline", "daq.campaign", "simulators"),
    ("daq.console", "daq.cli"),
)


def _module_name(path: Path) -> str:
    parts = path.relative_to(REPO).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for pkg in PACKAGES for p in sorted((REPO / pkg).rglob("*.py"))}


MODULES = _modules()


def _imports(name: str, path: Path) -> Iterator[tuple[str, str, int]]:
    """Yield ``(imported module, imported name or "", line)`` of every first-party import."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] in PACKAGES:
                    yield alias.name, "", node.lineno
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                module = ".".join([*base, *([node.module] if node.module else [])])
            else:
                module = node.module or ""
            if module.split(".")[0] not in PACKAGES:
                continue
            for alias in node.names:
                yield module, alias.name, node.lineno


def _graph() -> dict[str, set[str]]:
    """Return module -> the first-party modules it imports (``from`` a package: its module)."""
    edges: dict[str, set[str]] = {name: set() for name in MODULES}
    for name, path in MODULES.items():
        for module, imported, _ in _imports(name, path):
            target = f"{module}.{imported}" if f"{module}.{imported}" in MODULES else module
            if target != name:
                edges[name].add(target)
    return edges


GRAPH = _graph()


def _cycles(nodes: set[str]) -> list[list[str]]:
    """Return the strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(GRAPH.get(v, set()) & nodes):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(nodes):
        if v not in index:
            visit(v)
    return found


def _in(module: str, *packages: str) -> bool:
    return any(module == p or module.startswith(p + ".") for p in packages)


def test_no_import_cycle_among_daq_modules():
    daq_modules = {m for m in MODULES if _in(m, "daq")}
    assert _cycles(daq_modules) == []


def test_the_graph_sees_function_level_imports():
    """A cycle hidden in a function still counts (the test's own premise, checked)."""
    assert "daq.sim.rig" in GRAPH["daq.sim.rig_process"]  # imported inside the child's target


@pytest.mark.parametrize(("importer", "forbidden"), [
    ("ident", ("daq", "simulators")),
    ("simulators", ("daq",)),
    ("daq.recording", ("daq.sim", "simulators")),
    ("daq.acquisition", ("daq.sim", "simulators")),
])
def test_layer_rules(importer, forbidden):
    broken = sorted(f"{m} imports {t}" for m, targets in GRAPH.items() if _in(m, importer)
                    for t in targets if _in(t, *forbidden))
    assert broken == []


def _layer(module: str) -> int | None:
    """Return the layer of ``module`` (its longest matching prefix), or None (``daq`` itself)."""
    found = [(len(p), i) for i, names in enumerate(LAYERS) for p in names if _in(module, p)]
    return max(found)[1] if found else None


def test_layers_only_import_downwards():
    upward = []
    for module, targets in GRAPH.items():
        if not _in(module, "daq"):
            continue
        own = _layer(module)
        for target in targets:
            theirs = _layer(target)
            if own is not None and theirs is not None and theirs > own:
                upward.append(f"{module} ({own}) imports {target} ({theirs})")
    assert upward == []
    unplaced = sorted(m for m in MODULES if _in(m, "daq") and m != "daq" and _layer(m) is None)
    assert unplaced == []


def test_packages_have_a_map_and_import_nothing():
    for name, path in MODULES.items():
        if path.name != "__init__.py" or not _in(name, "daq"):
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        assert ast.get_docstring(tree), f"{name}: no docstring (the package's map)"
        imports = [n for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom))
                   and not (isinstance(n, ast.ImportFrom) and n.module == "__future__")]
        assert imports == [], f"{name}/__init__.py imports something"


def test_no_cross_module_private_imports_in_daq():
    broken = []
    for name, path in MODULES.items():
        if not _in(name, "daq"):
            continue
        for module, imported, line in _imports(name, path):
            private = [part for part in (*module.split("."), imported)
                       if part.startswith("_") and not part.startswith("__")]
            if private and module != name:
                broken.append(f"{path.relative_to(REPO)}:{line}: {module} {imported}")
    assert broken == []


def test_long_modules_say_why():
    """Every module of daq, ident and simulators over 600 lines says why at its top."""
    broken = []
    for name, path in MODULES.items():
        text = path.read_text(encoding="utf-8")
        lines = text.count("\n")
        doc = ast.get_docstring(ast.parse(text)) or ""
        if lines > MAX_LINES and not any(p.startswith(LONG_MARKER) for p in doc.split("\n\n")):
            broken.append(f"{name}: {lines} lines")
    assert broken == []


def test_every_daq_exception_is_defined_in_daq_errors():
    errors = importlib.import_module("daq.errors")
    elsewhere = []
    for name in MODULES:
        if not _in(name, "daq") or name == "daq.errors":
            continue
        module = importlib.import_module(name)
        for cls_name, cls in inspect.getmembers(module, inspect.isclass):
            if issubclass(cls, BaseException) and cls.__module__ == name:
                elsewhere.append(f"{name}.{cls_name}")
    assert elsewhere == []
    assert set(errors.__all__) == {n for n, c in inspect.getmembers(errors, inspect.isclass)
                                   if issubclass(c, BaseException)
                                   and c.__module__ == "daq.errors"}
