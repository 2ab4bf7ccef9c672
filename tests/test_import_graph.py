"""No import circles between the product's modules.

Every module of every package under src/ (``src/<pkg>/<pkg>/*.py``, not the
tests), every import in it, at module level or inside a function: a circle
(a imports b, which imports a, directly or through others) is a design knot
that makes either module impossible to read, test or move alone.
"""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def import_graph() -> dict[str, set[str]]:
    """Module name -> the product modules it imports."""
    files = {f"{p.parent.name}.{p.stem}": p for p in ROOT.glob("src/*/*/*.py")
             if p.parent.name == p.parent.parent.name}
    graph = {}
    for name, path in files.items():
        edges = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                edges |= {t for t in [node.module] + [f"{node.module}.{a.name}" for a in node.names]
                          if t in files}
            elif isinstance(node, ast.Import):
                edges |= {a.name for a in node.names if a.name in files}
        graph[name] = edges - {name}
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
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


def test_the_scan_finds_a_circle_where_there_is_one():
    assert circles({"a.x": {"a.y"}, "a.y": {"a.z"}, "a.z": {"a.x"}, "a.w": {"a.x"}}) == [
        ["a.x", "a.y", "a.z"]]
    assert circles({"a.x": {"a.y"}, "a.y": set()}) == []


def test_the_product_has_no_import_circles():
    graph = import_graph()
    assert len(graph) > 100                      # it read the packages
    assert "holonomic_sim.physics_process" in graph["holonomic_sim.sim_driver"]
    assert circles(graph) == []
