"""QoS profile YAML, metadata.yaml and the YAML dumper (mwip_ros.bag.metadata)."""
import pytest
import yaml

from bagcheck import ENDPOINT_QOS, ENDPOINT_QOS_YAML
from mwip_ros.bag.metadata import (
    FileInfo, TopicInfo, bag_metadata, dump_yaml, metadata_yaml_text, parse_qos_yaml, qos_profiles_yaml,
    write_metadata_yaml,
)

pytestmark = pytest.mark.unit

ROSBAG2_KEYS = ["version", "storage_identifier", "duration", "starting_time", "message_count",
                "topics_with_message_count", "compression_format", "compression_mode", "relative_file_paths",
                "files", "custom_data", "ros_distro"]


def test_qos_yaml_is_rosbag2_format():
    assert qos_profiles_yaml([ENDPOINT_QOS]) == ENDPOINT_QOS_YAML
    assert qos_profiles_yaml([]) == "[]"
    assert parse_qos_yaml(ENDPOINT_QOS_YAML)[0]["reliability"] == "reliable"
    # v8 (integers) in, v9 (names) out
    v8 = ENDPOINT_QOS_YAML.replace("unknown", "3").replace("reliable", "1").replace("volatile", "2") \
        .replace("automatic", "1")
    assert parse_qos_yaml(v8) == parse_qos_yaml(ENDPOINT_QOS_YAML)
    # the loaded list (as metadata.yaml holds it) is accepted too
    assert parse_qos_yaml(yaml.safe_load(ENDPOINT_QOS_YAML)) == parse_qos_yaml(ENDPOINT_QOS_YAML)
    assert parse_qos_yaml("") == parse_qos_yaml(None) == parse_qos_yaml("[]") == []


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


def _info(custom_data=None):
    topics = [TopicInfo("/joint_states", "sensor_msgs/msg/JointState", [ENDPOINT_QOS], "RIHS01_" + "ab" * 32, 3),
              TopicInfo("/empty", "std_msgs/msg/Float64")]
    f = FileInfo("run_0.mcap")
    for t in (5, 9, 7):
        f.add(t)
    return bag_metadata(topics, [f], custom_data=custom_data)


def test_metadata_yaml_reads_back_identically_in_rosbag2_key_order(tmp_path):
    for custom in (None, {"run": "42", "note": "a: b # not a comment", "empty": "", "long": "x " * 100}):
        info = _info(custom)
        text = metadata_yaml_text(info)
        assert text.endswith("\n") and not text.endswith("\n\n")
        assert yaml.safe_load(text) == {"rosbag2_bagfile_information": info}
        assert list(yaml.safe_load(text)["rosbag2_bagfile_information"]) == ROSBAG2_KEYS
        assert len(text.splitlines()) == len(dump_yaml({"rosbag2_bagfile_information": info}).splitlines())
    path = write_metadata_yaml(tmp_path, info)
    assert path == tmp_path / "metadata.yaml" and path.read_text() == text
    assert sorted(p.name for p in tmp_path.iterdir()) == ["metadata.yaml"]


def test_metadata_yaml_layout_is_yaml_cpp_like():
    info = _info()
    lines = metadata_yaml_text(info).splitlines()
    assert lines[0] == "rosbag2_bagfile_information:"
    assert "  version: 9" in lines and "  storage_identifier: mcap" in lines
    # a sequence is indented under its key, as yaml-cpp writes it
    i = lines.index("  topics_with_message_count:")
    assert lines[i + 1] == "    - topic_metadata:" and lines[i + 2] == "        name: /joint_states"
    assert "  relative_file_paths:" in lines and "    - run_0.mcap" in lines
    assert '  compression_format: ""' in lines and "  custom_data: ~" in lines
    assert "  ros_distro: jazzy" in lines
    assert dump_yaml({"a": [], "b": {}, "c": None}) == "a: []\nb: {}\nc: ~"
