"""Test-only bag helpers: decode a recorded bag independently of the package's message layer.

``decoded_messages(bag, topics=None)`` yields ``(topic, type_name, log_time_ns, msg)`` for
every message in log-time order, where ``msg`` is decoded by mcap_ros2's CDR decoder (from
the schema stored in the file, not from the package's own layouts) and has attribute access
(``msg.position``, ``msg.header.stamp.sec``).  ``bag`` is a bag directory (its files merged
in log-time order) or one ``.mcap`` file.

The rest builds bags to test the bag layer with (:func:`write_graph_bag`, :func:`write_bag`)
and damaged copies of them with the messages a repair must save (:func:`damage_cases`),
computed from the intact file's chunk and message indexes.
"""
from __future__ import annotations

import functools
import heapq
import struct
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path
from typing import Any, Dict, Iterable, Iterator, List, Optional, Tuple, Union

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import MessageIndex
from mcap_ros2.decoder import DecoderFactory

from mwip_ros.bag import mcap_files

__all__ = [
    "ENDPOINT_QOS", "ENDPOINT_QOS_YAML", "T0", "ChunkInfo", "chunk_table", "counts_of", "damage_cases",
    "decodable_end", "decoded_messages", "saved_in_cut",
    "graph_topics", "make_msg", "summed", "typestore", "write_bag", "write_graph_bag",
]


def _decoded_file(path: Path, topics: Optional[list]) -> Iterator[Tuple[int, str, str, Any]]:
    with open(path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        for schema, channel, message, msg in reader.iter_decoded_messages(topics=topics, log_time_order=True):
            yield message.log_time, channel.topic, schema.name if schema else "", msg


def decoded_messages(bag: Union[str, Path], topics: Optional[Iterable[str]] = None
                     ) -> Iterator[Tuple[str, str, int, Any]]:
    """``(topic, type_name, log_time_ns, msg)`` of every message of ``bag``, in log-time order."""
    wanted = None if topics is None else list(topics)
    streams = [_decoded_file(path, wanted) for path in mcap_files(bag)]
    merged = streams[0] if len(streams) == 1 else heapq.merge(*streams, key=lambda m: m[0])
    for log_time, topic, type_name, msg in merged:
        yield topic, type_name, log_time, msg


# --- bags to test with -------------------------------------------------------------------------

# What `ros2 bag record` (Jazzy) stores for a publisher discovered over DDS.
ENDPOINT_QOS = {"history": 3, "depth": 0, "reliability": 1, "durability": 2,
                "deadline": {"sec": 9223372036, "nsec": 854775807},
                "lifespan": {"sec": 9223372036, "nsec": 854775807}, "liveliness": 1,
                "liveliness_lease_duration": {"sec": 9223372036, "nsec": 854775807},
                "avoid_ros_namespace_conventions": False}
ENDPOINT_QOS_YAML = (
    "- history: unknown\n  depth: 0\n  reliability: reliable\n  durability: volatile\n"
    "  deadline:\n    sec: 9223372036\n    nsec: 854775807\n"
    "  lifespan:\n    sec: 9223372036\n    nsec: 854775807\n"
    "  liveliness: automatic\n"
    "  liveliness_lease_duration:\n    sec: 9223372036\n    nsec: 854775807\n"
    "  avoid_ros_namespace_conventions: false")
T0 = 1_700_000_000_000_000_000


@functools.lru_cache(maxsize=None)
def typestore():
    """rosbags' Jazzy type store (an independent CDR serializer and rosbag2 reader)."""
    from rosbags.typesys import Stores, get_typestore
    return get_typestore(Stores.ROS2_JAZZY)


def make_msg(type_name: str, i: int):
    """A rosbags message of ``type_name`` whose values depend on ``i``."""
    import numpy as np
    T = typestore().types

    def stamp():
        return T["builtin_interfaces/msg/Time"](sec=i, nanosec=123)

    def header():
        return T["std_msgs/msg/Header"](stamp=stamp(), frame_id="base_link")

    def vec(x, y, z):
        return T["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z))

    if type_name == "sensor_msgs/msg/JointState":
        effort = np.array([], dtype=np.float64) if i % 2 == 0 else np.array([0.5 * i, -1.0])
        return T[type_name](header=header(), name=["wheel", "body_pitch"], position=np.array([0.1 * i, -0.2 * i]),
                            velocity=np.array([1.0 * i, 2.0]), effort=effort)
    if type_name == "std_msgs/msg/Float64":
        return T[type_name](data=0.25 * i)
    if type_name == "std_msgs/msg/Bool":   # emergency_stop
        return T[type_name](data=bool(i % 2))
    if type_name == "std_msgs/msg/String":   # driver_state: a transition, JSON
        return T[type_name](data=f'{{"state": "fault", "reason": "watchdog", "t": {0.005 * i:.3f}}}')
    if type_name == "geometry_msgs/msg/Twist":   # cmd_vel
        return T[type_name](linear=vec(0.1 * i, 0, 0), angular=vec(0, 0, -0.05 * i))
    if type_name == "geometry_msgs/msg/Wrench":
        return T[type_name](force=vec(i, 2 * i, 3), torque=vec(-i, 0, 0.5))
    if type_name == "geometry_msgs/msg/WrenchStamped":
        return T[type_name](header=header(), wrench=T["geometry_msgs/msg/Wrench"](
            force=vec(i, 0, 1), torque=vec(0, i, 2)))
    if type_name == "rosgraph_msgs/msg/Clock":
        return T[type_name](clock=stamp())
    if type_name == "sensor_msgs/msg/Imu":   # imu/data_raw (raw sensors): no orientation
        return T[type_name](header=header(), orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=0.0),
                            orientation_covariance=np.array([-1.0] + [0.0] * 8),
                            angular_velocity=vec(0, 0.1 * i, 0), angular_velocity_covariance=np.eye(3).ravel() * 1e-5,
                            linear_acceleration=vec(0.5 * i, 0, 9.81),
                            linear_acceleration_covariance=np.eye(3).ravel() * 4e-4)
    if type_name == "visualization_msgs/msg/MarkerArray":
        return T[type_name](markers=[_marker(T, header(), i, k) for k in range(2)])
    if type_name == "geometry_msgs/msg/PoseStamped":   # true_pose (backend mujoco)
        pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=0.1 * i, y=-0.05 * i, z=0.5),
                                           orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
        return T[type_name](header=T["std_msgs/msg/Header"](stamp=stamp(), frame_id="odom"), pose=pose)
    if type_name == "nav_msgs/msg/Odometry":   # robot_state's odom
        pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=0.1 * i, y=0.0, z=0.254),
                                           orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
        twist = T["geometry_msgs/msg/Twist"](linear=vec(0.5 * i, 0, 0), angular=vec(0, 0, 0))
        return T[type_name](header=T["std_msgs/msg/Header"](stamp=stamp(), frame_id="odom"), child_frame_id="base_link",
                            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.eye(6).ravel() * i),
                            twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)))
    raise AssertionError(type_name)


