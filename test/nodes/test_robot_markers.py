"""robot_markers draws what joint_states says, in frame world, and refuses what it cannot use."""
import math

import pytest
from sensor_msgs.msg import JointState
from visualization_msgs.msg import MarkerArray

from graphproc import Graph
from injector import Injector
from mathfixtures import NOM
from mwip_ros.core.model import State
from mwip_ros.msgs import layouts as L

pytestmark = pytest.mark.graph


def test_markers_follow_the_state_and_bad_states_are_rejected(tmp_path):
    with Graph(tmp_path) as g:
        node = g.start("robot_markers")
        with Injector(g.domain_id) as inj:
            js = inj.publisher("joint_states", JointState)
            got = []
            sub = inj.node.create_subscription(MarkerArray, "robot_markers", got.append, 10)
            # matched both ways (not only discovered): a volatile marker published before our reader matched
            # would be lost, and this test sends each state once
            assert inj.wait(lambda: (js.get_subscription_count() >= 1
                                     and sub.get_publisher_count() >= 1), 30), node.output()
            js.publish(L.encode_state(5_000_000, State(2.0, 0.3, 0.0, 0.0), 0.0))
            assert inj.wait(lambda: len(got) >= 1, 30), node.output()
            js.publish(b"\x00\x01\x00\x00garbage")
            js.publish(L.encode_state(10_000_000, State(-1.0, -0.2, 0.0, 0.0), 0.0))
            assert inj.wait(lambda: len(got) >= 2, 30), node.output()
        assert node.stop() == 0
    first = {m.id: m for m in got[0].markers}
    assert all(m.header.frame_id == "world" and m.header.stamp.nanosec == 5_000_000 for m in first.values())
    wheel, body, cog = first[0], first[2], first[3]
    assert math.isclose(wheel.pose.position.x, NOM.r * 2.0) and math.isclose(wheel.pose.position.z, NOM.r)
    assert math.isclose(wheel.scale.x, 2 * NOM.r) and math.isclose(body.scale.z, 2 * NOM.l)
    assert (math.isclose(body.pose.orientation.y, math.sin(0.15))
            and math.isclose(body.pose.orientation.w, math.cos(0.15)))
    assert math.isclose(cog.pose.position.x, NOM.r * 2.0 + NOM.l * math.sin(0.3))
    second = {m.id: m for m in got[1].markers}
    assert math.isclose(second[0].pose.position.x, -NOM.r)
    out = node.output()
    assert "rejected message #1 on joint_states" in out and "drew 2 states" in out
