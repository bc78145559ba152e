"""The architecture of daq/, ident/ and simulators/ as rules on their import graph.

The graph is built from the source with :mod:`ast`: every ``import`` and ``from ... import``
of a first-party module, at module level, inside functions and under ``TYPE_CHECKING`` alike
(a function-level import is still a dependency; it only hides a cycle). The rules
(``docs/reference/architecture.md`` states them for readers):

- no import cycle among the modules of daq, ident and simulators;
- ident imports nothing from daq or simulators; simulators imports nothing from daq;
- daq.recording and daq.acquisition import nothing from daq.sim or simulators (the production
  recording path knows no simulator);
- each package's subpackages form layers (:data:`DAQ_LAYERS`, :data:`IDENT_LAYERS`,
  :data:`SIMULATORS_LAYERS`): a module imports from its own layer or below, and every module
  has a layer;
- a subpackage's ``__init__.py`` has a docstring (the map of its modules) and imports nothing,
  so that importing one module of a package never imports its siblings (the top-level
  ``ident`` and ``simulators`` re-export the names scripts start from);
- no module of daq imports a private name (``_x``) from another module; no module of ident or
  simulators imports one from another subpackage (a subpackage's private machinery is its own);
- no module is longer than 600 lines unless its docstring has a paragraph starting
  ``Longer than 600 lines:`` that says why, and none is longer than 800;
- daq has at most eight top-level modules (the rest lives in its subpackages);
- every exception class of daq is defined in :mod:`daq.errors`.

Each checker is a function of a source tree, so that the tests at the end show it failing on a
deliberately broken tree.
"""

from __future__ import annotations

import ast
import importlib
import inspect
from collections.abc import Iterator, Sequence
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("daq", "ident", "simulators")
MAX_LINES = 600
HARD_MAX_LINES = 800
LONG_MARKER = "Longer than 600 lines:"
MAX_DAQ_TOP_LEVEL_MODULES = 8
#: Top-level packages whose ``__init__`` re-exports public names (their subpackages' do not).
FACADES = ("ident", "simulators")

#: daq's layers, bottom first (``docs/reference/architecture.md``): a module may import from its own
#: layer and from the layers below. ``daq.instruments.build`` (a configured instrument's driver)
#: sits above the rig config, which validates instrument tables through the driver registry.
DAQ_LAYERS: tuple[tuple[str, ...], ...] = (
    ("daq.errors", "daq.validation", "daq.log_file", "ident"),
    ("daq.transports",),
    ("daq.instruments",),
    ("daq.config", "daq.tubing_config", "daq.calibration", "daq.procedure",
     "daq.instruments.build", "daq.testing"),
    ("daq.sync",),
    ("daq.acquisition",),
    ("daq.recording",),
    ("daq.sim", "daq.offline", "daq.campaign", "daq.exchange", "simulators"),
    ("daq.console", "daq.cli"),
)
#: ident's layers, bottom first.
IDENT_LAYERS: tuple[tuple[str, ...], ...] = (
    ("ident.errors", "ident.numerics"),
    ("ident.model",),
    ("ident.tables",),
    ("ident.physics",),
    ("ident.simulation",),
    ("ident.records",),
    ("ident.identification",),
    ("ident.discrepancy", "ident.bridge"),
)
#: simulators' layers, bottom first (ident, which it may import, lies below them all).
SIMULATORS_LAYERS: tuple[tuple[str, ...], ...] = (
    ("ident",),
    ("simulators.clock", "simulators.noise", "simulators.tubing", "simulators.effects",
     "simulators.decks"),
    ("simulators.tunnel", "simulators.campaigns"),
    ("simulators.virtual_tunnel",),
    ("simulators.devices", "simulators.nidaqmx_standin", "simulators.tunnel_campaigns"),
)


# --------------------------------------------------------------------------------------------
# The graph of a source tree


def module_name(root: Path, path: Path) -> str:
    """Return the dotted name of the module at ``path`` under ``root``."""
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def find_modules(root: Path, packages: Sequence[str]) -> dict[str, Path]:
    """Return dotted name -> path of every module of ``packages`` under ``root``."""
    return {module_name(root, p): p for pkg in packages for p in sorted((root / pkg).rglob("*.py"))}


