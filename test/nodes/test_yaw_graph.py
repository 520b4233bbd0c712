"""The yaw stage in the graph (docs/theory.md 6.13): with the MuJoCo plant and motion on, the controller answers with
the two wheels' torques on wheel_torques_cmd, and the lockstep graph equals mwip_sim to 1e-9, the turn included
(one graph: DSCNDO, LQR, then DSCNDO again with robot_state integrating the gyro's yaw); raw sensors through the
estimator; a realtime Twist turns the robot; the plant refuses bad wheel torques (in this process)."""
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

from graphproc import PARAMS, run_lockstep  # noqa: E402
from loopgraph import LoopGraph, concurrently  # noqa: E402
from mwip_ros import params as P  # noqa: E402
from mwip_ros.core.closed_loop.sim import simulate  # noqa: E402
from mwip_ros.core.closed_loop.trajectory import POSE_COLUMNS  # noqa: E402
from mwip_ros.runs import read_csv  # noqa: E402

MOTION = Path(__file__).resolve().parents[2] / "config" / "motion.yaml"
STATE = ["theta_w", "theta_b", "dtheta_w", "dtheta_b", "u", "tau_d1", "tau_d2"]
TURN = ("plant_sim:\n  ros__parameters:\n    backend: mujoco\n"
        "dscndo_controller:\n  ros__parameters:\n"
        "    motion: {profile: [0.0, 0.0, 0.5, 0.3], yaw_profile: [0.0, 0.0, 0.25, 0.5]}\n")
ODOM_RUN_S = 3.0


def _turning(work):
    """One lockstep graph of [paper.yaml, motion.yaml, the turn on MuJoCo]: robot_state, the observer and the
    controller up; a plant of 2 s with DSCNDO, one with LQR, then one of 3 s with DSCNDO while this test's reader
    (subscribed before the run: nothing to join late) takes robot_state's odom."""
    from nav_msgs.msg import Odometry as OdometryMsg
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    from injector import Injector
    from mwip_ros.core import laws
    work.mkdir(parents=True)
    turn = work / "turn.yaml"
    turn.write_text(TURN)
    files = [PARAMS, MOTION, turn]
    late = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)
    out = {"files": files, "runs": {}}
    with LoopGraph(work, params=files) as loop:
        robot_state = loop.graph.start("robot_state", params=files)
        loop.start()
        for name in ("dscndo", "lqr"):
            cls = laws.get(name)
            loop.set("dscndo_controller", law=cls.family, use_observer=cls.observer)
            out["runs"][name] = loop.run(name, "-p", "duration_s:=2.0")
        loop.set("dscndo_controller", law="dsc", use_observer=True)
        with Injector(loop.domain_id, name="reader") as inj:
            odom = out["odom"] = []
            inj.node.create_subscription(OdometryMsg, "odom", odom.append, late)

            def last_k():
                return int(round((odom[-1].header.stamp.sec + odom[-1].header.stamp.nanosec * 1e-9) / 0.005)) \
                    if odom else -1
            # expected_subscribers 3: the plant starts once robot_state's reader has matched too (observer,
            # controller, robot_state), as a user counts a viewer that must see the whole run
            out["runs"]["odom"] = loop.run("odom", "-p", f"duration_s:={ODOM_RUN_S}", "-p", "expected_subscribers:=3")
            # robot_state may still be working through the run's states: wait for the last one's odom
            out["last_k"] = inj.wait(lambda: last_k() == 600, 60) and last_k()
        out["robot_state"] = (robot_state.stop(), robot_state.output())
    return out


def _raw_turning(work):
    """Raw sensors (config/sensors_raw_realistic.yaml) on the MuJoCo plant, turning from 1 s (graphproc.run_lockstep):
    (the parameter files, the plant's exit code, its csv, the logs)."""
    from test_graph import RAW
    work.mkdir(parents=True)
    turn = work / "turn.yaml"
    turn.write_text("plant_sim:\n  ros__parameters:\n    backend: mujoco\n"
                    "state_estimator:\n  ros__parameters:\n    kalman: {accel_noise_std: 1.0, slip_gate: 150.0}\n"
                    "dscndo_controller:\n  ros__parameters:\n"
                    "    motion: {profile: [0.0, 0.0, 0.5, 0.3], yaw_profile: [0.0, 0.0, 1.0, 0.0, 1.25, 0.5]}\n")
    files = [*RAW, MOTION, turn]
    return (files, *run_lockstep(work, True, "-p", "duration_s:=3.0", params=files, law="dsc"))


