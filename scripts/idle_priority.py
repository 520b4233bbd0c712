#!/usr/bin/env python3
"""Run a command at the idle scheduling class, and bring it (and everything it started) back to normal.

scripts/test.sh runs the tiers that start no ROS process at Linux's SCHED_IDLE beside the tests that keep
real-time deadlines: they then take only the CPU that nothing else wants. Once the timed tests end, ``restore``
puts every thread of the command and of its descendants back to SCHED_OTHER, so that on a machine loaded by other
work the rest of the run gets its share instead of waiting for idle CPU; at a nice of its own if given (test.sh
gives 10: the graph tests beside it, which wait on their processes, come first, and the in-process tests take what
they leave, yet more than idle).

    python scripts/idle_priority.py run CMD [ARG ...]   exec CMD at SCHED_IDLE (its children inherit it)
    python scripts/idle_priority.py restore PID [NICE]  PID's process tree back to SCHED_OTHER (at nice NICE)

Scheduling is per thread on Linux, so ``restore`` walks /proc/PID/task of every process in the tree, twice (a
process forked by a thread that was still idle during the first walk is caught by the second). An unprivileged
user may switch its own threads from SCHED_IDLE to SCHED_OTHER (sched(7), since Linux 2.6.39). Linux only.
"""
import os
import sys


def _children() -> dict:
    kids: dict = {}
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat") as f:
                    ppid = int(f.read().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue   # ended meanwhile
            kids.setdefault(ppid, []).append(int(d))
    return kids


def restore(root: int, nice: int = 0) -> int:
    """Every thread of ``root`` and its descendants from SCHED_IDLE to SCHED_OTHER, at ``nice`` at least (raising a
    nice needs no privilege); how many threads were switched."""
    switched = 0
    for _ in range(2):
        kids, todo = _children(), [root]
        while todo:
            pid = todo.pop()
            todo += kids.get(pid, [])
            try:
                tids = [int(t) for t in os.listdir(f"/proc/{pid}/task")]
            except OSError:
                continue
            for tid in tids:
                try:
                    if os.sched_getscheduler(tid) == os.SCHED_IDLE:
                        os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))
                        if nice and os.getpriority(os.PRIO_PROCESS, tid) < nice:
                            os.setpriority(os.PRIO_PROCESS, tid, nice)
                        switched += 1
                except OSError:   # ended meanwhile, or not ours
                    pass
    return switched


def main(argv) -> int:
    if len(argv) >= 2 and argv[0] == "run":
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
        os.execvp(argv[1], argv[1:])
    if len(argv) in (2, 3) and argv[0] == "restore" and all(a.isdigit() for a in argv[1:]):
        restore(int(argv[1]), int(argv[2]) if len(argv) == 3 else 0)
        return 0
    print(__doc__.split("\n\n")[2], file=sys.stderr)
    return 0 if argv[:1] in (["-h"], ["--help"]) else 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
