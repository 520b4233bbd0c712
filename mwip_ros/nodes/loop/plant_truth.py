"""``plant_sim``'s truth: what happened, published beside what the loop reads (docs/graph.md).

* ``lumped_disturbance`` (geometry_msgs/WrenchStamped): the true tau_d at t_k, every period;
* ``true_joint_states`` (sensor_msgs/JointState): the true state when what the loop reads is a measurement
  (sensing or actuation options on, or raw sensors);
* a spatial plant's (``backend: mujoco``, docs/theory.md 6.10) ``true_pose`` (geometry_msgs/PoseStamped, frame
  ``odom``) and ``true_wheel_states`` (sensor_msgs/JointState ``[wheel_left_joint, wheel_right_joint]``, the URDF's
  joints: each wheel's absolute angle and rate), both stamped t_k: the bag then carries the csv's pose columns.

None of them is an input of the loop: a recorder and a report read them.
"""
from __future__ import annotations

from geometry_msgs.msg import PoseStamped, WrenchStamped
from sensor_msgs.msg import JointState

from mwip_ros.msgs import layouts as L

__all__ = ["TruthPublishers"]


class TruthPublishers:
    """The plant node's truth topics; ``measured``: whether the loop reads a measurement (so the truth state goes on
    ``true_joint_states``), ``spatial``: a plant with a 3D pose (``Plant.spatial``)."""

    def __init__(self, node, qos, measured: bool, spatial: bool):
        self.state = node.create_publisher(JointState, "true_joint_states", qos) if measured else None
        self.disturbance = node.create_publisher(WrenchStamped, "lumped_disturbance", qos)
        self.pose = node.create_publisher(PoseStamped, "true_pose", qos) if spatial else None
        self.wheels = node.create_publisher(JointState, "true_wheel_states", qos) if spatial else None
        self._pending = []

    @property
    def publishers(self) -> tuple:
        """Every truth publisher the node has (the lockstep driver's ``also_published``, the final acks)."""
        return tuple(p for p in (self.disturbance, self.state, self.pose, self.wheels) if p is not None)

    def sample(self, stamp: int, plant) -> None:
        """State k's truth, taken before its measurement: the true state (when measured), the pose and the wheels;
        serialized now, published by :meth:`flush` once the loop's own messages of state k are out (the truth is
        not on the lockstep chain: the other nodes start on state k while these go out)."""
        out = self._pending = []
        if self.state is not None:
            out.append((self.state, L.encode_state(stamp, plant.x, plant.u_prev)))
        if self.pose is not None:
            pose = plant.pose
            out.append((self.pose, L.encode_pose(stamp, pose)))
            out.append((self.wheels, L.encode_wheel_states(stamp, (pose.wheel_left, pose.wheel_right),
                                                           getattr(plant, "wheel_rates", ()))))

    def flush(self) -> None:
        """Publish what :meth:`sample` took (once: a resent state does not send its truth again)."""
        for pub, data in self._pending:
            pub.publish(data)
        self._pending = []

    def lumped_disturbance(self, stamp: int, tau_d) -> None:
        self.disturbance.publish(L.encode_wrench(stamp, tau_d[0], tau_d[1]))
