"""Message definitions and type hashes for MCAP schemas, as rosbag2 writes them.

``message_definition('sensor_msgs/msg/JointState')`` returns the ``ros2msg`` schema text
rosbag2 (Jazzy, ``rosbag2_cpp::LocalMessageDefinitionSource``) stores in an MCAP Schema
record: the type's own ``.msg`` file verbatim, then every dependency once, depth first,
each dependency set visited in sorted order, each one introduced by::

    \\n
    ================================================================================\\n
    MSG: std_msgs/Header\\n

(80 '=').  Dependencies are found the way rosbag2 finds them: a regex over the field
lines of the ``.msg`` text; a type without a package is in the same package as the
message that uses it; the primitive types are skipped.

``type_hash('sensor_msgs/msg/JointState')`` is the ``RIHS01_...`` hash rosidl generated
for the installed type (``share/<pkg>/msg/<Type>.json``).
"""
from __future__ import annotations

import functools
import json
import os
import re
import sys
from pathlib import Path
from typing import Dict, List, Set, Tuple

from mwip_ros.msgs.topics import split_type

from .errors import BagError

__all__ = ["message_definition", "share_directory", "type_hash"]

SEPARATOR = "=" * 80 + "\n"
MAX_RECURSION_DEPTH = 50

# A field line of a .msg file: its type ("foo_msgs/Bar" in "foo_msgs/Bar[] bar").
_MSG_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
PRIMITIVE_TYPES = frozenset({
    "bool", "byte", "char", "float32", "float64", "int8", "uint8",
    "int16", "uint16", "int32", "uint32", "int64", "uint64", "string"})


def _split(type_name: str) -> Tuple[str, str, str]:
    """(package, namespace, name) of a type name; BagError when it is not one."""
    try:
        return split_type(type_name)
    except ValueError as exc:
        raise BagError(str(exc)) from None


@functools.lru_cache(maxsize=None)
def share_directory(package: str) -> Path:
    """``share/<package>`` from the ament index (AMENT_PREFIX_PATH), else ``sys.prefix/share``."""
    if os.environ.get("AMENT_PREFIX_PATH"):
        try:
            from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
            try:
                return Path(get_package_share_directory(package))
            except PackageNotFoundError:
                pass
        except ImportError:  # pragma: no cover - ament_index_python ships with rclpy
            pass
    candidate = Path(sys.prefix) / "share" / package
    if candidate.is_dir():
        return candidate
    raise BagError(f"ROS package {package!r} not found (searched AMENT_PREFIX_PATH="
                   f"{os.environ.get('AMENT_PREFIX_PATH', '')!r} and {Path(sys.prefix) / 'share'})")


@functools.lru_cache(maxsize=None)
def _load_msg(type_name: str) -> Tuple[str, Tuple[str, ...]]:
    """(text of the .msg file, sorted dependency names) for 'pkg/Type' or 'pkg/msg/Type'."""
    package, namespace, name = _split(type_name)
    path = share_directory(package) / namespace / f"{name}.msg"
    try:
        text = path.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise BagError(f"no message definition for {type_name!r}: {path} does not exist") from None
    deps: Set[str] = set()
    for match in _MSG_FIELD_TYPE.finditer(text):
        field_type = match.group(1)
        if field_type in PRIMITIVE_TYPES:
            continue
        deps.add(field_type if "/" in field_type else f"{package}/{field_type}")
    return text, tuple(sorted(deps))


@functools.lru_cache(maxsize=None)
def message_definition(type_name: str) -> str:
    """The rosbag2 ``ros2msg`` schema text of ``type_name`` with all dependencies appended.

    Raises BagError naming the type when it, or one of its dependencies, has no ``.msg``.
    """
    seen: Set[str] = set()

    def append(name: str, depth: int) -> str:
        if depth <= 0:
            raise BagError(f"reached max recursion depth resolving the definition of {type_name!r}")
        text, deps = _load_msg(name)
        parts: List[str] = [text]
        for dep in deps:
            if dep in seen:
                continue
            seen.add(dep)
            parts.append("\n" + SEPARATOR + f"MSG: {dep}\n")
            parts.append(append(dep, depth - 1))
        return "".join(parts)

    try:
        return append(type_name, MAX_RECURSION_DEPTH)
    except BagError as exc:
        if type_name in str(exc):
            raise
        raise BagError(f"cannot build the message definition of {type_name!r}: {exc}") from None


@functools.lru_cache(maxsize=None)
def type_hash(type_name: str) -> str:
    """The installed type's ``RIHS01_...`` hash, or '' when rosidl did not generate one."""
    try:
        package, namespace, name = _split(type_name)
        path = share_directory(package) / namespace / f"{name}.json"
        doc = json.loads(path.read_text())
    except (BagError, OSError, ValueError):
        return ""
    full = f"{package}/{namespace}/{name}"
    hashes: Dict[str, str] = {h.get("type_name"): h.get("hash_string") for h in doc.get("type_hashes", [])}
    return hashes.get(full, "") or ""
