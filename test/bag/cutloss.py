"""How much of a run a repair loses when the recording is cut: bags to cut, cut points, the loss.

A *run* is what the recorder writes in a lockstep run of the graph: every loop topic at
``RATE_HZ`` (log times one period apart, the topics of a state together), written with
:class:`~mwip_ros.bag.BagWriter` (the recorder's writer, its chunk size and compression).
Two ways to cut it:

* **a cut file** (:func:`cut_points`, :func:`time_at_cut`): the first bytes of the intact
  file, what a full disk, a power loss or a copy broken off leaves; the run's time at the cut
  is the log time of the last message whose record lies wholly before it (in a zstd chunk,
  where only whole blocks decode: before the same fraction of the cut block's uncompressed
  bytes as of its compressed bytes);
* **a killed recorder** (``kills`` of :func:`record_run`): the bytes on disk after the
  messages up to a log time were handed to the writer, as ``kill -9`` leaves them (the
  writer's file output is unbuffered); the run's time is that of the last message written.

:func:`loss` repairs a copy and returns the seconds of the run lost: the run's time at the
cut minus the log time of the last message the repaired bag holds (one period before the
first message when it holds none, so losing everything up to time t counts t plus a period).
"""
from __future__ import annotations

import functools
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, Iterable, List, Optional, Tuple

from mcap.reader import make_reader

from bagcheck import ENDPOINT_QOS, T0, ChunkInfo, chunk_table, typestore

RATE_HZ = 200
RUN_S = 10.0
# The topics of a lockstep run the recorder writes once per state (the loop and what watches it).
RUN_TOPICS = {
    "/clock": "rosgraph_msgs/msg/Clock",
    "/joint_states": "sensor_msgs/msg/JointState",
    "/wheel_torque_cmd": "std_msgs/msg/Float64",
    "/disturbance_estimate": "geometry_msgs/msg/WrenchStamped",
    "/lumped_disturbance": "geometry_msgs/msg/WrenchStamped",
    "/controller_internals": "sensor_msgs/msg/JointState",
    "/robot_markers": "visualization_msgs/msg/MarkerArray",
}
_VARIANTS = 400  # distinct payloads per topic (the values change from state to state)


@functools.lru_cache(maxsize=None)
def _payloads() -> Dict[str, List[bytes]]:
    """CDR bytes of ``_VARIANTS`` different messages per topic of :data:`RUN_TOPICS`."""
    from bagcheck import make_msg
    ts = typestore()
    return {topic: [bytes(ts.serialize_cdr(make_msg(type_name, i), type_name)) for i in range(_VARIANTS)]
            for topic, type_name in RUN_TOPICS.items()}


@dataclass
class Run:
    """A recorded run: its MCAP file, ``(topic, log_time)`` of every message in the order
    written, the bytes on disk at each kill time (seconds from the start) and the period."""

    mcap: Path
    written: List[Tuple[str, int]]
    kills: Dict[float, bytes] = field(default_factory=dict)
    period_ns: int = int(1e9 / RATE_HZ)

    @property
    def t0(self) -> int:
        return self.written[0][1]

    @functools.cached_property
    def chunks(self) -> List[ChunkInfo]:
        return chunk_table(self.mcap)

    def blocks(self, c: ChunkInfo) -> List[Tuple[int, int, int, int]]:
        """The zstd blocks of chunk ``c`` (positions relative to its compressed records)."""
        cache = self.__dict__.setdefault("_blocks", {})
        if c.start not in cache:
            with open(self.mcap, "rb") as fh:
                fh.seek(c.data_start)
                cache[c.start] = zstd_blocks(fh.read(c.end - c.data_start))
        return cache[c.start]


def record_run(bag_dir: Path, seconds: float = RUN_S, rate_hz: int = RATE_HZ, compression: Optional[str] = None,
               kills: Iterable[float] = (), **writer_args) -> Run:
    """Write a run of ``seconds`` at ``rate_hz`` into the new bag ``bag_dir`` (``writer_args``:
    BagWriter's, e.g. ``chunk_size``, ``max_chunk_duration``); keep what is on disk after the
    last message at or before each of ``kills`` [s from the start] (what kill -9 then leaves)."""
    from mwip_ros.bag import BagWriter, qos_profiles_yaml

    payloads = _payloads()
    period = int(round(1e9 / rate_hz))
    pending = sorted(kills)
    written: List[Tuple[str, int]] = []
    snapshots: Dict[float, bytes] = {}
    with BagWriter(bag_dir, compression=compression, **writer_args) as bag:
        for topic, type_name in RUN_TOPICS.items():
            bag.add_topic(topic, type_name, qos_profiles_yaml([ENDPOINT_QOS]), "")
        for i in range(int(round(seconds * rate_hz))):
            t = T0 + i * period
            while pending and (t - T0) / 1e9 > pending[0] + 1e-12:
                snapshots[pending.pop(0)] = bag.mcap_path.read_bytes()
            for topic in RUN_TOPICS:
                bag.write(topic, payloads[topic][i % _VARIANTS], t)
                written.append((topic, t))
        for k in pending:
            snapshots[k] = bag.mcap_path.read_bytes()
    return Run(bag.mcap_path, written, snapshots, period)


