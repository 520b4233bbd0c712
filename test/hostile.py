"""Hostile inputs shared by the tests of the bounded YAML loader and the memory budget: an alias bomb, and a
tool or node run in a fresh interpreter that reports its exit code, stderr lines, wall time and peak RSS."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PAPER = REPO / "config" / "paper.yaml"
FAST_S = 10.0          # a refusal's CPU time, process start-up (rclpy, numpy) included; it takes < 2 s here. CPU
                       # time, not wall time: a loaded machine stretches the wall (14.8 s seen at load 8), not the work
LOW_KB = 300 * 1024    # a refusal's peak RSS: the bombs went past 3 GiB


def laughs(levels: int = 9) -> str:
    """A YAML alias bomb: ``levels`` levels of 9 aliases each, 9**levels strings once expanded (~870 bytes)."""
    lines = ['l0: &l0 ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    for i in range(1, levels):
        lines.append(f"l{i}: &l{i} [" + ",".join([f"*l{i - 1}"] * 9) + "]")
    return "\n".join(lines) + "\n"


def param_bomb(path: Path, levels: int = 9) -> Path:
    """A parameter file of ~870 bytes whose plant_sim section nests ``levels`` mappings of 9 aliases each:
    flattened, 9**levels parameters (the issue's bomb; without the bound the loader's flattening went past
    3 GiB).  Tests that load it in the pytest process use a few levels (harmless if the loader regressed); the
    full one runs in :func:`measured`, under an address-space limit."""
    keys = "abcdefghi"
    lines = ["plant_sim:", "  ros__parameters:",
             "    l0: &l0 {" + ", ".join(f"{k}: 1" for k in keys) + "}"]
    for i in range(1, levels):
        lines.append(f"    l{i}: &l{i} {{" + ", ".join(f"{k}: *l{i - 1}" for k in keys) + "}")
    path.write_text("\n".join(lines) + "\n")
    return path


def spec_bomb(path: Path, levels: int = 9, base: Path = None) -> Path:
    """A sweep spec whose ``duration_s`` is a list that nests ``levels`` lists of 9 aliases each (the issue's
    632-byte spec: without the bound, the error message's repr of it went past 3 GiB)."""
    lines = [f"base: {base}"] if base else []
    lines += ["duration_s:", '  - &l0 ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    for i in range(1, levels):
        lines.append(f"  - &l{i} [" + ",".join([f"*l{i - 1}"] * 9) + "]")
    path.write_text("\n".join(lines) + "\n")
    return path


# a measured process's address space: a regressed loader fails fast instead of eating the machine
AS_LIMIT = 1536 << 20


# one thread per pool, and few malloc arenas: the address space then does not grow with the machine's cores
THREADS = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1",
           "MALLOC_ARENA_MAX": "2"}


def _limit():
    import resource
    resource.setrlimit(resource.RLIMIT_AS, (AS_LIMIT, AS_LIMIT))


def measured(module: str, args, env=None, node: bool = False):
    """Run ``module``'s main(args) in a fresh interpreter: (exit code, stderr lines, CPU s, peak RSS KiB), the CPU
    time (user + system, every thread) the process spent, which a busy machine does not stretch as it does the wall.
    A ``node``'s main takes the whole argv (its name first), a tool's the arguments alone."""
    argv = "[sys.argv[0].replace('-c', 'node')] + sys.argv[1:]" if node else "sys.argv[1:]"
    code = ("import sys, importlib\n"
            f"m = importlib.import_module({module!r})\n"
            f"try:\n    rc = m.main({argv})\nexcept SystemExit as e:\n    rc = e.code\n"
            "sys.stderr.flush()\n"
            # VmHWM, not ru_maxrss: Linux keeps ru_maxrss across exec, so a child of a large pytest process
            # would report the parent's resident size at fork
            "hwm = [ln for ln in open('/proc/self/status') if ln.startswith('VmHWM:')][0].split()[1]\n"
            "import resource\n"
            "ru = resource.getrusage(resource.RUSAGE_SELF)\n"
            "print(f'CPU_S={ru.ru_utime + ru.ru_stime}', file=sys.stderr)\n"
            "print(f'PEAK_KB={hwm}', file=sys.stderr)\n"
            "sys.exit(rc)\n")
    r = subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True, timeout=120,
                       preexec_fn=_limit, env={**os.environ, "ROS_DOMAIN_ID": os.environ.get("ROS_DOMAIN_ID", "93"),
                                               **THREADS, **(env or {})})
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    peak = int(lines[-1].split("=", 1)[1]) if lines and lines[-1].startswith("PEAK_KB=") else None
    cpu = None
    if peak is not None and len(lines) >= 2 and lines[-2].startswith("CPU_S="):
        cpu, lines = float(lines[-2].split("=", 1)[1]), lines[:-2]
    elif peak is not None:
        lines = lines[:-1]
    return r.returncode, lines, cpu, peak


def assert_refused(result, *words):
    rc, lines, cpu, peak = result
    assert rc == 2, lines
    assert len(lines) == 1, lines          # one line, no traceback
    for w in words:
        assert w in lines[0], lines
    assert cpu is not None and cpu < FAST_S, cpu
    assert peak is not None and peak < LOW_KB, peak
    assert len(lines[0]) < 1000
