"""robot_markers draws what joint_states says, in frame world, and refuses what it cannot use (in this process)."""
import math
import re

import pytest
from visualization_msgs.msg import MarkerArray

from mathfixtures import NOM
from mwip_ros.core.plants.model import State
from mwip_ros.msgs import layouts as L
from nodeharness import NodeHarness, node_class

pytestmark = pytest.mark.node


def test_markers_follow_the_state_and_bad_states_are_rejected():
    with NodeHarness(node_class("robot_markers")) as node:
        node.feed("joint_states", L.encode_state(5_000_000, State(2.0, 0.3, 0.0, 0.0), 0.0))
        node.feed("joint_states", b"\x00\x01\x00\x00garbage")
        node.feed("joint_states", L.encode_state(10_000_000, State(-1.0, -0.2, 0.0, 0.0), 0.0))
        got = node.messages("robot_markers", MarkerArray)
    assert [m.markers[0].header.stamp.nanosec for m in got] == [5_000_000, 10_000_000]
    first = {m.id: m for m in got[0].markers}
    assert all(m.header.frame_id == "world" and m.header.stamp.nanosec == 5_000_000 for m in first.values())
    wheel, body, cog = first[0], first[2], first[3]
    assert math.isclose(wheel.pose.position.x, NOM.r * 2.0) and math.isclose(wheel.pose.position.z, NOM.r)
    assert math.isclose(wheel.scale.x, 2 * NOM.r) and math.isclose(body.scale.z, 2 * NOM.l)
    assert (math.isclose(body.pose.orientation.y, math.sin(0.15))
            and math.isclose(body.pose.orientation.w, math.cos(0.15)))
    assert math.isclose(cog.pose.position.x, NOM.r * 2.0 + NOM.l * math.sin(0.3))
    second = {m.id: m for m in got[-1].markers}
    assert math.isclose(second[0].pose.position.x, -NOM.r)
    out = node.logs()
    drew = int(re.search(r"drew (\d+) states", out).group(1))
    assert "rejected message #1 on joint_states" in out and drew == 2, out
