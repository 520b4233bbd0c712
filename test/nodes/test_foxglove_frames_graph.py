"""foxglove_server with robot_state on a graph: a Foxglove client gets the URDF and the frames (foxglove_frames)."""
from __future__ import annotations

import math
import struct

import pytest
from sensor_msgs.msg import JointState


@pytest.mark.graph
def test_the_server_sends_the_frames_and_the_urdf_to_a_client(tmp_path):
    """robot_state and foxglove_server on a graph, states injected: a Foxglove client gets /robot_description
    (the URDF, forwarded as the ROS message) and /tf as foxglove.FrameTransforms with odom -> base_link at the
    integrated pose and the wheels turned by phi."""
    from websockets.sync.client import connect

    from graphproc import Graph
    from injector import Injector
    from mwip_ros.core.plants.model import State
    from mwip_ros.msgs import layouts as L
    from test_foxglove_server import SUBPROTOCOL, FoxgloveClient, free_port

    port = free_port()
    with Graph(tmp_path) as g, Injector(g.domain_id) as inj:
        fox = g.start("foxglove_server", "-p", f"port:={port}")
        rs = g.start("robot_state")
        assert fox.wait_for_output(f"on ws://127.0.0.1:{port}", 60), fox.output()
        assert rs.wait_for_output("robot state ready", 60), rs.output()
        js = inj.publisher("joint_states", JointState)
        assert inj.wait(lambda: js.get_subscription_count() >= 1, 30)
        with connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL], open_timeout=30) as ws:
            client = FoxgloveClient(ws, topics=("/tf", "/robot_description"))
            k = [0]

            def frames_arrived() -> bool:   # a state every 50 ms, 4 rad/s, theta_b 0.1: until both have come
                if client.got("/tf") and client.got("/robot_description"):
                    return True
                k[0] += 1
                js.publish(L.encode_state(k[0] * 5_000_000, State(0.02 * k[0], 0.1, 4.0, 0.0), 0.0))
                inj.spin(0.05)
                return False
            assert inj.wait(frames_arrived, 60), (sorted(client.topics()), fox.output(), rs.output())
            ch = {c["topic"]: c for c in client.channels.values()}
            assert ch["/tf"]["schemaName"] == "foxglove.FrameTransforms" and ch["/tf"]["encoding"] == "protobuf"
            client.close()
        assert not client.errors, client.errors
        assert fox.stop() == 0, fox.output()
    urdf_cdr = client.got("/robot_description")[0]
    from mwip_ros.nodes.tools.foxglove_frames import FrameView
    v = FrameView()
    v.feed("robot_description", urdf_cdr)
    assert {j.name for j in v.joints} == {"wheel_left_joint", "wheel_right_joint", "imu_joint"}
    tf = b"".join(client.got("/tf"))
    assert b"base_link" in tf and b"odom" in tf
    assert struct.pack("<d", 0.254) in tf                      # base_link r above the ground
    assert struct.pack("<d", math.sin(0.05)) in tf             # pitched by theta_b = 0.1 about y
