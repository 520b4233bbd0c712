"""A gain changed in the middle of a recorded lockstep run: the bag has the change (/parameter_events) and the
robot (/robot_markers); resim applies the change at the same state and reproduces the run exactly, and without
it (parameter_events:=false) it does not."""
import os
import signal

import pytest

from graphproc import Graph
from injector import Injector, call_until_answered

pytestmark = pytest.mark.graph

MODULE = "mwip_ros.nodes.tools.bag_replay"
NEW_K1 = 8.0
DURATION_S = 10.0                 # the recorded run: 2001 states (a 2 s run ended before a loaded test process, behind
STATES = 2001                     # the plant's stream, saw t = 0.3 s: the change came at its last state)
CHANGE_AFTER_NS = 300_000_000     # set k1 once the run passed t = 0.3 s (the observer held meanwhile: inside the run)


@pytest.fixture(scope="module")
def changed_bag(tmp_path_factory):
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters
    from sensor_msgs.msg import JointState

    from mwip_ros.msgs import layouts as L
    work = tmp_path_factory.mktemp("changed")
    out = work / "bag"
    with Graph(work) as g:
        rec = g.start("mcap_recorder", "-p", f"output:={out}", "-p", "use_sim_time:=true", params=None)
        obs = g.start("disturbance_observer")     # no use_sim_time, as run_experiment.sh runs them
        ctl = g.start("dscndo_controller")
        markers = g.start("robot_markers")
        with Injector(g.domain_id) as inj:
            states = inj.record("joint_states", JointState)
            client = inj.node.create_client(SetParameters, "/dscndo_controller/set_parameters")
            assert client.wait_for_service(timeout_sec=30)   # found before the run, which lasts about 2 s of wall time
            call_until_answered(inj, client, SetParameters.Request)   # its answers reach us: no parameters, a no-op
            # expected_subscribers: the observer, the controller, the markers and the recorder (the user's count)
            plant = g.start("plant_sim", "-p", f"duration_s:={DURATION_S}", "-p", "expected_subscribers:=4")
            # a state one period past CHANGE_AFTER_NS: the plant sent it only once the controller had answered the one
            # before, so the controller's clock (the last state it answered) is at CHANGE_AFTER_NS at least
            past = CHANGE_AFTER_NS + 5_000_000

            def past_and_held() -> bool:   # the observer stopped at once: the lockstep chain waits for it (well
                if any(L.parse_joint_state(d)[0] >= past for d in states[-5:]):   # within lockstep_timeout_s), so
                    os.kill(obs.pid, signal.SIGSTOP)   # the change comes inside the run however slow the machine
                    return True
                return False
            assert inj.wait(past_and_held, 120), plant.output()[-2000:]
            try:
                value = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=NEW_K1)
                future = client.call_async(SetParameters.Request(parameters=[Parameter(name="k1", value=value)]))
                assert inj.wait(future.done, 5) and future.result().results[0].successful, future.result()
            finally:
                os.kill(obs.pid, signal.SIGCONT)
            assert plant.wait(180) == 0, plant.output()[-2000:]
        for p in (obs, ctl, markers, rec):
            assert p.stop() == 0, p.output()[-2000:]
    assert f"k1: 6.0 -> {NEW_K1}" in ctl.output()
    return out


@pytest.mark.alone
def test_the_bag_has_the_robot_and_the_gain_change(changed_bag):
    from bagcheck import decoded_messages, distinct_stamps
    from mwip_ros.bag import topic_counts
    counts = topic_counts(changed_bag)
    assert counts.get("/robot_markers", 0) > STATES // 2 and distinct_stamps(changed_bag, ["/joint_states"]) == \
        {"/joint_states": STATES}, counts
    markers = [m for topic, _, _, m in decoded_messages(changed_bag, ["/robot_markers"])]
    assert all(mk.header.frame_id == "world" for mk in markers[0].markers)
    changes = [(m.node, m.stamp.sec * 10 ** 9 + m.stamp.nanosec, p.name, p.value.double_value)
               for topic, _, _, m in decoded_messages(changed_bag, ["/parameter_events"]) for p in m.changed_parameters]
    [(node, stamp, name, value)] = [c for c in changes if c[2] == "k1"]
    assert (node, name, value) == ("/dscndo_controller", "k1", NEW_K1)
    # stamped with the state the controller had answered last: on the plant's grid, inside the run
    assert stamp % 5_000_000 == 0 and CHANGE_AFTER_NS <= stamp < DURATION_S * 10 ** 9, stamp


@pytest.mark.alone
@pytest.mark.parametrize("apply, code, result", [(True, 0, "RESULT: REPRODUCED"), (False, 4, "RESULT: DIFFERENT")])
def test_resim_applies_the_recorded_change_at_the_same_state(tmp_path, changed_bag, apply, code, result):
    with Graph(tmp_path) as g:
        g.start("disturbance_observer")
        ctl = g.start("dscndo_controller")
        br = g.start("bag_replay", "-p", f"bag:={changed_bag}", "-p", "mode:=resim", "-p",
                     f"parameter_events:={'true' if apply else 'false'}", params=None, module=MODULE)
        got = br.wait(180)
    out = br.output()
    assert got == code and result in out, out[-3000:]
    if apply:
        assert "recorded parameter changes applied: 1" in out and f"k1: 6.0 -> {NEW_K1}" in ctl.output(), out[-3000:]
