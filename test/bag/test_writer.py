"""The rosbag2-compatible MCAP writer (mwip_ros.bag.writer), checked with independent readers."""
import os

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from bagcheck import (ENDPOINT_QOS_YAML, decoded_messages, graph_topics, make_msg, typestore, write_bag,
                      write_graph_bag)
from mwip_ros.bag import BagError, BagWriter, message_definition, raw_messages, topic_counts, type_hash

pytestmark = pytest.mark.unit

TS = typestore()


def as_plain(msg):
    """A rosbags or mcap_ros2 message as nested plain Python values (for equality)."""
    if isinstance(msg, (int, float, str, bool)):
        return msg
    if isinstance(msg, np.ndarray):
        return [float(x) for x in msg]
    if isinstance(msg, (bytes, bytearray)):   # uint8[] as mcap_ros2 decodes it
        return [float(x) for x in msg]
    if isinstance(msg, (list, tuple)):
        return [as_plain(x) for x in msg]
    fields = getattr(msg, "__dataclass_fields__", None) or getattr(msg, "__slots__", None)
    if fields is None:
        fields = [k for k in vars(msg) if not k.startswith("_")]
    return {k: as_plain(getattr(msg, k)) for k in fields if not k.startswith("__") and not k.isupper()}  # no constants


@pytest.mark.parametrize("compression", [None, "zstd"])
def test_roundtrip_every_graph_type(tmp_path, compression):
    bag_dir = tmp_path / "run1"
    written = write_graph_bag(bag_dir, compression=compression)
    n_topics = len(graph_topics())
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
    # the rosbag2 Metadata record holds the final metadata, as YAML
    with open(bag_dir / "run1_0.mcap", "rb") as fh:
        records = list(make_reader(fh).iter_metadata())
    assert [r.name for r in records] == ["rosbag2", "rosbag2"]
    final = yaml.safe_load(records[-1].metadata["serialized_metadata"])
    assert final["message_count"] == len(written)

    # metadata.yaml: rosbag2 version 9, counts equal to what was written
    meta = yaml.safe_load((bag_dir / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert final == meta
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

    # our own reader, and the independent decoder the tests use
    assert topic_counts(bag_dir) == counts
    assert list(raw_messages(bag_dir)) == [(w[2], w[0], w[4]) for w in written]
    ours = list(decoded_messages(bag_dir, topics=["/joint_states"]))
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
    with pytest.raises(BagError, match="chunk_size"):
        BagWriter(tmp_path / "other", chunk_size=0)
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
    with pytest.raises(BagError, match="negative"):
        bag.write("/x", b"", -1)
    assert bag.topic_counts == {"/x": 1} and bag.message_count == 1
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
    assert meta["starting_time"]["nanoseconds_since_epoch"] == 2 ** 63 - 1
    assert topic_counts(tmp_path / "empty") == {"/joint_states": 0}


# (a size of 6000 bytes, below the metadata record each file carries once a few dozen files are listed in it, made
# every file hold one message: 300 files in 80 s; 20000 gives 4 files in half a second)
@pytest.mark.parametrize("split", [{"max_bagfile_duration": 0.05}, {"max_bagfile_size": 20000}],
                         ids=["duration", "size"])
def test_a_split_bag_is_rosbag2s_layout_and_every_reader_takes_it_as_one_run(tmp_path, split):
    """rosbag2's max_bagfile_size / max_bagfile_duration: files <bag>_0.mcap, <bag>_1.mcap, ..., each a whole MCAP
    file with every topic's channel; metadata.yaml lists them all (relative_file_paths, files); rosbags (an
    independent reader), our reader and each file's own summary agree with what was written."""
    bag_dir = tmp_path / "run1"
    topics = {"/joint_states": "sensor_msgs/msg/JointState", "/disturbance_estimate": "geometry_msgs/msg/WrenchStamped",
              "/wheel_torque_cmd": "std_msgs/msg/Float64"}
    n = 100
    written = write_bag(bag_dir, topics, n, **split)
    meta = yaml.safe_load((bag_dir / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    names = [f"run1_{i}.mcap" for i in range(len(meta["files"]))]
    assert len(names) >= 3 and meta["relative_file_paths"] == names
    assert sorted(os.listdir(bag_dir)) == sorted(names + ["metadata.yaml"])
    assert [f["path"] for f in meta["files"]] == names
    assert sum(f["message_count"] for f in meta["files"]) == meta["message_count"] == len(written)
    times = [w[2] for w in written]
    start = 0
    for f, name in zip(meta["files"], names):   # each file: its own span of the messages, all its channels
        with open(bag_dir / name, "rb") as fh:
            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            got = [(c.topic, m.log_time, m.data) for _s, c, m, _d in reader.iter_decoded_messages()]
            channels = {c.topic for c in reader.get_summary().channels.values()}
        assert got == [(w[0], w[2], w[4]) for w in written[start:start + len(got)]]
        assert f["message_count"] == len(got) and f["starting_time"]["nanoseconds_since_epoch"] == got[0][1]
        assert f["duration"]["nanoseconds"] == got[-1][1] - got[0][1]
        if "max_bagfile_duration" in split:
            assert got[-1][1] - got[0][1] <= split["max_bagfile_duration"] * 1e9
        elif name != names[-1]:   # a file ends once what is on disk passes the size (the chunk being filled is
            assert (bag_dir / name).stat().st_size > split["max_bagfile_size"]   # in memory till then)
        assert channels == set(topics)
        start += len(got)
    assert start == len(written)
    assert meta["duration"]["nanoseconds"] == times[-1] - times[0]

    with AnyReader([bag_dir], default_typestore=TS) as reader:
        got = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]
        counts = {}
        for c in reader.connections:
            counts[c.topic] = counts.get(c.topic, 0) + c.msgcount
    assert got == [(w[0], w[2], w[4]) for w in written]
    assert counts == {topic: n for topic in topics}
    assert topic_counts(bag_dir) == counts
    assert list(raw_messages(bag_dir)) == [(w[2], w[0], w[4]) for w in written]


def test_split_sizes_are_checked(tmp_path):
    for bad in ({"max_bagfile_size": -1}, {"max_bagfile_size": 1.5}, {"max_bagfile_duration": -1.0},
                {"max_bagfile_duration": float("inf")}):
        with pytest.raises(BagError, match=next(iter(bad))):
            BagWriter(tmp_path / "b", **bad)
