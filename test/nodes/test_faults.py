"""Killed and paused peers, a second controller in the domain: the plant names the node at fault."""
import os
import signal

from graphproc import Graph

LOCKSTEP = ("-p", "duration_s:=0.0", "-p", "lockstep_timeout_s:=3.0")


def _lockstep_graph(g, *controllers):
    obs = g.start("disturbance_observer")
    ctls = [g.start("dscndo_controller", *args, label=label) for label, args in controllers]
    return obs, ctls


def test_a_killed_observer_is_named_not_the_controller(tmp_path):
    with Graph(tmp_path) as g:
        obs, (ctl,) = _lockstep_graph(g, ("dscndo_controller", ()))
        plant = g.start("plant_sim", *LOCKSTEP)
        assert plant.wait_for_output("steps/s", 60), plant.output()  # running (progress every 2 s)
        os.kill(obs.pid, signal.SIGKILL)
        code = plant.wait(60)
        out = plant.output()
    assert code == 1, out
    failure = out.split("lockstep timeout:")[1]
    assert "disturbance_observer (it did not answer state k = " in failure, failure
    assert "the controller is running but did not answer" not in failure


def test_a_paused_controller_is_named(tmp_path):
    with Graph(tmp_path) as g:
        obs, (ctl,) = _lockstep_graph(g, ("dscndo_controller", ()))
        plant = g.start("plant_sim", *LOCKSTEP)
        assert plant.wait_for_output("steps/s", 60), plant.output()
        os.kill(ctl.pid, signal.SIGSTOP)
        try:
            code = plant.wait(60)
        finally:
            os.kill(ctl.pid, signal.SIGCONT)
        out = plant.output()
    assert code == 1, out
    failure = out.split("lockstep timeout:")[1]
    assert "the controller is running but did not answer" in failure and "disturbance_observer" not in failure


def test_lockstep_refuses_two_controllers_and_names_them(tmp_path):
    with Graph(tmp_path) as g:
        obs, ctls = _lockstep_graph(g, ("dscndo_controller", ()),
                                    ("second_controller", ("-r", "__node:=dscndo_controller_b")))
        for c in ctls:
            assert c.wait_for_output("ready", 30)
        plant = g.start("plant_sim", "-p", "expected_subscribers:=3", "-p", "duration_s:=20.0")
        code = plant.wait(60)
        out = plant.output()
        c_out = ctls[0].output()
    assert code == 1, out
    assert "lockstep refuses mixed streams" in out
    assert "/dscndo_controller, /dscndo_controller_b" in out and "wheel_torque_cmd" in out
    assert "2 publishers on /disturbance_estimate" not in c_out  # the observer is alone on its topic


def test_the_plant_rejects_absurd_commands_and_cut_wrenches_and_keeps_running(tmp_path):
    import math
    import struct

    from geometry_msgs.msg import Wrench
    from injector import Injector
    from mwip_ros.msgs import layouts as L
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64

    with Graph(tmp_path) as g:
        plant = g.start("plant_sim", "-p", "mode:=realtime", "-p", "duration_s:=0.0", "-p", "initial.theta_b:=0.0",
                        "-p", "lockstep_timeout_s:=0.5", "-p", "actual.D_w_variance:=0.0")
        with Injector(g.domain_id) as inj:
            cmd = inj.publisher("wheel_torque_cmd", Float64)
            wr = inj.publisher("external_wrench", Wrench)
            states = inj.record("joint_states", JointState)
            assert inj.wait(lambda: cmd.get_subscription_count() >= 1 and wr.get_subscription_count() >= 1, 30)
            assert inj.wait(lambda: len(states) > 20, 30), plant.output()
            for u in (1e300, -1e7, math.inf, math.nan):
                cmd.publish(L.encode_command(u))
            full = L.encode_external_wrench(25.0, -3.0)
            wr.publish(full[:-12])                                       # cut inside torque.y: refused
            wr.publish(L.encode_external_wrench(1e9, 0.0))                # absurd
            wr.publish(b"\x00\x01\x00\x00" + struct.pack("<5d", 1, 2, 3, 4, 5))  # one double short
            n = len(states)
            assert inj.wait(lambda: len(states) > n + 100, 30), plant.output()  # still stepping, 200 Hz
            last = L.parse_joint_state(states[-1])[1]
        code = plant.stop()
    out = plant.output()
    assert code == 0, out
    assert all(math.isfinite(v) for v in last) and abs(last.theta_b) < 0.5  # nothing absurd was applied
    assert "wheel_torque_cmd: 4" in out.split("rejected messages:")[1]
    assert "external_wrench: 3" in out.split("rejected messages:")[1]
    assert "implausible command" in out and "not a geometry_msgs/Wrench: message ends at byte" in out
    assert "external wrench: tau_ext1" not in out  # nothing was applied as a push
    assert "Traceback" not in out