def imports_of(name: str, path: Path, packages: Sequence[str]) -> Iterator[tuple[str, str, int]]:
    """Yield ``(imported module, imported name or "", line)`` of every first-party import."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] in packages:
                    yield alias.name, "", node.lineno
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                module = ".".join([*base, *([node.module] if node.module else [])])
            else:
                module = node.module or ""
            if module.split(".")[0] not in packages:
                continue
            for alias in node.names:
                yield module, alias.name, node.lineno


def import_graph(modules: dict[str, Path], packages: Sequence[str]) -> dict[str, set[str]]:
    """Return module -> the first-party modules it imports (``from`` a package: its module)."""
    edges: dict[str, set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        for module, imported, _ in imports_of(name, path, packages):
            target = f"{module}.{imported}" if f"{module}.{imported}" in modules else module
            if target != name:
                edges[name].add(target)
    return edges


def within(module: str, *packages: str) -> bool:
    """Whether ``module`` is one of ``packages`` or inside one of them."""
    return any(module == p or module.startswith(p + ".") for p in packages)


# --------------------------------------------------------------------------------------------
# The rules, each a function of a tree's graph or modules


def cycles(graph: dict[str, set[str]], nodes: set[str]) -> list[list[str]]:
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
        for w in sorted(graph.get(v, set()) & nodes):
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


def forbidden_imports(graph: dict[str, set[str]], importer: str,
                      forbidden: Sequence[str]) -> list[str]:
    """Return the imports of ``importer``'s modules from ``forbidden`` packages."""
    return sorted(f"{m} imports {t}" for m, targets in graph.items() if within(m, importer)
                  for t in targets if within(t, *forbidden))


def layer_of(module: str, layers: Sequence[Sequence[str]]) -> int | None:
    """Return the layer of ``module`` (its longest matching prefix), or None."""
    found = [(len(p), i) for i, names in enumerate(layers) for p in names if within(module, p)]
    return max(found)[1] if found else None


def layer_violations(graph: dict[str, set[str]], package: str,
                     layers: Sequence[Sequence[str]]) -> list[str]:
    """Return the upward imports of ``package``'s modules and its modules without a layer."""
    broken = []
    for module, targets in graph.items():
        if not within(module, package) or module == package:
            continue
        own = layer_of(module, layers)
        if own is None:
            broken.append(f"{module} has no layer")
            continue
        for target in targets:
            theirs = layer_of(target, layers)
            if theirs is not None and theirs > own:
                broken.append(f"{module} ({own}) imports {target} ({theirs})")
    return sorted(broken)


def impure_package_maps(modules: dict[str, Path], package: str,
                        facades: Sequence[str] = ()) -> list[str]:
    """Return the ``__init__`` files of ``package`` without a docstring or with an import."""
    broken = []
    for name, path in modules.items():
        if path.name != "__init__.py" or not within(name, package):
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        if not ast.get_docstring(tree):
            broken.append(f"{name}: no docstring (the package's map)")
        if name in facades:
            continue
        imports = [n for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom))
                   and not (isinstance(n, ast.ImportFrom) and n.module == "__future__")]
        if imports:
            broken.append(f"{name}: its __init__.py imports something")
    return broken


def _is_private(part: str) -> bool:
    return part.startswith("_") and not part.startswith("__")


def subpackage_of(module: str) -> str:
    """Return the first level of a package a module lies in (``ident.model``, say)."""
    return ".".join(module.split(".")[:2])


def private_imports(modules: dict[str, Path], package: str, packages: Sequence[str], *,
                    across: str) -> list[str]:
    """Return the imports of private names (``_x``) by ``package``'s modules.

    ``across="module"``: any private name from another module; ``across="subpackage"``: from a
    module of another subpackage (a subpackage's private machinery is its own).
    """
    broken = []
    for name, path in modules.items():
        if not within(name, package):
            continue
        for module, imported, line in imports_of(name, path, packages):
            target = f"{module}.{imported}" if imported else module
            if not any(_is_private(part) for part in target.split(".")):
                continue
            if module == name:
                continue
            if across == "subpackage" and subpackage_of(target) == subpackage_of(name):
                continue
            broken.append(f"{path}:{line}: {module} {imported}")
    return broken


