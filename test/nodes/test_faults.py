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
