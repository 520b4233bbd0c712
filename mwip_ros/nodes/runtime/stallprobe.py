"""Where a node's loop is when it stalls: a debugging aid, off unless ``MWIP_STALL_PROBE`` names a directory.

    MWIP_STALL_PROBE=/tmp/probe [MWIP_STALL_PROBE_MS=60] [MWIP_STALL_PROBE_NODES=plant_sim,...] plant_sim ...

With it set, ``run_node`` makes the probe, and the node's realtime tick (plant_sim's runner, the wheel driver)
writes the monotonic time into a small shared file at each wake (:func:`beat`: a store into a memory map; a no-op
without the variable), and a watcher process (this module run as a script) that
reads that file every 2 ms. When the tick has not run for ``MWIP_STALL_PROBE_MS`` ms (default 60: a realtime
loop wakes at least once a period), the watcher appends to ``<dir>/<node>-<pid>.stalls`` what every thread of the
node is doing: from ``/proc`` at once (its state, the kernel function it waits in, the system call and its
arguments, the kernel stack when readable), then, if ``py-spy`` is on the PATH, the native and Python stack of each
thread (``py-spy dump --native``: it pauses the node for about 0.2 s, so a probed run misses more deadlines). One
report per stall; the stall's length is written when the tick runs again (``MWIP_STALL_PROBE_NODES``: probe only
these nodes, comma-separated; default every node that ticks). Without the variable nothing here runs.
"""
from __future__ import annotations

import mmap
import os
import shutil
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import List, Optional

__all__ = ["StallProbe", "from_environment", "beat"]

_BEAT = struct.Struct("=q")
_ACTIVE: List["StallProbe"] = []   # this process's probe, while one runs


def beat() -> None:
    """The realtime tick ran: now (nothing without a probe)."""
    if _ACTIVE:
        _ACTIVE[0].beat()


class StallProbe:
    """The node's side: a beat per turn of its loop into ``path``, watched by a process of its own.

    Parameters
    ----------
    directory : Path
        Where the beat file and the report go.
    name : str
        The node's name (the files' prefix).
    threshold_ms : float
        A loop that has not turned for this long is reported.
    """

    def __init__(self, directory: Path, name: str, threshold_ms: float):
        directory.mkdir(parents=True, exist_ok=True)
        stem = directory / f"{name}-{os.getpid()}"
        self.path = stem.with_suffix(".beat")
        self.path.write_bytes(_BEAT.pack(0))   # 0: no tick yet (a node that never ticks is never reported)
        self._file = open(self.path, "r+b")   # noqa: SIM115 (held for the node's life)
        self._map = mmap.mmap(self._file.fileno(), _BEAT.size)
        self.watcher = subprocess.Popen(
            [sys.executable, __file__, str(os.getpid()), str(self.path), str(stem.with_suffix(".stalls")),
             str(threshold_ms)], stdin=subprocess.DEVNULL, start_new_session=True)
        _ACTIVE[:] = [self]

    def beat(self) -> None:
        """The loop turned: now."""
        _BEAT.pack_into(self._map, 0, time.monotonic_ns())

    def close(self) -> None:
        """Stop the watcher; the report stays."""
        _ACTIVE.clear()
        self.watcher.terminate()
        try:
            self.watcher.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.watcher.kill()
        self._map.close()
        self._file.close()


def from_environment(name: str) -> Optional[StallProbe]:
    """A probe for node ``name`` when ``MWIP_STALL_PROBE`` names a directory, else None."""
    directory = os.environ.get("MWIP_STALL_PROBE", "").strip()
    nodes = [n.strip() for n in os.environ.get("MWIP_STALL_PROBE_NODES", "").split(",") if n.strip()]
    if not directory or (nodes and name not in nodes):
        return None
    return StallProbe(Path(directory), name, float(os.environ.get("MWIP_STALL_PROBE_MS", "60")))


def _read(path: str) -> str:
    try:
        with open(path) as f:
            return f.read().strip()
    except OSError as exc:
        return f"({exc.strerror})"


def _mapping(maps: str, address: int) -> str:
    """The file (or [heap], [stack]) of ``pid``'s mapping that holds ``address``, from /proc/PID/maps' text."""
    for line in maps.splitlines():
        fields = line.split()
        start, end = (int(x, 16) for x in fields[0].split("-"))
        if start <= address < end:
            return fields[5] if len(fields) > 5 else "anonymous"
    return "unmapped"


def _threads(pid: int) -> List[str]:
    """Each thread of ``pid`` as /proc tells it now; for a thread in futex(2), the mapping its word is in (a shared
    memory file names another process's part in the wait)."""
    lines = []
    maps = _read(f"/proc/{pid}/maps")
    for tid in sorted(os.listdir(f"/proc/{pid}/task"), key=int):
        base = f"/proc/{pid}/task/{tid}"
        stat = _read(f"{base}/stat")
        state = stat.rsplit(")", 1)[-1].split()[0] if ")" in stat else "?"
        call = _read(base + "/syscall")
        where = ""
        if call.startswith("202 "):   # futex(uaddr, op, ...)
            try:
                where = f" (futex word in {_mapping(maps, int(call.split()[1], 16))})"
            except (ValueError, IndexError):
                pass
        lines.append(f"  thread {tid} {_read(base + '/comm')!r} state {state} wchan {_read(base + '/wchan')} "
                     f"syscall {call}{where}")
        stack = _read(f"{base}/stack")
        if stack and not stack.startswith("("):
            lines.extend("      " + ln for ln in stack.splitlines()[:12])
    return lines


def watch(pid: int, beat_path: str, out_path: str, threshold_ms: float) -> None:
    """Report each stall of ``pid``'s loop to ``out_path`` until ``pid`` ends."""
    threshold = int(threshold_ms * 1e6)
    spy = shutil.which("py-spy")
    with open(beat_path, "rb") as f:
        beats = mmap.mmap(f.fileno(), _BEAT.size, access=mmap.ACCESS_READ)
        stalled_since = None
        while os.path.exists(f"/proc/{pid}"):
            last = _BEAT.unpack_from(beats, 0)[0]
            now = time.monotonic_ns()
            if stalled_since is None and last and now - last > threshold:
                stalled_since = last
                report = [f"stall: the tick has not run for {(now - last) / 1e6:.0f} ms "
                          f"(at monotonic {now / 1e9:.3f} s)"] + _threads(pid)
                if spy:
                    dump = subprocess.run([spy, "dump", "--native", "--pid", str(pid)], capture_output=True,
                                          text=True, timeout=30)
                    report.append(f"  py-spy, {(time.monotonic_ns() - now) / 1e6:.0f} ms after:")
                    report.extend("    " + ln for ln in (dump.stdout + dump.stderr).splitlines())
                with open(out_path, "a") as out:
                    out.write("\n".join(report) + "\n")
            elif stalled_since is not None and last != stalled_since:
                with open(out_path, "a") as out:
                    out.write(f"  the tick ran again after {(last - stalled_since) / 1e6:.0f} ms\n\n")
                stalled_since = None
            time.sleep(0.002)


if __name__ == "__main__":
    watch(int(sys.argv[1]), sys.argv[2], sys.argv[3], float(sys.argv[4]))