def zstd_blocks(frame: bytes) -> List[Tuple[int, int, int, int]]:
    """``(start, end, out_start, out_end)`` of each block of a zstd frame: its compressed bytes
    in ``frame`` and the uncompressed bytes it decodes to (a block decodes only whole)."""
    import zstandard
    assert frame[:4] == b"\x28\xb5\x2f\xfd", "not a zstd frame"
    fhd = frame[4]
    single = (fhd >> 5) & 1
    fcs = (0 if not single else 1, 2, 4, 8)[fhd >> 6]
    pos = 5 + (0 if single else 1) + (0, 1, 2, 4)[fhd & 3] + fcs
    dec = zstandard.ZstdDecompressor().decompressobj()
    out = len(dec.decompress(frame[:pos]))
    blocks = []
    while pos + 3 <= len(frame):
        head = int.from_bytes(frame[pos:pos + 3], "little")
        kind, size = (head >> 1) & 3, head >> 3
        end = pos + 3 + (1 if kind == 1 else size)
        got = len(dec.decompress(frame[pos:end]))
        blocks.append((pos, end, out, out + got))
        out += got
        pos = end
        if head & 1:
            break
    return blocks


def _plain_position(run: "Run", c: ChunkInfo, there: int) -> float:
    """Where ``there`` bytes into the compressed records of ``c`` fall in its uncompressed
    records: proportionally inside the zstd block they fall in."""
    for start, end, out_start, out_end in run.blocks(c):
        if there < end:
            return out_start + max(0, there - start) / (end - start) * (out_end - out_start)
    return c.messages[-1][2]


def _compressed_position(run: "Run", c: ChunkInfo, plain: int) -> int:
    """The inverse of :func:`_plain_position`, rounded up."""
    for start, end, out_start, out_end in run.blocks(c):
        if plain <= out_end:
            return start + -(-(plain - out_start) * (end - start) // max(1, out_end - out_start))
    return c.end - c.data_start


def offset_at(run: "Run", t_ns: int, into_next: int = 3) -> int:
    """The byte offset ``into_next`` bytes past the record of the last message at or before log
    time ``t_ns`` (in a compressed chunk: where that record ends in its block's compressed bytes,
    proportionally)."""
    last = None
    for c in run.chunks:
        for _topic, t, end in c.messages:
            if t <= t_ns:
                last = (c, end)
    if last is None:
        raise ValueError(f"no message at or before log time {t_ns}")
    c, end = last
    if c.compression:
        end = _compressed_position(run, c, end)
    return c.data_start + end + into_next


def cut_points(run: "Run", at_times: Iterable[float] = (0.1, 0.25, 0.4, 1.0, 2.0, 3.0, 3.5),
               of_file: Iterable[float] = tuple(i / 20 for i in range(1, 20))) -> List[Tuple[str, int]]:
    """``(label, byte offset)`` of the cuts to try: 3 bytes into the record after the message at
    each of ``at_times`` [s from the start] (with 1 MiB chunks, all inside the first; with the
    0.5 s chunks of the default writer, the first three), then fractions of the file size."""
    size = run.mcap.stat().st_size
    out = [(f"{t:g} s into the run + 3 B", offset_at(run, run.t0 + int(t * 1e9))) for t in at_times]
    out += [(f"{f:.0%} of the file", int(f * size)) for f in of_file]
    return out


def time_at_cut(run: "Run", cut: int) -> Optional[int]:
    """Log time of the last message whose record lies wholly in the first ``cut`` bytes of the
    intact file (see the module docstring); None when there is none."""
    last = None
    for c in run.chunks:
        if c.end <= cut:
            last = c.messages[-1][1]
        elif c.start < cut:
            there = cut - c.data_start
            if c.compression:
                there = _plain_position(run, c, there)
            done = [t for _topic, t, end in c.messages if end <= there]
            if done:
                last = done[-1]
    return last


def saved_last(bag: Path) -> Optional[int]:
    """Log time of the last message of the (repaired, complete) bag, from the statistics in its
    files' summaries; None when it has none."""
    last = None
    for mcap in sorted(bag.glob("*.mcap")):
        with open(mcap, "rb") as fh:
            stats = make_reader(fh).get_summary().statistics
        if stats.message_count:
            last = stats.message_end_time if last is None else max(last, stats.message_end_time)
    return last


def copy_bag(data: bytes, bag: Path) -> Path:
    """A bag directory ``bag`` holding only ``data`` as its MCAP file (the recorder died before
    writing metadata.yaml)."""
    if bag.exists():
        shutil.rmtree(bag)
    bag.mkdir(parents=True)
    (bag / f"{bag.name}_0.mcap").write_bytes(data)
    return bag


def lost_seconds(run: Run, t_cut: Optional[int], t_saved: Optional[int]) -> float:
    """Seconds of the run between the last message before the cut and the last one saved."""
    if t_cut is None:
        return 0.0
    saved = run.t0 - run.period_ns if t_saved is None else t_saved
    return (t_cut - saved) / 1e9


def repair_cut(run: Run, data: bytes, t_cut: Optional[int], bag: Path, repair=None):
    """Repair ``data`` (a cut copy of ``run``) as the bag ``bag``: ``(seconds of the run lost,
    the RepairResult)``."""
    if repair is None:
        from mwip_ros.bag import repair
    copy_bag(data, bag)
    result = repair(bag)
    saved = None if any(f.error for f in result.files) else saved_last(bag)  # error: nothing recovered
    return lost_seconds(run, t_cut, saved), result


def loss(run: Run, data: bytes, t_cut: Optional[int], bag: Path, repair=None) -> float:
    """The seconds of the run lost when ``data`` is repaired (see :func:`repair_cut`)."""
    return repair_cut(run, data, t_cut, bag, repair)[0]
