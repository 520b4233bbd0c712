"""test/ holds shared helpers (graphproc, bagcheck, mathfixtures); the tests in its subfolders import them.

Every test is in exactly one tier (pytest.ini registers the markers; a module says its tier with
``pytestmark = pytest.mark.<tier>`` after its imports, a module that mixes tiers marks each test instead):

- ``unit``: no ROS middleware and no project script. In this process (no ``rclpy.init``, no ``Graph``),
  or a short-lived child process that starts no ROS node: a project CLI (``python -m mwip_ros.cli...``,
  a small local worker pool of mwip_sweep's or mwip_tune's included), ``python -c`` that imports the
  package, ``colcon list``. Each finishes in a few seconds (``--durations``: at most about 4 s here,
  but about 14 s for the one that compiles the batch loop twice into an empty cache); the tier is the
  developer's fast loop (``scripts/test.sh -m unit -n 2``: about 75 s on two workers, under 2 minutes on one).
- ``graph``: brings up ROS: starts a node process (``Graph``, ``run_lockstep``, ``python -m
  mwip_ros.nodes.X``, even one that is expected to refuse its start-up or to answer ``--help``), runs
  ``mwip_ctl`` against a graph, or calls ``rclpy.init`` in the test process (a node in-process).
- ``e2e``: the project's scripts and whole jobs (``scripts/run_experiment.sh``, ``colcon build``), external
  servers beyond ROS nodes (a real ``dask scheduler`` and ``dask worker``: a cluster as deployed, its own
  ports and processes, not the project's code), and CLI jobs run whole as a user runs them where that is
  not fast: signalled with their worker processes and their session checked for leftovers
  (test/cli/test_sigterm.py), or several whole sweeps in one test.
- ``bench``: ``scripts/bench.sh``.

``scripts/test.sh`` runs every tier (CI); ``scripts/test.sh -m unit -n 2`` is the fast loop,
``-m "unit or graph"`` adds the ROS graphs. A test with no tier or more than one fails collection.
"""
import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from mwip_ros.optional import headless_gl  # noqa: E402

headless_gl()   # before a test module imports mujoco itself: MuJoCo picks its GL platform then (mwip_sim --render)

TIERS = ("unit", "node", "graph", "e2e", "bench")


@pytest.hookimpl(tryfirst=True)   # before -m deselects: a test outside the tier asked for is checked too
def pytest_collection_modifyitems(config, items):
    bad = []
    for item in items:
        tiers = sorted({m.name for m in item.iter_markers() if m.name in TIERS})
        if len(tiers) != 1:
            bad.append(f"  {item.nodeid}: {' + '.join(tiers) if tiers else 'no tier'}")
    if bad:
        raise pytest.UsageError(
            f"{len(bad)} test(s) not in exactly one tier of {', '.join(TIERS)} (test/conftest.py says which; "
            "add `pytestmark = pytest.mark.<tier>` to the module, or a mark to each test of a mixed module):\n"
            + "\n".join(bad))
