"""The nodes' entry points: what a node process does first, then the node's ``main``.

The console scripts (setup.py: ``plant_sim = mwip_ros.nodes.runtime.entry:plant_sim``, ...) and
``python -m mwip_ros.nodes NODE [--ros-args ...]`` come here.  :func:`run` limits glibc's malloc
arenas (:func:`bound_malloc_arenas`) and only then imports the node's module: importing rclpy
starts threads that allocate (2, with an arena each, when its C extension loads), so the limit
must come before that import, which is why it is not in ``run_node`` (it runs there too, for a
node started as ``python -m mwip_ros.nodes.loop.NODE``, where it bounds only the arenas made later).
This module imports neither rclpy nor numpy; importing it changes nothing.
"""
from __future__ import annotations

import importlib
import sys
from typing import Optional, Sequence

from .arenas import M_ARENA_MAX, bound_malloc_arenas

__all__ = ["NODES", "M_ARENA_MAX", "bound_malloc_arenas", "run", "main", *(
    "plant_sim", "disturbance_observer", "dscndo_controller", "mcap_recorder", "bag_replay", "robot_markers",
    "foxglove_server", "state_estimator", "robot_state", "wheel_driver")]

# every node by name, and its module: the loop's nodes in nodes/loop, the tool nodes in nodes/tools
NODES = {name: f"mwip_ros.nodes.{room}.{name}" for room, names in (
    ("loop", ("plant_sim", "disturbance_observer", "dscndo_controller", "state_estimator", "wheel_driver")),
    ("tools", ("mcap_recorder", "bag_replay", "robot_markers", "foxglove_server", "robot_state"))) for name in names}


def run(node: str, argv: Optional[Sequence[str]] = None) -> int:
    """The malloc arena limit, then the node's ``main(argv)`` (its module: :data:`NODES`; argv None: ``sys.argv``)."""
    bound_malloc_arenas()
    return importlib.import_module(NODES[node]).main(None if argv is None else list(argv))


def plant_sim(argv=None) -> int:
    return run("plant_sim", argv)


def disturbance_observer(argv=None) -> int:
    return run("disturbance_observer", argv)


def dscndo_controller(argv=None) -> int:
    return run("dscndo_controller", argv)


def mcap_recorder(argv=None) -> int:
    return run("mcap_recorder", argv)


def bag_replay(argv=None) -> int:
    return run("bag_replay", argv)


def robot_markers(argv=None) -> int:
    return run("robot_markers", argv)


def foxglove_server(argv=None) -> int:
    return run("foxglove_server", argv)


def state_estimator(argv=None) -> int:
    return run("state_estimator", argv)


def robot_state(argv=None) -> int:
    return run("robot_state", argv)


def wheel_driver(argv=None) -> int:
    return run("wheel_driver", argv)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``python -m mwip_ros.nodes NODE [ARGS]``: the node ``NODE`` as its console script runs it, with the
    command line ``NODE ARGS``."""
    args = list(sys.argv if argv is None else argv)[1:]
    if not args or args[0] not in NODES:
        given = f"unknown node {args[0]!r}; " if args and not args[0].startswith("-") else ""
        print(f"usage: python -m mwip_ros.nodes NODE [--ros-args ...] ({given}nodes: {', '.join(NODES)})",
              file=sys.stderr, flush=True)
        return 0 if args and args[0] in ("-h", "--help") else 2
    sys.argv = [args[0], *args[1:]]
    return run(args[0], sys.argv)
