"""The package's floors hold: the import graph of ``hbmp_bench`` (every ``import`` statement, at the top of a
module and inside functions) has no circle, and the rooms below do not reach the rooms above them."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import hbmp_bench

PACKAGE = Path(hbmp_bench.__file__).parent


def _modules() -> dict[str, tuple[Path, bool]]:
    """Dotted module name -> (file, whether it is a package's ``__init__``)."""
    found = {}
    for file in sorted(PACKAGE.rglob("*.py")):
        parts = list(file.relative_to(PACKAGE.parent).with_suffix("").parts)
        package = parts[-1] == "__init__"
        found[".".join(parts[:-1] if package else parts)] = (file, package)
    return found


def import_graph() -> dict[str, set[str]]:
    """Module -> the package's modules it imports (``from a.b import c`` counts as ``a.b.c`` where that is a
    module, else ``a.b``); relative imports resolved; imports under ``if TYPE_CHECKING:`` count too."""
    modules = _modules()

    def known(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {name: set() for name in modules}
    for name, (file, package) in modules.items():
        for node in ast.walk(ast.parse(file.read_text(encoding="utf-8"))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parent = name.split(".") if package else name.split(".")[:-1]
                    parent = parent[:len(parent) - node.level + 1]
                    base = ".".join([*parent, base] if base else parent)
                targets = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in modules else base
                           for alias in node.names]
            for target in targets:
                module = known(target)
                if module is not None and module != name:
                    graph[name].add(module)
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
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

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_import_graph_sees_function_level_imports():
    graph = import_graph()
    assert "hbmp_bench.agents.learned" in graph["hbmp_bench.agents.loading"]  # load_agent imports it in its body
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_circles():
    found = circles(import_graph())
    assert found == [], "import circles: " + "; ".join(" <-> ".join(c) for c in found)


@pytest.mark.parametrize("low, high", [
    ("hbmp_bench.policies", "hbmp_bench.training"),  # inference never imports training
    ("hbmp_bench.agents", "hbmp_bench.training"),
    ("hbmp_bench.metrics", "hbmp_bench.evaluation"),  # results files are read below the leaderboard
    ("hbmp_bench.planning", "hbmp_bench.sim"),
    ("hbmp_bench.vocabulary", "hbmp_bench."),
    ("hbmp_bench.errors", "hbmp_bench."),
])
def test_floors(low, high):
    graph = import_graph()
    reach = {m: set(t) for m, t in graph.items()}
    crossing = sorted((m, t) for m, targets in reach.items() if m == low or m.startswith(low + ".")
                      for t in targets if t.startswith(high) and not (t == low or t.startswith(low + ".")))
    assert crossing == [], f"{low} imports {high}: {crossing}"
