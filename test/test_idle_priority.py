"""scripts/idle_priority.py: a command run at SCHED_IDLE, with its threads and children, and back to SCHED_OTHER
(scripts/test.sh runs the in-process tiers so beside the timed tests)."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.cli

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "idle_priority.py"
# a process with a second thread and a child; it prints every thread's policy (its own and its child's) on request
TREE = r"""
import os, subprocess, sys, threading
child = subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.read()"], stdin=subprocess.PIPE)
threading.Thread(target=threading.Event().wait, daemon=True).start()
def policies():
    return sorted({(os.sched_getscheduler(int(t)), os.getpriority(os.PRIO_PROCESS, int(t)))
                   for pid in (os.getpid(), child.pid) for t in os.listdir(f"/proc/{pid}/task")})
print(policies(), flush=True)
sys.stdin.readline()
print(policies(), flush=True)
child.stdin.close(); child.wait()
"""


@pytest.mark.parametrize("nice", [[], ["10"]])
def test_a_tree_runs_idle_and_restore_brings_every_thread_and_child_back(nice):
    p = subprocess.Popen([sys.executable, str(SCRIPT), "run", sys.executable, "-c", TREE], stdin=subprocess.PIPE,
                         stdout=subprocess.PIPE, text=True)
    mine = os.getpriority(os.PRIO_PROCESS, 0)
    try:
        # both threads and the child inherited it
        assert p.stdout.readline().strip() == str([(os.SCHED_IDLE, mine)])
        r = subprocess.run([sys.executable, str(SCRIPT), "restore", str(p.pid), *nice], timeout=30)
        assert r.returncode == 0
        p.stdin.write("\n")
        p.stdin.flush()
        assert p.stdout.readline().strip() == str([(os.SCHED_OTHER, max(mine, int(nice[0]) if nice else 0))])
    finally:
        p.stdin.close()
        assert p.wait(timeout=30) == 0


def test_a_wrong_call_is_refused_with_the_usage():
    r = subprocess.run([sys.executable, str(SCRIPT), "restore", "abc"], capture_output=True, text=True, timeout=30)
    assert r.returncode == 2 and "restore PID" in r.stderr
