"""Message definitions and type hashes for MCAP schemas (mwip_ros.bag.schema)."""
import os
import sys
from pathlib import Path

import pytest

from mwip_ros.bag import BagError, message_definition, type_hash
from mwip_ros.msgs.topics import GRAPH_TOPICS, graph_type

pytestmark = pytest.mark.unit

SEP = "=" * 80


def test_message_definition_is_rosbag2_ros2msg_text():
    share = Path(os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)[0] or sys.prefix) / "share"
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
    assert message_definition("std_msgs/Float64") == message_definition("std_msgs/msg/Float64")


def test_message_definition_unknown_type_names_it():
    with pytest.raises(BagError, match="std_msgs/msg/NoSuchType"):
        message_definition("std_msgs/msg/NoSuchType")
    with pytest.raises(BagError, match="no_such_msgs"):
        message_definition("no_such_msgs/msg/Foo")
    assert issubclass(BagError, ValueError)


@pytest.mark.parametrize("bad", ["Float64", "std_msgs/msg/Float64/x", "std msgs/Float64", "", "/std_msgs/Float64"])
def test_bad_type_name_is_a_bag_error(bad):
    with pytest.raises(BagError, match="not a ROS message type name"):
        message_definition(bad)
    assert type_hash(bad) == ""


def test_type_hash_is_installed_rihs01():
    h = type_hash("sensor_msgs/msg/JointState")
    assert h.startswith("RIHS01_") and len(h) == 7 + 64
    assert type_hash("no_such_msgs/msg/Foo") == ""


def test_graph_topic_table():
    assert GRAPH_TOPICS["joint_states"] == "sensor_msgs/msg/JointState"
    assert graph_type("/joint_states") == graph_type("joint_states") == "sensor_msgs/msg/JointState"
    assert graph_type("/clock") == "rosgraph_msgs/msg/Clock"
    assert graph_type("nope") is None
