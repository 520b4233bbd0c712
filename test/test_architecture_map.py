"""docs/architecture.md's map ("The layers") names every package of mwip_ros/, and only those (issue 48 item 1).

The map is the code block under "## The layers": one line a package, ``name/`` indented two spaces a level under its
parent (``mwip_ros/`` at the top), then what it holds; a line further indented and not naming a package continues
the one above.  A package is a directory of mwip_ros/ with an ``__init__.py``.  A room of ``core/`` names each of its
modules on its lines, so a module moved or added shows on the map too.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Dict, List

import pytest

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "mwip_ros"
DOC = ROOT / "docs" / "architecture.md"

_ENTRY = re.compile(r"^( *)([a-z_]+)/(?: {2,}|$)")


def the_map(text: str) -> Dict[str, str]:
    """The map of ``text`` (architecture.md): package path (``core/plants``; ``""`` for mwip_ros itself) -> the
    text of its lines."""
    block = text.split("## The layers", 1)[1].split("```", 2)[1]
    out: Dict[str, str] = {}
    stack: List[str] = []
    current = None
    for line in block.splitlines():
        m = _ENTRY.match(line)
        if m:
            depth = len(m.group(1)) // 2
            stack = stack[:depth] + [m.group(2)]
            current = "/".join(stack[1:])
            assert current not in out, f"{current}/ is on the map twice"
            out[current] = line[m.end():].strip()
        elif current is not None and line.strip():
            out[current] += " " + line.strip()
    return out


def packages(root: Path) -> List[str]:
    """Every package under ``root`` (itself included, as ``""``), as a path relative to it."""
    rel = (p.parent.relative_to(root) for p in root.rglob("__init__.py"))
    return sorted("" if r == Path(".") else r.as_posix() for r in rel)


def test_every_package_is_on_the_map_and_nothing_else():
    mapped = the_map(DOC.read_text(encoding="utf-8"))
    found = packages(PACKAGE)
    assert len(found) > 15 and "core/plants" in found   # the package, read whole
    missing = sorted(set(found) - set(mapped))
    assert not missing, f"docs/architecture.md's map lacks these packages of mwip_ros/: {missing}"
    gone = sorted(set(mapped) - set(found))
    assert not gone, f"docs/architecture.md's map names packages mwip_ros/ does not have: {gone}"


def test_each_room_of_core_names_its_modules():
    mapped = the_map(DOC.read_text(encoding="utf-8"))
    for room in sorted(p for p in packages(PACKAGE) if p.startswith("core/")):
        modules = sorted(f.stem for f in (PACKAGE / room).glob("*.py") if f.stem != "__init__")
        words = set(re.findall(r"[a-z_]+", mapped[room]))
        absent = [m for m in modules if m not in words]
        assert not absent, f"docs/architecture.md's map: {room}/ does not name its modules {absent}"


def test_the_check_fails_without_any_one_line_of_the_map():
    text = DOC.read_text(encoding="utf-8")
    for line in text.split("## The layers", 1)[1].split("```", 2)[1].splitlines():
        if _ENTRY.match(line):
            lost = set(packages(PACKAGE)) - set(the_map(text.replace(line + "\n", "", 1)))
            assert lost, f"removing {line.strip()!r} from the map loses no package"


def test_each_room_of_core_imports_only_the_rooms_above_it_in_the_table():
    from test_import_graph import import_graph
    text = DOC.read_text(encoding="utf-8")
    order = re.findall(r"^\| `([a-z_]+)` \| [^|]+ \| [^|]+ \| [0-9]+ \|$", text, re.M)
    rooms = sorted(p.split("/")[1] for p in packages(PACKAGE) if p.startswith("core/"))
    assert sorted(order) == rooms, order   # the table has every room, once
    graph = import_graph(PACKAGE)

    def room(module):
        parts = module.split(".")
        return parts[2] if len(parts) > 2 and parts[:2] == ["mwip_ros", "core"] else None
    wrong = sorted({(a, b) for a in graph for b in graph[a]
                    if room(a) and room(b) and order.index(room(b)) > order.index(room(a))})
    assert not wrong, f"a room of core imports one below it in architecture.md's table: {wrong}"
