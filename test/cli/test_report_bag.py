"""mwip_report and runs.read_bag_run on bags written here message by message (no ROS graph): the torque that
acted in the last row, the plant's own record of a fall and of its configured duration (/rosout,
/parameter_events), and the warning for a bag mwip_bag_repair repaired."""
import json
import math

import numpy as np
import pytest
from PIL import Image
from rcl_interfaces.msg import Log, Parameter, ParameterEvent, ParameterValue
from rclpy.serialization import serialize_message

from mwip_ros.bag import REPAIRED_KEY, BagWriter
from mwip_ros.cli import animation as A
from mwip_ros.cli import report
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.cdr import encode_float64
from mwip_ros.runs import read_bag_run

pytestmark = pytest.mark.unit

H = 0.005
PERIOD_NS = 5_000_000
LIMIT = 50.0


def write_bag(path, theta_b, cmds, limit=LIMIT, logs=(), params=None, custom_data=None):
    """States k with theta_b[k] (stamp k h), the command cmds[k] answering each, the plant's applied torque
    (clipped at ``limit``) as the effort of state k + 1; ``logs`` [(t, text)] from plant_sim on /rosout,
    ``params`` {name: double} declared by /plant_sim on /parameter_events."""
    with BagWriter(path, custom_data=custom_data) as bag:
        for topic, kind in (("/joint_states", "sensor_msgs/msg/JointState"),
                            ("/wheel_torque_cmd", "std_msgs/msg/Float64"), ("/rosout", "rcl_interfaces/msg/Log"),
                            ("/parameter_events", "rcl_interfaces/msg/ParameterEvent")):
            bag.add_topic(topic, kind)
        if params:
            ev = ParameterEvent(node="/plant_sim", new_parameters=[
                Parameter(name=k, value=ParameterValue(type=3, double_value=float(v))) for k, v in params.items()])
            bag.write("/parameter_events", serialize_message(ev), 0)
        applied_prev = 0.0
        pending = sorted(logs)
        for k, (th, cmd) in enumerate(zip(theta_b, cmds)):
            stamp = k * PERIOD_NS
            while pending and pending[0][0] * 1e9 <= stamp:
                t, text = pending.pop(0)
                bag.write("/rosout", serialize_message(Log(name="plant_sim", level=40, msg=text)), stamp)
            bag.write("/joint_states", L.encode_state(stamp, (0.0, float(th), 0.0, 0.0), applied_prev), stamp)
            bag.write("/wheel_torque_cmd", encode_float64(float(cmd)), stamp + 1)
            applied_prev = max(-limit, min(limit, cmd)) if limit > 0 else cmd
        for t, text in pending:
            bag.write("/rosout", serialize_message(Log(name="plant_sim", level=40, msg=text)),
                      len(theta_b) * PERIOD_NS)
    return path


def test_the_last_row_takes_the_torque_that_acted_never_the_unclipped_command(tmp_path):
    n = 20
    cmds = np.full(n, 400.0)
    cmds[-1] = 2851.0                        # the last command, far beyond the limit: no state says what acted
    th = np.linspace(0.0, 0.01, n)
    run = read_bag_run(write_bag(tmp_path / "a", th, cmds))
    assert np.all(run["u"][:-1] == LIMIT)    # the effort of the next state: the applied torque
    assert math.isnan(run["u"][-1])          # no torque_limit recorded and 2851 > every applied torque: unknown
    run = read_bag_run(write_bag(tmp_path / "b", th, cmds, params={"torque_limit": LIMIT, "duration_s": 10.0}))
    assert run["u"][-1] == LIMIT and run.record["torque_limit"] == LIMIT   # the plant's limit, from the bag
    cmds[-1] = 12.5                          # within what the plant applied: no limit below it could clip it
    run = read_bag_run(write_bag(tmp_path / "c", th, cmds))
    assert run["u"][-1] == 12.5
    unlimited = np.linspace(-30.0, 30.0, n)
    run = read_bag_run(write_bag(tmp_path / "d", th, unlimited, limit=0.0, params={"torque_limit": 0.0}))
    np.testing.assert_array_equal(run["u"], unlimited)   # torque_limit 0: every command acted as sent