@pytest.fixture(scope="module")
def graphs(tmp_path_factory):
    """The turning graph and the raw one at once (each a domain of its own)."""
    work = tmp_path_factory.mktemp("yaw")
    turning, raw = concurrently(lambda: _turning(work / "turning"), lambda: _raw_turning(work / "raw"))
    return {"turning": turning, "raw": raw}


@pytest.fixture(scope="module")
def turning(graphs):
    return graphs["turning"]


@pytest.mark.graph
@pytest.mark.parametrize("controller", ["dscndo", "lqr"])
def test_lockstep_mujoco_graph_with_the_yaw_stage_equals_mwip_sim(turning, controller):
    run = turning["runs"][controller]
    assert run.code == 0, run.output()
    offline = simulate(P.closed_loop(P.merged_values(P.load_param_files(turning["files"])), controller=controller,
                                     duration=2.0))
    graph = read_csv(run.csv)
    assert len(graph) == len(offline) == 401
    assert np.max(np.abs(offline["u_psi"])) > 10.0 and offline["yaw"][-1] > 0.2   # it turned
    for c in STATE + POSE_COLUMNS:
        np.testing.assert_allclose(graph[c], offline[c], rtol=0, atol=1e-9, err_msg=c)


@pytest.mark.graph
def test_robot_state_on_the_3d_plant_integrates_the_gyro_s_yaw(turning):
    """robot_state beside the lockstep mujoco graph turning: its last odom is the offline states integrated as
    core.mobile_base.odometry.state_update does (1e-9), and within the drift of docs/real-robot.md of the true pose
    (5 cm, 2 mrad); without the yaw joint it would have no yaw at all. (The runs before this one: the odometry restarts
    at the origin when the stamps go back.)"""
    from mwip_ros.core.mobile_base.odometry import Odometry, state_update
    run = turning["runs"]["odom"]
    assert run.code == 0, run.output()
    code, rs_out = turning["robot_state"]
    assert turning["last_k"] == 600, (len(turning["odom"]), rs_out[-800:])
    assert code == 0, rs_out
    assert "the odometry restarts at the origin" in rs_out
    last = turning["odom"][-1]
    k = int(round((last.header.stamp.sec + last.header.stamp.nanosec * 1e-9) / 0.005))
    assert k == 600
    run = simulate(P.closed_loop(P.merged_values(P.load_param_files(turning["files"])), controller="dscndo",
                                 duration=ODOM_RUN_S))
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


@pytest.mark.graph
def test_lockstep_graph_with_raw_sensors_and_the_yaw_stage_equals_mwip_sim(graphs):
    """Raw sensors (config/sensors_raw_realistic.yaml) on the MuJoCo plant, turning from 1 s: the plant's IMU carries
    its z gyro (angular_velocity.z, core.plants.raw_sensors.YawGyro), the state estimator passes it on as the yaw joint
    (its files say backend mujoco), the controller answers with the wheels' pair; the graph equals mwip_sim to 1e-9,
    the turn and the yaw gyro's bias and noise included.  The turn in place slips at the 5 ms physics step: the
    filter leaves the slipping samples out (kalman.slip_gate, theory.md 6.4; without it it diverges at 2.04 s)."""
    files, code, csv_path, logs = graphs["raw"]
    assert code == 0, logs["plant_sim"].output() + logs["state_estimator"].output()
    offline = simulate(P.closed_loop(P.merged_values(P.load_param_files(files)), controller="dscndo",
                                     duration=3.0))
    graph = read_csv(csv_path)
    assert not offline.fallen and len(graph) == len(offline) == 601
    assert np.unwrap(offline["yaw"])[-1] - offline["yaw"][0] > 0.4 and np.max(np.abs(offline["u_psi"])) > 100.0
    for c in STATE + POSE_COLUMNS:
        np.testing.assert_allclose(graph[c], offline[c], rtol=0, atol=1e-9, err_msg=c)


