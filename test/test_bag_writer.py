"""The rosbag2-compatible MCAP writer, reader and repair tool (no ROS graph needed)."""
import os
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from mwip_ros.bag import BagError, message_definition, type_hash
from mwip_ros.bag import repair as R
from mwip_ros.bag.reader import read_messages, topic_counts
from mwip_ros.bag.writer import BagWriter, parse_qos_yaml, qos_profiles_yaml
from mwip_ros.topics import GRAPH_TOPICS, graph_type

TS = get_typestore(Stores.ROS2_JAZZY)
SEP = "=" * 80

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


def T(name):
    return TS.types[name]


def stamp(i):
    return T("builtin_interfaces/msg/Time")(sec=i, nanosec=123)


def header(i):
    return T("std_msgs/msg/Header")(stamp=stamp(i), frame_id="base_link")


def vec(x, y, z):
    return T("geometry_msgs/msg/Vector3")(x=float(x), y=float(y), z=float(z))


def make_msg(type_name, i):
    """A message of ``type_name`` whose values depend on ``i``."""
    if type_name == "sensor_msgs/msg/JointState":
        effort = np.array([], dtype=np.float64) if i % 2 == 0 else np.array([0.5 * i, -1.0])
        return T(type_name)(header=header(i), name=["wheel", "body_pitch"],
                            position=np.array([0.1 * i, -0.2 * i]), velocity=np.array([1.0 * i, 2.0]),
                            effort=effort)
    if type_name == "std_msgs/msg/Float64":
        return T(type_name)(data=0.25 * i)
    if type_name == "geometry_msgs/msg/Wrench":
        return T(type_name)(force=vec(i, 2 * i, 3), torque=vec(-i, 0, 0.5))
    if type_name == "geometry_msgs/msg/WrenchStamped":
        return T(type_name)(header=header(i), wrench=T("geometry_msgs/msg/Wrench")(
            force=vec(i, 0, 1), torque=vec(0, i, 2)))
    if type_name == "rosgraph_msgs/msg/Clock":
        return T(type_name)(clock=stamp(i))
    raise AssertionError(type_name)


def as_plain(msg):
    """A rosbags or mcap_ros2 message as nested plain Python values (for equality)."""
    if isinstance(msg, (int, float, str, bool)):
        return msg
    if isinstance(msg, np.ndarray):
        return [float(x) for x in msg]
    if isinstance(msg, (list, tuple)):
        return [as_plain(x) for x in msg]
    fields = getattr(msg, "__dataclass_fields__", None) or getattr(msg, "__slots__", None)
    if fields is None:
        fields = [k for k in vars(msg) if not k.startswith("_")]
    return {k: as_plain(getattr(msg, k)) for k in fields if not k.startswith("__") and k != "__msgtype__"}


def write_graph_bag(path, n=7, compression=None, chunk_size=300):
    """Every graph topic, n messages each, interleaved; returns [(topic, type, t, msg, cdr)]."""
    written = []
    with BagWriter(path, compression=compression, chunk_size=chunk_size) as bag:
        for name, type_name in GRAPH_TOPICS.items():
            topic = name if name.startswith("/") else "/" + name
            bag.add_topic(topic, type_name, qos_profiles_yaml([ENDPOINT_QOS]), "")
        t = 1_700_000_000_000_000_000
        for i in range(n):
            for name, type_name in GRAPH_TOPICS.items():
                topic = name if name.startswith("/") else "/" + name
                msg = make_msg(type_name, i)
                cdr = bytes(TS.serialize_cdr(msg, type_name))
                bag.write(topic, cdr, t)
                written.append((topic, type_name, t, msg, cdr))
                t += 1_000_000
    return written


# --- message definitions -------------------------------------------------------------------

def test_message_definition_is_rosbag2_ros2msg_text():
    share = Path(os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)[0] or __import__("sys").prefix) / "share"
    own = (share / "sensor_msgs/msg/JointState.msg").read_text()
    text = message_definition("sensor_msgs/msg/JointState")
    assert text.startswith(own)
    header_msg = (share / "std_msgs/msg/Header.msg").read_text()
    time_msg = (share / "builtin_interfaces/msg/Time.msg").read_text()
    assert text == (own + "\n" + SEP + "\nMSG: std_msgs/Header\n" + header_msg
                    + "\n" + SEP + "\nMSG: builtin_interfaces/Time\n" + time_msg)
    # depth first, each dependency set sorted, every dependency once
    ws = message_definition("geometry_msgs/msg/WrenchStamped")
    order = [line[5:] for line in ws.splitlines() if line.startswith("MSG: ")]
    assert order == ["geometry_msgs/Wrench", "geometry_msgs/Vector3", "std_msgs/Header", "builtin_interfaces/Time"]
    assert message_definition("std_msgs/msg/Float64").count(SEP) == 0
    assert [line for line in message_definition("rosgraph_msgs/msg/Clock").splitlines()
            if line.startswith("MSG: ")] == ["MSG: builtin_interfaces/Time"]


