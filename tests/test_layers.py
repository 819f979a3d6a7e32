"""The three layers and markov's pipeline (docs/architecture.md): arrows point down, no cycle.

Every import of every module is read from the source (``ast``), including the
imports inside functions, which run later but are dependencies all the same.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
LAYERS = ("markov", "symbolic", "nasch")   # bottom to top


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for layer in LAYERS for p in sorted((ROOT / layer).rglob("*.py"))}


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    """The project modules ``name`` imports (a package's ``__init__`` counts as the package)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                stem = ".".join(base + ([node.module] if node.module else []))
            else:
                stem = node.module
            # ``from pkg import mod`` imports the module pkg.mod when there is one
            targets = [f"{stem}.{a.name}" if f"{stem}.{a.name}" in known else stem
                       for a in node.names]
        else:
            continue
        for target in targets:
            while target and target not in known:   # a name inside a module: the module
                target = target.rpartition(".")[0]
            if target and target != name:
                out.add(target)
    return out


GRAPH = {name: _imports(name, path, set(_modules())) for name, path in _modules().items()}


@pytest.mark.parametrize("name", sorted(GRAPH))
def test_imports_point_down(name):
    level = LAYERS.index(name.split(".")[0])
    upward = sorted(t for t in GRAPH[name] if LAYERS.index(t.split(".")[0]) > level)
    assert not upward, f"{name} imports from a layer above it: {upward}"


def test_no_import_cycle():
    # a package's __init__ imports its own modules lazily by name: those edges are not
    # followed, a package and its modules are one node only when the package is imported
    state: dict[str, int] = {}
    path: list[str] = []

    def visit(node):
        state[node] = 1
        path.append(node)
        for nxt in sorted(GRAPH[node]):
            if state.get(nxt) == 1:
                cycle = path[path.index(nxt):] + [nxt]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if nxt not in state:
                visit(nxt)
        path.pop()
        state[node] = 2

    for node in sorted(GRAPH):
        if node not in state:
            visit(node)


def test_the_walk_sees_imports_inside_functions():
    assert "markov.solvers.storage" in GRAPH["markov.solvers.ring_chain"]         # Solution.save imports it lazily
    assert "symbolic" in GRAPH["nasch.tables"]


@pytest.mark.parametrize("name", sorted(n for n in GRAPH if not n.startswith("markov")))
def test_private_modules_stay_inside_their_package(name):
    # markov.chain.kernels, _factored, ... are free to change: the layers above use the public modules
    private = sorted(t for t in GRAPH[name]
                     if any(part.startswith("_") for part in t.split(".")[1:])
                     and t.split(".")[0] != name.split(".")[0])
    assert not private, f"{name} imports private modules of another package: {private}"
