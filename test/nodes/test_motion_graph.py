"""cmd_vel and the motion references in the graph (theory 6.11): lockstep with config/motion.yaml's profile equals
mwip_sim for every law (two graphs at once, the law switched between plant runs); the loop in this process follows
cmd_vel, stops when it ends (the timeout, logged once, counted on /diagnostics), and hostile Twists are rejected and
counted (a published cmd_vel across processes: test_yaw_graph.py, test_motion_flood.py)."""
from pathlib import Path

import numpy as np
import pytest

from graphproc import PARAMS
from loopgraph import LoopGraph, concurrently
from mwip_ros import params as P
from mwip_ros.core import laws
from mwip_ros.core.closed_loop.sim import simulate
from mwip_ros.runs import load_run

MOTION = Path(__file__).resolve().parents[2] / "config" / "motion.yaml"
COLUMNS = ["t", "theta_w", "theta_b", "dtheta_w", "dtheta_b", "u", "tau_d1", "tau_d2"]
CONTROLLERS = ["dsc", "dscndo", "lqr", "lqr_ndo", "smc", "smc_ndo", "mpc", "mpc_ndo"]


def _motion_runs(work, names):
    """One lockstep graph of [paper.yaml, motion.yaml]: the observer and the controller up, a plant of 12 s per law
    of ``names`` whose packages are installed (``law`` and ``use_observer`` switched through the parameter service);
    (the runs, the controller's exit code and output)."""
    runs = {}
    with LoopGraph(work, params=[PARAMS, MOTION]) as loop:
        loop.start()
        for name in names:
            cls = laws.get(name)
            if laws.unavailable(cls):
                continue
            loop.set("dscndo_controller", law=cls.family, use_observer=cls.observer)
            runs[name] = loop.run(name, "-p", "duration_s:=12.0")
        code = loop.stop("dscndo_controller")
        return runs, code, loop.nodes["dscndo_controller"].output()


@pytest.fixture(scope="module")
def motion_runs(tmp_path_factory):
    """Two such graphs at once (test/loopgraph.py), half the laws each: {law: (its run, its controller's output)}."""
    work = tmp_path_factory.mktemp("motion")
    halves = (CONTROLLERS[:4], CONTROLLERS[4:])
    out = {}
    for i, (runs, code, ctl_out) in enumerate(concurrently(*(lambda i=i, h=h: _motion_runs(work / str(i), h)
                                                              for i, h in enumerate(halves)))):
        assert code == 0, ctl_out
        out.update({name: (run, ctl_out) for name, run in runs.items()})
    return out


@pytest.mark.graph
@pytest.mark.parametrize("controller", CONTROLLERS)
def test_lockstep_graph_with_the_motion_profile_equals_mwip_sim(motion_runs, controller):
    cls = laws.get(controller)
    if laws.unavailable(cls):
        pytest.skip(laws.unavailable(cls))
    run, ctl_out = motion_runs[controller]
    assert run.code == 0, run.output()
    assert "tracking motion.profile" in ctl_out
    files = [PARAMS, MOTION]
    graph = load_run(run.csv)
    offline = simulate(P.closed_loop(P.merged_values(P.load_param_files(files)), controller=controller,
                                     duration=12.0))
    assert len(graph) == len(offline) == 2401
    assert np.abs(0.254 * offline["dtheta_w"][1900:]).mean() > 0.5   # it drove (1 m/s from 2 s on)
    for c in COLUMNS:
        np.testing.assert_allclose(graph[c], offline[c], rtol=0, atol=1e-9, err_msg=c)


@pytest.mark.node
def test_cmd_vel_is_followed_then_the_timeout_stops_it_and_hostile_twists_are_counted(tmp_path):
    """The loop (plant, observer, controller with motion on and no profile) in this process: hostile Twists first,
    none of which moves the robot, each rejected and counted; then 0.6 m/s at 20 Hz for 4 s (the ramp at 0.5 m/s^2
    takes 1.2 s) is followed; 6 s of silence stop it (one stop, logged once) and it holds."""
    from mwip_ros.msgs import layouts as L
    from nodeharness import Loop
    cfg = tmp_path / "drive.yaml"
    cfg.write_text("dscndo_controller:\n  ros__parameters:\n    motion: {enabled: true, cmd_vel_timeout_s: 0.5}\n")
    with Loop("-p", "duration_s:=0.0", params=[PARAMS, cfg]) as loop:
        plant, ctl = loop.plant, loop["dscndo_controller"]

        def k():
            return plant.node.plant.k

        def speeds(n):   # the robot's speed over the last n periods [m/s]
            return 0.254 * np.array([L.parse_joint_state(d)[1][2] for d in plant.sent("joint_states")[-n:]])

        def diag(key):
            return ctl.node.diagnostic_status()[2][key]
        loop.start()
        assert loop.run(lambda: k() >= 400)
        for i, data in enumerate((L.encode_twist(float("nan"), 0.0), L.encode_twist(0.0, float("inf")),
                                  L.encode_twist(1e6, 0.0), b"\x00\x01\x00\x00" + bytes(8)), start=1):
            ctl.feed("cmd_vel", data)
            assert diag("cmd_vel_rejected") == i
        assert diag("cmd_vel_accepted") == 0 and ctl.node.motion.stopped   # no target was set
        end = k() + 800
        while k() < end:   # drive: 0.6 m/s, 20 Hz (every 10 periods) for 4 s
            ctl.feed("cmd_vel", L.encode_twist(0.6, 0.0))
            next_k = k() + 10
            assert loop.run(lambda: k() >= next_k)
        moving = float(np.mean(speeds(200)))   # the last second of driving
        timeouts_moving = diag("cmd_vel_timeouts")
        assert loop.run(lambda: k() >= end + 1200)   # 6 s of silence: the stop, then the hold
        stopped = float(np.mean(speeds(200)))
        timeouts = diag("cmd_vel_timeouts")
        assert diag("cmd_vel_accepted") == 80
    out = ctl.logs()
    assert 0.35 < moving < 0.85, moving        # it follows 0.6 m/s (with the paper's disturbances on)
    assert abs(stopped) < 0.15, stopped          # stopped and holding
    assert out.count("cmd_vel: none for 0.5 s") == 1   # the stop logged once
    assert timeouts_moving == 0 and timeouts == 1
    for why in ("not finite (linear.x = nan", "absurd (linear.x = 1e+06",   # (a kind is logged 3 times)
                "not a geometry_msgs/Twist"):
        assert why in out, why
    assert int(out.rsplit("rejected: cmd_vel: ", 1)[1].split()[0]) == 4
    assert "cmd_vel: 80 accepted, 1 timeout stop(s), 4 rejected, 0 clipped" in out
