"""No import circle in mwip_ros/: the package's modules form a graph without cycles (issue 48 item 2).

The graph is read from the source with ``ast``, nothing imported: an edge a -> b for every import of b written in
a, wherever it is written (at the top, inside a function, under ``if TYPE_CHECKING:``, in a ``try``), and for every
``importlib.import_module`` / ``__import__`` of a string constant (relative to ``__package__`` when given).  An
import hidden in a function or behind ``import_module`` is still an edge: it closes the circle as soon as it runs, so
a circle is broken by moving the shared piece down (``core/plants/plant_base.py``, ``params/spec.py``,
``core/laws/base.py``,
...), not by hiding the import.  ``from pkg import name`` is an edge to the submodule ``pkg.name`` when there is one,
else to ``pkg``.  The implicit import of a module's parent packages is not an edge (a package that imports its own
submodules is the normal shape); an import of a name computed at run time (a plug-in, a node by its name) cannot be
read and is not one either.
"""
from __future__ import annotations

import ast
from pathlib import Path
from typing import Dict, Iterator, List, Optional, Set, Tuple

import pytest

pytestmark = pytest.mark.unit

PACKAGE = Path(__file__).resolve().parents[1] / "mwip_ros"

Where = Tuple[str, int]                   # (file relative to the package's parent, line)
Graph = Dict[str, Dict[str, List[Where]]]  # module -> {module it imports: where}


def _modules(root: Path) -> Dict[str, Tuple[Path, bool]]:
    """Every module under the package directory ``root``: dotted name -> (file, is a package's __init__)."""
    out = {}
    for f in sorted(root.rglob("*.py")):
        parts = list(f.relative_to(root.parent).with_suffix("").parts)
        is_pkg = parts[-1] == "__init__"
        out[".".join(parts[:-1] if is_pkg else parts)] = (f, is_pkg)
    return out


def _known(name: str, modules) -> Optional[str]:
    """``name`` or its nearest enclosing module that is in ``modules`` (``pkg.mod.attr`` -> ``pkg.mod``), or None."""
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def _base(module: str, is_pkg: bool, level: int) -> str:
    """The package a relative import of ``level`` dots in ``module`` starts from."""
    parts = module.split(".") if is_pkg else module.split(".")[:-1]
    return ".".join(parts[:len(parts) - (level - 1)])


