"""scripts/bench_driver.py's reading of a run (no run here: the folders run_experiment.sh --robot leaves, written by
the test): each law judged on its own driver's exit, not the invocation's (which is 3 when any law fell); a robot
without a truth judged on its estimate and saying so; a realtime device's bag, which starts at its first estimate,
still covering its window; a goal without its number is unmeasured, never met."""
from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import pytest

from bagcheck import ENDPOINT_QOS
from graphproc import REPO

pytestmark = pytest.mark.unit

H_NS = 5_000_000


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_driver", REPO / "scripts" / "bench_driver.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _log(text: str) -> bytes:
    from rcl_interfaces.msg import Log
    from rclpy.serialization import serialize_message
    return serialize_message(Log(name="wheel_driver", msg=text))


def _run(out: Path, law: str, seconds: float, *, truth: bool, fell_at=None, exit_code=0, first_k: int = 0,
         fault=None, periods=None, read_to_publish_p99=0.3, trips=None) -> None:
    """What run_experiment.sh --robot leaves of one law: the bag (imu/data_raw, wheel_encoder, joint_states; with
    ``truth`` true_joint_states and true_pose too; from period ``first_k``, to the fall or the end), the driver's
    summary, the emulator's last line (``trips``)."""
    from mwip_ros.bag import BagWriter, qos_profiles_yaml
    from mwip_ros.core.plants.plant import Pose
    from mwip_ros.msgs import layouts as L

    n = int(round(seconds / (H_NS * 1e-9)))
    last = n if fell_at is None else int(round(fell_at / (H_NS * 1e-9)))
    topics = {"/imu/data_raw": "sensor_msgs/msg/Imu", "/wheel_encoder": "sensor_msgs/msg/JointState",
              "/joint_states": "sensor_msgs/msg/JointState", "/rosout": "rcl_interfaces/msg/Log"}
    if truth:
        topics.update({"/true_joint_states": "sensor_msgs/msg/JointState",
                       "/true_pose": "geometry_msgs/msg/PoseStamped"})
    out.mkdir(parents=True, exist_ok=True)
    with BagWriter(out / f"run_{law}") as bag:
        for topic, type_name in topics.items():
            bag.add_topic(topic, type_name, qos_profiles_yaml([ENDPOINT_QOS]), "")
        for k in range(first_k, last + 1):
            stamp = 1_000_000_000 + k * H_NS
            theta = 0.004 * math.sin(0.3 * k) if fell_at is None or k < last else 1.2
            bag.write("/imu/data_raw", L.encode_imu(stamp, 0.0, 0.0, 9.81), stamp)
            bag.write("/wheel_encoder", L.encode_encoder(stamp, 0.0, 0.0, 0.1), stamp)
            if truth:
                bag.write("/true_joint_states", L.encode_state(stamp, (0.0, theta, 0.0, 0.0), 0.1), stamp)
                pose = Pose(0.002 * k * 5e-3, 0.0, 0.25, 0.0, theta, 0.0, 0.0, 0.0)   # 0.02 m in 10 s
                bag.write("/true_pose", L.encode_pose(stamp, pose), stamp)
            bag.write("/joint_states", L.encode_state(stamp, (0.0, theta + 1e-4, 0.0, 0.0), 0.1), stamp + 1000)
        if fell_at is not None:
            end = 1_000_000_000 + last * H_NS
            bag.write("/rosout", _log(f"FALLEN at t = {fell_at:.3f} s: |theta_b| = 1.2000 > fall_angle 1.0"), end)
    logs = out / "run_logs"
    logs.mkdir(exist_ok=True)
    timing = {"periods": n if periods is None else periods, "missed": 0, "read_to_publish_ms_p99": read_to_publish_p99}
    (logs / f"{law}_driver.json").write_text(json.dumps({
        "exit_code": exit_code, "fell_at": fell_at, "driver_state": "fault" if fault else "enabled",
        "fault_reason": fault, "fault_detail": fault and "moteus right wheel (CAN id 2): no answer for 53 ms",
        "timing": timing, "schedule": {"periods_due": n}}))
    if trips is not None:
        (logs / f"{law}_moteus_emulator.log").write_text(
            f"fdcanusb: /tmp/x\nmwip_moteus_emulator: 100 frames, watchdog trips {trips[0]} left {trips[1]} right\n")


