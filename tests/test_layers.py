"""Layers point one way (issue 12): the import graph of nnid (module level and inside
functions) has no cycle, and no layer imports one above it."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "nnid"
#: what each layer may import besides itself (the foundation modules are below everything)
FOUNDATION = {"nnid", "nnid.errors", "nnid.validation", "nnid.serialization", "nnid.threads",
              # how a number is written for a person ("-" where it was not measured): the
              # sentences the loop and fault layers write use it too; it imports no nnid module
              "nnid.reports.cells"}  # fmt: skip
ALLOWED = {
    "physics": set(),
    "datasets": {"physics"},
    "evaluation": {"physics", "datasets"},
    "trainers": {"physics", "datasets", "evaluation"},
    "models": {"physics", "datasets", "evaluation", "trainers"},
    "fault": {"physics", "datasets", "evaluation", "trainers", "models", "loop"},
}


def _modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = path
    return out


def _imports(path: Path, modules: dict[str, Path]) -> set[str]:
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("nnid"):
            for alias in node.names:
                full = f"{node.module}.{alias.name}"
                found.add(full if full in modules else node.module)
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("nnid")}
    return {m for m in found if m in modules}


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(path, modules) - {name} for name, path in modules.items()}


def test_no_import_cycle(graph):
    state: dict[str, int] = {}

    def visit(node: str, trail: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycle = [*trail[trail.index(nxt) :], nxt] if nxt in trail else [node, nxt]
                pytest.fail(f"import cycle: {' -> '.join(cycle)}")
            if nxt not in state:
                visit(nxt, [*trail, nxt])
        state[node] = 2

    for name in sorted(graph):
        if name not in state:
            visit(name, [name])


def test_foundation_modules_import_no_layer(graph):
    # a foundation module in a layer's package runs that package's __init__ too
    for name in FOUNDATION - {"nnid"}:
        parent = name.rsplit(".", 1)[0]
        for module in {name} | ({parent} if parent in graph and parent != "nnid" else set()):
            assert graph[module] <= {"nnid"} | FOUNDATION, f"{module} imports {graph[module]}"


@pytest.mark.parametrize("layer", list(ALLOWED))
def test_layer_imports_only_below_it(layer, graph):
    prefix = f"nnid.{layer}"
    for name, targets in graph.items():
        if not name.startswith(prefix):
            continue
        for target in targets:
            if target in FOUNDATION or (target == "nnid.vehicle" and layer != "physics"):
                continue
            top = target.split(".")[1]
            assert top == layer or top in ALLOWED[layer], f"{name} imports {target}"
