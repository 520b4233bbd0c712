"""The node modules import one another one way: no cycle among mwip_ros/nodes (read from the sources, lazy
imports inside functions included), e.g. runtime.guards <- runtime.rclpy_compat <- runtime.state_input, never back."""
import ast
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

NODES = Path(__file__).resolve().parents[2] / "mwip_ros" / "nodes"


def _imports() -> dict:
    """{module: the mwip_ros.nodes modules it imports}, by dotted name under mwip_ros.nodes (``runtime.guards``)."""
    files = {".".join(f.relative_to(NODES).with_suffix("").parts): f for f in NODES.rglob("*.py")}
    names = set(files)
    graph = {}
    for name, f in files.items():
        package = name.rsplit(".", 1)[0] if "." in name else ""
        deps = set()
        for n in ast.walk(ast.parse(f.read_text())):
            if isinstance(n, ast.ImportFrom):
                mod = n.module or ""
                if n.level:   # relative: from the module's own package upwards
                    base = package.split(".")[: max(0, len(package.split(".")) - (n.level - 1))] if package else []
                    mod = ".".join(["mwip_ros", "nodes", *base, *([mod] if mod else [])])
                if mod.startswith("mwip_ros.nodes"):
                    sub = mod[len("mwip_ros.nodes"):].lstrip(".")
                    deps |= {f"{sub}.{a.name}".lstrip(".") for a in n.names} & names
                    deps |= {sub} & names
            elif isinstance(n, ast.Import):
                deps |= {a.name[len("mwip_ros.nodes."):] for a in n.names
                         if a.name.startswith("mwip_ros.nodes.")} & names
        graph[name] = deps - {name}
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
    assert "runtime.guards" in graph["runtime.rclpy_compat"]   # the imports are read
    cycle = _cycle(graph)
    assert cycle is None, " -> ".join(cycle)


def test_the_cycle_finder_finds_a_cycle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None