def _marker(T, header, i: int, k: int):
    import numpy as np
    point = T["geometry_msgs/msg/Point"]
    return T["visualization_msgs/msg/Marker"](
        header=header, ns="robot", id=k, type=4 if k else 3, action=0,
        pose=T["geometry_msgs/msg/Pose"](position=point(x=0.1 * i, y=0.0, z=0.5),
                                         orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)),
        scale=T["geometry_msgs/msg/Vector3"](x=0.1, y=0.1, z=0.1),
        color=T["std_msgs/msg/ColorRGBA"](r=1.0, g=0.5, b=0.0, a=1.0),
        lifetime=T["builtin_interfaces/msg/Duration"](sec=0, nanosec=0), frame_locked=False,
        points=[point(x=0.0, y=0.0, z=0.0), point(x=float(i), y=0.0, z=1.0)] if k else [],
        colors=[], texture_resource="", texture=T["sensor_msgs/msg/CompressedImage"](
            header=header, format="", data=np.array([], dtype=np.uint8)),
        uv_coordinates=[], text="", mesh_resource="",
        mesh_file=T["visualization_msgs/msg/MeshFile"](filename="", data=np.array([], dtype=np.uint8)),
        mesh_use_embedded_materials=False)


def write_bag(path, topics: Dict[str, str], n: int, compression=None, chunk_size: int = 300,
              t0: int = T0, **split) -> List[tuple]:
    """``n`` messages on each topic (topic -> type), interleaved, log times 1 ms apart from ``t0``; ``split``:
    the writer's ``max_bagfile_size``, ``max_bagfile_duration``.

    Returns ``[(topic, type_name, log_time_ns, msg, cdr_bytes)]`` in the order written."""
    from mwip_ros.bag import BagWriter, qos_profiles_yaml

    ts = typestore()
    written = []
    with BagWriter(path, compression=compression, chunk_size=chunk_size, **split) as bag:
        for topic, type_name in topics.items():
            bag.add_topic(topic, type_name, qos_profiles_yaml([ENDPOINT_QOS]), "")
        t = t0
        for i in range(n):
            for topic, type_name in topics.items():
                msg = make_msg(type_name, i)
                cdr = bytes(ts.serialize_cdr(msg, type_name))
                bag.write(topic, cdr, t)
                written.append((topic, type_name, t, msg, cdr))
                t += 1_000_000
    return written


