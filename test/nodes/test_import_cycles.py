"""The node modules import one another one way: no cycle among mwip_ros/nodes (read from the sources, lazy
imports inside functions included), e.g. guards <- rclpy_compat <- state_input, never back."""
import ast
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

NODES = Path(__file__).resolve().parents[2] / "mwip_ros" / "nodes"


def _imports() -> dict:
    """{module: the mwip_ros.nodes modules it imports}, by file stem."""
    names = {f.stem for f in NODES.glob("*.py")}
    graph = {}
    for f in NODES.glob("*.py"):
        deps = set()
        for n in ast.walk(ast.parse(f.read_text())):
            if isinstance(n, ast.ImportFrom):
                mod = n.module or ""
                if n.level == 1:
                    mod = f"mwip_ros.nodes.{mod}" if mod else "mwip_ros.nodes"
                if mod == "mwip_ros.nodes":
                    deps |= {a.name for a in n.names if a.name in names}
                elif mod.startswith("mwip_ros.nodes."):
                    deps.add(mod.split(".")[2])
            elif isinstance(n, ast.Import):
                deps |= {a.name.split(".")[2] for a in n.names if a.name.startswith("mwip_ros.nodes.")}
        graph[f.stem] = deps & names - {f.stem}
    return graph


def _cycle(graph: dict):
    """One import cycle as a list of modules, or None."""
    state = {}

    def visit(m, path):
        state[m] = "open"
        for d in sorted(graph[m]):
            if state.get(d) == "open":
                return path[path.index(d):] + [d]
            if d not in state:
                found = visit(d, path + [d])
                if found:
                    return found
        state[m] = "done"
        return None
    for m in sorted(graph):
        if m not in state:
            found = visit(m, [m])
            if found:
                return found
    return None


def test_the_node_modules_import_each_other_one_way():
    graph = _imports()
    assert "guards" in graph["rclpy_compat"]   # the imports are read
    cycle = _cycle(graph)
    assert cycle is None, " -> ".join(cycle)


def test_the_cycle_finder_finds_a_cycle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None
