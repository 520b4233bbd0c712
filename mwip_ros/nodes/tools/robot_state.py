"""``robot_state``: odometry, the URDF, wheel joint states and the frame tree, as a ROS mobile base has them.

Subscribes ``joint_states`` (the plant's state, or the state estimator's with raw sensors: theta_w' = phi' +
theta_b', the encoder's rate plus the bias-corrected pitch rate; from a 3D plant also the gyro's yaw rate, its joint
``yaw``: :func:`mwip_ros.core.mobile_base.odometry.state_update`) and publishes (docs/graph.md):

- ``odom`` (nav_msgs/Odometry, frame ``odom``, child ``base_link``): the pose integrated by
  :class:`mwip_ros.core.mobile_base.odometry.Odometry` (both wheels at theta_w' on the planar robot, yaw 0), pitched by
  theta_b, with the covariances of the sensors' noise (``sensors.encoder_counts_per_rev``,
  ``sensors.imu.gyro_noise_std``);
- ``robot_description`` (std_msgs/String, latched: transient local, depth 1):
  :func:`mwip_ros.core.mobile_base.urdf.urdf`;
- ``wheel_joint_states`` (sensor_msgs/JointState: ``wheel_left_joint``, ``wheel_right_joint``, position phi =
  theta_w - theta_b): what robot_state_publisher reads (remap its ``joint_states`` to it: the project's
  ``joint_states`` is the robot's state, another layout);
- ``/tf`` (tf2_msgs/TFMessage): odom -> base_link -> wheel_left_link / wheel_right_link / imu_link, where
  tf2_msgs is importable; without it (the PyPI wheels), one log line says so.

The robot's geometry (``actual.*``, ``sensors.*``) is plant_sim's: read from the plant_sim sections of the same
parameter files unless robot_state's own section gives it, and checked as plant_sim checks it (a body inertia no rigid
body has, wheels that overlap: one line naming the key, exit 2).  The stamps are judged as the observer and the
controller judge theirs (:class:`~mwip_ros.nodes.runtime.guards.StampGuard`, docs/graph.md): a stamp older than the
stream's or more than a window ahead of it is rejected and counted, and the odometry restarts at the origin (logged)
only when the stream itself restarted (agreeing stamps from the topic's one publisher: a plant's ``~/reset``, a new
plant); a state the odometry refuses (not finite) is rejected and counted and nothing is published for it.
"""
from __future__ import annotations

import importlib
import sys

from nav_msgs.msg import Odometry as OdometryMsg
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from mwip_ros import params as P
from mwip_ros.core.mobile_base.odometry import Odometry, odometry_noise, rule_for, state_update
from mwip_ros.core.mobile_base.urdf import (BASE_LINK, KEYS, ODOM_FRAME, WHEEL_JOINTS, frame_transforms, robot_model,
                                             urdf)
from mwip_ros.msgs import BadMessage
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.qos import GRAPH_QOS, RECORD_QOS
from mwip_ros.msgs.stamps import to_time
from mwip_ros.nodes.runtime.guards import NEW, REPEAT, RESTART, STAMP_WINDOW_PERIODS, Rejects, StampGuard, \
    sole_publisher
from mwip_ros.nodes.runtime.params import declare, plant_file_values, start_values
from mwip_ros.nodes.runtime.process import GracefulNodeMixin, run_node

__all__ = ["NAME", "LATCHED_QOS", "RobotState", "plant_values", "main"]

NAME = "robot_state"
WHEEL_JOINT_STATES = "wheel_joint_states"
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
MODEL_KEYS = KEYS + ("sensors.model", "sensors.encoder_counts_per_rev", "sensors.imu.gyro_noise_std")


def plant_values(argv) -> dict:
    """The robot's geometry and sensors (:data:`MODEL_KEYS`) from the plant_sim sections of the command line's
    parameter files, the later file winning."""
    return plant_file_values(argv, MODEL_KEYS)


def _tf_message_type(logger):
    """tf2_msgs/TFMessage, or None (logged once) without tf2_msgs: a full ROS install has it, no PyPI wheel does,
    so it is looked up by name, an optional runtime dependency (package.xml) and not one of the venv's."""
    try:
        TFMessage = importlib.import_module("tf2_msgs.msg").TFMessage
    except ImportError:
        logger.info("tf2_msgs is not installed (the PyPI wheels lack it): no /tf; odom, robot_description and "
                    f"{WHEEL_JOINT_STATES} are published, and the live view shows the frames")
        return None
    return TFMessage