def test_message_definition_unknown_type_names_it():
    with pytest.raises(BagError, match="std_msgs/msg/NoSuchType"):
        message_definition("std_msgs/msg/NoSuchType")
    with pytest.raises(BagError, match="no_such_msgs"):
        message_definition("no_such_msgs/msg/Foo")
    assert issubclass(BagError, ValueError)


def test_type_hash_is_installed_rihs01():
    h = type_hash("sensor_msgs/msg/JointState")
    assert h.startswith("RIHS01_") and len(h) == 7 + 64


def test_graph_topic_table():
    assert GRAPH_TOPICS["joint_states"] == "sensor_msgs/msg/JointState"
    assert graph_type("/joint_states") == graph_type("joint_states") == "sensor_msgs/msg/JointState"
    assert graph_type("/clock") == "rosgraph_msgs/msg/Clock"
    assert graph_type("nope") is None


# --- QoS ---------------------------------------------------------------------------------------

def test_qos_yaml_is_rosbag2_format():
    assert qos_profiles_yaml([ENDPOINT_QOS]) == ENDPOINT_QOS_YAML
    assert qos_profiles_yaml([]) == "[]"
    assert parse_qos_yaml(ENDPOINT_QOS_YAML)[0]["reliability"] == "reliable"
    # v8 (integers) in, v9 (names) out
    v8 = ENDPOINT_QOS_YAML.replace("unknown", "3").replace("reliable", "1").replace("volatile", "2") \
        .replace("automatic", "1")
    assert parse_qos_yaml(v8) == parse_qos_yaml(ENDPOINT_QOS_YAML)


def test_qos_yaml_from_rclpy_profile():
    from rclpy.duration import Infinite
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    q = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                   durability=DurabilityPolicy.TRANSIENT_LOCAL)
    q.deadline = Infinite
    doc = yaml.safe_load(qos_profiles_yaml([q]))
    assert doc == [{"history": "keep_last", "depth": 1000, "reliability": "reliable",
                    "durability": "transient_local", "deadline": {"sec": 9223372036, "nsec": 854775807},
                    "lifespan": {"sec": 0, "nsec": 0}, "liveliness": "system_default",
                    "liveliness_lease_duration": {"sec": 0, "nsec": 0},
                    "avoid_ros_namespace_conventions": False}]


# --- writing and reading back ------------------------------------------------------------------

