"""The memory tracer of a long run (nodes.runtime.memtrace, MWIP_MEMTRACE): its samples and what it names as grown."""
import tracemalloc

import pytest

from mwip_ros.nodes.runtime import memtrace

pytestmark = pytest.mark.unit

KEPT = []


def test_off_unless_the_variable_names_a_file(monkeypatch, tmp_path):
    monkeypatch.delenv("MWIP_MEMTRACE", raising=False)
    assert memtrace.from_environment() is None
    monkeypatch.setenv("MWIP_MEMTRACE", "  ")
    assert memtrace.from_environment() is None
    monkeypatch.setenv("MWIP_MEMTRACE", str(tmp_path / "n.mem"))
    monkeypatch.setenv("MWIP_MEMTRACE_EVERY", "abc")      # a bad value: the default, not a crash
    monkeypatch.setenv("MWIP_MEMTRACE_WARMUP", "-3")
    m = memtrace.from_environment()
    try:
        assert (m.every, m.warmup) == (10.0, 60.0)
    finally:
        tracemalloc.stop()


def test_samples_and_names_the_line_whose_objects_grew(tmp_path, monkeypatch):
    """A list that keeps 20,000 objects after the warm-up: the Python heap column grows by about their size, and
    the closing lines name this file's line that made them; every sample has its nine columns, and the baseline
    snapshot (a step in RSS, after which the slopes are taken) is marked where it was taken."""
    clock = [1000.0]
    monkeypatch.setattr(memtrace.time, "monotonic", lambda: clock[0])
    path = tmp_path / "node.mem"
    m = memtrace.MemTrace(str(path), every=10.0, warmup=20.0)
    for _ in range(3):      # t = 0, 10, 20: the baseline snapshot at 20
        m.tick()
        clock[0] += 10.0
    m.tick()                # t = 30
    clock[0] += 5.0
    m.tick()                # not due: no line
    KEPT.extend(str(i) * 10 for i in range(20_000))   # ~1.2 MB kept
    clock[0] += 10.0
    m.close()
    KEPT.clear()
    lines = path.read_text().splitlines()
    rows = [[float(v) for v in line.split()] for line in lines if not line.startswith("#")]
    assert [r[0] for r in rows] == [0.0, 10.0, 20.0, 30.0, 45.0]
    assert all(len(r) == 9 and r[1] > 0 and r[1] >= r[6] > 0 for r in rows)   # VmRSS >= its RssAnon
    assert lines.index("# baseline snapshot at t = 20.0 s") == 4   # after the header and the samples at 0, 10, 20
    assert rows[-1][2] - rows[-2][2] > 1e6   # the Python heap column saw the kept objects
    grew = [line for line in lines if line.startswith("# grew since t = 20 s")]
    assert grew and "test_memtrace.py" in grew[0], grew[:3]
    assert any(line.startswith("# malloc_trim(0): RSS") for line in lines)
    assert not tracemalloc.is_tracing()


def test_a_sample_keeps_no_memory_of_its_own():
    """Each sample reads glibc's heap through ctypes: made once, not a CDLL per sample (which kept ~220 B each: the
    tracer's own growth, 63 KiB in an 11-minute soak, was the first thing it found)."""
    memtrace.mallinfo()
    tracemalloc.start(1)
    try:
        before, _ = tracemalloc.get_traced_memory()
        for _ in range(2000):
            used, free, mapped = memtrace.mallinfo()
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert used > 0 and free >= 0 and mapped >= 0
    assert grown < 20_000, grown
