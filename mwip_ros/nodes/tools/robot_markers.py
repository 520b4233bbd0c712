"""``robot_markers``: the robot as a ``visualization_msgs/MarkerArray``, for Foxglove or RViz.

Subscribes ``joint_states`` (remap it to ``true_joint_states`` to draw the truth when the
plant measures with noise); publishes ``robot_markers`` in frame ``world``: the wheel (a
cylinder, its rolling shown by a spoke), the body (a rod from the axle, tilted by theta_b,
with a sphere at its centre of gravity) and a ground line, sized from the nominal model
(``core.plants.markers``).  The recorder records them, so a bag opened in Foxglove or RViz shows
the robot too.  A state it cannot use is rejected and counted, as everywhere.
"""
from __future__ import annotations

import sys

from geometry_msgs.msg import Point
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from mwip_ros import params as P
from mwip_ros.core.plants.markers import pitch_quaternion, robot_pose
from mwip_ros.msgs import BadMessage
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.qos import GRAPH_QOS, INPUT_QOS
from mwip_ros.msgs.stamps import to_time
from mwip_ros.nodes.runtime.guards import Rejects
from mwip_ros.nodes.runtime.params import declare
from mwip_ros.nodes.runtime.process import GracefulNodeMixin, run_node

NAME = "robot_markers"
FRAME = "world"
WHEEL, SPOKE, BODY, COG, GROUND = range(5)   # marker ids
GROUND_HALF_LENGTH = 50.0                    # [m] either side of the wheel


def _color(r, g, b, a=1.0) -> ColorRGBA:
    return ColorRGBA(r=float(r), g=float(g), b=float(b), a=float(a))


class RobotMarkers(Node, GracefulNodeMixin):
    def __init__(self, context=None, argv=()):
        super().__init__(NAME, context=context)
        self.v = declare(self, NAME, argv)
        self.nominal = P.physical(self.v, "nominal")
        self.rejects = Rejects(self.get_logger())
        self.count = 0
        self.pub = self.create_publisher(MarkerArray, "robot_markers", GRAPH_QOS)
        self.create_subscription(JointState, "joint_states", self._on_state, INPUT_QOS, raw=True)
        self.get_logger().info(f"robot markers ready: wheel radius {self.nominal.r} m, body 2 l = "
                               f"{2 * self.nominal.l} m, frame {FRAME}")

    def _on_state(self, data: bytes) -> None:
        try:
            stamp, x, _u = L.parse_joint_state(data)
        except BadMessage as exc:
            self.rejects("joint_states", str(exc))
            return
        self.pub.publish(markers(self.nominal, x, stamp))
        self.count += 1

    def diagnostic_count(self) -> int:
        return self.count

    def on_shutdown(self) -> None:
        self.get_logger().info(f"drew {self.count} states; rejected: {self.rejects.summary()}")


def markers(nominal, x, stamp: int) -> MarkerArray:
    """The MarkerArray of state ``x`` at ``stamp`` [ns]."""
    pose = robot_pose(nominal, x)
    t = to_time(stamp)
    out = []

    def marker(mid, kind, position=(0.0, 0.0, 0.0), angle=0.0, scale=(1.0, 1.0, 1.0), color=_color(1, 1, 1)):   # noqa: B008 - read-only
        m = Marker()
        m.header.frame_id, m.header.stamp = FRAME, t
        m.ns, m.id, m.type, m.action = "mwip", mid, kind, Marker.ADD
        m.pose.position.x, m.pose.position.y, m.pose.position.z = position
        qx, qy, qz, qw = pitch_quaternion(angle)
        m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w = qx, qy, qz, qw
        m.scale.x, m.scale.y, m.scale.z = scale
        m.color = color
        out.append(m)
        return m

    r, length = pose.wheel_radius, pose.body_length
    wheel = marker(WHEEL, Marker.CYLINDER, pose.wheel_center, 0.0, (2 * r, 2 * r, 0.12), _color(0.2, 0.2, 0.2))
    wheel.pose.orientation.x, wheel.pose.orientation.w = 0.7071067811865476, 0.7071067811865476  # axis along y
    spoke = marker(SPOKE, Marker.LINE_LIST, scale=(0.03, 0.0, 0.0), color=_color(1.0, 0.6, 0.0))
    spoke.points = [Point(x=pose.wheel_center[0], y=-0.07, z=pose.wheel_center[2]),
                    Point(x=pose.spoke_end[0], y=-0.07, z=pose.spoke_end[2])]
    mid = tuple((a + b) / 2 for a, b in zip(pose.wheel_center, pose.body_top))
    marker(BODY, Marker.CUBE, mid, pose.theta_b, (0.12, 0.3, length), _color(0.1, 0.4, 0.8, 0.9))
    marker(COG, Marker.SPHERE, pose.body_center, 0.0, (0.1, 0.1, 0.1), _color(0.9, 0.1, 0.1))
    ground = marker(GROUND, Marker.LINE_STRIP, scale=(0.02, 0.0, 0.0), color=_color(0.5, 0.5, 0.5))
    ground.points = [Point(x=pose.wheel_center[0] - GROUND_HALF_LENGTH),
                     Point(x=pose.wheel_center[0] + GROUND_HALF_LENGTH)]
    return MarkerArray(markers=out)


def main(argv=None) -> int:
    return run_node(RobotMarkers, argv)


if __name__ == "__main__":
    sys.exit(main())