@pytest.mark.node
def test_bad_wheel_torques_are_rejected_and_counted():
    """plant_sim (mujoco, realtime) refuses a wheel_torques_cmd with other names, one effort, or a NaN torque, each
    counted (as /diagnostics reports it) and named in its log; the NaN is also the driver's bad_command fault."""
    from mwip_ros.msgs import cdr
    from mwip_ros.msgs import layouts as L
    from nodeharness import NodeHarness, node_class
    with NodeHarness(node_class("plant_sim"), "-p", "mode:=realtime", "-p", "duration_s:=0.0",
                     "-p", "backend:=mujoco", "-p", "watchdog_s:=1000.0") as plant:
        for n, data in enumerate((cdr.JointStateEncoder(("left", "right"))(1, (), (), (1.0, 2.0)),
                                  cdr.JointStateEncoder(L.WHEEL_TORQUE_JOINTS)(1, (), (), (1.0,)),
                                  L.encode_wheel_torques(1, float("nan"), 0.0)), start=1):
            plant.feed("wheel_torques_cmd", data)
            assert plant.node.rejects.counts == {"wheel_torques_cmd": n}
        state = plant.node.safety.state
    out = plant.logs()
    assert "joint names ['left', 'right'], expected ['wheel_left_joint', 'wheel_right_joint']" in out
    assert "effort has 1 entries, expected 2" in out and "bad_command" in out
    assert state == "fault", state


@pytest.mark.alone
@pytest.mark.graph
def test_realtime_cmd_vel_angular_z_turns_the_3d_robot(tmp_path):
    """Realtime on the MuJoCo plant: a Twist with angular.z = 0.5 rad/s for 3 s, published by this test's process,
    turns the robot (true_pose's yaw past 0.8 rad), it stays up, and the controller answers on wheel_torques_cmd."""
    import time

    from geometry_msgs.msg import PoseStamped, Twist
    from sensor_msgs.msg import JointState

    from graphproc import Graph
    from injector import Injector
    from mwip_ros.msgs import layouts as L
    cfg = tmp_path / "drive.yaml"
    cfg.write_text("dscndo_controller:\n  ros__parameters:\n    motion: {enabled: true, cmd_vel_timeout_s: 0.5}\n")
    with Graph(tmp_path) as g:
        with Injector(g.domain_id) as inj:
            yaws, pairs = [], []
            inj.node.create_subscription(
                PoseStamped, "true_pose",
                lambda m: yaws.append(2 * math.atan2(m.pose.orientation.z, m.pose.orientation.w)), 10)
            inj.node.create_subscription(JointState, "wheel_torques_cmd", lambda m: pairs.append(tuple(m.effort)), 10)
            g.start("disturbance_observer", "-p", "mode:=realtime", params=[PARAMS, cfg])
            g.start("dscndo_controller", "-p", "mode:=realtime", params=[PARAMS, cfg])
            plant = g.start("plant_sim", "-p", "mode:=realtime", "-p", "duration_s:=0.0", "-p", "backend:=mujoco",
                            params=[PARAMS, cfg])
            pub = inj.publisher("cmd_vel", Twist)
            # the loop runs (its states for 2 s) and the controller's cmd_vel subscription is there
            assert inj.wait(lambda: pub.get_subscription_count() >= 1 and len(yaws) > 400, 30), plant.output()
            end = time.monotonic() + 3.0
            while time.monotonic() < end:
                pub.publish(L.encode_twist(0.0, 0.5))
                inj.spin(0.05)
            inj.spin(0.5)
            turned = float(np.unwrap(yaws)[-1] - np.unwrap(yaws)[0])
        assert plant.poll() is None, plant.output()   # still running: it did not fall
    assert turned > 0.8, turned
    assert len(pairs) > 100 and any(abs(a - b) > 1.0 for a, b in pairs)