def test_each_law_is_judged_on_its_own_drivers_exit_not_the_invocations(bench, tmp_path):
    # one run_experiment.sh, three laws, realtime: mpc_ndo fell, so the invocation exits 3; the others ran to their
    # end with exit 0 (this read "ended at t = 10.000 s: None (exit 3)" for every law)
    for law in ("dscndo", "lqr_ndo"):
        _run(tmp_path, law, 10.0, truth=True)
    _run(tmp_path, "mpc_ndo", 10.0, truth=True, fell_at=2.0, exit_code=3)
    for law in ("dscndo", "lqr_ndo"):
        g = bench.goals(tmp_path, law, 10.0, 3)
        assert g["exit"] == 0 and g["complete"] and bench._verdict(g) == "yes"
        assert g["judged_on"] == "truth" and 0.0 < g["theta_b_rms"] < 0.004
        assert bench.upkie_goals(g) == "meets"
    fell = bench.goals(tmp_path, "mpc_ndo", 10.0, 3)
    assert fell["exit"] == 3 and not fell["complete"] and bench._verdict(fell).startswith("FELL (FALLEN at t = 2.000 s")
    assert bench.upkie_goals(fell).startswith("MISSES") and math.isnan(fell["theta_b_rms"])
    # a table cell: the plant's "|theta_b|" would split the row
    cell = bench._verdict(dict(fell, failure="FALLEN at t = 2.000 s: |theta_b| = 1.0 > 1.0"))
    assert "|" not in cell.replace("\\|", "") and "\\|theta_b\\|" in cell
    with pytest.raises(ValueError, match="no bag of smc_ndo under "):   # a law the invocation never ran
        bench.goals(tmp_path, "smc_ndo", 10.0, 1)


def test_a_run_ended_in_fault_says_its_reason_and_is_not_complete(bench, tmp_path):
    _run(tmp_path, "dscndo", 10.0, truth=False, exit_code=1, fault="device", first_k=2)
    g = bench.goals(tmp_path, "dscndo", 10.0, 1)
    assert not g["complete"]
    assert bench._verdict(g) == ("ended at t = 9.990 s in fault device: moteus right wheel (CAN id 2): no answer "
                                 "for 53 ms (exit 1)")


def test_a_robot_without_truth_is_judged_on_its_estimate_its_window_ending_with_its_bag(bench, tmp_path):
    # the emulated moteus robot: no truth, no pose; its bag starts at the estimator's first estimate (period 3), so it
    # ends 15 ms short of the planned 10 s (this raised KeyError: 'theta_b_hat')
    _run(tmp_path, "dscndo", 10.0, truth=False, first_k=3, trips=(0, 0), periods=2000)
    g = bench.goals(tmp_path, "dscndo", 10.0, 0)
    assert g["judged_on"] == "estimate" and g["complete"] and bench._verdict(g) == "yes"
    assert g["t_end"] == pytest.approx(10.0 - 3 * H_NS * 1e-9, abs=1e-9)
    assert 0.0 < g["theta_b_rms"] < 0.0045   # the estimate's (the truth's + 1e-4), over [5, the bag's end]
    assert math.isnan(g["theta_b_est_err_rms"]) and math.isnan(g["max_drift"])
    assert g["watchdog_trips"] == (0, 0)
    assert bench.moteus_goals(g, 10.0) == "meets"
    assert bench.upkie_goals(g) == "unmeasured (no truth)"   # the pitch goal's truth: not claimed from an estimate


def test_a_goal_without_its_number_is_unmeasured_and_a_missed_one_is_named(bench, tmp_path):
    _run(tmp_path, "dscndo", 10.0, truth=False, periods=1950, read_to_publish_p99=None)
    g = bench.goals(tmp_path, "dscndo", 10.0, 0)
    assert bench.moteus_goals(g, 10.0) == "watchdog unmeasured, periods MISSES, read-to-publish unmeasured"
    assert bench._check(math.nan, 1.0) == bench._check(None, 1.0) == "unmeasured"
    assert bench._check(0.5, 1.0) == "meets" and bench._check(1.5, 1.0) == "MISSES"


def test_the_window_ends_with_a_realtime_bag_only_within_the_slack(bench):
    assert bench.window_for(60.0, 60.0) == (5.0, 60.0)
    assert bench.window_for(60.0, 59.99) == (5.0, 59.99)
    assert bench.window_for(60.0, 59.5) == (5.0, 60.0)    # short by more: the window is not covered (NaN)
    assert bench.window_for(4.0, 4.0) == (2.0, 4.0)
    assert bench.window_for(60.0, math.nan) == (5.0, 60.0)


def test_the_estop_row_measures_the_estops_stop_only(bench):
    stopped = {"fault_reason": "emergency_stop", "stop_after_s": [0.0021], "driver_state": "fault"}
    assert bench.estop_line(stopped, [8.0], 1) == (
        "e-stop at t = 8 s of a 10 s realtime run (published at t = 8.000 s): emergency_stop latched; first stop "
        "written 2.100 ms after the transition (0.42 periods: meets within one period); exit 1")
    # a device's fault (a loaded machine's stall) took the driver out of enabled first: its stop is not the e-stop's
    device = {"fault_reason": "device", "fault_detail": "moteus left wheel (CAN id 1): no answer for 58 ms",
              "stop_after_s": [0.0041], "driver_state": "fault"}
    assert bench.estop_line(device, [], 3) == (
        "e-stop: unmeasured: the driver latched device first (moteus left wheel (CAN id 1): no answer for 58 ms); "
        "the e-stop never published; exit 3")