def long_modules(modules: dict[str, Path]) -> list[str]:
    """Return the modules over 600 lines that do not say why, and any over 800."""
    broken = []
    for name, path in modules.items():
        text = path.read_text(encoding="utf-8")
        lines = text.count("\n")
        doc = ast.get_docstring(ast.parse(text)) or ""
        if lines > HARD_MAX_LINES:
            broken.append(f"{name}: {lines} lines (at most {HARD_MAX_LINES})")
        elif lines > MAX_LINES and not any(p.startswith(LONG_MARKER) for p in doc.split("\n\n")):
            broken.append(f"{name}: {lines} lines, no '{LONG_MARKER}' paragraph")
    return broken


def top_level_modules(root: Path, package: str) -> list[str]:
    """Return the plain modules directly in ``package`` (not its subpackages or __init__)."""
    return sorted(p.stem for p in (root / package).glob("*.py") if p.name != "__init__.py")


# --------------------------------------------------------------------------------------------
# The rules on this repository

MODULES = find_modules(REPO, PACKAGES)
GRAPH = import_graph(MODULES, PACKAGES)


def test_no_import_cycle_anywhere():
    assert cycles(GRAPH, set(MODULES)) == []


def test_the_graph_sees_function_level_imports():
    """A cycle hidden in a function still counts (the test's own premise, checked)."""
    assert "daq.sim.rig" in GRAPH["daq.sim.rig_process"]  # imported inside the child's target


@pytest.mark.parametrize(("importer", "forbidden"), [
    ("ident", ("daq", "simulators")),
    ("simulators", ("daq",)),
    ("daq.recording", ("daq.sim", "simulators")),
    ("daq.acquisition", ("daq.sim", "simulators")),
])
def test_packages_import_only_what_they_may(importer, forbidden):
    assert forbidden_imports(GRAPH, importer, forbidden) == []


@pytest.mark.parametrize(("package", "layers"), [
    ("daq", DAQ_LAYERS), ("ident", IDENT_LAYERS), ("simulators", SIMULATORS_LAYERS),
])
def test_layers_only_import_downwards(package, layers):
    assert layer_violations(GRAPH, package, layers) == []


@pytest.mark.parametrize("package", PACKAGES)
def test_subpackages_have_a_map_and_import_nothing(package):
    assert impure_package_maps(MODULES, package, FACADES) == []


def test_no_cross_module_private_imports_in_daq():
    assert private_imports(MODULES, "daq", PACKAGES, across="module") == []


@pytest.mark.parametrize("package", ["ident", "simulators"])
def test_no_private_imports_across_subpackages(package):
    assert private_imports(MODULES, package, PACKAGES, across="subpackage") == []


def test_long_modules_say_why_and_none_is_over_800_lines():
    assert long_modules(MODULES) == []


def test_daq_keeps_its_modules_in_subpackages():
    found = top_level_modules(REPO, "daq")
    assert len(found) <= MAX_DAQ_TOP_LEVEL_MODULES, found


def test_every_daq_exception_is_defined_in_daq_errors():
    errors = importlib.import_module("daq.errors")
    elsewhere = []
    for name in MODULES:
        if not within(name, "daq") or name == "daq.errors":
            continue
        module = importlib.import_module(name)
        for cls_name, cls in inspect.getmembers(module, inspect.isclass):
            if issubclass(cls, BaseException) and cls.__module__ == name:
                elsewhere.append(f"{name}.{cls_name}")
    assert elsewhere == []
    assert set(errors.__all__) == {n for n, c in inspect.getmembers(errors, inspect.isclass)
                                   if issubclass(c, BaseException)
                                   and c.__module__ == "daq.errors"}


# --------------------------------------------------------------------------------------------
# Each rule fails on a deliberately broken tree


def _tree(root: Path, files: dict[str, str]) -> dict[str, Path]:
    """Write ``files`` (relative path -> source) under ``root``; return its modules."""
    for relative, source in files.items():
        path = root / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(source, encoding="utf-8")
    return find_modules(root, ("pkg",))


MAP = '"""The map."""\n'


def test_a_cycle_hidden_in_a_function_is_found(tmp_path):
    modules = _tree(tmp_path, {
        "pkg/__init__.py": MAP,
        "pkg/a.py": "from pkg.b import y\nx = 1\n",
        "pkg/b.py": "y = 2\ndef late():\n    from pkg.a import x\n    return x\n",
        "pkg/c.py": "from pkg import a\n",
    })
    assert cycles(import_graph(modules, ("pkg",)), set(modules)) == [["pkg.a", "pkg.b"]]


