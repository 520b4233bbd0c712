"""The yaw stage in the graph (docs/theory.md 6.13): with the MuJoCo plant and motion on, the controller answers with
the two wheels' torques on wheel_torques_cmd, and the lockstep graph equals mwip_sim to 1e-9, the turn included."""
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

from graphproc import PARAMS, run_lockstep  # noqa: E402
from mwip_ros import params as P  # noqa: E402
from mwip_ros.core.sim import simulate  # noqa: E402
from mwip_ros.core.trajectory import POSE_COLUMNS  # noqa: E402
from mwip_ros.runs import read_csv  # noqa: E402

pytestmark = pytest.mark.graph

MOTION = Path(__file__).resolve().parents[2] / "config" / "motion.yaml"
STATE = ["theta_w", "theta_b", "dtheta_w", "dtheta_b", "u", "tau_d1", "tau_d2"]


@pytest.mark.parametrize("controller", ["dscndo", "lqr"])
def test_lockstep_mujoco_graph_with_the_yaw_stage_equals_mwip_sim(tmp_path, controller):
    from mwip_ros.core import laws
    turn = tmp_path / "turn.yaml"
    turn.write_text("plant_sim:\n  ros__parameters:\n    backend: mujoco\n"
                    "dscndo_controller:\n  ros__parameters:\n"
                    "    motion: {profile: [0.0, 0.0, 0.5, 0.3], yaw_profile: [0.0, 0.0, 0.25, 0.5]}\n")
    files = [PARAMS, MOTION, turn]
    cls = laws.get(controller)
    code, csv_path, logs = run_lockstep(tmp_path, cls.observer, "-p", "duration_s:=2.0", params=files,
                                        law=cls.family)
    assert code == 0, logs["plant_sim"].output()
    offline = simulate(P.closed_loop(P.merged_values(P.load_param_files(files)), controller=controller,
                                     duration=2.0))
    graph = read_csv(csv_path)
    assert len(graph) == len(offline) == 401
    assert np.max(np.abs(offline["u_psi"])) > 10.0 and offline["yaw"][-1] > 0.2   # it turned
    for c in STATE + POSE_COLUMNS:
        np.testing.assert_allclose(graph[c], offline[c], rtol=0, atol=1e-9, err_msg=c)


def test_lockstep_graph_with_raw_sensors_and_the_yaw_stage_equals_mwip_sim(tmp_path):
    """Raw sensors (config/sensors_raw_realistic.yaml) on the MuJoCo plant, turning from 1 s: the plant's IMU carries
    its z gyro (angular_velocity.z, core.raw_sensors.YawGyro), the state estimator passes it on as the yaw joint
    (its files say backend mujoco), the controller answers with the wheels' pair; the graph equals mwip_sim to 1e-9,
    the turn and the yaw gyro's bias and noise included.  The turn in place slips at the 5 ms physics step: the
    filter leaves the slipping samples out (kalman.slip_gate, theory.md 6.4; without it it diverges at 2.04 s)."""
    from test_graph import RAW
    turn = tmp_path / "turn.yaml"
    turn.write_text("plant_sim:\n  ros__parameters:\n    backend: mujoco\n"
                    "state_estimator:\n  ros__parameters:\n    kalman: {accel_noise_std: 1.0, slip_gate: 150.0}\n"
                    "dscndo_controller:\n  ros__parameters:\n"
                    "    motion: {profile: [0.0, 0.0, 0.5, 0.3], yaw_profile: [0.0, 0.0, 1.0, 0.0, 1.25, 0.5]}\n")
    files = [*RAW, MOTION, turn]
    code, csv_path, logs = run_lockstep(tmp_path, True, "-p", "duration_s:=3.0", params=files, law="dsc")
    assert code == 0, logs["plant_sim"].output() + logs["state_estimator"].output()
    offline = simulate(P.closed_loop(P.merged_values(P.load_param_files(files)), controller="dscndo",
                                     duration=3.0))
    graph = read_csv(csv_path)
    assert not offline.fallen and len(graph) == len(offline) == 601
    assert np.unwrap(offline["yaw"])[-1] - offline["yaw"][0] > 0.4 and np.max(np.abs(offline["u_psi"])) > 100.0
    for c in STATE + POSE_COLUMNS:
        np.testing.assert_allclose(graph[c], offline[c], rtol=0, atol=1e-9, err_msg=c)


