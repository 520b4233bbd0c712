"""The stall probe (mwip_ros.nodes.runtime.stallprobe, a debugging aid): off without its variable; with it, a tick
that stops for longer than the threshold is reported once, with every thread's state, and its length when the tick
runs again. The watcher is a process of its own: the test bounds wall time, so it runs alone."""
import os
import time

import pytest

from mwip_ros.nodes.runtime import stallprobe


@pytest.mark.unit
def test_off_unless_the_variable_names_a_directory(monkeypatch, tmp_path):
    monkeypatch.delenv("MWIP_STALL_PROBE", raising=False)
    assert stallprobe.from_environment("plant_sim") is None
    stallprobe.beat()   # a no-op without a probe
    monkeypatch.setenv("MWIP_STALL_PROBE", str(tmp_path))
    monkeypatch.setenv("MWIP_STALL_PROBE_NODES", "wheel_driver")
    assert stallprobe.from_environment("plant_sim") is None   # not one of the nodes named
    assert list(tmp_path.iterdir()) == []


@pytest.mark.unit
def test_a_futex_word_is_named_by_its_mapping():
    maps = ("55d4a9c00000-55d4aa200000 rw-p 00000000 00:00 0                          [heap]\n"
            "7fb066835000-7fb066836000 rw-s 00000000 00:1a 1234                       /dev/shm/fastrtps_port7003\n"
            "7fb066837000-7fb066838000 rw-p 00000000 00:00 0\n")
    assert stallprobe._mapping(maps, 0x7fb066835000) == "/dev/shm/fastrtps_port7003"
    assert stallprobe._mapping(maps, 0x55d4a9d22ca0) == "[heap]"
    assert stallprobe._mapping(maps, 0x7fb066837010) == "anonymous"
    assert stallprobe._mapping(maps, 0x10) == "unmapped"


@pytest.mark.alone
@pytest.mark.cli
def test_a_stalled_tick_is_reported_once_with_every_thread_and_its_length(monkeypatch, tmp_path):
    monkeypatch.setenv("MWIP_STALL_PROBE", str(tmp_path))
    monkeypatch.setenv("MWIP_STALL_PROBE_MS", "500")
    monkeypatch.delenv("MWIP_STALL_PROBE_NODES", raising=False)
    monkeypatch.setenv("PATH", "/nonexistent")   # no py-spy: /proc only (the watcher runs by its full path)
    probe = stallprobe.from_environment("plant_sim")
    report = tmp_path / f"plant_sim-{os.getpid()}.stalls"
    try:
        time.sleep(0.8)   # no tick yet: not a stall
        for _ in range(20):   # ticking every 5 ms: no stall
            stallprobe.beat()
            time.sleep(0.005)
        assert not report.exists()
        end = time.monotonic() + 30
        while not report.exists() and time.monotonic() < end:   # the tick stops until the watcher has seen it
            time.sleep(0.01)
        stallprobe.beat()
        while "ran again" not in report.read_text() and time.monotonic() < end:
            time.sleep(0.01)
    finally:
        probe.close()
    text = report.read_text()
    assert text.count("stall: the tick has not run for") == 1, text
    assert f"thread {os.getpid()} " in text and "state " in text and "syscall " in text, text
    ran = int(text.split("ran again after ")[1].split(" ms")[0])
    assert ran >= 500, text
    assert stallprobe._ACTIVE == []