def graph_topics() -> Dict[str, str]:
    """Every topic of the graph, absolute name -> type."""
    from mwip_ros.msgs.topics import GRAPH_TOPICS
    return {(name if name.startswith("/") else "/" + name): type_name for name, type_name in GRAPH_TOPICS.items()}


def write_graph_bag(path, n=7, compression=None, chunk_size=300, **split):
    """Every graph topic, n messages each, interleaved; returns [(topic, type, t, msg, cdr)]."""
    return write_bag(path, graph_topics(), n, compression, chunk_size, **split)


# --- what a damaged copy should give back ------------------------------------------------------

@dataclass
class ChunkInfo:
    """One chunk of an intact MCAP file: its bytes [start, end) and messages per topic;
    ``data_start``: the file offset of its (compressed) records; ``compression``; ``messages``:
    ``(topic, log_time, end)`` of each message, ``end`` being where its record ends in the
    chunk's uncompressed records, in record order."""

    start: int
    end: int
    counts: Dict[str, int]
    data_start: int = 0
    compression: str = ""
    messages: List[Tuple[str, int, int]] = None


def chunk_table(mcap_path) -> List[ChunkInfo]:
    """The chunks of an intact file in file order, from its summary's chunk indexes and the
    message indexes they point to (a chunk is opened only to read its records' lengths)."""
    import zstandard
    with open(mcap_path, "rb") as fh:
        summary = make_reader(fh).get_summary()
        table = []
        for ci in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
            counts: Dict[str, int] = {}
            starts = []
            for channel_id, offset in ci.message_index_offsets.items():
                fh.seek(offset)
                opcode, length = struct.unpack("<BQ", fh.read(9))
                assert opcode == Opcode.MESSAGE_INDEX
                index = MessageIndex.read(ReadDataStream(BytesIO(fh.read(length))))
                topic = summary.channels[channel_id].topic
                counts[topic] = counts.get(topic, 0) + len(index.records)
                starts += [(at, topic, t) for t, at in index.records]
            data_start = ci.chunk_start_offset + 9 + 8 + 8 + 8 + 4 + 4 + len(ci.compression) + 8
            fh.seek(data_start)
            data = fh.read(ci.compressed_size)
            if ci.compression == "zstd":
                data = zstandard.decompress(data, ci.uncompressed_size)
            else:
                assert ci.compression == "", ci.compression
            messages = [(topic, t, at + 9 + struct.unpack_from("<Q", data, at + 1)[0])
                        for at, topic, t in sorted(starts)]
            table.append(ChunkInfo(ci.chunk_start_offset, ci.chunk_start_offset + ci.chunk_length, counts,
                                   data_start, ci.compression, messages))
    return table


def summed(chunks: Iterable[ChunkInfo]) -> Dict[str, int]:
    out: Dict[str, int] = {}
    for c in chunks:
        for topic, n in c.counts.items():
            out[topic] = out.get(topic, 0) + n
    return {t: n for t, n in out.items() if n}


def decodable_end(data: bytes, chunk: ChunkInfo, cut: int) -> int:
    """How many bytes of ``chunk``'s uncompressed records the first ``cut`` bytes of the file
    ``data`` hold: the bytes there are (an uncompressed chunk) or what zstd's streaming
    decompression makes of them (the complete blocks), trailing zeros not trusted."""
    import zstandard
    there = data[chunk.data_start:min(cut, chunk.end)].rstrip(b"\0")
    if chunk.compression == "":
        return len(there)
    dec = zstandard.ZstdDecompressor().decompressobj()
    return len(dec.decompress(there))


