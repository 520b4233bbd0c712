"""Start mwip_ros nodes as separate processes for tests, isolated and always cleaned up.

Every process gets ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and the ROS_DOMAIN_ID of
its ``Graph``; ``Graph.close()`` ends every process it started, by PID
(SIGINT, then SIGTERM, then SIGKILL, each with a timeout).
"""
from __future__ import annotations

import fcntl
import itertools
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Dict, List, Optional


REPO = Path(__file__).resolve().parent.parent
PARAMS = REPO / "config" / "paper.yaml"
_counter = itertools.count()


_held: Dict[int, int] = {}   # domain id -> descriptor of its lock file, while this process holds it


def _lock_path(domain_id: int) -> str:
    return os.path.join(os.environ.get("TMPDIR", "/tmp"), f"mwip_ros-domain-{domain_id}.lock")


def fresh_domain_id() -> int:
    """A ROS domain in 1..101 that no other mwip_ros run holds, locked until :func:`release_domain_id`.

    ROS 2 documents 0..101 as the ids whose ports never clash (0 is the default a user's own graph is
    on). The lock is the one scripts/domain.sh takes (flock on ``$TMPDIR/mwip_ros-domain-ID.lock``),
    so a test never shares a domain with a run_experiment.sh, a bench or another test session."""
    start = (os.getpid() * 7 + next(_counter) * 13 + random.randrange(0, 97)) % 101
    for i in range(101):
        domain_id = 1 + (start + i) % 101
        if domain_id in _held:
            continue
        fd = os.open(_lock_path(domain_id), os.O_WRONLY | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue
        _held[domain_id] = fd
        return domain_id
    raise RuntimeError("every ROS domain 1..101 is held by another mwip_ros run")


def release_domain_id(domain_id: int) -> None:
    fd = _held.pop(domain_id, None)
    if fd is not None:
        os.close(fd)


def ros_env(domain_id: int) -> Dict[str, str]:
    env = dict(os.environ)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env.setdefault("AMENT_PREFIX_PATH", sys.prefix)
    env["PYTHONUNBUFFERED"] = "1"
    env["RCUTILS_LOGGING_BUFFERED_STREAM"] = "0"
    return env


def script_env(**extra: str) -> Dict[str, str]:
    """The environment for the project's scripts (run_experiment.sh, bench.sh) as a newcomer has it: no
    ROS_DOMAIN_ID, so each picks and locks a free domain of its own (this session's own domain is locked
    by scripts/test.sh, and a script asked for a held domain refuses to share it)."""
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
    env.update(extra)
    return env


def wait_until(cond, timeout: float, step: float = 0.05, spin=None) -> bool:
    """Poll ``cond()`` until it is true (True) or ``timeout`` seconds pass (False, after a last look).

    The event a test waits for (a file appearing, a message count, a process state), instead of a sleep that
    guesses how long it takes. ``spin(step)``, if given, runs between looks instead of sleeping (e.g. an
    executor's ``spin_once(timeout_sec=step)``, so the messages counted arrive)."""
    end = time.monotonic() + timeout
    while True:
        if cond():
            return True
        if time.monotonic() >= end:
            return bool(cond())
        if spin is not None:
            spin(step)
        else:
            time.sleep(step)


class Proc:
    def __init__(self, name: str, popen: subprocess.Popen, log: Path):
        self.name, self.popen, self.log = name, popen, log

    @property
    def pid(self) -> int:
        return self.popen.pid

    peak_rss_kib: Optional[int] = None  # the process's peak resident memory (VmHWM), known once it has exited

    def _sample_peak(self) -> None:
        """Keep the process's own high-water mark of resident memory (``VmHWM`` of /proc/PID/status, kept up
        to date while it runs; the wheels' re-exec keeps the PID). Not ``ru_maxrss`` from wait4: Linux
        carries that across exec, so a child of a large parent (pytest, bench.py) would report the
        parent's size at fork."""
        try:
            with open(f"/proc/{self.pid}/status") as f:
                hwm = next((int(ln.split()[1]) for ln in f if ln.startswith("VmHWM:")), None)
        except (OSError, ValueError):
            return
        if hwm is not None:
            self.peak_rss_kib = max(hwm, self.peak_rss_kib or 0)

    def wait(self, timeout: float) -> int:
        """Wait for the process to exit (subprocess.TimeoutExpired after ``timeout``), reaped with wait4;
        :attr:`peak_rss_kib` is sampled while it runs (see :meth:`_sample_peak`)."""
        end = time.monotonic() + timeout
        while self.popen.returncode is None:
            self._sample_peak()
            try:
                pid, status, _usage = os.wait4(self.pid, os.WNOHANG)
            except ChildProcessError:  # reaped elsewhere
                return self.popen.wait(timeout=max(0.0, end - time.monotonic()))
            if pid:
                self.popen.returncode = os.waitstatus_to_exitcode(status)
                break
            if time.monotonic() > end:
                raise subprocess.TimeoutExpired(self.popen.args, timeout)
            time.sleep(0.005)
        return self.popen.returncode

    def poll(self) -> Optional[int]:
        try:
            return self.wait(0.0)
        except subprocess.TimeoutExpired:
            return None

    def output(self) -> str:
        return self.log.read_text(errors="replace") if self.log.exists() else ""

    def wait_for_output(self, text: str, timeout: float = 20.0) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if text in self.output():
                return True
            if self.poll() is not None:
                return text in self.output()
            time.sleep(0.05)
        return False

    def stop(self, sig=signal.SIGINT, timeout: float = 10.0) -> Optional[int]:
        """Signal the process by PID and wait; escalate to SIGKILL. Returns the exit code."""
        if self.poll() is None:
            self._sample_peak()   # the run's peak, before shutdown
            try:
                os.kill(self.pid, sig)
                return self.wait(timeout)
            except subprocess.TimeoutExpired:
                try:
                    os.kill(self.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                self.wait(5)
                return None
            except ProcessLookupError:
                pass
        return self.poll()


def node_rules(node: str, ros_args) -> List[str]:
    """``ros_args`` with each ``-p name:=value`` made ``-p NODE:name:=value``: for the node started (its name,
    or the ``-r __node:=`` one), so that it wins over the parameter file's section, as ROS 2 has it."""
    args = list(ros_args)
    name = next((a.split(":=", 1)[1] for a in args if a.startswith("__node:=")), node)
    out = []
    for i, a in enumerate(args):
        rule = i > 0 and args[i - 1] in ("-p", "--param")
        out.append(f"{name}:{a}" if rule and ":=" in a and ":" not in a.split(":=", 1)[0] else a)
    return out


def param_files(params) -> List[Path]:
    """``params`` (None, one file or several) as a list of files."""
    if params is None:
        return []
    return [Path(params)] if isinstance(params, (str, Path)) else [Path(p) for p in params]


def loop_chain(params, *plant_args: str):
    """The answering stages of the loop these parameter files (and ``-p`` rules for the plant) configure
    (:func:`mwip_ros.core.closed_loop.loop.answering`): a raw plant's chain starts with the state estimator."""
    from mwip_ros import params as P
    from mwip_ros.core.closed_loop.loop import answering
    model = P.merged_values(P.load_param_files(param_files(params))).get("sensors.model", "state")
    for i, a in enumerate(plant_args):   # a -p sensors.model:=... rule for the plant wins
        if i > 0 and plant_args[i - 1] in ("-p", "--param") and a.split(":=", 1)[0].endswith("sensors.model"):
            model = a.split(":=", 1)[1]
    return answering(estimator=model == "raw")


class Graph:
    """A set of node processes on one private ROS domain."""

    def __init__(self, workdir: Path, domain_id: Optional[int] = None):
        self.workdir = Path(workdir)
        self._own_domain = domain_id is None
        self.domain_id = domain_id if domain_id is not None else fresh_domain_id()
        self.env = ros_env(self.domain_id)
        self.procs: List[Proc] = []

    def start(self, node: str, *ros_args: str, params=PARAMS, label: Optional[str] = None,
              module: Optional[str] = None, cmd: Optional[List[str]] = None, as_given: bool = False) -> Proc:
        """Start ``python -m mwip_ros.nodes <node>`` (as its console script starts it: mwip_ros.nodes.runtime.entry; or
        ``python -m module``, or the command ``cmd``) --ros-args ... (each ``-p`` rule for that node, see
        :func:`node_rules`, unless ``as_given``).  ``params``: a parameter file, several (a base file and
        overlays, one ``--params-file`` each, in order) or None."""
        label = label or node
        default = ["mwip_ros.nodes", node]
        cmd = list(cmd or [sys.executable, "-m", *([module] if module else default)]) + ["--ros-args"]
        for f in param_files(params):
            cmd += ["--params-file", str(f)]
        cmd += list(ros_args) if as_given else node_rules(node, ros_args)
        log = self.workdir / f"{label}.log"
        f = open(log, "wb")
        p = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, env=self.env, cwd=self.workdir)
        f.close()
        proc = Proc(label, p, log)
        self.procs.append(proc)
        return proc

    def close(self) -> None:
        for p in reversed(self.procs):
            p.stop(signal.SIGINT, timeout=10)
        if self._own_domain:
            release_domain_id(self.domain_id)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def run_lockstep(workdir: Path, use_observer: bool, *plant_args: str, timeout: float = 180.0,
                 params=PARAMS, law: str = "dsc", wait=None, domain_id: Optional[int] = None):
    """The loop's nodes and the plant (lockstep), each a process; returns (plant exit, csv path, graph logs).

    The nodes are the answering stages of the chain the parameters configure (:func:`loop_chain`: the
    observer and the controller; a raw plant's state estimator first).  ``params``: one file or several
    (a base file and overlays).  The plant writes ``graph.csv``, the observer its estimates to
    ``estimates.csv`` beside it (and the estimator, if it has a ``csv`` parameter, to ``estimator.csv``).
    ``wait(plant, timeout)``, if given, waits for the plant instead of ``plant.wait`` and returns its exit
    code (e.g. spinning a test's own subscriber meanwhile); ``domain_id``: the graph's domain (default a fresh
    one), for such a subscriber made before the graph."""
    from mwip_ros import params as P
    csv_path = workdir / "graph.csv"
    args = {"disturbance_observer": ("-p", f"csv:={workdir / 'estimates.csv'}"),
            "dscndo_controller": ("-p", f"use_observer:={'true' if use_observer else 'false'}", "-p", f"law:={law}")}
    if "csv" in P.specs_for("state_estimator"):
        args["state_estimator"] = ("-p", f"csv:={workdir / 'estimator.csv'}")
    with Graph(workdir, domain_id) as g:
        procs = [g.start(a.node, "-p", "use_sim_time:=true", *args.get(a.node, ()), params=params)
                 for a in loop_chain(params, *plant_args)]
        plant = g.start("plant_sim", "-p", f"csv:={csv_path}", *plant_args, params=params)
        code = plant.wait(timeout) if wait is None else wait(plant, timeout)
        logs = {p.name: p for p in (*procs, plant)}
    return code, csv_path, logs
