"""cmd_vel and the motion references in the graph (theory 6.11): lockstep with config/motion.yaml's profile equals
mwip_sim for every law; realtime, the robot follows a published cmd_vel, stops when it ends (the timeout, logged
once, counted on /diagnostics), and hostile Twists are rejected and counted."""
import time
from pathlib import Path

import numpy as np
import pytest

from graphproc import PARAMS, Graph, run_lockstep
from injector import Injector, controller_value
from mwip_ros import params as P
from mwip_ros.core import laws
from mwip_ros.core.sim import simulate
from mwip_ros.runs import load_run

pytestmark = pytest.mark.graph

MOTION = Path(__file__).resolve().parents[2] / "config" / "motion.yaml"
COLUMNS = ["t", "theta_w", "theta_b", "dtheta_w", "dtheta_b", "u", "tau_d1", "tau_d2"]


@pytest.mark.parametrize("controller", ["dsc", "dscndo", "lqr", "lqr_ndo", "smc", "smc_ndo", "mpc", "mpc_ndo"])
def test_lockstep_graph_with_the_motion_profile_equals_mwip_sim(tmp_path, controller):
    cls = laws.get(controller)
    if laws.unavailable(cls):
        pytest.skip(laws.unavailable(cls))
    files = [PARAMS, MOTION]
    code, csv_path, logs = run_lockstep(tmp_path, cls.observer, "-p", "duration_s:=12.0", params=files,
                                        law=cls.family)
    assert code == 0, logs["plant_sim"].output()
    assert "tracking motion.profile" in logs["dscndo_controller"].output()
    graph = load_run(csv_path)
    offline = simulate(P.closed_loop(P.merged_values(P.load_param_files(files)), controller=controller,
                                     duration=12.0))
    assert len(graph) == len(offline) == 2401
    assert np.abs(0.254 * offline["dtheta_w"][1900:]).mean() > 0.5   # it drove (1 m/s from 2 s on)
    for c in COLUMNS:
        np.testing.assert_allclose(graph[c], offline[c], rtol=0, atol=1e-9, err_msg=c)


def test_realtime_cmd_vel_is_followed_then_the_timeout_stops_it_and_hostile_twists_are_counted(tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import Twist
    from sensor_msgs.msg import JointState

    from mwip_ros.msgs import layouts as L
    cfg = tmp_path / "drive.yaml"
    cfg.write_text("dscndo_controller:\n  ros__parameters:\n    motion: {enabled: true, cmd_vel_timeout_s: 0.5}\n")
    with Graph(tmp_path) as g:
        with Injector(g.domain_id) as inj:
            speeds, diags = [], []
            inj.node.create_subscription(JointState, "joint_states",
                                         lambda m: speeds.append(0.254 * m.velocity[0]), 10)
            inj.node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: diags.append(m), 10)
            g.start("disturbance_observer", "-p", "mode:=realtime", params=[PARAMS, cfg])
            ctl = g.start("dscndo_controller", "-p", "mode:=realtime", params=[PARAMS, cfg])
            g.start("plant_sim", "-p", "mode:=realtime", "-p", "duration_s:=0.0", params=[PARAMS, cfg])
            pub = inj.publisher("cmd_vel", Twist)
            assert inj.wait(lambda: pub.get_subscription_count() >= 1 and len(speeds) > 400, 30), "no graph"
            # hostile Twists first, none of which may move the robot: cmd_vel keeps the newest only (a burst loses
            # some), so each is sent until /diagnostics counts it
            for i, data in enumerate((L.encode_twist(float("nan"), 0.0), L.encode_twist(0.0, float("inf")),
                                      L.encode_twist(1e6, 0.0), b"\x00\x01\x00\x00" + bytes(8)), start=1):
                def counted(i=i, data=data):
                    pub.publish(data)
                    inj.spin(0.05)
                    return controller_value(diags, "cmd_vel_rejected") >= i
                assert inj.wait(counted, 20), (i, controller_value(diags, "cmd_vel_rejected"))
            # drive: 0.6 m/s, sent at 20 Hz for 4 s (the ramp at 0.5 m/s^2 takes 1.2 s)
            end = time.monotonic() + 4.0
            while time.monotonic() < end:
                pub.publish(L.encode_twist(0.6, 0.0))
                inj.spin(0.05)
            moving = float(np.mean(speeds[-200:]))   # the last second of driving
            n_at_stop = len(speeds)
            inj.wait(lambda: len(speeds) > n_at_stop + 1200, 20)   # 6 s of silence: the stop, then the hold
            stopped = float(np.mean(speeds[-200:]))
            inj.wait(lambda: controller_value(diags, "cmd_vel_timeouts") == 1, 10)
            timeouts = controller_value(diags, "cmd_vel_timeouts")
        g.close()
        out = ctl.output()
    assert 0.35 < moving < 0.85, moving        # it follows 0.6 m/s (with the paper's disturbances on)
    assert abs(stopped) < 0.15, stopped          # stopped and holding
    assert out.count("cmd_vel: none for 0.5 s") == 1   # the stop logged once
    assert timeouts == 1
    for why in ("not finite (linear.x = nan", "absurd (linear.x = 1e+06",   # (a kind is logged 3 times)
                "not a geometry_msgs/Twist"):
        assert why in out, why
    assert int(out.rsplit("rejected: cmd_vel: ", 1)[1].split()[0]) >= 4
    assert "cmd_vel: 1 timeout stop(s)" in out