def test_robot_state_on_the_3d_plant_integrates_the_gyro_s_yaw(tmp_path):
    """robot_state beside the lockstep mujoco graph turning: its last odom is the offline states integrated as
    core.odometry.state_update does (1e-9), and within the drift of docs/real-robot.md of the true pose (5 cm,
    2 mrad); without the yaw joint it would have no yaw at all."""
    import math

    from nav_msgs.msg import Odometry as OdometryMsg
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    from graphproc import Graph
    from injector import Injector
    from mwip_ros.core.odometry import Odometry, state_update
    turn = tmp_path / "turn.yaml"
    turn.write_text("plant_sim:\n  ros__parameters:\n    backend: mujoco\n"
                    "dscndo_controller:\n  ros__parameters:\n"
                    "    motion: {profile: [0.0, 0.0, 0.5, 0.3], yaw_profile: [0.0, 0.0, 0.25, 0.5]}\n")
    files = [PARAMS, MOTION, turn]
    late = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)
    with Graph(tmp_path) as g:
        node = g.start("robot_state", params=files)
        assert node.wait_for_output("robot state ready", 30), node.output()
        with Injector(g.domain_id, name="reader") as inj:   # subscribed before the run: nothing to join late
            odom = []
            inj.node.create_subscription(OdometryMsg, "odom", odom.append, late)

            def last_k():
                return int(round((odom[-1].header.stamp.sec + odom[-1].header.stamp.nanosec * 1e-9) / 0.005)) \
                    if odom else -1
            # expected_subscribers 3: the plant starts once robot_state's reader has matched too (observer, controller,
            # robot_state); else, under load, the run can end before robot_state's participant is discovered
            code, _csv, logs = run_lockstep(tmp_path, True, "-p", "duration_s:=3.0", "-p", "expected_subscribers:=3",
                                            params=files, law="dsc", domain_id=g.domain_id)
            assert code == 0, logs["plant_sim"].output()
            # robot_state may still be working through the run's states: wait for the last one's odom
            assert inj.wait(lambda: last_k() == 600, 60), (len(odom), last_k(), node.stop(), node.output()[-800:])
        assert node.stop() == 0
    last = odom[-1]
    k = int(round((last.header.stamp.sec + last.header.stamp.nanosec * 1e-9) / 0.005))
    assert k == 600
    run = simulate(P.closed_loop(P.merged_values(P.load_param_files(files)), controller="dscndo", duration=3.0))
    o = Odometry(0.254, 0.5, rule="trapezoid")   # robot_state's rule for a state that is not raw sensors
    for j in range(k + 1):
        state_update(o, run["t"][j], run["dtheta_w"][j], run["theta_b"][j], run["gyro_z"][j])
    q = last.pose.pose.orientation
    yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
    p = last.pose.pose.position
    assert abs(p.x - o.x) < 1e-9 and abs(p.y - o.y) < 1e-9 and abs(yaw - o.yaw) < 1e-9
    true_yaw = float(np.unwrap(run["yaw"])[k] - run["yaw"][0])
    assert true_yaw > 0.3 and abs(yaw - true_yaw) < 2e-3   # 1.3 mrad of 1.21 rad: each rate held over its interval
    assert math.hypot(p.x - (run["x"][k] - run["x"][0]), p.y - (run["y"][k] - run["y"][0])) < 0.05


