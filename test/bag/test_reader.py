"""The one bag reader (mwip_ros.bag.reader): files, metadata, raw messages, counts, types."""
import shutil

import pytest
import yaml

from bagcheck import T0, decoded_messages, write_bag
from mwip_ros.bag import BagError, mcap_files, raw_messages, read_metadata, topic_counts, topic_types
from mwip_ros.bag.metadata import FileInfo, TopicInfo, bag_metadata, write_metadata_yaml

pytestmark = pytest.mark.unit

TOPICS = {"/joint_states": "sensor_msgs/msg/JointState", "/wheel_torque_cmd": "std_msgs/msg/Float64"}


def split_bag(tmp_path, with_metadata=True):
    """A bag of two files whose log times interleave (file 1 is 0.5 ms after file 0)."""
    bag_dir = tmp_path / "bag"
    bag_dir.mkdir()
    expected, files = [], []
    for i in range(2):
        part = tmp_path / f"part{i}"
        written = write_bag(part, TOPICS, 20, chunk_size=500, t0=T0 + i * 500_000)
        shutil.move(part / f"part{i}_0.mcap", bag_dir / f"bag_{i}.mcap")
        expected += [(t, topic, cdr) for topic, _type, t, _msg, cdr in written]
        files.append(FileInfo(f"bag_{i}.mcap"))
        for _topic, _type, t, _msg, _cdr in written:
            files[-1].add(t)
    if with_metadata:
        topics = [TopicInfo(name, type_name, [], "", 40) for name, type_name in TOPICS.items()]
        write_metadata_yaml(bag_dir, bag_metadata(topics, files))
    return bag_dir, sorted(expected)


@pytest.mark.parametrize("with_metadata", [True, False])
def test_split_bag_merges_in_log_time_order(tmp_path, with_metadata):
    bag, expected = split_bag(tmp_path, with_metadata)
    assert mcap_files(bag) == [bag / "bag_0.mcap", bag / "bag_1.mcap"]
    got = list(raw_messages(bag))
    assert got == expected
    assert [g[0] for g in got] == sorted(g[0] for g in got)
    assert list(raw_messages(bag, topics=["/wheel_torque_cmd"])) == [e for e in expected if e[1] == "/wheel_torque_cmd"]
    assert topic_counts(bag) == {"/joint_states": 40, "/wheel_torque_cmd": 40}
    assert topic_types(bag) == TOPICS
    decoded = list(decoded_messages(bag, ["/joint_states"]))
    assert [(d[0], d[1], d[2]) for d in decoded] == \
        [(topic, "sensor_msgs/msg/JointState", t) for t, topic, _ in expected if topic == "/joint_states"]
    assert decoded[1][3].header.stamp.sec == 0  # file 1's first message comes second
    one = list(raw_messages(bag / "bag_1.mcap"))  # a single .mcap file is a bag too
    assert one == [e for e in expected if (e[0] - expected[0][0]) % 1_000_000]


def test_file_order_and_missing_files(tmp_path):
    bag = tmp_path / "b"
    bag.mkdir()
    for name in ("b_10.mcap", "b_2.mcap", "b_0.mcap"):
        (bag / name).write_bytes(b"")
    assert [p.name for p in mcap_files(bag)] == ["b_0.mcap", "b_2.mcap", "b_10.mcap"]
    write_metadata_yaml(bag, bag_metadata([], [FileInfo("b_2.mcap"), FileInfo("b_7.mcap")]))
    with pytest.raises(BagError, match="b_7.mcap"):
        mcap_files(bag)
    with pytest.raises(BagError, match="no such bag"):
        mcap_files(tmp_path / "missing")
    (tmp_path / "none").mkdir()
    with pytest.raises(BagError, match="no .mcap file"):
        mcap_files(tmp_path / "none")


def test_read_metadata(tmp_path):
    assert read_metadata(tmp_path) is None
    (tmp_path / "metadata.yaml").write_text("rosbag2_bagfile_information: [")
    with pytest.raises(BagError, match="not valid YAML"):
        read_metadata(tmp_path)
    (tmp_path / "metadata.yaml").write_text("something_else: 1\n")
    with pytest.raises(BagError, match="rosbag2_bagfile_information"):
        read_metadata(tmp_path)
    info = bag_metadata([], [FileInfo("x_0.mcap")])
    write_metadata_yaml(tmp_path, info)
    assert read_metadata(tmp_path) == yaml.safe_load(yaml.safe_dump(info))


def test_cut_short_file_says_try_repair(tmp_path):
    write_bag(tmp_path / "b", TOPICS, 30, chunk_size=400)
    mcap = tmp_path / "b" / "b_0.mcap"
    data = mcap.read_bytes()
    mcap.write_bytes(data[: len(data) // 2])
    with pytest.raises(BagError, match="mwip_bag_repair"):
        list(raw_messages(tmp_path / "b"))
    with pytest.raises(BagError, match="mwip_bag_repair"):
        topic_types(tmp_path / "b")
    with pytest.raises(BagError, match="mwip_bag_repair"):
        topic_counts(tmp_path / "b")