def test_a_fall_the_plant_logged_is_reported_with_its_time_in_every_output(tmp_path, capsys):
    n = 97                                   # t = 0 .. 0.480 s
    th = np.linspace(0.9, 1.04, n)
    th[-1] = 1.06                            # the plant's last row: the one beyond the fall angle (t = 0.480 s)
    first_over = int(np.flatnonzero(th > report.FALL_ANGLE)[0]) * H
    assert first_over == pytest.approx(0.48)
    text = f"FALLEN at t = {first_over:.3f} s: |theta_b| = {th[int(round(first_over / H))]:.4f} > fall_angle 1.0472"
    bag = write_bag(tmp_path / "bag", th, np.full(n, 80.0), logs=[(first_over, text),
                                                                  (0.0, "lockstep plant: h = 5.000 ms, 10 RK4 "
                                                                        "sub-steps, 3 s, seed 1")])
    out = tmp_path / "rep"
    assert report.main([str(bag), "--labels", "dsc", "--out", str(out), "--gif-fps", "20"]) == 0
    stdout = capsys.readouterr().out
    fell = [line for line in stdout.splitlines() if line.startswith("FELL: ")]
    assert fell == [f"FELL: dsc at t = {first_over:.3f} s"]
    md = (out / "metrics.md").read_text()
    assert text in md and "NO" in md
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["runs"]["dsc"]["t_fall"] == pytest.approx(first_over) and doc["runs"]["dsc"]["upright"] is False
    # the animation's last frame is the run's end (0.480 s, between frames 0.45 and 0.50): titled FELL in red
    with Image.open(out / "animation.gif") as im:
        assert im.n_frames == 11             # t = 0, 0.05, .., 0.45 s and the end, 0.48 s
        reds = []
        for k in (im.n_frames - 2, im.n_frames - 1):
            im.seek(k)
            header = np.asarray(im.convert("RGB")).astype(int)[:A.HEADER + 20]
            reds.append(((header[..., 0] > 150) & (header[..., 1] < 110) & (header[..., 2] < 110)).sum())
    assert reds[0] == 0 and reds[1] > 20


def test_the_plants_fall_angle_and_record_judge_a_fall_the_default_angle_would_miss(tmp_path, capsys):
    n = 61
    th = np.linspace(0.3, 0.6, n)            # never beyond the default fall angle, beyond the plant's 0.5
    first_over = int(np.flatnonzero(th > 0.5)[0]) * H
    text = f"FALLEN at t = {first_over:.3f} s: |theta_b| = 0.6000 > fall_angle 0.5"
    bag = write_bag(tmp_path / "bag", th, np.zeros(n), logs=[(first_over, text)])
    out = tmp_path / "rep"
    assert report.main([str(bag), "--labels", "x", "--out", str(out), "--no-animation"]) == 0
    assert f"FELL: x at t = {first_over:.3f} s" in capsys.readouterr().out.splitlines()
    # only the record: a run whose table shows no fall at any angle still fell when the plant said so
    run = read_bag_run(bag)
    run.record.pop("fall_angle")
    run.columns["theta_b"] = np.zeros(n)
    res = report.write_report([run], tmp_path / "rep2", gif_fps=None)
    assert res["fallen"] == {run.label: pytest.approx(first_over)}


def test_a_run_cut_before_the_plants_configured_duration_says_so(tmp_path, capsys):
    n = 401                                  # 2 s of a run the plant was to run for 10 s
    th = 0.01 * np.sin(np.arange(n) * H)
    bag = write_bag(tmp_path / "bag", th, np.zeros(n),
                    logs=[(0.0, "lockstep plant: h = 5.000 ms, 10 RK4 sub-steps, 10 s, seed 1")])
    out = tmp_path / "rep"
    assert report.main([str(bag), "--labels", "dscndo", "--out", str(out), "--no-animation"]) == 0
    stdout = capsys.readouterr().out
    assert "dscndo: run ends at t = 2.000 s: cut, before the plant's configured duration of 10 s" in stdout
    assert "cut, before the plant's configured duration of 10 s" in (out / "metrics.md").read_text()
    assert "FELL" not in stdout
    whole = write_bag(tmp_path / "whole", th, np.zeros(n),
                      logs=[(0.0, "lockstep plant: h = 5.000 ms, 10 RK4 sub-steps, 2 s, seed 1")])
    assert report.main([str(whole), "--out", str(tmp_path / "rep2"), "--no-animation"]) == 0
    stdout = capsys.readouterr().out
    assert "run ends at t = 2.000 s (the plant's configured duration: 2 s)" in stdout and ": cut" not in stdout


def test_a_repaired_bag_is_reported_with_a_warning_quoting_the_repair(tmp_path, capsys):
    said = "recovered 12 of 13 chunks; lost t = 1.9 .. 2.0 s (the recorder was killed)"
    bag = write_bag(tmp_path / "bag", np.zeros(50), np.zeros(50), custom_data={REPAIRED_KEY: said})
    out = tmp_path / "rep"
    assert report.main([str(bag), "--out", str(out), "--no-animation"]) == 0
    err = capsys.readouterr().err
    assert "WARNING" in err and said in err
    md = (out / "metrics.md").read_text()
    assert "**Warning:**" in md and said in md
    assert said in " ".join(json.loads((out / "metrics.json").read_text())["warnings"])
