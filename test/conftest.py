"""test/ holds shared helpers (graphproc, nodeharness, bagcheck, mathfixtures, printed); the tests in its subfolders
import them.

Every test is in exactly one tier (pytest.ini registers the markers; a module says its tier with
``pytestmark = pytest.mark.<tier>`` after its imports; a test's own tier mark replaces its module's, so a module of
unit tests may hold one slow test marked ``@pytest.mark.slow``):

- ``unit``: in this process, with no ROS middleware (no ``rclpy.init``, no ``Graph``) and no child process. At
  most 5 s each (a run lists the unit, cli and node tests that took longer, and the unit tests that started a
  process).
- ``cli``: a child process that starts no ROS node: a project command run whole as a user types it (its exit code,
  its one line on stderr, its files), ``python -c`` with a package hidden, ``colcon list``. At most 5 s each.
- ``node``: a node built in the test's own process by test/nodeharness.py (rclpy with discovery off: no other
  process, no DDS traffic), fed messages, service calls and parameter requests directly. At most 5 s each.
- ``slow``: like ``unit``, but heavy: a test longer than 5 s (a kernel compiled into an empty cache, a search run to
  its end), the documentation's tables recomputed (MuJoCo runs: test/test_docs_motion.py, _terrain, _real_robot),
  the rest of an oracle's matrix over every law and sensing whose fast loop keeps two cases.
- ``montecarlo``: statistical coverage over many seeds or fits (a confidence interval's coverage over 100 runs).
- ``graph``: brings up ROS across processes: starts a node process (``Graph``, ``run_lockstep``, ``python -m
  mwip_ros.nodes.X``), runs ``mwip_ctl`` against a graph, or an rclpy participant of the test's that discovers
  them. For what needs processes: exit codes, signals, lockstep across processes, the recorder's file, timing.
- ``e2e``: the project's scripts and whole jobs (``scripts/run_experiment.sh``, ``colcon build``), external
  servers beyond ROS nodes (a real ``dask scheduler`` and ``dask worker``), and CLI jobs run whole as a user runs
  them where that is not fast (signalled with their worker processes, several whole sweeps in one test).
- ``bench``: ``scripts/bench.sh``.

``alone`` is not a tier but a mark on a test that keeps real-time deadlines or times something on the wall clock (a
realtime loop, a watchdog, discovery's second, a device's timeout) or hands a domain to a script: such a test runs
alone, at normal priority, with only idle-class work beside it.

``scripts/test.sh`` runs every tier (CI): the ones marked alone and the bench one test at a time, with the tiers
without ROS processes (unit, cli, node, slow, montecarlo) on every core (pytest-xdist) beside them at the idle
scheduling class (scripts/idle_priority.py: they take only the CPU the timed tests leave); then the in-process run
goes back to normal priority, and the graph and e2e tests not marked alone run on every core beside what is left of
it (a module's tests on one worker: its graph is shared).
``scripts/test.sh -m unit`` is the fast loop. A test with no tier or more than one fails collection.
"""
import os
import subprocess
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from mwip_ros.optional import headless_gl  # noqa: E402

headless_gl()   # before a test module imports mujoco itself: MuJoCo picks its GL platform then (mwip_sim --render)

TIERS = ("unit", "cli", "node", "slow", "montecarlo", "graph", "e2e", "bench")
IN_PROCESS = ("unit", "cli", "node", "slow", "montecarlo")   # scripts/test.sh runs these on every core (xdist)
FAST = ("unit", "cli", "node")                        # at most 5 s a test here
FAST_LIMIT_S = 5.0


def _own_tiers(node) -> set:
    return {m.name for m in getattr(node, "own_markers", ()) if m.name in TIERS}


def _lift_overridden_module_tiers(items) -> None:
    """A test's own tier mark (on it or its class) replaces its module's: the module's mark moves onto each of its
    other tests, so ``-m`` sees one tier per test."""
    by_module = {}
    for item in items:
        module = item.getparent(pytest.Module)
        if module is not None and _own_tiers(module):
            by_module.setdefault(module, []).append(item)
    for module, its in by_module.items():
        overriding = [i for i in its if _own_tiers(i) or _own_tiers(i.getparent(pytest.Class) or i)]
        if not overriding:
            continue
        marks = [m for m in module.own_markers if m.name in TIERS]
        module.own_markers[:] = [m for m in module.own_markers if m.name not in TIERS]
        for item in its:
            if item not in overriding:
                for m in marks:
                    item.add_marker(m.name)


_SPAWNED = [0]   # child processes this test process started (subprocess.Popen), for the unit tier's promise
_popen_init = subprocess.Popen.__init__


def _counted_popen_init(self, *args, **kwargs):
    _SPAWNED[0] += 1
    return _popen_init(self, *args, **kwargs)


subprocess.Popen.__init__ = _counted_popen_init


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item):
    before = _SPAWNED[0]
    yield
    if _SPAWNED[0] > before:   # in the report (a worker's too): the summary names a unit test that started one
        item.user_properties.append(("spawned", _SPAWNED[0] - before))


@pytest.hookimpl(tryfirst=True)   # before -m deselects: a test outside the tier asked for is checked too
def pytest_collection_modifyitems(config, items):
    _lift_overridden_module_tiers(items)
    bad = []
    for item in items:
        tiers = sorted({m.name for m in item.iter_markers() if m.name in TIERS})
        if len(tiers) != 1:
            bad.append(f"  {item.nodeid}: {' + '.join(tiers) if tiers else 'no tier'}")
        else:   # in the test's reports (a worker's too): the summary's check reads it there
            item.user_properties.append(("tier", tiers[0]))
    if bad:
        raise pytest.UsageError(
            f"{len(bad)} test(s) not in exactly one tier of {', '.join(TIERS)} (test/conftest.py says which; "
            "add `pytestmark = pytest.mark.<tier>` to the module, or a mark to each test of a mixed module):\n"
            + "\n".join(bad))


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    """The unit and node tests that took longer than their tier allows (a warning: the tier's promise drifted)."""
    slow = []
    for reports in terminalreporter.stats.values():
        for r in reports:
            if getattr(r, "when", None) == "call" and getattr(r, "duration", 0.0) > FAST_LIMIT_S and \
                    dict(getattr(r, "user_properties", ())).get("tier") in FAST:
                slow.append((r.duration, r.nodeid))
    if slow:
        terminalreporter.write_line(f"tier: {len(slow)} unit/cli/node test(s) over {FAST_LIMIT_S:g} s (move them to "
                                    "slow, or make them faster):", yellow=True)
        for d, nodeid in sorted(slow, reverse=True):
            terminalreporter.write_line(f"  {d:6.1f} s  {nodeid}", yellow=True)
    spawning = sorted({r.nodeid for reports in terminalreporter.stats.values() for r in reports
                       if getattr(r, "when", None) == "call" and dict(getattr(r, "user_properties", ())).get("tier")
                       == "unit" and dict(getattr(r, "user_properties", ())).get("spawned")})
    if spawning:
        terminalreporter.write_line(f"tier: {len(spawning)} unit test(s) started a child process (mark them cli):",
                                    yellow=True)
        for nodeid in spawning:
            terminalreporter.write_line(f"  {nodeid}", yellow=True)