@pytest.mark.parametrize("compression", [None, "zstd"])
def test_roundtrip_every_graph_type(tmp_path, compression):
    bag_dir = tmp_path / "run1"
    written = write_graph_bag(bag_dir, compression=compression)
    n_topics = len(GRAPH_TOPICS)
    assert sorted(os.listdir(bag_dir)) == ["metadata.yaml", "run1_0.mcap"]

    # rosbags (an independent rosbag2 reader): every message deserializes, equal values, counts match
    with AnyReader([bag_dir], default_typestore=TS) as reader:
        got = [(c.topic, c.msgtype, t, reader.deserialize(raw, c.msgtype), bytes(raw))
               for c, t, raw in reader.messages()]
        counts = {c.topic: c.msgcount for c in reader.connections}
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    assert len(got) == len(written)
    for (topic, type_name, t, msg, cdr), (rtopic, rtype, rt, rmsg, rraw) in zip(written, got):
        assert (topic, type_name, t, cdr) == (rtopic, rtype, rt, rraw)
        assert as_plain(rmsg) == as_plain(msg)
    assert counts == {w[0]: len(written) // n_topics for w in written}
    assert all(len(q) == 1 and q[0].reliability.name == "RELIABLE" for q in qos.values())

    # mcap + mcap_ros2 (the decoder reports and replay use): every message decodes
    with open(bag_dir / "run1_0.mcap", "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        decoded = list(reader.iter_decoded_messages())
        summary = reader.get_summary()
    assert len(decoded) == len(written)
    for (schema, channel, message, dmsg), (topic, type_name, t, msg, cdr) in zip(decoded, written):
        assert (channel.topic, schema.name, schema.encoding, message.log_time, message.data) == \
               (topic, type_name, "ros2msg", t, cdr)
        assert channel.message_encoding == "cdr"
        assert schema.data.decode() == message_definition(type_name)
        assert as_plain(dmsg) == as_plain(msg)
    for channel in summary.channels.values():
        assert channel.metadata["offered_qos_profiles"] == ENDPOINT_QOS_YAML
        schema = summary.schemas[channel.schema_id]
        assert channel.metadata["topic_type_hash"] == type_hash(schema.name)
    assert summary.statistics.chunk_count > 3  # small chunks
    assert {ci.compression for ci in summary.chunk_indexes} == {"zstd" if compression else ""}

    # metadata.yaml: rosbag2 version 9, counts equal to what was written
    meta = yaml.safe_load((bag_dir / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
    assert meta["message_count"] == len(written)
    assert meta["relative_file_paths"] == ["run1_0.mcap"]
    assert meta["starting_time"]["nanoseconds_since_epoch"] == written[0][2]
    assert meta["duration"]["nanoseconds"] == written[-1][2] - written[0][2]
    assert meta["compression_format"] == "" and meta["compression_mode"] == ""
    assert meta["ros_distro"] == "jazzy" and meta["custom_data"] is None
    assert meta["files"] == [{"path": "run1_0.mcap", "starting_time": {"nanoseconds_since_epoch": written[0][2]},
                              "duration": {"nanoseconds": written[-1][2] - written[0][2]},
                              "message_count": len(written)}]
    per_topic = {e["topic_metadata"]["name"]: e for e in meta["topics_with_message_count"]}
    for topic, type_name, *_ in written:
        entry = per_topic[topic]
        assert entry["message_count"] == len(written) // n_topics
        tm = entry["topic_metadata"]
        assert tm["type"] == type_name and tm["serialization_format"] == "cdr"
        assert tm["type_description_hash"] == type_hash(type_name)
        assert tm["offered_qos_profiles"] == yaml.safe_load(ENDPOINT_QOS_YAML)

    # our own reader
    assert topic_counts(bag_dir) == counts
    ours = list(read_messages(bag_dir, topics=["/joint_states"]))
    assert [m[2] for m in ours] == [w[2] for w in written if w[0] == "/joint_states"]
    assert list(ours[0][3].effort) == [] and ours[0][1] == "sensor_msgs/msg/JointState"


def test_writer_refuses_existing_directory(tmp_path):
    existing = tmp_path / "bag"
    existing.mkdir()
    (existing / "keep.txt").write_text("x")
    with pytest.raises(BagError, match=str(existing)):
        BagWriter(existing)
    assert os.listdir(existing) == ["keep.txt"]
    with pytest.raises(BagError, match="compression"):
        BagWriter(tmp_path / "other", compression="lz5")
    assert not (tmp_path / "other").exists()


def test_writer_errors_close_idempotent(tmp_path):
    bag = BagWriter(tmp_path / "b")
    with pytest.raises(BagError, match="/nope"):
        bag.write("/nope", b"\0\1\0\0", 1)
    bag.add_topic("/x", "std_msgs/msg/Float64")
    assert bag.add_topic("/x", "std_msgs/msg/Float64") == bag.add_topic("/x", "std_msgs/msg/Float64")
    with pytest.raises(BagError, match="/x"):
        bag.add_topic("/x", "std_msgs/msg/String")
    bag.write("/x", bytes(TS.serialize_cdr(make_msg("std_msgs/msg/Float64", 1), "std_msgs/msg/Float64")), 5)
    bag.close()
    first = (tmp_path / "b" / "metadata.yaml").read_text()
    bag.close()
    assert (tmp_path / "b" / "metadata.yaml").read_text() == first
    with pytest.raises(BagError, match="closed"):
        bag.write("/x", b"", 6)
    assert topic_counts(tmp_path / "b") == {"/x": 1}


def test_empty_bag_reads(tmp_path):
    with BagWriter(tmp_path / "empty") as bag:
        bag.add_topic("/joint_states", "sensor_msgs/msg/JointState")
    with AnyReader([tmp_path / "empty"], default_typestore=TS) as reader:
        assert list(reader.messages()) == []
    meta = yaml.safe_load((tmp_path / "empty" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == 0 and meta["topics_with_message_count"][0]["message_count"] == 0


# --- repair ----------------------------------------------------------------------------------

def _expected_saved(mcap_path, cut, written):
    """Messages of the chunks wholly inside the first ``cut`` bytes (from the intact file's index)."""
    with open(mcap_path, "rb") as fh:
        chunks = make_reader(fh).get_summary().chunk_indexes
    complete = [c for c in chunks if c.chunk_start_offset + c.chunk_length <= cut]
    if not complete:
        return 0
    last_time = max(c.message_end_time for c in complete)
    return sum(1 for w in written if w[2] <= last_time)  # log times increase strictly


@pytest.mark.parametrize("compression", [None, "zstd"])
def test_repair_truncated_copies(tmp_path, compression):
    src_dir = tmp_path / "orig"
    written = write_graph_bag(src_dir, n=12, compression=compression, chunk_size=400)
    src = src_dir / "orig_0.mcap"
    data = src.read_bytes()
    with open(src, "rb") as fh:
        chunks = make_reader(fh).get_summary().chunk_indexes
    boundary = chunks[2].chunk_start_offset + chunks[2].chunk_length  # exactly after a chunk
    cuts = sorted({len(data) // 3, len(data) // 2, boundary, boundary - 1, (2 * len(data)) // 3, len(data) - 40})
    for cut in cuts:
        bag = tmp_path / f"cut{cut}"
        bag.mkdir()
        (bag / f"cut{cut}_0.mcap").write_bytes(data[:cut])  # no metadata.yaml: the recorder died first
        expected = _expected_saved(src, cut, written)
        assert expected > 0, cut

        dry = R.repair(bag, dry_run=True)
        assert dry.total_messages == expected and sorted(os.listdir(bag)) == [f"cut{cut}_0.mcap"]

        result = R.repair(bag)
        assert result.total_messages == expected, cut
        assert 0 <= result.bytes_discarded < cut
        if cut == boundary:  # the file ends right after a chunk: nothing lost
            assert result.bytes_discarded == 0
        if cut == boundary - 1:  # ... one byte less: that whole chunk is lost
            assert result.bytes_discarded == chunks[2].chunk_length - 1
        broken = bag / f"cut{cut}_0.mcap.broken"
        assert broken.read_bytes() == data[:cut]
        assert result.files[0].backup == broken and result.metadata_written

        with AnyReader([bag], default_typestore=TS) as reader:
            got = [(c.topic, t, bytes(raw), reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages()]
            counts = {c.topic: c.msgcount for c in reader.connections}
        assert [(g[0], g[1], g[2]) for g in got] == [(w[0], w[2], w[4]) for w in written[:expected]]
        meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        assert meta["message_count"] == expected
        assert {e["topic_metadata"]["name"]: e["message_count"] for e in meta["topics_with_message_count"]} \
            == result.topic_counts
        assert sum(counts.values()) == expected
        for e in meta["topics_with_message_count"]:
            tm = e["topic_metadata"]
            assert tm["offered_qos_profiles"] == yaml.safe_load(ENDPOINT_QOS_YAML)
            assert tm["type_description_hash"] == type_hash(tm["type"])

        again = R.repair(bag)  # a second run finds a complete bag
        assert not again.needed_repair and again.total_messages == expected and not again.metadata_written


def test_repair_keeps_existing_metadata_fields(tmp_path):
    bag = tmp_path / "b"
    written = write_graph_bag(bag, n=10, chunk_size=400)
    meta_path = bag / "metadata.yaml"
    doc = yaml.safe_load(meta_path.read_text())
    doc["rosbag2_bagfile_information"]["custom_data"] = {"run": "42"}
    meta_path.write_text(yaml.safe_dump(doc))
    mcap = bag / "b_0.mcap"
    mcap.write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 2])
    assert R.main([str(mcap)]) == 0  # an .mcap inside a bag directory repairs the bag
    meta = yaml.safe_load(meta_path.read_text())["rosbag2_bagfile_information"]
    assert meta["custom_data"] == {"run": "42"}
    assert 0 < meta["message_count"] < len(written)


def test_repair_complete_bag_without_metadata(tmp_path):
    bag = tmp_path / "b"
    written = write_graph_bag(bag, n=3)
    (bag / "metadata.yaml").unlink()
    result = R.repair(bag)
    assert not result.needed_repair and result.metadata_written and result.total_messages == len(written)
    assert sorted(os.listdir(bag)) == ["b_0.mcap", "metadata.yaml"]
    with AnyReader([bag], default_typestore=TS) as reader:
        assert sum(1 for _ in reader.messages()) == len(written)


def test_repair_cli_exit_codes(tmp_path, capsys):
    bag = tmp_path / "b"
    write_graph_bag(bag, n=6, chunk_size=400)
    mcap = bag / "b_0.mcap"
    full = mcap.read_bytes()
    mcap.write_bytes(full[:100])  # not even the first chunk
    assert R.main([str(bag)]) == 1
    assert "nothing could be recovered" in capsys.readouterr().out
    assert mcap.read_bytes() == full[:100]  # left unchanged
    assert R.main([str(tmp_path / "missing")]) == 2
    assert "no such bag" in capsys.readouterr().err
    (tmp_path / "notes.txt").write_text("x")
    assert R.main([str(tmp_path / "notes.txt")]) == 2
    with pytest.raises(SystemExit) as exc:
        R.main(["--help"])
    assert exc.value.code == 0
    with pytest.raises(SystemExit) as exc:
        R.main([])
    assert exc.value.code == 2
    mcap.write_bytes(full[: len(full) * 2 // 3])
    assert R.main([str(bag), "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "would save" in out and mcap.stat().st_size == len(full) * 2 // 3
    assert R.main([str(bag)]) == 0
    out = capsys.readouterr().out
    assert "saved" in out and "b_0.mcap.broken" in out and "total:" in out