class RobotState(Node, GracefulNodeMixin):
    def __init__(self, context=None, argv=()):
        super().__init__(NAME, context=context)
        self.v = declare(self, NAME, argv)
        own, _ = start_values(self, NAME, argv)
        values = {**self.v, **{k: val for k, val in plant_values(argv).items() if k not in own}}
        P.check_geometry(values, "the robot's geometry (plant_sim's, or robot_state's own)")   # plant_sim's check
        self.model = robot_model(values)
        h = P.period(self.v)
        noise = odometry_noise(self.model.r, self.model.track_width, h, int(values["sensors.encoder_counts_per_rev"]),
                               float(values["sensors.imu.gyro_noise_std"]), encoders=1, yaw_gyro=True)
        rule = rule_for(values["sensors.model"])
        self.odom = Odometry(self.model.r, self.model.track_width, noise, rule=rule)
        self.rejects = Rejects(self.get_logger())
        self.count, self.restarts = 0, 0
        # a stray state (another publisher, a stamp far off) neither restarts nor jumps the odometry
        self.guard = StampGuard(STAMP_WINDOW_PERIODS * round(h * 1e9), "joint_states stamp",
                                sole_publisher(self, "joint_states"))
        self.description = urdf(self.model)
        self.pub_desc = self.create_publisher(String, "robot_description", LATCHED_QOS)
        self.pub_desc.publish(String(data=self.description))
        self.pub_odom = self.create_publisher(OdometryMsg, "odom", GRAPH_QOS)
        self.pub_joints = self.create_publisher(JointState, "wheel_joint_states", GRAPH_QOS)
        self.tf_type = _tf_message_type(self.get_logger())
        self.pub_tf = self.create_publisher(self.tf_type, "/tf", GRAPH_QOS) if self.tf_type else None
        # as the recorder: transient local, so states published before discovery matched this reader (a lockstep
        # run can be over in a second, before the next discovery announcement) still reach it, in order
        self.create_subscription(JointState, "joint_states", self._on_state, RECORD_QOS, raw=True)
        self.get_logger().info(f"robot state ready: r {self.model.r} m, track {self.model.track_width} m, odom "
                               f"speed noise {noise.speed_std:.3g} m/s, {rule} rule; robot_description "
                               f"{len(self.description)} B")

    def _on_state(self, data: bytes) -> None:
        try:
            stamp, x, _u = L.parse_joint_state(data)
            gyro_z = L.parse_yaw_rate(data)   # a 3D plant's gyro (docs/theory.md 6.13), None on the planar robot
        except BadMessage as exc:
            self.rejects("joint_states", str(exc))
            return
        last, publisher = self.guard.last, getattr(self.guard.may_restart, "own", None)
        verdict = self.guard.check(stamp)
        if verdict == RESTART:
            self.restarts += 1
            if last is not None and stamp > last and publisher is not None and \
                    getattr(self.guard.may_restart, "own", None) == publisher:
                # the stream's own publisher went on after a pause (a realtime plant that stalled keeps the clock's
                # schedule: its next stamp is the gap ahead, docs/graph.md "Modes"): the robot is where it was
                self.get_logger().info(f"joint_states went on after a gap of {(stamp - last) * 1e-9:.3f} s (the "
                                       f"plant paused or stalled): the odometry goes on over it")
            else:
                self.get_logger().info("joint_states restarted (a reset, a new plant): the odometry restarts at the "
                                       "origin")
                self.odom.reset()
        elif verdict == REPEAT:
            self.rejects("joint_states", f"stamp {stamp} ns repeats the last one")
            return
        elif verdict != NEW:
            self.rejects("joint_states", verdict)
            return
        if not state_update(self.odom, stamp * 1e-9, float(x[2]), float(x[1]), gyro_z):   # the planar robot: no yaw
            self.rejects("joint_states", f"the odometry refuses the state at t = {stamp * 1e-9:.6f} s (a rate that "
                                         f"is not finite, or a time that does not advance)")
            return
        self._publish(stamp, float(x[0]), float(x[1]))
        self.count += 1

    def _publish(self, stamp: int, theta_w: float, theta_b: float) -> None:
        t, o, phi = to_time(stamp), self.odom, theta_w - theta_b
        frames = frame_transforms(self.model, o.x, o.y, o.yaw, theta_b, phi, phi)
        msg = OdometryMsg()
        msg.header.stamp, msg.header.frame_id, msg.child_frame_id = t, ODOM_FRAME, BASE_LINK
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        (p.x, p.y, p.z), (q.x, q.y, q.z, q.w) = frames[0].translation, frames[0].rotation
        msg.pose.covariance = o.pose_covariance()
        msg.twist.twist.linear.x, msg.twist.twist.angular.z = o.v, o.yaw_rate
        msg.twist.covariance = o.twist_covariance()
        self.pub_odom.publish(msg)
        js = JointState()
        js.header.stamp = t
        js.name, js.position = list(WHEEL_JOINTS), [phi, phi]
        self.pub_joints.publish(js)
        if self.pub_tf is not None:
            self.pub_tf.publish(tf_message(self.tf_type, frames, t))

    def diagnostic_count(self) -> int:
        return self.count

    def on_shutdown(self) -> None:
        self.get_logger().info(f"integrated {self.count} states (x {self.odom.x:.6g} m, restarts {self.restarts}); "
                               f"rejected: {self.rejects.summary()}")


def tf_message(tf_type, frames, stamp):
    """A tf2_msgs/TFMessage (``tf_type``) of :func:`~mwip_ros.core.mobile_base.urdf.frame_transforms`' ``frames``."""
    from geometry_msgs.msg import TransformStamped
    out = []
    for f in frames:
        ts = TransformStamped()
        ts.header.stamp, ts.header.frame_id, ts.child_frame_id = stamp, f.parent, f.child
        tr, ro = ts.transform.translation, ts.transform.rotation
        tr.x, tr.y, tr.z = f.translation
        ro.x, ro.y, ro.z, ro.w = f.rotation
        out.append(ts)
    return tf_type(transforms=out)


def main(argv=None) -> int:
    return run_node(RobotState, argv)


if __name__ == "__main__":
    sys.exit(main())