def test_bad_wheel_torques_are_rejected_and_counted(tmp_path):
    """plant_sim (mujoco, realtime) refuses a wheel_torques_cmd with other names, one effort, or a NaN torque, each
    counted on /diagnostics and named in its log; the NaN is also the driver's bad_command fault."""
    from sensor_msgs.msg import JointState

    from graphproc import Graph
    from injector import Injector, health, publish_until_rejected
    from mwip_ros.msgs import cdr
    from mwip_ros.msgs import layouts as L
    with Graph(tmp_path) as g:
        with Injector(g.domain_id) as inj:
            latest = health(inj)
            plant = g.start("plant_sim", "-p", "mode:=realtime", "-p", "duration_s:=0.0", "-p", "backend:=mujoco",
                            "-p", "watchdog_s:=1000.0")
            pub = inj.publisher("wheel_torques_cmd", JointState)
            assert inj.wait(lambda: pub.get_subscription_count() >= 1, 30), plant.output()
            for data in (cdr.JointStateEncoder(("left", "right"))(1, (), (), (1.0, 2.0)),
                         cdr.JointStateEncoder(L.WHEEL_TORQUE_JOINTS)(1, (), (), (1.0,)),
                         L.encode_wheel_torques(1, float("nan"), 0.0)):
                assert publish_until_rejected(inj, latest, "/plant_sim", "wheel_torques_cmd", pub, data), latest
        assert plant.stop() in (0, 130, 143), plant.output()
    out = plant.output()
    assert "joint names ['left', 'right'], expected ['wheel_left_joint', 'wheel_right_joint']" in out
    assert "effort has 1 entries, expected 2" in out and "bad_command" in out


def test_realtime_cmd_vel_angular_z_turns_the_3d_robot(tmp_path):
    """Realtime on the MuJoCo plant: a Twist with angular.z = 0.5 rad/s for 3 s turns the robot (true_pose's yaw past
    0.8 rad), it stays up, and the controller answers on wheel_torques_cmd."""
    import math
    import time

    from geometry_msgs.msg import PoseStamped, Twist
    from sensor_msgs.msg import JointState

    from graphproc import Graph
    from injector import Injector, health, wait_matched
    from mwip_ros.msgs import layouts as L
    cfg = tmp_path / "drive.yaml"
    cfg.write_text("dscndo_controller:\n  ros__parameters:\n    motion: {enabled: true, cmd_vel_timeout_s: 0.5}\n")
    with Graph(tmp_path) as g:
        with Injector(g.domain_id) as inj:
            yaws, pairs = [], []
            latest = health(inj)
            inj.node.create_subscription(
                PoseStamped, "true_pose",
                lambda m: yaws.append(2 * math.atan2(m.pose.orientation.z, m.pose.orientation.w)), 10)
            inj.node.create_subscription(JointState, "wheel_torques_cmd", lambda m: pairs.append(tuple(m.effort)), 10)
            g.start("disturbance_observer", "-p", "mode:=realtime", params=[PARAMS, cfg])
            g.start("dscndo_controller", "-p", "mode:=realtime", params=[PARAMS, cfg])
            plant = g.start("plant_sim", "-p", "mode:=realtime", "-p", "duration_s:=0.0", "-p", "backend:=mujoco",
                            params=[PARAMS, cfg])
            pub = inj.publisher("cmd_vel", Twist)
            assert inj.wait(lambda: pub.get_subscription_count() >= 1 and len(yaws) > 400, 30), plant.output()
            # the 3 s of turning begin once the controller's reader has matched (what comes before it is lost)
            assert wait_matched(inj, latest, "/dscndo_controller", {"/cmd_vel": 1}), latest.get("/dscndo_controller")
            end = time.monotonic() + 3.0
            while time.monotonic() < end:
                pub.publish(L.encode_twist(0.0, 0.5))
                inj.spin(0.05)
            inj.spin(0.5)
            turned = float(np.unwrap(yaws)[-1] - np.unwrap(yaws)[0])
        assert plant.poll() is None, plant.output()   # still running: it did not fall
    assert turned > 0.8, turned
    assert len(pairs) > 100 and any(abs(a - b) > 1.0 for a, b in pairs)
