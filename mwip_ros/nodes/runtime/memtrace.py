"""Where a node's memory goes over a long run: a debugging aid, off unless ``MWIP_MEMTRACE`` names a file.

    MWIP_MEMTRACE=/tmp/rec.mem [MWIP_MEMTRACE_EVERY=10] mcap_recorder --ros-args ...

With it set, ``run_node`` starts :mod:`tracemalloc` before the node is made and, every ``MWIP_MEMTRACE_EVERY``
seconds (default 10) of its loop, appends one line to the file: the seconds since the start, the resident memory
(VmRSS, KiB), the Python heap that tracemalloc traces (bytes), and glibc's own account of its heap
(``mallinfo2``: bytes in use, bytes free but kept, bytes in mmap'd blocks), which covers the C, C++ and Rust
libraries (rcl, Fast DDS, the foxglove SDK) that tracemalloc does not see, and VmRSS's parts (RssAnon, RssFile,
RssShmem: Fast DDS's shared-memory transport maps segments that count as RssShmem once touched).  So a growing RSS
can be told apart:

* the Python heap grows: our code (or rclpy's Python side) keeps something; the file ends with the 25 source lines
  whose allocations grew most since the first sample after ``MWIP_MEMTRACE_WARMUP`` seconds (default 60);
* glibc's bytes in use grow: a native library keeps something;
* only glibc's free-but-kept bytes (or RSS alone) grow: allocator fragmentation, no leak; the last line says how
  much RSS ``malloc_trim(0)`` gives back at the end.

tracemalloc slows every Python allocation (a node under it may miss realtime deadlines): use it on the tool
nodes, or accept that.  Without the variable nothing here runs.
"""
from __future__ import annotations

import ctypes
import os
import time
import tracemalloc
from typing import Optional, Tuple

__all__ = ["MemTrace", "from_environment", "rss_kib", "mallinfo", "trim"]

TOP = 25


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")]


_LIBC = []   # the C library, loaded once: a CDLL made per sample is Python heap that grows (seen: 63 KiB in 11 min)


def _libc():
    if not _LIBC:
        try:
            libc = ctypes.CDLL(None)
            libc.mallinfo2.restype = _MallInfo2
            _LIBC.append((libc, libc.mallinfo2, libc.malloc_trim))
        except (OSError, AttributeError):   # pragma: no cover - not glibc >= 2.33
            _LIBC.append(None)
    return _LIBC[0]


def trim() -> bool:
    """Give the heap's free pages back to the system (glibc's ``malloc_trim(0)``); False without glibc."""
    libc = _libc()
    if libc is None:
        return False
    libc[2](0)
    return True


def mallinfo() -> Tuple[int, int, int]:
    """glibc's heap: (bytes in use, bytes free but kept, bytes in mmap'd blocks); (-1, -1, -1) without glibc."""
    libc = _libc()
    if libc is None:
        return -1, -1, -1
    m = libc[1]()
    return int(m.uordblks), int(m.fordblks), int(m.hblkhd)


def rss_kib(key: str = "VmRSS") -> int:
    return status_kib(key)[key]


def status_kib(*keys: str, pid="self") -> dict:
    """Fields of /proc/PID/status in KiB (-1 when absent): VmRSS = RssAnon (the heaps) + RssFile (mapped files)
    + RssShmem (shared memory: Fast DDS's shared-memory transport maps its segments)."""
    out = dict.fromkeys(keys, -1)
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                name = line.split(":", 1)[0]
                if name in out:
                    out[name] = int(line.split()[1])
    except OSError:
        pass
    return out


class MemTrace:
    """Samples of RSS, the Python heap and glibc's heap into ``path`` every ``every`` seconds (see the module)."""

    def __init__(self, path: str, every: float = 10.0, warmup: float = 60.0):
        self.path, self.every, self.warmup = path, every, warmup
        tracemalloc.start(1)
        self.t0 = time.monotonic()
        self.next = self.t0
        self.base: Optional[tracemalloc.Snapshot] = None
        with open(self.path, "w") as f:
            f.write("# t_s rss_kib python_heap_bytes glibc_in_use_bytes glibc_free_bytes glibc_mmap_bytes rss_anon_kib "
                    "rss_file_kib rss_shmem_kib\n")

    def tick(self) -> None:
        now = time.monotonic()
        if now < self.next:
            return
        self.next = now + self.every
        t = now - self.t0
        traced, _ = tracemalloc.get_traced_memory()
        used, free, mapped = mallinfo()
        rss = status_kib("VmRSS", "RssAnon", "RssFile", "RssShmem")
        with open(self.path, "a") as f:
            f.write(f"{t:.1f} {rss['VmRSS']} {traced} {used} {free} {mapped} {rss['RssAnon']} {rss['RssFile']} "
                    f"{rss['RssShmem']}\n")
            if self.base is None and t >= self.warmup:
                # the snapshot is itself memory (MiB, a step in RSS): the slopes are taken after this line
                self.base = tracemalloc.take_snapshot()
                f.write(f"# baseline snapshot at t = {t:.1f} s\n")

    def close(self) -> None:
        """The last sample, what grew most since the warm-up, and what ``malloc_trim`` gives back."""
        self.next = 0.0
        self.tick()
        lines = []
        if self.base is not None:
            grown = tracemalloc.take_snapshot().compare_to(self.base, "lineno")
            lines += [f"# grew since t = {self.warmup:g} s: {s}" for s in grown[:TOP]]
        tracemalloc.stop()
        libc = _libc()
        if libc is not None:
            before = rss_kib()
            libc[2](0)
            lines.append(f"# malloc_trim(0): RSS {before} -> {rss_kib()} KiB")
        with open(self.path, "a") as f:
            f.write("\n".join(lines) + "\n")


def from_environment() -> Optional[MemTrace]:
    """A :class:`MemTrace` when ``MWIP_MEMTRACE`` names a file, else None."""
    path = os.environ.get("MWIP_MEMTRACE", "").strip()
    if not path:
        return None
    return MemTrace(path, _seconds("MWIP_MEMTRACE_EVERY", 10.0), _seconds("MWIP_MEMTRACE_WARMUP", 60.0))


def _seconds(key: str, default: float) -> float:
    try:
        value = float(os.environ.get(key, default))
    except ValueError:
        return default
    return value if value > 0 else default
