"""bag_replay resim of lockstep recordings in which the controller tracked motion (docs/theory.md 6.11): a
``motion.profile`` (config/motion.yaml) and ``cmd_vel`` (the recorded Twists replayed before the states recorded
after them) are both reproduced exactly. The two recordings, each with its resim, run at once."""
import signal

import pytest

from graphproc import PARAMS, REPO
from loopgraph import LoopGraph, concurrently
from test_bag_replay import parse_table, resim

pytestmark = pytest.mark.graph

DURATION = 2.5
STATES = 501   # 2.5 s at 200 Hz
MOTION = REPO / "config" / "motion.yaml"


def _record_and_resim(work, files, twist=None):
    """(bag, resim's exit code and output): a lockstep DSCNDO run of ``files`` recorded by mcap_recorder, then
    bag_replay resim of the bag (a freshly started observer and controller, as it asks); ``twist``: a cmd_vel
    (linear.x) the controller and the recorder have before the plant starts."""
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import Twist

    from injector import Injector, controller_publishers, controller_value, publish_until
    bag = work / "bag"
    with LoopGraph(work, params=files) as loop:
        with Injector(loop.domain_id) as inj:   # gone before the resim: bag_replay is then cmd_vel's one publisher
            diags = []
            inj.node.create_subscription(DiagnosticArray, "/diagnostics", diags.append, 10)
            rec = loop.graph.start("mcap_recorder", "-p", f"output:={bag}", "-p", "use_sim_time:=true", params=None)
            loop.start()
            ctl = loop.nodes["dscndo_controller"]
            if twist is not None:
                pub = inj.publisher("cmd_vel", Twist, qos=10)
                # matched both ways: this publisher counts the controller's subscription and the recorder's (made
                # once it discovers this publisher), and the controller's best-effort subscription counts this one
                assert inj.wait(lambda: pub.get_subscription_count() >= 2
                                and controller_publishers(diags, "/cmd_vel") >= 1, 30), \
                    (pub.get_subscription_count(), controller_publishers(diags, "/cmd_vel"))
                msg = Twist()
                msg.linear.x = twist
                # the controller has it before the plant starts (its /diagnostics count it; best effort: sent again
                # if lost, the newest counts and the recorder keeps them all before state 0)
                assert publish_until(inj, pub, msg, lambda: controller_value(diags, "cmd_vel_accepted") >= 1, 30.0,
                                     every=3.0), ctl.output()
            run = loop.run("plant", "-p", f"duration_s:={DURATION}", "-p", "expected_subscribers:=3")
            assert run.code == 0, run.output()
            assert rec.stop(signal.SIGINT, timeout=20) == 0, rec.output()
    return bag, resim(work / "resim", bag, params=files)


def _reproduced(code, out):
    assert code == 0, out
    rows = parse_table(out)
    for name in ("wheel_torque_cmd", "disturbance_estimate", "controller_internals", "u"):
        compared, missing, diff = rows[name]
        assert compared == STATES and missing in (0, None) and diff == 0.0, (name, out)
    assert "RESULT: REPRODUCED" in out


GAINS = "      max_accel: 0.5\n      position_gain: 0.2\n      lean_gain: 0.03\n"   # config/motion.yaml's


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """The two recordings at once, each a graph of its own then its resim: {"profile": config/motion.yaml's
    profile, "cmd_vel": a controller tracking cmd_vel (no profile, no timeout within the run) given 0.5 m/s before
    the plant starts}, each (bag, resim's exit code and output)."""
    work = tmp_path_factory.mktemp("resim_motion")
    over = work / "cmd_vel.yaml"
    over.write_text("dscndo_controller:\n  ros__parameters:\n    motion:\n      enabled: true\n" + GAINS
                    + "      cmd_vel_timeout_s: 10.0\n")
    profile, cmd_vel = concurrently(lambda: _record_and_resim(work / "profile", [PARAMS, MOTION]),
                                    lambda: _record_and_resim(work / "cmd_vel", [PARAMS, over], twist=0.5))
    return {"profile": profile, "cmd_vel": cmd_vel}


def test_resim_of_a_recording_with_a_motion_profile_reproduces_it(recordings):
    _bag, replayed = recordings["profile"]   # at rest, then 1 m/s from t = 2 s
    _reproduced(*replayed)


def test_resim_replays_the_recorded_cmd_vel_and_reproduces_the_run(tmp_path, recordings):
    import numpy as np

    from mwip_ros import params as P
    from mwip_ros.core.closed_loop.sim import simulate
    from mwip_ros.runs import read_bag_run
    bag, (code, out) = recordings["cmd_vel"]
    # the recording is the run with v* = 0.5 m/s from state 0 (mwip_sim with that profile): the controller had the
    # Twist before the first state
    prof = tmp_path / "profile.yaml"
    prof.write_text("dscndo_controller:\n  ros__parameters:\n    motion:\n      enabled: true\n" + GAINS
                    + "      profile: [0.0, 0.5]\n")
    offline = simulate(P.closed_loop(P.merged_values(P.load_param_files([PARAMS, prof])), duration=DURATION,
                                     controller="dscndo"))
    recorded = read_bag_run(bag)
    np.testing.assert_allclose(recorded["theta_w"], offline["theta_w"], rtol=0, atol=1e-9)
    assert "recorded cmd_vel replayed: 1" in out, out
    _reproduced(code, out)