def test_an_upward_import_and_a_module_without_a_layer_are_found(tmp_path):
    modules = _tree(tmp_path, {
        "pkg/__init__.py": MAP,
        "pkg/low/__init__.py": MAP,
        "pkg/low/x.py": "from pkg.high.y import f\n",
        "pkg/high/__init__.py": MAP,
        "pkg/high/y.py": "def f():\n    return 1\n",
        "pkg/stray.py": "",
    })
    layers = (("pkg.low",), ("pkg.high",))
    assert layer_violations(import_graph(modules, ("pkg",)), "pkg", layers) == [
        "pkg.low.x (0) imports pkg.high.y (1)", "pkg.stray has no layer"]


def test_a_forbidden_package_import_is_found(tmp_path):
    modules = _tree(tmp_path, {
        "pkg/__init__.py": MAP,
        "pkg/pure/__init__.py": MAP,
        "pkg/pure/m.py": "def f():\n    import pkg.rig.n\n",
        "pkg/rig/__init__.py": MAP,
        "pkg/rig/n.py": "",
    })
    graph = import_graph(modules, ("pkg",))
    assert forbidden_imports(graph, "pkg.pure", ("pkg.rig",)) == ["pkg.pure.m imports pkg.rig.n"]


def test_a_private_import_across_subpackages_is_found(tmp_path):
    modules = _tree(tmp_path, {
        "pkg/__init__.py": MAP,
        "pkg/one/__init__.py": MAP,
        "pkg/one/_machinery.py": "def _helper():\n    return 1\n",
        "pkg/one/public.py": "from pkg.one._machinery import _helper\n",
        "pkg/two/__init__.py": MAP,
        "pkg/two/user.py": "from pkg.one import _machinery\nfrom pkg.one.public import _x\n",
    })
    across = private_imports(modules, "pkg", ("pkg",), across="subpackage")
    assert [line.split(": ", 1)[1] for line in across] == ["pkg.one _machinery",
                                                           "pkg.one.public _x"]
    # Within its own subpackage the machinery may be shared, not across modules in daq's rule.
    strict = private_imports(modules, "pkg", ("pkg",), across="module")
    assert [line.split(": ", 1)[1] for line in strict] == ["pkg.one._machinery _helper",
                                                           "pkg.one _machinery",
                                                           "pkg.one.public _x"]


def test_a_package_map_that_imports_or_is_missing_is_found(tmp_path):
    modules = _tree(tmp_path, {
        "pkg/__init__.py": "from pkg.sub import m\n",
        "pkg/sub/__init__.py": MAP + "from pkg.sub import m\n",
        "pkg/sub/m.py": "",
        "pkg/other/__init__.py": MAP,
    })
    assert impure_package_maps(modules, "pkg") == [
        "pkg: no docstring (the package's map)", "pkg: its __init__.py imports something",
        "pkg.sub: its __init__.py imports something"]
    # A facade may import (it still needs its map).
    assert impure_package_maps(modules, "pkg", ("pkg",)) == [
        "pkg: no docstring (the package's map)", "pkg.sub: its __init__.py imports something"]


def test_long_modules_are_found(tmp_path):
    body = "x = 1\n" * (MAX_LINES + 1)
    modules = _tree(tmp_path, {
        "pkg/__init__.py": MAP,
        "pkg/silent.py": '"""Long."""\n' + body,
        "pkg/explained.py": f'"""Long.\n\n{LONG_MARKER} one job.\n"""\n' + body,
        "pkg/huge.py": f'"""Huge.\n\n{LONG_MARKER} no excuse.\n"""\n'
                       + "x = 1\n" * HARD_MAX_LINES,
    })
    found = long_modules(modules)
    assert [line.split(":")[0] for line in found] == ["pkg.huge", "pkg.silent"]
    assert "at most 800" in found[0] and LONG_MARKER in found[1]


def test_too_many_top_level_modules_are_found(tmp_path):
    _tree(tmp_path, {"pkg/__init__.py": MAP, **{f"pkg/m{i}.py": "" for i in range(9)},
                     "pkg/sub/__init__.py": MAP, "pkg/sub/deep.py": ""})
    assert len(top_level_modules(tmp_path, "pkg")) == 9 > MAX_DAQ_TOP_LEVEL_MODULES