def _imported(module: str, is_pkg: bool, tree: ast.AST, modules) -> Iterator[Tuple[str, int]]:
    """(module imported, line) for every import written anywhere in ``tree`` (module docstring)."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, node.lineno
        elif isinstance(node, ast.ImportFrom):
            src = node.module or ""
            if node.level:
                src = _base(module, is_pkg, node.level) + (f".{src}" if src else "")
            for alias in node.names:
                sub = f"{src}.{alias.name}"
                yield (sub if sub in modules else src), node.lineno
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant) \
                and isinstance(node.args[0].value, str):
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
            if name not in ("import_module", "__import__"):
                continue
            target = node.args[0].value
            if target.startswith("."):   # import_module(".x", __package__): relative to this module's package
                level = len(target) - len(target.lstrip("."))
                rest = target.lstrip(".")
                target = _base(module, is_pkg, level) + (f".{rest}" if rest else "")
            yield target, node.lineno


def import_graph(root: Path) -> Graph:
    """The import graph of the package directory ``root`` (module docstring): only edges between its own modules."""
    modules = _modules(root)
    graph: Graph = {m: {} for m in modules}
    for module, (path, is_pkg) in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        for name, line in _imported(module, is_pkg, tree, modules):
            target = _known(name, modules)
            if target is not None and target != module:
                graph[module].setdefault(target, []).append((str(path.relative_to(root.parent)), line))
    return graph


def cycles(graph: Graph) -> List[List[str]]:
    """One cycle per strongly connected component of more than one module, as [m0, m1, ..., m0] (Tarjan's, then
    the shortest way back to the component's first module)."""
    index: Dict[str, int] = {}
    low: Dict[str, int] = {}
    stack: List[str] = []
    on: Set[str] = set()
    comps: List[List[str]] = []

    def visit(v: str) -> None:   # the package has some 200 modules: recursion is fine
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                comps.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    out = []
    for comp in comps:
        inside, start = set(comp), comp[0]
        paths = {w: [start, w] for w in graph[start] if w in inside}
        todo = list(paths)
        while start not in paths:   # breadth first from start's neighbours back to start
            v = todo.pop(0)
            for w in graph[v]:
                if w in inside and w not in paths:
                    paths[w] = paths[v] + [w]
                    todo.append(w)
        out.append(paths[start])
    return out


def _said(graph: Graph, cycle: List[str]) -> str:
    """A cycle as one line: each edge with the import that makes it (file:line)."""
    steps = [f"{b} ({graph[a][b][0][0]}:{graph[a][b][0][1]})" for a, b in zip(cycle, cycle[1:])]
    return " -> ".join([cycle[0], *steps])


def test_mwip_ros_has_no_import_cycle():
    graph = import_graph(PACKAGE)
    assert len(graph) > 150 and graph["mwip_ros.core.plants.plant"]   # the package, read whole
    found = cycles(graph)
    assert not found, "import circles in mwip_ros/ (break each by moving the shared piece down):\n" + "\n".join(
        _said(graph, c) for c in found)


def test_the_plant_s_registry_imports_both_plants_and_neither_plant_imports_it():
    graph = import_graph(PACKAGE)
    assert {"mwip_ros.core.plants.mujoco_plant", "mwip_ros.core.plants.plant_base"} <= set(
        graph["mwip_ros.core.plants.plant"])
    assert "mwip_ros.core.plants.plant" not in graph["mwip_ros.core.plants.mujoco_plant"]
    assert "mwip_ros.core.plants.plant" not in graph["mwip_ros.core.plants.plant_base"]


def _package(tmp_path: Path, files: Dict[str, str]) -> Path:
    root = tmp_path / "pkg"
    for name, text in {"__init__.py": "", **files}.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text)
    return root


@pytest.mark.parametrize("b_imports_a", [
    "from . import a\n",                                                     # at the top
    "def f():\n    from .a import X\n",                                      # hidden in a function
    "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.a import X\n",   # for the annotations only
    "import importlib\ndef f():\n    return importlib.import_module('.a', __package__)\n",   # by a string constant
    "try:\n    import pkg.a.inner\nexcept ImportError:\n    pass\n",         # a name inside a, in a try
])
def test_the_graph_sees_a_circle_however_its_import_is_written(tmp_path, b_imports_a):
    root = _package(tmp_path, {"a.py": "from .b import Y\n", "b.py": b_imports_a, "c.py": "from . import a, b\n"})
    graph = import_graph(root)
    assert cycles(graph) == [["pkg.a", "pkg.b", "pkg.a"]], graph
    said = _said(graph, cycles(graph)[0])   # the failure's line names each import that closes the circle
    assert said.startswith("pkg.a -> pkg.b (pkg/a.py:1) -> pkg.a (pkg/b.py:") and said.endswith(")"), said


def test_a_package_that_imports_its_own_modules_below_it_is_no_circle(tmp_path):
    root = _package(tmp_path, {"__init__.py": "from . import impl\nfrom .base import Base\n",
                               "base.py": "class Base: ...\n",
                               "impl.py": "from . import base\nfrom .base import Base\nimport importlib\n"
                                          "def load(name):\n    return importlib.import_module(name)\n"})
    graph = import_graph(root)
    assert graph["pkg.impl"] == {"pkg.base": [("pkg/impl.py", 1), ("pkg/impl.py", 2)]}   # not the package itself
    assert cycles(graph) == []
    (root / "impl.py").write_text("from . import Base\n")   # Base through the package that imports impl: a circle
    assert cycles(import_graph(root)) == [["pkg", "pkg.impl", "pkg"]]