def saved_in_cut(data: bytes, chunks: List[ChunkInfo], cut: int) -> List[Tuple[str, int]]:
    """``(topic, log_time)`` of the messages a repair must save from the first ``cut`` bytes of
    the intact file ``data``: those of the chunks wholly there (and their message indexes
    need not be), then those of the chunk the cut falls inside whose record is complete."""
    out = []
    for c in chunks:
        if c.end <= cut:
            out += [(topic, t) for topic, t, _end in c.messages]
        elif c.start < cut:
            there = decodable_end(data, c, cut)
            out += [(topic, t) for topic, t, end in c.messages if end <= there]
    return out


def counts_of(messages: Iterable[Tuple[str, int]]) -> Dict[str, int]:
    out: Dict[str, int] = {}
    for topic, _t in messages:
        out[topic] = out.get(topic, 0) + 1
    return out


def damage_cases(mcap_path) -> List[Tuple[str, bytes, Dict[str, int]]]:
    """Damaged copies of an intact MCAP file (with at least 6 chunks):
    ``[(case, file bytes, messages per topic a repair must save)]``: the messages of every
    intact chunk, and those of a chunk the copy ends inside whose record is complete
    (:func:`saved_in_cut`).

    Cut inside a chunk, one byte before a chunk's end, exactly at a chunk's end, after its
    message indexes, inside the summary, inside a chunk with zeros after the cut (what a
    file system may leave after a crash), 9 bytes in; a chunk in the middle with flipped
    bytes (file otherwise complete), and the same flipped chunk in a file cut short later."""
    data = Path(mcap_path).read_bytes()
    chunks = chunk_table(mcap_path)
    assert len(chunks) >= 6, len(chunks)
    k, m = len(chunks) // 3, len(chunks) // 2
    data_end = chunks[-1].end
    while data[data_end] != Opcode.DATA_END:  # past the last chunk's message indexes
        data_end += 9 + struct.unpack_from("<Q", data, data_end + 1)[0]
    summary_mid = (data_end + len(data)) // 2
    mid = (chunks[m].start + chunks[m].end) // 2
    flipped = data[:mid] + bytes(b ^ 0xFF for b in data[mid:mid + 16]) + data[mid + 16:]
    late_cut = (chunks[-2].start + chunks[-2].end) // 2

    def before(offset: int, skip: int = -1) -> Dict[str, int]:  # cut there: the complete records before it
        keep = [c for i, c in enumerate(chunks) if i != skip]
        return counts_of(saved_in_cut(data, keep, offset))

    return [
        ("cut inside a chunk", data[:mid], before(mid)),
        ("cut 1 byte before a chunk end", data[:chunks[k].end - 1], before(chunks[k].end - 1)),
        ("cut exactly at a chunk end", data[:chunks[k].end], before(chunks[k].end)),
        ("cut after a chunk's message indexes", data[:chunks[k + 1].start], before(chunks[k + 1].start)),
        ("cut inside the summary", data[:summary_mid], summed(chunks)),
        ("cut inside a chunk, zeros after", data[:mid] + bytes(4096),
         before(mid) if mid + 4096 < chunks[m].end else summed(c for c in chunks if c.end <= mid)),
        ("cut 9 bytes in", data[:9], {}),
        ("damaged chunk in the middle", flipped, summed(c for i, c in enumerate(chunks) if i != m)),
        ("damaged chunk, then cut short", flipped[:late_cut],
         before(late_cut, skip=m)),
    ]


def distinct_stamps(bag, topics) -> Dict[str, int]:
    """{topic: how many distinct stamps its messages carry} (header stamp, or a Clock's time): a state the
    lockstep plant resent before its graph answered is recorded twice but is one state."""
    seen: Dict[str, set] = {t: set() for t in topics}
    for topic, _type, _t, msg in decoded_messages(bag, list(topics)):
        stamp = getattr(msg, "clock", None) or msg.header.stamp
        seen[topic].add((stamp.sec, stamp.nanosec))
    return {t: len(v) for t, v in seen.items()}
