"""robot_state against stray states (issue 46 item 4), in this process (test/nodeharness.py): the rule docs/graph.md
states for the other nodes holds for it too: a restart needs agreeing stamps from the stream's own publisher, and a
far-future stamp is never integrated.  Before, one message stamped 1 s old restarted the odometry at the origin (2 m
lost) and one stamped 1000 s ahead made odom x 127,502.6 m.  Also (items 8, 10): the robot's geometry is checked as
plant_sim checks it, and a state the odometry refuses publishes nothing."""
import pytest
from nav_msgs.msg import Odometry as OdometryMsg

from mwip_ros.core.plants.model import State
from mwip_ros.msgs import layouts as L
from nodeharness import NodeHarness, node_class, refused

pytestmark = pytest.mark.node

H_NS = 5_000_000
R = 0.254   # config/paper.yaml's actual.r


def _state(k: int, rate: float = 4.0) -> bytes:
    return L.encode_state(k * H_NS, State(0.0, 0.0, rate, 0.0), 0.0)


def _x(h) -> float:
    return h.messages("odom", OdometryMsg)[-1].pose.pose.position.x


def _stream(h, ks, feeder="feeder"):
    for k in ks:
        h.feed("joint_states", _state(k), feeder=feeder)


def test_one_stray_state_neither_restarts_nor_jumps_the_odometry():
    with NodeHarness(node_class("robot_state")) as h:
        _stream(h, range(0, 401))   # 2 s at 4 rad/s: 2.03 m
        x = _x(h)
        assert x == pytest.approx(R * 4.0 * 2.0, rel=1e-9)
        n = len(h.sent("odom"))
        h.feed("joint_states", _state(400 - 200))            # 1 s old
        h.feed("joint_states", _state(400 + 200_000))        # 1000 s ahead
        assert len(h.sent("odom")) == n and h.node.restarts == 0
        assert h.node.rejects.counts["joint_states"] == 2
        _stream(h, range(401, 601))                           # the stream goes on where it was
        assert _x(h) == pytest.approx(R * 4.0 * 3.0, rel=1e-9)
        assert max(m.pose.pose.position.x for m in h.messages("odom", OdometryMsg)) < R * 4.0 * 3.0 + 1e-9


def test_a_second_publishers_agreeing_stamps_restart_nothing_and_the_streams_own_reset_does():
    with NodeHarness(node_class("robot_state")) as h:
        _stream(h, range(0, 201))
        x = _x(h)
        _stream(h, range(0, 10), feeder="intruder")   # another publisher's run of agreeing old stamps
        assert h.node.restarts == 0 and _x(h) == x
    with NodeHarness(node_class("robot_state")) as h:
        _stream(h, range(0, 201))
        _stream(h, range(0, 5))   # the stream's own publisher back at its first stamp: a ~/reset
        assert h.node.restarts == 1
        assert "restarts at the origin" in h.logs()
        # restarted at the third agreeing stamp (k = 2), integrated over k = 3, 4
        assert _x(h) == pytest.approx(R * 4.0 * 2 * H_NS * 1e-9, rel=1e-9)


@pytest.mark.parametrize("key, value", [("actual.track_width", 0.01), ("actual.I_b_roll", 500.0)])
def test_a_geometry_plant_sim_refuses_is_refused_at_start_up(key, value):
    """Wheels that overlap, a body inertia no rigid body has: plant_sim (backend mujoco) refuses them, and so does
    robot_state now instead of publishing that URDF."""
    line = refused(node_class("robot_state"), "-p", f"{key}:={value}")
    assert f"'{key}'" in line and "\n" not in line, line


def test_a_state_the_odometry_refuses_publishes_nothing(monkeypatch):
    import mwip_ros.nodes.tools.robot_state as rs
    with NodeHarness(node_class("robot_state")) as h:
        _stream(h, range(0, 3))
        n = len(h.sent("odom"))
        monkeypatch.setattr(rs, "state_update", lambda *a, **k: False)
        h.feed("joint_states", _state(3))
        assert len(h.sent("odom")) == n and len(h.sent("wheel_joint_states")) == n
        assert "odometry refuses" in h.logs()


def test_a_stall_of_the_plant_pauses_the_stream_and_the_odometry_goes_on():
    """The realtime plant keeps the clock's schedule (issue 47 item 2): after a stall of its process (335 ms, seen on
    the drive graph when a mwip_ctl joined) its next state is stamped 72 periods on, wider than the stamp window.
    That is the stream's own publisher going on after a pause, not a new run: the robot is where it was, so odom
    goes on (integrating over the gap) instead of restarting at the origin (1.3 m lost on the drive graph)."""
    import time
    with NodeHarness(node_class("robot_state")) as h:
        _stream(h, range(0, 201))   # 1 s at 4 rad/s
        time.sleep(0.15)            # the plant's process stalled: nothing for longer than the stamp window
        deadline = time.monotonic() + 3.0
        k = 273
        while h.node.restarts == 0 and time.monotonic() < deadline:   # its late states, a period apart
            _stream(h, [k])
            k += 1
            time.sleep(0.005)
        assert h.node.restarts == 1, h.logs()[-2000:]
        _stream(h, range(k, 401))
        assert "restarts at the origin" not in h.logs()
        # v = r theta_w' = 4 R all along, the gap too: odom is the whole 2 s of it
        assert _x(h) == pytest.approx(R * 4.0 * 400 * H_NS * 1e-9, rel=1e-9)
