"""The topics of the mwip_ros graph and their message types: the one table every module uses.

Names are relative (so ``--ros-args -r __ns:=/robot1`` moves them), except ``/clock``,
which ROS always reads from the root namespace.
"""
from __future__ import annotations

import importlib
import re
from typing import Dict, Optional, Tuple

__all__ = ["GRAPH_TOPICS", "USER_TOPICS", "SYSTEM_TOPICS", "topic_type", "split_type", "msg_class", "leaf",
           "graph_type"]

GRAPH_TOPICS: Dict[str, str] = {
    "joint_states": "sensor_msgs/msg/JointState",
    "true_joint_states": "sensor_msgs/msg/JointState",   # with sensing or actuation options on, or raw sensors
    "true_pose": "geometry_msgs/msg/PoseStamped",        # a spatial plant's (backend mujoco) true 3D pose
    "true_wheel_states": "sensor_msgs/msg/JointState",   # a spatial plant's wheels: each one's absolute angle
    "imu/data_raw": "sensor_msgs/msg/Imu",               # raw sensors (sensors.model: raw): the body's IMU
    "wheel_encoder": "sensor_msgs/msg/JointState",       # raw sensors: the wheel's angle relative to the body
    "wheel_states": "sensor_msgs/msg/JointState",        # wheel_driver: each wheel's angle, rate, torque (the servos)
    "wheel_torque_cmd": "std_msgs/msg/Float64",
    "wheel_torques_cmd": "sensor_msgs/msg/JointState",  # the yaw stage (mujoco, motion): [u_L, u_R] (theory 6.13)
    "cmd_vel": "geometry_msgs/msg/Twist",                # motion: v* (linear.x) and psi'* (angular.z) (theory 6.11)
    "disturbance_estimate": "geometry_msgs/msg/WrenchStamped",
    "lumped_disturbance": "geometry_msgs/msg/WrenchStamped",
    "external_wrench": "geometry_msgs/msg/Wrench",
    "emergency_stop": "std_msgs/msg/Bool",               # plant_sim: true latches the driver's fault (theory.md 6.8)
    "driver_state": "std_msgs/msg/String",               # plant_sim: each driver transition, JSON, latched
    "controller_internals": "sensor_msgs/msg/JointState",
    "/clock": "rosgraph_msgs/msg/Clock",
    "robot_markers": "visualization_msgs/msg/MarkerArray",  # robot_markers: the robot to look at
    "odom": "nav_msgs/msg/Odometry",                     # robot_state: wheel odometry (frame odom, child base_link)
    "robot_description": "std_msgs/msg/String",          # robot_state: the URDF, latched
    "wheel_joint_states": "sensor_msgs/msg/JointState",  # robot_state: the URDF's wheel joints (robot_state_publisher)
}
# published by users (any QoS), not by the graph's nodes with GRAPH_QOS
USER_TOPICS = {"external_wrench", "emergency_stop", "cmd_vel"}
SYSTEM_TOPICS: Dict[str, str] = {    # ROS's own topics, which every node publishes (absolute names)
    "/rosout": "rcl_interfaces/msg/Log",
    "/parameter_events": "rcl_interfaces/msg/ParameterEvent",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
}


_NAME = re.compile(r"^[a-zA-Z][a-zA-Z0-9_]*$")


def split_type(type_string: str) -> Tuple[str, str, str]:
    """'sensor_msgs/msg/JointState' -> ('sensor_msgs', 'msg', 'JointState'); 'pkg/Type' -> (pkg, 'msg', Type).

    Raises ValueError for anything that is not a ROS message type name."""
    parts = str(type_string).split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3 or not all(_NAME.match(p) for p in parts):
        raise ValueError(f"not a ROS message type name: {type_string!r} (expected e.g. 'sensor_msgs/msg/JointState')")
    return parts[0], parts[1], parts[2]


def msg_class(type_string: str):
    """Import and return the Python message class for e.g. ``'sensor_msgs/msg/JointState'``."""
    pkg, ns, name = split_type(type_string)
    try:
        module = importlib.import_module(f"{pkg}.{ns}")
    except ImportError as exc:
        raise ValueError(f"cannot import message type {type_string!r}: {exc}") from None
    try:
        return getattr(module, name)
    except AttributeError:
        raise ValueError(f"cannot import message type {type_string!r}: {pkg}.{ns} has no {name}") from None


def leaf(topic: str) -> str:
    """'/robot1/joint_states' -> 'joint_states': a topic's name without its namespace."""
    return topic.rstrip("/").rsplit("/", 1)[-1]


def graph_type(topic: str) -> Optional[str]:
    """The message type of a graph topic given as 'joint_states', '/joint_states',
    '/robot1/joint_states' or '/clock'; None if it is not one of the graph's topics."""
    if topic in GRAPH_TOPICS:
        return GRAPH_TOPICS[topic]
    stripped = topic.lstrip("/")
    if stripped in GRAPH_TOPICS:
        return GRAPH_TOPICS[stripped]
    if "/" + stripped in GRAPH_TOPICS:
        return GRAPH_TOPICS["/" + stripped]
    last = stripped.rsplit("/", 1)[-1]
    if last in GRAPH_TOPICS:
        return GRAPH_TOPICS[last]
    for name, type_name in GRAPH_TOPICS.items():   # a name of several levels under a namespace: /robot1/imu/data_raw
        if "/" in name.strip("/") and stripped.endswith("/" + name.strip("/")):
            return type_name
    return None


def topic_type(topic: str) -> Optional[str]:
    """The type of a graph topic (:func:`graph_type`) or of a system topic ('/rosout', 'rosout', ...)."""
    return graph_type(topic) or SYSTEM_TOPICS.get("/" + topic.strip("/"))
